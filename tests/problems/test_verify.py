"""Violation, level norms, scales and the lexicographic comparison on hand-made
cases whose expected values are derived in the comments."""

import numpy as np
import pytest
from hik_strategies import hierarchies, moderate
from hypothesis import given
from hypothesis import strategies as st

from hikbench.problems import Hierarchy, HikbenchError, Level, compare_lexicographic, level_norms, level_scales, verify
from hikbench.problems.verify import violation

INF = np.inf

# Rows (n = 2), levels [0, 0, 1, 1, 2]:
#   r0: x0 = 1             (equality)
#   r1: x1 >= 2            (lower only)
#   r2: x0 + x1 <= 0       (upper only)
#   r3: -1 <= x0 - x1 <= 1 (two-sided)
#   r4: free
H = Hierarchy([[1, 0], [0, 1], [1, 1], [1, -1], [3, 7]], [1, 2, -INF, -1, -INF], [1, INF, 0, 1, INF],
              [0, 0, 1, 1, 2])


@pytest.mark.parametrize("x, expected_v, expected_norms", [
    # x = (3, 1): r0: Ax=3, v=max(1-3,0)+max(3-1,0)=2; r1: Ax=1, v=2-1=1; r2: Ax=4, v=4-0=4;
    # r3: Ax=2, v=2-1=1; r4: free, 0. Norms: sqrt(2^2+1^2)=sqrt5, sqrt(4^2+1^2)=sqrt17, 0.
    ((3.0, 1.0), [2, 1, 4, 1, 0], [np.sqrt(5), np.sqrt(17), 0]),
    # x = (1, 2): r0 exact; r1 at its bound; r2: 3 > 0 by 3; r3: -1 at its lower bound. Norms 0, 3, 0.
    ((1.0, 2.0), [0, 0, 3, 0, 0], [0, 3, 0]),
    # x = (-1, -1): r0: |-1-1|=2; r1: 2-(-1)=3; r2: -2 <= 0 ok; r3: 0 ok. Norms sqrt13, 0, 0.
    ((-1.0, -1.0), [2, 3, 0, 0, 0], [np.sqrt(13), 0, 0]),
], ids=["all violated", "second level only", "first level only"])
def test_violation_and_norms_by_hand(x, expected_v, expected_norms):
    np.testing.assert_allclose(violation(H, x), expected_v, rtol=0, atol=1e-15)
    np.testing.assert_allclose(level_norms(H, x), expected_norms, rtol=1e-15, atol=0)


def test_level_norms_with_empty_levels():
    # levels: empty, {x0 = 1}, empty, {x0 + x1 = 1}, empty; at x = 0: norms 0, 1, 0, 1, 0
    e = Level(np.zeros((0, 2)), [], [])
    h = Hierarchy.from_levels([e, Level.equality([[1, 0]], [1]), e, Level.equality([[1, 1]], [1]), e])
    np.testing.assert_array_equal(level_norms(h, [0.0, 0.0]), [0, 1, 0, 1, 0])


def test_nan_in_x_gives_nan_not_zero():
    norms = level_norms(H, [np.nan, 0.0])
    assert np.isnan(norms[0]) and np.isnan(norms[1])
    assert np.isnan(norms[2])  # the free row: NaN too, never a silent zero (a wrong x must look wrong)


def test_x_with_wrong_shape():
    with pytest.raises(HikbenchError, match=r"x has shape \(3,\): expected \(2,\)"):
        level_norms(H, [0.0, 0.0, 0.0])


@given(hierarchies(coefficients=moderate, bounds=moderate, min_n=1, names=False, x0=False),
       st.data())
