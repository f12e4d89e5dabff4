"""Float64 reference of the angular method: ridge edges, the span table (a face's span over each whole
row band it meets), lookups (a face record's hit must lie in the triangle), the paper's pairing
of section 4 for one loop, and the loop table as ``table="loops"`` builds it (:func:`loop_table`: pairs
per lit region, cut at concave creases, pole crossings). Written from the paper; never calls
``shadowcl.angular``.

The frame (rotation, origin, rows) is an input here: its choice is a heuristic of the method, the
table and the lookups given a frame are what is checked. Coordinates: a point light at the origin,
row half-planes through the X axis at theta = atan2(Y, -Z), key s = X / |P|; a directional light comes
from +Z, rows are planes Y = const, s = X.

Tolerances (float32 device against float64 here):
- Row membership of a (face, row) pair is exact except when a row boundary (the loop table: a row centre)
  lies within ``ROW_TIE`` (in row units) of the end of the face's padded row-coordinate range: the device's
  atan2 and division round.
- ``s`` of a span end: the device cuts the face in float32 from float32 corners rotated on the host;
  a cut point carries a few float32 roundings of the coordinates (~1e-7 relative) amplified by
  1 / sin(angle between edge and cutting plane); ``S_TOL`` = 2e-4 holds for edges more than ~0.1 degree off
  the plane, and spans from flatter cuts are compared where they agree (see the tests).
- A face record's hit: the device's edge functions in float32 decide points within ~1e-6 of the face's
  size from an edge either way: :func:`classify`'s ``grow`` bounds that band (the tests call points whose
  answer changes with grow = +-1e-5 ties).
"""

from __future__ import annotations

import numpy as np

ROW_TIE = 1e-3
S_TOL = 2e-4


def facing(vertices, faces, light_local_point: bool) -> np.ndarray:
    """(F,) light-facing faces in the frame (point light at the origin, or directional light from +Z)."""
    v = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    side = -np.einsum("ij,ij->i", n, v[:, 0]) if light_local_point else n[:, 2]
    return side > 0


def ridge_edges(vertices, faces, point: bool) -> set:
    """Ridge edges as {(tail, head)}: edges with exactly one light-facing face (a border edge's missing face
    counts as hidden), oriented as the facing face runs along them."""
    lit = facing(vertices, faces, point)
    owners: dict = {}
    for f, tri in enumerate(np.asarray(faces).tolist()):
        if len(set(tri)) < 3:
            continue
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            owners.setdefault((min(a, b), max(a, b)), []).append((f, a, b))
    out = set()
    for sides in owners.values():
        lit_sides = [(a, b) for f, a, b in sides if lit[f]]
        if len(lit_sides) == 1 and len(sides) <= 2:
            out.add(lit_sides[0])
    return out


def row_coordinate(local, point: bool) -> np.ndarray:
    local = np.asarray(local, dtype=np.float64)
    return np.arctan2(local[..., 1], -local[..., 2]) if point else local[..., 1]


