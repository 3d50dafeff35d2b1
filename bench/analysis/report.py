"""``hikbench report RUN``: RUN/report.md, RUN/report.json and RUN/plots/*.png.

report.md opens with a table of contents, the run's one-line summary
(bench/harness/summary.py) and the ranking (bench/analysis/ranking.py: one
problem set per mode, success first, then time relative to the fastest, with
failures charged 10 x the slowest success on their problem, never the job
timeout); then each solver on its own problems, the tail latency per solver
(bench/analysis/tail.py), the non-strict solvers with
their per-level gap to the yardstick, the details, the runs of the suite's
``[[scenarios]]`` (bench/analysis/scenarios.py), the figures, and the
environment last. report.json holds the same numbers (docs/reports.md).

report.md is diff-friendly: every table has a one-line title before it, rows
are sorted, numbers have fixed formats.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from hikbench.bench.analysis import plots
from hikbench.bench.analysis.plots import solver_label
from hikbench.bench.analysis.scenarios import scenario_rows, scenario_section
from hikbench.bench.analysis.ranking import Ranking, non_strict, own_problems, rank, rank_supported, strict_labels, success_by
from hikbench.bench.analysis.shgeom import FAILURE_FACTOR, SHIFT_S, shifted_geometric_mean, timed
from hikbench.bench.analysis.tail import tail_table
from hikbench.bench.harness.environment import read_run_json
from hikbench.bench.harness.results import read_results
from hikbench.bench.harness.summary import run_summary, summary_line
from hikbench.bench.scenarios.rows import read_scenario_rows
from hikbench.bench.testset.sequences import sequence_rows, sequence_section
from hikbench.problems.errors import HikbenchError
from hikbench.problems.verify import PROFILES

__all__ = ["MIN_PROFILE_PROBLEMS", "REPORT_JSON", "solver_label", "write_report"]

REPORT_JSON = "report.json"
#: a performance profile over fewer problems is not drawn (its steps are a handful of ties)
MIN_PROFILE_PROBLEMS = 5
#: the suite whose runs carry the paper's claims section
CLAIMS_SUITE = "paper"


def _profile_groups(d: pd.DataFrame) -> list[tuple[str, str, pd.DataFrame]]:
    """The rows of one mode split for performance profiles: a profile compares
    solvers on one set of problems, and a solver that does not support a problem
    (status ``unsupported``, e.g. an equality-only method on a problem with
    inequalities) has not failed it. Problems are grouped by the solvers that
    support them; each group gets (title words, file suffix, its supported rows).
    One group (every solver supports every problem): no words, no suffix."""
    sup = d[d["status"] != "unsupported"]
    if sup.empty:
        return []
    key = sup.groupby("problem")["label"].agg(lambda s: tuple(sorted(set(s))))
    groups = sorted(key.groupby(key), key=lambda kv: (-len(kv[0]), kv[0]))
    if len(groups) == 1:
        return [("", "", sup)]
    ineq = sup.groupby("problem")["ineq_rows"].max().fillna(0) > 0
    every = set(d["label"])
    out, used = [], {}
    for labels, probs in groups:
        kinds = set(ineq[probs.index])
        kind, slug = (("with inequalities", "_ineq") if kinds == {True} else
                      ("equality-only", "_eq") if kinds == {False} else ("", "_mixed"))
        used[slug] = used.get(slug, 0) + 1
        if used[slug] > 1:
            slug = f"{slug}{used[slug]}"
        mine = d[d["problem"].isin(probs.index)]
        declined = sorted(set(mine.loc[mine["status"] == "unsupported", "label"]) - set(labels))
        not_run = sorted(every - set(labels) - set(declined))  # (a partial run: no row of these problems)
        what = (f", {len(probs)} problem{'s' * (len(probs) != 1)}{' ' + kind if kind else ''} "
                f"({len(labels)} solver{'s' * (len(labels) != 1)}"
                f"{'; unsupported by ' + ', '.join(declined) if declined else ''}"
                f"{'; not run by ' + ', '.join(not_run) if not_run else ''})")
        out.append((what, slug, sup[sup["problem"].isin(probs.index)]))
    return out


def _table(title: str, header: list[str], rows: list[list]) -> list[str]:
    out = [f"### {title}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return out + [""]


def _us(t: float | None) -> str:
    """A time in s as us with one decimal; '-' for none."""
    return "-" if t is None or not np.isfinite(t) else f"{t * 1e6:.1f}"


def _cut(text: str, size: int) -> str:
    """text, or its first ``size`` characters and " ..." when longer."""
    return text if len(text) <= size else text[:size] + " ..."


def _num(v: float) -> str:
    return f"{v:.2f}" if np.isfinite(v) else "-"


def _rows_note(rows: int, suite_rows) -> str:
    """``rows``, and of how many the suite has when run.json knows it (older runs do not)."""
    if not isinstance(suite_rows, int):
        return str(rows)
    if rows >= suite_rows:
        return f"{rows} (the whole suite)"
    return (f"{rows} of the suite's {suite_rows} (`hikbench run` with the same suite and --out runs the "
            f"other {suite_rows - rows})")


def _speed_cell(t: float, verified: float, seeds: float, declined: bool) -> str:
    """A cell of the speed table: the median time, with (k/m) when only k of
    the m seeds that ran were verified; ``unsupported`` when the solver
    declined the problem, ``not run`` when it has no row of it (a partial
    run), ``-`` when none of its rows is verified."""
    if not seeds > 0:  # (NaN: no row that ran)
        return "unsupported" if declined else "not run"
    if not verified > 0:
        return "-"
    return _us(t) + (f" ({int(verified)}/{int(seeds)})" if verified < seeds else "")


TIME_COLUMNS = ("time_median_s", "time_p90_s", "time_p99_s", "time_max_s", "time_min_s")
#: file name prefixes of the figures write_report draws in RUN/plots/
REPORT_FIGURES = ("time_vs_", "success_rate", "performance_profile_", "accuracy_per_level", "cold_vs_warm")


def normalise_hosts(df: pd.DataFrame) -> tuple[pd.DataFrame, str]:
    """With rows from several hosts (Dask), scale each host's times by
    calib(reference host) / calib(host), the reference host being the one
    with most rows, so that the aggregates and plots compare like with like."""
    hosts = df["host"].fillna("?").astype(str)
    cal = df.assign(_h=hosts).groupby("_h")["calib_ns"].median()
    if len(cal) <= 1 or cal.isna().any():
        why = "one host" if len(cal) <= 1 else "calibration missing on a host"
        return df, f"as measured ({why})"
    ref = hosts.value_counts().index[0]
    factor = hosts.map(lambda h: cal[ref] / cal[h]).astype(float)
    df = df.copy()
    for c in TIME_COLUMNS:
        df[c] = df[c] * factor
    return df, f"normalised to host {ref} by the calibration kernel ({len(cal)} hosts)"



class _Doc:
    """report.md's lines as they are written, and every table again for report.json."""

    def __init__(self):
        self.lines: list[str] = []
        self.tables: list[dict] = []

    def section(self, title: str) -> None:
        self.lines += [f"## {title}", ""]

    def text(self, *lines: str) -> None:
        self.lines += [*lines, ""]

    def table(self, key: str, title: str, header: list[str], rows: list[list]) -> None:
        rows = [[str(c) for c in r] for r in rows]
        self.lines += _table(title, header, rows)
        self.tables.append({"key": key, "title": title, "columns": header, "rows": rows})


