"""The dual active-set cascades as independent judges of hcod and the yardstick.

A judge solves each level on the exact frozen set of the levels above (freeze ``shift``,
regularisation 1e-12), not on the backend's default: ``relaxed`` (quadprog's default) widens
that set by 1e-9, so its level k + 1 may end below the optimum by more than verify's 1e-9
where level k pays for it within it."""

from __future__ import annotations

from hikbench.solvers import registry

#: the options of each cascade used as a judge
JUDGE_OPTIONS = {"cascade-daqp": {"freeze": "shift", "regularization": 1e-12},
                 "cascade-quadprog": {"freeze": "shift", "regularization": 1e-12}}


def judge(name: str):
    """The registry solver ``name`` built as a judge (:data:`JUDGE_OPTIONS`)."""
    return registry.create(name, **JUDGE_OPTIONS.get(name, {}))
