"""Peers: other people's shadow rays, measured in the same run with the method protocol of shadowcl:
Embree (embreex), Open3D (``open3d-cpu``) and Mitsuba 3 (``mitsuba``, LLVM backend): the ``peers`` extra.

``EmbreePeer`` answers DESIGN.md's question with Embree (through embreex) occlusion queries. embreex's
``EmbreeScene.run`` takes one ray per row, fixes ``tnear`` at 0 and holds the GIL for the whole batch
(two threads run no faster than one), so:

- ``tnear = eps`` is emulated: the ray starts ``eps`` along its unit direction and ``tfar`` is
  shortened by ``eps`` (the same segment; origins are float32, as Embree stores them);
- ``workers > 1`` runs that many worker processes, each with its own copy of the scene. They are
  started when the peer is created (not timed, like a thread pool); ``prepare`` sends them the mesh and
  waits until each has built and committed its BVH (timed); ``classify`` copies the receivers into a
  shared memory block, and each worker makes the rays of its share, queries and writes its part of the
  mask there.
"""

from __future__ import annotations

import multiprocessing
import time
from multiprocessing import shared_memory

import numpy as np

from shadowcl import PointLight


def shadow_rays(points, normals, light, eps: float):
    """Rays of DESIGN.md's shadow test as float32 ``(origins, directions, tfar)`` for Embree with
    ``tnear = 0``, and ``away``: the points whose normal faces away from the light (in shadow, no ray).

    The segment starts at the point (moved ``eps`` along its normal when ``normals`` is given) and
    ends at a point light (or runs to infinity towards a directional light); hits closer than ``eps``
    to its start do not count, which is emulated by starting the ray ``eps`` further along. The start
    is computed in float64, the rest in float32 (Embree's precision).
    """
    start = points if normals is None else points + eps * normals
    eps32 = np.float32(eps)
    direction = light.direction_to_light(start).astype(np.float32)
    length = np.sqrt(np.einsum("ij,ij->i", direction, direction))
    if normals is None:
        away = np.zeros(len(points), bool)
    else:  # point light: n . (light - point) = n . (light - start) + eps for a unit normal
        facing = np.einsum("ij,ij->i", normals.astype(np.float32), direction)
        away = (facing + eps32 if isinstance(light, PointLight) else facing) <= 0
    direction /= length[:, None]
    origins = start.astype(np.float32)
    origins += eps32 * direction
    tfar = length - eps32 if isinstance(light, PointLight) else np.full(len(points), np.inf, np.float32)
    return origins, direction, tfar, away


def build_scene(vertices: np.ndarray, faces: np.ndarray, stats: dict | None = None):
    """A committed embreex scene of the triangles (Embree commits on the first query, so we send one).
    ``stats`` gets the seconds spent in embreex's mesh copy (``mesh_s``) and Embree's commit (``commit_s``)."""
    from embreex import mesh_construction, rtcore_scene

    start = time.perf_counter()
    scene = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(scene, vertices, faces)
    copied = time.perf_counter()
    zero = np.zeros((1, 3), np.float32)
    scene.run(zero, zero + np.float32([[0, 0, 1]]), dists=np.zeros(1, np.float32), query="OCCLUDED")
    if stats is not None:
        stats.update(mesh_s=copied - start, commit_s=time.perf_counter() - copied)
    return scene


def occluded(scene, origins, directions, tfar) -> np.ndarray:
    """Bool per ray: something lies on it between 0 and ``tfar``."""
    return scene.run(origins, directions, dists=tfar, query="OCCLUDED") != -1


def shadow_mask(scene, points, normals, light, eps: float, stats: dict | None = None) -> np.ndarray:
    """DESIGN.md's mask (True = in shadow) by Embree: facing away, or a hit on the shadow ray.
    Facing-away points get ``tfar = -1``, which Embree skips as an inactive ray. ``stats`` gets the
    seconds spent making rays (``rays_s``) and in Embree (``query_s``)."""
    start = time.perf_counter()
    origins, directions, tfar, away = shadow_rays(points, normals, light, eps)
    tfar[away] = -1
    made = time.perf_counter()
    mask = occluded(scene, origins, directions, tfar) | away
    if stats is not None:
        stats.update(rays_s=made - start, query_s=time.perf_counter() - made)
    return mask


