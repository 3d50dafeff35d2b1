"""The rankings of report.md (docs/reports.md, "Ranking"), one mode at a time.

* :func:`rank`: strict solvers over ONE set of problems, the problems every
  ranked solver attempted; a strict solver that declared some of them
  ``unsupported`` is listed apart with its count. Success rate first (success
  = ``verified`` True), then the relative time of
  :func:`hikbench.bench.analysis.shgeom.relative_time` (1.0 = fastest), with
  failures charged by :func:`hikbench.bench.analysis.shgeom.charge_failures`.
* :func:`rank_supported`: for each strict solver that declined some problems,
  the same ranking over the problems it supports, of every strict solver that
  attempted all of them: a decliner is ranked there.
* :func:`own_problems`: each strict solver over the problems it attempted
  alone: not comparable across solvers, and labelled so.
* :func:`non_strict`: solvers that do not claim the lexicographic optimum,
  with their real times and their per-level gap to the yardstick.
* :func:`claim_met`: each row judged by its solver's own claim (the success
  of the per-family table and figure): a strict row by ``verified``, a
  non-strict row by its highest-priority level, level 0, met; NaN where the
  row cannot tell (no certified yardstick).
* :func:`success_by`: the share of :func:`claim_met` per solver and family (or
  any column): the one table report.md prints and success_rate.png draws.

Every function takes the rows of one mode with a ``label`` column
(:func:`hikbench.bench.analysis.plots.solver_label`).
"""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from hikbench.bench.analysis.shgeom import charge_failures, relative_time, shifted_geometric_mean, timed
from hikbench.problems.verify import PROFILES

__all__ = ["Ranking", "claim_met", "level0_met", "non_strict", "own_problems", "rank", "rank_supported", "strict_labels",
           "success_by"]


@dataclass
class Ranking:
    """The headline ranking of one mode."""
    mode: str
    problems: list[str]  #: the one problem set every ranked figure is over
    rows: list[dict] = field(default_factory=list)  #: ranked solvers, best first
    apart: dict[str, dict] = field(default_factory=dict)  #: label -> {declined, of}: not ranked
    unsolved: list[str] = field(default_factory=list)  #: problems no ranked solver solved: out of the time


def strict_labels(df: pd.DataFrame) -> set[str]:
    """Labels whose rows all say ``strict`` True (a solver claiming the lexicographic optimum)."""
    strict = df["strict"].astype(str).eq("True").groupby(df["label"]).all()
    return set(strict.index[strict])


def _grid(r: pd.DataFrame, values: pd.Series, problems: list[str], labels: list[str]) -> pd.DataFrame:
    """problems x labels table of ``values`` (one row per problem and label)."""
    return values.set_axis(pd.MultiIndex.from_arrays([r["problem"], r["label"]])).unstack("label").reindex(
        index=problems, columns=labels)


def rank(d: pd.DataFrame, strict: set[str], mode: str) -> Ranking | None:
    """The ranking of the strict solvers of ``d`` (rows of one mode); None without strict rows."""
    d = d[d["label"].isin(strict)]
    if d.empty:
        return None
    declined = d[d["status"] == "unsupported"].groupby("label")["problem"].nunique()
    labels = sorted(set(d["label"]) - set(declined.index))
    apart = {lab: {"declined": int(declined[lab]), "of": int(d.loc[d["label"] == lab, "problem"].nunique())}
             for lab in sorted(declined.index)}
    r = d[d["label"].isin(labels)]
    have = r.groupby("problem")["label"].nunique()
    problems = sorted(have.index[have == len(labels)])  # (a partial run: only the problems all of them ran)
    r = r[r["problem"].isin(problems)]
    out = Ranking(mode, problems, apart=apart)
    if not problems:
        return out
    t = _grid(r, r["time_median_s"].where(timed(r, zero_ok=True)).astype(float), problems, labels)
    ok = _grid(r, r["verified"].eq(True), problems, labels)
    at = {p: _grid(r, r[f"verified_{p}"].eq(True), problems, labels) for p in PROFILES
          if f"verified_{p}" in r and r[f"verified_{p}"].notna().any()}  # (rows written before the profiles: none)
    charged, out.unsolved = charge_failures(t)
    rel = relative_time(charged)
    fastest = charged.eq(charged.min(axis=1), axis=0).sum()
    for lab in labels:
        k = int(ok[lab].sum())
        succ = t[lab].dropna()
        out.rows.append({"solver": lab, "problems": len(problems), "success": k,
                         "success_rate": k / len(problems),
                         "success_at": {p: int(g[lab].sum()) for p, g in at.items()},
                         "relative_time": float(rel[lab]),
                         "fastest_on": int(fastest[lab]), "charged": int(t[lab].loc[charged.index].isna().sum()),
                         "median_time_s": float(succ.median()) if len(succ) else None})
    out.rows.sort(key=lambda row: (-row["success_rate"], _or_inf(row["relative_time"]), row["solver"]))
    return out


