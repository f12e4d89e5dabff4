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
    """Skip (with the reason) when ../shared/models is not beside the checkout."""
    if not MODELS.is_dir():
        pytest.skip(f"real meshes not found at {MODELS}")
    return MODELS


@pytest.fixture
def small_buffer_device(device, monkeypatch):
    """The device, allowing at most 256 MiB per buffer: PoCL reports a limit that follows free memory,
    so tests of the "does not fit" errors set one instead of depending on the machine."""
    monkeypatch.setattr(type(device), "max_alloc_bytes", property(lambda self: 256 << 20))
    return device
