"""PNG figures of a run (matplotlib, Agg backend). Each function takes the
results DataFrame (hikbench.bench.harness.results.read_results) and a path, writes one PNG and
returns the path (or None when the run has no data for that figure)."""

from __future__ import annotations

import json
import math
import textwrap
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import matplotlib.ticker
import numpy as np
import pandas as pd

from hikbench.bench.analysis.shgeom import loglog_fit, performance_profile, timed

__all__ = ["PALETTE", "fit_title", "loglog_slope", "solver_styles", "title_fits", "plot_accuracy", "plot_cold_warm", "plot_profiles", "plot_success", "plot_sweep",
           "sweeps"]

_STYLE = {"figsize": (9.5, 5.0), "dpi": 110}


def loglog_slope(x, y) -> tuple[float, float]:
    """Slope of log y vs log x and its standard error (:func:`hikbench.bench.analysis.shgeom.loglog_fit`)."""
    slope, se, _ = loglog_fit(x, y)
    return slope, se


def _other_params(params_json: str, var: str) -> str:
    p = json.loads(params_json) if params_json else {}
    p.pop(var, None)
    return json.dumps(p, sort_keys=True)


def sweeps(df: pd.DataFrame, var: str, min_points: int = 3) -> list[tuple[str, str, pd.DataFrame]]:
    """(family, fixed-params JSON, rows) of each sweep over column ``var``
    (n or depth) with at least ``min_points`` distinct values."""
    if df.empty:
        return []
    d = df.assign(_fixed=[_other_params(p, var) for p in df["params"]])
    d = d[[var in (json.loads(p) if p else {}) for p in d["params"]]]
    out = []
    for (fam, fixed), g in d.groupby(["family", "_fixed"]):
        if g[var].nunique() >= min_points:
            out.append((fam, fixed, g))
    return out


#: 20 colours told apart at a glance (no light/dark pairs as in tab20), then markers
PALETTE = ("#e6194b", "#3cb44b", "#4363d8", "#f58231", "#911eb4", "#42d4f4", "#f032e6", "#9acd32",
           "#469990", "#9a6324", "#800000", "#808000", "#000075", "#000000", "#a9a9a9", "#e6b800",
           "#ff8fab", "#b48cff", "#66cdaa", "#d2a679")
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*", "<", ">", "h")
#: line style by claim: solid for strict solvers (lexicographic optimum), dashed for the others
LINESTYLE = {True: "-", False: "--"}


def solver_label(df: pd.DataFrame) -> pd.Series:
    """``solver``, or ``solver [settings]`` for a ``[[settings]]`` variant: a
    solver's name in every table and figure of the report."""
    return df["solver"].where(df["settings"] == "default", df["solver"] + " [" + df["settings"] + "]")


def solver_styles(df: pd.DataFrame) -> dict[str, dict]:
    """{solver label: colour, marker, linestyle} for every solver of the run:
    colour and marker by the label's place in the sorted labels of the whole
    run (so a solver looks the same in every figure), line style by its claim
    (solid strict, dashed non-strict)."""
    labels = solver_label(df)
    strict = df["strict"].astype(str).eq("True").groupby(labels).all()
    return {label: {"color": PALETTE[i % len(PALETTE)], "marker": MARKERS[i % len(MARKERS)],
                    "linestyle": LINESTYLE[bool(strict[label])]}
            for i, label in enumerate(sorted(strict.index))}


def _legend(ax) -> None:
    """Legend outside the axes on the right (never over the data)."""
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)


def _readable_log_ticks(ax) -> None:
    """Plain numbers on log axes (1, 2, 5, 10, 20, ...) instead of 2 x 10^1; the
    minor ticks (2, 5) are labelled only on an axis spanning at most 2 decades
    (over more, their labels run into each other: 200000500000)."""
    fmt = matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}")
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(fmt)
        axis.set_minor_locator(matplotlib.ticker.LogLocator(subs=(2.0, 5.0)))
        axis.set_minor_formatter(matplotlib.ticker.FuncFormatter(
            lambda v, _, axis=axis: f"{v:g}" if _decades(axis) <= 2 else ""))
        axis.set_tick_params(which="minor", labelsize=7)


def _decades(axis) -> float:
    lo, hi = sorted(axis.get_view_interval())
    return float(np.log10(hi / lo)) if lo > 0 else float("inf")


def _finish(fig, ax, path: Path, title: str) -> Path:
    ax.set_title(title, fontsize=11)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fit_title(fig, ax)
    fig.savefig(path)
    plt.close(fig)
    return path


def title_fits(fig, ax) -> bool:
    """Whether the axes' title lies inside the figure (drawn: nothing cut off)."""
    fig.canvas.draw()
    box, page = ax.title.get_window_extent(), fig.bbox
    return box.x0 >= page.x0 and box.x1 <= page.x1 and box.y1 <= page.y1


