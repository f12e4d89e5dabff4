"""Issue 14's red-team table rerun with other values: every class of the issue, on scenes made here,
through the public API, every method, with and without normals.

    python bench/redteam.py [--only CLASS ...] [--out DIR]

Scenes (none of them in ../shared or in tests/test_range.py): a tilted torus, a manifold3d box minus a
sphere and a cylinder, a thin tilted plate (1e-3 thick) over an open one-sided quad, each over a
ground quad, and a 200 k-triangle sphere; a closed room around a torus. Receivers: seeded points on
the ground and in the air round the occluders (random unit normals in the air, up on the ground).
Truth is the float64 brute force (``shadowcl.reference.exact``), judged by
:func:`shadowcl.testing.wrong_receivers` (the float32 band, the method's discretisation band, a light
used as directional beyond the method's reach). The voxel method (subdivision surfaces only) is judged
against itself at scale 1 and against the exact method on its tessellation, with the surfaces' normals
(it answers a point on its surfaces as with its outward normal).

Each case ends in one of: ``right`` (no receiver wrong outside the band), ``refused (ARG:)`` (a
ValueError/TypeError naming the argument; ``refused?`` when the message names none), ``WRONG n/N``
(silently wrong), ``CRASH`` (any other exception). Writes OUT/redteam.{json,md}.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import shadowcl as sc
from report import save
from shadowcl.methods import method_class
from shadowcl.testing import wrong_receivers

METHODS = ("exact", "shadow_map", "shadow_volume", "angular")
NAMED = re.compile(r"^(\S+: )|^[\w\[\].,'\" ]+: ")
RNG = np.random.default_rng(1414)
ODD = [np.array(d) / np.linalg.norm(d) for d in ((-0.61, 0.35, 0.71), (0.05, 1.0, -0.9), (0.93, 0.12, -0.4),
                                                  (-0.2, 0.6, -0.77))]


# ---- scenes -----------------------------------------------------------------------------------------

def with_ground(v, f, half):
    n = len(v)
    ground = np.array([[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]])
    return np.concatenate([v, ground]), np.concatenate([f, [[n, n + 2, n + 1], [n, n + 3, n + 2]]])


def rotation(ax, ay):
    cx, sx, cy, sy = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay)
    return np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]]) @ np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])


def torus():
    import trimesh
    t = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3, major_sections=48, minor_sections=20)
    return with_ground(t.vertices @ rotation(0.5, 0.3).T + [0.2, 1.3, -0.1], t.faces, 4.0)


def csg():
    import manifold3d as m3d
    solid = (m3d.Manifold.cube((2.0, 1.2, 1.5), center=True) - m3d.Manifold.sphere(0.8, 40).translate((0.6, 0.5, 0.1))
             - m3d.Manifold.cylinder(3.0, 0.25, 0.25, 24, True).translate((-0.5, 0.0, 0.0)))
    mesh = solid.translate((-0.2, 1.1, 0.3)).to_mesh()
    return with_ground(mesh.vert_properties[:, :3], mesh.tri_verts, 5.0)


def plates():
    import manifold3d as m3d
    thin = m3d.Manifold.cube((2.0, 1e-3, 1.4), center=True).to_mesh()
    v = thin.vert_properties[:, :3] @ rotation(0.35, 0.2).T + [0.1, 1.2, 0.0]
    quad = np.array([[-1.0, 0.6, -0.3], [0.4, 0.6, -0.3], [0.4, 0.6, 1.2], [-1.0, 0.6, 1.2]])   # open, one-sided
    n = len(v)
    return with_ground(np.concatenate([v, quad]), np.concatenate([thin.tri_verts, [[n, n + 1, n + 2], [n, n + 2, n + 3]]]),
                       3.5)


def big_sphere():
    import manifold3d as m3d
    mesh = m3d.Manifold.sphere(1.0, 632).translate((0.0, 1.2, 0.0)).to_mesh()
    return with_ground(mesh.vert_properties[:, :3], mesh.tri_verts, 3.0)


def room():
    """A closed 10 x 4 x 10 box room (its floor at y = 0) holding a torus."""
    import manifold3d as m3d
    import trimesh
    box = m3d.Manifold.cube((10.0, 4.0, 10.0), center=True).translate((0.0, 2.0, 0.0)).to_mesh()
    t = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3, major_sections=32, minor_sections=16)
    v = np.concatenate([box.vert_properties[:, :3], t.vertices @ rotation(1.2, 0.0).T + [1.0, 1.5, 0.5]])
    return v, np.concatenate([box.tri_verts, t.faces + len(box.vert_properties)])


SCENES = {"torus": torus, "csg": csg, "plates": plates}


def receivers(mesh: sc.Mesh, ground: int, air: int, half: float):
    """``ground`` points on y = 0 within ``half`` (normals up), ``air`` points in the occluders' box grown by
    half its size (random unit normals)."""
    lo, hi = mesh.bounds
    body = np.array([lo[0], 0.05, lo[2]]), np.array([hi[0], hi[1] * 1.3, hi[2]])
    g = np.c_[RNG.uniform(-half, half, ground), np.zeros(ground), RNG.uniform(-half, half, ground)]
    a = RNG.uniform(body[0], body[1], (air, 3))
    nrm = np.concatenate([np.tile([0.0, 1.0, 0.0], (ground, 1)), RNG.normal(size=(air, 3))])
    return np.concatenate([g, a]), nrm


# ---- running one case --------------------------------------------------------------------------------

ROWS: list[dict] = []


def outcome_of(call) -> tuple[str, object]:
    try:
        return "ok", call()
    except (ValueError, TypeError, FileNotFoundError) as error:
        message = str(error).split("\n")[0]
        return ("refused (" + message.split(":")[0][:40] + ":)" if NAMED.match(message) else "refused?"), message
    except Exception as error:   # noqa: BLE001: every other escape is a finding
        return "CRASH", f"{type(error).__name__}: {str(error)[:200]}"


def judge(cls: str, value: str, method: str, mesh, light, points, normals=None, eps=None, allowed=("light",)):
    """One public call judged against the brute force; a row of the table."""
    start = time.perf_counter()
    kind, result = outcome_of(lambda: sc.shadow_mask(mesh, light, points, normals, method=method, eps=eps))
    note = ""
    if kind == "ok":
        truth, wrong = wrong_receivers(method, mesh, light, points, result, normals, eps)
        kind = "right" if len(wrong) == 0 else f"WRONG {len(wrong)}/{len(points)}"
        note = f"{int(truth.sum())} shadowed" + (f"; e.g. {wrong[:3].tolist()}" if len(wrong) else "")
    else:
        note = result
        argument = kind[len("refused ("):-2] if kind.startswith("refused (") else None
        if argument is not None and argument not in allowed:
            kind += " UNEXPECTED"
    add(cls, value, method, "normals" if normals is not None else "none", kind, note, time.perf_counter() - start)


def add(cls, value, method, normals, kind, note, seconds=0.0):
    ROWS.append({"class": cls, "value": value, "method": method, "normals": normals, "result": kind,
                 "note": str(note)[:240], "s": round(seconds, 2)})
    print(f"{cls} | {value} | {method} | {normals} | {kind} | {str(note)[:160]}", flush=True)


def each_method(cls, value, mesh, light, points, normals, eps=None, allowed=("light",), methods=METHODS):
    for method in methods:
        for nrm in (None, normals):
            judge(cls, value, method, mesh, light, points, nrm, eps, allowed)


# ---- the numeric classes -------------------------------------------------------------------------------

def scale_and_offset():
    """Whole scenes scaled by 1e-9 .. 1e18 and moved up to 1e7 scene sizes along an odd direction."""
    for name, make in SCENES.items():
        v, f = make()
        base = sc.Mesh(v, f)
        points, normals = receivers(base, 150, 60, 3.0)
        size = float(np.linalg.norm(np.ptp(base.bounds, 0)))
        light = np.array([0.2, 1.3, -0.1]) + 2.5 * size * ODD[0]
        for s, sizes in ((1e-9, 0.0), (1e-9, 1e7), (3e-5, -2e6), (7.3, 1e7), (1e9, 5e5), (1e15, -1e7), (1e18, 1e7)):
            shift = sizes * size * s * np.array([0.6, -0.3, 0.74])
            mesh = sc.Mesh(v * s + shift, f)
            each_method("scale and offset", f"{name} x{s:g} +{sizes:g} sizes", mesh, sc.PointLight(light * s + shift),
                        points * s + shift, normals)


def distant_lights():
    """Point lights 3 .. 1e9 scene sizes away in odd directions (one grazing)."""
    for name in ("torus", "csg"):
        v, f = SCENES[name]()
        mesh = sc.Mesh(v, f)
        points, normals = receivers(mesh, 200, 60, 4.0)
        size = float(np.linalg.norm(np.ptp(np.concatenate([mesh.bounds, points]), axis=0)))
        for k, sizes in enumerate((3.0, 37.0, 1e3, 4e4, 1e5, 2.9e6, 1e8, 1e9)):
            direction = ODD[k % len(ODD)]
            each_method("distant point light", f"{name} {sizes:g} sizes along {np.round(direction, 2).tolist()}", mesh,
                        sc.PointLight(direction * sizes * size), points, normals)


def outside_float32():
    """Point lights beyond float32's range; directions with huge, tiny and subnormal components."""
    v, f = torus()
    mesh = sc.Mesh(v, f)
    points, normals = receivers(mesh, 200, 60, 4.0)
    for position in ((2e39, 7e38, -1e39), (-1e300, 1e301, 3e299), (0.0, 1e308, 0.0), (-3e38, 5e38, 3e38)):
        each_method("light outside float32", f"point {position}", mesh, sc.PointLight(position), points, normals)
    for direction in ((1e250, -3e250, 1e249), (-5e-324, -1e-323, 0.0), (1e308, -1e308, 1e308), (3e-310, -1e-309, 2e-310)):
        kind, light = outcome_of(lambda: sc.DirectionalLight(direction))
        if kind != "ok":
            add("direction overflow", f"{direction}", "-", "-", kind, light)
            continue
        exact = np.ldexp(np.asarray(direction), -math.frexp(float(np.abs(direction).max()))[1])   # exactly scaled to ~1
        unit = exact / np.linalg.norm(exact)
        fine = np.allclose(light.direction, unit, rtol=1e-12) and abs(np.linalg.norm(light.direction) - 1) < 1e-12
        add("direction overflow", f"{direction}.direction", "-", "-", "right" if fine else "WRONG",
            np.round(light.direction, 6).tolist())
        each_method("direction overflow", f"{direction}", mesh, light, points, normals)
    for bad in ((10 ** 40, -1, 0), (10 ** 400, -1, 0), (np.float16(1e4), 0, -1), ("1", 0, 0), (True, 0, -1), (1e-320j, 0, 1)):
        for maker in (sc.PointLight, sc.DirectionalLight):
            kind, note = outcome_of(lambda: maker(bad))
            kind = "accepted" if kind == "ok" else kind
            add("light outside float32", f"{maker.__name__}{bad!r}"[:48], "-", "-", kind, note)


