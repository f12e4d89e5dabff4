"""Lights: a point light, and a directional light given by the direction its light travels."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checks import vector3


@dataclass(frozen=True, init=False)
class PointLight:
    """A point light at ``position``; a point is lit when its segment to the light is unblocked."""

    position: np.ndarray

    def __init__(self, position):
        object.__setattr__(self, "position", vector3("position", position))

    def direction_to_light(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) unnormalised vectors from ``points`` to the light."""
        return self.position - points


@dataclass(frozen=True, init=False)
class DirectionalLight:
    """A light at infinity whose light travels along ``direction`` (normalised on construction)."""

    direction: np.ndarray

    def __init__(self, direction):
        object.__setattr__(self, "direction", unit_vector("direction", direction))

    def direction_to_light(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) unit vectors from ``points`` towards the light (the same for every point)."""
        return np.broadcast_to(-self.direction, np.shape(points)).copy()


def unit_vector(name: str, value) -> np.ndarray:
    """``value`` (finite, non-zero) as a float64 unit vector, scaled by its largest component first so
    that neither huge (1e200) nor tiny (1e-200) components overflow or underflow the length."""
    v = vector3(name, value)
    largest = np.abs(v).max()
    if largest == 0:
        raise ValueError(f"{name}: must have non-zero length, got {v.tolist()}")
    v = v / largest
    return v / np.linalg.norm(v)


Light = PointLight | DirectionalLight


def check_light(light) -> Light:
    if not isinstance(light, (PointLight, DirectionalLight)):
        raise TypeError(f"light: expected a PointLight or DirectionalLight, got {type(light).__name__}")
    return light


def same_light(a, b) -> bool:
    """Whether lights ``a`` and ``b`` are the same light (type and coordinates, bit for bit)."""
    if type(a) is not type(b):
        return False
    vector = "position" if isinstance(a, PointLight) else "direction"
    return bool(np.array_equal(getattr(a, vector), getattr(b, vector)))
