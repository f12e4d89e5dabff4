"""Smoke test of the bench harness (bench/) on a tiny scene: receivers, the Embree peer, rows, reports.

The harness is a bench extra (embreex, matplotlib): without them this module is skipped.
"""

import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import PROJECT

pytest.importorskip("embreex")
pytest.importorskip("matplotlib")
sys.path.insert(0, str(PROJECT / "bench"))

import peers  # noqa: E402
import receivers as rx  # noqa: E402
import report  # noqa: E402
import run  # noqa: E402
import timing  # noqa: E402
from shadowcl import Mesh  # noqa: E402
from shadowcl.frame import frame_for  # noqa: E402
from shadowcl.methods import METHODS, Method, default_eps  # noqa: E402

# A unit cube standing on y = 0, wound inwards on purpose: the scene must turn it outwards.
CUBE_VERTICES = [(x, y, z) for x in (-0.5, 0.5) for y in (0.0, 1.0) for z in (-0.5, 0.5)]
CUBE_FACES_OUTWARD = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
                      (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
CUBE_INWARD = Mesh(CUBE_VERTICES, np.array(CUBE_FACES_OUTWARD)[:, ::-1])
COUNTS = {"ground": 3000, "model": 1000}


class AllLit(Method):
    """Stand-in method, registered by the harness test only: nothing is in shadow. It keeps the receiver
    boxes it was prepared for, so the test can see that the bench went through the public calls."""

    name = "all_lit"
    parameters = {"label": ("a", "a dummy parameter, to exercise the sweep")}
    prepared_bounds: list = []

    def prepare(self, occluders, light, receiver_bounds, eps):
        self.prepared_bounds.append(np.array(receiver_bounds))
        self.stats = {"device_bytes": 2**20}

    def classify(self, points, normals=None):
        return np.zeros(len(points), bool)


def brute_force_mask(mesh, light, points, normals, eps):
    """DESIGN.md's mask in float64 by testing every triangle (Moller-Trumbore), for small scenes."""
    start = points + eps * normals
    to_light = light.position - start
    length = np.linalg.norm(to_light, axis=1)
    d = to_light / length[:, None]
    a, b, c = (mesh.triangles[:, i][None] for i in range(3))
    e1, e2 = b - a, c - a
    p = np.cross(d[:, None], e2)
    det = np.einsum("nfi,nfi->nf", e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = start[:, None] - a
        u = np.einsum("nfi,nfi->nf", s, p) / det
        q = np.cross(s, e1)
        v = np.einsum("ni,nfi->nf", d, q) / det
        t = np.einsum("nfi,nfi->nf", e2, q) / det
    hit = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > eps) & (t < length[:, None])
    away = np.einsum("ij,ij->i", normals, light.position - points) <= 0
    return away | hit.any(axis=1)


@pytest.fixture(scope="module")
def scene():
    return rx.model_scene("cube", CUBE_INWARD)


def test_model_scene_turns_the_model_outwards_and_splits_back(scene):
    assert len(scene.mesh.faces) == 12 + 2
    centre = scene.model.vertices.mean(axis=0)
    face_centres = scene.model.triangles.mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", scene.model.face_normals, face_centres - centre) > 0)
    model, ground_y = rx.split_ground(scene.mesh)
    assert (len(model.faces), ground_y) == (12, 0.0)


def test_receivers_are_seeded_and_where_they_belong(scene):
    points, normals = rx.receivers(scene, **COUNTS, seed=3)
    again, _ = rx.receivers(scene, **COUNTS, seed=3)
    np.testing.assert_array_equal(points, again)
    assert points.shape == normals.shape == (4000, 3)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)
    ground, model = slice(0, 3000), slice(3000, None)
    assert np.all(points[ground, 1] == 0.0) and np.all(normals[ground] == [0, 1, 0])
    assert np.all(np.abs(points[ground][:, [0, 2]]) <= 1.5)  # 3x the cube's footprint
    assert np.all(np.abs(np.abs(points[model] - [0, 0.5, 0]).max(axis=1) - 0.5) < 1e-12)  # on the cube
    generic, _ = rx.receivers(rx.BenchScene("any", scene.mesh, scene.lights, "test"), 50, 50)
    assert generic.shape == (100, 3)


