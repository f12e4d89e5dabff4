"""Sensor grids for sun-hours studies: points on the upward-facing faces of named objects.

A grid is square as seen from above: the lattice ``spacing * (i u + j v)`` of the plane across ``up``
(``u``, ``v`` a fixed basis of it), and each lattice point inside an upward-facing triangle's
projection is lifted onto the triangle, then moved ``offset`` along its normal. Lattice points on an
edge shared by two triangles of one object are kept once. A scene file's ``[[sensors]]`` tables
(:mod:`shadowcl.scene`) name the objects, the spacing and the offset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checks import vector3

UPWARD = 1e-3   # a face counts as upward-facing when its unit normal's component along up exceeds this
# Lattice points a grid may span (summed over the upward faces' bounding boxes, about twice the sensors):
# 1e8 sensors already take 4.8 GB of points and normals and hours of queries per sun step, so more is
# almost surely a spacing in the wrong unit, refused before NumPy tries to allocate it.
MAX_LATTICE_POINTS = 2 * 10**8


@dataclass(frozen=True)
class SensorGrid:
    """One named grid: ``points`` (N, 3) float64 and unit ``normals`` (N, 3)."""

    name: str
    points: np.ndarray
    normals: np.ndarray


def scene_sensors(scene, spacing: float | None = None, up=(0.0, 1.0, 0.0)) -> list[SensorGrid]:
    """The grids of ``scene.sensors`` (its ``[[sensors]]`` tables), with every spacing replaced by
    ``spacing`` when given. Raises ``ValueError`` when the scene has none."""
    if not scene.sensors:
        raise ValueError(f"scene {scene.name!r}: has no [[sensors]] grids")
    if spacing is not None and not (np.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing: must be a positive distance, got {spacing}")
    meshes = dict(scene.objects)
    return [SensorGrid(spec["name"], *grid_on_faces([meshes[name] for name in spec["objects"]],
                                                     spec["spacing"] if spacing is None else spacing,
                                                     spec["offset"], up))
            for spec in scene.sensors]


def grid_on_faces(meshes, spacing: float, offset: float = 0.0, up=(0.0, 1.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) and unit normals (N, 3) of the grid over the upward-facing triangles of ``meshes``."""
    if not (np.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing: must be a positive distance, got {spacing}")
    up = vector3("up", up, nonzero=True)
    up = up / np.linalg.norm(up)
    u = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    v = np.cross(up, u)
    faces = [_upward_faces(mesh, spacing, u, v, up) for mesh in meshes]
    count = sum(_lattice_count(plane) for _, _, plane in faces)
    if count > MAX_LATTICE_POINTS:
        raise ValueError(f"spacing: {spacing} puts {count:.3g} lattice points over the upward faces' bounding "
                         f"boxes, more than the {MAX_LATTICE_POINTS:.0e} a sensor grid may span")
    points, normals = [], []
    for corners, normal, plane in faces:
        p, n = _mesh_grid(corners, normal, plane, spacing, up)
        points.append(p + offset * n)
        normals.append(n)
    return np.concatenate(points), np.concatenate(normals)


def _upward_faces(mesh, spacing, u, v, up):
    """One mesh's upward-facing triangles: corners (F, 3, 3), unit normals (F, 3) and corners in
    lattice units (F, 3, 2)."""
    corners = mesh.vertices.astype(np.float64)[mesh.faces]                # (F, 3, 3)
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(normal, axis=1)
    keep = length > 0
    normal[keep] /= length[keep, None]
    upward = keep & (normal @ up > UPWARD)
    corners, normal = corners[upward], normal[upward]
    return corners, normal, np.stack([corners @ u, corners @ v], axis=-1) / spacing


def _lattice_count(plane) -> float:
    """Lattice points in the bounding boxes of the triangles ``plane`` (F, 3, 2), as a float (no overflow)."""
    sides = np.floor(plane.max(axis=1)) - np.ceil(plane.min(axis=1)) + 1
    return float(np.prod(np.maximum(sides, 0), axis=1).sum())


def _mesh_grid(corners, normal, plane, spacing, up):
    """The lattice points on one mesh's upward-facing triangles, once each."""
    keys, points, normals = [], [], []
    for f in range(len(plane)):
        tri = plane[f]
        lo, hi = np.ceil(tri.min(axis=0)).astype(np.int64), np.floor(tri.max(axis=0)).astype(np.int64)
        if np.any(hi < lo):
            continue
        i, j = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
        ij = np.stack([i.ravel(), j.ravel()], axis=1)
        weights = _barycentric(tri, ij.astype(np.float64))
        inside = np.all(weights >= -1e-9, axis=1)
        if not inside.any():
            continue
        world = weights[inside] @ corners[f]
        keys.append(np.column_stack([ij[inside], np.round(world @ up / spacing * 1e3).astype(np.int64)]))
        points.append(world)
        normals.append(np.broadcast_to(normal[f], world.shape))
    if not points:
        return np.zeros((0, 3)), np.zeros((0, 3))
    _, first = np.unique(np.concatenate(keys), axis=0, return_index=True)
    first.sort()
    return np.concatenate(points)[first], np.ascontiguousarray(np.concatenate(normals)[first])


def _barycentric(tri: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(K, 3) barycentric weights of the 2-D points ``xy`` in the 2-D triangle ``tri``."""
    a, b, c = tri
    det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
    w1 = ((xy[:, 0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (xy[:, 1] - a[1])) / det
    w2 = ((b[0] - a[0]) * (xy[:, 1] - a[1]) - (xy[:, 0] - a[0]) * (b[1] - a[1])) / det
    return np.column_stack([1 - w1 - w2, w1, w2])
