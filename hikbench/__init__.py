"""hikbench: a benchmark harness for hierarchized (prioritized) inverse kinematics.

Three subpackages, data flowing one way: :mod:`hikbench.problems` (what is
solved) -> :mod:`hikbench.solvers` (how it is solved) -> :mod:`hikbench.bench`
(how it is measured). The console script is ``hikbench`` (also
``python -m hikbench``).
"""

from importlib.metadata import version

__version__ = version("hikbench")

__all__ = ["__version__"]