#: report.md's sections, in order: (title, what decides whether it is written)
SECTIONS = ("Ranking", "Each solver on its own problems", "Tail latency", "Non-strict solvers", "Success per family",
            "Speed per problem", "Scenarios", "Sequences", "Statuses and unverified rows", "Claims of the paper", "Figures", "Environment")


def _anchor(title: str) -> str:
    """GitHub's anchor of a ``##`` heading."""
    return "".join(c for c in title.lower().replace(" ", "-") if c.isalnum() or c == "-")


def _contents(titles: list[str]) -> str:
    return "Contents: " + " · ".join(f"[{t}](#{_anchor(t)})" for t in titles)


def _ranking_table(doc: _Doc, key: str, title: str, r: Ranking, accuracy: str) -> None:
    """One ranking table: success at each accuracy profile side by side (the headline's orders
    the table), time vs fastest, fastest on, failures charged, median time of its successes."""
    P, solved = len(r.problems), len(r.problems) - len(r.unsolved)
    have = r.rows[0].get("success_at", {}) if r.rows else {}
    profiles = [p for p in PROFILES if p in have or p == accuracy]

    def success(row: dict, p: str) -> int:
        return row["success"] if p == accuracy else row["success_at"][p]  # (the headline: column verified)

    doc.table(key, title, ["rank", "solver", *[f"success {p}" for p in profiles],
                           "time vs fastest (1.00 = fastest)", "fastest on", "failures charged",
                           "median time of its successes [us]"],
              [[i + 1, row["solver"], *[f"{success(row, p) / P:.0%} ({success(row, p)}/{P})" for p in profiles],
                _num(row["relative_time"]), f"{row['fastest_on']}/{solved}", row["charged"],
                _us(row["median_time_s"])] for i, row in enumerate(r.rows)])


