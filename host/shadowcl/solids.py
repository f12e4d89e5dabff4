"""Which closed components of a mesh are solids (embedded surfaces), and the faces a light needs of them.

Why: call a face "towards" a light when the light is on its front (the side its winding's normal
points to), else "away". A segment from a start s to the light crosses a closed, consistently wound
surface C ``#towards - #away = w_C(s) - w_C(light)`` times, signed, where ``w_C`` is C's winding
number. When C is embedded (no two of its triangles meet except along their shared edges and
corners), ``w_C`` is 0 outside and one ``sigma`` inside: +1 wound outwards, -1 inwards. Then the sign
of the difference is known, so one kind of face meets every segment that meets C at all, and the
exact method may list only that kind (:meth:`Solids.faces_for`): about half the faces, and the lists
and the walks shrink with them.

Which kind: the faces towards the light when ``sigma > 0`` and the light is outside C, or ``sigma < 0``
and it is inside; else those away. (Wound outwards, light outside: ``#towards - #away = w_C(s) >= 0``,
so a segment that meets C meets a face towards the light.) A self-intersecting or partly inside-out
closed mesh has regions of the other sign, where a segment may meet only the other kind (tests/
test_solids.py's finger: thousands of receivers wrong): such a component keeps all its faces. The
certificate, computed once per mesh (:func:`solids`) and reused by every light:

- **closed and consistently wound**: :attr:`shadowcl.topology.EdgeAdjacency.closed_faces`;
- **embedded**: no two triangles of the component intersect except as neighbours must (along their
  shared edge, at their shared corner), judged on the corners the exact method's kernels test (float32,
  relative to the mesh box's centre), not the caller's: rounding may make two faces that nearly touch
  meet, and the proof must hold for the surface the walks see. Candidate pairs are those whose boxes
  share a cell of a grid per component; each pair is proved apart, in float64, with margins far above
  its rounding: by a separating axis (the 17 of two triangles, coplanar ones included) when they share
  no corner, by the far corner's side of the plane when they share an edge, by a plane through the
  shared corner when they share one. A pair that cannot be proved apart (touching, or too close to call) leaves its
  component uncertified: the answer stays exact, only slower;
- **the sign**: the component's signed volume, which must be clearly non-zero;
- **the light's side** (per light): outside the component's box, or its winding number (solid angles,
  :func:`shadowcl.topology.solid_angles`; 0 or ``sigma`` off an embedded surface). A point light within
  ``LIGHT_CLEARANCE`` of the component's size, or ``NEAR_LIGHT`` of its reach, from its triangles lists
  all its faces: on the surface the winding number is fractional (1/8 at a box's corner), very near it
  the float64 sum of solid angles may round to the wrong side, and the walks' float32 segments may end
  short of a face the light nearly touches (:meth:`Solids._light_sides`).

A solid with a face nearly edge-on to the light (within ``EDGE_ON`` times the kernels' own bound of the
light's side of its plane) lists all its faces: the walk may miss such a face where it is the crossing
(its cone test is oriented by that side), and without the cull the face turned away catches the
segment. Faces of open components, and of components not certified, are always listed.

A light that would leave out fewer than ``MIN_CULLED`` of all faces lists them all, and a mesh whose
closed components hold fewer than twice that share is not certified (no light could then leave out
enough): reordering and uploading the faces and the side tests cost 2-3 ms a light per 100 k faces.
Measured on four scenes (bench/results/cull.md), a judgment between them, not a fit: ogre, 27 % of its
faces left out, gained nothing (75.9 -> 81.1 ms a light with normals, 77.3 -> 76.9 without); default
(54 %), city_block (46 %) and light_inside (69 %) gained 4-20 %. Bunny on its ground would leave out
10 of 69,463 (its model is open).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from .frame import triangle_distances
from .geometry import Mesh, per_mesh
from .lights import PointLight
from .topology import edge_adjacency, solid_angles

REL = 1e-9                  # float64 margins, relative to the sizes involved (its rounding is ~1e-16 of them)
MAX_CELLS_PER_FACE = 16     # grid cells per face on average before a component's cells are made larger
MAX_PAIRS_PER_FACE = 256    # candidate pairs (before repeats go) per face beyond which no component is certified;
MAX_PAIRS = 1 << 24         # and in all (~40 bytes each): the bench scenes need 24-64 per face, 0.5-3 M in all
PAIRS_PER_PASS = 1 << 18    # pairs proved apart at a time
LIGHT_CLEARANCE = 1e-6     # a point light nearer a solid than this share of its box diagonal lists all its faces,
NEAR_LIGHT = 1e-4          # or nearer than this share of its reach (the farthest receiver or face from it)
EDGE_ON = 4                # a face within this many times the kernels' plane bound of the light lists its solid
KERNEL_NORMAL_ULPS = 8     # kernels/ray_triangle.h NORMAL_ULPS: the plane test's allowance for a normal's lean
MIN_CULLED = 1 / 3         # culls leaving out fewer faces than this share list them all (measured: module doc)

_CACHE: "weakref.WeakKeyDictionary[Mesh, Solids]" = weakref.WeakKeyDictionary()


@dataclass(frozen=True, eq=False)
class Solids:
    """A mesh's certified solids: ``sigma`` (F,) int8, +1 or -1 for a face of a component certified
    embedded and wound outwards or inwards, 0 for every other face; ``label`` (F,) each face's
    component; ``low`` / ``high`` (C, 3) the components' boxes. For the certified faces only, ascending
    ``ids`` (K,), their first ``corners`` (K, 3), ``normals`` (K, 3, not unit), the normals' ``lengths``
    (K,) and ``plane_rel`` (K,), the relative bound of the kernels' plane test (kernels/exact.cl
    wt_record: 1e-6 plus how far the float32 normal may lean). All of it in the exact method's frame: the
    corners relative to ``centre`` (the mesh box's), rounded to float32, as its kernels test them
    (kernels/exact.cl triangle_records), and ``vertices`` likewise."""

    vertices: np.ndarray
    faces: np.ndarray
    sigma: np.ndarray
    label: np.ndarray
    low: np.ndarray
    high: np.ndarray
    ids: np.ndarray
    corners: np.ndarray
    normals: np.ndarray
    lengths: np.ndarray
    plane_rel: np.ndarray
    centre: np.ndarray

    @property
    def certified_faces(self) -> int:
        return len(self.ids)

    def faces_for(self, light, receiver_bounds: np.ndarray) -> np.ndarray | None:
        """Ids of the faces ``light`` needs listed (ascending) for receivers in ``receiver_bounds`` ((2, 3),
        the mesh's frame), or None to list every face: when the light would leave fewer than
        MIN_CULLED of them out, the lists would save less than the reordered faces cost."""
        if len(self.ids) < MIN_CULLED * len(self.faces):
            return None
        sigma = self.sigma[self.ids].astype(np.int64)
        label = self.label[self.ids]
        if isinstance(light, PointLight):
            # the light as the kernels have it (exact.py prepare: light - origin, in float32)
            position = (np.asarray(light.position, dtype=np.float64) - self.centre).astype(np.float32).astype(float)
            to_light = position - self.corners
            side = np.einsum("ij,ij->i", self.normals, to_light)
            reach = np.abs(to_light).sum(axis=1)                  # the kernels' bound scales by |light - v0|_1
            inside, unsure = self._light_sides(position, self._reach(position, receiver_bounds))
            sigma = np.where(inside[label], -sigma, sigma)
        else:
            side = self.normals @ -np.asarray(light.direction, dtype=np.float32).astype(float)
            reach = 1.0
            unsure = np.zeros(len(self.low), dtype=bool)
        # A face nearly edge-on to the light, within EDGE_ON times the kernels' own bound of its side: its
        # cone test is oriented by that side, and a walk may miss it where it is the crossing; without the
        # cull the face turned away catches the segment (bench/cull.py's red team: 57 of 40 k receivers
        # on a floor with the light 1e-7 above it). Its whole component is listed.
        edge_on = np.abs(side) <= EDGE_ON * self.plane_rel * self.lengths * reach
        unsure[label[edge_on]] = True
        culled = self.ids[~unsure[label] & (sigma * side < 0)]
        if len(culled) < MIN_CULLED * len(self.faces):
            return None
        keep = np.ones(len(self.faces), dtype=bool)
        keep[culled] = False
        return np.flatnonzero(keep)

    def _reach(self, position: np.ndarray, receiver_bounds: np.ndarray) -> float:
        """The farthest a receiver or a corner may lie from the light at ``position`` (frame coordinates)."""
        box = np.asarray(receiver_bounds, dtype=np.float64) - self.centre
        low = np.minimum(box[0], self.low.min(axis=0))
        high = np.maximum(box[1], self.high.max(axis=0))
        return float(np.linalg.norm(np.maximum(np.abs(low - position), np.abs(high - position))))

    def _light_sides(self, position: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
        """(C,) bool twice: the light inside each certified component, and too near its surface to
        rely on that. Within LIGHT_CLEARANCE of the component's size, the winding number's float64 sum
        may round to the wrong integer (on the surface it is fractional). Within NEAR_LIGHT of
        ``reach``, the walks' float32 segments end within ~6e-8 of their length of the light, and near
        an edge the fine cells' masks and the watertight test may disagree on which face a crossing
        is in: a red team lost shadows with lights 1.2e-6 to 1e-5 of the scene off a sphere's vertex
        and 1e-5 of a small cube's size above its face (in a scene 300 times larger), none at 2e-5
        of the scene; NEAR_LIGHT leaves a factor of 5. Without the cull the face the segment entered
        by catches it."""
        ncomp = len(self.low)
        inside, unsure = np.zeros(ncomp, dtype=bool), np.zeros(ncomp, dtype=bool)
        size = np.linalg.norm(self.high - self.low, axis=1)
        clearance = np.maximum(LIGHT_CLEARANCE * size, NEAR_LIGHT * reach)
        pad = clearance[:, None]
        near = np.all((self.low - pad <= position) & (position <= self.high + pad), axis=1)
        certified = np.zeros(ncomp, dtype=bool)
        certified[self.label[self.ids]] = True
        for comp in np.flatnonzero(near & certified):
            tri = self.vertices[self.faces[self.label == comp]]
            if triangle_distances(tri, position).min() <= clearance[comp]:
                unsure[comp] = True
                continue
            winding = solid_angles(tri, position).sum() / (4 * np.pi)
            inside[comp] = abs(winding) > 0.5
        return inside, unsure


def solids(mesh: Mesh) -> Solids:
    """The :class:`Solids` of ``mesh``, certified once per mesh (a :class:`Mesh` is immutable)."""
    return per_mesh(_CACHE, mesh, _certify)


def _certify(mesh: Mesh) -> Solids:
    adjacency = edge_adjacency(mesh)
    centre = 0.5 * (mesh.bounds[0] + mesh.bounds[1])            # the exact method's frame (exact.py prepare)
    vertices = (mesh.vertices.astype(np.float64) - centre).astype(np.float32).astype(np.float64)
    faces = mesh.faces.astype(np.int64)
    label = np.asarray(adjacency.components, dtype=np.int64)
    ncomp = int(label.max()) + 1
    tris = vertices[faces]                                                  # (F, 3, 3)
    low = np.full((ncomp, 3), np.inf)
    high = np.full((ncomp, 3), -np.inf)
    np.minimum.at(low, label, tris.min(axis=1))
    np.maximum.at(high, label, tris.max(axis=1))

    good = np.zeros(ncomp, dtype=bool)
    good[label[adjacency.closed_faces]] = True
    good[label[adjacency.collapsed_faces]] = False
    sigma_of = _volume_signs(tris, label, ncomp, low, high)
    good &= sigma_of != 0
    if np.count_nonzero(good[label]) < 2 * MIN_CULLED * len(faces):     # too few to leave out enough
        good[:] = False
    if good.any():
        candidates = np.flatnonzero(good[label])
        bad = _components_not_embedded(tris, faces, label, candidates, low, high)
        good[bad] = False
    sigma = np.where(good[label], sigma_of[label], 0).astype(np.int8)
    ids = np.flatnonzero(sigma)
    tri = tris[ids]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    lengths = np.linalg.norm(normals, axis=1)
    edges = np.linalg.norm(tri[:, 1] - tri[:, 0], axis=1) * np.linalg.norm(tri[:, 2] - tri[:, 0], axis=1)
    with np.errstate(divide="ignore"):
        plane_rel = 1e-6 + KERNEL_NORMAL_ULPS * np.finfo(np.float32).eps * edges / lengths
    return Solids(vertices, faces, sigma, label, low, high, ids, tri[:, 0], normals, lengths, plane_rel, centre)


def _volume_signs(tris, label, ncomp, low, high) -> np.ndarray:
    """(C,) int: the sign of each component's signed volume, 0 where it is too small to be sure of."""
    centre = 0.5 * (low + high)[label]                                      # fewer cancellations
    a, b, c = (tris[:, i] - centre for i in range(3))
    volume = np.bincount(label, weights=np.einsum("ij,ij->i", a, np.cross(b, c)), minlength=ncomp) / 6
    size = np.linalg.norm(high - low, axis=1)
    return np.where(np.abs(volume) > 1e-6 * size ** 3, np.sign(volume), 0).astype(np.int64)


def _components_not_embedded(tris, faces, label, ids, low, high) -> np.ndarray:
    """Labels of the components among faces ``ids`` with a pair of triangles not proved apart."""
    pairs = _candidate_pairs(tris[ids], label[ids], low, high)
    if pairs is None:
        return np.unique(label[ids])
    bad = []
    for lo in range(0, len(pairs), PAIRS_PER_PASS):           # bounded memory: ~1 KB of temporaries a pair
        a, b = ids[pairs[lo:lo + PAIRS_PER_PASS, 0]], ids[pairs[lo:lo + PAIRS_PER_PASS, 1]]
        bad.append(label[a[~_apart(tris[a], tris[b], faces[a], faces[b])]])
    return np.unique(np.concatenate(bad)) if bad else np.zeros(0, dtype=np.int64)


def _candidate_pairs(tris, label, low, high) -> np.ndarray | None:
    """(P, 2) index pairs (i < j) of triangles of one component whose boxes share a cell of that
    component's grid: every pair that may intersect, and others. None if they are too many."""
    lo, hi = tris.min(axis=1), tris.max(axis=1)
    pad = REL * np.abs(high - low).max(axis=1)[label][:, None] + REL * np.abs(lo)
    lo, hi = lo - pad, hi + pad
    extent = (hi - lo).max(axis=1)
    ncomp = len(low)
    order = np.lexsort((extent, label))                      # by component, then face size
    starts = np.searchsorted(label[order], np.arange(ncomp))
    ends = np.searchsorted(label[order], np.arange(ncomp), side="right")
    middle = order[np.clip((starts + ends - 1) // 2, 0, len(order) - 1)]
    cell = np.where(ends > starts, extent[middle], 0.0)         # a component's median face size
    cell = np.maximum(cell, REL * np.abs(high - low).max(axis=1) + np.finfo(float).tiny)
    for _ in range(64):                                      # doubled while its faces cover too many cells
        first = np.floor((lo - low[label]) / cell[label][:, None]).astype(np.int64)
        last = np.floor((hi - low[label]) / cell[label][:, None]).astype(np.int64)
        span = last - first + 1
        count = span.prod(axis=1)
        per_comp = np.bincount(label, weights=count, minlength=ncomp)
        faces_per_comp = np.bincount(label, minlength=ncomp)
        crowded = per_comp > MAX_CELLS_PER_FACE * np.maximum(faces_per_comp, 1)
        if not crowded.any():
            break
        cell[crowded] *= 2
    else:
        return None
    shift = first.min(axis=0)                               # padded boxes may start a cell below 0
    first, last = first - shift, last - shift
    dims = last.max(axis=0) + 1
    if float(np.prod(dims.astype(np.float64))) * ncomp >= 2.0 ** 62:
        return None
    face = np.repeat(np.arange(len(tris)), count)
    k = np.arange(len(face)) - np.repeat(np.cumsum(count) - count, count)
    sx, sy = span[face, 0], span[face, 1]
    ix = first[face, 0] + k % sx
    iy = first[face, 1] + (k // sx) % sy
    iz = first[face, 2] + k // (sx * sy)
    key = ((label[face] * dims[0] + ix) * dims[1] + iy) * dims[2] + iz
    order = np.argsort(key, kind="stable")
    key, face = key[order], face[order]
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    size = np.diff(np.r_[start, len(key)])
    group_start = np.repeat(start, size)
    rank = np.arange(len(key)) - group_start
    later = np.repeat(size, size) - 1 - rank                 # entries after this one in its cell
    total = int(later.sum())
    if total > min(MAX_PAIRS_PER_FACE * len(tris), MAX_PAIRS):
        return None
    first_of = np.repeat(np.arange(len(key)), later)
    step = np.arange(total) - np.repeat(np.cumsum(later) - later, later) + 1
    i, j = face[first_of], face[first_of + step]
    i, j = np.minimum(i, j), np.maximum(i, j)
    keys = np.sort(i * len(tris) + j)
    keys = keys[np.r_[True, keys[1:] != keys[:-1]]] if len(keys) else keys
    i, j = keys // len(tris), keys % len(tris)
    overlap = np.all((lo[i] <= hi[j]) & (lo[j] <= hi[i]), axis=1)
    return np.stack([i[overlap], j[overlap]], axis=1)


def _apart(ta, tb, fa, fb) -> np.ndarray:
    """(P,) bool: triangles ``ta``, ``tb`` ((P, 3, 3) float64, corner ids ``fa``, ``fb``) proved to meet
    at most as mesh neighbours do: nowhere, along their shared edge, or at their shared corner."""
    same = fa[:, :, None] == fb[:, None, :]                       # (P, 3, 3): corner i of a is corner j of b
    shared = same.sum(axis=(1, 2))
    apart = np.zeros(len(ta), dtype=bool)
    for n, test in ((0, _separated), (1, _apart_at_corner), (2, _apart_at_edge)):
        rows = np.flatnonzero(shared == n)
        if len(rows):
            apart[rows] = test(ta[rows], tb[rows], same[rows])
    return apart


def _margin(size: np.ndarray, degree: int) -> np.ndarray:
    """How far from 0 a product m . x must be to trust its sign, m of ``degree`` lengths and x of one,
    made of differences of corners within ``size`` of each other: far above float64's rounding."""
    return REL * size ** (degree + 1)


def _separated(ta, tb, _same) -> np.ndarray:
    """Disjoint by a separating axis: the two normals, the nine edge-edge cross products and, for
    coplanar pairs, the six in-plane edge normals (complete for two triangles). Each axis is tried on
    the pairs no earlier one separated."""
    origin = ta[:, :1]
    ta, tb = ta - origin, tb - origin
    ea, eb = np.roll(ta, -1, axis=1) - ta, np.roll(tb, -1, axis=1) - tb
    na, nb = np.cross(ea[:, 0], ea[:, 1]), np.cross(eb[:, 0], eb[:, 1])
    axes = [(lambda r: na[r], 2), (lambda r: nb[r], 2)]        # (axis of the rows r, its degree in lengths)
    axes += [(lambda r, i=i, j=j: np.cross(ea[r, i], eb[r, j]), 2) for i in range(3) for j in range(3)]
    axes += [(lambda r, i=i: np.cross(na[r], ea[r, i]), 3) for i in range(3)]
    axes += [(lambda r, i=i: np.cross(nb[r], eb[r, i]), 3) for i in range(3)]
    size = np.abs(np.concatenate([ta, tb], axis=1)).max(axis=(1, 2))
    apart = np.zeros(len(ta), dtype=bool)
    rows = np.arange(len(ta))
    for axis_of, degree in axes:
        axis = axis_of(rows)
        pa, pb = np.einsum("pkj,pj->pk", ta[rows], axis), np.einsum("pkj,pj->pk", tb[rows], axis)
        gap = _margin(size[rows], degree)
        done = (pa.max(axis=1) < pb.min(axis=1) - gap) | (pb.max(axis=1) < pa.min(axis=1) - gap)
        apart[rows[done]] = True
        rows = rows[~done]
        if not len(rows):
            break
    return apart


def _apart_at_edge(ta, tb, same) -> np.ndarray:
    """Neighbours across an edge meet only along it: b's far corner off a's plane, or in it but on the
    other side of the edge."""
    rows = np.arange(len(ta))
    ia = np.argmin(same.any(axis=2), axis=1)                  # a's corner off the edge
    ib = np.argmin(same.any(axis=1), axis=1)
    ja = (ia + 1) % 3
    p, q, c, d = ta[rows, ja], ta[rows, (ia + 2) % 3], ta[rows, ia], tb[rows, ib]
    edge = q - p
    na = np.cross(edge, c - p)
    size = np.abs(np.stack([p, q, c, d], axis=1) - p[:, None]).max(axis=(1, 2))
    off_plane = np.abs(np.einsum("ij,ij->i", na, d - p)) > _margin(size, 2)
    across = np.einsum("ij,ij->i", na, np.cross(edge, d - p)) < -_margin(size, 3)
    return off_plane | across


def _apart_at_corner(ta, tb, same) -> np.ndarray:
    """Triangles sharing one corner v meet only there when a plane through v has one strictly on each
    side, each touching it at most along the rays the plane is built from."""
    rows = np.arange(len(ta))
    ia = np.argmax(same.any(axis=2), axis=1)
    ib = np.argmax(same.any(axis=1), axis=1)
    v = ta[rows, ia]
    a1, a2 = ta[rows, (ia + 1) % 3] - v, ta[rows, (ia + 2) % 3] - v
    b1, b2 = tb[rows, (ib + 1) % 3] - v, tb[rows, (ib + 2) % 3] - v
    size = np.abs(np.stack([a1, a2, b1, b2], axis=1)).max(axis=(1, 2))

    def sides(r, m, degree, free_a, free_b):
        """For rows r: m's plane through v touches a along its rays not in free_a, b along those not in
        free_b; the free corners strictly on opposite sides, either way round."""
        gap = _margin(size[r], degree)
        dot_a = [np.einsum("ij,ij->i", m, x[r]) for x in free_a]
        dot_b = [np.einsum("ij,ij->i", m, x[r]) for x in free_b]
        return np.any([np.all([s * d > gap for d in dot_a] + [-s * d > gap for d in dot_b], axis=0)
                       for s in (1.0, -1.0)], axis=0)

    na, nb = np.cross(a1, a2), np.cross(b1, b2)
    tries = [(lambda r: na[r], 2, [], [b1, b2]), (lambda r: nb[r], 2, [a1, a2], [])]
    for x, x_free in ((a1, a2), (a2, a1)):
        tries.append((lambda r, x=x: np.cross(na[r], x[r]), 3, [x_free], [b1, b2]))
        for y, y_free in ((b1, b2), (b2, b1)):
            tries.append((lambda r, x=x, y=y: np.cross(x[r], y[r]), 2, [x_free], [y_free]))
    for y, y_free in ((b1, b2), (b2, b1)):
        tries.append((lambda r, y=y: np.cross(nb[r], y[r]), 3, [a1, a2], [y_free]))
    apart = np.zeros(len(v), dtype=bool)
    rows = np.arange(len(v))
    for plane_of, degree, free_a, free_b in tries:              # each on the pairs not yet proved apart
        done = sides(rows, plane_of(rows), degree, free_a, free_b)
        apart[rows[done]] = True
        rows = rows[~done]
        if not len(rows):
            return apart
    apart[rows] = _sectors_apart(a1[rows], a2[rows], b1[rows], b2[rows], na[rows])
    return apart


def _sectors_apart(a1, a2, b1, b2, na) -> np.ndarray:
    """Wedges v + cone(a1, a2) and v + cone(b1, b2) that meet only at v, by their directions in a's plane:
    b's wedge projected along a's normal ``na`` spans a sector disjoint from a's, by a margin. Sound:
    the projection keeps every point of a's wedge, so a common point other than v would give a common
    direction. The planes above miss coplanar fans whose edges are collinear through v (a grid's
    triangles round a vertex, two sectors opposite each other): every plane along an edge of one holds
    an edge of the other."""
    u = a1 / np.linalg.norm(a1, axis=1, keepdims=True)
    w = np.cross(na, a1)
    w /= np.linalg.norm(w, axis=1, keepdims=True)

    def angle(x):
        along, across = np.einsum("ij,ij->i", x, u), np.einsum("ij,ij->i", x, w)
        clear = np.hypot(along, across) > 1e-6 * np.linalg.norm(x, axis=1)   # not along the normal
        return np.mod(np.arctan2(across, along), 2 * np.pi), clear

    (alpha, _), (beta1, clear1), (beta2, clear2) = angle(a2), angle(b1), angle(b2)
    turn = np.mod(beta2 - beta1, 2 * np.pi)
    start = np.where(turn < np.pi, beta1, beta2)               # b's sector, counter-clockwise from start
    span = np.minimum(turn, 2 * np.pi - turn)
    margin = 1e-9
    return (clear1 & clear2 & (span < np.pi - margin) & (start > alpha + margin)
            & (start + span < 2 * np.pi - margin))
