"""Float64 reference of silhouette edges: adjacency from a dictionary of directed edges, facing and
classification in float64; and tracking's walks in NumPy (:func:`tracking_frame`, below). Never calls
the kernel's host code (``shadowcl.silhouette``).

Rules (the same as the module's): a face is light-facing when s = n . (L - v0) > 0 (point light) or
s = -n . d > 0 (directional light), n = (v1 - v0) x (v2 - v0); faces with a repeated vertex index have
no edges; an edge is a silhouette when exactly one of its one or two faces is light-facing, oriented as
that face runs along it; edges with three or more faces are reported, not classified.

Ties: the device computes s in float32 from the float32 vertices (exact) and the light rounded to
float32 (an error up to half a unit in the last place of |L|). The edge vectors, the normal, L - v0
and the dot product each add a few roundings relative to their size, so with
``B = |e1| |e2| (|L - v0| + |L|)`` (``|e1| |e2|`` for a directional light) the sign can differ only when
``|s| <= TIE * B``. TIE = 1e-5 is ~170 float32 units in the last place, far above the few roundings
involved. Geometrically: the face's
plane passes within ``TIE * B / |n|`` of the light (wider for thin triangles, whose float32 normal is
less certain). :func:`tie_faces` lists those faces; tests leave their edges out of exact comparisons.
"""

from __future__ import annotations

import numpy as np

from ..lights import DirectionalLight, PointLight

TIE = 1e-5


def directed_edges(faces) -> dict:
    """{(a, b): [face, ...]} for every directed edge a -> b of every face without a repeated vertex."""
    table: dict = {}
    for f, (a, b, c) in enumerate(np.asarray(faces).tolist()):
        if a == b or b == c or c == a:
            continue
        for tail, head in ((a, b), (b, c), (c, a)):
            table.setdefault((tail, head), []).append(f)
    return table


def undirected_edges(faces) -> dict:
    """{(low, high): [(face, tail, head), ...]}: every undirected edge with its faces and their sense."""
    table: dict = {}
    for (tail, head), owners in directed_edges(faces).items():
        key = (min(tail, head), max(tail, head))
        table.setdefault(key, []).extend((f, tail, head) for f in owners)
    return table


