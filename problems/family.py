"""A named problem family: a generator of hierarchies by seed, with default
parameters and a suggested sweep (:mod:`hikbench.problems.generators` and
:mod:`hikbench.problems.robots.testsets` define them)."""

from __future__ import annotations

import difflib
from collections.abc import Callable
from dataclasses import dataclass, field

from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import Hierarchy, check_fits_in_memory
from hikbench.problems.schema import Bool, Named, Number, Str

__all__ = ["Family"]

#: the type a parameter's value must have, by the type of its default; numbers are checked,
#: with their ranges, by the family's generator (``make``), a None default by the code using it
_BY_DEFAULT = {bool: Bool(), str: Str()}
_BOUND_SCALE = Number(0, low_open=True, unit="it multiplies every bound")
_WHOLE = Number(integer=True, whole_floats=True)


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
        params = {**self.defaults, **self.check_params(params)}
        if _WHOLE.fits(params.get("n")):  # (before the generator makes its n x n matrices; a wrong n is its to name)
            check_fits_in_memory(int(params["n"]), f"family {self.name}")
        scale = float(_BOUND_SCALE.check(params.pop("bound_scale"), "bound_scale", self._at()))
        h = self.make(seed=seed, **params)
        if scale != 1.0:
            h = h.with_bounds(h.lower * scale, h.upper * scale)
        return h

    def _at(self) -> Named:
        return Named(f"family {self.name!r}", HikbenchError)

    def check_params(self, params: dict) -> dict:
        """``params`` when each is a parameter of the family (:attr:`defaults`) and, where
        the default is a bool or a string, of that type; else HikbenchError
        ``family 'random': unknown parameter 'depht' (did you mean 'depth'?); expected one of ...``
        or ``family 'random': box must be true or false; got 1``."""
        at = self._at()
        for key in params:
            if key not in self.defaults:
                near = difflib.get_close_matches(str(key), list(self.defaults), n=1)
                hint = f" (did you mean {near[0]!r}?)" if near else ""
                at.say(f"unknown parameter {key!r}{hint}; expected one of {', '.join(self.defaults)}")
        return {key: _BY_DEFAULT[type(self.defaults[key])].check(value, key, at)
                if type(self.defaults[key]) in _BY_DEFAULT else value for key, value in params.items()}
