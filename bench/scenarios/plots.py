"""The figures of ICRA 2010 sec. XII for scenario runs (matplotlib, Agg backend).

* Fig. 1 ``fig1_solve_time.png``: solve time per step (ms) of each run
  (warm_start none / stage / time, or several solvers), and the median per run.
* Fig. 2 ``fig2_time_activations.png``: solve time over the run with the steps
  where constraints were activated / deactivated marked (the peaks).
* Fig. 3 ``fig3_joints_<run>.png``: joint trajectories normalised to their
  limits, 2 (q - q_l) / (q_u - q_l) - 1 (so -1 and 1 are the two limits).
* Fig. 4 ``fig4_task_errors.png``: task error norms (log scale), one panel per
  task, one line per run.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

__all__ = ["normalised_joints", "plot_runs"]


def _plt():
    import matplotlib

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


def plot_runs(runs: list, out_dir: str | Path, joints: list[str] | None = None) -> list[Path]:
    """Write the four figures for ``runs`` (ScenarioRun objects of one scenario); returns paths."""
    plt = _plt()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    name = runs[0].scenario.name

    # Fig. 1: solve time per step, per run
    fig, (ax, axb) = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [3, 1]})
    for i, run in enumerate(runs):
        df = run.records
        ax.plot(df["step"], df["solve_time_s"] * 1e3, lw=0.8, color=f"C{i}", label=run.label)
        bad, text = not_optimal(df)
        if bad.any():
            ax.scatter(df["step"][bad], df["solve_time_s"][bad] * 1e3, s=18, facecolors="none",
                       edgecolors=f"C{i}", zorder=3, label=f"{run.label}: not optimal ({text})")
    ax.set_xlabel("control step")
    ax.set_ylabel("solve time (ms)")
    ax.set_yscale("log")
    ax.set_title(f"{name}: solve time per step (Fig. 1)")
    # (below the axes: inside, the legend covered the lines of the slower runs)
    ax.legend(title="solver (warm start)", fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=3)
    med = [float(np.median(r.records["solve_time_s"])) * 1e3 for r in runs]
    axb.bar(range(len(runs)), med, color=[f"C{i}" for i in range(len(runs))])
    axb.set_xticks(range(len(runs)), [r.label for r in runs], rotation=30, ha="right")
    axb.set_ylabel("median solve time (ms)")
    axb.set_title("median per run")
    fig.tight_layout()
    paths.append(out / "fig1_solve_time.png")
    fig.savefig(paths[-1], dpi=110, bbox_inches="tight")
    plt.close(fig)

    # Fig. 2: time over the run, activation peaks marked
    fig, axes = plt.subplots(len(runs), 1, figsize=(10, 2.6 * len(runs)), sharex=True, squeeze=False)
    for ax, run in zip(axes[:, 0], runs):
        df = run.records
        t_ms = df["solve_time_s"].to_numpy() * 1e3
        ax.plot(df["step"], t_ms, lw=0.8, color="C0", label="solve time")
        act = df["activations"].to_numpy() > 0
        deact = df["deactivations"].to_numpy() > 0
        ax.scatter(df["step"][act], t_ms[act], s=14, color="C3", zorder=3,
                   label=f"activation ({int(act.sum())} steps)")
        ax.scatter(df["step"][deact], t_ms[deact], s=14, marker="x", color="C2", zorder=3,
                   label=f"deactivation ({int(deact.sum())} steps)")
        bad, text = not_optimal(df)
        if bad.any():
            ax.scatter(df["step"][bad], t_ms[bad], s=40, facecolors="none", edgecolors="k", zorder=4,
                       label=f"status not optimal ({text})")
        if not (act.any() or deact.any()):
            ax.text(0.01, 0.9, "solver reports no active-set changes", transform=ax.transAxes, fontsize=8)
        ax.set_ylabel("solve time (ms)")
        ax.set_title(f"{name} — {run.label}: cost over the run (Fig. 2)", fontsize=10)
        ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5))  # (outside: no data hidden)
    axes[-1, 0].set_xlabel("control step")
    fig.tight_layout()
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
        for i in idx:
            ax.plot(t, z[:, i], lw=1.0, label=names[i])
        ax.axhline(1.0, color="k", ls="--", lw=0.8)
        ax.axhline(-1.0, color="k", ls="--", lw=0.8)
        for te in _events_within(run.scenario, t[-1]):
            ax.axvline(te, color="grey", ls=":", lw=0.8)
        ax.set_ylim(-1.1, 1.1)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("2 (q - q_l) / (q_u - q_l) - 1  (limits at ±1)")
        ax.set_title(f"{name} — {run.label}: normalised joint trajectories (Fig. 3)")
        ax.legend(fontsize=7, ncol=2, loc="center left", bbox_to_anchor=(1.0, 0.5))
        fig.tight_layout()
        paths.append(out / f"fig3_joints_{_slug(run.label)}.png")
        fig.savefig(paths[-1], dpi=110, bbox_inches="tight")
        plt.close(fig)

    # Fig. 4: task errors, one panel per task, one line per run
    stack = runs[0].scenario.stack
    tasks = [t for t in stack.tasks if t.kind == "equality" and f"err_{t.name}" in runs[0].records
             and type(t).__name__ != "MinimalVelocityTask"]
    ncol = min(3, len(tasks))
    nrow = int(np.ceil(len(tasks) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.0 * nrow), squeeze=False, sharex=True)
    for ax, task in zip(axes.flat, tasks):
        for i, run in enumerate(runs):
            df = run.records
            ax.semilogy(df["time_s"], np.maximum(df[f"err_{task.name}"], 1e-16), lw=1.0, color=f"C{i}",
                        label=run.label)
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