@pytest.mark.parametrize("workers", [1, 2])
def test_embree_peer_agrees_with_brute_force(scene, workers):
    points, normals = rx.receivers(scene, **COUNTS)
    light, eps = scene.lights[0], default_eps(scene.mesh.bounds)
    peer = peers.EmbreePeer(workers)
    try:
        peer.prepare(scene.mesh, light, None, eps)
        mask = peer.classify(points, normals)
    finally:
        peer.close()
    expected = brute_force_mask(scene.mesh, light, points, normals, eps)
    # Random receivers almost never send a ray within float32 rounding of an edge: allow 2 of 4000.
    assert np.count_nonzero(mask != expected) <= 2, f"{np.count_nonzero(mask != expected)} differ"
    assert 0 < expected.sum() < len(expected)


def counting(calls: dict, name: str, function):
    """``function``, counting its calls with a stand-in method in ``calls[name]``."""
    def counted(*args, **kwargs):
        if kwargs.get("method", args[2] if len(args) > 2 else None) == "all_lit":
            calls[name] = calls.get(name, 0) + 1
        return function(*args, **kwargs)
    return counted


def test_harness_rows_reports_and_compare(scene, device, tmp_path, monkeypatch):
    monkeypatch.setitem(METHODS, "all_lit", f"{__name__}:AllLit")
    calls = {}
    monkeypatch.setattr(run.sc, "shadow_mask", counting(calls, "shadow_mask", run.sc.shadow_mask))
    monkeypatch.setattr(run.sc, "prepare", counting(calls, "prepare", run.sc.prepare))
    monkeypatch.setattr(AllLit, "prepared_bounds", [])
    sweep = {"all_lit": {"label": ["a", "b"]}, "embreex": {"workers": [1]}}
    doc = run.run_bench([scene], sweep, COUNTS, repeats=2, device=device, progress=False)
    rows = doc["rows"]
    assert [r["label"] for r in rows] == ["all_lit label=a", "all_lit label=b", "embreex workers=1"]
    # per setting, public calls only: shadow_mask cold, warm-up, 2 timed, 1 profiled, then 1 warm-up and 2
    # timed interleaved with the peer; prepare warm-up, 2 timed
    assert calls == {"shadow_mask": 2 * 8, "prepare": 2 * 3}
    points, _ = rx.receivers(scene, **COUNTS)
    box = np.stack([points.min(axis=0), points.max(axis=0)])
    assert len(AllLit.prepared_bounds) == 2 * 11
    framed = frame_for(scene.mesh).points(box)      # methods work in the occluders' frame (shadowcl.frame)
    assert all(np.allclose(b, framed) for b in AllLit.prepared_bounds)
    for row in rows[:2]:
        assert row["false_shadow"] == 0 and row["false_light"] == row["in_shadow"] > 0
        assert row["error_percent"] == pytest.approx(100 * row["in_shadow"] / 4000)
        assert row["prepared_wrong"] == row["in_shadow"]
        assert row["device_mib"] == 1.0 and row["host_peak_mib"] is not None
        assert 0 < row["host_s"] <= row["host_profiled_wall_s"] and 0 < row["host_share"] <= 1
        assert row["receivers_per_s"] == pytest.approx(4000 / row["oneshot_s"])
    peer = rows[2]
    assert peer["vs_peer"] == 1.0 and peer["wrong"] <= 2 and peer["host_share"] is None
    # the peer's one-shot time is its prepare + classify, run by run; vs_peer compares one-shot throughputs
    assert peer["oneshot_runs_s"] == pytest.approx([p + q for p, q in zip(peer["prepare_runs_s"], peer["query_runs_s"])])
    # ... from the one-shot times taken again in interleaved rounds (repeats of them)
    assert all(len(r["oneshot_interleaved_runs_s"]) == 2 and r["oneshot_interleaved_s"] > 0 for r in rows)
    assert rows[0]["vs_peer"] == pytest.approx(peer["oneshot_interleaved_s"] / rows[0]["oneshot_interleaved_s"])
    assert all(r["oneshot_s"] > 0 and len(r["query_runs_s"]) == len(r["prepare_runs_s"]) == 2 for r in rows)
    doc = json.loads(json.dumps(doc, default=report.to_json))
    table = report.markdown(doc, plot_name="plot.png")
    assert table.count("| cube | 0 |") == 3 and "![speed against error](plot.png)" in table
    report.plot(doc, tmp_path / "plot.png")
    assert (tmp_path / "plot.png").stat().st_size > 0
    assert report.compare(doc, doc).count("| 1 | 1 | 1 |") == 3


