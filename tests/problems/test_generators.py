"""Generators: requested ranks and conflicts (checked by SVD), inequality mixes,
conditioning, determinism, the IK-like definition, degenerate cases; and
hikbench.problems.analysis, which `hikbench inspect` prints."""

import numpy as np
import pytest

from hikbench.problems import Hierarchy, HikbenchError, UnknownFamilyError
from hikbench.problems.analysis import level_structure
from hikbench.problems.generators import (
    DEGENERATE_CASES,
    FAMILIES,
    INEQUALITY_MIXES,
    degenerate,
    equality_stack,
    generate,
    ik_like,
    random_hierarchy,
)


def svd_rank(M: np.ndarray) -> int:
    """Rank by SVD with the threshold 1e-9 * largest singular value."""
    if M.size == 0:
        return 0
    s = np.linalg.svd(M, compute_uv=False)
    return int(np.sum(s > 1e-9 * s[0]))


def ranks_and_conflicts(h: Hierarchy, first: int = 0):
    """Per level k >= first: rank(A_k), and the conflicts rank(A_k) + rank(above)
    - rank(above and A_k), i.e. dim(row space of A_k inside the row space above)."""
    out = []
    for k in range(first, h.depth):
        A_k = h.A[h.level_rows(k)]
        above = h.A[h.starts[first]:h.starts[k]]
        both = h.A[h.starts[first]:h.starts[k + 1]]
        out.append((svd_rank(A_k), svd_rank(A_k) + svd_rank(above) - svd_rank(both)))
    return out


@pytest.mark.parametrize("n, rows, rank, shared, expected", [
    # enough DOF: rank r_k, conflicts = shared_k (level 0 has nothing above)
    (12, [4, 5, 3], [3, 4, 2], [0, 2, 1], [(3, 0), (4, 2), (2, 1)]),
    # full-rank levels, no conflicts requested
    (12, [3, 3, 3], None, 0, [(3, 0), (3, 0), (3, 0)]),
    # saturation at n = 6: level 1 gets the 2 DOF left (2 new + 2 shared), level 2 none left (4 shared)
    (6, [4, 4, 4], [4, 4, 4], 0, [(4, 0), (4, 2), (4, 4)]),
    # rank-deficient levels with conflicts, and a rank-0 level
    (10, [6, 3, 5], [2, 0, 5], [0, 0, 2], [(2, 0), (0, 0), (5, 2)]),
    # shared_rank is capped at the rank above: level 2 asks 3 but only 2 dimensions are above
    (10, [6, 2, 5], [2, 0, 5], [0, 0, 3], [(2, 0), (0, 0), (5, 2)]),
], ids=["ranks and conflicts", "full rank", "saturated", "deficient", "shared capped"])
@pytest.mark.parametrize("inequality", INEQUALITY_MIXES)
def test_random_hierarchy_hits_ranks_and_conflicts(n, rows, rank, shared, expected, inequality):
    h = random_hierarchy(n, len(rows), rows, rank=rank, shared_rank=shared, inequality=inequality, seed=3)
    np.testing.assert_array_equal(h.rows_per_level, rows)
    assert ranks_and_conflicts(h) == expected
    # hikbench.problems.analysis (hikbench inspect) reports the same numbers
    assert [(L.rank, L.conflicts) for L in level_structure(h)] == expected


def test_box_is_level_zero_and_tasks_keep_their_structure():
    h = random_hierarchy(8, 2, [3, 4], rank=[3, 2], shared_rank=[0, 1], box=True, box_bound=0.7, seed=1)
    np.testing.assert_array_equal(h[0].A, np.eye(8))
    np.testing.assert_array_equal(h[0].lower, -0.7 * np.ones(8))
    np.testing.assert_array_equal(h[0].upper, 0.7 * np.ones(8))
    assert ranks_and_conflicts(h, first=1) == [(3, 0), (2, 1)]


@pytest.mark.parametrize("cond", [1.0, 10.0, 1e6], ids=["cond1", "cond10", "cond1e6"])
def test_random_hierarchy_condition_number(cond):
    h = random_hierarchy(10, 3, 4, cond=cond, seed=5)
    for k in range(h.depth):
        s = np.linalg.svd(h[k].A, compute_uv=False)
        np.testing.assert_allclose(s[0] / s[-1], cond, rtol=1e-6)


def test_random_hierarchy_row_scale():
    h = random_hierarchy(10, 3, 6, row_scale=1e4, seed=2)
    norms = np.linalg.norm(h.A, axis=1)
    assert norms.max() / norms.min() <= 1e4 * (1 + 1e-9)
    assert norms.max() / norms.min() > 10  # actually spread