def _ranking_section(doc: _Doc, rankings: dict[str, Ranking | None], has_non_strict: bool,
                     uncertified: frozenset = frozenset(), accuracy: str = "default",
                     supported: dict | None = None) -> None:
    """The headline tables, one per mode, with the solvers listed apart and, for those, the
    rankings on the problems they support; ``uncertified``: the problems whose yardstick is not
    certified (their rows are never verified); ``accuracy``: the headline profile."""
    doc.section("Ranking")
    doc.text(f"Strict solvers over the problems every one of them attempted, one table per mode. Success "
             f"first, at each accuracy profile side by side (the share of the problems where no level of x is "
             f"above the certified optimum beyond rtol times the level's own terms: "
             + ", ".join(f"{p} {_e(prof.rtol)}" for p, prof in PROFILES.items())
             + f"; docs/verification.md); the table is ordered by the headline profile, {accuracy} (column "
             f"`verified`, `hikbench run --accuracy`), then by the shifted geometric mean (shift "
             f"{SHIFT_S * 1e6:g} us) of each solver's time over the fastest's on each problem, divided by the "
             f"lowest: 1.00 = the fastest. A failure (at the headline profile) is charged {FAILURE_FACTOR:g} x "
             f"the slowest success on its problem; a problem no solver succeeded on is left out of the time and "
             f"counted. A solver that declined some of the problems is listed apart and ranked, below, on the "
             f"problems it supports"
             + ("; non-strict solvers are judged by their own claim (below)." if has_non_strict else "."))
    for p, prof in PROFILES.items():
        doc.lines.append(f"- `{p}` (rtol {_e(prof.rtol)}): {prof.accepts}.")
    doc.lines.append("")
    for mode, r in rankings.items():
        if r is None:
            continue
        P, solved = len(r.problems), len(r.problems) - len(r.unsolved)
        _ranking_table(doc, f"ranking_{mode}", f"Ranking, {mode}: {len(r.rows)} solvers over the same {P} problems "
                       f"(time over the {solved} solved by at least one)", r, accuracy)
        notes = []
        unjudged = [p for p in r.unsolved if p in uncertified]
        unsolved = [p for p in r.unsolved if p not in uncertified]
        if unjudged:
            notes.append(f"{len(unjudged)} of the {P} problems have no certified yardstick, so no row of them is "
                         f"verified (left out of the time; column `yardstick_reason` says why): "
                         f"{', '.join(unjudged[:5])}{' ...' if len(unjudged) > 5 else ''}.")
        if unsolved:
            notes.append(f"No solver of the ranking solved {len(unsolved)} of the {P} problems (left out of "
                         f"the time): {', '.join(unsolved[:5])}{' ...' if len(unsolved) > 5 else ''}.")
        if r.apart:
            notes.append(f"Not ranked in {mode} over these problems (declined some): " + "; ".join(
                f"{lab} declined {a['declined']} of its {a['of']}" for lab, a in r.apart.items())
                + ": ranked below on the problems it supports.")
        if notes:
            doc.text(*notes)
        for labs, sr in (supported or {}).get(mode, []):
            Ps, solved = len(sr.problems), len(sr.problems) - len(sr.unsolved)
            _ranking_table(doc, f"ranking_{mode}_supported_{'_'.join(labs)}",
                           f"Ranking, {mode}, on the {Ps} problems {', '.join(labs)} "
                           f"support{'s' * (len(labs) == 1)}: {len(sr.rows)} solvers (time over the {solved} "
                           f"solved by at least one)", sr, accuracy)
            if sr.apart:
                doc.text(f"Not ranked over these problems (declined some): " + "; ".join(
                    f"{lab} declined {a['declined']} of its {a['of']}" for lab, a in sr.apart.items()) + ".")


def _e(v: float) -> str:
    """1e-09 as 1e-9."""
    return f"{v:.0e}".replace("e-0", "e-")


def _uncertified_problems(df: pd.DataFrame) -> frozenset:
    """Problems whose yardstick is there but not certified (column ``yardstick``)."""
    if "yardstick" not in df:
        return frozenset()
    return frozenset(df.loc[df["yardstick"].isin(["reference-only", "none"]), "problem"])


