"""``hikbench compare BASE RUN``: timing regressions and newly failing cases.

For every key (problem, solver, settings, mode) present in both runs, the
timing samples are divided by a calibration kernel time (bench/harness/calibration.py):
the row's own ``calib_ns`` when the suite timed the kernel around every job
(``calibrate_each_job``, the ``ci`` suite: tracks load that comes and goes
during the run), else the median ``calib_ns`` of the rows of the same host.
So runs of different machines or of a loaded CI runner compare as ratios.

The timing verdicts (hikbench.bench.analysis.timing_verdicts) stand on two measured
spreads, because a case's samples are taken in one block of about 0.1 s: they
tell the noise within that moment, not how far the machine's speed moves
between two runs (two runs in a row of the same code on a loaded 2-core VM:
the kernel read 2.28 and 2.29 ms, the cases' medians moved 0.5x-2x; judged on
the samples alone, 7 SLOWER and 8 faster):

* the calibration's: the ratio k of the runs' kernels lies between the lowest
  and the highest ratio of their readings (one per worker process, or per
  job, and run.json's at the start and end of each session), and a verdict
  must hold at both ends;
* the cases' run-to-run spread: sigma of the log ratios of medians over the
  timed cases (1.4826 x their median absolute deviation; 8 cases at least).

A case is a **slowdown** when, with the new samples made as fast as the
calibration's spread allows,

* ratio = median(new normalised samples) / median(base normalised samples)
  exceeds ``threshold`` (default 1.15), and so does the ratio of the minima
  (load from other processes only ever adds time, so a shift of the whole
  distribution, minimum included, is what a real slowdown looks like), and
* q < ``alpha`` (default 0.01): p, the larger of the one-sided Mann-Whitney U
  test's (new > base) over the samples and the normal test's of the log ratio
  against sigma, adjusted over the cases by Benjamini-Hochberg;

both ratios past the threshold at the point estimate without that is
**inconclusive** (shown, not failed: the samples or the cases too spread, or
the calibration too uncertain, to tell a change of that size; with fewer than
two readings on a side or 8 timed cases, no case is more than inconclusive);
**faster** the same way round;
**newly failing** when it was verified in BASE and is not verified in RUN
(but for want of a certified yardstick in RUN: its timing is judged and the
reason shown),
and **missing** when it was verified in BASE and RUN has no row for it
although RUN ran the same suite (run.json's suite name) and selected its
solver (run.json's ``selected_solvers``: the suite's or ``--solvers``'), a
solver it skipped included (a backend that no longer imports; the reason is
shown). Any of the three makes ``compare`` exit 1. Other keys in only one run
(a ``--solvers`` selection, another suite) are listed, not judged; runs of different suites, repetitions or calibration modes are
compared with a note saying so. Given several runs (``compare BASE RUN1
RUN2``), a case fails only when it fails in every run (``confirmed``): a
neighbour's load on a shared CI runner slows one job once, a regression slows
it every time. A run with no row for the case does not clear it.

The calibration kernel (BLAS QR and matmul) does not follow every solver
from one kind of CPU to another: on an AVX-512 AMD EPYC (OpenBLAS SkylakeX
kernels) the kernel took 1.2x its time on the AVX2 one (Haswell) while the
reference solver's SVDs took 1.9x, so a baseline holds for one machine class
(``hikbench.bench.harness.environment.machine_class``: CPU model, OpenBLAS kernels and numba's
target). BASE may be a directory of baselines, one subdirectory per class
(``results/baseline``): ``baseline_for`` picks the one recorded on RUN's
class, else one recorded before run.json named numba's target on RUN's CPU
and kernels. Runs of two classes are compared with a note saying so.

On a loaded machine only large changes can be told from two stored runs
(docs/ci-timing.md has the figures); ``hikbench regress`` pairs the solves
milliseconds apart instead and needs no calibration.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from hikbench.bench.analysis.timing_verdicts import (
    MIN_CASES,
    CalibrationBand,
    calibration_readings,
    run_to_run_spread,
    timing_verdicts,
)
from hikbench.bench.harness.columns import KEY
from hikbench.bench.harness.environment import machine_class, read_run_json
from hikbench.bench.harness.results import RESULTS, read_results
from hikbench.problems.errors import HikbenchError

__all__ = ["FAILING", "Comparison", "NoBaseline", "baseline_for", "compare_runs", "confirmed", "machine_class_of",
           "normalised_samples", "why_not_verified"]

FAILING = ("SLOWER", "NEWLY FAILING", "MISSING")  #: the verdicts that make compare exit 1
_COLUMNS = [*KEY, "base_status", "new_status", "base_verified", "new_verified", "base_median_s", "new_median_s",
            "ratio", "ratio_min", "p_value", "q_value", "verdict", "why"]


@dataclass
class Comparison:
    table: pd.DataFrame          # one row per common key, and per missing key (verdict MISSING)
    only_base: list
    only_new: list
    notes: list = field(default_factory=list)  # why the two runs may not compare (suites, repeat, ...)
    calibration: "CalibrationBand | None" = None  # the spread of the calibration (None: not compared)
    sigma: float = float("nan")  # run-to-run spread of one case's log ratio (run_to_run_spread)
    timed_cases: int = 0

    def spreads(self) -> str:
        """The two spreads the timing verdicts stand on, in words."""
        lines = [] if self.calibration is None else [self.calibration.describe()]
        if math.isnan(self.sigma):
            lines.append(f"run-to-run spread: unknown ({self.timed_cases} timed cases, {MIN_CASES} needed): "
                         f"no case is SLOWER or faster")
        else:
            lines.append(f"run-to-run spread of a case's ratio: sigma {self.sigma:.2g} in log (x{math.exp(self.sigma):.3g}), "
                         f"from the {self.timed_cases} timed cases")
        return "\n".join(lines)

    @property
    def slowdowns(self) -> pd.DataFrame:
        return self.table[self.table["verdict"] == "SLOWER"]

    @property
    def inconclusive(self) -> pd.DataFrame:
        return self.table[self.table["verdict"] == "inconclusive"]

    @property
    def new_failures(self) -> pd.DataFrame:
        return self.table[self.table["verdict"] == "NEWLY FAILING"]

    @property
    def missing(self) -> pd.DataFrame:
        return self.table[self.table["verdict"] == "MISSING"]

    @property
    def failed(self) -> bool:
        return bool(self.table["verdict"].isin(FAILING).any())


def _host_calibration(df: pd.DataFrame, meta: dict) -> dict:
    """host -> median calib_ns of its rows; "" -> run.json's ``calibration_ns``
    (None when neither is known)."""
    fallback = meta.get("calibration_ns")
    cal = df.dropna(subset=["calib_ns"]).groupby("host")["calib_ns"].median().to_dict()
    return {h: cal.get(h, fallback) for h in df["host"].fillna("").unique()} | {"": fallback}


def normalised_samples(df: pd.DataFrame, meta: dict, source: str = "results") -> pd.Series:
    """Samples (ns) divided by a calibration time (see the module docstring): dimensionless."""
    return _normalised(df, meta, source)[0]


def _normalised(df: pd.DataFrame, meta: dict, source: str) -> tuple[pd.Series, pd.Series]:
    """Each row's samples divided by its calibration time, and that time (ns; NaN for a row
    without samples).

    A row with samples and no calibration (an empty ``calib_ns`` on every row
    of its host and no ``calibration_ns`` in run.json: a hand-made file) is a
    HikbenchError naming ``source`` and the row: raw nanoseconds compared with
    a calibrated run would give ratios of a million."""
    cal = _host_calibration(df, meta)
    per_job = bool(meta.get("suite", {}).get("calibrate_each_job"))
    out, scales = [], []
    for i, (s, h, c) in enumerate(zip(df["samples_ns"], df["host"].fillna(""), df["calib_ns"])):
        v = np.asarray(json.loads(s), dtype=float) if s else np.zeros(0)
        scale = float(c) if per_job and pd.notna(c) else cal.get(h, cal[""])
        if v.size and (scale is None or not float(scale) > 0):
            raise HikbenchError(f"{source}: data row {i + 1} ({df['solver'].iloc[i]}, {df['problem'].iloc[i]}) "
                                f"has timing samples but no calibration: calib_ns is empty on every row of "
                                f"its host and run.json has no calibration_ns; expected a run written by "
                                f"`hikbench run`")
        out.append(v / float(scale) if v.size else v)
        scales.append(float(scale) if v.size else float("nan"))
    return pd.Series(out, index=df.index), pd.Series(scales, index=df.index, dtype=float)


def _true(v) -> bool:
    return isinstance(v, (bool, np.bool_)) and bool(v)


def why_not_verified(row) -> str:
    """What a row that is not verified says: its status and reason, or, an ``optimal`` row
    judged against the yardstick, its verdict with the level and the amount
    (``verdict_level``, ``verdict_diff``): ``optimal: worse than the yardstick at level 2 by
    0.0123``. ``row``: a mapping of results.csv's columns (a pandas row or a dict)."""
    status = str(row.get("status"))
    reason = row.get("reason")
    reason = reason if isinstance(reason, str) and reason else ""
    side = row.get("verdict_side")
    if status != "optimal" or not isinstance(side, str) or not side:
        return f"{status}: {reason}" if reason else status
    if side in ("worse", "better"):
        lvl, diff = row.get("verdict_level"), row.get("verdict_diff")
        side += " than the yardstick"
        side += f" at level {int(lvl)}" if pd.notna(lvl) else ""
        side += f" by {abs(float(diff)):.3g}" if diff is not None and pd.notna(diff) else ""
    return f"{status}: {side}" + (f" ({reason})" if reason else "")