def test_disputes_are_judged_by_the_float64_reference(scene):
    """A peer's disagreements with exact: the reference backs whichever side is right, and a segment
    through a triangle edge is within float32 rounding, whatever the two said."""
    points, normals = rx.receivers(scene, **COUNTS)
    light = scene.lights[0]
    eps = default_eps(scene.mesh.bounds)
    edge_point, eye = np.array([-0.5, 1.0, 0.0]), light.position    # the middle of a top edge of the cube
    start = eye + (edge_point - eye) * (eye[1] - eps) / (eye[1] - edge_point[1])   # at y = eps, on that line
    points = np.vstack([points, start - [0.0, eps, 0.0]])      # a ground receiver whose segment s = p + eps n
    normals = np.vstack([normals, [0.0, 1.0, 0.0]])            # runs through the edge
    case = run.Case(scene, 0, points, normals, eps)
    right = run.reference.shadow_mask(scene.mesh.vertices, scene.mesh.faces, light, points, normals, eps=case.eps)
    clear = np.flatnonzero(run.reference.segment_edge_distance(scene.mesh.vertices, scene.mesh.faces, light,
                                                                points, normals, eps=case.eps) > 1e-3)[:5]
    flipped = right.copy()
    flipped[clear] ^= True
    flipped[-1] ^= True
    assert run.judge_disputes(case, flipped, right) == {"judged": 6, "truth_right": 5, "row_right": 0,
                                                        "within_rounding": 1}
    assert run.judge_disputes(case, right, flipped) == {"judged": 6, "truth_right": 0, "row_right": 5,
                                                        "within_rounding": 1}
    assert "exact right on 5, embreex right on 0, 1 within float32 rounding" in report.judged(
        run.judge_disputes(case, flipped, right), "embreex")


def test_host_share_counts_opencl_calls_as_device_time(device):
    """A call that only waits in pyopencl has almost no host share; one that only works in NumPy, all."""
    data = np.zeros(1 << 22, np.float32)
    buffer = device.to_device(data)
    copy = run.host_share(lambda: [device.from_device(buffer, data.shape, data.dtype) for _ in range(20)])
    numpy = run.host_share(lambda: [np.sort(data + 1) for _ in range(3)])
    assert copy["host_share"] < 0.2 and numpy["host_share"] > 0.9, (copy, numpy)


def test_timing_warms_up_then_times_every_repeat_in_rounds():
    order = []
    timings = timing.interleaved({"a": lambda: order.append("a") or 1, "b": lambda: order.append("b") or 2},
                                 repeats=3, warmup=1)
    assert order == ["a", "b"] * 4
    assert [len(t.runs) for t in timings.values()] == [3, 3] and timings["b"].result == 2
    t = timing.Timing([3.0, 1.0, 2.0])
    assert (t.median, t.min) == (2.0, 1.0)
    assert len(timing.timed(lambda: None, repeats=0, warmup=0).runs) == 1