def shared_arrays(buffer, n: int, with_normals: bool):
    """Views of a shared block holding points, normals (if any) as float64 (n, 3) and the mask."""
    points = np.ndarray((n, 3), np.float64, buffer)
    normals = np.ndarray((n, 3), np.float64, buffer, offset=24 * n) if with_normals else None
    mask = np.ndarray(n, bool, buffer, offset=(48 if with_normals else 24) * n)
    return points, normals, mask


def _worker(conn) -> None:
    """Worker process loop. ("mesh", vertices, faces): build the scene, answer "ready".
    ("classify", block, n, with_normals, light, eps, lo, hi): write the mask of receivers lo:hi of
    the shared block, answer "done". None: end."""
    scene, block = None, None
    while (message := conn.recv()) is not None:
        if message[0] == "mesh":
            scene = build_scene(*message[1:])
            conn.send("ready")
            continue
        block_name, n, with_normals, light, eps, lo, hi = message[1:]
        if block is None or block.name != block_name:  # kept attached while the peer keeps it
            block = shared_memory.SharedMemory(block_name)
        points, normals, mask = shared_arrays(block.buf, n, with_normals)
        mask[lo:hi] = shadow_mask(scene, points[lo:hi], None if normals is None else normals[lo:hi], light, eps)
        del points, normals, mask  # no views left when the block is replaced
        conn.send("done")


class EmbreePeer:
    """Embree occlusion queries with shadowcl's method protocol (``prepare`` / ``classify``)."""

    name = "embreex"
    parameters = {"workers": (1, "processes querying in parallel; 1 runs in this process")}

    def __init__(self, workers: int = 1):
        import embreex  # noqa: F401 - fail here, before any timing, when the bench extra is missing

        self._pipes, self._processes = [], []
        context = multiprocessing.get_context("spawn")  # fork would copy OpenCL and TBB threads' state
        for _ in range(workers if workers > 1 else 0):
            ours, theirs = context.Pipe()
            process = context.Process(target=_worker, args=(theirs,), daemon=True)
            process.start()
            self._pipes.append(ours)
            self._processes.append(process)
        self.scene = None
        self._block = None
        self.stats = {}  # in process (workers=1): stage times of the last prepare and classify

    def prepare(self, mesh, light, receiver_bounds, eps: float) -> None:
        """Build (and commit) Embree's BVH of ``mesh``; ``receiver_bounds`` is not needed."""
        self.light, self.eps = light, eps
        if not self._pipes:
            self.stats = {}
            self.scene = build_scene(mesh.vertices, mesh.faces, self.stats)
            return
        for pipe in self._pipes:
            pipe.send(("mesh", mesh.vertices, mesh.faces))
        for pipe in self._pipes:
            pipe.recv()

    def classify(self, points, normals) -> np.ndarray:
        """Bool mask, True = in shadow (DESIGN.md's segment test, see :func:`shadow_rays`)."""
        if not self._pipes:
            return shadow_mask(self.scene, points, normals, self.light, self.eps, self.stats)
        n, with_normals = len(points), normals is not None
        size = max((49 if with_normals else 25) * n, 1)
        if self._block is None or self._block.size < size:  # kept between calls: fresh pages are slow
            self._release_block()
            self._block = shared_memory.SharedMemory(create=True, size=size)
        shared_points, shared_normals, mask = shared_arrays(self._block.buf, n, with_normals)
        shared_points[:] = points
        if with_normals:
            shared_normals[:] = normals
        bounds = np.linspace(0, n, len(self._pipes) + 1).astype(int)
        for pipe, lo, hi in zip(self._pipes, bounds[:-1], bounds[1:]):
            pipe.send(("classify", self._block.name, n, with_normals, self.light, self.eps, lo, hi))
        for pipe in self._pipes:
            pipe.recv()
        return mask.copy()

    def _release_block(self) -> None:
        if self._block is not None:
            self._block.close()
            self._block.unlink()
            self._block = None

    def close(self) -> None:
        """Stop the worker processes and free the shared block."""
        for pipe in self._pipes:
            try:
                pipe.send(None)
            except BrokenPipeError:  # the worker died already; its error has been raised
                pass
        for process in self._processes:
            process.join()
        self._pipes, self._processes = [], []
        self._release_block()


