"""Scenario figures of a run cut short by --steps: the time axis ends with the data; steps
whose status is not optimal are marked (and counted in the legend) in Figs. 1 and 2."""

import matplotlib.axes
from doubles import still_run

from bench.scenario_plots import plot_runs
from problems.robots.scenarios import load_scenario


def test_event_lines_of_later_events_are_not_drawn(tmp_path, monkeypatch):
    sc = load_scenario("reach")
    steps = 10
    assert sc.event_times() and min(sc.event_times()) > steps * sc.dt  # the event comes after the run
    drawn = []
    real = matplotlib.axes.Axes.axvline

    def spy(self, x=0, *args, **kwargs):
        drawn.append(x)
        return real(self, x, *args, **kwargs)

    monkeypatch.setattr(matplotlib.axes.Axes, "axvline", spy)
    paths = plot_runs([still_run(sc, steps)], tmp_path)
    assert all(p.exists() for p in paths)
    assert [x for x in drawn if x > steps * sc.dt] == [], f"event lines past the run's end: {drawn}"


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