def face_rows(corners, t0, dt, rows, full_circle, point, pad_t) -> tuple[list[np.ndarray], np.ndarray]:
    """(rows, pad) per face (corners (F, 3, 3)): the rows (ascending) whose band [t0 + k dt, t0 + (k + 1) dt]
    meets the face's row-coordinate range widened by its pad (``pad_t``; point light: times max(1, r / rho)
    over the corners, rho the distance from the pole axis, every row when rho <= r pad_t or when the widened
    range covers the circle); every row for a point-light face whose YZ projection surrounds the pole, none
    for an edge-on face."""
    out, pads = [], []
    for tri in np.asarray(corners, dtype=np.float64):
        n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
        side = -n @ tri[0] if point else n[2]
        pad = pad_t
        if side == 0:
            out.append(np.zeros(0, dtype=np.int64))
            pads.append(pad)
            continue
        t = row_coordinate(tri, point)
        if point:
            rel = (t - t[0] + np.pi) % (2 * np.pi) - np.pi             # unwrapped round the first corner
            lo, hi = t[0] + rel.min(), t[0] + rel.max()
            u, v = tri[:, 1], -tri[:, 2]
            e = np.array([u[i] * v[(i + 1) % 3] - v[i] * u[(i + 1) % 3] for i in range(3)])
            rho, r = np.hypot(u, v).min(), np.linalg.norm(tri, axis=1).max()
            pad = pad_t * max(1.0, r / rho) if rho > r * pad_t else 2 * np.pi
            pads.append(pad)
            if np.all(e >= 0) or np.all(e <= 0) or hi - lo + 2 * pad >= 2 * np.pi:
                out.append(np.arange(rows))
                continue
        else:
            lo, hi = t.min(), t.max()
            pads.append(pad)
        k = np.arange(np.floor((lo - pad - t0) / dt), np.floor((hi + pad - t0) / dt) + 1).astype(np.int64)
        k = np.unique(k % rows) if full_circle else k[(k >= 0) & (k < rows)]
        out.append(k)
    return out, np.array(pads)


def _clip(poly, g) -> list:
    """The convex polygon ``poly`` (list of (3,) points) where the linear function ``g`` is >= 0."""
    out = []
    for i, p in enumerate(poly):
        q = poly[(i + 1) % len(poly)]
        gp, gq = g(p), g(q)
        if gp >= 0:
            out.append(p)
        if (gp >= 0) != (gq >= 0):
            out.append(p + gp / (gp - gq) * (q - p))
    return out


def _segment_s_range(a, b) -> tuple[float, float]:
    """min and max of s = x / |p| along the segment a -> b (point light): at the ends or where ds/dt = 0,
    which for p = a + t e is linear in t: t (e_x a.e - a_x |e|^2) = a_x a.e - e_x |a|^2."""
    e = b - a
    cand = [a, b]
    den = e[0] * (a @ e) - a[0] * (e @ e)
    if den != 0:
        t = (a[0] * (a @ e) - e[0] * (a @ a)) / den
        if 0 < t < 1:
            cand.append(a + t * e)
    s = [p[0] / np.linalg.norm(p) if np.linalg.norm(p) > 0 else 0.0 for p in cand]
    return min(s), max(s)


def band_span(tri, ta, tb, point, pad_s) -> tuple[float, float]:
    """[s_lo, s_hi] of the directions of face ``tri`` whose row coordinate lies in [ta, tb] (point light: the
    face cut to the wedge ta <= theta <= tb, uncut when the band is a half-turn or wider; directional: the
    slab ta <= Y <= tb), widened by ``pad_s``; (2, -2) when the face misses the band."""
    poly = [np.asarray(p, dtype=np.float64) for p in tri]
    if point:
        if tb - ta < np.pi:
            poly = _clip(poly, lambda p: np.cos(ta) * p[1] + np.sin(ta) * p[2])        # sin(theta - ta) >= 0
            poly = _clip(poly, lambda p: -np.cos(tb) * p[1] - np.sin(tb) * p[2])       # sin(tb - theta) >= 0
        if len(poly) < 3:
            return 2.0, -2.0
        ranges = [_segment_s_range(poly[i], poly[(i + 1) % len(poly)]) for i in range(len(poly))]
        lo, hi = min(r[0] for r in ranges), max(r[1] for r in ranges)
    else:
        poly = _clip(_clip(poly, lambda p: p[1] - ta), lambda p: tb - p[1])
        if len(poly) < 2:
            return 2.0, -2.0
        lo, hi = min(p[0] for p in poly), max(p[0] for p in poly)
    return lo - pad_s, hi + pad_s


