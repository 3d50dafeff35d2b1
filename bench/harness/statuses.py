"""Row statuses the harness gives when a solve did not return: beside the
solvers' own (:data:`hikbench.solvers.base.STATUSES`)."""

from hikbench.solvers.base import STATUSES

__all__ = ["CRASHED", "ROW_STATUSES", "TIMEOUT"]

TIMEOUT = "timeout"  #: the harness killed the solve after its time limit
CRASHED = "crashed"  #: the worker process died (segfault, abort) or an external program was killed
#: every status a row of results.csv can have
ROW_STATUSES = (*STATUSES, TIMEOUT, CRASHED)