def _own_section(doc: _Doc, own: dict[str, list[dict]]) -> None:
    doc.section("Each solver on its own problems")
    doc.table("own_problems", "Each strict solver on the problems it attempted alone (each row over its own "
              "problems: NOT a ranking, rows do not compare; times of verified rows only)",
              ["solver", "mode", "attempted", "declined", "success", "sgm of its verified times [us]",
               "median [us]"],
              [[o["solver"], mode, o["attempted"], o["declined"],
                f"{_percent_of(o['success'], o['attempted'])} ({o['success']}/{o['attempted']})",
                _us(o["sgm_time_s"]), _us(o["median_time_s"])]
               for mode, rows in own.items() for o in rows])


def _tail_section(doc: _Doc, tail: dict[str, list[dict]]) -> None:
    doc.section("Tail latency")
    doc.text("A controller waits for its slowest solve, not its typical one. Each row's p50, p90, p99 and max "
             "are over its timed repetitions (`repeat`: a suite that sets no count times a solve under 1 ms "
             "100 times, docs/running.md); below, per solver, the median of each over its rows (the verified "
             "rows of a strict solver, every timed row of a non-strict one), the median over rows of p99 / "
             "p50, and the slowest single solve of all its rows."
             + (" With fewer than 100 samples per row, p99 lies between a row's slowest solves." if any(
                 t["samples_per_row"] < 100 for rows in tail.values() for t in rows) else ""))
    doc.table("tail", "Tail latency per solver (medians over each solver's own rows: NOT a ranking)",
              ["solver", "mode", "rows", "samples per row", "p50 [us]", "p90 [us]", "p99 [us]", "max [us]",
               "p99 / p50", "slowest solve [us] (problem)"],
              [[t["solver"], mode, t["rows"], f"{t['samples_per_row']:g}", _us(t["p50_s"]), _us(t["p90_s"]),
                _us(t["p99_s"]), _us(t["max_s"]), _num(t["p99_over_p50"]),
                f"{_us(t['worst_s'])} ({t['worst_problem']})"] for mode, rows in tail.items() for t in rows])


def _percent_of(k: int, n: int) -> str:
    return f"{100 * k / n:.0f}%" if n else "-"


def _gaps(g: dict, shown: int = 8) -> str:
    """'L0 +0, L1 +1.2e-03, ...': the median gap per level, the first ``shown`` levels."""
    cells = [f"L{k} {v:+.2g}" for k, v in enumerate(g["median_gap_per_level"][:shown])]
    return ", ".join(cells) + (" ..." if len(g["median_gap_per_level"]) > shown else "") if cells else "-"


def _non_strict_section(doc: _Doc, ns: dict[str, list[dict]]) -> None:
    doc.section("Non-strict solvers")
    doc.text("Solvers that do not claim the lexicographic optimum (`strict` False: weighted, damped, "
             "pseudo-inverse...) are not ranked against it. Their time is their real median time over every "
             "row that has one, verified or not; the gap of level k is ||v_k(x)|| - ||v_k(x_ref)|| (how much "
             "the level loses against the yardstick; < 0: it gains, as a lower level paid for it), its median "
             "over the rows that reach level k; the first level lost is the level most of its rows first lose "
             "at (the verdict's level); level 0 met: the rows whose level 0, the highest priority, is as low "
             "as the yardstick's within the suite's accuracy, of those with a yardstick (their success in the "
             "per-family table and figure).")
    doc.table("non_strict", "Non-strict solvers: real times and per-level gap to the yardstick",
              ["solver", "mode", "attempted", "median time [us]", "rows timed", "meets the yardstick",
               "level 0 met", "first level lost (rows)", "median gap per level"],
              [[g["solver"], mode, g["attempted"], _us(g["median_time_s"]), g["timed"],
                f"{g['meets_yardstick']}/{g['attempted']}", f"{g['level0_met']}/{g['level0_judged']}",
                f"L{g['first_level_lost']['level']} ({g['first_level_lost']['rows']})" if g["first_level_lost"]
                else "none", _gaps(g)] for mode, rows in ns.items() for g in rows])


