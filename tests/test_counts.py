"""Many lights: shadow_counts and shadow_matrix against per-light masks and Embree, locally and on a
2-worker Dask LocalCluster (also with a worker killed mid-run); bad input.

Scenes are made here (manifold3d CSG and primitives), not taken from ../shared.
"""

import os
import signal
import sys
import threading
import time

import numpy as np
import pytest
from manifold3d import Manifold

import shadowcl as sc
from conftest import PROJECT, SCENES
from shadowcl.methods import default_eps


def csg_scene() -> sc.Mesh:
    """A hollowed, rotated box and a sphere with a cylinder bored through it, over a ground slab."""
    hollow = (Manifold.cube([2.0, 1.6, 1.2], True) - Manifold.sphere(0.85, 48)).rotate([0, 30, 0]).translate([-1.2, 1.0, 0.3])
    bored = (Manifold.sphere(0.9, 48) - Manifold.cylinder(3.0, 0.35, 0.35, 32, True)).rotate([70, 0, 20]).translate([1.4, 1.3, -0.5])
    ground = Manifold.cube([9.0, 0.3, 9.0], True).translate([0, -0.15, 0])
    mesh = (hollow + bored + ground).to_mesh()
    return sc.Mesh(mesh.vert_properties[:, :3], mesh.tri_verts)


