"""kernels/voxel.cl (Lai & Cheng's shadow determination) against its NumPy reference, and the method."""

from types import SimpleNamespace

import numpy as np
import pytest

import shadowcl as sc
from shadowcl import voxel
from shadowcl import voxelize as vz
from shadowcl.reference import voxel as ref
from shadowcl.subdivision import SubdivisionSurface
from shadowcl.testing import grid_patch_table

from conftest import SCENES, require_models
from test_voxelize import torus_net


def ground_net(size=3.0, height=-0.6, count=10):
    x, y = np.meshgrid(np.linspace(-size, size, count), np.linspace(-size, size, count), indexing="ij")
    return np.stack([x, y, height + 0 * x], axis=-1)


def torus_on_ground():
    return vz.merge_tables([grid_patch_table(torus_net(), True, True), grid_patch_table(ground_net())])


BOX = np.array([[-3.0, -3.0, -1.0], [3.0, 3.0, 1.0]])
LIGHTS = {
    "point": sc.PointLight((0.5, 0.3, 5.0)),
    "directional": sc.DirectionalLight((-0.3, 0.2, -1.0)),
    "inside": sc.PointLight((0.05, 2.1, 0.4)),      # inside the box: a cube of six views
}


def prepared(device, table, light, determination, resolution=24, **kw):
    method = voxel.VoxelMethod(device, resolution=resolution, determination=determination, **kw)
    method.prepare(table, light, BOX, 1e-4)
    return method


def light_args(light):
    point = isinstance(light, sc.PointLight)
    return point, np.asarray(light.position if point else light.direction, dtype=np.float64)


@pytest.mark.parametrize("light", list(LIGHTS))
def test_topology_matches_reference(device, light):
    table = torus_on_ground()
    m = prepared(device, table, LIGHTS[light], "topology")
    vox = m.vox
    states, unsure = ref.topology(vox.corners, vox.corner_voxels, m.sample_normals, *light_args(LIGHTS[light]),
                                  vox.resolution)
    assert unsure.mean() < 0.01
    differ = np.flatnonzero((states != m.sample_states) & ~unsure)
    assert len(differ) == 0, f"topology_shadow R=24 {light}: {len(differ)} of {len(states)} samples differ, e.g. {differ[:5]}"
    assert 0.05 < np.mean(states == 2) < 0.95          # both lit and shadowed samples occur


@pytest.mark.parametrize("light", ["point", "directional"])
def test_lists_hold_leaves_sorted_nearest_first(device, light):
    m = prepared(device, torus_on_ground(), LIGHTS[light], "topology")
    offsets, items = m.lists.to_host(device)
    centroid = m.vox.corners.astype(np.float64).mean(axis=1)
    point, vec = light_args(LIGHTS[light])
    key = np.linalg.norm(centroid - vec, axis=1) if point else centroid @ vec
    assert len(items) >= m.vox.nleaves and set(np.unique(items).tolist()) == set(range(m.vox.nleaves))
    step = np.diff(key[items])
    inside = np.ones(len(step), dtype=bool)
    inside[offsets[1:-1][(offsets[1:-1] > 0) & (offsets[1:-1] < len(items))] - 1] = False   # across cells
    # float32 keys: equal within rounding may come in either order
    assert np.all(step[inside] >= -1e-5 * np.abs(key[items][1:][inside]).max())


@pytest.mark.parametrize("light", ["point", "directional"])
def test_offset_matches_reference(device, light):
    table = torus_on_ground()
    m = prepared(device, table, LIGHTS[light], "offset")
    vox = m.vox
    grid = m.grid
    states, unsure = ref.offset(vox.corners, m.sample_normals, *light_args(LIGHTS[light]), grid.views, grid.nx, grid.ny,
                                np.sqrt(2) * vox.voxel_size)
    assert unsure.mean() < 0.05
    differ = np.flatnonzero((states != m.sample_states) & ~unsure)
    assert len(differ) == 0, f"offset_shadow R=24 {light}: {len(differ)} of {len(states)} samples differ, e.g. {differ[:5]}"


@pytest.mark.parametrize("determination", ["topology", "offset"])
def test_frame_buffer_states_are_lit_wins_of_samples(device, determination):
    m = prepared(device, torus_on_ground(), LIGHTS["point"], determination)
    keys, values = voxel.sparse_states(m.vox.corner_voxels.ravel(), m.sample_states)
    frame = vz.unpack_states(m.vox.frame_words, m.vox.resolution ** 3)
    assert np.array_equal(np.flatnonzero(frame), keys)
    assert np.array_equal(frame[keys], values)
    assert set(np.unique(frame).tolist()) <= {0, 1, 2}


