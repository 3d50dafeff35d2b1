"""The optional dependencies, by extra (pyproject.toml's
``[project.optional-dependencies]``), and the one line that says which extra a
missing module belongs to.

``pip install hikbench`` gives the core (the model, ``hcod``, the yardstick,
the qpsolvers cascades, the harness, the reports); ``robots``, ``cvxpy`` and
``dask`` add the rest, ``all`` all three. ``peers`` holds the headers ``make peers``
compiles the C++ peers SOTH and LexLS with (docs/peers.md).
"""

from __future__ import annotations

__all__ = ["EXTRA_OF", "extra_for", "install_hint"]

#: top-level module -> the extra that installs it
EXTRA_OF = {
    "pinocchio": "robots",
    "example_robot_data": "robots",
    "pink": "robots",
    "cvxpy": "cvxpy",
    "dask": "dask",
    "distributed": "dask",
}


def extra_for(module: str | None) -> str | None:
    """The extra that installs ``module`` (a dotted name; its top level counts),
    or None when it belongs to none."""
    return EXTRA_OF.get((module or "").split(".")[0])


def install_hint(module: str) -> str:
    """``"pinocchio is not installed: pip install 'hikbench[robots]'"``; for a
    module of no extra, ``pip install`` of the module itself."""
    extra = extra_for(module)
    top = module.split(".")[0]
    if extra is None:
        return f"{top} is not installed: pip install {top}"
    return f"{top} is not installed (extra '{extra}'): pip install 'hikbench[{extra}]'"
