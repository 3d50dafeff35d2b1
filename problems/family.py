"""A named problem family: a generator of hierarchies by seed, with default
parameters and a suggested sweep (:mod:`hikbench.problems.generators` and
:mod:`hikbench.problems.robots.testsets` define them)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import Hierarchy

__all__ = ["Family", "finite_number"]


def finite_number(v, label: str, low: float, what: str = "", high: float = np.inf, low_open: bool = False) -> float:
    """v as a finite float in [low, high] (``(low, high]`` when ``low_open``);
    HikbenchError naming ``label`` otherwise (a string, True, NaN, inf, or a
    value outside the interval)."""
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer, float, np.floating)) \
            or not np.isfinite(v) or not low <= v <= high or (low_open and v == low):
        bound = f" and <= {high:g}" if np.isfinite(high) else ""
        raise HikbenchError(f"{label} must be a finite number {'>' if low_open else '>='} {low:g}{bound}{what}; "
                            f"got {v!r}")
    return float(v)



@dataclass(frozen=True)
class Family:
    """A named problem family.

    Attributes
    ----------
    name, description : str
    make : callable
        ``make(seed=..., **params) -> Hierarchy``.
    defaults : dict
        Default parameters.
    sweep : dict
        Suggested grid for sweeps: parameter -> list of values.
    """

    name: str
    description: str
    make: Callable[..., Hierarchy]
    defaults: dict = field(default_factory=dict)
    sweep: dict = field(default_factory=dict)

    def __post_init__(self):
        # every family takes bound_scale (see generate); its default is in defaults, for the CLI
        object.__setattr__(self, "defaults", {**self.defaults, "bound_scale": 1.0})

    def generate(self, seed: int = 0, **params) -> Hierarchy:
        """The family's problem for ``seed`` and ``params`` (the defaults for
        the others). ``bound_scale`` (every family, default 1) multiplies every
        bound, equality targets included: the problem in other units of x,
        whose lexicographic optima are the scaled ones (the problem is
        homogeneous in (x, bounds)). Small scales test a solver's absolute
        tolerances."""
        unknown = sorted(set(params) - set(self.defaults))
        if unknown:
            raise HikbenchError(f"family {self.name!r}: unknown parameter(s) {unknown}; "
                                f"expected some of {sorted(self.defaults)}")
        params = {**self.defaults, **params}
        scale = finite_number(params.pop("bound_scale"), f"family {self.name!r}: bound_scale", 0,
                        " (it multiplies every bound)", low_open=True)
        h = self.make(seed=seed, **params)
        if scale != 1.0:
            h = h.with_bounds(h.lower * scale, h.upper * scale)
        return h
