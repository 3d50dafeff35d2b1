"""Session-scoped robot models (loading one takes ~0.3-2 s)."""

import pytest


@pytest.fixture(scope="session")
def talos():
    from hikbench.problems.robots.models import load_robot

    return load_robot("talos")


@pytest.fixture(scope="session")
def panda():
    from hikbench.problems.robots.models import load_robot

    return load_robot("panda")
