"""The timing verdicts of ``hikbench compare`` (hikbench.bench.analysis.compare): two stored
runs, each case's samples normalised by a calibration kernel, judged against two measured
spreads (docs/ci-timing.md, "Comparing two stored runs"):

* the calibration's: the ratio of the runs' kernels is known only within the ratios of their
  readings (:class:`CalibrationBand`), and a verdict must hold at both ends;
* the cases' run-to-run spread: a case's samples are taken in one block of about 0.1 s at
  the machine's speed of that moment, so two runs' medians move far more than the samples
  of one row tell; sigma of the log ratios over the timed cases (:func:`run_to_run_spread`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.stats import false_discovery_control, mannwhitneyu, norm

__all__ = ["MIN_CASES", "CalibrationBand", "calibration_readings", "run_to_run_spread", "timing_verdicts"]


def calibration_readings(df: pd.DataFrame, meta: dict) -> list[float]:
    """Every reading of the calibration kernel a run holds (ns): each row's ``calib_ns`` when
    the suite timed the kernel around every job (``calibrate_each_job``), else one per worker
    process (``worker``, or ``host`` without it: the readings its rows share), and run.json's
    readings at the start and the end of each session (``calibration_start_ns``, ``_end_ns``)."""
    cal = df.dropna(subset=["calib_ns"]) if "calib_ns" in df else df.iloc[:0]
    if bool(meta.get("suite", {}).get("calibrate_each_job")):
        out = [float(c) for c in cal["calib_ns"]]
    else:
        who = "worker" if "worker" in cal and cal["worker"].notna().all() else "host"
        out = [float(c) for c in cal.groupby(cal[who].fillna(""))["calib_ns"].median()] if len(cal) else []
    for session in meta.get("sessions") or []:
        out += [float(session[k]) for k in ("calibration_start_ns", "calibration_end_ns")
                if isinstance(session.get(k), (int, float)) and session[k] > 0]
    return [c for c in out if c > 0]


@dataclass
class CalibrationBand:
    """How well the calibration kernel tells the two runs' machine speeds apart.

    The ratio k = calibration(new) / calibration(base) that divides a case's time ratio is
    known only within the spread of the runs' readings ``base`` and ``new`` (ns): between
    ``k_low`` = min(new) / max(base) and ``k_high`` = max(new) / min(base). With fewer than
    two readings on a side the spread is unknown (``known`` False): no timing verdict."""

    base: list
    new: list

    @property
    def known(self) -> bool:
        return len(self.base) >= 2 and len(self.new) >= 2

    @property
    def k_low(self) -> float:
        return float(min(self.new) / max(self.base)) if self.known else float("nan")

    @property
    def k_high(self) -> float:
        return float(max(self.new) / min(self.base)) if self.known else float("nan")

    def describe(self) -> str:
        def side(name, r):
            if not r:
                return f"{name} none"
            return f"{name} {min(r) / 1e6:.3g}-{max(r) / 1e6:.3g} ms ({len(r)} reading{'s' * (len(r) != 1)})"
        text = f"calibration kernel: {side('base', self.base)}, {side('new', self.new)}"
        if not self.known:
            return text + ": its spread is unknown (fewer than 2 readings on a side): no case is SLOWER or faster"
        return (text + f": new/base between {self.k_low:.3g} and {self.k_high:.3g}; a case is SLOWER or faster "
                       f"only at both ends")


MIN_CASES = 8  #: timed cases needed to estimate the run-to-run spread of one case's ratio


def run_to_run_spread(ratios) -> float:
    """sigma of one case's log time ratio between two runs, from every timed case's ratio:
    1.4826 x the median absolute deviation of the log ratios (the standard deviation for
    normal noise; a minority of real changes barely moves it); NaN under MIN_CASES cases."""
    d = np.log(np.asarray(ratios, dtype=float))
    d = d[np.isfinite(d)]
    return float(1.4826 * np.median(np.abs(d - np.median(d)))) if d.size >= MIN_CASES else float("nan")


def timing_verdicts(timed: list, band: CalibrationBand, sigma: float, threshold: float,
                     alpha: float) -> list[tuple[str, float, float, str]]:
    """(verdict, p, q, why) of each timed case ``(bs, ns, k)``: normalised samples of base and
    new, and the ratio k new / base of the calibrations they were divided by.

    A direction's p is the larger of the one-sided Mann-Whitney test of the samples and the
    normal test of the case's log ratio against the run-to-run spread ``sigma``, both with
    the new samples moved to the calibration band's end that favours no change (k_high
    for a slowdown, k_low for a speed-up); q is p adjusted over the cases (Benjamini-Hochberg).
    SLOWER: q < alpha and, at that end, the ratios of medians and of minima past the
    threshold; faster the same way round; inconclusive: both ratios past the threshold
    at the point estimate without that."""
    rows, p_up, p_down = [], [], []
    for bs, ns, k in timed:
        if band.known:
            high, low = max(band.k_high / k, 1.0), min(band.k_low / k, 1.0)  # (k within: its scales are readings)
        else:
            high = low = float("nan")
        ends = {}
        for name, f, alt in (("up", high, "greater"), ("down", low, "less")):
            moved = ns / f
            r, rmin = float(np.median(moved) / np.median(bs)), float(np.min(moved) / np.min(bs))
            within = float(mannwhitneyu(moved, bs, alternative=alt).pvalue) if np.isfinite(f) else float("nan")
            z = _z(math.log(r), sigma)
            between = float(norm.sf(z if alt == "greater" else -z)) if not math.isnan(z) else float("nan")
            ends[name] = (r, rmin, float(np.maximum(within, between)))  # (NaN, unknown, stays NaN)
        rows.append((float(np.median(ns) / np.median(bs)), float(np.min(ns) / np.min(bs)), ends))
        p_up.append(ends["up"][2])
        p_down.append(ends["down"][2])
    q_up, q_down = _bh(p_up), _bh(p_down)
    out = []
    for (ratio, ratio_min, ends), qu, qd in zip(rows, q_up, q_down):
        (ru, mu, pu), (rd, md, pd_) = ends["up"], ends["down"]
        if ratio > threshold and ratio_min > threshold:
            if ru > threshold and mu > threshold and qu < alpha:
                out.append(("SLOWER", pu, qu, ""))
                continue
            # past the threshold at the point estimate, not beyond the spreads: too few or too spread
            # samples or cases, or a calibration too uncertain, to tell (docs/ci-timing.md,
            # "Comparing two stored runs"); shown, not failed
            out.append(("inconclusive", pu, qu, _undecided(band, sigma, ru, mu, threshold)))
        elif ratio < 1 / threshold and ratio_min < 1 / threshold and rd < 1 / threshold and md < 1 / threshold \
                and qd < alpha:
            out.append(("faster", pd_, qd, ""))
        else:
            out.append(("ok", pu, qu, ""))
    return out


def _z(d: float, sigma: float) -> float:
    """d / sigma; NaN for an unknown sigma, +-inf (0 for d = 0) for sigma = 0."""
    if math.isnan(sigma):
        return float("nan")
    if sigma > 0:
        return d / sigma
    return math.copysign(math.inf, d) if d else 0.0


def _undecided(band: CalibrationBand, sigma: float, r_end: float, rmin_end: float, threshold: float) -> str:
    if not band.known:
        return "the calibration's spread is unknown"
    if math.isnan(sigma):
        return f"too few timed cases to know the run-to-run spread ({MIN_CASES} needed)"
    if not (r_end > threshold and rmin_end > threshold):
        return f"within the calibration's spread ({r_end:.3g} at its end)"
    return f"not significant against the run-to-run spread (sigma {sigma:.2g} in log)"


def _bh(p: list) -> list:
    """Benjamini-Hochberg adjusted p-values (NaN stays NaN: never below alpha)."""
    p = np.asarray(p, dtype=float)
    q = np.full(p.shape, np.nan)
    ok = np.isfinite(p)
    if ok.any():
        q[ok] = false_discovery_control(p[ok])
    return q.tolist()