class Open3DPeer:
    """Open3D's ``RaycastingScene.test_occlusions`` (Embree inside, its own threads), rays in NumPy by
    :func:`shadow_rays`; a ray's ``tfar`` is folded into its direction's length (Open3D takes one)."""

    name = "open3d"
    parameters = {}

    def __init__(self):
        import open3d  # noqa: F401 - fail here, before any timing, when the peers extra is missing

    def prepare(self, mesh, light, receiver_bounds, eps: float) -> None:
        import open3d as o3d

        self.light, self.eps = light, eps
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(o3d.core.Tensor(mesh.vertices), o3d.core.Tensor(mesh.faces.astype(np.uint32)))
        self.scene.test_occlusions(o3d.core.Tensor(np.zeros((1, 6), np.float32)))   # builds its BVH now

    def classify(self, points, normals) -> np.ndarray:
        import open3d as o3d

        origins, directions, tfar, away = shadow_rays(points, normals, self.light, self.eps)
        point = isinstance(self.light, PointLight)
        rays = np.concatenate([origins, directions * tfar[:, None] if point else directions], axis=1)[~away]
        mask = away.copy()
        mask[~away] = self.scene.test_occlusions(o3d.core.Tensor(rays), tfar=1.0 if point else np.inf).numpy() != 0
        return mask


class MitsubaPeer:
    """Mitsuba 3's ``Scene.ray_test`` on the ``llvm_ad_rgb`` variant (Dr.Jit's LLVM backend: needs a libLLVM
    on the machine, e.g. Debian's libllvm19), the segments computed in Dr.Jit as a Mitsuba user would:
    DESIGN.md's segment with the eps start emulated as in :func:`shadow_rays`."""

    name = "mitsuba"
    parameters = {}

    def __init__(self):
        import mitsuba as mi

        mi.set_variant("llvm_ad_rgb")

    def prepare(self, mesh, light, receiver_bounds, eps: float) -> None:
        import drjit as dr
        import mitsuba as mi

        self.light, self.eps = light, eps
        shape = mi.Mesh("occluders", len(mesh.vertices), len(mesh.faces))
        params = mi.traverse(shape)
        params["vertex_positions"] = mi.Float(mesh.vertices.ravel())
        params["faces"] = mi.UInt32(mesh.faces.astype(np.uint32).ravel())
        params.update()
        self.scene = mi.load_dict({"type": "scene", "occluders": shape})
        dr.eval(self.scene.ray_test(mi.Ray3f(mi.Point3f(0, 0, 0), mi.Vector3f(0, 0, 1))))   # BVH built now

    def classify(self, points, normals) -> np.ndarray:
        import drjit as dr
        import mitsuba as mi

        eps = mi.Float(self.eps)
        p = mi.Point3f(*(mi.Float(np.ascontiguousarray(points[:, i], np.float32)) for i in range(3)))
        n = None if normals is None else mi.Vector3f(*(mi.Float(np.ascontiguousarray(normals[:, i], np.float32))
                                                       for i in range(3)))
        start = p if n is None else p + eps * n
        point = isinstance(self.light, PointLight)
        if point:
            to_light = mi.Point3f(*(float(c) for c in self.light.position)) - start
            length = dr.norm(to_light)
            direction = to_light / length
            maxt = length - eps
        else:
            direction = mi.Vector3f(*(float(-c) for c in self.light.direction))
            maxt = mi.Float(np.inf)
        away = mi.Bool(False) if n is None else dr.dot(n, direction * (length if point else 1)) + (eps if point else 0) <= 0
        ray = mi.Ray3f(mi.Ray3f(start + eps * direction, direction), maxt)   # (o, d, x) would read x as a time
        hit = self.scene.ray_test(ray, active=~away)
        return (hit | away).numpy().astype(bool)


PEER = "embreex"  # the peer every method is compared with
PEERS = {PEER: EmbreePeer, "open3d": Open3DPeer, "mitsuba": MitsubaPeer}