def far_receivers():
    """20 receivers 3e3 .. 3e8 scene sizes away in random 3-D directions, 5 of them exactly behind the
    occluders from the light (shadowed at any distance)."""
    for name in ("torus", "csg", "plates"):
        v, f = SCENES[name]()
        mesh = sc.Mesh(v, f)
        points, normals = receivers(mesh, 200, 60, 4.0)
        size = float(np.linalg.norm(np.ptp(mesh.bounds, 0)))
        centre = 0.5 * (mesh.bounds[0] + mesh.bounds[1])
        for light in (sc.PointLight(centre + 3.1 * size * ODD[1]), sc.DirectionalLight(-ODD[3])):
            moved = points.copy()
            d = RNG.normal(size=(20, 3))
            moved[:20] = centre + d / np.linalg.norm(d, axis=1, keepdims=True) * size * 10 ** RNG.uniform(3.5, 8.5, (20, 1))
            towards = (centre - light.position) if isinstance(light, sc.PointLight) else light.direction
            towards = towards / np.linalg.norm(towards)
            moved[20:25] = centre + towards * size * np.array([30.0, 1e3, 1e5, 3e6, 1e8])[:, None]
            what = f"{name} {'point' if isinstance(light, sc.PointLight) else 'directional'}"
            each_method("far receivers", what, mesh, light, moved, normals, allowed=("light", "points"))