def _family_section(doc: _Doc, df: pd.DataFrame, strict: set[str]) -> None:
    """Success per solver and family (and per bound_scale when the run has several),
    each solver judged by its own claim (hikbench.bench.analysis.ranking.success_by, the
    numbers success_rate.png draws)."""
    doc.section("Success per family")
    labels = sorted(df["label"].unique())
    shown = {i: i if i in strict else f"{i} (non-strict: level 0)" for i in labels}
    rates, _ = success_by(df, strict, "family")
    left = _uncertified_problems(df)
    out = f"; rows of the {len(left)} problem{'s' * (len(left) != 1)} without a certified yardstick left out" if left else ""
    doc.table("success_per_family", "Success rate per solver and family, by each solver's claim (strict: "
              "verified; non-strict: level 0 met as the yardstick does; unsupported rows left out" + out +
              "; - = no row judged: the solver declined every problem of the family, or none has a certified "
              "yardstick)", ["solver", *rates.columns],
              [[shown[i], *[_rate(rates.at[i, f]) if i in rates.index else "-" for f in rates.columns]]
               for i in labels])
    # the units suite: the same problems with every bound times bound_scale (a family parameter)
    scales = df["params"].map(lambda p: float(json.loads(p or "{}").get("bound_scale", 1.0)))
    if scales[df["status"] != "unsupported"].ne(1.0).any():
        rates, _ = success_by(df, strict, scales)
        cols = sorted(rates.columns, reverse=True)
        doc.table("success_per_bound_scale", "Success rate per solver and bound_scale, by each solver's claim "
                  "(every bound times it: the same problems in other units of x; unsupported rows left out)",
                  ["solver", *[f"x {c:g}" for c in cols]],
                  [[shown[i], *[_rate(rates.at[i, c]) if i in rates.index else "-" for c in cols]] for i in labels])


def _rate(v: float) -> str:
    """A rate in [0, 1] as a percentage, '-' for NaN (no row judged)."""
    return f"{100 * v:.0f}%" if np.isfinite(v) else "-"


def _speed_section(doc: _Doc, df: pd.DataFrame) -> None:
    """The median time of every problem over its seeds, per mode."""
    doc.section("Speed per problem")
    for mode in ("cold", "warm"):
        in_mode = df[df["mode"] == mode]
        unsup = in_mode[in_mode["status"] == "unsupported"]
        declined = set(zip(unsup["problem"].str.replace(r"/seed=\d+$", "", regex=True), unsup["label"]))
        ran = in_mode[in_mode["status"] != "unsupported"]
        if ran.empty:
            continue
        # every solver and problem that ran in this mode has its cell (groupby keeps a group
        # whose times are all NaN, unstack fills the grid, both sorted): a solver without a
        # verified row shows "-" rather than dropping out of the table
        ran = ran.assign(group=ran["problem"].str.replace(r"/seed=\d+$", "", regex=True),
                         t=ran["time_median_s"].where(timed(ran, zero_ok=True)))
        by = ran.groupby(["group", "label"])["t"]
        groups = sorted({g for g, _ in declined} | set(ran["group"]))
        labels = sorted(in_mode["label"].unique())  # (a problem or solver that only declined keeps its cell)
        med, verified, seeds = (x.unstack("label").reindex(index=groups, columns=labels)
                                for x in (by.median(), by.count(), by.size()))
        doc.table(f"speed_{mode}", f"Median {mode} time per problem over its seeds [us] (verified rows; the speed "
                  "table; (k/m) = over the k of its m seeds verified; - = no verified row; "
                  "unsupported = declined; not run = no row in this run)", ["problem", *med.columns],
                  [[g, *[_speed_cell(med.at[g, c], verified.at[g, c], seeds.at[g, c], (g, c) in declined)
                         for c in med.columns]] for g in med.index])


def _status_section(doc: _Doc, df: pd.DataFrame) -> None:
    doc.section("Statuses and unverified rows")
    st = df.pivot_table(index="label", columns="status", values="problem", aggfunc="count", fill_value=0)
    doc.table("statuses", "Statuses per solver", ["solver", *st.columns],
              [[i, *st.loc[i].tolist()] for i in st.index])
    _yardstick_table(doc, df)
    unverified = df[~df["verified"].eq(True)]
    strict = unverified["strict"].astype(str).eq("True") & (unverified["status"] != "unsupported")
    bad = unverified[strict].sort_values(["label", "problem", "mode"])
    doc.table("unverified", f"Unverified rows of strict solvers ({len(bad)}, first 40; not listed: "
              f"{int((~strict).sum())} unsupported or non-strict rows)",
              ["solver", "problem", "mode", "status", "verdict", "reason"],
              [[r.label, r.problem, r.mode, r.status,
                f"{r.verdict_side} at level {int(r.verdict_level)}" if pd.notna(r.verdict_level) else
                (r.verdict_side if isinstance(r.verdict_side, str) else ""),
                _cut(str(r.reason), 240).replace("|", "/")] for r in bad.head(40).itertuples()])


