"""Shared test set-up: hypothesis profiles and fixtures."""

import os

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile("default", deadline=None, max_examples=30,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("ci", deadline=None, max_examples=30, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("ci" if os.environ.get("CI") else "default")


@pytest.fixture(scope="module")
def hcod_kernels_loaded_first():
    """hcod's kernels loaded before a test module that calls its helpers
    directly: a kernel loaded after them would call the helpers' own
    objects, not the copies inside it, and compute other last bits than in
    other processes (hikbench.solvers.hcod._cache.load_kernels)."""
    from hikbench.solvers.hcod import warmup

    warmup()