def touching_lights():
    """Lights 0 .. 1e-3 of the diagonal off a face's centre, an edge's midpoint, a vertex (outward)."""
    for name in ("torus", "csg", "plates"):
        v, f = SCENES[name]()
        mesh = sc.Mesh(v, f)
        points, normals = receivers(mesh, 200, 40, 3.5)
        size = float(np.linalg.norm(np.ptp(mesh.bounds, 0)))
        tri = mesh.triangles.astype(np.float64)
        for k in RNG.choice(len(tri) - 2, 2, replace=False):
            a, b, c = tri[k]
            n = np.cross(b - a, c - a)
            n /= np.linalg.norm(n)
            for where, base in (("face", (a + b + c) / 3), ("edge", (a + b) / 2), ("vertex", a)):
                for offset in (0.0, 1e-8, 1e-6, 1e-5, 1e-4, 3e-4, 1e-3):
                    light = sc.PointLight(base + offset * size * n)
                    for method in METHODS:
                        clearance = method_class(method).min_light_clearance
                        judge("light touching the occluder", f"{name} face {k} {where} +{offset:g}", method, mesh,
                              light, points, normals if offset in (0.0, 1e-5) else None,
                              allowed=("light",) if offset < 2 * clearance else ())


def receiving_planes():
    """The light in a plane of receivers: the ground (an occluder), beyond the ground quad, a wall of
    receivers that occludes nothing."""
    v, f = csg()
    mesh = sc.Mesh(v, f)
    points, normals = receivers(mesh, 300, 0, 5.0)
    each_method("light in a receiving plane", "csg: on the ground at a receiver", mesh, sc.PointLight(points[17]), points,
                normals)
    each_method("light in a receiving plane", "csg: ground plane, beyond the quad", mesh,
                sc.PointLight((7.5, 0.0, -1.3)), points, normals)
    wall = np.c_[np.full(300, -2.5), RNG.uniform(0, 3, 300), RNG.uniform(-3, 3, 300)]
    each_method("light in a receiving plane", "csg: a wall of receivers (no occluder)", mesh, sc.PointLight(wall[5]), wall,
                np.tile([1.0, 0.0, 0.0], (300, 1)))
    each_method("light in a receiving plane", "csg: wall plane, off the wall", mesh, sc.PointLight((-2.5, 1.7, 4.4)), wall,
                np.tile([1.0, 0.0, 0.0], (300, 1)))


def inside_solids():
    """Lights inside a torus's tube, inside the CSG solid, inside a closed room (receivers inside and out)."""
    v, f = torus()
    mesh = sc.Mesh(v, f)
    points, normals = receivers(mesh, 200, 60, 4.0)
    ring = np.array([1.0, 0.0, 0.0]) @ rotation(0.5, 0.3).T + [0.2, 1.3, -0.1]
    each_method("light inside a solid", "in the torus's tube", mesh, sc.PointLight(ring), points, normals)
    v, f = csg()
    mesh = sc.Mesh(v, f)
    points, normals = receivers(mesh, 200, 60, 5.0)
    each_method("light inside a solid", "in the csg solid's corner", mesh, sc.PointLight((-1.0, 0.7, 0.85)), points, normals)
    v, f = room()
    mesh = sc.Mesh(v, f)
    inside = np.c_[RNG.uniform(-4.9, 4.9, 250), np.zeros(250), RNG.uniform(-4.9, 4.9, 250)]
    air = RNG.uniform([-4.9, 0.1, -4.9], [4.9, 3.9, 4.9], (60, 3))
    outside = RNG.uniform([-20, -5, -20], [20, 10, 20], (60, 3))
    outside = outside[np.any(np.abs(outside - [0, 2, 0]) > [5.5, 2.5, 5.5], axis=1)]
    points = np.concatenate([inside, air, outside])
    normals = np.concatenate([np.tile([0.0, 1.0, 0.0], (250, 1)), RNG.normal(size=(len(points) - 250, 3))])
    for where in ((-3.0, 3.2, 2.0), (1.0, 1.5, 0.5), (4.99, 3.99, -4.99)):
        each_method("light inside a room", f"room with a torus, light {where}", mesh, sc.PointLight(where), points, normals)


