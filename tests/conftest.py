"""Shared fixtures: one OpenCL device for the whole run, a seeded random generator per test, and the
settings of every hypothesis fuzz test (:func:`fuzz`)."""

import os
from pathlib import Path

import numpy as np
import pytest

import shadowcl as sc

PROJECT = Path(__file__).resolve().parents[1]
SCENES = PROJECT / "scenes"
MODELS = PROJECT.parent / "shared" / "models"
FUZZ_SEED = 14   # issue 14: the fuzz tests' draw, the same in CI and locally (for one hypothesis version)


def fuzz(max_examples: int, deadline=None):
    """The settings of a hypothesis fuzz test (put it above ``@given``): ``max_examples`` drawn from the
    fixed seed :data:`FUZZ_SEED`, no example database, so CI and a local run draw the same examples and
    the run is bounded. A stronger hunt changes both by environment, e.g.
    ``SHADOWCL_FUZZ_SCALE=20 SHADOWCL_FUZZ_SEED=3 pytest tests/test_range.py``: 20x the examples from seed 3."""
    from hypothesis import HealthCheck, seed, settings

    scale = float(os.environ.get("SHADOWCL_FUZZ_SCALE", "1"))
    chosen = int(os.environ.get("SHADOWCL_FUZZ_SEED", FUZZ_SEED))
    configured = settings(max_examples=max(1, round(max_examples * scale)), deadline=deadline, database=None,
                          derandomize=False, suppress_health_check=[HealthCheck.too_slow,
                                                                    HealthCheck.function_scoped_fixture])

    def decorate(test):
        return seed(chosen)(configured(test))
    return decorate


@pytest.fixture(scope="session")
def device():
    return sc.get_device()


@pytest.fixture
def rng():
    return np.random.default_rng(20261122)


def require_models():
    """The real meshes' folder; the test fails (never skips) when ../shared/models is not beside the
    checkout, so a CI run without them cannot pass with those tests silently left out."""
    if not MODELS.is_dir() or not any(MODELS.iterdir()):
        pytest.fail(f"real meshes not found at {MODELS}: the tests need ../shared/models beside the "
                    "checkout (see README, 'Set up and run')", pytrace=False)
    return MODELS


@pytest.fixture
def small_buffer_device(device, monkeypatch):
    """The device, allowing at most 256 MiB per buffer: PoCL reports a limit that follows free memory,
    so tests of the "does not fit" errors set one instead of depending on the machine."""
    monkeypatch.setattr(type(device), "max_alloc_bytes", property(lambda self: 256 << 20))
    return device
