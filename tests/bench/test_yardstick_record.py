"""The yardstick record (bench/harness/yardstick.py): a frozen :class:`Yardstick` read by
name, its cache file round-trips every field, a damaged or foreign file is said and computed
again, a cached yardstick is reused without a job, and a row is made from it."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from doubles import tiny

from hikbench.bench.harness.cache import problem_hash
from hikbench.bench.harness.runner import make_row
from hikbench.bench.harness.yardstick import (
    CERTIFIED,
    NO_YARDSTICK,
    REFERENCE_ONLY,
    Yardstick,
    certify_all,
    load_yardstick,
    save_yardstick,
    yardstick_path,
    yardsticks,
)
from hikbench.bench.suites import SolverEntry, Task
from hikbench.bench.suites.problemset import ProblemSpec, problem_columns
from hikbench.bench.specs import SolverSpec
from hikbench.problems.verify import level_norms
from hikbench.solvers.yardstick import nullspace_yardstick


class _NoJobs:
    """An executor that must not be asked for anything (every yardstick is cached)."""

    def map(self, items):
        items = list(items)
        assert not items, items
        return iter(())


class _Refusing:
    """An executor recording the kinds of the jobs asked, each answered with status error."""

    def __init__(self):
        self.kinds = []

    def map(self, items):
        for key, job, _ in items:
            self.kinds.append(job["kind"])
            yield key, {"status": "error", "reason": "not run here", "x": None}


class _Said:
    """The run's progress and log callback, recording what is said."""

    def __init__(self):
        self.lines = []

    def say(self, line):
        self.lines.append(line)

    def add(self, description, total):
        return 0

    def advance(self, tid, label="", steps=1):
        pass


def test_a_yardstick_is_frozen():
    y = Yardstick(np.zeros(2), "optimal", "note", CERTIFIED, "why")
    with pytest.raises(dataclasses.FrozenInstanceError):
        y.kind = REFERENCE_ONLY
    assert dataclasses.replace(y, kind=REFERENCE_ONLY).kind == REFERENCE_ONLY and y.kind == CERTIFIED
    assert y.certify_budget == 0.0


@pytest.mark.parametrize("ref", [
    Yardstick(np.array([1.0, -2.5, 1e-300]), "optimal", "the independent yardstick's point", CERTIFIED,
              "the certificate's exact optimum x*, from the independent yardstick's point"),
    Yardstick(np.array([0.5, 0.0, 3.0]), "optimal", "hcod's point", REFERENCE_ONLY,
              "hcod's point; not certified: timed out", 30.0),
    Yardstick(None, "timeout", "independent yardstick timeout: ", NO_YARDSTICK, "no candidate point"),
], ids=["certified", "reference-only-with-budget", "none"])
def test_the_cache_file_round_trips_every_field(tmp_path, ref):
    path = yardstick_path(tmp_path, "0123456789abcdef")
    assert path == tmp_path / "yardstick" / "0123456789abcdef.npz"
    save_yardstick(path, ref, "0123456789abcdef", "fedcba9876543210")
    said = _Said()
    got, phash, code = load_yardstick(path, 3, said.say)
    assert (phash, code, said.lines) == ("0123456789abcdef", "fedcba9876543210", [])
    for f in dataclasses.fields(Yardstick):
        a, b = getattr(got, f.name), getattr(ref, f.name)
        if f.name == "x" and b is not None:
            np.testing.assert_array_equal(a, b)
        else:
            assert a == b, f.name


def test_a_cache_file_of_another_size_is_said_and_dropped(tmp_path):
    path = yardstick_path(tmp_path, "0123456789abcdef")
    save_yardstick(path, Yardstick(np.ones(3), "optimal", "", CERTIFIED, ""), "0123456789abcdef", "c")
    said = _Said()
    assert load_yardstick(path, 4, said.say) is None
    [line] = said.lines
    assert line.startswith(f"{path} cannot be read (ValueError: x of dtype float64 and shape (3,): expected "
                           f"float64 of shape (4,))") and line.endswith("computing the yardstick again")