def table(local_vertices, faces, table_faces, t0, dt, rows, full_circle, point, pad_t, pad_s) -> dict:
    """The span table: arrays ``row``, ``face``, ``s_lo``, ``s_hi`` (float64), sorted by (row, s_lo, face),
    and per face of ``faces``: ``plane`` (F, 4) (n, d with n.x = d, the light on the positive side) and
    ``triangle`` (F, 3, 3), its corners, which a lookup's hit must lie in."""
    v = np.asarray(local_vertices, dtype=np.float64)
    faces = np.asarray(faces)
    corners = v[faces[np.asarray(table_faces, dtype=np.int64)]]
    rows_of, pads = face_rows(corners, t0, dt, rows, full_circle, point, pad_t)
    rec = []
    for f, tri, ks, pad in zip(table_faces, corners, rows_of, pads):
        for k in ks:
            lo, hi = band_span(tri, t0 + k * dt - pad, t0 + (k + 1) * dt + pad, point, pad_s)
            rec.append((k, f, lo, hi))
    rec = np.array(rec, dtype=np.float64).reshape(-1, 4)
    order = np.lexsort((rec[:, 1], rec[:, 2], rec[:, 0]))
    rec = rec[order]
    allc = v[faces]
    n = np.cross(allc[:, 1] - allc[:, 0], allc[:, 2] - allc[:, 0])
    d = np.einsum("ij,ij->i", n, allc[:, 0])
    side = -d if point else n[:, 2]
    flip = np.where(side < 0, -1.0, 1.0)
    return dict(row=rec[:, 0].astype(np.int64), face=rec[:, 1].astype(np.int64), s_lo=rec[:, 2], s_hi=rec[:, 3],
                plane=np.c_[n * flip[:, None], d * flip], triangle=allc)


def receiver_keys(points, t0, dt, rows, full_circle, point):
    """(row (-1 outside), s, |p|) of frame points."""
    p = np.asarray(points, dtype=np.float64)
    k = np.floor((row_coordinate(p, point) - t0) / dt).astype(np.int64)
    if full_circle:
        k %= rows
    else:
        k[(k < 0) | (k >= rows)] = -1
    dist = np.linalg.norm(p, axis=1)
    s = p[:, 0] / np.where(dist > 0, dist, 1) if point else p[:, 0]
    return k, s, dist


def _inside(tri, x, grow) -> bool:
    """Point ``x`` of the triangle's plane lies in triangle ``tri`` (edges moved out by about ``grow`` times
    the triangle's size; negative: in)."""
    n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    size = np.linalg.norm(n)
    if size == 0:
        return False
    sides = [np.cross(tri[(i + 1) % 3] - tri[i], x - tri[i]) @ n / size for i in range(3)]   # edge length x distance
    return all(s >= -grow * size for s in sides)


def classify(points, normals, tab, t0, dt, rows, full_circle, point, eps, grow=0.0) -> np.ndarray:
    """Bool (N,): a receiver is shadowed when a face with a span of its row containing its s meets its
    segment to the light further than eps from it, inside the triangle (``tab["triangle"]``; ``grow``
    moves its edges out, for ties; a table without triangles, the loop table's chords, uses the plane)
    (normals: back-facing is shadowed, offset eps)."""
    p = np.array(points, dtype=np.float64)
    shadow = np.zeros(len(p), dtype=bool)
    if normals is not None:
        nrm = np.asarray(normals, dtype=np.float64)
        back = (np.einsum("ij,ij->i", nrm, -p) <= 0) if point else (nrm[:, 2] <= 0)
        shadow |= back
        p = p + eps * nrm
    k, s, dist = receiver_keys(p, t0, dt, rows, full_circle, point)
    triangles = tab.get("triangle")
    for i in np.flatnonzero(~shadow & (k >= 0)):
        sel = (tab["row"] == k[i]) & (tab["s_lo"] <= s[i]) & (s[i] <= tab["s_hi"])
        for f in tab["face"][sel]:
            n, d = tab["plane"][f, :3], tab["plane"][f, 3]
            q = n @ p[i]
            hit = (q < d and (1 - d / q) * dist[i] > eps) if point else (d - q > eps * n[2])
            if hit and triangles is not None:
                x = p[i] * (d / q) if point else p[i] + np.array([0.0, 0.0, (d - q) / n[2]])
                hit = _inside(triangles[f], x, grow)
            if hit:
                shadow[i] = True
                break
    return shadow


