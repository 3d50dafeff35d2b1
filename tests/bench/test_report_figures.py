"""The report's figures: one colour and marker per solver, the same in every
figure; line style by claim (solid strict, dashed non-strict); 20 solvers told
apart; titles that fit their figure."""

from __future__ import annotations

import matplotlib.colors
import pandas as pd
import pytest

from hikbench.bench.analysis import plots
from hikbench.bench.analysis.report import write_report
from report_runs import make_row, write_run


@pytest.fixture
def drawn(tmp_path, monkeypatch):
    """{figure file: {series label: (colour, line style)}} of a report of the made-up run."""
    out = {}

    def keep(fig, ax, path, title):
        series = {}
        for line in ax.get_lines():
            if not line.get_label().startswith("_"):
                series[line.get_label()] = (matplotlib.colors.to_hex(line.get_color()), line.get_linestyle())
        for coll in ax.collections:
            if not coll.get_label().startswith("_"):
                series[coll.get_label()] = (matplotlib.colors.to_hex(coll.get_facecolor()[0]), None)
        out[path.name] = series
        plots.plt.close(fig)
        return path

    monkeypatch.setattr(plots, "_finish", keep)
    write_report(write_run(tmp_path / "run"))
    return out


def test_a_solver_has_one_colour_in_every_figure(drawn):
    profile, accuracy = drawn["performance_profile_cold_eq.png"], drawn["accuracy_per_level.png"]
    accuracy = {k.split(" (")[0]: v for k, v in accuracy.items()}
    for solver in ("fast", "slow", "wsum"):
        assert profile[solver][0] == accuracy[solver][0], solver
    assert len({c for c, _ in profile.values()}) == len(profile)  # (distinct solvers, distinct colours)


@pytest.mark.parametrize("solver, style", [("fast", "-"), ("slow", "-"), ("wsum", "--")],
                         ids=["strict-fast", "strict-slow", "non-strict"])
def test_line_style_says_strict_or_not(drawn, solver, style):
    assert drawn["performance_profile_cold_eq.png"][solver][1] == style


def test_twenty_solvers_get_twenty_colours_whatever_the_figure():
    rows = [make_row("equality/depth=2,n=4,rows=2/seed=0", f"s{i:02d}", i % 3 > 0, 1e-5, True) for i in range(20)]
    styles = plots.solver_styles(pd.DataFrame(rows))
    assert len({s["color"] for s in styles.values()}) == 20
    assert len({(s["color"], s["marker"]) for s in styles.values()}) == 20
    # the order is the run's sorted names: a figure holding a few of them does not renumber them
    assert styles["s07"]["color"] == plots.PALETTE[7]


@pytest.mark.parametrize("title", [
    "short",
    "Performance profiles (Dolan-More), cold solves; failures never reach 1\n"
    "12 problems with inequalities (13 solvers; unsupported by dls-liegeois, nullspace-cod, nullspace-svd, "
    "pinv-all, and a few more solvers with long names)",
], ids=["short", "long-two-lines"])
def test_titles_are_wrapped_to_fit(title):
    fig, ax = plots.plt.subplots(figsize=(9.5, 5.0), dpi=110)
    for i in range(12):
        ax.plot([1, 2], [i, i], label=f"a solver with a long name {i}")
    plots._legend(ax)
    ax.set_title(title, fontsize=11)
    fig.tight_layout()
    plots.fit_title(fig, ax)
    assert plots.title_fits(fig, ax)
    plots.plt.close(fig)