def _problem(seed=0):
    ps = ProblemSpec("equality", {"n": 6}, seed)
    h = tiny(seed)
    return ps, h, {**problem_columns(ps, h), "problem_hash": problem_hash(h)}


def test_a_cached_yardstick_is_reused_without_a_job_and_shared_by_the_same_content(tmp_path, monkeypatch):
    from hikbench.bench.harness import yardstick as module

    ps, h, cols = _problem()
    ref = Yardstick(nullspace_yardstick(h), "optimal", "the independent yardstick's point", CERTIFIED, "certified")
    save_yardstick(yardstick_path(tmp_path, cols["problem_hash"]), ref, cols["problem_hash"], module.yardstick_code())
    said = _Said()
    refs = yardsticks(["a", "b"], {"a": ps}, {"a": h, "b": h}, {"a": cols, "b": cols}, tmp_path, _NoJobs(),
                      timeout=10.0, certify_timeout=10.0, progress=said)
    assert refs["a"] is refs["b"] and said.lines == []
    np.testing.assert_array_equal(refs["a"].x, ref.x)
    assert (refs["a"].kind, refs["a"].kind_reason) == (CERTIFIED, "certified")
    monkeypatch.setattr(module, "yardstick_code", lambda: "0000000000000000")  # (other code: computed again)
    jobs = _Refusing()
    refs = yardsticks(["a"], {"a": ps}, {"a": h}, {"a": cols}, tmp_path, jobs, 10.0, 10.0, said)
    assert jobs.kinds == ["yardstick", "candidate"] and refs["a"].kind == NO_YARDSTICK
    assert refs["a"].reason == "independent yardstick error: not run here; hcod error: not run here"
    assert said.lines == ["1 cached yardstick(s) computed again: the yardstick's code changed "
                          "(hikbench.bench.harness.cache.YARDSTICK_MODULES, version 0000000000000000)"]


def test_a_certificate_beyond_its_budget_is_not_tried_and_keeps_the_point():
    _, h, _ = _problem()
    x = nullspace_yardstick(h)
    [(pid, ref)] = certify_all({"p": (x, "the independent yardstick's point")}, {"p": h}, _NoJobs(), 1e-9,
                               _Said()).items()
    assert (pid, ref.kind, ref.status, ref.certify_budget) == ("p", REFERENCE_ONLY, "optimal", 1e-9)
    assert ref.x is x and ref.kind_reason.startswith("the independent yardstick's point; not certified: the exact "
                                                     "certificate was not tried")


@pytest.mark.parametrize("kind, verified, side", [
    (CERTIFIED, True, None),
    (REFERENCE_ONLY, None, "no certified yardstick"),
    (NO_YARDSTICK, None, "no yardstick"),
], ids=["certified", "reference-only", "none"])
def test_a_row_reads_its_yardstick_by_name(kind, verified, side):
    ps, h, cols = _problem()
    x = nullspace_yardstick(h)
    ref = Yardstick(None if kind == NO_YARDSTICK else x, "optimal" if kind != NO_YARDSTICK else "error",
                    "the note" if kind != NO_YARDSTICK else "independent yardstick error: E", kind, "the kind's reason")
    task = Task(ps, SolverEntry("s", SolverSpec.parse("hcod")), "cold")
    row = make_row(task, cols, h, ref, {"status": "optimal", "x": x, "samples_ns": [1000, 2000]})
    assert (row["verified"], row.get("verdict_side"), row["yardstick"], row["yardstick_reason"]) == (
        verified, side, kind, "the kind's reason")
    if kind == NO_YARDSTICK:
        assert row["reason"] == "yardstick error: independent yardstick error: E"
    else:
        np.testing.assert_allclose(np.array(json.loads(row["ref_level_norms"])), level_norms(h, x), rtol=0, atol=0)