def facing_values(vertices, faces, light) -> tuple[np.ndarray, np.ndarray]:
    """(s, B) per face in float64: s > 0 means light-facing; |s| <= TIE * B is a tie (module docstring)."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    normal = np.cross(e1, e2)
    scale = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
    if isinstance(light, PointLight):
        position = np.asarray(light.position, dtype=np.float64)
        to_light = position - tri[:, 0]
        s = np.einsum("ij,ij->i", normal, to_light)
        bound = scale * (np.linalg.norm(to_light, axis=1) + np.linalg.norm(position))
    elif isinstance(light, DirectionalLight):
        s = -normal @ np.asarray(light.direction, dtype=np.float64)
        bound = scale
    else:
        raise TypeError(f"light: expected a PointLight or DirectionalLight, got {type(light).__name__}")
    return s, bound


def tie_faces(vertices, faces, light) -> np.ndarray:
    """Indices of faces whose facing float32 may decide either way."""
    s, bound = facing_values(vertices, faces, light)
    return np.flatnonzero(np.abs(s) <= TIE * bound)


def classify(vertices, faces, light, table: dict | None = None) -> dict:
    """Silhouettes as a dict with keys

    - ``oriented``: set of (tail, head) silhouette edges, running as their light-facing face does;
    - ``nonmanifold``: set of (low, high) edges with three or more faces;
    - ``facing``: (F,) bool light-facing faces.

    ``table`` is :func:`undirected_edges` of ``faces`` (built here when not given).
    """
    table = undirected_edges(faces) if table is None else table
    facing = facing_values(vertices, faces, light)[0] > 0
    oriented, nonmanifold = set(), set()
    for key, around in table.items():
        if len(around) > 2:
            nonmanifold.add(key)
            continue
        lit = [(tail, head) for f, tail, head in around if facing[f]]
        if len(lit) == 1:
            oriented.add(lit[0])
    return {"oriented": oriented, "nonmanifold": nonmanifold, "facing": facing}


def recall_precision(codes, truth_codes) -> tuple[float, float]:
    """(recall, precision) of the silhouette edges in ``codes`` against ``truth_codes`` (per-edge codes,
    +1/-1 silhouettes of either orientation). An edge counts as found only with the right orientation.
    Recall of an empty truth and precision of an empty answer are 1."""
    codes, truth_codes = np.asarray(codes), np.asarray(truth_codes)
    found, truth = np.abs(codes) == 1, np.abs(truth_codes) == 1
    hits = np.count_nonzero(found & truth & (codes == truth_codes))
    return (hits / np.count_nonzero(truth) if truth.any() else 1.0,
            hits / np.count_nonzero(found) if found.any() else 1.0)


# ---- tracking's walks (Fawad, Wang & Wu, sections III.B-C): the reference of the device walks ----
#
# The NumPy twin of kernels/silhouette.cl's track_previous, seed_edges and complete_loops (the walks
# SilhouetteTracker(method="tracking") runs), all walkers a step at a time. It takes the tracker's
# half-edge tables as plain arrays and the frame's facing as a callable, so the walks alone are compared
# (the facing is compared bit for bit by its own test). Half-edge h = 3 f + k is face f's edge k, from
# tails[h] to heads[h]; twin[h] the other face's half-edge on that edge (-1: a border, face -1 missing);
# edge[h] its edge; edge_halves[e] the edge's half-edges (-1 for a border's second).


def tracking_frame(twin, edge, tails, heads, edge_halves, previous, extra, lit, max_walk: int, max_stale: float,
                   max_lost: float) -> tuple:
    """One tracked frame from ``previous`` (last frame's light-facing silhouette half-edges): (this frame's
    light-facing silhouette half-edges, or None where the tracker falls back to brute force; stats with
    ``stale`` and ``lost_walks``). ``extra`` are the edges tested every frame (border and concave);
    ``lit(faces)`` the facing of faces (face -1, the missing one, never light-facing)."""
    stats = {}
    across = twin[previous]
    lit_here, lit_there = lit(previous // 3), lit(across // 3)
    seeds = [previous[lit_here & ~lit_there], across[~lit_here & lit_there]]
    away, into = lit_here & lit_there, ~lit_here & ~lit_there
    stats["stale"] = float(np.mean(away | into)) if len(previous) else 0.0
    if stats["stale"] > max_stale:
        return None, stats
    # III.B: walk from the face that turned, away from the other one.
    starts = np.r_[across[away], previous[into]]
    walked, lost = find_edges_by_walk(twin, starts // 3, starts % 3,
                                      np.r_[np.ones(away.sum(), bool), np.zeros(into.sum(), bool)], lit, max_walk)
    stats["lost_walks"] = lost
    if len(starts) and lost > max_lost * len(starts):
        return None, stats
    first, second = edge_halves[extra].T
    lit_first, lit_second = lit(first // 3), lit(second // 3)
    tested = np.where(lit_first, first, second)[lit_first != lit_second]
    found = complete_loops(twin, edge, tails, heads, np.concatenate(seeds + [walked, tested]), extra, lit,
                           len(edge_halves))
    if len(found) < (1 - max_stale) * len(previous):
        return None, stats
    return found, stats


def find_edges_by_walk(twin, faces, back, lit_walk, lit, max_walk: int) -> tuple:
    """Section III.B's ``find_edge_by_walk`` for many walkers at once. Walker i stands on ``faces[i]``,
    entered through its edge ``back[i]``; a light-facing walk (``lit_walk``) crosses light-facing faces
    until a left or right neighbour faces away (or is missing), the other walk crosses faces facing away
    until a neighbour faces the light. Steps go left and right in turn; a missing neighbour is a wall.
    Returns (light-facing half-edges of the silhouettes found, walkers lost: out of steps or walled in)."""
    found, lost = [], 0
    step_left = np.ones(len(faces), dtype=bool)
    for _ in range(max_walk):
        if not len(faces):
            break
        left, right = 3 * faces + (back + 1) % 3, 3 * faces + (back + 2) % 3
        left_twin, right_twin = twin[left], twin[right]
        lit_left, lit_right = lit(left_twin // 3), lit(right_twin // 3)
        hit_left = np.where(lit_walk, ~lit_left, lit_left)
        hit_right = np.where(lit_walk, ~lit_right, lit_right)
        done = hit_left | hit_right
        found.append(np.where(hit_left, np.where(lit_walk, left, left_twin),
                              np.where(lit_walk, right, right_twin))[done])
        go_left = np.where(step_left, left_twin >= 0, right_twin < 0)
        walled = (left_twin < 0) & (right_twin < 0) & ~done
        lost += int(walled.sum())
        going = ~done & ~walled
        step = np.where(go_left, left_twin, right_twin)[going]
        faces, back, lit_walk, step_left = step // 3, step % 3, lit_walk[going], ~step_left[going]
    return np.concatenate(found + [np.zeros(0, np.int64)]), lost + len(faces)


def complete_loops(twin, edge, tails, heads, seeds, tested, lit, nedges: int) -> np.ndarray:
    """Section III.C: from each seed (a light-facing half-edge of a silhouette edge) turn around its tail
    vertex through light-facing faces; the first edge whose other face faces away (or is missing) is the
    next silhouette edge, whose other vertex is turned around next; stop at an edge already found or
    ``tested`` this frame. All walkers step together; returns every loop edge's light-facing half."""
    seeds = seeds[np.unique(edge[seeds], return_index=True)[1]] if len(seeds) else seeds
    known = np.zeros(nedges, dtype=bool)
    known[tested] = True
    known[edge[seeds]] = True
    found, current, pivot = [seeds], seeds, tails[seeds]
    for _ in range(6 * nedges + 6):                 # a loop's faces are each entered at most thrice
        if not len(current):
            break
        faces, k = current // 3, current % 3
        # The other edge of this face at the pivot: it ends there or starts there.
        side = 3 * faces + np.where(tails[current] == pivot, (k + 2) % 3, (k + 1) % 3)
        across = twin[side]
        turn = lit(across // 3)
        side_edge = edge[side]
        new = ~turn & ~known[side_edge]
        known[side_edge[new]] = True
        found.append(side[new])
        far = np.where(tails[side] == pivot, heads[side], tails[side])
        current = np.r_[across[turn], side[new]]
        pivot = np.r_[pivot[turn], far[new]]
    else:
        raise RuntimeError("silhouette loop completion did not end (an inconsistent adjacency table)")
    return np.concatenate(found)
