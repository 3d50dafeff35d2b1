"""Each registered solver's SolverInfo is what its class declares: the name, the
description and the flags are the class attributes, the options the defaults of
its ``__init__`` (hikbench.solvers.info.SolverInfo.of); nothing re-declared."""

from __future__ import annotations

import inspect

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hikbench.solvers import registry
from hikbench.solvers.base import Solver, SolveResult
from hikbench.solvers.errors import SolverOptionError
from hikbench.solvers.info import SolverInfo

INFOS = registry.available()


def _declared_defaults(cls) -> dict:
    """The keyword defaults written in ``cls.__init__``'s signature."""
    params = inspect.signature(cls.__init__).parameters.values()
    return {p.name: p.default for p in params if p.name != "self" and p.default is not p.empty}


@pytest.mark.parametrize("name", list(INFOS), ids=list(INFOS))
def test_registered_info_is_what_the_class_declares(name):
    info = INFOS[name]
    cls = info.factory
    assert isinstance(cls, type) and issubclass(cls, Solver)
    assert (info.name, info.description) == (cls.name, cls.description)
    assert (info.supports_inequalities, info.supports_warm_start, info.strict) == \
        (cls.supports_inequalities, cls.supports_warm_start, cls.strict)
    declared = _declared_defaults(cls)
    assert info.options == declared
    assert set(info.options) == set(registry.option_names(info))  # every option has its default


@pytest.mark.parametrize("name", list(INFOS), ids=list(INFOS))
def test_defaults_build_the_solver_the_class_builds(name):
    """The defaults listed are those a solver built with none uses (an attribute of each
    option the class keeps under its own name compares equal)."""
    info = INFOS[name]
    if name.startswith("daqp") or name in ("soth", "lexls", "nipm-hlsp"):
        pytest.skip("keeps its options in the backend's settings")
    listed, plain = registry.create(name), info.factory()
    for key in info.options:
        if hasattr(plain, key) and not callable(getattr(plain, key)):
            assert getattr(listed, key) == getattr(plain, key), key


def test_of_reads_a_new_class():
    class Mine(Solver):
        name = "mine"
        description = "a test double"
        supports_inequalities = True
        strict = False

        def __init__(self, tol: float = 1e-6, *, passes: int = 2, label=None):
            self.tol, self.passes, self.label = tol, passes, label

        def solve(self, hierarchy):  # pragma: no cover - never called
            return SolveResult(None, "unsupported")

    info = SolverInfo.of(Mine)
    assert info == SolverInfo("mine", "a test double", Mine, supports_inequalities=True, supports_warm_start=False,
                              strict=False, options={"tol": 1e-6, "passes": 2, "label": None})


@pytest.mark.parametrize("obj, message", [
    (len, "expects a hikbench.solvers.base.Solver subclass"),
    (type("Nameless", (Solver,), {"solve": lambda self, h: None}), "needs a class attribute `name`"),
], ids=["function", "nameless"])
def test_of_refuses_what_is_not_a_named_solver_class(obj, message):
    with pytest.raises(TypeError, match=message):
        SolverInfo.of(obj)


VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6), st.sampled_from(["time", "none", "high", "shift", "CLARABEL", "[1, 2]"]),
    st.lists(st.floats(-2, 2), max_size=3), st.dictionaries(st.text(max_size=2), st.integers(), max_size=2),
)


@pytest.mark.parametrize("name", list(INFOS), ids=list(INFOS))
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_option_value_builds_or_is_one_line_naming_the_option(name, data):
    """Whatever value an option gets, the solver is built or SolverOptionError names the
    solver and the option on one line; no other exception escapes the constructor."""
    info = INFOS[name]
    if not info.options:
        return
    option = data.draw(st.sampled_from(sorted(info.options)), label="option")
    value = data.draw(VALUES, label="value")
    try:
        registry.create(name, **{option: value})
    except SolverOptionError as err:
        message = str(err)
        assert message.startswith(f"{name}: option {option}") and "\n" not in message, message
