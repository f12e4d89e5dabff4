"""Shared fixtures: one OpenCL device for the whole run, a seeded random generator per test."""

from pathlib import Path

import numpy as np
import pytest

import shadowcl as sc

PROJECT = Path(__file__).resolve().parents[1]
SCENES = PROJECT / "scenes"
MODELS = PROJECT.parent / "shared" / "models"


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
