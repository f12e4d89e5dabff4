"""Reference shadow-map test in NumPy float64: the oracle of ``tests/test_shadow_map.py``.

Written from Williams (1978) and the contract of ``kernels/shadow_map.cl``, without calling the
method's host code: it takes the light's depth maps and view records as plain arrays (what
``ShadowMapMethod.prepare`` built, or maps from ``reference/raster.py``) and repeats the test:

1. A receiver whose normal faces away from the light (``dot <= 0``) has visibility 0.
2. Texel footprint ``T``: the widest extent of one texel across the light's ray at the receiver. In
   perspective that is the texel size (tangent units) times ``d . forward`` (``d`` from the eye): at
   angle ``alpha`` off the view axis the texel is ``d . forward`` wide across the ray in the direction
   perpendicular to the axis and the ray, and narrower by ``cos(alpha)`` in the other (see
   :func:`texel_footprint`). Orthographically it is the texel size.
3. Bias (``bias = (constant, slope)`` in texels): the receiver may lie ``constant T`` behind the stored
   surface; "slope" adds ``slope T min(tan theta, 16)``; "normal" lifts it ``slope T sin theta`` along its
   normal first. Without normals only the constant applies. ``eps`` (DESIGN.md): with normals the
   receiver starts ``eps`` along its normal, and the receiver may lie ``eps`` (along the ray, as a
   distance along the view axis) behind the stored surface on top of the bias.
4. Transform by the view matrix into texel coordinates (centres at integers, row 0 at the top), add
   the dither (lowbias32 hash of ``seed`` and the index), and compare distances along the view axis:
   lit where the stored surface is not nearer than the receiver's distance minus the bias. Nearest:
   the texel containing the point; bilinear: the depths interpolated first; pcf: the fraction of
   the ``k x k`` texels around the nearest that are lit. Texel indices are clamped to the map.
5. Bias "plane" reads the maps' triangle ids instead of their depths and lifts nothing. For the ray
   ``s + lambda l`` from the start (``l`` unit, towards the light), a texel's triangle is HIT when the
   ray meets it for ``tmin < lambda < tmax`` (``tmin`` = eps + rounding, ``tmax`` the light's distance
   or infinite), BEHIND when it meets it at ``-behind < lambda < tmin``
   (``behind`` = ``ahead`` without normals, infinite with them: a receiver facing the light), AHEAD
   when not and its plane crosses the
   ray more than ``ahead`` = ``constant T + tmin`` in front of ``s`` and before the light. A texel
   shadows when HIT, or AHEAD unless some texel the filter reads is BEHIND. Nearest (reading the 3 x 3
   around): in shadow when any is HIT or the own texel shadows; bilinear: lit when the texels not
   shadowing carry at least half the bilinear weight of the four around; pcf: the fraction of the
   ``k x k`` texels not shadowing. Rounding is
   ``PRECISION_ULPS`` float32 epsilons of ``extent`` (the largest vertex coordinate) plus the start's
   largest coordinate.
"""

from __future__ import annotations

import numpy as np

TAN_MAX = 16.0
FILTERS = ("nearest", "bilinear", "pcf")
BIASES = ("constant", "slope", "normal", "plane")
PRECISION_ULPS = 16.0
FLT_EPSILON = float(np.finfo(np.float32).eps)


def hash32(x: np.ndarray) -> np.ndarray:
    """Lowbias32 on uint32 arrays (wrapping multiplies)."""
    x = np.asarray(x, dtype=np.uint32)
    with np.errstate(over="ignore"):
        x = x ^ (x >> np.uint32(16))
        x = x * np.uint32(0x7FEB352D)
        x = x ^ (x >> np.uint32(15))
        x = x * np.uint32(0x846CA68B)
        x = x ^ (x >> np.uint32(16))
    return x


def dither_offsets(n: int, seed: int) -> np.ndarray:
    """(n, 2) the +-0.5 texel noise of receivers 0..n-1."""
    index = np.arange(n, dtype=np.uint64)
    out = np.empty((n, 2))
    for axis in range(2):
        h = hash32(np.uint32(seed) ^ hash32((2 * index + axis).astype(np.uint32)))
        out[:, axis] = (h >> np.uint32(8)).astype(np.float64) * 2.0**-24 - 0.5
    return out


def distance_of(depth: np.ndarray, record: np.ndarray, perspective: bool) -> np.ndarray:
    near, far, ratio = float(record[17]), float(record[18]), float(record[19])
    if perspective:   # depth = near (far - w) / (w (far - near)), ratio = near / far (0: far infinite)
        with np.errstate(divide="ignore"):
            return np.where(depth > 0, near / np.where(depth > 0, depth * (1 - ratio) + ratio, 1.0), np.inf)
    return far - depth * (far - near)


def texel_coordinates(points_rel: np.ndarray, record: np.ndarray, res: int):
    """(s, t, depth) of points relative to the maps' origin: texel centres at integers."""
    m = np.asarray(record[:16], dtype=np.float64).reshape(4, 4)
    clip = points_rel @ m[:, :3].T + m[:, 3]
    x, y, z = (clip[:, k] / clip[:, 3] for k in range(3))
    return (x + 1) * 0.5 * res - 0.5, (1 - y) * 0.5 * res - 0.5, z