def test_violation_is_distance_to_the_interval(h, data):
    """v_i = dist(A_i x, [lower_i, upper_i]): zero inside, and the projection
    clip(A x, lower, upper) is at exactly that distance."""
    x = np.array(data.draw(st.lists(moderate, min_size=h.n, max_size=h.n)))
    r = h.A @ x
    v = violation(h, x)
    assert np.all(v >= 0)
    np.testing.assert_allclose(v, np.abs(r - np.clip(r, h.lower, h.upper)), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(level_norms(h, x) ** 2, np.bincount(h.level, v * v, minlength=h.depth),
                               rtol=1e-12, atol=1e-12)


def test_level_scales_by_hand():
    # level 0: A = [[3, 4]] (||A||_F = 5), bounds (-inf, 12] -> finite bounds norm 12;
    # level 1: A = [[0, 0]], bounds [0, 0] -> 0 (no floor: its tolerance is atol alone);
    # level 2: A = [[3e-8, 4e-8]], bounds [1e-7, 1e-7] -> sqrt(2) 1e-7 (+ 5e-8 ||x||).
    h = Hierarchy([[3, 4], [0, 0], [3e-8, 4e-8]], [-INF, 0, 1e-7], [12, 0, 1e-7], [0, 1, 2])
    np.testing.assert_allclose(level_scales(h), [12.0, 0.0, 2 ** 0.5 * 1e-7], rtol=1e-15)
    # with ||x|| = 1: 5 * 1 + 12 = 17
    np.testing.assert_allclose(level_scales(h, [0.6, 0.8]), [17.0, 0.0, 5e-8 + 2 ** 0.5 * 1e-7], rtol=1e-15)


@pytest.mark.parametrize("scale", [1e-9, 1e-3, 1.0, 1e4], ids=["1e-9", "1e-3", "1", "1e4"])
def test_a_level_of_small_bounds_left_undone_is_worse(scale):
    """[x1 + x2 = scale] > [x = 0]: x = 0 leaves level 0 undone by its whole target. With the
    scale ``||A_0||_F (1 + ||x||) + ||b_0||`` (before) level 0's tolerance at rtol 1e-6 was
    1.4e-6 whatever the target: at 1e-9, x = 0 was judged equal to the optimum at level 0 and
    better at level 1."""
    h = Hierarchy.from_levels([Level.equality(np.ones((1, 2)), [scale]), Level.equality(np.eye(2), [0, 0])])
    optimum = np.array([0.5, 0.5]) * scale
    v = verify(h, np.zeros(2), optimum, rtol=1e-6, atol=0)
    assert (v.level, v.lower) == (0, "b")
    assert verify(h, optimum * (1 + 1e-9), optimum, rtol=1e-6, atol=0).equal


@given(hierarchies(coefficients=moderate, bounds=moderate, min_n=1, names=False, x0=False),
       st.data(), st.integers(min_value=-60, max_value=60))
def test_verdicts_do_not_depend_on_the_units(h, data, e):
    """Bounds, x and the reference times one power of 2 (exact): the same verdict at rtol, with
    atol 0 (its one absolute part)."""
    x, x_ref = (np.array(data.draw(st.lists(moderate, min_size=h.n, max_size=h.n))) for _ in range(2))
    f = 2.0 ** e
    hs = h.with_bounds(h.lower * f, h.upper * f)
    v, vs = verify(h, x, x_ref, rtol=1e-6), verify(hs, x * f, x_ref * f, rtol=1e-6)
    assert (vs.level, vs.lower) == (v.level, v.lower)
    if v.level is not None and np.isfinite(v.difference):
        assert vs.difference == v.difference * f


@pytest.mark.parametrize("e", [-990, -600, 600, 900], ids=lambda e: f"2^{e}")
def test_verdicts_at_the_ends_of_the_double_range(e):
    """The same, deterministic, at exponents where the squares of the violations leave the
    doubles (below 2^-512 or above 2^512): the norms are taken scaled by each level's largest
    violation, so they and the verdicts scale exactly. From plain sums of squares, every level
    norm was 0 at 2^-600 (a wrong answer passed as the reference) and inf at 2^600."""
    from hikbench.problems.generators import ik_like

    h = ik_like(12, seed=3)
    rng = np.random.default_rng(0)
    f = 2.0 ** e
    hs = h.with_bounds(h.lower * f, h.upper * f)
    for trial in range(20):
        x, x_ref = rng.standard_normal(h.n) * 0.3, rng.standard_normal(h.n) * 0.3
        np.testing.assert_array_equal(level_norms(hs, x * f), level_norms(h, x) * f)
        v, vs = verify(h, x, x_ref, rtol=1e-9), verify(hs, x * f, x_ref * f, rtol=1e-9)
        assert v.level is not None, f"trial {trial}: two random points judged equal"
        assert (vs.level, vs.lower, vs.difference) == (v.level, v.lower, v.difference * f)


def test_norms_keep_nan_and_inf():
    h = Hierarchy.from_levels([Level.equality(np.eye(2), [0.0, 0.0]), Level.equality(np.ones((1, 2)), [1.0])])
    assert np.isnan(level_norms(h, [np.nan, 0.0])).all()
    with np.errstate(over="ignore"):  # (A x overflows at level 1)
        big = level_norms(h, [1e308, 1e308])
    np.testing.assert_allclose(big[0], np.sqrt(2) * 1e308, rtol=1e-15)  # its sum of squares overflowed
    assert big[1] == np.inf
    np.testing.assert_allclose(level_norms(h, [3e200, 4e200]), [5e200, 7e200], rtol=1e-15)


@pytest.mark.parametrize("scale", [1e-7, 1e-3, 1.0, 1e4], ids=["1e-7", "1e-3", "1", "1e4"])
def test_a_small_scaled_level_left_undone_is_worse(scale):
    """[scale (x1 + x2) = scale] > [x = 0]: x = 0 leaves level 0 undone by its whole target and is
    lower at level 1 than the optimum (0.5, 0.5). The level's tolerance is relative to its own
    scale at every scale (atol 1e-9 apart); with scales floored at 1 (before) a level of scale
    1e-7 was within rtol 1e-6 of any answer, and x = 0 was judged *better* than the optimum at
    level 1."""
    h = Hierarchy.from_levels([Level.equality(scale * np.ones((1, 2)), [scale]), Level.equality(np.eye(2), [0, 0])])
    v = verify(h, np.zeros(2), np.array([0.5, 0.5]), rtol=1e-6, atol=1e-9)  # the suites' "default" profile
    assert (v.level, v.lower) == (0, "b")
    assert verify(h, np.array([0.5, 0.5]) * (1 + 1e-9), np.array([0.5, 0.5]), rtol=1e-6, atol=0).equal


@pytest.mark.parametrize("a, b, kwargs, level, lower, difference", [
    # identical vectors: no verdict
    ([1.0, 2.0], [1.0, 2.0], {}, None, None, 0.0),
    # 1e-12 apart with tolerance rtol * scale = 1e-9 * 1: equal
    ([1.0, 2.0], [1.0 + 1e-12, 2.0], {}, None, None, 0.0),
    # level 0 equal, level 1: 5 vs 3 -> b is lower there, difference a - b = 2
    ([1.0, 5.0], [1.0, 3.0], {}, 1, "b", 2.0),
    # level 0 decides even though a is far worse below: 0.9 < 1.0 -> a lower, difference -0.1
    ([0.9, 100.0], [1.0, 0.0], {}, 0, "a", 0.9 - 1.0),
    # 1e-6 apart: tolerance 1e-9 * 1e4 = 1e-5 -> equal ...
    ([1.0], [1.0 + 1e-6], {"scales": [1e4]}, None, None, 0.0),
    # ... but with scale 1 the tolerance is 1e-9 -> b is worse (higher), a lower, difference -1e-6
    ([1.0], [1.0 + 1e-6], {"scales": [1.0]}, 0, "a", 1.0 - (1.0 + 1e-6)),
    # atol adds to the tolerance: 1e-6 <= 0 + 2e-6 -> equal
    ([1.0], [1.0 + 1e-6], {"rtol": 0.0, "atol": 2e-6}, None, None, 0.0),
    # NaN is worse than any number: a = NaN at level 1 -> b lower
    ([0.0, np.nan], [0.0, 7.0], {}, 1, "b", np.nan),
    ([0.0, 7.0], [0.0, np.nan], {}, 1, "a", np.nan),
    # empty vectors (no levels): equal
    ([], [], {}, None, None, 0.0),
], ids=["identical", "within tolerance", "second level", "first level decides", "scaled tolerance",
        "unit tolerance", "atol", "nan in a", "nan in b", "empty"])
def test_compare_lexicographic_by_hand(a, b, kwargs, level, lower, difference):
    v = compare_lexicographic(a, b, **kwargs)
    assert (v.level, v.lower) == (level, lower)
    assert v.equal == (level is None)
    np.testing.assert_allclose(v.difference, difference, rtol=1e-12, atol=0)


@pytest.mark.parametrize("a, b, kwargs, message", [
    ([1.0, 2.0], [1.0], {}, r"norm vectors must have the same 1-D shape; got \(2,\) and \(1,\)"),
    ([1.0], [1.0], {"scales": [1.0, 2.0]}, r"scales has shape \(2,\): expected \(1,\)"),
], ids=["shapes", "scales"])
def test_compare_lexicographic_bad_input(a, b, kwargs, message):
    with pytest.raises(HikbenchError, match=message):
        compare_lexicographic(a, b, **kwargs)


def test_verify_by_hand():
    # level 0: x0 + x1 = 2; level 1: x0 = 3. Optimum: x = (3, -1), norms (0, 0).
    h = Hierarchy.from_levels([Level.equality([[1, 1]], [2]), Level.equality([[1, 0]], [3])])
    assert verify(h, [3.0, -1.0], [3.0, -1.0]).equal
    # x = (1, 1): level 0 exact, level 1 off by 2 -> worse than the reference at level 1
    v = verify(h, [1.0, 1.0], [3.0, -1.0])
    assert (v.level, v.lower) == (1, "b")
    np.testing.assert_allclose(v.difference, 2.0, rtol=1e-15)
    # x = (3, 0): level 0 off by 1 -> the verdict is at level 0 even though level 1 is exact
    v = verify(h, [3.0, 0.0], [3.0, -1.0])
    assert (v.level, v.lower) == (0, "b")


@pytest.mark.parametrize("free", [0.0, 1e10, 1e12], ids=["x2=0", "x2=1e10", "x2=1e12"])
def test_a_huge_free_component_buys_no_tolerance(free):
    """Level 0 ``x0 = 1``, level 1 ``x0 + x1 = 0``, x2 free: x0 off by 1e-3 is worse at level 0
    whatever x2 is. The tolerance scaled with the larger of the two norms of x let x2 = 1e10
    pass it (and x0 off by 1000 beside x2 = 1e12)."""
    h = Hierarchy.from_levels([Level.equality([[1.0, 0.0, 0.0]], [1.0]),
                               Level.equality([[1.0, 1.0, 0.0]], [0.0])], n=3)
    v = verify(h, [1.001, -1.0, free], [1.0, -1.0, 0.0], rtol=1e-6)
    assert (v.level, v.lower) == (0, "b"), v


def test_level_terms_by_hand():
    """t_k = || |A_k| |x| + |b_k| ||, b_i the finite bound nearer a_i x (0 for a free row)."""
    from hikbench.problems.verify import level_terms

    # level 0: rows [3, -4] in (-inf, 12] and [1, 1] in [-1, 50]; level 1: a free row [1, 1]
    h = Hierarchy([[3, -4], [1, 1], [1, 1]], [-INF, -1, -INF], [12, 50, INF], [0, 0, 1])
    x = np.array([1.0, 2.0])  # A x = (-5, 3, 3): bounds 12 and -1 (nearer 3 than 50)
    np.testing.assert_allclose(level_terms(h, x), [np.hypot(3 + 8 + 12, 1 + 2 + 1), 3.0], rtol=1e-15)
    np.testing.assert_allclose(level_terms(h), [np.hypot(12, 1), 0.0], rtol=1e-15)  # (x = 0)


@pytest.mark.parametrize("rtol", [1e-9, 1e-8, 1e-6], ids=["high", "default", "low"])
def test_a_huge_optimum_at_one_level_buys_no_tolerance_at_another(rtol):
    """Level 0 ``0.1 x0 = 1e9`` puts x0* at 1e10; level 1 ``10 x1 = 0``. x1 = 6.526 leaves
    level 1 at 65.26 where 0 is reachable. With the tolerance rtol ||A_1||_F ||x*|| (before) it
    was 100 at rtol 1e-9, and the gap was hidden; level 1's own terms at x* are 0, which leaves
    the round-off floor 1e-12 x ||A_1||_F ||x*|| = 0.1."""
    from hikbench.problems.verify import judge, level_tolerances

    h = Hierarchy.from_levels([Level.equality([[0.1, 0.0]], [1e9]), Level.equality([[0.0, 10.0]], [0.0])])
    x_star, x = np.array([1e10, 0.0]), np.array([1e10, 6.526])
    np.testing.assert_allclose(level_norms(h, x), [0.0, 65.26], rtol=1e-12)
    np.testing.assert_allclose(level_tolerances(h, x_star, rtol)[1], 0.1, rtol=1e-12)
    assert 1e-9 * level_scales(h, x_star)[1] == pytest.approx(100.0)  # (the former tolerance)
    for v in (verify(h, x, x_star, rtol=rtol), judge(h, x, x_star, rtol)):
        assert (v.level, v.lower) == (1, "b"), v


@given(hierarchies(coefficients=moderate, bounds=moderate, min_n=1, names=False, x0=False), st.data(),
       st.floats(min_value=1e-12, max_value=1e-2))
def test_a_row_verified_at_a_profile_is_verified_at_every_looser_one(h, data, d):
    """judge at high, default, low (PROFILES, tightest first): True, then never False again,
    for x = x_ref perturbed by d relative and for an unrelated x."""
    from hikbench.problems.verify import PROFILES, judge

    x_ref = np.array(data.draw(st.lists(moderate, min_size=h.n, max_size=h.n)))
    s = np.array(data.draw(st.lists(st.sampled_from([-1.0, 1.0]), min_size=h.n, max_size=h.n)))
    for x in (x_ref * (1 + d * s), np.array(data.draw(st.lists(moderate, min_size=h.n, max_size=h.n)))):
        ok = [judge(h, x, x_ref, p.rtol).lower != "b" for p in PROFILES.values()]
        assert ok == sorted(ok), ok