@pytest.mark.parametrize("determination", ["topology", "offset"])
def test_without_frame_buffer_same_answers(device, rng, determination):
    table = torus_on_ground()
    with_fb = prepared(device, table, LIGHTS["point"], determination, frame_buffer=True)
    without = prepared(device, table, LIGHTS["point"], determination, frame_buffer=False)
    points = with_fb.vox.corners.reshape(-1, 3)[rng.choice(4 * with_fb.vox.nleaves, 500)].astype(np.float64)
    points += rng.normal(scale=0.2 * with_fb.vox.voxel_size, size=points.shape)
    assert np.array_equal(with_fb.classify(points), without.classify(points))
    assert np.array_equal(with_fb.visibility(points), without.visibility(points))


def test_lit_plane_does_not_shadow_itself(device):
    """Figure 1: a plane under grazing light is lit everywhere (topology-based)."""
    plane = grid_patch_table(ground_net())
    for elevation in (2.0, 10.0, 45.0):
        e = np.radians(elevation)
        light = sc.DirectionalLight((np.cos(e), 0.3, -np.sin(e)))
        m = voxel.VoxelMethod(device, resolution=64, determination="topology")
        m.prepare(plane, light, BOX, 1e-4)
        assert np.all(m.sample_states == 1), f"elevation {elevation}: {np.sum(m.sample_states == 2)} self-shadowed samples"


def test_classify_and_visibility(device):
    m = prepared(device, torus_on_ground(), LIGHTS["point"], "topology", resolution=32)
    samples = m.vox.corners.reshape(-1, 3).astype(np.float64)
    mask = m.classify(samples)
    # a sample's point lies in its own voxel: its class is its voxel's lit-wins state (but for samples
    # within 1e-4 voxels of a face, which the host's float64 mapping may put in the next voxel)
    keys, values = voxel.sparse_states(m.vox.corner_voxels.ravel(), m.sample_states)
    expect = values[np.searchsorted(keys, m.vox.corner_voxels.ravel())] == 2
    x = (samples - m.vox.origin) / m.vox.voxel_size
    clear = np.all(np.minimum(x - np.floor(x), np.ceil(x) - x) >= 1e-4, axis=1)
    assert clear.mean() > 0.9
    assert np.array_equal(mask[clear], expect[clear])
    vis = m.visibility(samples)
    assert set(np.unique(vis).tolist()) <= {0.0, 0.125, 0.25, 0.5, 1.0}
    assert np.all(vis[mask] <= 0.5) and np.any(vis == 1.0) and np.any(vis == 0.0)
    # normals facing away are in shadow
    away = np.tile([0.0, 0.0, -1.0], (len(samples), 1))
    assert m.classify(samples, away).all()
    # a point far from every surface is classified lit and counted (unplaced="lit", the default)
    assert not m.classify(np.array([[2.5, 2.5, 0.9]]))[0] and m.stats["unplaced"] == 1


@pytest.mark.parametrize("frame_buffer", [True, False])
def test_locate_kernel_matches_reference(device, rng, frame_buffer):
    """classify's device lookup (locate_states) against a NumPy search of the dense states: points on the
    samples, scattered up to 3.5 voxels off them (in their voxel, in ring 1, ring 2, beyond), outside the
    grid, and far away; in the frame buffer (5.2) and in the sorted sparse states (5.1)."""
    m = prepared(device, torus_on_ground(), LIGHTS["point"], "topology", resolution=32, frame_buffer=frame_buffer)
    m.classify(np.zeros((1, 3)))                  # without a frame buffer (5.1) classify voxelizes and determines
    corners = m.vox.corners.reshape(-1, 3).astype(np.float64)
    h = m.vox.voxel_size
    points = np.concatenate([
        corners[rng.choice(len(corners), 400)] + rng.uniform(-3.5, 3.5, (400, 3)) * h,
        m.vox.origin + rng.uniform(-3, m.vox.resolution + 3, (300, 3)) * h,      # around and outside the grid
        [[1e6, -1e6, 3e5], [-1e30, 0.0, 0.0]],                                   # far away
    ])
    keys, values = voxel.sparse_states(m.vox.corner_voxels.ravel(), m.sample_states)
    dense = np.zeros(m.vox.resolution ** 3, np.uint8)
    dense[keys] = values
    want_ids, want_states = ref.locate(dense.reshape((m.vox.resolution,) * 3), points, m.vox.origin, h)
    ids, states = m._locate(points)
    assert np.array_equal(states, want_states) and np.array_equal(ids, want_ids)
    assert 0 < np.sum(want_ids < 0) < len(points) and np.any(want_states == 2)
    # unplaced="raise": a named error instead of calling them lit
    strict = prepared(device, torus_on_ground(), LIGHTS["point"], "topology", resolution=32, unplaced="raise")
    with pytest.raises(ValueError, match=r"points: \d+ of 702 are more than 2 voxels"):
        strict.classify(points)