def test_figures_in_readme_match_the_committed_results():
    """README's generated blocks are what bench/figures.py makes from bench/results/*.json."""
    result = subprocess.run([sys.executable, str(PROJECT / "bench" / "figures.py"), "--check"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_sweep_grid_expands_to_every_combination():
    assert run.settings({}) == [{}]
    grid = {"resolution": [256, 1024], "bias": ["slope", "normal"], "filter": ["pcf"]}
    assert len(run.settings(grid)) == 4
    assert run.label("shadow_map", run.settings(grid)[0]) == "shadow_map resolution=256 bias=slope filter=pcf"


@pytest.mark.parametrize("name", ["embreex", "open3d", "mitsuba"])
@pytest.mark.parametrize("scene_file", ["hard/light_inside.toml", "default.toml"])
def test_peers_agree_with_exact(device, name, scene_file):
    """Every peer answers DESIGN.md's question: in a room round the light (segments must end at the
    light, not run past it) and on the default scene, with and without normals."""
    try:
        peer = peers.PEERS[name]()
    except ImportError as error:     # the peers extra is optional (CI installs embreex only)
        pytest.skip(f"{name} not installed: {error}")
    import shadowcl as sc
    scene = rx.load_scene(str(PROJECT / "scenes" / scene_file))
    points, normals = rx.receivers(scene, 6000, 2000, 0)
    eps = default_eps(scene.mesh.bounds)
    peer.prepare(scene.mesh, scene.lights[0], None, eps)
    try:
        for given in (normals, None):
            truth = sc.shadow_mask(scene.mesh, scene.lights[0], points, given, device=device, eps=eps)
            assert np.count_nonzero(peer.classify(points, given) != truth) <= 2e-4 * len(points)
    finally:
        run.close(peer)


def test_scale_series_rows_and_exponents(device):
    """bench/scale.py on a tiny city: one row per tool, every mask equal to exact's, a fitted exponent."""
    import scale

    rows = scale.measure(scale.city(1, 2), 1500, 500, 1, device) + scale.measure(scale.city(2, 2), 1500, 500, 1, device)
    tools = {r["tool"] for r in rows}
    assert {"exact", "embreex"} <= tools and all(r["wrong"] == 0 for r in rows)
    assert rows[0]["triangles"] == 20 * 4**2 + 2 and rows[-1]["triangles"] == 4 * 20 * 4**2 + 2
    fits = scale.exponents(rows, "triangles")
    assert set(fits) == tools and all(np.isfinite(e) for e in fits.values())


def test_kernels_ab_times_variants_and_compares_masks(tmp_path, capsys):
    """bench/kernels_ab.py on a tiny city with two kernels folders, the second with the walk's answers
    inverted: per-kernel rows for each variant, a one-shot median, and the inversion seen in the mask
    count (so the variants really ran their own kernels)."""
    import shutil

    import kernels_ab
    from shadowcl.device import KERNEL_DIR

    same, inverted = tmp_path / "same", tmp_path / "inverted"
    shutil.copytree(KERNEL_DIR, same)
    shutil.copytree(KERNEL_DIR, inverted)
    source = (inverted / "exact.cl").read_text()
    line = "            out[index[j]] = (uchar)(hit_lane[j] != 0);"
    assert line in source
    (inverted / "exact.cl").write_text(source.replace(line, line.replace("!= 0", "== 0")))
    kernels_ab.main(["city:1:2", str(same), str(inverted), "--rounds", "1", "--ground", "1500", "--model", "500"])
    out = capsys.readouterr().out
    assert "exact_classify" in out and "exact_bin_count" in out and "one-shot call" in out
    differs = int(out.rsplit("differs from the first on ", 1)[1].split()[0])
    assert 0 < differs <= 2000