def _notes(base_meta: dict, new_meta: dict, new_rows: int, names) -> list[str]:
    """Differences of run.json that make ratios or missing cases mean something else."""
    notes = [f"{n} has no run.json: its suite is unknown and its times are divided by the median "
             f"calibration of each host" for n, m in zip(names, (base_meta, new_meta)) if not m]
    if base_meta and new_meta:
        b, n = base_meta.get("suite", {}), new_meta.get("suite", {})
        for what, label in (("name", "suite"), ("repeat", "repeat"), ("calibrate_each_job", "calibrate_each_job")):
            if b.get(what) != n.get(what):
                notes.append(f"{label} differs: {b.get(what)!r} in base, {n.get(what)!r} in the new run")
        classes = [machine_class(m.get("environment") or {}) for m in (base_meta, new_meta)]
        if None not in classes and classes[0] != classes[1]:
            notes.append(f"machine class differs: {classes[0]!r} in base, {classes[1]!r} in the new run "
                         f"(ratios between solvers move with the CPU; record a baseline on this class)")
        want = new_meta.get("suite_rows")
        if isinstance(want, int) and new_rows < want:
            notes.append(f"the new run is incomplete: {new_rows} of its suite's {want} rows")
    return notes


def _expected(base_meta: dict, new_meta: dict, new_solvers: set) -> dict:
    """solver -> why its case should be in RUN (see MISSING in the module docstring); {} when the
    runs are not of one suite."""
    name = base_meta.get("suite", {}).get("name")
    if not name or new_meta.get("suite", {}).get("name") != name:
        return {}
    skipped = new_meta.get("skipped_solvers") or {}
    ran = new_meta.get("selected_solvers") or new_solvers  # (run.json before selected_solvers: those with rows)
    return {s: "no row" for s in ran} | {s: f"solver skipped: {why}" for s, why in skipped.items()}