def rank_supported(d: pd.DataFrame, strict: set[str], mode: str, ranking: Ranking | None) -> list[tuple[list[str], Ranking]]:
    """A ranking on the problems each solver listed apart from ``ranking`` (it declined some)
    supports: the problems it attempted, and every strict solver of ``d`` that attempted all of
    them (:func:`rank` over those rows; a solver that declines one of them is listed apart
    there). Solvers that support the same problems share one ranking. Returns [(the solvers
    whose supported problems it is over, the Ranking)], the largest problem sets first."""
    if ranking is None or not ranking.apart:
        return []
    d = d[d["label"].isin(strict)]
    tried = d[d["status"] != "unsupported"]
    own = {lab: frozenset(tried.loc[tried["label"] == lab, "problem"]) for lab in ranking.apart}
    groups: dict[frozenset, list[str]] = {}
    for lab, probs in own.items():
        if probs:
            groups.setdefault(probs, []).append(lab)
    out = []
    for probs, labs in sorted(groups.items(), key=lambda kv: (-len(kv[0]), sorted(kv[1]))):
        r = rank(d[d["problem"].isin(probs)], strict, mode)
        if r is not None and r.rows:
            out.append((sorted(labs), r))
    return out


def _or_inf(v: float) -> float:
    return v if np.isfinite(v) else np.inf


def own_problems(d: pd.DataFrame, strict: set[str]) -> list[dict]:
    """Each strict solver of ``d`` over the problems it attempted (its own set)."""
    out = []
    for lab, g in sorted(d[d["label"].isin(strict)].groupby("label")):
        tried = g[g["status"] != "unsupported"]
        ok = tried[timed(tried, zero_ok=True)]["time_median_s"].astype(float)
        out.append({"solver": lab, "attempted": len(tried), "declined": len(g) - len(tried),
                    "success": int(tried["verified"].eq(True).sum()),
                    "success_rate": float(tried["verified"].eq(True).mean()) if len(tried) else None,
                    "sgm_time_s": shifted_geometric_mean(ok) if len(ok) else None,
                    "median_time_s": float(ok.median()) if len(ok) else None})
    return out


def _level_gaps(g: pd.DataFrame) -> list[list[float]]:
    """Per level k, the gaps ||v_k(x)|| - ||v_k(x_ref)|| of the rows of ``g`` that reach level k,
    up to the last level that at least half the rows reach (deeper ones: a few deep problems)."""
    gaps: list[list[float]] = []
    for a, b in zip(g["level_norms"], g["ref_level_norms"]):
        if not a or not b:
            continue
        for k, (u, v) in enumerate(zip(json.loads(a), json.loads(b))):
            if u is not None and v is not None:
                gaps.extend([] for _ in range(k + 1 - len(gaps)))
                gaps[k].append(u - v)
    half = len(gaps[0]) / 2 if gaps else 0
    return [x for x in gaps if len(x) >= half]


def _most_lost(lost: Counter) -> dict | None:
    """The level most rows first lose at (ties: the higher priority, lower k), with its count."""
    if not lost:
        return None
    level, count = max(lost.items(), key=lambda kv: (kv[1], -kv[0]))
    return {"level": level, "rows": count}


