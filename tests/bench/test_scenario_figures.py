"""Scenario figures of a run cut short by --steps: the time axis ends with the data."""

import matplotlib.axes
import numpy as np
import pandas as pd

from bench.scenario import ScenarioRun
from bench.scenario_plots import plot_runs
from problems.robots.scenarios import load_scenario


def _short_run(sc, steps):
    """A run of ``steps`` steps that stood still (no solve needed to draw its figures)."""
    t = np.arange(steps) * sc.dt
    rec = pd.DataFrame({"step": np.arange(steps), "time_s": t, "solve_time_s": 1e-4, "activations": 0,
                        "deactivations": 0, **{f"err_{task.name}": 1e-3 for task in sc.stack.tasks}})
    return ScenarioRun(sc, "hcod", "time", rec, np.tile(sc.q_init, (steps + 1, 1)))


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
    paths = plot_runs([_short_run(sc, steps)], tmp_path)
    assert all(p.exists() for p in paths)
    assert [x for x in drawn if x > steps * sc.dt] == [], f"event lines past the run's end: {drawn}"
