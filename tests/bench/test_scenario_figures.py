"""Scenario figures of a run cut short by --steps: the time axis ends with the data; steps
whose status is not optimal are marked (and counted in the legend) in Figs. 1 and 2."""

import matplotlib.axes
import pytest
from doubles import still_run

from hikbench.bench.scenarios.plots import plot_runs
from hikbench.problems.robots.scenarios import load_scenario


@pytest.mark.parametrize("steps", [10, 310], ids=["run-ends-before-the-event", "run-covers-the-event"])
def test_event_lines_are_drawn_within_the_run_only(tmp_path, monkeypatch, steps):
    """An event (the reach scenario's target switch at 3 s) gets a line in Figs. 3 and 4 when the
    run reaches it, none when the run ends before it."""
    sc = load_scenario("reach")
    assert sc.event_times() == [3.0]  # (the scenario file: a run of 10 steps ends before it)
    drawn = []
    real = matplotlib.axes.Axes.axvline

    def spy(self, x=0, *args, **kwargs):
        drawn.append((x, self))  # (the axes kept: their figures stay distinct objects)
        return real(self, x, *args, **kwargs)

    monkeypatch.setattr(matplotlib.axes.Axes, "axvline", spy)
    paths = plot_runs([still_run(sc, steps)], tmp_path)
    assert all(p.exists() for p in paths)
    if (steps - 1) * sc.dt >= 3.0:  # (the last step's time)
        assert {x for x, _ in drawn} == {3.0}, drawn
        panels = {}  # figure -> its axes with the line: Fig. 3 one, Fig. 4 one per task panel
        for _, ax in drawn:
            panels.setdefault(ax.figure, set()).add(ax)
        assert sorted(len(a) for a in panels.values()) == [1, len(drawn) - 1] and len(drawn) >= 3, drawn
    else:
        assert drawn == []


def test_steps_that_are_not_optimal_are_marked(tmp_path, monkeypatch):
    sc = load_scenario("reach")
    status = ["optimal", "infeasible_level", "optimal", "infeasible_level", "max_iterations", "optimal"]
    labels = []
    real = matplotlib.axes.Axes.scatter

    def spy(self, x, y, *args, **kwargs):
        labels.append((kwargs.get("label", ""), list(x)))
        return real(self, x, y, *args, **kwargs)

    monkeypatch.setattr(matplotlib.axes.Axes, "scatter", spy)
    plot_runs([still_run(sc, 6, status), still_run(sc, 6)], tmp_path)
    marked = [(lab, x) for lab, x in labels if "not optimal" in lab]
    assert marked == [("hcod (time): not optimal (infeasible_level 2, max_iterations 1)", [1, 3, 4]),
                      ("status not optimal (infeasible_level 2, max_iterations 1)", [1, 3, 4])]


@pytest.mark.parametrize("joints", [None, "all"], ids=["the-12-that-move-most", "every-joint-of-romeo"])
def test_every_joint_of_fig3_has_its_own_colour_and_line_style(tmp_path, monkeypatch, joints):
    """The default colour cycle has 10 colours: the 12 joints drawn by default repeated two."""
    sc = load_scenario("reach", robot="romeo" if joints else None)
    if joints:
        sc.plot_joints = list(sc.robot.bounded_joint_names)  # (55 joints)
    drawn = {}
    real = matplotlib.axes.Axes.plot

    def spy(self, *args, **kwargs):
        lines = real(self, *args, **kwargs)
        for line in lines:
            drawn.setdefault(self, []).append((line.get_label(), line.get_color(), line.get_linestyle()))
        return lines

    monkeypatch.setattr(matplotlib.axes.Axes, "plot", spy)
    plot_runs([still_run(sc, 4)], tmp_path, joints=sc.plot_joints)
    joint_names = set(sc.robot.bounded_joint_names)
    fig3 = [lines for lines in drawn.values() if any(label in joint_names for label, _, _ in lines)]
    assert len(fig3) == 1, drawn
    labels = [label for label, _, _ in fig3[0]]
    styles = [(c, ls) for _, c, ls in fig3[0]]
    assert len(labels) == (len(joint_names) if joints else 12)
    assert len(set(styles)) == len(styles), styles


def test_too_many_plotted_joints_are_refused_on_loading(tmp_path):
    from hikbench.problems.robots.scenarios import PLOT_JOINTS_MAX, ScenarioError

    f = tmp_path / "s.toml"
    f.write_text('name = "s"\nstack = "arm_reach"\n[plot]\njoints = [' + ", ".join(['"panda_joint1"'] * 81) + "]\n")
    with pytest.raises(ScenarioError, match=f"plot.joints: 81 joints; expected at most {PLOT_JOINTS_MAX}"):
        load_scenario(f)
