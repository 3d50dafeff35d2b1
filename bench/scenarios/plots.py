"""The figures of ICRA 2010 sec. XII for scenario runs (matplotlib, Agg backend).

Times are the solver's cost per step, ``solve_time_min_s`` (the minimum of
the step's timed calls, bench/scenarios/runner.py), drawn with the first
call's time (``solve_time_first_s``, what a controller sees, a pause of the
machine included) faint behind it. A solver has the colour and marker of
the run report's figures (:func:`hikbench.bench.analysis.plots.solver_styles`
over every installed solver, as a ``solvers = ["*"]`` suite selects them);
a solver's warm-start modes are told apart by line style and shade (time:
solid, the solver's colour; stage: dash-dot, lighter; none: dotted,
lighter still; a solver without modes: solid, dashed if non-strict).

* Fig. 1 ``fig1_solve_time.png``: solve time per step (ms) of each run
  (warm_start none / stage / time, or several solvers), and per run the
  median and the worst step; below, the solver's own iterations per step,
  and per run the mean iterations and activations of a step.
* Fig. 2 ``fig2_time_activations.png``: one panel per run, the solve time
  over the run, and below it a tick at every step where the active set
  changed: rows entering (``rows_entered``) and leaving (``rows_left``),
  found from u alike for every solver. (Not the solver's own
  ``activations``: they count from its starting active set, so a solver that
  starts cold, hcod with warm_start none or stage, counts every active row
  at every step, and every step was marked.)
* Fig. 3 ``fig3_joints_<run>.png``: joint trajectories normalised to their
  limits, 2 (q - q_l) / (q_u - q_l) - 1 (so -1 and 1 are the two limits), each
  joint its own colour and line style (:func:`joint_styles`).
* Fig. 4 ``fig4_task_errors.png``: task error norms (log scale), one panel per
  task, one line per run (the styles of Figs. 1-2).
"""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

import matplotlib
import matplotlib.colors
import numpy as np

__all__ = ["normalised_joints", "plot_runs", "run_strict", "run_styles"]

#: line style and shade (1: the solver's colour, less: mixed with white) of a warm-start mode
MODE_STYLE = {"time": ("-", 1.0), "stage": ("-.", 0.7), "none": (":", 0.45)}
FAINT = 0.3  #: alpha of the first-call times behind the solver's cost
#: Fig. 3's joint styles: the 20 colours of tab20, then again with each further line style
JOINT_LINESTYLES = ("-", "--", "-.", ":")


