"""The yardstick on the same problems in other units: A times s (x divided by s), and levels whose
rows reach norm 1e308 (bounds alike). The problem is invariant under both, so its yardstick is
the unscaled one's, mapped, and (slow) the exact certificate accepts it."""

from pathlib import Path

import numpy as np
import pytest

from hikbench.problems import Hierarchy, generators
from hikbench.problems.exact import certify
from hikbench.problems.verify import level_norms, verify
from hikbench.solvers.hcod import HcodSolver
from hikbench.solvers.yardstick import cascade_yardstick, yardstick_solution

DATA = Path(__file__).parent / "data"

#: (id, family, params): random mixes, IK-like, equality (the null-space recursion), degenerate
FAMILIES = [
    ("random-mixed-0", "random", {"n": 12}, 0),
    ("random-mixed-1", "random", {"n": 12}, 1),
    ("random-equality-fraction", "random", {"n": 12, "equality_fraction": 0.4}, 0),
    ("ik-like", "ik-like", {"n": 12}, 0),
    ("equality", "equality", {"n": 12, "depth": 3, "rows": 4}, 0),
    *[(f"degenerate-{c}", "degenerate", {"case": c, "n": 12}, 0) for c in generators.DEGENERATE_CASES],
]
#: A times s, bounds unchanged (x divided by s)
SCALES = [1e-100, 1e-20, 1e-12, 1e-6, 1e6, 1e20, 1e100]
#: rows of norm 1e308: "level0" scales level 0, "every-level" each level, so that its largest row has
#: norm 1e308, bounds alike, and every bound by t <= 1e-3 (x times t: A x and the bounds stay doubles)
BIG_ROWS = ["level0", "every-level"]


def _problem(family: str, params: dict, seed: int) -> Hierarchy:
    return generators.generate(family, seed=seed, **params)


def _a_scaled(h: Hierarchy, s: float) -> Hierarchy:
    return Hierarchy(h.A * s, h.lower, h.upper, h.level, n=h.n, depth=h.depth)


def _big_rows(h: Hierarchy, which: str) -> tuple[Hierarchy, np.ndarray]:
    """h with rows of norm 1e308 (the comment of BIG_ROWS) and t."""
    c = np.ones(h.depth)
    t, x = 1e-3, yardstick_solution(h)  # (t also keeps the level norms doubles)
    for k in range(h.depth) if which == "every-level" else [0]:
        rows = h.level_rows(k)
        norms = np.linalg.norm(h.A[rows], axis=1)
        if norms.size and norms.max() > 0:
            c[k] = 1e308 / norms.max()
            b = np.abs(np.concatenate([h.lower[rows], h.upper[rows], level_norms(h, x)[k:k + 1]]))
            t = min(t, 1e-3 * norms.max() / max(float(np.max(b[np.isfinite(b)], initial=0.0)), 1e-300))
    rc = c[h.level] * t
    return Hierarchy(h.A * c[h.level][:, None], h.lower * rc, h.upper * rc, h.level, n=h.n, depth=h.depth), t


def _cases():
    for fid, family, params, seed in FAMILIES:
        for s in SCALES:
            yield pytest.param(family, params, seed, s, id=f"{fid}-A{s:g}")
        for which in BIG_ROWS:
            yield pytest.param(family, params, seed, which, id=f"{fid}-1e308-{which}")


def _rescaled(family, params, seed, how):
    """The unscaled problem h0, the rescaled one h, and x -> the point of h0 (its inverse map)."""
    h0 = _problem(family, params, seed)
    if isinstance(how, str):
        h, t = _big_rows(h0, how)
        return h0, h, lambda x: x / t
    return h0, _a_scaled(h0, how), lambda x: x * how


@pytest.mark.parametrize(("family", "params", "seed", "how"), list(_cases()))
def test_the_yardstick_of_a_rescaled_problem_is_the_unscaled_ones(family, params, seed, how):
    """Mapped back to the unscaled problem, the rescaled problem's yardstick is lexicographically
    equal to the unscaled one's at 1e-9, and hcod's answer to the rescaled problem equals it there
    too (verify's scales follow the units). Before levels and units were scaled, random n=12
    seed 0 with A x 1e-12 was above the optimum from level 1 on, with x 1e100 from level 3."""
    h0, h, back = _rescaled(family, params, seed, how)
    x = yardstick_solution(h)
    assert np.all(np.isfinite(x))
    v = verify(h0, back(x), yardstick_solution(h0), rtol=1e-9)
    assert v.equal, v
    v = verify(h, x, HcodSolver().solve(h).x, rtol=1e-9)
    assert v.equal, v


def test_the_info_says_how_levels_and_units_were_scaled():
    h = _a_scaled(_problem("random", {"n": 12}, 0), 1e-12)
    _, info = cascade_yardstick(h)
    # levels brought to norm [1, 2) (times ~1e12, bounds alike), then units of x that bring the
    # bounds back to O(1)
    assert all(1e11 < f < 1e13 for f in info["levels_scaled_by"])
    assert 1e-13 < info["bounds_scaled_by"] < 1e-11
    assert all(np.log2(f) % 1 == 0 for f in [*info["levels_scaled_by"], info["bounds_scaled_by"]])  # (exact)
    _, info = cascade_yardstick(_problem("random", {"n": 12}, 0))
    assert "levels_scaled_by" not in info and "bounds_scaled_by" not in info  # (within the bands: as given)


@pytest.mark.slow
@pytest.mark.parametrize(("family", "params", "seed", "how"),
                         [c for c in _cases() if "rank_deficient" not in c.id])
def test_the_yardstick_of_a_rescaled_problem_is_certified(family, params, seed, how):
    """The exact certificate accepts the rescaled problem's yardstick and the yardstick attains it
    (rank_deficient is left out: rank-deficient only to rounding, the certificate refuses it)."""
    _, h, _ = _rescaled(family, params, seed, how)
    x = yardstick_solution(h)
    cert = certify(h, x)
    assert cert.certified, cert.reason
    v = verify(h, x, cert.x, rtol=1e-9)
    assert v.equal, v


def saved_rescaled(i: int) -> tuple[Hierarchy, np.ndarray]:
    """Random n=12 seed 0 with A times the i-th saved scale (1e-12, 1e100), and the yardstick's
    point on it before levels and units were scaled (tests/solvers/data/rescaled_random_12_0.npz)."""
    with np.load(DATA / "rescaled_random_12_0.npz") as z:
        h = Hierarchy(z["A"] * z["scales"][i], z["lower"], z["upper"], z["level"])
        return h, z[f"x_old_{i}"]


@pytest.mark.parametrize("i", [0, 1], ids=["A1e-12", "A1e100"])
def test_the_old_yardsticks_point_is_above_the_new_one(i):
    h, x_old = saved_rescaled(i)
    v = verify(h, x_old, yardstick_solution(h), rtol=1e-6)
    assert not v.equal and v.lower == "b", v