def eps_extremes():
    """eps from 0 to 1e30 (and bad values)."""
    v, f = torus()
    mesh = sc.Mesh(v, f)
    points, normals = receivers(mesh, 200, 60, 4.0)
    size = float(np.linalg.norm(np.ptp(mesh.bounds, 0)))
    light = sc.PointLight(np.array([0.2, 1.3, -0.1]) + 2.0 * size * ODD[1])
    for eps in (0.0, 1e-30, 1e-12 * size, 0.3 * size, 1e6 * size, 1e30):
        each_method("eps", f"eps={eps:g}", mesh, light, points, normals, eps=eps, allowed=("eps",))
    for eps in (-1.0, float("nan"), float("inf"), "1", np.float32(1e-3), True, 1e300):
        for method in METHODS + ("voxel",):
            kind, note = outcome_of(lambda: sc.prepare(mesh, light, method, eps=eps))
            add("eps", f"eps={eps!r}", method, "-", "right (accepted)" if kind == "ok" else kind,
                "" if kind == "ok" else note)


def huge_mesh():
    """A 200 k-triangle sphere over a ground: scaled, offset, distant and touching lights."""
    v, f = big_sphere()
    mesh = sc.Mesh(v, f)
    points, normals = receivers(mesh, 150, 40, 3.0)
    size = float(np.linalg.norm(np.ptp(mesh.bounds, 0)))
    add("200 k triangles", "triangles", "-", "-", str(len(f)), "")
    each_method("200 k triangles", "light at 2 sizes", mesh, sc.PointLight((0.0, 1.2, 0.0) + 2 * size * ODD[2]), points, normals)
    s, shift = 1e-7, 3e5 * size * 1e-7
    each_method("200 k triangles", "x1e-7 +3e5 sizes", sc.Mesh(v * s + shift, f),
                sc.PointLight(((0.0, 1.2, 0.0) + 2 * size * ODD[2]) * s + shift), points * s + shift, normals)
    each_method("200 k triangles", "light at 5e6 sizes", mesh, sc.PointLight(ODD[3] * 5e6 * size), points, normals)
    top = v[np.argmax(v[:, 1])]
    each_method("200 k triangles", "light 3e-4 above the top vertex", mesh, sc.PointLight(top + [0, 3e-4 * size, 0]),
                points, normals)


NUMERIC = {"scale": scale_and_offset, "distant": distant_lights, "float32": outside_float32, "far": far_receivers,
           "touching": touching_lights, "planes": receiving_planes, "inside": inside_solids, "eps": eps_extremes,
           "huge": huge_mesh}


def voxel_method():
    """The voxel method (subdivision surfaces only) on scenes/subdivision/torus.toml and cube.toml moved
    by 1e-9 .. 1e18 and up to 1e7 sizes, lit 3 .. 1e9 sizes away and 1e-6 off its surface, eps extremes:
    its mask against its own at scale 1 (scale invariance) and against exact on the same tessellation."""
    project = Path(__file__).resolve().parents[1]
    for name in ("torus", "cube"):
        base = sc.Scene.load(project / "scenes" / "subdivision" / f"{name}.toml")
        ground = np.c_[RNG.uniform(-3.5, 3.5, 300), np.zeros(300), RNG.uniform(-3.5, 3.5, 300)]
        # receivers on the ground and on the object's tessellation, with their normals (up; outward, the
        # vertices' summed face normals): the voxel method answers a point on its surfaces as with its
        # surface normal, so exact is asked with them (without: an inside light lights them from inside)
        tessellated = base.objects[1][1]
        tri = tessellated.vertices[tessellated.faces].astype(np.float64)
        vertex_normals = np.zeros((len(tessellated.vertices), 3))
        np.add.at(vertex_normals, tessellated.faces.ravel(), np.repeat(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), 3, axis=0))
        pick = RNG.choice(len(tessellated.vertices), 100, replace=False)
        points = np.concatenate([ground, tessellated.vertices[pick].astype(np.float64)])
        normals = np.concatenate([np.tile([0.0, 1.0, 0.0], (len(ground), 1)), vertex_normals[pick]])
        size = float(np.linalg.norm(np.ptp(base.bounds, 0)))
        centre = 0.5 * (base.bounds[0] + base.bounds[1])

        def moved(s, shift, light):
            matrix = np.diag([s, s, s, 1.0])
            matrix[:3, 3] = shift
            return sc.Scene([(n, surface.transformed(matrix)) for n, surface in base.surfaces], [light])

        def run(what, s, shift, light, pts, reference=None, eps=None):
            scene = moved(s, shift, light)
            kind, mask = outcome_of(lambda: sc.shadow_mask(scene, light, pts, method="voxel", eps=eps))
            if kind != "ok":
                add("voxel", f"{name} {what}", "voxel", "none", kind, mask)
                return None
            exact = sc.shadow_mask(scene, light, pts, normals, method="exact", eps=eps)
            off = float(np.mean(mask != exact))
            note = f"differs from exact on {100 * off:.2f} %"
            bad = off > 0.03
            if reference is not None:
                changed = int(np.count_nonzero(mask != reference))
                note += f", from scale 1 on {changed}"
                bad |= changed > 0.01 * len(pts)
            add("voxel", f"{name} {what}", "voxel", "none", "WRONG" if bad else "right", note)
            return mask

        light = sc.PointLight(centre + 2.5 * size * ODD[1])
        reference = run("x1", 1.0, np.zeros(3), light, points)
        for s, sizes in ((1e-9, 0.0), (1e-9, 1e7), (3e-5, -2e6), (3e-5, 40.0), (7.3, 1e7), (7.3, -300.0), (1e6, 0.0),
                         (1e9, 5e5), (1e15, -1e7), (1e18, 1e7)):
            shift = sizes * size * s * np.array([0.6, -0.3, 0.74])
            run(f"x{s:g} +{sizes:g} sizes", s, shift, sc.PointLight(light.position * s + shift), points * s + shift, reference)
        for sizes in (3.0, 1e3, 1e5, 1e9):
            run(f"light at {sizes:g} sizes", 1.0, np.zeros(3), sc.PointLight(centre + ODD[0] * sizes * size), points)
        top = tessellated.vertices[np.argmax(tessellated.vertices[:, 1])].astype(np.float64)
        run("light 1e-6 above the top", 1.0, np.zeros(3), sc.PointLight(top + [0, 1e-6 * size, 0]), points)
        run("light inside the object", 1.0, np.zeros(3), sc.PointLight(base.surfaces[1][1].vertices.mean(0)), points)
        for eps in (0.0, 1e-12, 0.3 * size):
            run(f"eps={eps:g}", 1.0, np.zeros(3), light, points, eps=eps)