def _yardstick_table(doc: _Doc, df: pd.DataFrame) -> None:
    """Problems and rows by the kind of their yardstick, and the problems whose yardstick is not
    certified with the reason (rows are verified only against a certified yardstick)."""
    from hikbench.bench.harness.summary import yardstick_counts

    counts = yardstick_counts(df)
    if not counts:
        return
    doc.table("yardstick", "Problems and rows by yardstick (a row is verified only against a certified one; "
              "docs/verification.md)", ["yardstick", "problems", "rows"],
              [[k, c["problems"], c["rows"]] for k, c in counts.items()])
    uncertified = df[~df["yardstick"].eq("certified")].drop_duplicates("problem")
    if len(uncertified):
        doc.table("yardstick_uncertified", f"Problems without a certified yardstick ({len(uncertified)}, first 20)",
                  ["problem", "yardstick", "why"],
                  [[r.problem, r.yardstick if isinstance(r.yardstick, str) else "none",
                    _cut(str(r.yardstick_reason) if isinstance(r.yardstick_reason, str) else "", 240).replace("|", "/")]
                   for r in uncertified.head(20).itertuples()])


def _claims_section(doc: _Doc, run_dir: Path) -> list[dict]:
    from hikbench.bench.analysis.claims import check_claims

    doc.section("Claims of the paper")
    claims = check_claims(run_dir)
    doc.table("claims", "Claims of the ICRA 2010 paper (hikbench claims; MISSING = no data; (d)-(e) name the "
              "reach scenario CSVs they read)", ["claim", "result", "measured", "paper"],
              [[c.name, c.status, c.measured, c.paper] for c in claims])
    return [{"claim": c.name, "result": c.status, "measured": c.measured, "paper": c.paper} for c in claims]


def _draw_figures(df: pd.DataFrame, plot_dir: Path, doc: _Doc, uncertified: frozenset = frozenset()) -> list[dict]:
    """Every figure of the report, drawn in ``plot_dir``; the slope tables go to
    ``doc``. The success figure and the profiles leave out the ``uncertified``
    problems (no row of theirs can be verified). Returns [{title, path (None: not
    drawn), why}]."""
    figures = []
    judged = df[~df["problem"].isin(uncertified)]
    styles = plots.solver_styles(df)  # (a solver's colour, marker and line style: the same in every figure)
    for var, what in (("n", "DOF"), ("depth", "depth")):
        for i, (family, fixed, g) in enumerate(plots.sweeps(df, var)):
            name = f"time_vs_{'dof' if var == 'n' else 'depth'}_{family}_{i}.png".replace(":", "_")
            fx = json.loads(fixed)
            sat = None
            if var == "depth" and {"n", "rows"} <= set(fx):
                sat = (fx["n"] / fx["rows"], f"DOF saturated (depth = n / rows = {fx['n'] / fx['rows']:g})")
            p, slopes = plots.plot_sweep(g, var, plot_dir / name,
                                         f"{family}: time vs {what} ({fixed.strip('{}') or 'defaults'}), cold",
                                         vline=sat, styles=styles)
            if p:
                figures.append({"title": f"Time vs {what}: {family} {fixed}", "path": p})
                span = "" if sat is None else f"; every depth, those below saturation ({sat[0]:g}) included"
                doc.table(f"slope_{var}_{family}_{i}", f"Log-log slope of cold time vs {what}: {family} {fixed} "
                          f"(verified rows{span}; - = fewer than 3 verified sizes)",
                          ["solver", "slope", "std. err.", "sizes verified / attempted"],
                          [[s, _num(a), _num(b), f"{k}/{m}"] for s, (a, b, k, m) in sorted(slopes.items())])
    p = plots.plot_success(df, plot_dir / "success_rate.png")  # (success_by leaves the uncertified rows out)
    left_out = (f" ({len(uncertified)} problem{'s' * (len(uncertified) != 1)} without a certified yardstick "
                f"left out)") if uncertified else ""
    if p:
        figures.append({"title": f"Success rate by each solver's claim{left_out}", "path": p})
    for mode in ("cold", "warm"):
        for what, slug, g in _profile_groups(judged[judged["mode"] == mode]):
            title = f"Performance profile, {mode}{what}"
            n = g["problem"].nunique()
            if n < MIN_PROFILE_PROBLEMS:
                figures.append({"title": title, "path": None,
                                "why": f"not drawn: {n} problem{'s' * (n != 1)}, fewer than {MIN_PROFILE_PROBLEMS}"})
                continue
            t = g.assign(t=g["time_median_s"].where(timed(g))).pivot_table(
                index="problem", columns="label", values="t", aggfunc="first", dropna=False)
            if t.shape[1] < 2:  # (a profile of one solver is a flat line at 1: it compares nothing)
                figures.append({"title": title, "path": None,
                                "why": "one solver, no profile drawn (it would be a flat line at 1)"})
                continue
            p = plots.plot_profiles(t, plot_dir / f"performance_profile_{mode}{slug}.png",
                                    f"Performance profiles (Dolan-More), {mode} solves; failures never reach 1"
                                    + (f"\n{what[2:]}" if what else ""), styles=styles)
            if p:
                figures.append({"title": title + left_out, "path": p})
    for name, draw, title in (("accuracy_per_level.png", plots.plot_accuracy, "Per-level accuracy"),
                              ("cold_vs_warm.png", plots.plot_cold_warm, "Cold vs warm")):
        p = draw(df, plot_dir / name, styles=styles)
        if p:
            figures.append({"title": title, "path": p})
    return figures