def texel_footprint(points_rel, eye, records, perspective):
    """(N,) ``T``: the largest width across the light's ray of one texel at each point (relative to the maps' origin).

    ``records`` (N, VIEW_FLOATS) is each point's view. Perspective, with ``d = p - eye``, ``z = d . forward``
    and ``alpha`` the angle between ``d`` and the axis: a texel spans ``size`` in tangent units ``u = d.right / z``;
    the ray's direction turns by ``size cos(alpha)`` radians for a step of ``u`` in the direction perpendicular
    to the axis and the ray, by ``size cos(alpha)^2`` in the radial direction. At distance ``|d| = z / cos(alpha)``
    the widths are ``size z`` and ``size z cos(alpha)``; the wider bounds where a lookup may land.
    """
    if not perspective:
        return records[:, 16].copy()
    forward = records[:, 12:15]   # the clip matrix's w row: w = (p - eye) . forward
    return records[:, 16] * np.einsum("ij,ij->i", points_rel - eye, forward)


def lit_fraction(depth_map, record, perspective, s, t, reach, filter, pcf_size=3):
    res = depth_map.shape[0]

    def at(r, c):
        return depth_map[np.clip(r, 0, res - 1), np.clip(c, 0, res - 1)].astype(np.float64)

    if filter == "bilinear":
        s0, t0 = np.floor(s), np.floor(t)
        fs, ft = s - s0, t - t0
        c, r = s0.astype(np.int64), t0.astype(np.int64)
        top = at(r, c) + fs * (at(r, c + 1) - at(r, c))
        bottom = at(r + 1, c) + fs * (at(r + 1, c + 1) - at(r + 1, c))
        return (distance_of(top + ft * (bottom - top), record, perspective) >= reach).astype(np.float64)
    c, r = np.floor(s + 0.5).astype(np.int64), np.floor(t + 0.5).astype(np.int64)
    half = 0 if filter == "nearest" else pcf_size // 2
    lit = np.zeros(len(s))
    for dr in range(-half, half + 1):
        for dc in range(-half, half + 1):
            lit += distance_of(at(r + dr, c + dc), record, perspective) >= reach
    return lit / (2 * half + 1) ** 2


HIT, BEHIND, AHEAD = 1, 2, 3


def triangle_verdict(triangles, start, direction, tmin, tmax, ahead, behind, slack=0.0):
    """(N,) what triangle ``triangles[i]`` ((N, 3, 3); NaN rows for an empty texel) says about ray i: HIT,
    BEHIND, AHEAD or 0 (module docstring, item 5). ``slack`` widens (> 0) or narrows (< 0) the triangles
    by that much in barycentric coordinates and moves the thresholds by that relative amount: a
    rounding-sized change."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    u, v = b - a, c - a
    normal = np.cross(u, v)
    with np.errstate(divide="ignore", invalid="ignore"):
        # Moller-Trumbore in float64: lambda along the ray and the barycentrics of its plane point
        pvec = np.cross(direction, v)
        det = np.einsum("ij,ij->i", u, pvec)
        w = start - a
        beta = np.einsum("ij,ij->i", w, pvec) / det
        qvec = np.cross(w, u)
        gamma = np.einsum("ij,ij->i", direction, qvec) / det
        lam = np.einsum("ij,ij->i", v, qvec) / det
        inside = (beta >= -slack) & (gamma >= -slack) & (beta + gamma <= 1 + slack) & (det != 0)
        threshold = tmin * (1 + slack)
        hit = inside & (lam > threshold) & (lam < tmax)
        at_or_behind = inside & (lam < threshold) & (lam > -behind)
        facing = np.einsum("ij,ij->i", normal, direction)
        plane = np.einsum("ij,ij->i", normal, a - start) / facing
        in_front = (facing != 0) & (plane > ahead * (1 + slack)) & (plane < tmax)
    verdict = np.where(hit, HIT, np.where(at_or_behind, BEHIND, np.where(in_front, AHEAD, 0)))
    return np.where(np.isfinite(a[:, 0]), verdict, 0)


def plane_lit_fraction(ids, vertices, faces, start, direction, s, t, tmin, tmax, ahead, behind, filter, pcf_size,
                       slack):
    """(N,) the "plane" bias's visibility from the triangle-id map ``ids`` (R, R) (module docstring, item 5)."""
    res = ids.shape[0]
    padded = np.concatenate([vertices[faces], np.full((1, 3, 3), np.nan)])   # index -1: an empty texel

    def verdict(r, c):
        f = ids[np.clip(r, 0, res - 1), np.clip(c, 0, res - 1)]
        return triangle_verdict(padded[f], start, direction, tmin, tmax, ahead, behind, slack)

    hit, in_front, seen = np.zeros(len(s)), np.zeros(len(s)), np.zeros(len(s), bool)
    if filter == "bilinear":
        s0, t0 = np.floor(s), np.floor(t)
        fs, ft = s - s0, t - t0
        c, r = s0.astype(np.int64), t0.astype(np.int64)
        for dr in (0, 1):
            for dc in (0, 1):
                weight = (fs if dc else 1 - fs) * (ft if dr else 1 - ft)
                v = verdict(r + dr, c + dc)
                hit += np.where(v == HIT, weight, 0.0)
                in_front += np.where(v == AHEAD, weight, 0.0)
                seen |= v == BEHIND
        return (1 - hit - np.where(seen, 0.0, in_front) >= 0.5).astype(np.float64)
    c, r = np.floor(s + 0.5).astype(np.int64), np.floor(t + 0.5).astype(np.int64)
    half = 1 if filter == "nearest" else pcf_size // 2
    for dr in range(-half, half + 1):
        for dc in range(-half, half + 1):
            v = verdict(r + dr, c + dc)
            hit += v == HIT
            in_front += (v == AHEAD) & (filter != "nearest" or (dr == 0 and dc == 0))   # nearest: its own texel's plane
            seen |= v == BEHIND
    shadowing = hit + np.where(seen, 0.0, in_front)
    if filter == "nearest":
        return (shadowing == 0).astype(np.float64)
    return 1 - shadowing / (2 * half + 1) ** 2