def compare_frames(base: pd.DataFrame, new: pd.DataFrame, base_meta: dict, new_meta: dict,
                   threshold: float = 1.15, alpha: float = 0.01, names=("base", "new")) -> Comparison:
    new_solvers, new_rows = set(new["solver"]), len(new)
    band = CalibrationBand(calibration_readings(base, base_meta), calibration_readings(new, new_meta))
    normed, scale = _normalised(base, base_meta, names[0])
    base = base.assign(_norm=normed, _scale=scale).set_index(list(KEY))
    normed, scale = _normalised(new, new_meta, names[1])
    new = new.assign(_norm=normed, _scale=scale).set_index(list(KEY))
    base = base[~base.index.duplicated(keep="last")]
    new = new[~new.index.duplicated(keep="last")]
    common = base.index.intersection(new.index)
    timed = [key for key in common if len(base.loc[key, "_norm"]) and len(new.loc[key, "_norm"])]
    sigma = run_to_run_spread([np.median(new.loc[k, "_norm"]) / np.median(base.loc[k, "_norm"]) for k in timed])
    verdicts = dict(zip(timed, timing_verdicts(
        [(base.loc[k, "_norm"], new.loc[k, "_norm"], new.loc[k, "_scale"] / base.loc[k, "_scale"]) for k in timed],
        band, sigma, threshold, alpha)))
    rows = []
    for key in common:
        b, n = base.loc[key], new.loc[key]
        bs, ns = b["_norm"], n["_norm"]
        ratio, ratio_min, p, q = float("nan"), float("nan"), float("nan"), float("nan")
        timing, timing_why = "ok", ""
        if key in verdicts:
            ratio = float(np.median(ns) / np.median(bs))
            ratio_min = float(np.min(ns) / np.min(bs))
            timing, p, q, timing_why = verdicts[key]
        why = ""
        # a row not verified for want of a certified yardstick is not the solver's failure: its
        # timing is judged, the reason shown (docs/verification.md, "The yardstick of a run")
        unjudged = str(n.get("verdict_side")).startswith("no certified yardstick")
        if unjudged:
            why = f"not verified: no certified yardstick ({n.get('yardstick_reason', '')})"
        if _true(b["verified"]) and not _true(n["verified"]) and not unjudged:
            verdict = "NEWLY FAILING"
            why = why_not_verified(n)
        else:
            verdict = timing
            why = "; ".join(w for w in (why, timing_why) if w)
        rows.append(dict(zip(KEY, key), base_status=b["status"], new_status=n["status"],
                         base_verified=b["verified"], new_verified=n["verified"],
                         base_median_s=b["time_median_s"], new_median_s=n["time_median_s"],
                         ratio=ratio, ratio_min=ratio_min, p_value=p, q_value=q, verdict=verdict, why=why))
    expected = _expected(base_meta, new_meta, new_solvers)
    only_base = []
    for key in base.index.difference(common, sort=False):
        b = base.loc[key]
        solver = dict(zip(KEY, key))["solver"]
        if _true(b["verified"]) and solver in expected:
            rows.append(dict(zip(KEY, key), base_status=b["status"], new_status="", base_verified=b["verified"],
                             new_verified=float("nan"), base_median_s=b["time_median_s"],
                             new_median_s=float("nan"), ratio=float("nan"), ratio_min=float("nan"),
                             p_value=float("nan"), q_value=float("nan"), verdict="MISSING", why=expected[solver]))
        else:
            only_base.append(key)
    table = pd.DataFrame(rows, columns=_COLUMNS)
    return Comparison(table, only_base, [k for k in new.index if k not in common],
                      _notes(base_meta, new_meta, new_rows, names), band, sigma, len(timed))