def fit_title(fig, ax, tries: int = 4) -> None:
    """Wrap the title of ``ax`` onto more lines until it fits in ``fig``
    (a long title centred over axes narrowed by an outside legend ran off the
    figure's left edge); ValueError when it still does not after ``tries``."""
    for _ in range(tries):
        if title_fits(fig, ax):
            return
        text = ax.get_title()
        box, page = ax.title.get_window_extent(), fig.bbox
        centre = (box.x0 + box.x1) / 2  # (over the axes, not the figure: the room is the nearer edge's twice)
        room = 2 * min(centre - page.x0, page.x1 - centre)
        longest = max(len(line) for line in text.splitlines())
        width = max(20, int(longest * room / box.width * 0.95))
        ax.set_title("\n".join(textwrap.fill(line, width) for line in text.splitlines()), fontsize=11)
        fig.tight_layout()
    if not title_fits(fig, ax):
        raise ValueError(f"figure title does not fit its figure: {ax.get_title()!r}")


def plot_sweep(g: pd.DataFrame, var: str, path: Path, title: str, mode: str = "cold",
               vline: tuple[float, str] | None = None, *, styles: dict[str, dict]) -> tuple[Path | None, dict]:
    """Median time vs ``var`` per solver, log-log, from the verified rows only,
    fitted slopes in the legend; a size where a solver was not verified has no
    point, and the legend says how many sizes were verified of those it
    attempted (unsupported rows left out). ``vline = (x, label)`` marks e.g.
    the depth where the DOF are saturated. Returns (path, {solver label:
    (slope, std. err., sizes verified, sizes attempted)})."""
    g = g[(g["mode"] == mode) & (g["status"] != "unsupported")]
    ok = timed(g) & (g[var] > 0)
    if not ok.any():
        return None, {}
    fig, ax = plt.subplots(figsize=_STYLE["figsize"], dpi=_STYLE["dpi"])
    slopes = {}
    for label, s in g.groupby(solver_label(g)):
        v = s[ok.loc[s.index]]
        med = v.groupby(var)["time_median_s"].median().sort_index()
        slope, se = loglog_slope(v[var], v["time_median_s"])
        sizes, tried = len(med), s[var].nunique()
        slopes[label] = (slope, se, sizes, tried)
        note = f"slope {slope:.2f}" if np.isfinite(slope) else "no slope: < 3 sizes"
        if sizes < tried:
            note += f", {sizes}/{tried} sizes verified"
        ax.plot(med.index, med.to_numpy() * 1e6, **styles[label], label=f"{label} ({note})")
    ax.set_xscale("log")
    ax.set_yscale("log")
    _readable_log_ticks(ax)
    ax.set_xlabel({"n": "DOF n (number of variables)", "depth": "number of levels (depth)"}.get(var, var))
    ax.set_ylabel(f"median solve time ({mode}, verified rows) [us]")
    if vline is not None:
        ax.axvline(vline[0], color="0.4", linestyle=":", linewidth=1.2, label=vline[1])
    _legend(ax)
    return _finish(fig, ax, path, title), slopes


def plot_success(df: pd.DataFrame, path: Path) -> Path | None:
    """Heatmap of the success rate per solver and family, each solver judged by
    its own claim: the table of :func:`hikbench.bench.analysis.ranking.success_by`
    (report.md's "Success per family"): strict solvers by ``verified``, non-strict
    ones (labelled so) by level 0 met; the rows a solver declined are left out,
    as are the rows that cannot tell (no certified yardstick)."""
    from hikbench.bench.analysis.ranking import strict_labels, success_by

    if df.empty or (df["status"] == "unsupported").all():
        return None
    df = df.assign(label=solver_label(df))
    strict = strict_labels(df)
    rates, _ = success_by(df, strict, "family")
    tab = rates.set_axis([i if i in strict else f"{i} (non-strict: level 0)" for i in rates.index])
    fig, ax = plt.subplots(figsize=(max(5.5, 2.5 + 1.3 * tab.shape[1]), max(2.8, 1.6 + 0.4 * tab.shape[0])),
                           dpi=_STYLE["dpi"])
    im = ax.imshow(tab.to_numpy() * 100, cmap="RdYlGn", vmin=0, vmax=100, aspect="auto")
    ax.set_xticks(range(tab.shape[1]), tab.columns, rotation=30, ha="right", fontsize=8)
    ax.set_yticks(range(tab.shape[0]), tab.index, fontsize=8)
    for i in range(tab.shape[0]):
        for j in range(tab.shape[1]):
            v = tab.iat[i, j]
            if np.isfinite(v):
                ax.text(j, i, f"{100 * v:.0f}%", ha="center", va="center", fontsize=7)
    fig.colorbar(im, ax=ax, label="success [%]")
    # (two lines: on one, the title of a figure of one or two families was cut at both ends)
    ax.set_title("Success per solver and family, by each solver's claim\n"
                 "(strict: verified; non-strict: level 0 met; unsupported left out)", fontsize=11)
    fig.tight_layout()
    fit_title(fig, ax)
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_profiles(times: pd.DataFrame, path: Path, title: str, *, styles: dict[str, dict]) -> Path | None:
    """Dolan-More performance profiles of a problems x solvers table
    (:func:`hikbench.bench.analysis.shgeom.performance_profile`: NaN, inf or <= 0 = failure)."""
    if times.empty or times.shape[1] == 0:
        return None
    prof = performance_profile(times)
    if prof is None:
        return None
    taus, fractions = prof
    solvers = list(fractions)  # (markers staggered along tau, so overlapping curves still show theirs)
    fig, ax = plt.subplots(figsize=_STYLE["figsize"], dpi=_STYLE["dpi"])
    for s, y in fractions.items():
        st = styles[s]
        ax.step(taus, y, where="post", label=s, color=st["color"], linestyle=st["linestyle"],
                marker=st["marker"], markevery=(solvers.index(s) % 7 * 4, 30), markersize=4)
    ax.set_xscale("log")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("performance ratio tau (time / best time on the problem)")
    ax.set_ylabel("fraction of problems solved within tau")
    _legend(ax)
    return _finish(fig, ax, path, title)


