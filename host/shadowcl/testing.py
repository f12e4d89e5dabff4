"""Test fixtures shared by tests/ and bench/ (not used by the library): hard cases of DESIGN.md made in
code, and the judge of the working range (:func:`wrong_receivers`)."""

from __future__ import annotations

import numpy as np

from .frame import is_distant, union
from .geometry import Mesh, bounds_diagonal
from .lights import DirectionalLight
from .methods import method_class
from .reference import exact as ref
from .subdivision import PatchTable

FLOAT_BAND = 1e-5   # of the scene's size: float32 rounding, as test_exact.py
# Of the scene's size, the distance from a shadow edge within which a method's answer is its
# discretisation's: a 2048-texel map over ~1.5x the scene is ~7e-4 a texel, the band four texels; the
# angular rows are about one receiver spacing wide (eq. 4), ~0.35 on the 6 x 6 ground with 400
# receivers, 4 % of the scene's size; the exact and shadow-volume methods have none.
METHOD_BAND = {"exact": 0.0, "shadow_volume": 0.0, "shadow_map": 3e-3, "angular": 5e-2}


def wrong_receivers(method: str, mesh: Mesh, light, points, mask, normals=None, eps=None):
    """``(truth, wrong)``: the float64 brute force's mask of ``points`` (world coordinates, ``eps``
    absolute, None: 1e-4 of ``mesh``'s diagonal) and the indices where ``method``'s ``mask`` differs
    from it outside the band where the method may decide either way (:func:`free_receivers`)."""
    points = np.asarray(points, dtype=np.float64)
    eps = eps if eps is not None else 1e-4 * bounds_diagonal(mesh.bounds)
    truth = ref.shadow_mask(mesh.vertices, mesh.faces, light, points, normals, eps)
    wrong = np.flatnonzero(mask != truth)
    if len(wrong):
        reach = union(mesh.bounds, np.stack([points.min(0), points.max(0)]))
        subset = None if normals is None else np.asarray(normals)[wrong]
        wrong = wrong[~free_receivers(method, mesh, light, points[wrong], subset, eps, reach)]
    return truth, wrong


def grazing(light, points, normals) -> np.ndarray:
    """bool (N,): receivers whose normal is within FLOAT_BAND radians of perpendicular to the light (or
    that lie at a point light): the facing test ``n . (light - p) <= 0`` is a tie that float32 rounding
    of any method's own arithmetic decides (a receiver in the light's plane, its normal in that plane)."""
    if normals is None:
        return np.zeros(len(points), dtype=bool)
    n = np.asarray(normals, dtype=np.float64)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    if isinstance(light, DirectionalLight):
        to_light = np.broadcast_to(-np.asarray(light.direction, dtype=np.float64), n.shape)
    else:
        to_light = np.asarray(light.position, dtype=np.float64) - points
    length = np.linalg.norm(to_light, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cosine = np.einsum("ij,ij->i", n, to_light) / length
    return (length == 0) | (np.abs(cosine) < FLOAT_BAND)


def free_receivers(method: str, mesh: Mesh, light, points, normals, eps: float, reach: np.ndarray) -> np.ndarray:
    """bool (N,): the receivers (world) where ``method`` may answer either way: the float32 band (the
    segment within FLOAT_BAND of a triangle edge, or its nearest hit within FLOAT_BAND of the start or
    the light, or a normal :func:`grazing` the light), the method's discretisation band (:data:`METHOD_BAND`), and, for a point light the
    method is given as the directional light (beyond its ``point_light_reach`` of ``reach``, the box of
    the occluders and all the query's receivers), where the two lights' brute forces differ, and that
    directional light's own float32 band."""
    v, f = mesh.vertices, mesh.faces
    # The method's band is the occluders' (a far receiver must not widen it: that would hide a map
    # coarsened by it); rounding grows with a receiver's own distance from them.
    occluders = bounds_diagonal(mesh.bounds)
    distance = np.linalg.norm(points - 0.5 * (mesh.bounds[0] + mesh.bounds[1]), axis=1)
    band = np.maximum(FLOAT_BAND * np.maximum(occluders, distance), METHOD_BAND[method] * occluders)
    lights = [light]
    free = np.zeros(len(points), dtype=bool)
    if is_distant(light, reach, method_class(method).point_light_reach):
        parallel = DirectionalLight(0.5 * (reach[0] + reach[1]) - light.position)
        free |= ref.shadow_mask(v, f, light, points, normals, eps) != ref.shadow_mask(v, f, parallel, points, normals, eps)
        lights.append(parallel)   # the light the method answers for: its float32 band too (the point
                                  # light's overflows in float64 beyond ~1e150)
    for each in lights:
        with np.errstate(over="ignore", invalid="ignore"):
            free |= ref.segment_edge_distance(v, f, each, points, normals, eps) < band
        free |= grazing(each, points, normals)
        free |= ref.shadow_mask(v, f, each, points, normals, eps, margin=FLOAT_BAND * occluders) != \
            ref.shadow_mask(v, f, each, points, normals, eps, margin=-FLOAT_BAND * occluders)
    return free


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