def _figures_section(doc: _Doc, figures: list[dict], run_dir: Path) -> None:
    doc.section("Figures")
    doc.text("One colour and marker per solver in every figure; solid lines: strict solvers, dashed: non-strict.")
    for f in figures:
        if f["path"] is None:
            doc.text(f"{f['title']}: {f['why']}.")
        else:
            doc.text(f"{f['title']}:", "", f"![{f['title']}]({f['path'].relative_to(run_dir)})")


def _calibration_ms(df: pd.DataFrame) -> dict[str, float | None]:
    """host -> the median over its rows of the calibration kernel time its workers measured, ms."""
    cal = df.groupby(df["host"].fillna("?").astype(str))["calib_ns"].median()
    return {h: (float(v) / 1e6 if np.isfinite(v) else None) for h, v in cal.items()}


def _environment_section(doc: _Doc, df: pd.DataFrame, meta: dict, norm_note: str) -> None:
    """Run facts, the calibration (one figure per host), hosts, package versions, skipped solvers."""
    env, suite = meta.get("environment", {}), meta.get("suite", {})
    doc.section("Environment")
    doc.table("run", "Run", ["field", "value"], [
        ["suite", f"{suite.get('name')} ({suite.get('source', '')})"],
        ["created", meta.get("created", "")],
        ["git commit", f"{env.get('git', {}).get('commit')} (dirty: {env.get('git', {}).get('dirty')})"],
        ["CPU", f"{env.get('cpu')} ({env.get('cpu_count')} logical cores)"],
        ["BLAS", "; ".join(f"{t.get('internal_api')} {t.get('version')} ({t.get('num_threads')} threads)"
                           for t in env.get("blas", {}).get("threadpools", [])) + "; solves timed at 1 thread"],
        ["accuracy", json.dumps(meta.get("accuracy", {}))],
        ["rows", _rows_note(len(df), meta.get("suite_rows"))],
        ["times", norm_note],
    ])
    cal = _calibration_ms(df)
    rows = df.groupby(df["host"].fillna("?").astype(str)).size()
    doc.table("calibration", "Calibration kernel per host (the median over the host's rows of the kernel time "
              f"its worker processes measured, {meta.get('calibration_kernel', 'see bench/harness/calibration.py')}; "
              "the figure `hikbench compare` divides times by)",
              ["host", "rows", "calibration [ms]"],
              [[h, int(rows[h]), f"{v:.3f}" if v is not None else "-"] for h, v in cal.items()])
    skipped = meta.get("skipped_solvers", {})
    if skipped:
        doc.table("skipped", "Solvers skipped (not installed)", ["solver", "why"],
                  [[k, v] for k, v in sorted(skipped.items())])
    doc.table("versions", "Package versions", ["package", "version"],
              [[k, v if v else "not installed"] for k, v in sorted(env.get("versions", {}).items())])


def _clear_old_figures(plot_dir: Path) -> None:
    """Remove the figures of an earlier report (a partial run's, say); other PNGs stay."""
    for old in plot_dir.glob("*.png"):
        if old.name.startswith(REPORT_FIGURES):
            old.unlink()