def plot_accuracy(df: pd.DataFrame, path: Path, *, styles: dict[str, dict]) -> Path | None:
    """Median |level norm - reference level norm| per level and solver (each
    ``[[settings]]`` variant a line of its own, its problem count in the legend).
    A level reached by fewer than a tenth of a solver's problems, or by one of
    several, is not drawn: its median would come from a few deep problems (one,
    for the cascades of the paper suite), not from the set the other levels'
    medians describe."""
    d = df[(df["level_norms"] != "") & (df["ref_level_norms"] != "") & (df["mode"] == "cold")]
    if d.empty:
        return None
    fig, ax = plt.subplots(figsize=_STYLE["figsize"], dpi=_STYLE["dpi"])
    for solver, s in d.groupby(solver_label(d)):
        per_level: dict[int, list] = {}
        for a, b in zip(s["level_norms"], s["ref_level_norms"]):
            for k, (u, v) in enumerate(zip(json.loads(a), json.loads(b))):
                if u is not None and v is not None:
                    per_level.setdefault(k, []).append(abs(u - v))
        if per_level:
            n0 = len(per_level[min(per_level)])
            enough = min(n0, max(2, math.ceil(0.1 * n0)))  # (one problem is never enough but when alone)
            ks = [k for k in sorted(per_level) if len(per_level[k]) >= enough]
            ax.plot(ks, [max(np.median(per_level[k]), 1e-17) for k in ks],
                    label=f"{solver} ({n0} problem{'' if n0 == 1 else 's'})", **styles[solver])
    ax.set_yscale("log")
    ax.set_xlabel("level k (0 = highest priority)")
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
    ax.set_ylabel("median | ||v_k(x)|| - ||v_k(x_ref)|| |  [units of the task]")
    _legend(ax)
    return _finish(fig, ax, path, "Per-level accuracy against the yardstick (floored at 1e-17; levels\n"
                   "reached by one or under 10 % of a solver's problems not drawn)")


def plot_cold_warm(df: pd.DataFrame, path: Path, *, styles: dict[str, dict]) -> Path | None:
    """Warm against cold median time per problem and solver (each ``[[settings]]``
    variant a series of its own)."""
    keys = ["problem", "_label"]
    d = df.assign(_label=solver_label(df))
    ok = d[timed(d)]  # log axes
    cold = ok[ok["mode"] == "cold"].set_index(keys)["time_median_s"]
    warm = ok[ok["mode"] == "warm"].set_index(keys)["time_median_s"]
    both = pd.concat([cold.rename("cold"), warm.rename("warm")], axis=1, join="inner")
    if both.empty:
        return None
    fig, ax = plt.subplots(figsize=(8, 6), dpi=_STYLE["dpi"])
    for solver, s in both.groupby(level="_label"):
        st = styles[solver]
        ax.scatter(s["cold"] * 1e6, s["warm"] * 1e6, label=solver, s=22, color=st["color"],
                   marker=st["marker"])
    lo = float(min(both.min())) * 1e6 / 2
    hi = float(max(both.max())) * 1e6 * 2
    ax.plot([lo, hi], [lo, hi], "k--", lw=0.8, label="warm = cold")
    ax.set_xscale("log")
    ax.set_yscale("log")
    _readable_log_ticks(ax)
    ax.set_xlabel("cold solve time (fresh solver) [us]")
    ax.set_ylabel("warm re-solve time (same solver object) [us]")
    _legend(ax)
    return _finish(fig, ax, path, "Cold vs warm: median time per problem")
