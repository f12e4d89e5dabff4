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
        d = vector3("direction", direction, nonzero=True)
        object.__setattr__(self, "direction", d / np.linalg.norm(d))

    def direction_to_light(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) unit vectors from ``points`` towards the light (the same for every point)."""
        return np.broadcast_to(-self.direction, np.shape(points)).copy()


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
