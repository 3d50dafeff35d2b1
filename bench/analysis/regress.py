"""The decision of ``hikbench regress``: per case (problem, solver, settings,
mode), the paired rounds' log time ratios ``d_r = log(change_r / base_r)``
(``time_median_s`` of each side's run in round r) are tested for a slowdown.

- ratio = exp(mean d), its 95 % interval exp(mean d +- t_{0.975, R-1} s/sqrt(R));
- p = one-sided one-sample t test of mean d > 0 (< 0 for ``faster``), and
  q = p adjusted over the cases by Benjamini-Hochberg
  (``scipy.stats.false_discovery_control``);
- SLOWER: q < alpha and ratio > threshold (1.15); FASTER the same the other way
  (ratio < 1 / threshold); inconclusive: ratio > threshold, q >= alpha; NEWLY FAILING: verified in
  every base round and not in most change rounds (the line names the status and
  reason, or the level and the amount it is worse by); MISSING: verified in every
  base round, its solver still selected by the change's runs, no change row;
  not timed: a case one side's solver declines (status ``unsupported``: not a
  timing case), or timed in fewer than 2 paired rounds.

A case is *borderline* (worth another round) when it is inconclusive, or
significantly slower with the threshold inside its interval.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from hikbench.bench.analysis.compare import why_not_verified
from hikbench.bench.harness.columns import KEY
from hikbench.solvers.base import UNSUPPORTED

__all__ = ["Decision", "FAILING", "decide", "markdown", "to_json"]

SLOWER, FASTER, NEWLY_FAILING, MISSING = "SLOWER", "faster", "NEWLY FAILING", "MISSING"
INCONCLUSIVE, OK, UNTIMED = "inconclusive", "ok", "not timed"
#: verdicts that fail the gate (exit 1)
FAILING = (SLOWER, NEWLY_FAILING, MISSING)
_DIFFERS = "the problem differs between base and change"
_ORDER = {v: i for i, v in enumerate((NEWLY_FAILING, MISSING, SLOWER, INCONCLUSIVE, FASTER, OK, UNTIMED))}


@dataclass
class Case:
    problem: str
    solver: str
    settings: str
    mode: str
    verdict: str
    rounds: int = 0
    base_s: float = math.nan
    change_s: float = math.nan
    ratio: float = math.nan
    low: float = math.nan
    high: float = math.nan
    p: float = math.nan
    q: float = math.nan
    why: str = ""
    borderline: bool = False


@dataclass
class Decision:
    cases: list[Case]
    threshold: float
    alpha: float
    notes: list[str] = field(default_factory=list)

    @property
    def failed(self) -> list[Case]:
        return [c for c in self.cases if c.verdict in FAILING]

    @property
    def borderline(self) -> list[Case]:
        return [c for c in self.cases if c.borderline]

    def count(self, verdict: str) -> int:
        return sum(c.verdict == verdict for c in self.cases)


def _by_key(frames: list[pd.DataFrame]) -> list[dict]:
    """Each frame as ``{key: row as a dict}`` (the last row of a key): a dict lookup
    per case and round, not a DataFrame's ``.loc`` (0.7 s a decision at 26 rounds)."""
    cols = list(KEY)
    return [{tuple(k): row for k, row in zip(f[cols].itertuples(index=False, name=None),
                                            f.to_dict("records"))} for f in frames]


def _true(v) -> bool:
    return isinstance(v, (bool, np.bool_)) and bool(v) or str(v) == "True"


def _verified(frames: list[dict], key) -> list[bool]:
    """verified in each round of one side (False where the round has no row)."""
    return [key in f and _true(f[key].get("verified")) for f in frames]


def _why(frames: list[dict], key) -> str:
    """Why the first round of a side that did not verify the case did not (its status and
    reason, or its verdict's level and amount: :func:`~hikbench.bench.analysis.compare.why_not_verified`)."""
    for f in frames:
        if key in f and not _true(f[key].get("verified")):
            return why_not_verified(f[key])
    return ""


def _declined(frames: list[dict], key) -> bool:
    """Whether a round of the side has the case's solver declining it (status ``unsupported``)."""
    return any(key in f and f[key].get("status") == UNSUPPORTED for f in frames)


def _paired(base: list[dict], change: list[dict], key) -> np.ndarray:
    """d_r = log(change_r / base_r) over the rounds where both sides timed the case."""
    d = []
    for b, c in zip(base, change):
        if key in b and key in c:
            tb, tc = float(b[key]["time_median_s"]), float(c[key]["time_median_s"])
            if tb > 0 and tc > 0 and math.isfinite(tb) and math.isfinite(tc):
                d.append(math.log(tc / tb))
    return np.asarray(d)


def _content_differs(base: list[dict], change: list[dict], key) -> bool:
    """True when both sides record the case's ``problem_hash`` and they differ (a
    changed generator: the two sides timed different problems under one id)."""
    hashes = [{str(f[key]["problem_hash"])} for f in (base[0], change[0])
              if key in f and "problem_hash" in f[key]]
    return len(hashes) == 2 and hashes[0] != hashes[1]


def _t_stats(d: np.ndarray) -> tuple[float, float, float, float, float]:
    """ratio, interval low, high, p of a slowdown, p of a speed-up."""
    mean = float(d.mean())
    sd = float(d.std(ddof=1))
    if sd == 0.0:
        return math.exp(mean), math.exp(mean), math.exp(mean), float(mean <= 0), float(mean >= 0)
    half = float(stats.t.ppf(0.975, d.size - 1)) * sd / math.sqrt(d.size)
    up = float(stats.ttest_1samp(d, 0.0, alternative="greater").pvalue)
    down = float(stats.ttest_1samp(d, 0.0, alternative="less").pvalue)
    return math.exp(mean), math.exp(mean - half), math.exp(mean + half), up, down


