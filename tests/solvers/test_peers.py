"""The C++ peers soth and lexls (``make peers``, docs/peers.md): agreement with hcod,
statuses, warm state, options; and ``peers/build.py``'s one-line errors.

The solver tests are skipped, with the reason, when the peers are not built."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hikbench.problems import generators as g
from hikbench.problems.hierarchy import Hierarchy, Level
from hikbench.problems.verify import verify
from hikbench.solvers import registry
from hikbench.solvers.base import MAX_ITERATIONS, OPTIMAL
from hikbench.solvers.errors import SolverOptionError
from hikbench.solvers.peers import NOT_BUILT, build_info, load_module

ROOT = Path(__file__).resolve().parents[2]
PEERS = ("soth", "lexls")
BUILT = all(load_module(p) is not None for p in PEERS)
needs_peers = pytest.mark.skipif(not BUILT, reason=f"the C++ peers soth and lexls are {NOT_BUILT}")
#: verify() rtol against hcod (docs/peers.md, "Agreement"): the peers' thresholds are absolute
#: (SOTH 1e-8 on ranks, multipliers and bound violations; LexLS 1e-12 on pivots, 1e-13 on
#: feasibility), on problems whose terms are of order 1
RTOL = 1e-6
KINDS = ("none", "one-sided", "two-sided", "mixed")


def _hcod(h: Hierarchy):
    res = registry.create("hcod").solve(h)
    assert res.status == OPTIMAL, res.reason
    return res.x


def _with_free_row_and_empty_level(h: Hierarchy) -> Hierarchy:
    """h with a free row added to its first level and an empty level at the end."""
    levels = list(h)
    top = levels[0]
    levels[0] = Level(np.vstack([top.A, np.ones((1, h.n))]), np.append(top.lower, -np.inf),
                      np.append(top.upper, np.inf))
    levels.append(Level(np.zeros((0, h.n)), np.zeros(0), np.zeros(0)))
    return Hierarchy.from_levels(levels, n=h.n)


@needs_peers
@pytest.mark.parametrize("peer", PEERS)
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("box", [False, True], ids=["no-box", "box"])
def test_peer_agrees_with_hcod_on_random_hierarchies_of_every_row_kind(peer, kind, box):
    for seed in range(8):
        h = g.random_hierarchy(10, 3, [3, 4, 5], inequality=kind, box=box, equality_fraction=0.3,
                               shared_rank=[0, 1, 2], seed=seed)
        res = registry.create(peer).solve(h)
        assert res.status == OPTIMAL, (seed, res.reason)
        v = verify(h, res.x, _hcod(h), rtol=RTOL)
        assert v.equal, (seed, v)


@needs_peers
@pytest.mark.parametrize("peer", PEERS)
def test_free_rows_and_empty_levels_are_left_out(peer):
    h = _with_free_row_and_empty_level(g.random_hierarchy(8, 3, 3, inequality="mixed", seed=2))
    res = registry.create(peer).solve(h)
    assert res.status == OPTIMAL and res.x.shape == (8,)
    assert verify(h, res.x, _hcod(h), rtol=RTOL).equal


@needs_peers
@pytest.mark.parametrize("peer", PEERS)
@pytest.mark.parametrize("make", [lambda: Hierarchy(np.zeros((0, 3)), [], [], [], n=3, depth=2),
                                  lambda: Hierarchy(np.ones((1, 3)), [-np.inf], [np.inf], [0])],
                         ids=["no-rows", "free-rows-only"])
def test_a_hierarchy_constraining_nothing_gives_x_zero(peer, make):
    res = registry.create(peer).solve(make())
    assert res.status == OPTIMAL
    np.testing.assert_array_equal(res.x, np.zeros(3))


@needs_peers
@pytest.mark.parametrize("peer", PEERS)
@pytest.mark.parametrize("problem", ["equality-36x6x6", "ik-like-20", "depth-12-two-sided"])
def test_peer_agrees_with_hcod_on_benchmark_problems(peer, problem):
    h = {"equality-36x6x6": lambda: g.equality_stack(36, 6, 6, seed=0),
         "ik-like-20": lambda: g.ik_like(20, seed=1),
         "depth-12-two-sided": lambda: g.random_hierarchy(36, 12, 6, inequality="two-sided", seed=0)}[problem]()
    res = registry.create(peer).solve(h)
    assert res.status == OPTIMAL, res.reason
    assert verify(h, res.x, _hcod(h), rtol=RTOL).equal


# SOTH cycles on this stack (12 levels of 6 two-sided rows, n = 36) and throws after its 1000
# active-set iterations; hcod and LexLS solve it (found by a search over seeds 0-5 of depths
# 12, 24, 48: also depth 12 mixed seed 5, depth 24 two-sided seed 2 and mixed seed 4)
def _soth_cycles():
    return g.random_hierarchy(36, 12, 6, inequality="two-sided", seed=3)


@needs_peers
def test_soth_cycling_is_a_max_iterations_status_and_the_next_solve_works():
    s = registry.create("soth")
    res = s.solve(_soth_cycles())
    assert res.status == MAX_ITERATIONS and res.x is None
    assert "1000 iterations" in res.reason and "throw 666" in res.reason
    h = g.ik_like(20, seed=0)
    after = s.solve(h)
    assert after.status == OPTIMAL and verify(h, after.x, _hcod(h), rtol=RTOL).equal


@needs_peers
def test_lexls_solves_the_stack_soth_cycles_on():
    h = _soth_cycles()
    res = registry.create("lexls").solve(h)
    assert res.status == OPTIMAL, res.reason
    assert verify(h, res.x, _hcod(h), rtol=RTOL).equal


@needs_peers
def test_lexls_cap_on_factorizations_is_a_max_iterations_status():
    res = registry.create("lexls", max_factorizations=1).solve(g.ik_like(20, seed=0))
    assert res.status == MAX_ITERATIONS and res.x is None
    assert "cap of 1 factorizations" in res.reason and "max_factorizations" in res.reason


@needs_peers
@pytest.mark.parametrize("peer", PEERS)
def test_warm_re_solve_starts_from_the_last_active_set(peer):
    h = g.ik_like(20, seed=0)
    warm, cold = registry.create(peer), registry.create(peer, warm_start="none")
    first, cold1 = warm.solve(h), cold.solve(h)
    assert first.activations > 0 and cold1.activations == first.activations
    again, cold2 = warm.solve(h), cold.solve(h)
    assert again.activations == 0 and again.deactivations == 0  # (nothing left to change)
    assert cold2.activations == first.activations  # (warm_start="none" forgets it)
    np.testing.assert_allclose(again.x, first.x, rtol=0, atol=1e-9)
    warm.reset()
    assert warm.solve(h).activations == first.activations


@needs_peers
@pytest.mark.parametrize("peer", PEERS)
def test_warm_state_follows_a_moving_problem_of_the_same_shape(peer):
    """A control loop: bounds moved a little each step; the warm solver changes few
    constraints and solves each step as hcod does."""
    h0 = g.ik_like(20, seed=0)
    s = registry.create(peer)
    cold_acts = s.solve(h0).activations
    rng = np.random.default_rng(0)
    for _ in range(5):
        shift = 1e-3 * rng.standard_normal(h0.rows)
        h = h0.with_bounds(h0.lower + shift, h0.upper + shift)
        res = s.solve(h)
        assert res.status == OPTIMAL and verify(h, res.x, _hcod(h), rtol=RTOL).equal
        assert res.activations < cold_acts


@needs_peers
@pytest.mark.parametrize("peer", PEERS)
def test_a_problem_of_another_shape_is_solved_cold(peer):
    s = registry.create(peer)
    s.solve(g.ik_like(20, seed=0))
    h = g.ik_like(40, seed=0)
    res = s.solve(h)
    assert res.status == OPTIMAL and res.activations == registry.create(peer).solve(h).activations


@needs_peers
@pytest.mark.parametrize("peer, option, value", [
    ("soth", "epsilon", 0.0), ("soth", "epsilon", "1e-8"), ("soth", "warm_start", "stage"),
    ("lexls", "tol_linear_dependence", -1.0), ("lexls", "max_factorizations", 0),
    ("lexls", "warm_start", True)])
def test_a_wrong_option_value_is_refused_at_construction(peer, option, value):
    with pytest.raises(SolverOptionError, match=f"{peer}: option {option}="):
        registry.create(peer, **{option: value})


@needs_peers
def test_each_peers_rank_tolerance_defaults_to_its_own():
    assert registry.create("soth")._peer.epsilon == 1e-8
    lexls = registry.create("lexls")._peer
    assert lexls.tol_linear_dependence == 1e-12 and lexls.max_factorizations == 1000
    assert load_module("lexls").default_max_factorizations == 200  # (LexLS's own, raised: docs/peers.md)


@needs_peers
def test_soth_rank_tolerance_decides_a_near_dependent_row():
    """Two rows of level 0 at an angle of 1e-6: SOTH's default epsilon (1e-8) keeps both
    (x meets both), epsilon 1e-4 drops the second as dependent (level 0 then has a residual)."""
    A = np.array([[1.0, 0.0], [1.0, 1e-6]])
    h = Hierarchy.from_levels([Level.equality(A, [1.0, 2.0])], n=2)
    exact = registry.create("soth").solve(h)
    np.testing.assert_allclose(A @ exact.x, [1.0, 2.0], rtol=1e-6)
    coarse = registry.create("soth", epsilon=1e-4).solve(h)
    assert coarse.status == OPTIMAL and np.linalg.norm(A @ coarse.x - [1.0, 2.0]) > 0.1


@needs_peers
def test_the_build_is_recorded_for_run_json():
    from hikbench.bench.harness.environment import environment

    info = environment()["peers"]
    assert info == build_info() and "-O3" in info["flags"] and "-DNDEBUG" in info["flags"]
    assert info["march_native"] == ("-march=native" in info["flags"])
    assert set(info["peers"]) == set(PEERS)


# -- without a build ------------------------------------------------------------------------------

def _run(args, env_extra=None, **kw):
    env = {**os.environ, **(env_extra or {})}
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, env=env, timeout=120,
                          check=False, **kw)


def test_unbuilt_peers_are_listed_with_the_command_that_builds_them(tmp_path):
    done = _run(["-m", "hikbench", "list", "solvers"], {"HIKBENCH_PEERS_DIR": str(tmp_path)})
    assert done.returncode == 0, done.stderr
    for peer in PEERS:
        (line,) = [ln for ln in done.stdout.splitlines() if ln.startswith(peer + " ")]
        assert "not built: run `make peers`" in line


@pytest.mark.parametrize("env, why", [
    ({"PATH": "/nonexistent", "CXX": ""}, "no C++ compiler found"),
    ({}, "not found: PEERS_SRC must be a folder holding soth-d2485f4.tar.gz")], ids=["no-compiler", "no-source"])
def test_build_without_compiler_or_source_is_one_line_and_exit_2(tmp_path, env, why):
    done = _run([str(ROOT / "peers" / "build.py"), "--src", str(tmp_path / "none"), "--out", str(tmp_path / "out")],
                env)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and lines[0].startswith("make peers: ") and why in lines[0], \
        done.stderr
    assert not (tmp_path / "out").exists()


def test_build_with_no_compiler_process_is_one_line_and_exit_2(tmp_path):
    """`make peers PEERS_JOBS=0` is refused, naming the option, before anything is built."""
    done = _run([str(ROOT / "peers" / "build.py"), "--jobs", "0", "--out", str(tmp_path / "out")])
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip() == "make peers: --jobs (PEERS_JOBS) must be at least 1; got 0"
    assert not (tmp_path / "out").exists()