def test_scene_with_triangles_is_refused(device):
    surface = SubdivisionSurface(torus_net().reshape(-1, 3)[:4], [[0, 1, 2, 3]])
    scene = sc.Scene([("patch", surface), ("box", sc.Mesh(np.eye(3), [[0, 1, 2]]))], [LIGHTS["point"]])
    with pytest.raises(ValueError, match="scene_or_mesh: .*objects \\['box'\\] are triangle meshes"):
        voxel.VoxelMethod(device).prepare(scene, LIGHTS["point"], BOX, 1e-4)


def test_a_mesh_is_refused_by_the_public_call_s_argument_name(device):
    """A Mesh given to method="voxel" names the caller's argument, not an internal one."""
    mesh = sc.Mesh(np.eye(3), [[0, 1, 2]])
    with pytest.raises(TypeError, match="scene_or_mesh: the voxel method voxelizes subdivision surfaces, got a Mesh"):
        sc.shadow_mask(mesh, LIGHTS["point"], np.zeros((2, 3)), method="voxel")


def test_shadow_mask_on_a_scene(device):
    require_models()                              # the scene's torus cage is in ../shared/models
    scene = sc.Scene.load(SCENES / "subdivision" / "torus.toml")
    points = scene.mesh.vertices[::7].astype(np.float64)
    mask = sc.shadow_mask(scene, scene.light, points, method="voxel", resolution=64)
    exact = sc.shadow_mask(scene, scene.light, points, method="exact")
    assert mask.shape == exact.shape and 0.0 < mask.mean() < 1.0
    assert np.mean(mask != exact) < 0.1       # a voxel-resolution method: errors near shadow edges only


@pytest.mark.parametrize("kw, error, match", [
    (dict(determination="both"), ValueError, "determination"),
    (dict(connectivity=4), ValueError, "connectivity"),
    (dict(resolution=0), ValueError, "resolution"),
    (dict(resolution=4096), ValueError, "resolution"),
    (dict(frame_buffer="yes"), TypeError, "frame_buffer"),
    (dict(unplaced="warn"), ValueError, "unplaced"),
])
def test_bad_parameters(device, kw, error, match):
    with pytest.raises(error, match=match):
        voxel.VoxelMethod(device, **kw)


def test_leaf_visibility_rule():
    states = np.array([[1, 1, 1, 1], [2, 1, 1, 1], [2, 1, 2, 1], [2, 2, 1, 2], [2, 2, 2, 2]])
    assert voxel.leaf_visibility(states).tolist() == [1.0, 0.5, 0.25, 0.125, 0.0]


def test_shaded_leaves_take_the_frame_buffer_states(device):
    m = prepared(device, torus_on_ground(), LIGHTS["point"], "topology", resolution=32)
    shaded = voxel.shade_leaves(m)
    leaves = shaded.leaves
    keys, values = voxel.sparse_states(m.vox.corner_voxels.ravel(), m.sample_states)
    corner_states = values[np.searchsorted(keys, m.vox.corner_voxels)]          # (n, 4) voxel states
    sample = leaves.vertex_sample
    assert np.array_equal(shaded.vertex_state[sample >= 0], corner_states.ravel()[sample[sample >= 0]])
    assert np.all(shaded.vertex_state[sample < 0] == 0)
    shadowed = np.sum(corner_states == 2, axis=1)[leaves.face_leaf]
    assert np.array_equal(shaded.face_visibility, np.where(shadowed == 4, 0.0, 0.5 ** shadowed).astype(np.float32))
    assert np.any(shaded.face_visibility == 1.0) and np.any(shaded.face_visibility == 0.0)
    assert np.any((shaded.face_visibility > 0) & (shaded.face_visibility < 1))     # the smooth transition
    # without a frame buffer (section 5.1) the same states are determined again
    again = voxel.shade_leaves(prepared(device, torus_on_ground(), LIGHTS["point"], "topology", resolution=32,
                                        frame_buffer=False), leaves)
    assert np.array_equal(again.face_visibility, shaded.face_visibility)


BAND = 2   # voxels: a pixel shows one leaf in the leaf rendering, and the reference's lookup takes the
           # first leaf with a corner in the point's voxel: near a shadow edge the two leaves' 1/2^n differ


