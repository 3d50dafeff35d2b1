"""Scenario steps timed several times: the solver's cost (the minimum) and the first call
(what a controller sees), each call from the controller's warm-start state; the active-set
changes that Fig. 2 marks (hikbench.bench.scenarios.runner)."""

import matplotlib.axes
import numpy as np
import pandas as pd
import pytest
from doubles import spec, still_run

from hikbench.bench.cli import main
from hikbench.bench.scenarios.plots import plot_runs
from hikbench.bench.scenarios.runner import ACTIVE_RTOL, COLUMNS, active_rows, run_scenario
from hikbench.problems.hierarchy import Hierarchy, Level
from hikbench.problems.robots.scenarios import load_scenario


@pytest.fixture(scope="module")
def reach():
    return load_scenario("reach")


def test_every_timed_call_starts_from_the_controllers_state(reach):
    """Each of the 4 objects has answered k calls before step k, as the controller's one object
    has: a runner re-solving on one object would show 1, 5, 9 (and no warm-up call counts)."""
    run = run_scenario(reach, spec("CountingSolver"), steps=3, repeat=4)
    df = run.records
    assert list(df.columns[:len(COLUMNS)]) == list(COLUMNS)
    assert df["iterations"].tolist() == [1, 2, 3]
    assert df["repeat"].tolist() == [4, 4, 4] and df["repeats_agree"].all()
    assert (df["solve_time_min_s"] <= df["solve_time_first_s"]).all() and (df["solve_time_min_s"] > 0).all()


def test_resolve_times_each_object_solving_the_steps_problem_again(reach):
    """--resolve: after the step's timed calls every object solves the same hierarchy once more
    (a second call per object and step: 2 calls a step, the step's record keeps the first's);
    without it the column is empty."""
    df = run_scenario(reach, spec("CountingSolver"), steps=3, repeat=2, resolve=True).records
    assert df["iterations"].tolist() == [1, 3, 5]
    assert (df["resolve_time_min_s"] > 0).all()
    plain = run_scenario(reach, spec("CountingSolver"), steps=1, repeat=2).records
    assert plain["resolve_time_min_s"].isna().all()


def test_objects_that_answer_differently_are_flagged(reach):
    run = run_scenario(reach, spec("SerialSolver"), steps=2, repeat=3)
    assert not run.records["repeats_agree"].any()
    assert run.records["repeat"].eq(3).all()


def test_one_call_per_step_makes_the_minimum_the_first(reach):
    df = run_scenario(reach, spec("CountingSolver"), steps=2, repeat=1).records
    np.testing.assert_array_equal(df["solve_time_min_s"], df["solve_time_first_s"])


def test_active_rows_are_the_inequality_rows_at_or_beyond_a_bound():
    rows = np.eye(7, 2)[[0, 0, 0, 0, 0, 1, 1]]  # A u = u_0 for rows 0..4, u_1 for rows 5..6
    lower = np.array([1.0, -np.inf, 1.0 - 0.5 * ACTIVE_RTOL, 0.0, 1.0 + 1.0, -np.inf, 2.0])
    upper = np.array([1.0, np.inf, 5.0, 1.0 + 2 * ACTIVE_RTOL, 5.0, 3.0 * (1 - 0.5 * ACTIVE_RTOL), 9.0])
    h = Hierarchy.from_levels([Level(rows, lower, upper)])
    # equality, free, near its lower bound, 2 tol inside its upper, violates its lower (1 < 2),
    # near its upper (relative to |3|), inside
    np.testing.assert_array_equal(active_rows(h, np.array([1.0, 3.0])),
                                  [False, False, True, False, True, True, False])


def test_a_cold_starting_solver_counts_activations_at_every_step_the_active_set_does_not_change_so(reach):
    """hcod with warm_start none activates every active row again at every step (its own
    `activations` > 0 at each step, which Fig. 2 marked); the active set found from u changes
    on some steps only."""
    df = run_scenario(reach, "hcod", warm_start="none", steps=12, repeat=2).records
    assert (df["activations"] > 0).all()
    assert df["rows_entered"].isna().iloc[0] and df["rows_entered"].iloc[1:].notna().all()
    changed = (df["rows_entered"] > 0) | (df["rows_left"] > 0)
    assert 0 < changed.sum() < len(df) - 1, df[["activations", "active_rows", "rows_entered", "rows_left"]]


def test_fig2_marks_the_active_set_changes_not_the_solvers_activations(tmp_path, monkeypatch, reach):
    run = still_run(reach, 6)
    run.records["activations"] = 1  # (a cold start: every step)
    run.records["rows_entered"] = [np.nan, 0, 2, 0, 1, 0]
    run.records["rows_left"] = [np.nan, 0, 0, 1, 0, 0]
    marks = {}
    real = matplotlib.axes.Axes.plot

    def spy(self, *args, **kwargs):
        label = kwargs.get("label", "")
        if label.startswith("rows "):
            marks[label] = list(args[0])
        return real(self, *args, **kwargs)

    monkeypatch.setattr(matplotlib.axes.Axes, "plot", spy)
    plot_runs([run], tmp_path)
    assert marks == {"rows entering the active set (2 steps)": [2, 4], "rows leaving it (1 steps)": [3]}


