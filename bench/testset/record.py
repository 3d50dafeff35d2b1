"""Control steps recorded from a closed-loop scenario, for the test set (docs/testset.md).

The scenario runs once with ``hcod`` (``time`` warm start: what a controller runs), and each
step's hierarchy is kept with the controller's u. The set takes every ``every``-th step, every
step whose active set (:func:`hikbench.bench.scenarios.runner.active_rows` of u) differs from
the previous step's (the hard steps: an activation or a deactivation), and one run of
``sequence`` consecutive steps, kept in order as a sequence (the warm-start ranking).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hikbench.problems.errors import HikbenchError

__all__ = ["Step", "record_steps", "select_steps"]


@dataclass
class Step:
    """One recorded control step: its number, hierarchy, the controller's u (or None) and
    whether its active set differs from the previous step's."""

    step: int
    hierarchy: object
    u: np.ndarray | None
    changed: bool


def record_steps(scenario: str, robot: str | None = None, steps: int | None = None,
                 solver: str = "hcod", warm_start: str = "time") -> tuple[list[Step], object]:
    """Run ``scenario`` on ``robot`` (a name or a .urdf path; default the scenario's) for
    ``steps`` control steps (default the scenario's) with ``solver``; returns every step and the
    loaded Scenario."""
    from hikbench.bench.scenarios.runner import active_rows, run_scenario
    from hikbench.problems.robots.scenarios import load_scenario

    sc = load_scenario(scenario, robot=robot)
    recorded, before = [], [None]

    def keep(k, h, res):
        u = None if res.x is None or not np.all(np.isfinite(res.x)) else np.array(res.x, dtype=float)
        now = None if u is None else active_rows(h, u)
        prev = before[0]
        changed = k > 0 and (now is None or prev is None or now.shape != prev.shape or bool(np.any(now != prev)))
        before[0] = now
        recorded.append(Step(k, h, u, changed))

    run_scenario(sc, solver, warm_start=warm_start, steps=steps, repeat=1, on_step=keep)
    return recorded, sc


def select_steps(recorded: list[Step], every: int, sequence: int, sequence_start: int | None = None,
                 max_changes: int | None = None) -> tuple[list[Step], list[Step]]:
    """``(single, run)``: the steps k with ``k % every == 0`` or an active-set change (outside the
    sequence; ``max_changes``: at most that many of the change steps, evenly spread over them), and ``sequence`` consecutive steps from ``sequence_start`` (default: a fifth of
    them before the first active-set change at or after the middle of the run, else before the
    first change: the run crosses activations)."""
    if every < 1 or sequence < 0:
        raise HikbenchError(f"every must be >= 1 and sequence >= 0; got every={every}, sequence={sequence}")
    if sequence_start is None:
        changes = [s.step for s in recorded if s.changed and s.step > 0]
        late = [k for k in changes if k >= len(recorded) // 2]
        first = (late or changes or [0])[0]
        sequence_start = max(0, min(first - sequence // 5, len(recorded) - sequence))
    run = [s for s in recorded if sequence_start <= s.step < sequence_start + sequence]
    in_run = {s.step for s in run}
    changes = [s.step for s in recorded if s.step not in in_run and s.changed and s.step % every]
    if max_changes is not None and len(changes) > max_changes:
        changes = [changes[i] for i in np.linspace(0, len(changes) - 1, max_changes).round().astype(int)] \
            if max_changes > 0 else []
    keep = set(changes)
    single = [s for s in recorded if s.step not in in_run and (s.step % every == 0 or s.step in keep)]
    return single, run
