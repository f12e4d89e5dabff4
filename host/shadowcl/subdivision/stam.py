"""Control nets of patches: the 4x4 net of a regular quad (phantom points on boundaries) and the local
mesh round an extraordinary vertex, with Stam's sub-domain weights (its levels subdivided in float64)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .refinement import _cc_step, _limit_tangent_weights_of, _limit_weights_of, _Topology

#: Stam levels stop once every point of the level-L control net is within this fraction of the net's
#: size from the EV's limit position (float32 resolution), so using that position below 2^-L is exact
#: to float32 precision.
STAM_TOLERANCE = 2.0**-21
#: Hard cap on Stam levels (valence 64 needs about 40).
MAX_STAM_LEVELS = 64


_INNER = ((1, 1), (2, 1), (2, 2), (1, 2))  # (i, j) of corner k in the 4x4 grid
_A_AXIS = ((1, 0), (0, 1), (-1, 0), (0, -1))  # from corner k towards corner k + 1
_B_AXIS = ((0, 1), (-1, 0), (0, -1), (1, 0))  # from corner k towards corner k - 1


def _quad_corners(topo: _Topology, face: int, rot: int) -> list[int]:
    start = topo.face_start[face]
    return [int(start + (rot + k) % 4) for k in range(4)]


def _gather_regular(topo: _Topology, points: np.ndarray, face: int, rot: int) -> np.ndarray:
    """The (16, d) B-spline control net of a regular quad, row-major (i along u), corner ``rot`` at (0, 0).

    All four corners must be regular (interior valence 4, boundary with 2 faces, or a corner with 1 face);
    missing points beyond a boundary are phantoms reflected through it.
    """
    vert, nxt, twin, prev = topo.vert, topo.next, topo.twin, topo.prev
    grid: list[list] = [[None] * 4 for _ in range(4)]  # grid[j][i]
    real = np.zeros((4, 4), dtype=bool)

    def put(i, j, corner):
        grid[j][i] = points[vert[corner]]
        real[j, i] = True

    for k, ck in enumerate(_quad_corners(topo, face, rot)):
        (pi, pj), (ai, aj), (bi, bj) = _INNER[k], _A_AXIS[k], _B_AXIS[k]
        put(pi, pj, ck)
        t = twin[ck]  # the face across edge k
        if t >= 0:
            x = nxt[nxt[t]]
            put(pi - bi, pj - bj, x)
            put(pi + ai - bi, pj + aj - bj, nxt[x])
            d = twin[nxt[t]]  # the diagonal face at corner k
            if d >= 0:
                put(pi - ai - bi, pj - aj - bj, nxt[nxt[nxt[d]]])
        t = twin[prev[ck]]  # the face across edge k - 1
        if t >= 0:
            put(pi - ai, pj - aj, nxt[nxt[nxt[t]]])
            put(pi - ai + bi, pj - aj + bj, nxt[nxt[t]])
    # Phantom points: sides first (reflection through the boundary row/column), then grid corners.
    inward = {0: (1, 2), 3: (2, 1)}
    for j in range(4):
        for i in range(4):
            if real[j, i] or (i in (0, 3) and j in (0, 3)):
                continue
            if i in inward:
                a, b = inward[i]
                grid[j][i] = 2.0 * grid[j][a] - grid[j][b]
            else:
                a, b = inward[j]
                grid[j][i] = 2.0 * grid[a][i] - grid[b][i]
    for j in (0, 3):
        for i in (0, 3):
            if real[j, i]:
                continue
            ja, jb = inward[j]
            ia, ib = inward[i]
            if real[ja, i]:
                grid[j][i] = 2.0 * grid[ja][i] - grid[jb][i]
            else:
                grid[j][i] = 2.0 * grid[j][ia] - grid[j][ib]
    return np.array([grid[j][i] for j in range(4) for i in range(4)])


def _local_mesh(topo: _Topology, face: int, rot: int) -> tuple[tuple, np.ndarray]:
    """The faces touching the four corners of quad ``face`` (corner ``rot`` first), canonically relabelled.

    Returns (signature, global vertex ids in local order): the signature is the tuple of local faces, so
    equal signatures mean identical local topology with identical labels. Local face 0 is the quad itself
    as (0, 1, 2, 3) starting at corner ``rot``.
    """
    seen_faces: dict[int, int] = {}
    order: list[int] = []
    for ck in _quad_corners(topo, face, rot):
        for c in topo.fan(ck):
            f = int(topo.face_of[c])
            if f not in seen_faces:
                seen_faces[f] = len(order)
                order.append(int(c))
    labels: dict[int, int] = {}
    local_faces = []
    for start in order:
        f = topo.face_of[start]
        base, size = topo.face_start[f], topo.sizes[f]
        local = []
        for k in range(size):
            v = int(topo.vert[base + (start - base + k) % size])
            local.append(labels.setdefault(v, len(labels)))
        local_faces.append(tuple(local))
    ids = np.fromiter(labels.keys(), dtype=np.int64, count=len(labels))
    return tuple(local_faces), ids


@lru_cache(maxsize=64)  # bounded: one valence-360 entry is 11 MB
def _stam_weights(signature: tuple) -> np.ndarray:
    """(48 L + 3, m) weights: Stam's sub-patch control nets, the EV limit, then two limit tangents at the
    EV (zero rows where :func:`_limit_tangent_weights_of` has none), from the m local points.

    Built by subdividing the local net with coefficient vectors (identity rows) as points, so the rows
    are exactly the entries of (picking matrix) A^n; cached per local topology (read-only).
    """
    m = 1 + max(max(f) for f in signature)
    faces = np.array(signature, dtype=np.int64)
    coefficients = np.eye(m)
    topo = _Topology.from_faces(faces, m)
    ids, weights = _limit_weights_of(topo, 0)
    limit = np.zeros(m)
    np.add.at(limit, ids, weights)
    tangents = np.zeros((2, m))
    tangent_weights = _limit_tangent_weights_of(topo, 0)
    if tangent_weights is not None:
        for row, row_weights in zip(tangents, tangent_weights[1]):
            np.add.at(row, tangent_weights[0], row_weights)
    rows = []
    for _ in range(MAX_STAM_LEVELS):
        child_points, child_faces = _cc_step(coefficients, topo)
        child_topo = _Topology.from_faces(child_faces, len(child_points))
        # Child (k + 1) of the patch quad, started at its corner 3 - k, is sub-patch k in the patch frame.
        for k in range(3):
            rows.append(_gather_regular(child_topo, child_points, k + 1, 3 - k))
        local_faces, local_ids = _local_mesh(child_topo, 0, 0)
        coefficients = child_points[local_ids]
        topo = _Topology.from_faces(np.array(local_faces, dtype=np.int64), len(local_ids))
        if np.abs(coefficients - limit).sum(axis=1).max() <= STAM_TOLERANCE:
            break
    else:
        raise RuntimeError(f"Stam levels did not converge within {MAX_STAM_LEVELS} levels")
    table = np.concatenate(rows + [limit[None, :], tangents])
    table.flags.writeable = False
    return table