def test_scenario_figures_use_the_run_reports_solver_colours(reach):
    """hcod and cascade-daqp get the colour and marker the quick and paper reports give them
    (every installed solver, sorted); hcod's warm-start modes keep its marker, time its colour."""
    from hikbench.bench.analysis.plots import solver_styles
    from hikbench.bench.scenarios.plots import run_styles
    from hikbench.solvers import registry

    infos = registry.available()
    report = solver_styles(pd.DataFrame({"solver": list(infos), "settings": "default",
                                         "strict": [str(i.strict) for i in infos.values()]}))
    runs = [still_run(reach, 2), still_run(reach, 2)]
    runs[1].solver, runs[1].warm_start = "cascade-daqp", "n/a"
    runs.append(still_run(reach, 2))
    runs[2].warm_start = "none"
    styles = run_styles(runs)
    assert styles["hcod (time)"] == report["hcod"]
    assert styles["cascade-daqp"] == report["cascade-daqp"]
    assert styles["hcod (none)"]["marker"] == report["hcod"]["marker"]
    assert styles["hcod (none)"]["color"] != report["hcod"]["color"] and styles["hcod (none)"]["linestyle"] == ":"


def test_cli_repeat(tmp_path, capsys):
    assert main(["scenario", "reach", "--steps", "2", "--repeat", "0", "--out", str(tmp_path)]) == 2
    assert "--repeat must be >= 1; got 0" in capsys.readouterr().err
    assert main(["scenario", "reach", "--steps", "2", "--repeat", "3", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "solve time per step (min of 3 calls) median" in out and "first call median" in out
    df = pd.read_csv(tmp_path / "reach_talos_hcod_time.csv")  # (hcod, the default solver)
    assert df["repeat"].eq(3).all() and (df["solve_time_min_s"] <= df["solve_time_first_s"]).all()


def test_long_solver_names_fit_the_figures(tmp_path, monkeypatch, reach):
    """A file.py:Class solver is named without its folders; a long module:Class name is wrapped
    under the bars: every title fits (one of them did not, and the command stopped)."""
    import matplotlib.figure

    from hikbench.bench.analysis.plots import title_fits

    saved = []
    real = matplotlib.figure.Figure.savefig

    def spy(self, *args, **kwargs):
        saved.append(all(title_fits(self, ax) for ax in self.axes if ax.get_title()))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", spy)
    runs = []
    for solver, mode in ((spec("WarmReference"), "none"), (spec("WarmReference"), "time"),
                         ("hikbench.solvers.yardstick:YardstickSolver", "n/a")):
        run = still_run(reach, 3)
        run.solver, run.warm_start = solver, mode
        runs.append(run)
    paths = plot_runs(runs, tmp_path)
    assert len(paths) == len(saved) and all(saved), saved


def _loaded(name: str):
    """The class the runner builds for ``spec(name)`` (a file.py:Class is imported as its own module)."""
    from hikbench.bench.specs import SolverSpec

    return SolverSpec.parse(spec(name)).info().factory


def test_interleaved_modes_take_turns_at_every_step(reach):
    """run_interleaved: at step k every mode's objects solve the step, the modes taken in turn
    from mode k mod 3 on (so that the machine's drift falls on every mode alike); one warm-up
    call per mode first."""
    from hikbench.bench.scenarios.runner import run_interleaved

    LoggedModes = _loaded("LoggedModes")
    LoggedModes.log.clear()
    runs = run_interleaved(reach, spec("LoggedModes"), ["none", "stage", "time"], steps=3, repeat=2)
    assert [r.warm_start for r in runs] == ["none", "stage", "time"]
    per_step = [m for m in ["none", "stage", "time"] for _ in range(2)]
    turns = [per_step[2 * k:] + per_step[:2 * k] for k in range(3)]
    assert LoggedModes.log == ["none", "stage", "time"] + [m for t in turns for m in t]
    for run in runs:
        assert run.records["step"].tolist() == [0, 1, 2] and (run.records["solve_time_min_s"] > 0).all()


def test_interleaved_modes_follow_the_first_modes_u(reach):
    """The loop follows the first mode's u: every run has its trajectory, and x_gap_to_first
    shows the mode whose x is another (stage: the reference's + 1e-3) and 0 for the others."""
    from hikbench.bench.scenarios.runner import run_interleaved

    runs = run_interleaved(reach, spec("LoggedModes"), ["none", "stage", "time"], steps=3, repeat=1)
    for run in runs:
        np.testing.assert_array_equal(run.q, runs[0].q)
    gaps = {r.warm_start: r.records["x_gap_to_first"].to_numpy() for r in runs}
    np.testing.assert_array_equal(gaps["none"], 0.0)
    np.testing.assert_array_equal(gaps["time"], 0.0)
    np.testing.assert_allclose(gaps["stage"], 1e-3, rtol=1e-9)
    alone = run_scenario(reach, spec("LoggedModes"), warm_start="stage", steps=3, repeat=1)
    assert "x_gap_to_first" not in alone.records and not np.array_equal(alone.q, runs[0].q)


@pytest.mark.parametrize("flag, interleaved", [([], True), (["--no-interleave"], False)],
                         ids=["default", "no-interleave"])
def test_scenario_interleaves_several_modes_unless_told_not_to(tmp_path, capsys, flag, interleaved):
    LoggedModes = _loaded("LoggedModes")
    LoggedModes.log.clear()
    code = main(["scenario", "reach", "--solver", spec("LoggedModes"), "--warm-start", "none", "time",
                 "--steps", "2", "--repeat", "1", "--out", str(tmp_path), *flag])
    out = capsys.readouterr().out
    assert code == 0
    assert ("interleaved step by step" in out) is interleaved
    calls = LoggedModes.log[2:] if interleaved else LoggedModes.log
    expected = ["none", "time", "time", "none"] if interleaved else ["none", "none", "none", "time", "time", "time"]
    assert calls == expected
    csv = pd.read_csv(next(tmp_path.glob("*time*.csv")))
    assert ("x_gap_to_first" in csv) is interleaved