def receivers(rng, n: int):
    """Points on the ground (normals up) and in the air above it (random unit normals: bench/peers.py's
    Embree rays take unit normals)."""
    ground = np.column_stack([rng.uniform(-4, 4, n // 2), np.zeros(n // 2), rng.uniform(-4, 4, n // 2)])
    air = rng.uniform([-3, 0.1, -3], [3, 2.5, 3], (n - n // 2, 3))
    normals = np.concatenate([np.tile([0.0, 1.0, 0.0], (n // 2, 1)), rng.normal(size=(n - n // 2, 3))])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return np.concatenate([ground, air]), normals


def directional_lights(rng, count: int):
    """Lights from above at elevations 5-85 degrees, any azimuth."""
    elevation, azimuth = np.radians(rng.uniform(5, 85, count)), rng.uniform(0, 2 * np.pi, count)
    return [sc.DirectionalLight((-np.cos(e) * np.cos(a), -np.sin(e), -np.cos(e) * np.sin(a)))
            for e, a in zip(elevation, azimuth)]


@pytest.mark.parametrize("method, params, with_normals", [
    ("exact", {}, False), ("exact", {}, True), ("shadow_map", {"resolution": 512}, True),
    ("angular", {}, False), ("shadow_volume", {}, True)])
def test_counts_are_the_sum_of_the_masks(method, params, with_normals, rng):
    """Any method: counts = sum of that method's sc.shadow_mask, and each matrix row is its packed mask
    (exactly: the same calls on the same data). Point lights too. 1001 points: not a multiple of 8."""
    mesh = csg_scene()
    points, normals = receivers(rng, 1001)
    normals = normals if with_normals else None
    lights = [sc.PointLight((x, 6.0, z)) for x, z in rng.uniform(-3, 3, (3, 2))]
    masks = np.array([sc.shadow_mask(mesh, light, points, normals, method=method, **params) for light in lights])
    counts = sc.shadow_counts(mesh, lights, points, normals, method=method, batch=2, **params)
    assert counts.dtype == np.float64 and counts.shape == (1001,)
    np.testing.assert_array_equal(counts, masks.sum(axis=0))
    matrix = sc.shadow_matrix(mesh, lights, points, normals, method=method, batch=2, **params)
    assert matrix.dtype == np.uint8 and matrix.shape == (3, 126)
    np.testing.assert_array_equal(matrix, np.packbits(masks, axis=1))
    assert 0 < counts.mean() < 3, "some points shadowed, not all: the test can tell a wrong mask"


@pytest.mark.filterwarnings("ignore:voxel")   # points in the box far from the surface are lit, and it says so
def test_counts_of_the_voxel_method_on_a_subdivision_surface(rng):
    """The voxel method takes the scene (its subdivision surfaces), not a mesh, and refuses an eps:
    counts = sum of its masks."""
    scene = sc.Scene.load(SCENES / "subdivision" / "torus.toml")
    low, high = scene.bounds
    points = rng.uniform(low, high, (1001, 3))
    lights = [sc.PointLight((x, high[1] + 3, z)) for x, z in rng.uniform(-2, 2, (3, 2))]
    masks = np.array([sc.shadow_mask(scene, light, points, method="voxel", resolution=32) for light in lights])
    counts = sc.shadow_counts(scene, lights, points, method="voxel", resolution=32, batch=2)
    np.testing.assert_array_equal(counts, masks.sum(axis=0))
    assert 0 < counts.mean() < 3


def test_weights_sum_in_light_order_then_batches_in_pairs(rng):
    """Weighted: each batch sums its lights in order, the batches are summed in a fixed tree (3 batches:
    (b0 + b1) + b2), the order a cluster's run repeats; the sums are float, so the order shows."""
    mesh = csg_scene()
    points, normals = receivers(rng, 500)
    lights = directional_lights(rng, 7)
    weights = rng.uniform(0.1, 2.0, 7)
    masks = [sc.shadow_mask(mesh, light, points, normals) for light in lights]
    batches = []
    for lo in (0, 3, 6):
        part = np.zeros(500)
        for mask, weight in zip(masks[lo:lo + 3], weights[lo:lo + 3]):
            part[mask] += weight
        batches.append(part)
    expected = (batches[0] + batches[1]) + batches[2]
    np.testing.assert_array_equal(sc.shadow_counts(mesh, lights, points, normals, weights=weights, batch=3), expected)


@pytest.mark.parametrize("parts", [1, 2, 3, 5, 6, 7, 8, 13])
def test_pairwise_sum_is_the_level_by_level_tree(parts):
    """PairwiseSum fed one part at a time builds the tree that pairs parts level by level (an odd one
    carried up): written out as brackets."""
    from shadowcl.counts import PairwiseSum

    level = [str(i) for i in range(parts)]
    while len(level) > 1:
        level = [f"({a}+{b})" for a, b in zip(level[::2], level[1::2])] + level[len(level) // 2 * 2:]
    tree = PairwiseSum(lambda a, b: f"({a}+{b})")
    for i in range(parts):
        tree.add(str(i))
    assert tree.total() == level[0]


def test_receivers_are_framed_once_per_loop(rng, monkeypatch):
    """The loop frames its receivers once, not once per light (a float64 N x 3 copy each); the counts
    are still the per-light masks' sum (test_counts_are_the_sum_of_the_masks)."""
    from shadowcl.frame import Frame

    calls = []
    framed = Frame.receivers
    monkeypatch.setattr(Frame, "receivers", lambda self, receivers: calls.append(1) or framed(self, receivers))
    points, normals = receivers(rng, 500)
    sc.shadow_counts(csg_scene(), directional_lights(rng, 4), points, normals, batch=2)
    assert len(calls) == 1


def test_no_points():
    counts = sc.shadow_counts(csg_scene(), [sc.DirectionalLight((0, -1, 0))], np.zeros((0, 3)))
    assert counts.shape == (0,)
    assert sc.shadow_matrix(csg_scene(), [sc.DirectionalLight((0, -1, 0))], np.zeros((0, 3))).shape == (1, 0)


def embree_masks(mesh, lights, points, normals, eps):
    sys.path.insert(0, str(PROJECT / "bench"))
    import peers   # bench/peers.py: Embree (embreex) answering DESIGN.md's question

    scene = peers.build_scene(mesh.vertices, mesh.faces)
    return np.array([peers.shadow_mask(scene, points, normals, light, eps) for light in lights])


@pytest.fixture(scope="module")
def bar_case():
    """The issue's bar: 50 directional lights, 50,000 receivers on a scene made here, and Embree's masks."""
    pytest.importorskip("embreex")
    rng = np.random.default_rng(50)
    mesh = csg_scene()
    points, normals = receivers(rng, 50_000)
    lights = directional_lights(rng, 50)
    return mesh, lights, points, normals, embree_masks(mesh, lights, points, normals, default_eps(mesh.bounds))


def check_against_embree(counts, matrix, embree, n):
    """Each matrix row against Embree's mask of that light, and the counts against Embree's masks summed,
    each within the bar on its own (not through our matrix: counts = the masks' sum is checked above,
    test_counts_are_the_sum_of_the_masks, and would make this bound hold by construction)."""
    mine = np.unpackbits(matrix, axis=1, count=n).astype(bool)
    differ = np.count_nonzero(mine != embree, axis=1)
    # The bar: at most 2e-5 of the receivers differ per light (1 of 50,000), float32 Embree vs the exact method.
    assert differ.max() <= 2e-5 * n, f"receivers differing per light: {differ.tolist()}"
    # The same bar over the counts: in all, at most 2e-5 n per light of count between us and Embree.
    off = np.abs(counts - embree.sum(axis=0))
    assert off.sum() <= 2e-5 * n * len(embree), f"counts off Embree's by {off.sum()} in all"


def test_counts_match_embree_over_50_lights(bar_case):
    mesh, lights, points, normals, embree = bar_case
    counts = sc.shadow_counts(mesh, lights, points, normals)
    matrix = sc.shadow_matrix(mesh, lights, points, normals)
    check_against_embree(counts, matrix, embree, len(points))


# Dask LocalCluster ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def client():
    distributed = pytest.importorskip("dask.distributed")   # here: the tests above need no Dask
    from shadowcl.distributed import local_cluster

    with local_cluster(2, threads=1) as cluster, distributed.Client(cluster) as client:
        yield client


def worker_compute_units() -> int:
    from shadowcl.device import get_device
    return get_device().cl_device.max_compute_units


def worker_loops() -> int:
    from shadowcl import distributed
    return len(distributed._loops)


def test_cluster_run_equals_local_run_and_embree(bar_case, client):
    mesh, lights, points, normals, embree = bar_case
    weights = np.random.default_rng(1).uniform(0.1, 2.0, len(lights))    # float sums: their order shows
    local = sc.shadow_counts(mesh, lights, points, normals, batch=8, weights=weights)
    remote = sc.shadow_counts(mesh, lights, points, normals, batch=8, weights=weights, client=client)
    np.testing.assert_array_equal(remote, local)          # bit for bit: the same sums in the same order
    matrix = sc.shadow_matrix(mesh, lights, points, normals, batch=8, client=client.scheduler.address)
    check_against_embree(sc.shadow_counts(mesh, lights, points, normals, client=client), matrix, embree, len(points))
    # each worker's PoCL device has the 1 thread it was given, and no run's loop outlives its run
    assert client.run(worker_compute_units) == dict.fromkeys(client.run(os.getpid), 1)
    assert set(client.run(worker_loops).values()) == {0}


def test_worker_with_two_threads_runs_batches_one_at_a_time(rng, monkeypatch):
    """A worker of 2 Dask threads (a `dask worker`'s default is one per core) shares one loop between
    them: the counts are the local run's, twice in a row. The client makes no OpenCL device for a
    cluster run; a bad parameter value comes back from the worker as its named ValueError; the worker
    killed mid-run (the only holder of the scattered data) ends the run in a RuntimeError saying why."""
    distributed = pytest.importorskip("dask.distributed")
    from shadowcl.distributed import pocl_environment

    mesh = csg_scene()
    points, normals = receivers(rng, 20_000)
    lights = directional_lights(rng, 24)
    local = sc.shadow_counts(mesh, lights, points, normals, batch=1)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=True, dashboard_address=None,
                                  env=pocl_environment(1)) as cluster, distributed.Client(cluster) as client:
        monkeypatch.setattr("shadowcl.counts.get_device", lambda *args: pytest.fail("a device in the client"))
        for _ in range(2):
            np.testing.assert_array_equal(sc.shadow_counts(mesh, lights, points, normals, batch=1, client=client), local)
        with pytest.raises(ValueError, match="resolution"):
            sc.shadow_counts(mesh, lights[:2], points, method="shadow_map", resolution=0, client=client)
        # the only worker, which holds the scattered data, killed mid-run: a RuntimeError that says why
        [pid] = client.run(os.getpid).values()
        outcome = []

        def run():
            try:
                sc.shadow_counts(mesh, lights, points, normals, batch=1, client=client)
            except Exception as error:
                outcome.append(error)
        thread = threading.Thread(target=run)
        thread.start()
        while thread.is_alive() and not client.run_on_scheduler(lambda dask_scheduler: any(
                ts.state == "memory" for key, ts in dask_scheduler.tasks.items() if str(key).startswith("shadowcl-"))):
            time.sleep(0.05)
        os.kill(pid, signal.SIGKILL)
        thread.join(120)
        assert len(outcome) == 1 and isinstance(outcome[0], RuntimeError) and "2 or more workers" in str(outcome[0])
        client.wait_for_workers(1, timeout=60)    # the nanny's new worker: the cluster then closes at once


def test_worker_killed_mid_run_gives_the_same_counts(client, rng):
    """One batch per light; once a batch has finished, a worker process is killed (SIGKILL) while the
    run goes on: its batches rerun on the other worker, and the counts are the local ones."""
    mesh = csg_scene()
    points, normals = receivers(rng, 20_000)
    lights = directional_lights(rng, 40)
    local = sc.shadow_counts(mesh, lights, points, normals, batch=1)
    pids = client.run(os.getpid)
    result, killed_while_running = {}, []
    run = threading.Thread(target=lambda: result.update(
        counts=sc.shadow_counts(mesh, lights, points, normals, batch=1, client=client)))
    run.start()
    victim = sorted(pids)[0]
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and run.is_alive():
        done = client.run_on_scheduler(lambda dask_scheduler: sum(
            ts.state == "memory" for key, ts in dask_scheduler.tasks.items() if str(key).startswith("shadowcl-")))
        if done >= 2:
            os.kill(pids[victim], signal.SIGKILL)
            killed_while_running.append(run.is_alive())
            break
        time.sleep(0.05)
    run.join(120)
    assert killed_while_running == [True], "the worker was killed before the run ended"
    np.testing.assert_array_equal(result["counts"], local)
    client.wait_for_workers(2, timeout=60)    # the nanny restarts the worker for the next tests


def test_sun_hours_command_on_the_cluster(client, tmp_path):
    """shadowcl sun-hours --scheduler ADDR gives the local run's hours (and --workers 0 is refused)."""
    pytest.importorskip("pvlib")
    from shadowcl.cli import main

    scene_file = tmp_path / "tower.toml"
    scene_file.write_text('[[lights]]\ntype = "directional"\ndirection = [0, -1, 0]\n'
                          '[[objects]]\nname = "ground"\nbox = { size = [10, 1, 10], center = true }\n'
                          '[[objects]]\nname = "tower"\nbox = { size = [1, 3, 1] }\n'
                          "[[sensors]]\nobjects = ['ground', 'tower']\nspacing = 1.0\n")
    period = ["--lat", "52.5", "--lon", "13.4", "--start", "2026-09-01", "--end", "2026-09-02", "--step", "2h"]
    assert main(["sun-hours", str(scene_file), *period, "--out", str(tmp_path / "local.png")]) == 0
    assert main(["sun-hours", str(scene_file), *period, "--scheduler", client.scheduler.address,
                 "--out", str(tmp_path / "cluster.png")]) == 0
    hours = np.load(tmp_path / "local.npy")
    np.testing.assert_array_equal(np.load(tmp_path / "cluster.npy"), hours)
    assert 0 < hours.mean() < hours.max()
    assert main(["sun-hours", str(scene_file), *period, "--workers", "0", "--out", str(tmp_path / "x.png")]) == 2


# Bad input ---------------------------------------------------------------------------------------------------
LIGHT = sc.DirectionalLight((0, -1, 0))
BAD = [
    (lambda: sc.shadow_counts(csg_scene(), [], np.zeros((1, 3))), ValueError, "lights: expected at least one"),
    (lambda: sc.shadow_counts(csg_scene(), LIGHT, np.zeros((1, 3))), TypeError, "lights: .*single light"),
    (lambda: sc.shadow_counts(csg_scene(), [LIGHT, "sun"], np.zeros((1, 3))), TypeError, r"lights\[1\]"),
    (lambda: sc.shadow_counts(csg_scene(), [LIGHT, sc.PointLight((0, 5, 0))], np.zeros((1, 3))), ValueError,
     "lights: expected lights of one kind"),
    (lambda: sc.shadow_counts(csg_scene(), [LIGHT, LIGHT], np.zeros((1, 3)), weights=[1.0]), ValueError,
     r"weights: expected shape \(2,\)"),
    (lambda: sc.shadow_counts(csg_scene(), [LIGHT], np.zeros((1, 3)), weights=[np.nan]), ValueError, "weights: must be finite"),
    (lambda: sc.shadow_counts(csg_scene(), [LIGHT], np.zeros((1, 3)), weights=["a"]), TypeError, "weights"),
    (lambda: sc.shadow_counts(csg_scene(), [LIGHT], np.zeros((1, 2))), ValueError, "points"),
    (lambda: sc.shadow_counts(csg_scene(), [LIGHT], np.zeros((1, 3)), batch=0), ValueError, "batch"),
    (lambda: sc.shadow_counts(csg_scene(), [LIGHT], np.zeros((1, 3)), method="nope"), ValueError, "method"),
    (lambda: sc.shadow_counts(csg_scene(), [LIGHT], np.zeros((1, 3)), resolution_typo=3), TypeError, "resolution_typo"),
    (lambda: sc.shadow_counts(csg_scene(), [LIGHT], np.zeros((1, 3)), client=3), TypeError, "client"),
    (lambda: sc.shadow_matrix("mesh", [LIGHT], np.zeros((1, 3))), TypeError, "scene_or_mesh"),
]


@pytest.mark.parametrize("call, error, match", BAD, ids=[f"bad{i}" for i in range(len(BAD))])
def test_bad_input(call, error, match):
    with pytest.raises(error, match=match):
        call()