# Section 4: the paper's loop-only table -----------------------------------------------------------------

def loop_crossings(loop_local, tk, point):
    """Crossings of the closed polygon ``loop_local`` ((L, 3) frame positions) with row ``tk``: (s, r, up)
    per crossing, ``up`` = +1 where the loop goes towards larger theta (Y), -1 towards smaller."""
    pts = np.asarray(loop_local, dtype=np.float64)
    nxt = np.roll(pts, -1, axis=0)
    if point:
        m, w = np.array([0.0, np.cos(tk), np.sin(tk)]), np.array([0.0, np.sin(tk), -np.cos(tk)])
        a, b = pts @ m, nxt @ m
    else:
        a, b = pts[:, 1] - tk, nxt[:, 1] - tk
    out = []
    for i in np.flatnonzero((a > 0) != (b > 0)):
        c = pts[i] + a[i] / (a[i] - b[i]) * (nxt[i] - pts[i])
        if point and c @ w <= 0:
            continue
        r = np.linalg.norm(c)
        out.append((c[0] / r if point else c[0], r, 1 if b[i] > a[i] else -1))
    return out


def paper_pairs(loop_local, tk, point) -> list[tuple[float, float]]:
    """Section 4's pairs of one loop in row ``tk``: the loop is cut at its local theta peaks into chains;
    the two chains leaving a peak bound one shadow span, so in phi order each crossing going one way pairs
    with the next unpaired crossing going the other way (first in, first out). Coils pair correctly
    (figure 4: (a,b) with (e,f), (g,h) with (j,k)), where even-odd pairing of sorted crossings would make
    the doubly covered part a hole."""
    cuts = sorted(loop_crossings(loop_local, tk, point))
    if not cuts:
        return []
    opener = cuts[0][2]
    waiting, pairs = [], []
    for s, _, up in cuts:
        if up == opener or not waiting:          # (a figure-eight row opens the other way)
            waiting.append(s)
        else:
            pairs.append((waiting.pop(0), s))
    return pairs


def even_odd_pairs(loop_local, tk, point) -> list[tuple[float, float]]:
    """Sorted crossings paired first-second, third-fourth: the pairing section 4 warns against."""
    cuts = sorted(c[0] for c in loop_crossings(loop_local, tk, point))
    return list(zip(cuts[0::2], cuts[1::2]))


def covered(pairs, s) -> np.ndarray:
    """(len(s),) bool: s inside any of ``pairs``."""
    s = np.asarray(s, dtype=np.float64)
    out = np.zeros(len(s), dtype=bool)
    for lo, hi in pairs:
        out |= (s >= lo) & (s <= hi)
    return out


# The paper's table as the device builds it (table="loops") -----------------------------------------------

def _components(n, links) -> np.ndarray:
    """Labels of the connected components of ``n`` items joined by ``links`` (union-find)."""
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in links:
        parent[root(a)] = root(b)
    return np.array([root(i) for i in range(n)], dtype=np.int64)


