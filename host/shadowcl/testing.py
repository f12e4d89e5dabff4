"""Test fixtures shared by tests/ and bench/ (not used by the library): hard cases of DESIGN.md made in code."""

from __future__ import annotations

import numpy as np

from .geometry import Mesh
from .subdivision import PatchTable


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


def grid_patch_table(net, wrap_u: bool = False, wrap_v: bool = False) -> PatchTable:
    """Regular B-spline patches of the (m, n, 3) control grid ``net`` (u along the first axis, v along
    the second): one per interior span, or per span along a wrapped axis (a torus wraps both); each is
    its own control face, over the unit domain.

    Patch normals (du x dv) follow the grid's orientation: make it outward for closed surfaces.
    """
    net = np.asarray(net, dtype=np.float64)
    if net.ndim != 3 or net.shape[2] != 3:
        raise ValueError(f"net: expected an (m, n, 3) control grid, got shape {net.shape}")
    m, n = net.shape[:2]
    pu = m if wrap_u else m - 3
    pv = n if wrap_v else n - 3
    if pu < 1 or pv < 1:
        raise ValueError("net: too few control points for one patch (4 per open axis)")
    a0 = np.arange(pu) - (1 if wrap_u else 0)
    b0 = np.arange(pv) - (1 if wrap_v else 0)
    ii, jj = np.arange(4), np.arange(4)
    A = (a0[:, None, None, None] + ii[None, None, None, :]) % m          # [a, b, j, i]
    B = (b0[None, :, None, None] + jj[None, None, :, None]) % n
    A, B = np.broadcast_arrays(A, B)
    points = net[A, B].reshape(-1, 3).astype(np.float32)
    count = pu * pv
    a, b = np.meshgrid(np.arange(pu), np.arange(pv), indexing="ij")

    def index(x, y):
        ok = np.ones_like(x, dtype=bool)
        if wrap_u:
            x = x % pu
        else:
            ok &= (x >= 0) & (x < pu)
        if wrap_v:
            y = y % pv
        else:
            ok &= (y >= 0) & (y < pv)
        return np.where(ok, np.clip(x, 0, pu - 1) * pv + np.clip(y, 0, pv - 1), -1)

    neighbors = np.stack([index(a, b - 1), index(a + 1, b), index(a, b + 1), index(a - 1, b)], axis=-1)
    return PatchTable(points, 16 * np.arange(count), np.zeros(count), np.arange(count),
                      np.tile([0.0, 0.0, 1.0, 1.0], (count, 1)), np.zeros(count), neighbors.reshape(-1, 4))
