"""Equality-only hierarchies (docs/hcod.md, "Equality-only hierarchies"): x is the
minimum-norm lexicographic optimum of the null-space yardstick, to 1e-9, one iteration per
level, with rank-deficient, saturated, duplicated and conflicting levels."""

from __future__ import annotations

import numpy as np
import pytest
from hcod_checks import check

from hikbench.problems import generators as G
from hikbench.problems.hierarchy import Hierarchy, Level
from hikbench.solvers.yardstick import nullspace_yardstick


@pytest.mark.parametrize("n, depth, rows, rank", [
    (36, 6, 6, None), (50, 5, 8, None), (12, 8, 3, None), (36, 24, 6, None), (20, 4, 6, 3), (7, 3, 5, 2),
    (120, 8, 12, None), (64, 5, 7, None), (80, 4, 13, 9),
], ids=["36x6x6", "50x5x8", "saturated-12x8x3", "saturated-36x24x6", "rank3-of-6", "tiny-rank2",
        "120x8x12", "64x5x7-odd-rows", "80x4x13-rank9"])
def test_equality_stack_min_norm(n, depth, rows, rank):
    for seed in range(3):
        h = G.equality_stack(n, depth, rows, seed=seed, rank=rank)
        x_ref = nullspace_yardstick(h)
        res, _ = check(h, x_ref=x_ref)
        np.testing.assert_allclose(res.x, x_ref, rtol=0, atol=1e-9 * (1 + np.linalg.norm(x_ref)))
        assert res.iterations_per_level == (1,) * depth


def test_equality_duplicate_and_conflicting_rows():
    rng = np.random.default_rng(3)
    A0 = rng.standard_normal((3, 6))
    A1 = np.vstack([A0[:2], A0[:1], rng.standard_normal((2, 6))])  # copies of higher rows
    h = Hierarchy.from_levels([Level.equality(A0, rng.standard_normal(3)),
                               Level.equality(A1, rng.standard_normal(5)),
                               Level.equality(np.zeros((0, 6)), np.zeros(0)),
                               Level.equality(np.vstack([A1[3], A1[3]]), [1.0, 2.0])], n=6)
    x_ref = nullspace_yardstick(h)
    res, _ = check(h, x_ref=x_ref)
    np.testing.assert_allclose(res.x, x_ref, atol=1e-10)