def joint_styles(count: int) -> list[dict]:
    """``count`` distinct (colour, line style) pairs for Fig. 3's joints: the 20 colours of
    matplotlib's ``tab20`` (the default cycle has 10, so 12 joints repeated two), then
    again with the next line style (at most 80: ``PLOT_JOINTS_MAX`` of a scenario file)."""
    colours = matplotlib.colormaps["tab20"].colors
    if count > len(colours) * len(JOINT_LINESTYLES):  # (a scenario file's [plot] joints are checked on loading)
        raise ValueError(f"{count} joints: Fig. 3 draws at most {len(colours) * len(JOINT_LINESTYLES)} "
                         "distinguishable lines")
    return [{"color": matplotlib.colors.to_hex(colours[k % len(colours)]),
             "linestyle": JOINT_LINESTYLES[k // len(colours)]} for k in range(count)]


def _plt():
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_")


def _events_within(scenario, t_end: float) -> list[float]:
    """The scenario's event times up to ``t_end`` (a run cut short by --steps
    ends before later events: a line there would stretch the time axis past the data)."""
    return [te for te in scenario.event_times() if te <= t_end]


def normalised_joints(run) -> tuple[np.ndarray, list[str]]:
    """(steps + 1, nb) joint trajectory mapped to [-1, 1] by the limits, and joint names."""
    robot = run.scenario.robot
    qb = run.q[:, robot.bounded_q]
    z = 2.0 * (qb - robot.lower) / (robot.upper - robot.lower) - 1.0
    return z, list(robot.bounded_joint_names)


def not_optimal(records) -> tuple[np.ndarray, str]:
    """The steps whose solve status is not ``optimal`` (bool mask, shape
    (steps,)) and the statuses with their counts, e.g. "infeasible_level 22"
    (empty when every step is optimal): the figures mark those steps, so a
    run whose solver failed on some steps does not look like a clean one."""
    bad = (records["status"] != "optimal").to_numpy()
    counts = records.loc[bad, "status"].value_counts()
    return bad, ", ".join(f"{k} {v}" for k, v in counts.sort_index().items())


def run_strict(run) -> bool:
    """The solver's claim (``strict``): the registry's, a ``module:Class``'s attribute
    (default True), a scenario controller's (pink: False)."""
    from hikbench.bench.scenarios.controllers import controller_class
    from hikbench.bench.specs import CONTROLLER, REGISTRY, SolverSpec
    from hikbench.solvers import registry

    spec = SolverSpec.parse(run.solver, controllers=True)
    if spec.kind == CONTROLLER:
        return bool(controller_class(run.solver).strict)
    if spec.kind == REGISTRY and spec.text in registry.available():
        return registry.get(spec.text).strict
    return bool(getattr(spec.info().factory, "strict", True))


def run_styles(runs: list) -> dict[str, dict]:
    """{run label: color, marker, linestyle}: the solver's colour and marker of
    the run report (module docstring), the line style of its warm-start mode. A
    scenario controller (pink, not in the run report) takes the next colour
    after every solver's, dashed when not strict."""
    import pandas as pd

    from hikbench.bench.analysis.plots import LINESTYLE, MARKERS, PALETTE, solver_styles
    from hikbench.bench.scenarios.controllers import is_controller
    from hikbench.solvers import registry

    strict = {name: info.strict for name, info in registry.available().items()}
    for run in runs:  # (a module:Class solver: its own place after the registry's)
        if not is_controller(run.solver):
            strict.setdefault(run.solver, run_strict(run))
    styles = solver_styles(pd.DataFrame({"solver": list(strict), "settings": "default",
                                         "strict": [str(v) for v in strict.values()]}))
    for i, run in enumerate(r for r in runs if is_controller(r.solver) and r.solver not in styles):
        k = len(strict) + i
        styles[run.solver] = {"color": PALETTE[k % len(PALETTE)], "marker": MARKERS[k % len(MARKERS)],
                              "linestyle": LINESTYLE[run_strict(run)]}
    out = {}
    for run in runs:
        st = dict(styles[run.solver])
        if run.warm_start in MODE_STYLE:
            ls, shade = MODE_STYLE[run.warm_start]
            rgb = np.asarray(matplotlib.colors.to_rgb(st["color"]))
            st.update(linestyle=ls, color=matplotlib.colors.to_hex(1.0 - shade * (1.0 - rgb)))
        out[run.label] = st
    return out


def _short(label: str) -> str:
    """A run's label without the folders of a ``path/file.py:Class`` solver."""
    return re.sub(r"\S*/", "", label)


def _ms(df, column: str) -> np.ndarray:
    return df[column].to_numpy(dtype=float) * 1e3


def _cost_lines(ax, df, style: dict, label: str, ls: str | None = None) -> None:
    """The first-call times faint, the per-step minimum over them (ms)."""
    every = max(1, len(df) // 12)
    ax.plot(df["step"], _ms(df, "solve_time_first_s"), lw=0.6, color=style["color"], alpha=FAINT,
            label=f"{label}: first call")
    ax.plot(df["step"], _ms(df, "solve_time_min_s"), lw=1.0, color=style["color"], ls=ls or style["linestyle"],
            marker=style["marker"], markevery=every, ms=4, label=f"{label}: solver's cost")


def _room_below(lo: float, hi: float, share: float = 0.15) -> tuple[float, float]:
    """Log-axis limits putting ``lo`` at ``share`` of the height (the ticks of _rug go below it)."""
    a, b = np.log10(lo), np.log10(hi)
    return 10 ** ((a - share * b) / (1 - share)), hi


def _rug(ax, steps, mask: np.ndarray, y: float, color: str, label: str) -> None:
    """A tick at each step of ``mask``, at height ``y`` in axes units (below the data)."""
    ax.plot(np.asarray(steps)[mask], np.full(int(mask.sum()), y), ls="none", marker="|", ms=7, mew=1.0,
            color=color, transform=ax.get_xaxis_transform(), label=label)


def _fit(fig, axes) -> None:
    """tight_layout, then the titles that run off the figure wrapped (one draw when all fit)."""
    from hikbench.bench.analysis.plots import fit_title

    fig.tight_layout()
    fig.canvas.draw()
    page = fig.bbox
    for ax in axes:
        box = ax.title.get_window_extent()
        if ax.get_title() and not (box.x0 >= page.x0 and box.x1 <= page.x1 and box.y1 <= page.y1):
            fit_title(fig, ax)


def _counts(ax, axb, runs: list, styles: dict) -> None:
    """Fig. 1, bottom: the solver's own iterations per step (``iterations``) of each run
    that reports them, and per run the mean iterations and activations of a step (a
    solver that reports neither, such as a QP backend through qpsolvers or pink, is
    named as such)."""
    silent = []
    for run in runs:
        df, st = run.records, styles[run.label]
        it = df["iterations"].to_numpy(dtype=float) if "iterations" in df else np.zeros(len(df))
        if not np.any(it > 0):
            silent.append(_short(run.label))
            continue
        ax.plot(df["step"], it, lw=0.9, color=st["color"], ls=st["linestyle"], label=_short(run.label))
    ax.set_xlabel("control step")
    ax.set_ylabel("iterations (solver's own count)")
    ax.set_title("iterations per step" + (f"; not reported by {', '.join(silent)}" if silent else ""),
                 fontsize=10)
    if len(silent) < len(runs):
        ax.legend(fontsize=8)
    x = np.arange(len(runs))
    for dx, col, hatch in ((-0.2, "iterations", None), (0.2, "activations", "//")):
        axb.bar(x + dx, [float(r.records[col].mean()) if col in r.records else np.nan for r in runs], width=0.4,
                hatch=hatch,
                color=[styles[r.label]["color"] for r in runs], edgecolor="k", lw=0.5, label=f"mean {col}")
    axb.set_xticks(x, [textwrap.fill(_short(r.label), 18) for r in runs], rotation=30, ha="right")
    axb.set_title("mean per step")
    axb.legend(fontsize=7)


def plot_runs(runs: list, out_dir: str | Path, joints: list[str] | None = None) -> list[Path]:
    """Write the four figures for ``runs`` (ScenarioRun objects of one scenario); returns paths."""
    plt = _plt()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    name = runs[0].scenario.name
    styles = run_styles(runs)

    # Fig. 1: solve time per step, per run (top); iterations and activations per step (bottom)
    fig, ((ax, axb), (axi, axc)) = plt.subplots(2, 2, figsize=(11, 8.4), gridspec_kw={"width_ratios": [3, 1]})
    for run in runs:
        df, st = run.records, styles[run.label]
        _cost_lines(ax, df, st, _short(run.label))
        bad, text = not_optimal(df)
        if bad.any():
            ax.scatter(df["step"][bad], _ms(df, "solve_time_min_s")[bad], s=18, facecolors="none",
                       edgecolors=st["color"], zorder=3, label=f"{_short(run.label)}: not optimal ({text})")
    ax.set_xlabel("control step")
    ax.set_ylabel("solve time (ms)")
    ax.set_yscale("log")
    k = sorted({int(v) for r in runs for v in r.records["repeat"]})
    ax.set_title(f"{name}: solve time per step, min of {'/'.join(map(str, k))} calls (first call faint) (Fig. 1)")
    # (below the axes: inside, the legend covered the lines of the slower runs)
    ax.legend(title="solver (warm start)", fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2)
    x = np.arange(len(runs))
    cost = [r.records["solve_time_min_s"].to_numpy(dtype=float) * 1e3 for r in runs]
    axb.bar(x, [np.median(c) for c in cost], color=[styles[r.label]["color"] for r in runs], label="median step")
    axb.scatter(x, [c.max() for c in cost], marker="_", s=200, color="k", zorder=3, label="worst step")
    axb.set_xticks(x, [textwrap.fill(_short(r.label), 18) for r in runs], rotation=30, ha="right")
    axb.set_ylabel("solver's cost per step (ms)")
    axb.set_yscale("log")
    axb.set_title("median and worst step")
    axb.legend(fontsize=7)
    _counts(axi, axc, runs, styles)
    _fit(fig, (ax, axb, axi, axc))
    paths.append(out / "fig1_solve_time.png")
    fig.savefig(paths[-1], dpi=110, bbox_inches="tight")
    plt.close(fig)

    # Fig. 2: time over the run, active-set changes marked
    fig, axes = plt.subplots(len(runs), 1, figsize=(10, 2.8 * len(runs)), sharex=True, squeeze=False)
    for ax, run in zip(axes[:, 0], runs):
        df, st = run.records, styles[run.label]
        t_ms = _ms(df, "solve_time_min_s")
        _cost_lines(ax, df, st, "solve time", ls="-")  # (one run per panel: solid)
        entered = df["rows_entered"].fillna(0).to_numpy() > 0
        left = df["rows_left"].fillna(0).to_numpy() > 0
        _rug(ax, df["step"], entered, 0.09, "#d62728",
             f"rows entering the active set ({int(entered.sum())} steps)")
        _rug(ax, df["step"], left, 0.03, "#2ca02c", f"rows leaving it ({int(left.sum())} steps)")
        ax.set_ylim(*_room_below(np.nanmin(t_ms), 1.5 * np.nanmax(_ms(df, "solve_time_first_s"))))
        bad, text = not_optimal(df)
        if bad.any():
            ax.scatter(df["step"][bad], t_ms[bad], s=40, facecolors="none", edgecolors="k", zorder=4,
                       label=f"status not optimal ({text})")
        if not (entered.any() or left.any()):
            ax.text(0.01, 0.9, "the active set did not change", transform=ax.transAxes, fontsize=8)
        ax.set_yscale("log")
        ax.set_ylabel("solve time (ms)")
        ax.set_title(f"{name} — {_short(run.label)}: solver's cost over the run, active-set changes marked "
                     f"(Fig. 2)", fontsize=10)
        ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5))  # (outside: no data hidden)
    axes[-1, 0].set_xlabel("control step")
    _fit(fig, axes[:, 0])
    paths.append(out / "fig2_time_activations.png")
    fig.savefig(paths[-1], dpi=110, bbox_inches="tight")
    plt.close(fig)

    # Fig. 3: joint trajectories normalised to their limits (one file per run)
    for run in runs:
        z, names = normalised_joints(run)
        idx = [names.index(j) for j in joints or () if j in names]
        if not idx:  # no list, or none of its joints on this robot: the 12 joints that move most
            idx = list(np.argsort(-(z.max(axis=0) - z.min(axis=0)))[:12])
        t = np.arange(len(z)) * run.scenario.dt
        fig, ax = plt.subplots(figsize=(10, 4.5))
        for i, style in zip(idx, joint_styles(len(idx))):
            ax.plot(t, z[:, i], lw=1.0, label=names[i], **style)
        ax.axhline(1.0, color="k", ls="--", lw=0.8)
        ax.axhline(-1.0, color="k", ls="--", lw=0.8)
        for te in _events_within(run.scenario, t[-1]):
            ax.axvline(te, color="grey", ls=":", lw=0.8)
        ax.set_ylim(-1.1, 1.1)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("2 (q - q_l) / (q_u - q_l) - 1  (limits at ±1)")
        ax.set_title(f"{name} — {_short(run.label)}: normalised joint trajectories (Fig. 3)")
        ax.legend(fontsize=7, ncol=2, loc="center left", bbox_to_anchor=(1.0, 0.5))
        fig.tight_layout()
        paths.append(out / f"fig3_joints_{_slug(run.label)}.png")
        fig.savefig(paths[-1], dpi=110, bbox_inches="tight")
        plt.close(fig)

    # Fig. 4: task errors, one panel per task, one line per run
    stack = runs[0].scenario.stack
    tasks = [t for t in stack.tasks if t.relation == "equality" and f"err_{t.name}" in runs[0].records
             and type(t).__name__ != "MinimalVelocityTask"]
    ncol = min(3, len(tasks))
    nrow = int(np.ceil(len(tasks) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.0 * nrow), squeeze=False, sharex=True)
    for ax, task in zip(axes.flat, tasks):
        for run in runs:
            df, st = run.records, styles[run.label]
            ax.semilogy(df["time_s"], np.maximum(df[f"err_{task.name}"], 1e-16), lw=1.0, color=st["color"],
                        ls=st["linestyle"], label=_short(run.label))
        for te in _events_within(runs[0].scenario, max(float(r.records["time_s"].max()) for r in runs)):
            ax.axvline(te, color="grey", ls=":", lw=0.8)
        unit = {"PoseTask": "log6 error (m, rad)", "OrientationTask": "rad", "PostureTask": "rad",
                "DirectionTask": "unit vector", "AlignmentTask": "1 - cos"}.get(type(task).__name__, "m")
        ax.set_title(f"{task.name} (level {next(k for k, lv in enumerate(stack.levels) if task in lv)})",
                     fontsize=10)
        ax.set_ylabel(f"||e|| ({unit})", fontsize=8)
        ax.set_xlabel("time (s)", fontsize=8)
        ax.tick_params(labelbottom=True)
    for ax in list(axes.flat)[len(tasks):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=8)
    fig.suptitle(f"{name}: task errors (Fig. 4)")
    fig.tight_layout()
    paths.append(out / "fig4_task_errors.png")
    fig.savefig(paths[-1], dpi=110, bbox_inches="tight")
    plt.close(fig)
    return paths