class NoBaseline(HikbenchError):
    """A directory of baselines holds none of the run's machine class."""


def machine_class_of(run_dir) -> str | None:
    """``hikbench.bench.harness.environment.machine_class`` of a run directory's run.json."""
    return machine_class(_environment_of(run_dir))


def _environment_of(run_dir) -> dict:
    return read_run_json(run_dir).get("environment") or {}


def baseline_for(base_dir, run_dir) -> Path:
    """The baseline run to compare RUN with: BASE itself when it holds a
    results.csv; else, BASE being a directory of baselines (one subdirectory
    per machine class, each a run directory), the subdirectory whose run.json
    was recorded on RUN's machine class (CPU model, OpenBLAS kernels and
    numba's target: "AMD EPYC" alone spans Zen 2 to Zen 5, whose ratios differ).
    NoBaseline when none was; HikbenchError when BASE is neither, when RUN's
    class is unknown, or when two subdirectories have its class."""
    base = Path(base_dir)
    if (base / RESULTS).exists() or not base.is_dir():
        return base  # (read_results says what is wrong with a file or a missing directory)
    envs = {d: _environment_of(d) for d in sorted(base.iterdir()) if (d / RESULTS).exists()}
    if not envs:
        raise HikbenchError(f"{base}: no {RESULTS} and no subdirectory holding one; expected a run directory "
                            f"(the --out of `hikbench run`) or a directory of baselines, one per machine class")
    classes = {d: machine_class(env) for d, env in envs.items()}
    run_env = _environment_of(run_dir)
    want = machine_class(run_env)
    if want is None:
        raise HikbenchError(f"{run_dir}: its run.json names no machine (cpu, BLAS); cannot pick one of the "
                            f"baselines in {base}: give the baseline run directory itself")
    same = [d for d, c in classes.items() if c == want]
    if len(same) > 1:
        raise HikbenchError(f"{base}: {len(same)} baselines of machine class {want!r} "
                            f"({', '.join(d.name for d in same)}); keep one")
    if not same:
        have = "; ".join(f"{d.name}: {c}" for d, c in classes.items())
        raise NoBaseline(f"no baseline in {base_dir} of the machine class of {run_dir} ({want!r}; it has "
                         f"{have}); record one: hikbench run --suite SUITE --out {base_dir}/NAME")
    return same[0]