@pytest.mark.parametrize("inequality, check", [
    ("none", lambda lo, up: np.all(lo == up)),
    ("one-sided", lambda lo, up: np.all(np.isinf(lo) ^ np.isinf(up))),
    ("two-sided", lambda lo, up: np.all(np.isfinite(lo) & np.isfinite(up) & (lo < up))),
    ("mixed", lambda lo, up: np.all(lo <= up) and np.any(np.isinf(lo) ^ np.isinf(up))
     and np.any(np.isfinite(lo) & np.isfinite(up) & (lo < up))),
], ids=list(INEQUALITY_MIXES))
def test_random_hierarchy_inequality_mix(inequality, check):
    h = random_hierarchy(10, 4, 8, inequality=inequality, seed=4)
    assert check(h.lower, h.upper)
    assert not h.is_free.any()


@pytest.mark.parametrize("fraction, expected", [(0.0, 0.0), (1.0, 1.0), (0.4, 0.4)],
                         ids=["fraction0", "fraction1", "fraction0.4"])
def test_equality_fraction(fraction, expected):
    h = random_hierarchy(10, 5, 40, rank=10, inequality="mixed", equality_fraction=fraction, seed=0)
    np.testing.assert_allclose(h.is_equality.mean(), expected, atol=0.1)


@pytest.mark.parametrize("family", list(FAMILIES))
def test_families_are_deterministic_for_a_seed(family):
    assert generate(family, seed=7) == generate(family, seed=7)
    assert generate(family, seed=7) != generate(family, seed=8)


@pytest.mark.parametrize("family", [f for f in FAMILIES if FAMILIES[f].sweep])
def test_family_sweeps_make_valid_problems(family):
    (param, values), = FAMILIES[family].sweep.items()
    for v in values[:3] + values[-1:]:
        h = generate(family, seed=0, **{param: v})
        assert h.rows > 0


def test_depth_sweep_goes_past_saturation():
    fam = FAMILIES["depth-sweep"]
    d = fam.defaults
    assert max(fam.sweep["depth"]) * d["rows"] > d["n"]  # sum of ranks > n at the deepest point
    h = generate("depth-sweep", depth=max(fam.sweep["depth"]))
    assert svd_rank(h.A) == d["n"]
    assert ranks_and_conflicts(h)[-1][1] == d["rows"]  # the last level is entirely decided above


@pytest.mark.parametrize("n", [7, 30], ids=lambda n: f"n{n}")
def test_equality_stack(n):
    h = equality_stack(n, 4, 5, seed=1)
    assert not h.has_inequalities
    assert [r for r, _ in ranks_and_conflicts(h)] == [5] * 4
    g = equality_stack(n, 3, 6, seed=1, rank=2)
    assert [r for r, _ in ranks_and_conflicts(g)] == [2] * 3