def non_strict(d: pd.DataFrame, strict: set[str]) -> list[dict]:
    """Each non-strict solver of ``d``: its real median time over the rows
    that have one (verified or not), how often it met the yardstick anyway,
    the level where it first loses (most often), and the median gap per level."""
    out = []
    for lab, g in sorted(d[~d["label"].isin(strict)].groupby("label")):
        tried = g[g["status"] != "unsupported"]
        t = tried["time_median_s"].astype(float)
        t = t[np.isfinite(t) & (t >= 0)]
        lost = Counter(int(v) for v, side in zip(tried["verdict_level"], tried["verdict_side"])
                       if side == "worse" and pd.notna(v))
        gaps = _level_gaps(tried)
        l0 = level0_met(tried).dropna()
        out.append({"solver": lab, "attempted": len(tried), "declined": len(g) - len(tried), "timed": len(t),
                    "median_time_s": float(t.median()) if len(t) else None,
                    "meets_yardstick": int(tried["verified"].eq(True).sum()),
                    "level0_met": int(l0.sum()), "level0_judged": len(l0),
                    "first_level_lost": _most_lost(lost),
                    "median_gap_per_level": [float(np.median(x)) for x in gaps],
                    "problems_per_level": [len(x) for x in gaps]})
    return out


#: verdict_side values that say level 0 is met (the verdict's first differing level is below it, or
#: the row is better there) or not ('no x': no solution); any other side cannot tell (no yardstick)
_LEVEL0_SIDES = ("worse", "better", "no x")


def level0_met(d: pd.DataFrame) -> pd.Series:
    """Per row, whether x meets the highest-priority level, level 0, as the
    yardstick does: ``||v_0(x)|| <= ||v_0(x_ref)||`` within the suite's
    accuracy tolerance, read from the verdict (verified, or a first differing
    level below 0, or better at level 0: met; worse at level 0, or no x: not
    met). 1.0 / 0.0, NaN where the row cannot tell (no yardstick)."""
    side = d["verdict_side"].where(d["verdict_side"].isin(_LEVEL0_SIDES))
    level = pd.to_numeric(d["verdict_level"], errors="coerce")
    met = pd.Series(np.nan, index=d.index)
    met[side.eq("no x")] = 0.0
    met[side.eq("better")] = 1.0
    met[side.eq("worse")] = (level[side.eq("worse")] > 0).astype(float)
    met[side.eq("worse") & level.isna()] = np.nan  # (a verdict without its level cannot tell)
    met[d["verified"].eq(True)] = 1.0
    return met


def claim_met(d: pd.DataFrame, strict: set[str]) -> pd.Series:
    """Per row (with its ``label``), whether its solver met its own claim: a
    strict solver's row when ``verified`` (1.0, else 0.0); a non-strict
    solver's row when it meets level 0 (:func:`level0_met`: NaN when it cannot
    tell). docs/reports.md, "Success by each solver's claim"."""
    is_strict = d["label"].isin(strict)
    judged = d["verified"].notna()  # (False or True: a row without a certified yardstick cannot tell)
    ok = d["verified"].eq(True).astype(float).where(judged)
    return ok.where(is_strict, level0_met(d))


def success_by(d: pd.DataFrame, strict: set[str], by: str | pd.Series = "family") -> tuple[pd.DataFrame, pd.DataFrame]:
    """The success of each solver by its own claim (:func:`claim_met`) per value of ``by`` (a
    column name, or a Series on d's index), over the rows it attempted (``unsupported`` left
    out) that can tell (no certified yardstick: left out): (rates, counts), two label x value
    tables, a rate NaN where no row is judged. report.md's "Success per family" table and
    success_rate.png are both this table."""
    d = d[d["status"] != "unsupported"]
    key = d[by] if isinstance(by, str) else by.loc[d.index]
    ok = claim_met(d, strict)
    g = pd.DataFrame({"label": d["label"], "by": key, "ok": ok}).dropna(subset=["ok"])
    labels, values = sorted(d["label"].unique()), sorted(key.unique())
    if g.empty:
        return (pd.DataFrame(np.nan, index=labels, columns=values),
                pd.DataFrame(0, index=labels, columns=values))
    rates = g.pivot_table(index="label", columns="by", values="ok", aggfunc="mean").reindex(index=labels,
                                                                                          columns=values)
    counts = g.pivot_table(index="label", columns="by", values="ok", aggfunc="count").reindex(
        index=labels, columns=values).fillna(0).astype(int)
    return rates, counts