def visibility(points_rel, normals, kind, to_light, views, depth, bias, bias_mode="slope", filter="bilinear",
               pcf_size=3, dither=0, seed=0, perturb=(0.0, 0.0, 0.0), eps=0.0, triangles=None):
    """(N,) visibility in [0, 1] of points relative to the maps' origin (see the module docstring).

    ``perturb`` = (ds, dt, relative reach change) moves every decision slightly: the tests call it
    with small perturbations to find the receivers that float32 rounding may decide either way.
    ``triangles`` = (ids, vertices, faces, extent) for bias "plane": (V, R, R) triangle-id maps, the
    mesh's vertices relative to the maps' origin (as the device holds them), its faces, the largest
    vertex coordinate.
    """
    p = np.asarray(points_rel, dtype=np.float64).copy()
    n = len(p)
    perspective = kind != "orthographic"
    to_light = np.asarray(to_light, dtype=np.float64)
    light_dir = to_light - p if perspective else np.broadcast_to(to_light, p.shape)
    dist = np.linalg.norm(light_dir, axis=1)
    light_dir = light_dir / dist[:, None]
    face = np.zeros(n, dtype=np.int64)
    if kind == "cube":
        e = p - to_light
        axis = np.argmax(np.abs(e), axis=1)             # ties: the lowest axis, as the kernel
        face = 2 * axis + (e[np.arange(n), axis] < 0)
    records = np.asarray(views, dtype=np.float64)[face]
    texel = texel_footprint(p, to_light, records, perspective)
    offset = bias[0] * texel
    plane = bias_mode == "plane"
    # eps along the ray, as a distance along the view axis (cos alpha = axial distance / ray distance)
    offset = offset + (eps * texel / records[:, 16] / dist if perspective else eps)
    facing = np.ones(n, dtype=bool)
    if normals is not None:
        normals = np.asarray(normals, dtype=np.float64)
        cosine = np.einsum("ij,ij->i", normals, light_dir)
        facing = cosine > 0
        sine = np.sqrt(np.maximum(1 - cosine**2, 0))
        p = p + eps * normals                           # the start s = p + eps n
        if bias_mode == "slope":
            with np.errstate(divide="ignore", invalid="ignore"):
                offset = offset + bias[1] * texel * np.minimum(sine / cosine, TAN_MAX)
        elif bias_mode == "normal":
            p = p + (bias[1] * texel * sine)[:, None] * normals
    out = np.zeros(n)
    res = depth.shape[1]
    jitter = dither_offsets(n, seed) if dither else np.zeros((n, 2))
    for f in np.unique(face):
        sel = np.flatnonzero((face == f) & facing)
        s, t, z = texel_coordinates(p[sel], views[f], res)
        s, t = s + jitter[sel, 0] + perturb[0], t + jitter[sel, 1] + perturb[1]
        if plane:
            ids, vertices, faces, extent = triangles
            start = p[sel]
            tmin = eps + PRECISION_ULPS * FLT_EPSILON * (extent + np.abs(start).max(axis=1))
            tmax = dist[sel] if perspective else np.inf
            ahead = bias[0] * texel[sel] + tmin
            behind = np.inf if normals is not None else ahead
            out[sel] = plane_lit_fraction(ids[f], np.asarray(vertices, np.float64), faces, start, light_dir[sel], s, t,
                                          tmin, tmax, ahead, behind, filter, pcf_size, perturb[2])
            continue
        reach = distance_of(z, views[f], perspective) * (1 + perturb[2]) - offset[sel]
        out[sel] = lit_fraction(depth[f], views[f], perspective, s, t, reach, filter, pcf_size)
    return out
