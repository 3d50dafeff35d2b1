"""Time-vs-size sweeps in report.md and plots: a slope is fitted only on 3 or
more verified sizes, and sizes where a solver was not verified are counted,
not silently dropped."""

import json

import numpy as np
import pandas as pd
import pytest

from hikbench.bench.harness.columns import names
from hikbench.bench.analysis.plots import loglog_slope, plot_sweep, solver_styles
from hikbench.bench.analysis.report import write_report

SIZES = (6, 12, 24, 48)


def _row(solver, n, t, verified=True, status="optimal"):
    r = {c: None for c in names()}
    r.update(problem=f"equality/depth=3,n={n},rows=4/seed=0", family="equality",
             params=json.dumps({"depth": 3, "n": n, "rows": 4}), seed=0, n=n, depth=3, solver=solver,
             settings="default", options="{}", strict=True, mode="cold", repeat=1, status=status,
             verified=verified, time_median_s=t, time_min_s=t, time_p90_s=t, time_p99_s=t, time_max_s=t,
             host="h", calib_ns=1e6)
    return r


def _rows():
    rows = [_row("all", n, 1e-5 * n) for n in SIZES]                      # slope 1 on 4 sizes
    rows += [_row("half", n, 1e-4, verified=n <= 12) for n in SIZES]      # verified on 2 sizes only
    rows += [_row("declines", n, np.nan, verified=False, status="unsupported") for n in SIZES]
    return rows


def test_sweep_slopes_need_three_verified_sizes(tmp_path):
    df = pd.DataFrame(_rows())
    path, slopes = plot_sweep(df, "n", tmp_path / "s.png", "t", styles=solver_styles(df))
    assert path == tmp_path / "s.png" and path.exists()
    assert slopes["all"][0] == pytest.approx(1.0, rel=1e-9) and slopes["all"][2:] == (4, 4)
    assert np.isnan(slopes["half"][0]) and slopes["half"][2:] == (2, 4)  # 2 points: no fitted slope
    assert "declines" not in slopes  # unsupported everywhere: not a solver of this sweep
    assert np.isnan(loglog_slope([1, 2], [1, 2])[0])


def test_report_slope_table_counts_verified_sizes(tmp_path):
    pd.DataFrame(_rows(), columns=names()).to_csv(tmp_path / "results.csv", index=False)
    md = write_report(tmp_path).read_text().splitlines()
    i = next(k for k, ln in enumerate(md) if ln.startswith("### Log-log slope of cold time vs DOF"))
    assert "verified rows" in md[i]
    table = {ln.split("|")[1].strip(): [c.strip() for c in ln.strip("|").split("|")] for ln in md[i + 4:i + 6]}
    assert table["all"] == ["all", "1.00", "0.00", "4/4"]
    assert table["half"] == ["half", "-", "-", "2/4"]


@pytest.mark.parametrize("hi, labelled", [(50.0, True), (1e5, False)], ids=["2 decades", "5 decades"])
def test_minor_tick_labels_only_on_narrow_log_axes(hi, labelled):
    """Over many decades the labels of the 2 and 5 minor ticks ran into each other (200000500000)."""
    import matplotlib.pyplot as plt

    from hikbench.bench.analysis.plots import _readable_log_ticks

    fig, ax = plt.subplots()
    ax.plot([1.0, hi], [1.0, hi])
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(1.0, hi)
    _readable_log_ticks(ax)
    fig.canvas.draw()
    texts = [t.get_text() for t in ax.xaxis.get_minorticklabels() if t.get_text()]
    plt.close(fig)
    assert bool(texts) == labelled, texts


def test_settings_variants_are_series_of_their_own_with_one_colour_per_solver(tmp_path, monkeypatch):
    """In accuracy_per_level.png and cold_vs_warm.png each of a solver's `[[settings]]`
    variants (cascade-osqp default at 1e-10, `low` at 1e-6) is a series of its own, not one line
    per solver name, and a label has the same colour in every figure (its place in the run's
    sorted labels)."""
    import matplotlib.colors

    from hikbench.bench.analysis import plots

    drawn = {}

    def keep(fig, ax, path, title):
        drawn[path.name] = {h.get_label(): matplotlib.colors.to_hex(
            h.get_color() if hasattr(h, "get_color") else h.get_facecolor()[0])
            for h in ax.get_legend_handles_labels()[0]}
        plots.plt.close(fig)
        return path

    monkeypatch.setattr(plots, "_finish", keep)
    rows = []
    for settings, err in (("default", 1e-10), ("low", 1e-6)):
        for n in SIZES:
            for mode, t in (("cold", 2e-5), ("warm", 1e-5)):
                r = _row("osqp", n, t)
                r.update(settings=settings, mode=mode, level_norms=json.dumps([err, 1.0]),
                         ref_level_norms=json.dumps([0.0, 1.0]))
                rows.append(r)
    df = pd.DataFrame(rows)
    styles = plots.solver_styles(pd.concat([df, pd.DataFrame([_row("aaa", 6, 1e-5)])]))  # (the run's labels)
    plots.plot_accuracy(df, tmp_path / "acc.png", styles=styles)
    plots.plot_cold_warm(df, tmp_path / "cw.png", styles=styles)
    acc, cw = drawn["acc.png"], drawn["cw.png"]
    assert set(acc) == {"osqp (4 problems)", "osqp [low] (4 problems)"}  # (the count: the cold rows)
    acc = {k.removesuffix(" (4 problems)"): v for k, v in acc.items()}
    assert set(cw) == {"osqp", "osqp [low]", "warm = cold"}
    for label, i in (("osqp", 1), ("osqp [low]", 2)):
        assert acc[label] == cw[label] == matplotlib.colors.to_hex(plots.PALETTE[i]), (label, acc, cw)


def test_accuracy_per_level_leaves_out_levels_few_problems_reach(tmp_path, monkeypatch):
    """A level reached by fewer than a tenth of a solver's problems, or by one problem of
    several, is not drawn: in the paper suite every cascade line would otherwise dip to the 1e-17
    floor at level 9 and come back at level 10, from the one problem with more than 8 levels."""
    from hikbench.bench.analysis import plots

    drawn = {}

    def keep(fig, ax, path, title):
        drawn.update({ln.get_label(): list(ln.get_xdata()) for ln in ax.get_lines()})
        plots.plt.close(fig)
        return path

    monkeypatch.setattr(plots, "_finish", keep)
    rows = []
    for solver, count in (("qp", 20), ("ns", 8), ("one", 1)):  # 3 levels, the first problem 12
        for i in range(count):
            depth = 12 if i == 0 else 3
            r = _row(solver, 6, 1e-5)
            r.update(problem=f"p{i}", level_norms=json.dumps([1e-9] * depth),
                     ref_level_norms=json.dumps([0.0] * depth))
            rows.append(r)
    df = pd.DataFrame(rows)
    plots.plot_accuracy(df, tmp_path / "acc.png", styles=plots.solver_styles(df))
    assert drawn == {"qp (20 problems)": [0, 1, 2], "ns (8 problems)": [0, 1, 2],  # (1 of 8: 12 %)
                     "one (1 problem)": list(range(12))}