def _expected_solvers(change_meta: dict) -> set:
    return set(change_meta.get("selected_solvers") or []) | set(change_meta.get("skipped_solvers") or {})


def decide(base_frames: list[pd.DataFrame], change_frames: list[pd.DataFrame], threshold: float = 1.15,
           alpha: float = 0.01, change_meta: dict | None = None) -> Decision:
    """The verdict of every case seen on either side (see the module docstring)."""
    base, change = _by_key(base_frames), _by_key(change_frames)
    keys = list(dict.fromkeys(k for f in base + change for k in f))
    expected = _expected_solvers(change_meta or {})
    problems_of_change = {k[0] for f in change for k in f}
    cases, timed, notes = [], [], []
    for key in keys:
        case = Case(*key, verdict=OK)
        b_ok, c_ok = _verified(base, key), _verified(change, key)
        in_change = any(key in f for f in change)
        in_base = any(key in f for f in base)
        d = _paired(base, change, key)
        if _content_differs(base, change, key):
            d = d[:0]
        case.rounds = int(d.size)
        if all(b_ok) and in_base and not in_change:
            if key[1] in expected and key[0] in problems_of_change:
                case.verdict, case.why = MISSING, "no row in the change's runs"
            else:
                case.verdict, case.why = UNTIMED, "only in the base's suite"
        elif all(b_ok) and in_change and sum(c_ok) * 2 < len(c_ok):
            case.verdict, case.why = NEWLY_FAILING, _why(change, key)
        elif not in_base:
            case.verdict, case.why = UNTIMED, "only in the change's suite"
        elif sides := [n for n, frames in (("base", base), ("change", change)) if _declined(frames, key)]:
            # a decline (a solver saying it does not solve such problems) is not a timing case
            case.verdict, case.why = UNTIMED, f"declined ({UNSUPPORTED}) on {' and '.join(sides)}"
            d, case.rounds = d[:0], 0
        if d.size:
            case.base_s = float(np.median([f[key]["time_median_s"] for f in base if key in f]))
            case.change_s = float(np.median([f[key]["time_median_s"] for f in change if key in f]))
        if d.size >= 2 and case.verdict == OK:
            case.ratio, case.low, case.high, up, down = _t_stats(d)
            timed.append((case, up, down))
        elif case.verdict == OK:
            case.verdict, case.why = UNTIMED, (
                _DIFFERS if _content_differs(base, change, key)
                else f"timed in {d.size} paired round(s); 2 are needed")
        cases.append(case)
    if timed:
        q_up = stats.false_discovery_control([t[1] for t in timed])
        q_down = stats.false_discovery_control([t[2] for t in timed])
        limit = threshold
        for (case, up, down), qu, qd in zip(timed, q_up, q_down):
            slower = case.ratio > 1.0
            case.p, case.q = (up, float(qu)) if slower else (down, float(qd))
            if qu < alpha and case.ratio > limit:
                case.verdict = SLOWER
            elif qd < alpha and case.ratio < 1.0 / limit:
                case.verdict = FASTER
            elif case.ratio > limit:
                case.verdict = INCONCLUSIVE
            case.borderline = bool(case.verdict == INCONCLUSIVE or (qu < alpha and case.low <= limit <= case.high))
    changed = sorted({c.problem for c in cases if c.why == _DIFFERS})
    if changed:
        notes.append(f"{len(changed)} problem(s) differ in content between base and change (problem_hash), "
                     f"not timed: {', '.join(changed)}")
    cases.sort(key=lambda c: (_ORDER[c.verdict], -(c.ratio if math.isfinite(c.ratio) else 0.0)))
    return Decision(cases, threshold, alpha, notes)


def _us(t: float) -> str:
    return "" if not math.isfinite(t) else f"{t * 1e6:,.1f}"


def _ratio(c: Case) -> str:
    if not math.isfinite(c.ratio):
        return ""
    return f"{c.ratio:.3f} [{c.low:.3f}, {c.high:.3f}]"


def markdown(dec: Decision, head: str) -> str:
    """The Markdown table of a decision (for a pull-request comment), every case."""
    lines = [head, "",
             "| case | base (us) | change (us) | ratio [95 % interval] | q | rounds | verdict |",
             "|---|---:|---:|---|---:|---:|---|"]
    for c in dec.cases:
        verdict = c.verdict if not c.why else f"{c.verdict}: {c.why}".replace("|", "/")
        q = "" if not math.isfinite(c.q) else f"{c.q:.2g}"
        lines.append(f"| {c.problem} · {c.solver} · {c.settings} · {c.mode} | {_us(c.base_s)} | "
                     f"{_us(c.change_s)} | {_ratio(c)} | {q} | {c.rounds} | {verdict} |")
    lines += ["", f"SLOWER: q < {dec.alpha:g} (Benjamini-Hochberg over the timed cases) and ratio > "
                  f"{dec.threshold:g}; ratio = geometric mean of the paired rounds' change/base medians."]
    lines += [f"note: {n}" for n in dec.notes]
    return "\n".join(lines) + "\n"


def _clean(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def to_json(dec: Decision, meta: dict, path: Path) -> None:
    """Write the decision and ``meta`` (revisions, suite, rounds, times) to ``path``."""
    doc = meta | {"threshold": dec.threshold, "alpha": dec.alpha, "notes": dec.notes,
                  "counts": {v: dec.count(v) for v in _ORDER},
                  "regression": bool(dec.failed),
                  "cases": [{k: _clean(v) for k, v in asdict(c).items()} for c in dec.cases]}
    path.write_text(json.dumps(doc, indent=1) + "\n")