def compare_runs(base_dir, new_dir, threshold: float = 1.15, alpha: float = 0.01) -> Comparison:
    """compare_frames on two run directories; HikbenchError when they have no case in common
    (nothing compared is not a pass)."""
    c = compare_frames(read_results(base_dir), read_results(new_dir), read_run_json(base_dir),
                       read_run_json(new_dir), threshold, alpha,
                       names=(f"{base_dir}/results.csv", f"{new_dir}/results.csv"))
    if c.table.empty:
        raise HikbenchError(f"{base_dir} ({len(c.only_base)} cases) and {new_dir} ({len(c.only_new)} cases) have "
                            f"no case (problem, solver, settings, mode) in common: expected two runs of the "
                            f"same suite")
    return c


def confirmed(comparisons: list[Comparison]) -> Comparison:
    """Several runs against one baseline: a case failing in the first run
    (SLOWER / NEWLY FAILING / MISSING) stays failed unless a later run has it
    passing (a one-off disturbance does not reproduce); then it reads "...,
    not reproduced". A later run that fails it another way (a slowdown that
    became a timeout) or has no row for it does not clear it. Numbers are
    those of the first run."""
    first = comparisons[0]
    if len(comparisons) == 1:
        return first
    key = list(KEY)
    t = first.table.set_index(key)
    for c in comparisons[1:]:
        v = c.table.set_index(key)["verdict"].reindex(t.index)
        cleared = t["verdict"].isin(FAILING) & v.notna() & ~v.isin(FAILING)
        t.loc[cleared, "verdict"] = t.loc[cleared, "verdict"].str.lower() + ", not reproduced"
    notes = list(dict.fromkeys(n for c in comparisons for n in c.notes))
    return Comparison(t.reset_index(), first.only_base, first.only_new, notes, first.calibration, first.sigma,
                      first.timed_cases)


def format_table(c: Comparison, show_all: bool = False) -> str:
    t = c.table.sort_values("ratio", ascending=False, na_position="last")
    if not show_all:
        t = pd.concat([t[t["verdict"] != "ok"], t[t["verdict"] == "ok"].head(10)])
    # q: the adjusted p-value of the verdict's direction (new slower than base, or faster for
    # "faster" rows: timing_verdicts); the verdict column is as wide as its longest entry
    w = max([13, *map(len, t["verdict"])])
    lines = [(f"{'verdict':<{w}} {'ratio':>6} {'min r':>6} {'q':>7} {'base us':>9} {'new us':>9}  "
              "solver / settings / mode / problem")]
    for r in t.itertuples():
        why = f"  ({r.why[:120]})" if isinstance(r.why, str) and r.why else ""
        lines.append(f"{r.verdict:<{w}} {r.ratio:>6.2f} {r.ratio_min:>6.2f} {r.q_value:>7.4f} "
                     f"{r.base_median_s * 1e6:>9.1f} "
                     f"{r.new_median_s * 1e6:>9.1f}  {r.solver} / {r.settings} / {r.mode} / {r.problem}{why}")
    for what, keys in (("only in base", c.only_base), ("only in new", c.only_new)):  # listed, not judged
        keys = sorted(keys)
        shown = keys if show_all else keys[:10]
        lines += [f"{what:<{w}} {'':>41}  {solver} / {settings} / {mode} / {problem}"
                  for problem, solver, settings, mode in shown]
        if len(shown) < len(keys):
            lines.append(f"{what:<{w}} {'':>41}  ... and {len(keys) - len(shown)} more (--all lists them)")
    return "\n".join(lines)
