"""Generators for the hard cases of DESIGN.md that are made in code, shared by tests and the bench."""

from __future__ import annotations

import numpy as np

from .geometry import Mesh


def icosphere(subdivisions: int) -> Mesh:
    """A closed unit icosphere: every edge shared by exactly two triangles."""
    import trimesh

    ico = trimesh.creation.icosphere(subdivisions=subdivisions)
    return Mesh(ico.vertices, ico.faces)


def aimed_receivers(mesh: Mesh, towards_light, per_edge: int, rng, light_position=None) -> np.ndarray:
    """Receivers inside a closed convex outward-wound ``mesh`` whose segment to the light passes through edge points
    and vertices computed in float32 (on the cap facing the light), so it crosses the surface exactly
    once, at a shared edge or vertex: a watertight test must report a hit for every one.

    Give ``light_position`` for a point light, else ``towards_light`` (unit direction to the light).
    """
    V, f = mesh.vertices, mesh.faces
    edges = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    lam = rng.random((len(edges), per_edge)).astype(np.float32)
    lam[:, 0] = 0.5
    on_edges = V[edges[:, 0]][:, None] + lam[..., None] * (V[edges[:, 1]] - V[edges[:, 0]])[:, None]
    targets = np.concatenate([on_edges.reshape(-1, 3), V]).astype(np.float64)  # float32 values
    centre = V.astype(np.float64).mean(0)
    radius = float(np.linalg.norm(V - centre, axis=1).mean())
    if light_position is not None:
        u = light_position - targets
        u /= np.linalg.norm(u, axis=1, keepdims=True)
    else:
        u = np.broadcast_to(towards_light, targets.shape)
    outward = (targets - centre) / np.linalg.norm(targets - centre, axis=1, keepdims=True)
    facing = np.einsum("ij,ij->i", outward, u) > 0.3
    receivers = targets[facing] - 0.25 * radius * u[facing]  # behind the aimed point
    # On a coarse mesh the step can leave the solid near a grazing vertex (icosphere(0): 9 of 67 did):
    # keep the receivers strictly inside every face plane, where the claim above holds.
    W = V.astype(np.float64)
    normals = np.cross(W[f[:, 1]] - W[f[:, 0]], W[f[:, 2]] - W[f[:, 0]])
    offsets = np.einsum("fk,fk->f", normals, W[f[:, 0]])
    inside = np.empty(len(receivers), dtype=bool)
    chunk = max(1, (1 << 24) // len(f))          # receivers x faces heights per step: 128 MiB at most
    for lo in range(0, len(receivers), chunk):
        heights = receivers[lo:lo + chunk] @ normals.T - offsets
        inside[lo:lo + chunk] = heights.max(axis=1) < 0
    return receivers[inside]
