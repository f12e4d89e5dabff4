"""Silhouettes of a moving light: the paper's tracking walks (sections III.B-C, as device walks) and
Markosian's randomized method (grown on the host), behind :class:`SilhouetteTracker`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from ..checks import non_negative_float, positive_float, positive_int
from ..device import get_device
from ..geometry import Mesh
from ..lights import PointLight, check_light
from ..topology import EdgeAdjacency, concave_edges, edge_adjacency
from .classify import Silhouette, _facing_on_device, _global_size, adjacency_buffers, host_facing, silhouette_edges


@dataclass(frozen=True, eq=False)
class HalfEdges:
    """Face-to-face tables for the walks. Half-edge ``h = 3 f + k`` is face f's edge k, running from
    ``faces[f, k]`` (``tails[h]``) to ``faces[f, (k + 1) % 3]`` (``heads[h]``).

    ``edge`` (3F,) the adjacency edge of each half-edge (-1 for collapsed faces); ``twin`` (3F,) the
    half-edge of the other face on the same edge (-1 on a border: ``twin // 3`` is then -1, the
    "missing face"); ``edge_halves`` (E, 2) each edge's half-edges in face order (-1 for a border's
    second); ``vertex_offsets``/``vertex_edges`` the edges at each vertex (CSR). Built for meshes whose
    edges have one or two faces.
    """

    tails: np.ndarray
    heads: np.ndarray
    edge: np.ndarray
    twin: np.ndarray
    edge_halves: np.ndarray
    vertex_offsets: np.ndarray
    vertex_edges: np.ndarray

    @classmethod
    def build(cls, adjacency: EdgeAdjacency) -> "HalfEdges":
        """The tables of ``adjacency``'s mesh (sort-based, vectorised; collapsed faces get no edges)."""
        faces = adjacency.faces.astype(np.int64)
        nvertices, nhalves = len(adjacency.vertices), 3 * len(faces)
        tails, heads = faces.reshape(-1), faces[:, [1, 2, 0]].reshape(-1)
        kept = np.ones(nhalves, dtype=bool)
        kept[(3 * adjacency.collapsed_faces[:, None] + np.arange(3)).reshape(-1)] = False
        edges = adjacency.edges.astype(np.int64)
        keys = np.minimum(tails, heads) * nvertices + np.maximum(tails, heads)
        edge = np.full(nhalves, -1, dtype=np.int64)
        edge[kept] = np.searchsorted(edges[:, 0] * nvertices + edges[:, 1], keys[kept])
        # Sorted by (edge, face), the half-edges line up with the table's face_items.
        halves = np.flatnonzero(kept)
        halves = halves[np.lexsort((halves // 3, edge[halves]))]
        first, count = adjacency.face_offsets[:-1], adjacency.face_count
        second = np.where(count > 1, halves[np.minimum(first + 1, len(halves) - 1)], -1)
        edge_halves = np.stack([halves[first], second], axis=1) if len(first) else np.zeros((0, 2), np.int64)
        twin = np.full(nhalves, -1, dtype=np.int64)
        pairs = edge_halves[count == 2]
        twin[pairs[:, 0]], twin[pairs[:, 1]] = pairs[:, 1], pairs[:, 0]
        ends = edges.reshape(-1)
        order = np.argsort(ends, kind="stable")
        return cls(tails=tails, heads=heads, edge=edge, twin=twin, edge_halves=edge_halves,
                   vertex_offsets=np.r_[0, np.cumsum(np.bincount(ends, minlength=nvertices))],
                   vertex_edges=order // 2)

    def edges_at(self, vertices: np.ndarray) -> np.ndarray:
        """The edges at each of ``vertices``, concatenated (with repeats)."""
        starts = self.vertex_offsets[vertices]
        counts = self.vertex_offsets[vertices + 1] - starts
        within = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        return self.vertex_edges[np.repeat(starts, counts) + within]


TRACKER_METHODS = ("brute", "tracking", "random")


class SilhouetteTracker:
    """Silhouette edges frame after frame for a moving light, by one of three methods.

    - ``"brute"``: every edge classified on the device each frame (:func:`silhouette_edges`).
    - ``"tracking"`` (Fawad, Wang & Wu, sections III.B-C, after Tom H.'s silhouette tracking): the
      first frame is brute force (the paper needs a silhouette to start from). Then from each of last
      frame's silhouette edges: if it is still one it is a seed; if both its faces now face the light
      the silhouette moved away, and a zigzag walk (``find_edge_by_walk``, left and right in turn)
      crosses light-facing faces from the face that turned until a neighbour faces away; if both face
      away, the walk crosses faces facing away from the face that turned until a neighbour faces the
      light. Walks stop after ``max_walk`` faces (counted as lost). From every seed the loop is completed
      by the walk of section III.C: around the seed's vertex through light-facing faces to the next
      face whose neighbour faces away, which gives the next edge of the loop, until an edge already
      found. As the paper adds, border edges are tested every frame (open meshes), and so are concave
      edges of at least ``180 + concave_angle`` degrees, where new loops are born.
      Jumps: when more than ``max_stale`` of last frame's edges are no longer silhouettes, or more than
      ``max_lost`` of the walks are lost, or fewer than ``1 - max_stale`` times last frame's edges
      are found, or last frame had no silhouette edge at all (a light inside a closed mesh: nothing to
      track from), the frame is redone by brute force (``stats["fallback"]``): no silent loss after a
      large light move. (Small loops that vanish leave lost walks too, ~12 % of the bunny's walks at
      3 degrees a frame, hence a share rather than any loss.)
    - ``"random"`` (Markosian et al. 1997, as the paper uses it): test a random ``fraction`` of the
      edges (drawn anew each frame from ``seed``), last frame's silhouette edges and every border edge;
      grow each silhouette edge found along the contour (test the edges at its vertices) until the
      chains close. No history on the first frame: the random fraction alone, as in the paper. Loops
      missed by every sample are lost until a later sample hits them (the paper trades accuracy for
      speed); found edges are always real silhouette edges.

    Where the work runs: tracking runs its tests and walks in kernels (``track_previous``,
    ``seed_edges``, ``complete_loops``: one work-item per candidate, last frame's edges kept on the
    device). Their NumPy twin, all walkers a step at a time, is their reference
    (``shadowcl.reference.silhouette.tracking_frame``; as a tracker option it was 1.05-9.9x slower on
    every model and path of bench/silhouettes.py). The randomized method grows
    on the host in NumPy rounds: its growth tests every edge at a chain's vertices, so it also finds
    loops that touch a found one at a vertex (a device version growing by the loop walk instead lost
    2-6 % of the recall on the bunny and ogre, 60 frames at 3 degrees, fractions 0.02 and 0.1). Its
    faces are tested on the host by :func:`host_facing` as the growth reaches them, except that a batch
    of at least ``device_batch`` new faces (default ``1000 + F / 20``, the measured break-even) is done
    by one device pass over every face. Every facing, on host or device, is the kernel's float32
    arithmetic, so tracking and random never report an edge the brute force would not (precision 1).

    ``update(light)`` returns a :class:`Silhouette` (codes 0 for edges not found; ``facing`` computed
    on use); ``stats`` describes the last update (``fallback``, ``stale``, ``lost_walks``,
    ``faces_tested`` (None for tracked frames: the device's walks do not count them), ``edges_found``;
    ``rounds`` and ``sampled`` for random); ``reset()`` forgets the history. Tracking refuses non-manifold and inconsistently wound meshes (its loop walk follows the winding), random non-manifold ones (``ValueError``); brute force
    reports non-manifold edges with code :data:`NONMANIFOLD`.
    """

    def __init__(self, device, mesh_or_adjacency, method: str = "brute", fraction: float = 0.02, seed: int = 0,
                 *, concave_angle: float = 0.0, max_walk: int = 16, max_stale: float = 0.5,
                 max_lost: float = 0.5, device_batch: "int | None" = None):
        self.device = get_device(device)
        adjacency = mesh_or_adjacency
        if isinstance(adjacency, Mesh):
            adjacency = edge_adjacency(adjacency)
        elif not isinstance(adjacency, EdgeAdjacency):
            raise TypeError(f"mesh_or_adjacency: expected a Mesh or an EdgeAdjacency, got {type(adjacency).__name__}")
        if method not in TRACKER_METHODS:
            raise ValueError(f"method: expected one of {TRACKER_METHODS}, got {method!r}")
        fraction = positive_float("fraction", fraction)
        if fraction > 1:
            raise ValueError(f"fraction: must be at most 1, got {fraction!r}")
        for name, share in (("max_stale", max_stale), ("max_lost", max_lost)):
            if positive_float(name, share) > 1:
                raise ValueError(f"{name}: must be at most 1, got {share!r}")
        self.adjacency, self.method, self.fraction = adjacency, method, fraction
        self.max_walk = positive_int("max_walk", max_walk)
        self.max_stale, self.max_lost = float(max_stale), float(max_lost)
        # Measured on PoCL (bench/silhouettes.py): host_facing ~0.08 us a face; one device pass ~0.085 ms
        # + ~4 ns a face with its read-back. Break-even: ~1000 + F / 20 faces.
        self.device_batch = (1000 + len(adjacency.faces) // 20 if device_batch is None
                             else positive_int("device_batch", device_batch))
        self.concave_angle = non_negative_float("concave_angle", concave_angle)
        self._seed = positive_int("seed", seed, minimum=0)
        self.stats: dict = {}
        self._on_device, self._previous = None, None
        if method == "brute":
            return
        if method == "tracking" or len(adjacency.nonmanifold_edges):
            adjacency.require_manifold(f"SilhouetteTracker(method={method!r}): mesh")
        self.halves = HalfEdges.build(adjacency)
        nfaces, nedges = len(adjacency.faces), len(adjacency.edges)
        # Per-frame caches stamped with the frame number (no clearing); index -1 is the missing face.
        self._face_stamp = np.zeros(nfaces + 1, dtype=np.int64)
        self._face_lit = np.zeros(nfaces + 1, dtype=bool)
        self._edge_stamp = np.zeros(nedges, dtype=np.int64)
        # Scratch for _distinct.
        self._face_slot = np.zeros(nfaces + 1, dtype=np.int64)
        self._edge_slot = np.zeros(nedges, dtype=np.int64)
        self._vertex_slot = np.zeros(len(adjacency.vertices), dtype=np.int64)
        self._frame = 0
        self._concave = self._concave_edges() if method == "tracking" else np.zeros(0, np.int64)
        self._on_device = _DeviceWalks(self) if method == "tracking" else None
        self.reset()

    @property
    def concave_edges(self) -> np.ndarray:
        """Edges tracking tests every frame for new loops (dihedral >= 180 + ``concave_angle`` degrees)."""
        return self._concave

    def reset(self) -> None:
        """Forget the previous frame: the next update starts as a first frame."""
        self._previous = None                    # last frame's silhouettes as light-facing half-edges
        if self.method == "random":
            self._rng = np.random.default_rng(self._seed)
        if self._on_device:
            self._on_device.set_previous(np.zeros(0, np.int64))

    def update(self, light) -> Silhouette:
        """The silhouette against ``light`` (a PointLight or DirectionalLight), using the history."""
        light = check_light(light)
        if self.method == "brute":
            self.stats = {"method": "brute", "fallback": False, "faces_tested": len(self.adjacency.faces)}
            return silhouette_edges(self.device, self.adjacency, light)
        self._frame += 1
        self._face_stamp[-1] = self._frame          # the missing face: known, not light-facing
        self._light, self._tested, self.stats = light, 0, {}
        fallback = False
        if self.method == "random":
            found = self._random_frame()
        elif self._previous is None:
            found = None
        elif not len(self._previous):
            # Nothing to track from: a loop born away from the border and concave edges would be lost.
            found, fallback = None, True
        else:
            found = self._on_device.frame()
            fallback = found is None
        if found is None:                            # first tracking frame, no history, or a detected jump
            silhouette = silhouette_edges(self.device, self.adjacency, light)
            self._previous = self._lit_halves(silhouette)
            if self._on_device:
                self._on_device.set_previous(self._previous)
            self.stats.update(method=self.method, fallback=fallback, faces_tested=len(self.adjacency.faces),
                              edges_found=len(self._previous))
            return silhouette
        self._previous = found
        codes = np.zeros(len(self.adjacency.edges), dtype=np.int8)
        h = self.halves
        codes[h.edge[found]] = np.where(h.tails[found] < h.heads[found], 1, -1)
        self.stats.update(method=self.method, fallback=False, edges_found=len(found),
                          faces_tested=None if self._on_device else self._tested)
        return Silhouette(self.adjacency, light, codes, device=self.device)

    # Shared pieces ----------------------------------------------------------------------------------
    def _lit(self, faces: np.ndarray, batch: bool = False) -> np.ndarray:
        """Facing of ``faces`` (-1: the missing face, never light-facing), each face tested once a frame:
        on the host, or for a ``batch`` of at least ``device_batch`` new faces by one device pass over
        every face (its launch and read-back cost as much as ~1000 + F / 20 faces on the host)."""
        unknown = _distinct(faces[self._face_stamp[faces] != self._frame], self._face_slot)
        if batch and len(unknown) >= self.device_batch:
            facing_g, _ = _facing_on_device(self.device, self.adjacency, self._light)
            self._face_lit[:-1] = self.device.from_device(facing_g, len(self._face_lit) - 1, np.uint8).view(bool)
            self._face_stamp[:] = self._frame
            self._tested += len(self._face_lit) - 1
        elif len(unknown):
            self._face_lit[unknown] = host_facing(self.adjacency.vertices, self.adjacency.faces, self._light, unknown)
            self._face_stamp[unknown] = self._frame
            self._tested += len(unknown)
        return self._face_lit[faces]

    def _test_edges(self, edges: np.ndarray, batch: bool = False) -> np.ndarray:
        """The light-facing half-edges of the silhouettes among ``edges``, marked as tested."""
        self._edge_stamp[edges] = self._frame
        first, second = self.halves.edge_halves[edges].T
        lit = self._lit(np.r_[first, second] // 3, batch)
        lit0, lit1 = lit[:len(edges)], lit[len(edges):]
        return np.where(lit0, first, second)[lit0 != lit1]

    def _lit_halves(self, silhouette: Silhouette) -> np.ndarray:
        """The light-facing half-edge of every silhouette edge of a brute-force ``silhouette``."""
        index = silhouette.indices
        first, second = self.halves.edge_halves[index].T
        runs_up = self.halves.tails[first] < self.halves.heads[first]
        return np.where(runs_up == (silhouette.codes[index] > 0), first, second)

    def _concave_edges(self) -> np.ndarray:
        """Two-face edges folding inwards by at least ``concave_angle`` degrees (dihedral >= 180 + angle)."""
        return concave_edges(self.adjacency, min_degrees=self.concave_angle)

    # Randomized -------------------------------------------------------------------------------------
    def _sample(self) -> np.ndarray:
        """This frame's random ``fraction`` of the edges (with repeats)."""
        nedges = len(self.adjacency.edges)
        size = int(np.ceil(self.fraction * nedges))
        return self._rng.integers(0, nedges, size=size) if nedges else np.zeros(0, np.int64)

    def _random_frame(self) -> np.ndarray:
        sample = self._sample()
        previous = self.halves.edge[self._previous] if self._previous is not None else np.zeros(0, np.int64)
        candidates = _distinct(np.r_[previous, sample, self.adjacency.border_edges], self._edge_slot)
        frontier = self._test_edges(candidates, batch=True)
        found, rounds = [frontier], 0
        while len(frontier):                              # grow along the contour until the chains close
            rounds += 1
            ends = _distinct(self.adjacency.edges[self.halves.edge[frontier]].reshape(-1), self._vertex_slot)
            near = self.halves.edges_at(ends)
            near = _distinct(near[self._edge_stamp[near] != self._frame], self._edge_slot)
            frontier = self._test_edges(near)
            found.append(frontier)
        self.stats.update(rounds=rounds, sampled=len(sample))
        return np.concatenate(found)


def _distinct(items: np.ndarray, slot: np.ndarray, positions: bool = False) -> np.ndarray:
    """``items`` without repeats (in no particular order), or the ``positions`` of one of each, in
    linear time: ``slot`` (scratch, one entry per possible item) keeps the last position that wrote
    it. np.unique sorts or hashes, ~10x slower on these sizes."""
    where = np.arange(len(items))
    slot[items] = where
    kept = where[slot[items] == where]
    return kept if positions else items[kept]


class _DeviceWalks:
    """Tracking's walks on the device (kernels/silhouette.cl: track_previous, seed_edges,
    complete_loops), one work-item per candidate, last frame's edges kept on the device between frames."""

    def __init__(self, tracker: SilhouetteTracker):
        self.tracker = tracker
        device, adjacency, halves = tracker.device, tracker.adjacency, tracker.halves
        self.capacity = max(len(adjacency.edges), 1)       # every edge is appended at most once a frame
        listed = halves.edge_halves[np.r_[adjacency.border_edges, tracker.concave_edges], 0]
        self.nlisted = len(listed)
        self.twin_g, self.edge_g, self.listed_g = (device.to_device(a.astype(np.int32))
                                                    for a in (halves.twin, halves.edge, listed))
        self.claim_g = _writable(device, np.zeros(self.capacity, np.int32), "claims")
        self.found_g = [device.empty(4 * self.capacity, "tracked edges") for _ in range(2)]
        self.seeds_g = device.empty(4 * (self.capacity + self.nlisted), "tracking seeds")
        self.counters_g = device.empty(4 * 5, "tracking counters")
        self.stamp, self.nprevious = 0, 0
        self.options = (f"-DMAX_WALK={tracker.max_walk}",)

    def set_previous(self, previous: np.ndarray) -> None:
        """Upload last frame's light-facing half-edges (after a brute-force frame; none after a reset)."""
        if len(previous):
            cl.enqueue_copy(self.tracker.device.queue, self.found_g[0], previous.astype(np.int32))
        self.nprevious = len(previous)

    def frame(self) -> "np.ndarray | None":
        """This frame's light-facing silhouette half-edges, or None to fall back (the host's rules)."""
        tracker, device = self.tracker, self.tracker.device
        light, queue = tracker._light, device.queue
        point = isinstance(light, PointLight)
        vector = [np.float32(c) for c in (light.position if point else light.direction)]
        options = (f"-DLIGHT_POINT={int(point)}",) + self.options
        vertices_g, faces_g, _, _ = adjacency_buffers(device, tracker.adjacency)
        cl.enqueue_fill_buffer(queue, self.counters_g, np.int32(0), 0, 4 * 5)
        device.kernel("silhouette.cl", "track_previous", options)(
            queue, _global_size(self.nprevious), None, vertices_g, faces_g, self.twin_g, self.found_g[0],
            np.int32(self.nprevious), *vector, self.seeds_g, self.counters_g)
        device.kernel("silhouette.cl", "seed_edges", options)(
            queue, _global_size(self.nlisted), None, vertices_g, faces_g, self.twin_g, self.listed_g,
            np.int32(self.nlisted), *vector, self.seeds_g, self.counters_g)
        _, stale, lost, _, nseeds = device.from_device(self.counters_g, 5, np.int32).tolist()
        tracker.stats.update(stale=stale / max(self.nprevious, 1), lost_walks=lost)
        if stale > tracker.max_stale * self.nprevious or lost > tracker.max_lost * stale:
            return None
        self.stamp += 1
        found_g = self.found_g[1]
        device.kernel("silhouette.cl", "complete_loops", options)(
            queue, _global_size(nseeds), None, vertices_g, faces_g, self.twin_g, self.edge_g, self.seeds_g,
            np.int32(nseeds), *vector, np.int32(self.stamp), self.claim_g, found_g, np.int32(self.capacity),
            np.int32(6 * self.capacity + 6), self.counters_g)
        count, _, _, unclosed, _ = device.from_device(self.counters_g, 5, np.int32).tolist()
        if count > self.capacity or unclosed:
            raise RuntimeError(f"complete_loops: {count} edges for {self.capacity} slots, {unclosed} unclosed walks "
                               "(an inconsistent adjacency table)")
        if count < (1 - tracker.max_stale) * self.nprevious:
            return None
        self.found_g.reverse()                            # this frame's edges are the next frame's previous
        self.nprevious = count
        return device.from_device(found_g, count, np.int32).astype(np.int64)


def _writable(device, array: np.ndarray, what: str):
    """A read-write device buffer holding ``array``."""
    buffer = device.empty(array.nbytes, what)
    cl.enqueue_copy(device.queue, buffer, array)
    return buffer
