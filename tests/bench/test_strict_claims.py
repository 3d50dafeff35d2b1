"""Every solver is judged by its own claim: strict (the lexicographic optimum,
judged by ``verified``) or not (weighted, damped: real times, per-level gaps,
success = level 0 met). Python solvers declare it (``Solver.strict``,
``SolverInfo.strict``, shown by ``hikbench list solvers``); an external
program declares it in its spec, ``external:NAME[strict=false]=CMD``."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import tomli_w
from clitools import assert_user_error, run

from hikbench.bench.analysis import plots
from hikbench.bench.analysis.ranking import claim_met, level0_met
from hikbench.bench.analysis.report import write_report
from hikbench.bench.harness.external import parse_spec
from hikbench.bench.harness.results import read_results
from hikbench.bench.suites import SuiteError, parse_external
from hikbench.solvers import registry
from hikbench.solvers.base import Solver

ROOT = Path(__file__).resolve().parents[2]

# ---- Python solvers -----------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(registry.available()), ids=list(registry.available()))
def test_a_registered_solver_declares_its_claim_once(name):
    """SolverInfo.strict is a bool and agrees with the class's own ``strict`` (what a
    ``file.py:Class`` of the same class would be run with)."""
    info = registry.available()[name]
    assert isinstance(info.strict, bool)
    assert isinstance(info.factory, type) and issubclass(info.factory, Solver)
    assert info.factory.strict is info.strict


def _docs_strict() -> dict[str, bool]:
    """solver -> strict, from the table of docs/solvers.md (column 'strict')."""
    out = {}
    lines = (ROOT / "docs" / "solvers.md").read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("| solver |"))
    cols = [c.strip() for c in lines[head].strip("|").split("|")]
    for ln in lines[head + 2:]:
        if not ln.startswith("|"):
            break
        cells = dict(zip(cols, (c.strip() for c in ln.strip("|").split("|"))))
        for name in re.findall(r"`([\w-]+)`", cells["solver"]):
            out[name] = {"yes": True, "no": False}[cells["strict"]]
    return out


def test_docs_solvers_table_says_each_solvers_claim():
    docs = _docs_strict()
    avail = registry.available()
    assert set(avail) <= set(docs), set(avail) - set(docs)
    assert {n: docs[n] for n in avail} == {n: i.strict for n, i in avail.items()}


def test_list_solvers_shows_each_claim(capsys):
    code, out, _ = run(capsys, "list", "solvers")
    assert code == 0
    for name, info in registry.available().items():
        [line] = [ln for ln in out.splitlines() if ln.split()[:1] == [name]]
        caps = line.rsplit("[", 1)[1].rstrip("]").split(", ")
        assert caps[0] == ("strict" if info.strict else "non-strict"), line


# ---- the external protocol -------------------------------------------------------------------------

CMD = "true {problem} {out}"  # (a program on PATH: a missing one is refused at start-up)


@pytest.mark.parametrize("spec, name, strict", [
    (f"external:p={CMD}", "p", True),
    (f"external:p[strict=true]={CMD}", "p", True),
    (f"external:p[strict=false]={CMD}", "p", False),
    (f"external:p[ strict = false ]={CMD}", "p", False),
    (f"external:p[]={CMD}", "p", True),
    (f"external:p[strict=false]=true --opt=[a] {{problem}} {{out}}", "p", False),
], ids=["plain", "strict-true", "strict-false", "spaces", "empty-brackets", "brackets-in-cmd"])
def test_an_external_spec_declares_its_claim(spec, name, strict):
    ext = parse_spec(spec)
    assert (ext.name, ext.strict) == (name, strict)
    assert "{out}" in ext.command and not ext.command.startswith("=")
    entry = parse_external(spec)
    assert (entry.solver, entry.strict, str(entry.spec)) == (f"external:{name}", strict, spec)


@pytest.mark.parametrize("spec, says", [
    (f"external:p[strict=no]={CMD}", "strict=no: expected strict=true"),
    (f"external:p[strict=False]={CMD}", "strict=False: expected strict=true"),
    (f"external:p[strict]={CMD}", "strict=: expected strict=true"),
    (f"external:p[strcit=false]={CMD}", "unknown declaration 'strcit' (did you mean 'strict'?)"),
    (f"external:p[strict=false={CMD}", "no ']=' after the declaration"),
    ("external:p[strict=false]=prog {problem}", "CMD must contain the placeholder {out}"),
    (f"external:[strict=false]={CMD}", "expected external:NAME=CMD"),
], ids=["no", "python-bool", "no-value", "misspelt", "unclosed", "no-out", "no-name"])
def test_a_bad_external_declaration_is_one_line_naming_the_suite_file(tmp_path, capsys, spec, says):
    suite = tmp_path / "s.toml"
    suite.write_text(tomli_w.dumps({"repeat": 1, "modes": ["cold"], "solvers": ["yardstick", spec],
                                    "problems": [{"family": "equality", "seeds": [0]}]}))
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "out")
    assert_user_error(code, err, f"suite {suite}", says)
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "out", "--solvers", spec)
    assert_user_error(code, err, "--solvers", says)
    with pytest.raises(SuiteError):
        parse_external(spec)
    assert not (tmp_path / "out" / "results.csv").exists()


# a weighted-like program: every level stacked in one least-squares solve (no hierarchy)
STACKED = '''
import json, sys
import numpy as np
with np.load(sys.argv[1]) as z:
    A, lower = z["A"], z["lower"]
x = np.linalg.lstsq(A, lower, rcond=None)[0]
json.dump({"x": x.tolist(), "solve_time_s": 1e-5}, open(sys.argv[2], "w"))
'''


@pytest.fixture(scope="module")
def stacked_run(tmp_path_factory):
    """A run of hcod and the stacked program declared non-strict on equality problems whose levels conflict."""
    from hikbench.bench.cli import main

    d = tmp_path_factory.mktemp("stacked")
    (d / "stacked.py").write_text(STACKED)
    spec = f"external:stacked[strict=false]={sys.executable} {d / 'stacked.py'} {{problem}} {{out}}"
    (d / "s.toml").write_text(tomli_w.dumps({
        "repeat": 2, "warmup": 0, "modes": ["cold"], "solvers": ["nullspace-svd", spec],
        "problems": [{"family": "equality", "grid": {"n": [4, 6], "rows": [3], "depth": [3]}, "seeds": [0, 1]}]}))
    assert main(["run", "--quiet", "--suite", str(d / "s.toml"), "--out", str(d / "out")]) == 0
    write_report(d / "out")
    return d / "out"


def test_a_non_strict_external_program_is_reported_like_weighted(stacked_run):
    df = read_results(stacked_run)
    ext = df[df["solver"] == "external:stacked"]
    assert len(ext) == 4 and ext["strict"].astype(str).eq("False").all()
    assert (ext["status"] == "optimal").all() and not ext["verified"].eq(True).all()  # (it loses levels)
    data = json.loads((stacked_run / "report.json").read_text())
    assert [r["solver"] for r in data["ranking"]["cold"]["solvers"]] == ["nullspace-svd"]
    [ns] = data["non_strict"]["cold"]
    assert ns["solver"] == "external:stacked" and ns["attempted"] == 4 and ns["timed"] == 4
    assert ns["median_time_s"] == pytest.approx(1e-5)  # its real (reported) time, not a charge
    assert len(ns["median_gap_per_level"]) == 3 and ns["level0_judged"] == 4
    md = (stacked_run / "report.md").read_text()
    unverified = md.split("### Unverified rows of strict solvers")[1].split("###")[0]
    assert "external:stacked" not in unverified


def test_the_success_table_judges_each_solver_by_its_claim(stacked_run):
    df = read_results(stacked_run)
    ext = df[df["solver"] == "external:stacked"].assign(label="external:stacked")
    expected = level0_met(ext).mean()
    md = (stacked_run / "report.md").read_text()
    table = md.split("### Success rate per solver and family")[1].split("###")[0]
    [row] = [ln for ln in table.splitlines() if ln.startswith("| external:stacked (non-strict: level 0)")]
    assert row.split("|")[2].strip() == f"{100 * expected:.0f}%"


# ---- success by claim -------------------------------------------------------------------------------


def _row(label, verified, side=None, level=None, strict=False):
    return {"label": label, "verified": verified, "verdict_side": side, "verdict_level": level,
            "strict": strict}


@pytest.mark.parametrize("row, met", [
    (_row("w", True), 1.0),
    (_row("w", False, "worse", 0), 0.0),
    (_row("w", False, "worse", 2), 1.0),
    (_row("w", False, "better", 0), 1.0),
    (_row("w", False, "no x"), 0.0),
    (_row("w", None, "no yardstick"), np.nan),
    (_row("w", False, "worse", None), np.nan),
], ids=["verified", "worse-at-0", "worse-below-0", "better-at-0", "no-x", "no-yardstick", "no-level"])
def test_a_non_strict_row_succeeds_when_level_0_is_met(row, met):
    d = pd.DataFrame([row])
    np.testing.assert_array_equal(claim_met(d, strict=set()).to_numpy(), [met])


@pytest.mark.parametrize("row, met", [
    (_row("s", True, strict=True), 1.0),
    (_row("s", False, "worse", 2, strict=True), 0.0),
    # no (certified) yardstick: the row cannot tell, as a non-strict one's (NaN: left out of the
    # per-family success, as success_rate.png always left it; it counted as a failure there before)
    (_row("s", None, "no yardstick", strict=True), np.nan),
    (_row("s", None, "no certified yardstick", strict=True), np.nan),
], ids=["verified", "worse-below-0", "no-yardstick", "no-certified-yardstick"])
def test_a_strict_row_succeeds_when_verified(row, met):
    d = pd.DataFrame([row])
    np.testing.assert_array_equal(claim_met(d, strict={"s"}).to_numpy(), [met])


def test_the_heatmap_cell_of_a_non_strict_solver_is_its_level_0_rate(tmp_path, monkeypatch):
    seen = {}
    real = plots.plt.Axes.imshow

    def keep(ax, data, *a, **k):
        seen["data"] = np.array(data)
        return real(ax, data, *a, **k)

    monkeypatch.setattr(plots.plt.Axes, "imshow", keep)
    rows = [dict(_row("w", False, "worse", lv), solver="w", settings="default", family="f", status="optimal")
            for lv in (0, 1, 1, 2)]
    rows += [dict(_row("s", ok, None if ok else "worse", None if ok else 1, strict=True), solver="s",
                  settings="default", family="f", status="optimal") for ok in (True, False)]
    assert plots.plot_success(pd.DataFrame(rows), tmp_path / "s.png")
    # rows sorted by label: "s" (strict: 1 of 2 verified), "w (non-strict: level 0)" (3 of 4 meet level 0)
    np.testing.assert_allclose(seen["data"].ravel(), [50.0, 75.0], rtol=0, atol=1e-12)


def test_a_user_class_with_a_claim_that_is_not_a_bool_is_refused(tmp_path, capsys):
    (tmp_path / "mine.py").write_text(
        "from hikbench.solvers.base import Solver\n"
        "class Mine(Solver):\n    name = 'mine'\n    strict = 'no'\n"
        "    def solve(self, h):\n        raise NotImplementedError\n")
    suite = tmp_path / "s.toml"
    suite.write_text(tomli_w.dumps({"repeat": 1, "modes": ["cold"], "solvers": [f"{tmp_path / 'mine.py'}:Mine"],
                                    "problems": [{"family": "equality", "seeds": [0]}]}))
    code, _, err = run(capsys, "run", "--quiet", "--suite", suite, "--out", tmp_path / "out")
    assert_user_error(code, err, f"suite {suite}", "strict = 'no'", "expected True or False")