def test_render_leaves_matches_render(device):
    """Section 5's rendering (render(method="voxel") draws the leaves) shadows the same regions as the
    method's visibility on the scene's own tessellation seen by the same camera: shadow masks differ
    only within BAND voxels (in the scene) of the reference's shadow boundary."""
    from scipy import ndimage, spatial
    from shadowcl import raster
    from shadowcl.render import camera_view, render_report

    require_models()
    scene = sc.Scene.load(SCENES / "subdivision" / "torus.toml")
    width, height = 192, 108
    view = camera_view(scene, width, height)
    seen = raster.receivers(device, scene.mesh, view, raster.rasterize(device, scene.mesh, view))
    shadows = sc.prepare(scene, scene.light, "voxel", device=device, resolution=64)
    ref = SimpleNamespace(covered=seen.mask, receivers=seen, shadow=[shadows.visibility(seen.points, seen.normals) < 0.5])
    new = render_report(scene, "voxel", width, height, device=device, resolution=64)
    assert new.image.shape == (height, width, 3) and new.visibility.shape == new.shadow.shape
    assert np.sum(ref.covered != new.covered) <= 0.001 * width * height       # same silhouette
    a, b = (np.zeros((height, width), bool) for _ in range(2))
    a.ravel()[ref.receivers.pixel_index] = ref.shadow[0]
    b.ravel()[new.receivers.pixel_index] = new.shadow[0]
    both = ref.covered & new.covered
    assert 0.03 < b[both].mean() < 0.5
    boundary = (a ^ ndimage.binary_erosion(a) | (ndimage.binary_dilation(a) & ~a)) & ref.covered
    where = np.full((height * width, 3), np.nan)
    where[seen.pixel_index] = seen.points
    differ = np.flatnonzero(((a != b) & both).ravel())
    distance, _ = spatial.cKDTree(where[np.flatnonzero(boundary.ravel())]).query(where[differ])
    assert 0 < len(differ) < 0.05 * both.sum()
    assert distance.max() <= BAND * shadows._instance.vox.voxel_size
    # shading: the shadowed pixels are darker than the lit ones of the same ground
    lit = new.image.reshape(-1, 3)[new.receivers.pixel_index][new.visibility[0] == 1.0].mean()
    dark = new.image.reshape(-1, 3)[new.receivers.pixel_index][new.visibility[0] == 0.0].mean()
    assert dark < lit


def test_leaf_rendering_bad_input(device):
    with pytest.raises(TypeError, match="scene"):
        sc.render(torus_on_ground(), "voxel", 32, 32, device=device)
    with pytest.raises(RuntimeError, match="before prepare"):
        voxel.shade_leaves(voxel.VoxelMethod(device, resolution=16))
    m = prepared(device, torus_on_ground(), LIGHTS["point"], "topology", resolution=16)
    other = vz.voxelize(device, torus_on_ground(), 32).tessellate()
    with pytest.raises(ValueError, match="leaves"):
        voxel.shade_leaves(m, other)


def test_scenes_outside_the_world_range_are_refused(device):
    """The voxel method computes in world coordinates: a scene scaled into its measured range gives
    the scale-1 mask; beyond it (1e-9 and 1e12 silently lost 46 and 354 of 400 receivers; 1e5 sizes
    off the origin) the call is refused naming the scene (voxel.WORLD_SIZES, WORLD_OFFSET)."""
    net, ground = torus_net(), ground_net()
    rng = np.random.default_rng(5)
    points = np.c_[rng.uniform(-2.5, 2.5, 300), rng.uniform(-2.5, 2.5, 300), np.full(300, -0.6)]

    def mask(scale, shift=0.0):
        table = vz.merge_tables([grid_patch_table(net * scale + shift, True, True),
                                 grid_patch_table(ground * scale + shift)])
        method = voxel.VoxelMethod(device, resolution=64)
        method.prepare(table, sc.PointLight(np.array([0.5, 0.3, 5.0]) * scale + shift), BOX * scale + shift, 1e-4 * scale)
        return method.classify(points * scale + shift)

    reference = mask(1.0)
    for scale in (1e-5, 1e6):
        assert np.count_nonzero(mask(scale) != reference) <= 2, scale   # the voxel lookup's float32 rounding
    for scale, shift in ((1e-9, 0.0), (1e12, 0.0), (1.0, 1e5)):
        with pytest.raises(ValueError, match="scene_or_mesh: the voxel method computes in world coordinates"):
            mask(scale, shift)

