"""Float64 reference of silhouette edges: adjacency from a dictionary of directed edges, facing and
classification in float64. Never calls the kernel's host code (``shadowcl.silhouette``).

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