def test_ik_like_matches_its_definition():
    n = 90
    h = ik_like(n, seed=11)
    assert h.depth == 5
    np.testing.assert_array_equal(h.rows_per_level, [n, 6, 2 * n // 3, 6, n])
    # level 0: box -0.5 <= x_i <= 0.5
    np.testing.assert_array_equal(h[0].A, np.eye(n))
    np.testing.assert_array_equal(h[0].lower, -0.5)
    np.testing.assert_array_equal(h[0].upper, 0.5)
    # level 1: 6 equalities; level 3: 6 equalities; level 4: posture x = b (A = I)
    for k in (1, 3, 4):
        np.testing.assert_array_equal(h[k].lower, h[k].upper)
    np.testing.assert_array_equal(h[4].A, np.eye(n))
    # level 2: one-sided A x <= u
    assert np.all(np.isneginf(h[2].lower)) and np.all(np.isfinite(h[2].upper))
    # distributions (loose statistical checks, far from their limits for this seed):
    # A entries N(0,1): 6n + 2n/3 n + 6n = 6480 draws -> mean within 0.05, std within 0.05 of 1
    a = np.concatenate([h[1].A.ravel(), h[2].A.ravel(), h[3].A.ravel()])
    assert abs(a.mean()) < 0.05 and abs(a.std() - 1) < 0.05
    # level 2 upper bounds N(0,1) - 0.5 (60 draws): mean -0.5 +- 0.4
    assert abs(h[2].upper.mean() + 0.5) < 0.4
    # posture targets 0.1 N(0,1) (90 draws): std in [0.07, 0.13]
    assert 0.07 < h[4].lower.std() < 0.13
    # targets of levels 1 and 3 (6 draws each) are N(0,1) and 3 N(0,1): too few draws for a
    # distribution test; both levels are full rank (6 <= n)
    assert [r for r, _ in ranks_and_conflicts(h, first=1)][:3] == [6, 2 * n // 3, 6]


@pytest.mark.parametrize("case", DEGENERATE_CASES)
def test_degenerate_cases_are_valid_hierarchies(case):
    h = degenerate(case, n=12, seed=0)
    assert isinstance(h, Hierarchy) and h.n == 12
    Hierarchy(h.A, h.lower, h.upper, h.level, n=h.n, depth=h.depth, names=h.names)  # re-validates


def test_degenerate_cases_have_their_property():
    n = 12
    h = degenerate("duplicate_rows", n)
    A1 = h[1].A
    assert any(np.array_equal(A1[i], A1[j]) for i in range(len(A1)) for j in range(i))
    assert any(np.array_equal(A1[i], h[0].A[0]) for i in range(len(A1)))
    h = degenerate("rank_deficient", n)
    assert [svd_rank(L.A) for L in h][1:] == [2, 3, 6]
    h = degenerate("empty_levels", n)
    assert [k for k in range(h.depth) if h.rows_per_level[k] == 0] == [0, 2, 4]
    h = degenerate("infeasible_top", n)
    e0 = np.eye(n)[0]
    top = h[0]
    lows = [top.lower[i] for i in range(top.rows) if np.array_equal(top.A[i], e0) and np.isinf(top.upper[i])]
    ups = [top.upper[i] for i in range(top.rows) if np.array_equal(top.A[i], e0) and np.isinf(top.lower[i])]
    assert min(lows) > max(ups)  # x_0 >= 1 and x_0 <= -1: no x satisfies level 0
    h = degenerate("badly_scaled", n)
    norms = np.linalg.norm(h.A, axis=1)
    assert norms.max() / norms.min() > 1e4
    h = degenerate("deep_inequalities", n)
    assert h.depth >= 11 and all((~h.is_equality[h.level_rows(k)]).any() for k in range(h.depth))
    h = degenerate("free_rows", n)
    assert all(h.is_free[h.level_rows(k)].any() for k in range(h.depth))
    h = degenerate("saturated", n)
    assert sum(svd_rank(L.A) for L in h) > n and not h.has_inequalities
    h = degenerate("equalities_in_inequality_levels", n)
    assert any(h.is_equality[h.level_rows(k)].any() and (~h.is_equality[h.level_rows(k)]).any()
               for k in range(h.depth))


@pytest.mark.parametrize("call, error, message", [
    (lambda: generate("nope"), UnknownFamilyError, r"unknown family 'nope'; expected one of equality"),
    (lambda: generate("random", depht=3), HikbenchError,
     r"family 'random': unknown parameter 'depht' \(did you mean 'depth'\?\); expected one of n, depth, "),
    (lambda: degenerate("nope"), UnknownFamilyError, r"unknown degenerate case 'nope'"),
    (lambda: random_hierarchy(5, 2, 3, rank=4), HikbenchError, r"level 0: rank 4 must be in \[0, rows=3\]"),
    (lambda: random_hierarchy(5, 2, 3, shared_rank=[0, 4]), HikbenchError,
     r"level 1: shared_rank 4 must be in \[0, rank=3\]"),
    (lambda: random_hierarchy(5, 2, [3]), HikbenchError, r"rows has 1 entries: expected one per level \(2\)"),
    (lambda: random_hierarchy(5, 2, 3, rank=2.5), HikbenchError, r"rank must be an integer; got 2.5"),
    (lambda: random_hierarchy(5, 2, 3, inequality="some"), HikbenchError, r"inequality must be one of"),
    (lambda: random_hierarchy(5, 2, 3, cond=0.5), HikbenchError, r"cond must be a finite number >= 1"),
    (lambda: equality_stack(0, 2, 3), HikbenchError, r"need n >= 1, depth >= 0, rows >= 0; got n=0"),
    (lambda: ik_like(0), HikbenchError, r"ik_like needs n >= 1; got 0"),
], ids=["family", "parameter", "case", "rank", "shared", "rows count", "rank not integer", "mix", "cond",
        "stack n", "ik n"])
def test_generator_errors(call, error, message):
    with pytest.raises(error, match=message):
        call()


def test_level_structure_by_hand():
    # level 0: x0 = 0 and x1 <= 1 (rank 2, singular values 1, 1);
    # level 1: rows (1, 1, 0), (0, 0, 2) and a free row: constraint rank 2, singular values sqrt2 and 2;
    #   projected on the null space of level 0 (span e2): only (0, 0, 2) survives -> rank 1, sv 2;
    #   conflicts = 2 - 1 = 1.
    h = Hierarchy([[1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 2], [5, 5, 5]],
                  [0, -np.inf, -1, 0, -np.inf], [0, 1, 1, np.inf, np.inf], [0, 0, 1, 1, 1])
    L0, L1 = level_structure(h)
    assert (L0.rows, L0.equalities, L0.one_sided, L0.two_sided, L0.free) == (2, 1, 1, 0, 0)
    assert (L1.rows, L1.equalities, L1.one_sided, L1.two_sided, L1.free) == (3, 0, 1, 1, 1)
    assert (L0.rank, L0.projected_rank, L0.conflicts) == (2, 2, 0)
    assert (L1.rank, L1.projected_rank, L1.conflicts) == (2, 1, 1)
    np.testing.assert_allclose([L1.sv_max, L1.sv_min, L1.cond], [2, np.sqrt(2), np.sqrt(2)], rtol=1e-14)
    np.testing.assert_allclose([L1.projected_sv_min, L1.projected_cond], [2, 1], rtol=1e-14)
