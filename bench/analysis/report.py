"""``hikbench report RUN``: RUN/report.md and RUN/plots/*.png.

report.md is diff-friendly: every table has a one-line title before it, rows
are sorted, numbers have fixed formats, and the environment (versions, CPU,
BLAS, git commit) is recorded. Runtime aggregates are shifted geometric means
(bench/analysis/shgeom.py) with failures charged at the job timeout.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from hikbench.bench.analysis import plots
from hikbench.bench.harness.environment import read_run_json
from hikbench.bench.analysis.plots import solver_label
from hikbench.bench.harness.results import read_results
from hikbench.bench.analysis.shgeom import SHIFT_S, charged_times, shifted_geometric_mean, timed
from hikbench.problems.errors import HikbenchError

__all__ = ["solver_label", "write_report"]


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


def _us(t: float) -> str:
    return "-" if not np.isfinite(t) else f"{t * 1e6:.1f}"


def _cut(text: str, size: int) -> str:
    """text, or its first ``size`` characters and " ..." when longer."""
    return text if len(text) <= size else text[:size] + " ..."


def _num(v: float) -> str:
    return f"{v:.2f}" if np.isfinite(v) else "-"


def _positive(v) -> float | None:
    """v as a finite float > 0, else None (a missing or bogus timeout in run.json)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v <= 0:
        return None
    return float(v)


def _recorded_timeout(meta: dict) -> float | None:
    """The largest job timeout of the run's sessions (the suite's when a session did not record
    one); None when run.json records none (missing, or bogus values): the charge is then 60 s."""
    suite_timeout = (meta.get("suite") or {}).get("timeout")
    vals = [_positive(s.get("timeout", suite_timeout)) for s in meta.get("sessions") or [{}]]
    vals = [v for v in vals if v is not None]
    return max(vals) if vals else None


def _aggregate(g: pd.DataFrame, penalty: float) -> float:
    """Shifted geometric mean of the charged times (a bogus time is charged like a failure)."""
    return shifted_geometric_mean(charged_times(g, penalty))


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


def _percent(ok: pd.Series) -> str:
    """Share of True in ``ok`` (a boolean Series), '-' for no rows."""
    return f"{100 * ok.mean():.0f}%" if len(ok) else "-"


TIME_COLUMNS = ("time_median_s", "time_min_s", "time_p95_s")
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