# ---- hostile inputs -------------------------------------------------------------------------------------

def expect_named(cls, value, call, what="named error", path=None):
    """A call that must give a ValueError/TypeError naming its argument (or ``path``)."""
    kind, note = outcome_of(call)
    if kind == "ok":
        add(cls, value, "-", "-", "accepted", repr(note)[:120])
        return note
    if kind.startswith("refused") and path is not None and str(path) not in str(note):
        kind += " (file not named)"
    add(cls, value, "-", "-", kind, note)
    return None


def mesh_files(tmp: Path):
    """Hostile OBJ / PLY / STL / OFF files not in tests/test_fuzz_inputs.py."""
    tri = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]
    stl_facet = struct.pack("<12fH", 0, 0, 1, *[c for p in tri for c in p], 0)
    ply_head = "ply\nformat {fmt} 1.0\nelement vertex {nv}\nproperty {t} x\nproperty {t} y\nproperty {t} z\n" \
               "element face {nf}\nproperty list {lt} {it} vertex_indices\nend_header\n"
    cases = {
        "utf16.obj": "\ufeffv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".encode("utf-16"),
        "nul.obj": b"v 0 0 0\nv 1 0\x00 0\nv 0 1 0\nf 1 2 3\n",
        "cr_only.obj": b"v 0 0 0\rv 1 0 0\rv 0 1 0\rf 1 2 3\r",
        "forward.obj": b"f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n",
        "neg_first.obj": b"f -1 -2 -3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n",
        "above_f32.obj": b"v 0 0 0\nv 3.5e38 0 0\nv 0 1 0\nf 1 2 3\n",
        "subnormal.obj": b"v 0 0 0\nv 1e-45 0 0\nv 0 1e-44 0\nf 1 2 3\n",
        "two_corners.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n",
        "only_comments.obj": b"# nothing\n# at all\n",
        "empty.obj": b"",
        "huge_polygon.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf " + b" ".join([b"1", b"2", b"3"] * 30000) + b"\n",
        "index_overflow.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 18446744073709551617\n",
        "slash_only.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf / / /\n",
        "binary_solid_header.stl": b"solid trap" + b" " * 70 + struct.pack("<I", 1) + stl_facet,
        "binary_zero.stl": b"\0" * 80 + struct.pack("<I", 0),
        "binary_nan.stl": b"\0" * 80 + struct.pack("<I", 1) + struct.pack("<12fH", 0, 0, 1, 0, 0, 0, float("nan"), 0, 0, 0, 1, 0, 0),
        "binary_short.stl": b"\0" * 83,
        "binary_extra.stl": b"\0" * 80 + struct.pack("<I", 1) + stl_facet + b"junk",
        "ascii_no_end.stl": b"solid a\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n",
        "ascii_4_vertices.stl": b"solid a\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nvertex 1 1 0\nendloop\nendfacet\nendsolid\n",
        "coff.off": b"COFF\n3 1 0\n0 0 0 1 1 1 1\n1 0 0 1 1 1 1\n0 1 0 1 1 1 1\n3 0 1 2\n",
        "one_line.off": b"OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "comment.off": b"OFF\n# made by hand\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "binary.off": b"OFF BINARY\n" + struct.pack(">iii", 3, 1, 0) + struct.pack(">9f", 0, 0, 0, 1, 0, 0, 0, 1, 0),
        "size2.off": b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n",
        "double.ply": (ply_head.format(fmt="binary_little_endian", nv=3, t="double", nf=1, lt="uchar", it="int").encode()
                       + struct.pack("<9d", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<B3i", 3, 0, 1, 2)),
        "uint_max.ply": (ply_head.format(fmt="binary_little_endian", nv=3, t="float", nf=1, lt="uchar", it="uint").encode()
                         + struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<B3I", 3, 0, 1, 2 ** 32 - 1)),
        "list255.ply": (ply_head.format(fmt="binary_little_endian", nv=3, t="float", nf=1, lt="uchar", it="int").encode()
                        + struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<B3i", 255, 0, 1, 2)),
        "version2.ply": ply_head.format(fmt="ascii", nv=3, t="float", nf=1, lt="uchar", it="int").replace("1.0", "2.0").encode()
                        + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "no_end_header.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n",
        "negative_count.ply": ply_head.format(fmt="ascii", nv=-1, t="float", nf=1, lt="uchar", it="int").encode(),
        "float128.ply": ply_head.format(fmt="ascii", nv=3, t="float128", nf=1, lt="uchar", it="int").encode()
                        + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "crlf.ply": ply_head.format(fmt="ascii", nv=3, t="float", nf=1, lt="uchar", it="int").replace("\n", "\r\n").encode()
                    + b"0 0 0\r\n1 0 0\r\n0 1 0\r\n3 0 1 2\r\n",
        "edge_after.ply": ply_head.format(fmt="ascii", nv=3, t="float", nf=1, lt="uchar", it="int").replace(
            "end_header", "element edge 1\nproperty int a\nproperty int b\nend_header").encode()
                          + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n0 1\n",
        "no_faces.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                        b"end_header\n0 0 0\n1 0 0\n0 1 0\n",
        "upper.OBJ": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        "mesh.xyz": b"0 0 0\n",
        "noext": b"v 0 0 0\n",
    }
    for name, data in cases.items():
        path = tmp / name
        path.write_bytes(data)
        expect_named("mesh files", name, lambda: sc.Mesh.load(path), path=path)
    (tmp / "folder.obj").mkdir(exist_ok=True)
    for name, arg in (("a folder named .obj", tmp / "folder.obj"), ("missing file", tmp / "missing.obj"),
                      ("None", None), ("an int", 3), ("bytes path", os.fsencode(tmp / "upper.OBJ"))):
        expect_named("mesh files", name, lambda: sc.Mesh.load(arg))


def scene_text(tmp: Path, name: str, objects: str, extra: str = "") -> Path:
    path = tmp / name
    path.write_text('[[lights]]\ntype = "point"\nposition = [0, 8, 0]\n' + extra + objects)
    return path


def scene_sizes(tmp: Path):
    """Primitive sizes past the bounds, many primitives, tessellations, render and method sizes."""
    for label, objects in (
            ("sphere segments 2049", "[[objects]]\nsphere = { segments = 2049 }\n"),
            ("sphere segments 2**31", "[[objects]]\nsphere = { segments = 2147483648 }\n"),
            ("sphere segments -4", "[[objects]]\nsphere = { segments = -4 }\n"),
            ("sphere segments 3.7", "[[objects]]\nsphere = { segments = 3.7 }\n"),
            ("sphere radius 1e39", "[[objects]]\nsphere = { radius = 1e39 }\n"),
            ("sphere radius 0", "[[objects]]\nsphere = { radius = 0 }\n"),
            ("cylinder segments 524290", "[[objects]]\ncylinder = { segments = 524290 }\n"),
            ("5 spheres of 2048 (10 M triangles)", "[[objects]]\nsphere = { segments = 2048 }\n" * 5),
            ("one union of 5 spheres of 2048", "[[objects]]\nunion = [" + ", ".join(["{ sphere = { segments = 2048 } }"] * 5) + "]\n"),
            ("tessellation 2**21 + 1", '[[objects]]\ntessellation = 2097153\nsubdivision = { vertices = [[0,0,0],[1,0,0],[1,0,1],[0,0,1]], faces = [[0,1,2,3]] }\n'),
            ("tessellation 1e9", '[[objects]]\ntessellation = 1000000000\nsubdivision = { vertices = [[0,0,0],[1,0,0],[1,0,1],[0,0,1]], faces = [[0,1,2,3]] }\n'),
            ("box size 1e39", "[[objects]]\nbox = { size = 1e39 }\n"),
            ("scale 1e30 of a sphere", "[[objects]]\nsphere = { segments = 8 }\nscale = 1e30\n"),
            ("scale 0", "[[objects]]\nsphere = { segments = 8 }\nscale = 0\n"),
            ("render 16385 wide", "[render]\nwidth = 16385\nheight = 10\n[[objects]]\nsphere = { segments = 8 }\n")):
        path = scene_text(tmp, "sizes.toml", objects)
        expect_named("scene sizes", label, lambda: sc.Scene.load(path), path=path)
    scene = sc.Scene.load(scene_text(tmp, "small.toml", "[[objects]]\nsphere = { segments = 16 }\n"))
    for width, height in ((16384, 16384), (12000, 12000), (10 ** 6, 1), (0, 10), (-5, 10), (2.5, 10), (True, 10),
                          (np.int64(40), np.uint8(30)), ("64", 48)):
        expect_named("render size", f"{width!r} x {height!r}", lambda: sc.render(scene, "exact", width, height))
    mesh, light = scene.mesh, scene.light
    points = np.zeros((4, 3))
    for method, params in (("shadow_map", {"resolution": 1 << 17}), ("shadow_map", {"resolution": 1e4}),
                           ("angular", {"resolution": 10 ** 9}), ("exact", {"resolution": 1 << 20}),
                           ("exact", {"initial_capacity": 2 ** 40}), ("voxel", {"resolution": 1025}),
                           ("voxel", {"connectivity": np.int64(26)}), ("voxel", {"connectivity": 26.0}),
                           ("shadow_map", {"resolution": True}), ("exact", {"chunk": 0})):
        expect_named("method sizes", f"{method} {params}", lambda: sc.shadow_mask(mesh, light, points, method=method, **params))


def deep_csg(tmp: Path):
    light = '[[lights]]\ntype = "point"\nposition = [0, 5, 0]\n'
    for depth in (65, 5000, 100000):
        shape = "{ sphere = { segments = 4 } }"
        for _ in range(depth - 1):
            shape = f"{{ difference = [{shape}] }}"
        path = tmp / f"inline{depth}.toml"
        path.write_text(light + f"[[objects]]\nintersection = [{shape}]\n")
        expect_named("deep CSG", f"inline difference/intersection {depth} deep", lambda: sc.Scene.load(path), path=path)
    for depth in (65, 3000):
        keys = ["objects"] + ["difference"] * depth
        path = tmp / f"tables{depth}.toml"
        path.write_text(light + "".join(f"[[{'.'.join(keys[:i + 1])}]]\n" for i in range(depth + 1)) + "box = {}\n")
        expect_named("deep CSG", f"array tables {depth} deep", lambda: sc.Scene.load(path), path=path)
    path = tmp / "wide.toml"
    path.write_text(light + "[[objects]]\nunion = [" + ", ".join(f"{{ sphere = {{ segments = 4 }}, translate = [{i}, 0, 0] }}"
                                                                 for i in range(3000)) + "]\n")
    start = time.perf_counter()
    scene = expect_named("deep CSG", "a union of 3000 spheres", lambda: sc.Scene.load(path), path=path)
    if scene is not None:
        ROWS[-1]["note"] += f" in {time.perf_counter() - start:.1f} s"
    path = tmp / "empty.toml"
    path.write_text(light + "[[objects]]\ndifference = [{ box = {} }, { box = { size = 2, center = true } }]\n")
    expect_named("deep CSG", "a difference that is empty", lambda: sc.Scene.load(path), path=path)


def cli(tmp: Path):
    """The command line misused: every error one line on stderr, exit code 2, no traceback."""
    exe = Path(sys.executable).parent / "shadowcl"
    small = scene_text(tmp, "cli.toml", "[[objects]]\nsphere = { segments = 8 }\n", "[render]\nwidth = 32\nheight = 24\n")
    (tmp / "a_file").write_text("x")
    for args in (["render", str(tmp / "missing.toml")], ["render", str(tmp)], ["render", str(small), "--out", "/proc/1/x.png"],
                 ["render", str(small), "--out", str(tmp / "a_file" / "x.png")], ["render", str(small), "--out", "/"],
                 ["render", str(small), "--size", "0x5"], ["render", str(small), "--size", "99999999x99999999"],
                 ["render", str(small), "--method", "nope"], ["render", str(small), "--device", "99:99"],
                 ["render", str(small), "--param", "resolution=-3", "--method", "shadow_map"],
                 ["render", str(small), "--param", "bogus=1"], ["render", str(small), "--param", "=1"],
                 ["render", str(tmp / "deep.toml")], ["sun-hours", str(small)],
                 ["sun-hours", "--start", "2026-13-01"], ["sun-hours", "--step", "0min"], ["sun-hours", "--step", "-1h"],
                 ["render", str(small), "--out", str(tmp / "out.txt")], []):
        if args and args[-1].endswith("deep.toml"):
            (tmp / "deep.toml").write_text("[[lights]]\ntype = 'point'\nposition = [0, 5, 0]\n[[objects]]\nunion = "
                                           + "[" * 400 + "{ box = {} }" + "]" * 400 + "\n")
        try:
            done = subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=120, cwd=tmp)
        except subprocess.TimeoutExpired:
            add("CLI", " ".join(args), "-", "-", "CRASH", "timeout 120 s")
            continue
        err = done.stderr.strip()
        lines = [line for line in err.splitlines() if line.strip()]
        ok = done.returncode == 0
        clean = done.returncode == 2 and len(lines) == 1 and "Traceback" not in err
        add("CLI", " ".join(a.replace(str(tmp), "TMP") for a in args) or "(nothing)", "-", "-",
            "ran (exit 0)" if ok else ("one line, exit 2" if clean else f"CRASH exit {done.returncode}, {len(lines)} lines"),
            (lines[-1] if lines else done.stdout.strip()[-120:]).replace(str(tmp), "TMP"))


def aliasing_and_messages(tmp: Path):
    v, f = torus()
    vv, ff = v.copy(), f.astype(np.int32)
    mesh = sc.Mesh(vv, ff)
    before = mesh.vertices.copy()
    vv[0] = 99.0
    ff[0] = 0
    add("aliasing", "Mesh(v, f) then caller edits v, f", "-", "-",
        "right" if np.array_equal(mesh.vertices, before) and vv.flags.writeable and ff.flags.writeable else "WRONG", "")
    view = np.asfortranarray(v)[::1]
    m2 = sc.Mesh(view[:, :], f[::-1][::-1])
    view[0] = -5.0
    add("aliasing", "Mesh on a Fortran-order view then caller edits it", "-", "-",
        "right" if not np.any(m2.vertices == -5.0) else "WRONG", "")
    p = np.array([0.0, 5.0, 0.0])
    light = sc.PointLight(p)
    p[1] = -5.0
    add("aliasing", "PointLight(p) then p edited", "-", "-", "right" if light.position[1] == 5.0 else "WRONG", "")
    d = np.array([0.0, -1.0, 0.0])
    dl = sc.DirectionalLight(d)
    d[1] = 1.0
    add("aliasing", "DirectionalLight(d) then d edited", "-", "-", "right" if dl.direction[1] == -1.0 else "WRONG", "")
    box = np.array([[-4.0, 0.0, -4.0], [4.0, 3.0, 4.0]])
    shadows = sc.prepare(mesh, light, "shadow_map", bounds=box)
    points = np.c_[RNG.uniform(-4, 4, 300), np.zeros(300), RNG.uniform(-4, 4, 300)]
    first = shadows.mask(points)
    box[:] = 0.0
    points_copy = points.copy()
    again = shadows.mask(points)
    points[:, 0] += 1.0
    moved = shadows.mask(points)
    truth = sc.shadow_mask(mesh, light, points, method="exact")
    add("aliasing", "prepare(bounds=box) then box zeroed; points edited in place between queries", "-", "-",
        "right" if np.array_equal(first, again) and np.array_equal(shadows.bounds[0], [-4, 0, -4])
        and np.mean(moved != truth) < 0.01 and np.array_equal(points_copy[:, 1], points[:, 1]) else "WRONG",
        f"moved points: {int(np.count_nonzero(moved != truth))} differ from exact")
    for label, call in (("Scene.load(None)", lambda: sc.Scene.load(None)), ("Scene.load(42)", lambda: sc.Scene.load(42)),
                        ("Scene.load(a folder)", lambda: sc.Scene.load(tmp)),
                        ("Scene.load(a binary file)", lambda: (tmp / "bin.toml").write_bytes(b"\xff\xfe\x00") and sc.Scene.load(tmp / "bin.toml")),
                        ("shadow_mask light=None", lambda: sc.shadow_mask(mesh, None, points)),
                        ("shadow_mask light=(0,5,0)", lambda: sc.shadow_mask(mesh, (0, 5, 0), points)),
                        ("method=None", lambda: sc.shadow_mask(mesh, light, points, method=None)),
                        ("method='EXACT'", lambda: sc.shadow_mask(mesh, light, points, method="EXACT")),
                        ("points (3,)", lambda: sc.shadow_mask(mesh, light, np.zeros(3))),
                        ("points object dtype", lambda: sc.shadow_mask(mesh, light, np.array([[1, 2, "3"]], dtype=object))),
                        ("points complex", lambda: sc.shadow_mask(mesh, light, np.zeros((2, 3), complex))),
                        ("normals (N, 2)", lambda: sc.shadow_mask(mesh, light, points, np.ones((300, 2)))),
                        ("normals 1e-300", lambda: sc.shadow_mask(mesh, light, points, np.full((300, 3), 1e-300))),
                        ("normals 1e300", lambda: sc.shadow_mask(mesh, light, points, np.full((300, 3), 1e300))),
                        ("bounds reversed", lambda: sc.prepare(mesh, light, bounds=[[1, 1, 1], [0, 0, 0]])),
                        ("bounds nan", lambda: sc.prepare(mesh, light, bounds=[[np.nan, 0, 0], [1, 1, 1]])),
                        ("Mesh faces float", lambda: sc.Mesh(v, f.astype(float) + 0.5)),
                        ("Mesh faces uint64 2**63", lambda: sc.Mesh(v, np.full((1, 3), 2 ** 63, np.uint64))),
                        ("Mesh vertices float16 inf", lambda: sc.Mesh(np.full((3, 3), np.inf, np.float16), [[0, 1, 2]])),
                        ("Mesh vertices 1e-40 (subnormal scene)", lambda: sc.shadow_mask(sc.Mesh(v * 1e-40, f), light, points * 1e-40)),
                        ):
        expect_named("messages", label, call)


NUMERIC["voxel"] = voxel_method
HOSTILE = {"files": mesh_files, "sizes": scene_sizes, "csg": deep_csg, "cli": cli,
           "aliasing": aliasing_and_messages}


def markdown(rows) -> str:
    lines = ["# Red team of issue 14, rerun with other values (bench/redteam.py)", "",
             f"{len(rows)} cases. Results: `right` (no receiver wrong outside the method's band against the float64 "
             "brute force), `refused (ARG:)` (an error naming the argument), `WRONG n/N`, `CRASH`. "
             "Only rows that are not `right` are listed in full; the summary counts every row.", "",
             "## Summary per class and method", "", "| class | method | results |", "|---|---|---|"]
    summary: dict = {}
    for r in rows:
        key = (r["class"], r["method"])
        summary.setdefault(key, {})
        summary[key][r["result"]] = summary[key].get(r["result"], 0) + 1
    for (cls, method), counts in summary.items():
        lines.append(f"| {cls} | {method} | " + ", ".join(f"{k} x{n}" for k, n in sorted(counts.items())) + " |")
    lines += ["", "## Every case that is not `right`", "", "| class | value | method | normals | result | note |",
              "|---|---|---|---|---|---|"]
    for r in rows:
        if r["result"] != "right":
            note = r["note"].replace("|", "/").replace("\n", " ")
            lines.append(f"| {r['class']} | {r['value']} | {r['method']} | {r['normals']} | {r['result']} | {note} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", choices=sorted({**NUMERIC, **HOSTILE}), help="classes to run (default all)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args(argv)
    chosen = args.only or list({**NUMERIC, **HOSTILE})
    load = os.getloadavg()
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        for name in chosen:
            if name in NUMERIC:
                NUMERIC[name]()
            else:
                HOSTILE[name](Path(folder))
    for row in ROWS:   # the temporary folder's name changes from run to run
        for key in ("result", "note", "value"):
            row[key] = row[key].replace(folder, "TMP")
    stem = "redteam" if not args.only else "redteam-" + "-".join(args.only)
    doc = {"load": load, "seconds": time.perf_counter() - start, "rows": ROWS}
    save(args.out, stem, doc, markdown(ROWS) + f"\nLoad average at the start {load[0]:.1f}; {doc['seconds']:.0f} s.\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