def write_report(run_dir) -> Path:
    """Write RUN/report.md, RUN/report.json and RUN/plots/; the path of report.md."""
    run_dir = Path(run_dir)
    df = read_results(run_dir)
    if df.empty:
        raise HikbenchError(f"{run_dir / 'results.csv'} has no rows; expected the rows of a `hikbench run` "
                            f"(nothing to report)")
    meta = read_run_json(run_dir)
    plot_dir = run_dir / "plots"
    plot_dir.mkdir(exist_ok=True)
    _clear_old_figures(plot_dir)
    summary = run_summary(df, meta, read_scenario_rows(run_dir))  # (the numbers of summary.json)
    df = df.assign(label=solver_label(df))
    df, norm_note = normalise_hosts(df)
    strict = strict_labels(df)
    modes = [m for m in ("cold", "warm") if (df["mode"] == m).any()]
    rankings = {m: rank(df[df["mode"] == m], strict, m) for m in modes}
    supported = {m: rank_supported(df[df["mode"] == m], strict, m, rankings[m]) for m in modes}
    accuracy = (meta.get("accuracy") or {}).get("profile", "default")
    own = {m: own_problems(df[df["mode"] == m], strict) for m in modes}
    ns = {m: non_strict(df[df["mode"] == m], strict) for m in modes}
    tail = {m: tail_table(df[df["mode"] == m], strict) for m in modes}
    has_ns = any(ns.values())
    with_claims = (meta.get("suite") or {}).get("name") == CLAIMS_SUITE

    doc = _Doc()
    slopes = _Doc()  # (the slope tables come with the figures, and are printed after the speed tables)
    figures = _draw_figures(df, plot_dir, slopes, _uncertified_problems(df))
    has_scenarios = bool(scenario_rows(run_dir))
    has_sequences = bool(sequence_rows(run_dir))
    titles = [t for t in SECTIONS if (t != "Non-strict solvers" or has_ns) and (t != "Claims of the paper"
                                                                                  or with_claims)
              and (t != "Scenarios" or has_scenarios) and (t != "Sequences" or has_sequences)]
    doc.lines += [f"# hikbench report: suite {summary['suite'] or '?'}", ""]
    if isinstance(meta.get("suite_rows"), int) and len(df) < meta["suite_rows"]:
        doc.text(f"**Incomplete run: {_rows_note(len(df), meta['suite_rows'])}.** Every table and figure below "
                 f"covers the rows run so far only.")
    doc.text(_contents(titles))
    doc.text(f"**Summary:** {summary_line(summary)}")
    _ranking_section(doc, rankings, has_ns, _uncertified_problems(df), accuracy, supported)
    _own_section(doc, own)
    _tail_section(doc, tail)
    if has_ns:
        _non_strict_section(doc, ns)
    _family_section(doc, df, strict)
    _speed_section(doc, df)
    doc.lines += slopes.lines
    doc.tables += slopes.tables
    scenarios = scenario_section(doc, run_dir, meta)
    sequences = sequence_section(doc, run_dir)
    _status_section(doc, df)
    claims = _claims_section(doc, run_dir) if with_claims else None
    _figures_section(doc, figures, run_dir)
    _environment_section(doc, df, meta, norm_note)
    out = run_dir / "report.md"
    out.write_text("\n".join(doc.lines).rstrip() + "\n")
    _write_json(run_dir, summary, rankings, own, ns, claims, figures, _calibration_ms(df), doc, meta, tail,
                scenarios, sequences, supported)
    return out


def _write_json(run_dir: Path, summary, rankings, own, ns, claims, figures, calibration, doc: _Doc,
                meta: dict, tail: dict, scenarios: list[dict], sequences: list[dict] = (),
                supported: dict | None = None) -> Path:
    """RUN/report.json: the numbers of report.md (docs/reports.md, "report.json")."""
    data = {
        "summary": summary,
        "rule": {"shift_s": SHIFT_S, "failure_factor": FAILURE_FACTOR,
                 "min_profile_problems": MIN_PROFILE_PROBLEMS},
        "ranking": {m: None if r is None else {
            "problems": len(r.problems), "problem_ids": r.problems, "unsolved": r.unsolved,
            "solvers": r.rows, "not_ranked": r.apart,
            "supported": [{"for": labs, "problems": len(sr.problems), "problem_ids": sr.problems,
                           "unsolved": sr.unsolved, "solvers": sr.rows, "not_ranked": sr.apart}
                          for labs, sr in (supported or {}).get(m, [])]} for m, r in rankings.items()},
        "accuracy": meta.get("accuracy", {}),
        "own_problems": own,
        "tail": tail,
        "non_strict": ns,
        "claims": claims,
        "scenarios": scenarios,
        "sequences": list(sequences),
        "figures": [{"title": f["title"], "path": None if f["path"] is None else str(f["path"].relative_to(run_dir)),
                     "why": f.get("why")} for f in figures],
        "calibration_ms": calibration,
        "tables": doc.tables,
        "environment": meta.get("environment", {}),
    }
    path = run_dir / REPORT_JSON
    path.write_text(json.dumps(data, indent=1, default=_json_default) + "\n")
    return path


def _json_default(v):
    """numpy scalars as Python numbers (json cannot write them)."""
    if isinstance(v, np.generic):
        return v.item()
    raise TypeError(f"report.json: cannot write {type(v).__name__} {v!r}")