def write_report(run_dir) -> Path:
    run_dir = Path(run_dir)
    df = read_results(run_dir)
    if df.empty:
        raise HikbenchError(f"{run_dir / 'results.csv'} has no rows; expected the rows of a `hikbench run` "
                            f"(nothing to report)")
    meta = read_run_json(run_dir)
    env = meta.get("environment", {})
    plot_dir = run_dir / "plots"
    plot_dir.mkdir(exist_ok=True)
    for old in plot_dir.glob("*.png"):  # the figures of an earlier report (a partial run's, say) go
        if old.name.startswith(REPORT_FIGURES):
            old.unlink()
    df = df.assign(label=solver_label(df))
    df, norm_note = normalise_hosts(df)
    timeout = _recorded_timeout(meta)
    penalty = 60.0 if timeout is None else timeout  # (the charge of an unverified row)
    suite = meta.get("suite", {})
    L = [f"# hikbench report: suite {suite.get('name', '?')}", ""]
    if isinstance(meta.get("suite_rows"), int) and len(df) < meta["suite_rows"]:
        note = _rows_note(len(df), meta["suite_rows"])
        L += [f"**Incomplete run: {note}.** Every table and figure below covers the rows run so far only.", ""]
    L += _table("Run", ["field", "value"], [
        ["suite", f"{suite.get('name')} ({suite.get('source', '')})"],
        ["created", meta.get("created", "")],
        ["git commit", f"{env.get('git', {}).get('commit')} (dirty: {env.get('git', {}).get('dirty')})"],
        ["host(s)", ", ".join(sorted(df["host"].dropna().astype(str).unique()))],
        ["CPU", f"{env.get('cpu')} ({env.get('cpu_count')} logical cores)"],
        ["BLAS", "; ".join(f"{t.get('internal_api')} {t.get('version')} ({t.get('num_threads')} threads)"
                           for t in env.get("blas", {}).get("threadpools",
                                                            [])) + "; solves timed at 1 thread"],
        ["calibration kernel", (f"{meta.get('calibration_ns', float('nan')) / 1e6:.3f} ms "
                                f"({meta.get('calibration_kernel', '')}; timed in the main process at "
                                f"the start and end of each session, their median; the workers' own "
                                f"are under Hosts)")],
        ["accuracy", json.dumps(meta.get("accuracy", {}))],
        ["rows", _rows_note(len(df), meta.get("suite_rows"))],
        ["times", norm_note],
        ["runtime aggregate", (f"shifted geometric mean, shift {SHIFT_S * 1e6:g} us; "
                               f"unverified rows charged {penalty:g} s "
                               + ("(the job timeout)" if timeout is not None else
                                  "(no job timeout recorded: run.json missing or without one)"))],
    ])
    L += _table("Package versions", ["package", "version"],
                [[k, v if v else "not installed"] for k, v in sorted(env.get("versions", {}).items())])
    hosts = df.groupby(df["host"].fillna("?").astype(str)).agg(rows=("problem", "count"),
                                                                 calib=("calib_ns", "median"))
    L += _table("Hosts (calibration kernel time of their workers, the median over their rows; compare "
                "divides times by it)",
                ["host", "rows", "median calibration [ms]"],
                [[h, int(r.rows), f"{r.calib / 1e6:.3f}" if np.isfinite(r.calib) else "-"]
                 for h, r in hosts.iterrows()])
    skipped = meta.get("skipped_solvers", {})
    if skipped:
        L += _table("Solvers skipped (not installed)", ["solver", "why"], [[k, v] for k,
                                                                           v in sorted(skipped.items())])

    # per solver summary
    rows = []
    for label, g in sorted(df.groupby("label")):
        strict = "yes" if g["strict"].astype(str).eq("True").all() else "no"
        sup = g[g["status"] != "unsupported"]
        r = [label, strict, str(len(g)), str(len(g) - len(sup)), _percent(sup["verified"].eq(True))]
        for mode in ("cold", "warm"):
            gm = sup[sup["mode"] == mode]
            if len(gm) and not gm["verified"].eq(True).any():  # (the charge alone: not a time)
                r.append(f"none verified ({len(gm)} charged {penalty:g} s)")
            else:
                r.append(_us(_aggregate(gm, penalty)) if len(gm) else "-")
        rows.append(r)
    L += _table("Solvers: verified success and shifted geometric mean time (us; unverified rows charged, "
                "unsupported rows left out)",
                ["solver", "strict", "rows", "unsupported", "verified", "sgm cold [us]",
                 "sgm warm [us]"], rows)

    # success among the rows a solver supports: a family it declines entirely shows '-'
    supported = df[df["status"] != "unsupported"]
    labels, families = sorted(df["label"].unique()), sorted(df["family"].unique())
    by = {k: g["verified"].eq(True) for k, g in supported.groupby(["label", "family"])}
    L += _table("Verified success rate per solver and family (unsupported rows left out; "
                "- = the solver declined every problem of the family)", ["solver", *families],
                [[i, *[_percent(by.get((i, f), pd.Series(dtype=bool))) for f in families]] for i in labels])

    # the units suite: the same problems with every bound times bound_scale (a family parameter)
    scales = supported["params"].map(lambda p: float(json.loads(p or "{}").get("bound_scale", 1.0)))
    if scales.ne(1.0).any():
        cols = sorted(scales.unique(), reverse=True)
        by = {k: g["verified"].eq(True) for k, g in supported.assign(bs=scales).groupby(["label", "bs"])}
        L += _table("Verified success rate per solver and bound_scale (every bound times it: the same problems "
                    "in other units of x; unsupported rows left out)", ["solver", *[f"x {c:g}" for c in cols]],
                    [[i, *[_percent(by.get((i, c), pd.Series(dtype=bool))) for c in cols]] for i in labels])

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
        L += _table(f"Median {mode} time per problem over its seeds [us] (verified rows; the speed table; "
                    "(k/m) = over the k of its m seeds verified; - = no verified row; "
                    "unsupported = declined; not run = no row in this run)", ["problem", *med.columns],
                    [[g, *[_speed_cell(med.at[g, c], verified.at[g, c], seeds.at[g, c], (g, c) in declined)
                           for c in med.columns]] for g in med.index])

    st = df.pivot_table(index="label", columns="status", values="problem", aggfunc="count", fill_value=0)
    L += _table("Statuses per solver", ["solver", *st.columns], [[i, *st.loc[i].tolist()] for i in st.index])

    unverified = df[~df["verified"].eq(True)]
    strict = unverified["strict"].astype(str).eq("True") & (unverified["status"] != "unsupported")
    bad = unverified[strict].sort_values(["label", "problem", "mode"])
    L += _table(f"Unverified rows of strict solvers ({len(bad)}, first 40; not listed: {int((~strict).sum())} "
                "unsupported or non-strict rows)", ["solver", "problem", "mode", "status", "verdict",
                                                            "reason"],
                [[r.label, r.problem, r.mode, r.status,
                  f"{r.verdict_side} at level {int(r.verdict_level)}" if pd.notna(r.verdict_level) else
                  (r.verdict_side if isinstance(r.verdict_side, str) else ""),
                  _cut(str(r.reason), 240).replace("|", "/")] for r in bad.head(40).itertuples()])

    from hikbench.bench.analysis.claims import check_claims

    L += _table("Claims of the ICRA 2010 paper (hikbench claims; MISSING = no data; (d)-(e) name the reach "
                "scenario CSVs they read)",
                ["claim", "result", "measured", "paper"],
                [[c.name, c.status, c.measured, c.paper] for c in check_claims(run_dir)])

    figures = []
    order = sorted(df["label"].unique())  # (a solver's colour is the same in every figure)
    for var, what in (("n", "DOF"), ("depth", "depth")):
        for i, (family, fixed, g) in enumerate(plots.sweeps(df, var)):
            name = f"time_vs_{'dof' if var == 'n' else 'depth'}_{family}_{i}.png".replace(":", "_")
            fx = json.loads(fixed)
            sat = None
            if var == "depth" and {"n", "rows"} <= set(fx):
                sat = (fx["n"] / fx["rows"], f"DOF saturated (depth = n / rows = {fx['n'] / fx['rows']:g})")
            p, slopes = plots.plot_sweep(g, var, plot_dir / name,
                                         f"{family}: time vs {what} "
                                         f"({fixed.strip('{}') or 'defaults'}), cold", vline=sat, order=order)
            if p:
                figures.append((f"Time vs {what}: {family} {fixed}", p))
                span = "" if sat is None else f"; every depth, those below saturation ({sat[0]:g}) included"
                L += _table(f"Log-log slope of cold time vs {what}: {family} {fixed} (verified rows{span}; "
                            "- = fewer than 3 verified sizes)",
                            ["solver", "slope", "std. err.", "sizes verified / attempted"],
                            [[s, _num(a), _num(b), f"{k}/{m}"] for s, (a, b, k, m) in sorted(slopes.items())])
    p = plots.plot_success(df, plot_dir / "success_rate.png")
    if p:
        figures.append(("Verified success rate", p))
    for mode in ("cold", "warm"):
        d = df[df["mode"] == mode]
        for what, slug, g in _profile_groups(d):
            t = g.assign(t=g["time_median_s"].where(timed(g))).pivot_table(
                index="problem", columns="label", values="t", aggfunc="first", dropna=False)
            if t.shape[1] < 2:  # (a profile of one solver is a flat line at 1: it compares nothing)
                figures.append((f"Performance profile, {mode}{what}", None))
                continue
            p = plots.plot_profiles(t, plot_dir / f"performance_profile_{mode}{slug}.png",
                                    f"Performance profiles (Dolan-More), {mode} solves; failures never reach 1"
                                    + (f"\n{what[2:]}" if what else ""), order=order)
            if p:
                figures.append((f"Performance profile, {mode}{what}", p))
    p = plots.plot_accuracy(df, plot_dir / "accuracy_per_level.png", order=order)
    if p:
        figures.append(("Per-level accuracy", p))
    p = plots.plot_cold_warm(df, plot_dir / "cold_vs_warm.png", order=order)
    if p:
        figures.append(("Cold vs warm", p))
    L += ["### Figures", ""]
    for title, p in figures:
        if p is None:
            L += [f"{title}: one solver, no profile drawn (it would be a flat line at 1).", ""]
        else:
            L += [f"{title}:", "", f"![{title}]({p.relative_to(run_dir)})", ""]
    out = run_dir / "report.md"
    out.write_text("\n".join(L).rstrip() + "\n")
    return out