def loop_table(local_vertices, faces, chains, t0, dt, rows, full_circle, point) -> dict:
    """The paper's table of a closed, consistently wound mesh (frame coordinates) whose ridge-edge loops are
    ``chains`` (vertex lists, each edge tail -> head as its light-facing face runs along it).

    Per row (centre tk), every crossing of a ridge edge with the row's half-plane (plane for a directional
    light) is keyed by s; so are the points where the pole axis pierces a light-facing face (s = +-1, point
    light). Crossings are grouped by the lit region (light-facing faces joined across edges with both faces
    lit) of their face and paired per region by section 4's rule (:func:`paper_pairs`); each pair is cut at
    the crossings of the region's concave creases (edges between two lit faces folding inwards) inside it,
    the duplicates of section 5. Returns arrays ``row``, ``s_lo``, ``s_hi``, ``region``, ``a``, ``b`` (the
    (P, 3) end points), sorted by (row, s_lo, s_hi)."""
    v = np.asarray(local_vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    lit = facing(v, faces, point)
    owner, links = {}, []
    for f, tri in enumerate(faces.tolist()):
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            owner[(a, b)] = f
    for (a, b), f in owner.items():
        g = owner.get((b, a))
        if g is not None and lit[f] and lit[g]:
            links.append((f, g))
    region = _components(len(faces), links)
    edges = []                                                       # (tail, head, region, kind)
    for chain in chains:
        chain = list(chain)
        for tail, head in zip(chain, chain[1:] + chain[:1]):
            edges.append((tail, head, region[owner[(tail, head)]], 0))
    for (a, b), f in owner.items():
        g = owner.get((b, a))
        if a < b and g is not None and lit[f] and lit[g]:
            tri = v[faces[f]]
            n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
            far = v[int(sum(faces[g]) - a - b)] - v[a]
            if n @ far > 1e-6 * np.linalg.norm(n) * np.linalg.norm(far):
                edges.append((a, b, region[f], 1))
    poles = []                                                       # (x, region)
    if point:
        for f in np.flatnonzero(lit):
            tri = v[faces[f]]
            u, w = tri[:, 1], -tri[:, 2]
            e = np.array([u[i] * w[(i + 1) % 3] - w[i] * u[(i + 1) % 3] for i in range(3)])
            n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
            if (np.all(e >= 0) or np.all(e <= 0)) and n[0] != 0:
                poles.append((n @ tri[0] / n[0], region[f]))
    out = []
    for k in range(rows):
        tk = t0 + (k + 0.5) * dt
        if point:
            m, wdir = np.array([0.0, np.cos(tk), np.sin(tk)]), np.array([0.0, np.sin(tk), -np.cos(tk)])
        cuts = {}
        for tail, head, reg, kind in edges:
            p, q = v[tail], v[head]
            a, b = (p @ m, q @ m) if point else (p[1] - tk, q[1] - tk)
            if (a > 0) == (b > 0):
                continue
            c = p + a / (a - b) * (q - p)
            if point and c @ wdir <= 0:
                continue
            s = c[0] / np.linalg.norm(c) if point else c[0]
            cuts.setdefault(reg, []).append((kind, s, 1 if b > a else -1, c))
        for x, reg in poles:
            cuts.setdefault(reg, []).append((0, float(np.sign(x)), int(np.sign(x)), np.array([x, 0.0, 0.0])))
        for reg, items in cuts.items():
            ridge = sorted((c for c in items if c[0] == 0), key=lambda c: c[1])
            dups = sorted((c for c in items if c[0] == 1), key=lambda c: c[1])
            if not ridge:
                continue
            opener, waiting = ridge[0][2], []
            for c in ridge:
                if c[2] == opener or not waiting:
                    waiting.append(c)
                    continue
                start = waiting.pop(0)
                chain = [start] + [d for d in dups if start[1] < d[1] < c[1]] + [c]
                for p0, p1 in zip(chain, chain[1:]):
                    out.append((k, min(p0[1], p1[1]), max(p0[1], p1[1]), reg, p0[3], p1[3]))
    out.sort(key=lambda r: (r[0], r[1], r[2]))
    return dict(row=np.array([r[0] for r in out], dtype=np.int64), s_lo=np.array([r[1] for r in out]),
                s_hi=np.array([r[2] for r in out]), region=np.array([r[3] for r in out], dtype=np.int64),
                a=np.array([r[4] for r in out]).reshape(-1, 3), b=np.array([r[5] for r in out]).reshape(-1, 3))
