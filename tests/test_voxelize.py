"""kernels/voxelize.cl against its NumPy reference, and the voxelization's invariants (no leaks, accuracy)."""

from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial import cKDTree

from shadowcl import voxelize as vz
from shadowcl.geometry import Mesh
from shadowcl.reference import voxelize as ref
from shadowcl.subdivision import SubdivisionSurface
from shadowcl.testing import grid_patch_table

from conftest import SCENES, require_models


def torus_net(m=12, n=8, major=1.0, minor=0.4, tilt=0.3, shift=0.0123):
    """Control grid of a torus (u around the axis, v around the tube: du x dv points outward), tilted and
    shifted off the grid's symmetry planes."""
    theta, phi = np.meshgrid(2 * np.pi * np.arange(m) / m, 2 * np.pi * np.arange(n) / n, indexing="ij")
    p = np.stack([(major + minor * np.cos(phi)) * np.cos(theta), (major + minor * np.cos(phi)) * np.sin(theta),
                  minor * np.sin(phi)], axis=-1)
    c, s = np.cos(tilt), np.sin(tilt)
    return p @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]]).T + shift


def torus_core(tilt=0.3, shift=0.0123, count=64):
    """Points on the torus's core circle (inside the solid)."""
    t = np.linspace(0, 2 * np.pi, count, endpoint=False)
    c, s = np.cos(tilt), np.sin(tilt)
    return np.stack([np.cos(t), np.sin(t), 0 * t], axis=-1) @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]]).T + shift


def bumpy_ground(rng, m=9, n=7):
    """An open control grid with random heights: a random, non-symmetric surface."""
    x, y = np.meshgrid(np.arange(m, dtype=float), np.arange(n, dtype=float), indexing="ij")
    return np.stack([x + 0.2 * rng.standard_normal(x.shape), y, 1.5 * rng.standard_normal(x.shape)], axis=-1)


MARGIN = 1e-4   # voxels: a corner closer than this to a voxel face may fall either side in float32 vs float64


def float32_margin(table, voxel_size):
    """MARGIN, or more far from the origin: float32 evaluation sums 16 control points of magnitude |p|,
    each rounded to 2^-24 |p| relative, and the voxel mapping subtracts an origin of that magnitude."""
    return max(MARGIN, 32 * 2.0 ** -24 * float(np.max(np.abs(table.points))) / voxel_size)


def compare_with_reference(device, table, resolution, connectivity):
    """Kernel leaves and voxels equal the reference's, except under subpatches whose corners came within
    MARGIN voxels of a voxel face (there float32 and float64 rounding may decide differently)."""
    vox = vz.voxelize(device, table, resolution, connectivity)
    r = ref.voxelize(table.points, table.first, table.levels, resolution, connectivity, vox.origin, vox.voxel_size)
    kernel_leaves = {tuple(x) for x in vox.leaves[:, :4].astype(np.int64).tolist()}
    sure = r["margin"] >= float32_margin(table, vox.voxel_size)
    sure_leaves = {tuple(x) for x in r["leaves"][sure].tolist()}
    missing = sure_leaves - kernel_leaves
    assert not missing, f"voxelize R={resolution} N={connectivity}: {len(missing)} reference leaves missing, e.g. {sorted(missing)[:3]}"
    assert abs(vox.nleaves - len(r["leaves"])) <= 4 * np.sum(~sure) + 0, "leaf counts differ beyond the unsure subpatches"
    R = resolution
    occupied = set(np.flatnonzero(vox.occupied.ravel()).tolist())
    sure_voxels = r["voxels"][sure].reshape(-1, 3)
    sure_ids = set(((sure_voxels[:, 0] * R + sure_voxels[:, 1]) * R + sure_voxels[:, 2]).tolist())
    assert sure_ids <= occupied, f"voxelize R={R} N={connectivity}: {len(sure_ids - occupied)} reference voxels missing"
    extra = occupied - r["occupied"]
    assert len(extra) <= 8 * np.sum(~sure), f"voxelize R={R} N={connectivity}: {len(extra)} voxels not in the reference"
    # The frame buffer holds exactly the kernel's own leaf corners
    from_leaves = set(np.unique(vox.corner_voxels).tolist())
    assert occupied == from_leaves
    return vox, r


@pytest.mark.parametrize("resolution", [1, 2, 31, 32, 33])
@pytest.mark.parametrize("connectivity", [26, 18, 6])
def test_torus_matches_reference(device, resolution, connectivity):
    table = grid_patch_table(torus_net(), True, True)
    vox, r = compare_with_reference(device, table, resolution, connectivity)
    assert vox.nleaves >= len(table.first)


@pytest.mark.parametrize("connectivity", [26, 6])
def test_random_surface_matches_reference(device, rng, connectivity):
    table = grid_patch_table(bumpy_ground(rng))
    compare_with_reference(device, table, 40, connectivity)


def test_far_from_origin_matches_reference(device):
    """The whole torus translated 1000 units away (float32 control points lose ~6e-5 there)."""
    table = grid_patch_table(torus_net(shift=1000.0), True, True)
    vox, _ = compare_with_reference(device, table, 32, 26)
    assert np.allclose(vox.origin, 1000.0 + np.array([-1.4, -1.4, -1.4]) - 0.0, atol=0.3)


def test_extraordinary_patches_match_reference(device):
    cube = SubdivisionSurface.load(require_models() / "ccss" / "catmark_cube.obj")
    table = cube.patch_table(device)
    assert np.any(table.levels > 0)          # the Stam sub-domain path is exercised
    compare_with_reference(device, table, 24, 26)


def outside_reaches(occupied, ijk, fill: int) -> int:
    """How many voxels ``ijk`` ((N, 3)) a ``fill``-connected flood fill from outside the grid reaches."""
    padded = np.pad(occupied, 1)
    structure = ndimage.generate_binary_structure(3, {6: 1, 18: 2, 26: 3}[fill])
    labels, _ = ndimage.label(~padded, structure)
    ijk = ijk + 1
    return int(np.sum(labels[ijk[:, 0], ijk[:, 1], ijk[:, 2]] == labels[0, 0, 0]))


def reaches(vox, points, fill):
    ijk, inside = vox.voxel_of(points)
    assert inside.all()
    return outside_reaches(vox.occupied, ijk, fill)


# The pairing that holds (measured): leaves with 26- or 18-adjacent edges block 6-connected fills (an
# 18-connected fill leaks through both); 6-adjacent edges also block 18-connected fills. 26-connected
# fills can cross a 6-connectivity voxelization through a voxel vertex between leaves (measured on the
# cube at 24^3 to 64^3 and the torus at 64^3), so 6 is not claimed to be 26-separating.
SEPARATES = {26: 6, 18: 6, 6: 18}


@pytest.mark.parametrize("connectivity", [26, 18, 6])
@pytest.mark.parametrize("resolution", [24, 47])
def test_closed_surfaces_do_not_leak(device, connectivity, resolution):
    torus = vz.voxelize(device, grid_patch_table(torus_net(), True, True), resolution, connectivity)
    assert reaches(torus, torus_core(), SEPARATES[connectivity]) == 0
    cube = vz.voxelize(device, SubdivisionSurface.load(require_models() / "ccss" / "catmark_cube.obj"), resolution,
                       connectivity)
    assert reaches(cube, np.zeros((1, 3)), SEPARATES[connectivity]) == 0


def test_flood_fill_detects_a_hole(device):
    """The leak test can fail: removing the voxels around a surface point opens the torus."""
    torus = vz.voxelize(device, grid_patch_table(torus_net(), True, True), 24, 26)
    occupied = torus.occupied
    core, _ = torus.voxel_of(torus_core())
    assert outside_reaches(occupied, core, 6) == 0
    i, j, k = torus.voxel_of(torus.corners[:1, 0].astype(np.float64))[0][0]
    occupied[i - 2:i + 3, j - 2:j + 3, k - 2:k + 3] = False
    assert outside_reaches(occupied, core, 6) > 0


@pytest.mark.parametrize("connectivity", [26, 6])
def test_voxels_are_near_the_surface_and_cover_it(device, rng, connectivity):
    table = grid_patch_table(torus_net(), True, True)
    vox = vz.voxelize(device, table, 40, connectivity)
    h = vox.voxel_size
    # Dense float64 samples of the limit surface (spacing well below a voxel)
    count = 120_000
    patch = rng.integers(0, len(table.first), count)
    u, v = rng.random(count), rng.random(count)
    samples = ref.patch_eval(table.points, table.first, table.levels, patch, u, v)
    # Every sample's voxel is an occupied voxel or Chebyshev-adjacent to one (no holes)
    occupied = vox.occupied
    ijk, inside = vox.voxel_of(samples)
    assert inside.all()
    near = ndimage.binary_dilation(occupied, ndimage.generate_binary_structure(3, 3))
    assert near[ijk[:, 0], ijk[:, 1], ijk[:, 2]].all()
    # Every occupied voxel holds a leaf corner, a limit-surface point: its centre is within sqrt(3)/2
    # voxels of the surface (plus float32 rounding of the corner, 1e-5 of the scene)
    corners = vox.corners.reshape(-1, 3).astype(np.float64)
    exact = ref.patch_eval(table.points, table.first, table.levels, np.repeat(vox.patch, 4).astype(np.int64),
                           (vox.rect[:, [0]] + vox.rect[:, [2]] * [0, 1, 1, 0]).ravel(),
                           (vox.rect[:, [1]] + vox.rect[:, [3]] * [0, 0, 1, 1]).ravel())
    assert np.max(np.abs(corners - exact)) < 1e-5 * 3
    # ... and each corner's voxel is the one its float64 position falls in (but within MARGIN of a face)
    x = (exact - vox.origin) / h
    clear = np.all(np.minimum(x - np.floor(x), np.ceil(x) - x) >= MARGIN, axis=1)
    R = vox.resolution
    exact_ijk = np.floor(x).astype(np.int64)
    exact_ids = (exact_ijk[:, 0] * R + exact_ijk[:, 1]) * R + exact_ijk[:, 2]
    assert clear.mean() > 0.95
    assert np.array_equal(exact_ids[clear], vox.corner_voxels.ravel()[clear])
    centres = vox.origin + (np.argwhere(occupied) + 0.5) * h
    distance, _ = cKDTree(exact).query(centres)
    # half the voxel diagonal, plus the corners' float32 rounding (3e-5 above) for a voxel it tipped over
    assert distance.max() <= np.sqrt(3) / 2 * h + 3e-5


def test_overflow_regrows_to_the_same_result(device):
    table = grid_patch_table(torus_net(), True, True)
    normal = vz.voxelize(device, table, 32, 26)
    tiny = vz.voxelize(device, table, 32, 26, initial_capacity=8)
    assert tiny.stats["reruns"] > 0
    assert {tuple(x) for x in tiny.leaves.tolist()} == {tuple(x) for x in normal.leaves.tolist()}
    assert np.array_equal(tiny.occupied, normal.occupied)


def test_counters_that_could_wrap_are_refused(device, monkeypatch):
    """A level whose slot counters could pass the 32-bit limit is refused with a ValueError naming the
    resolution before the kernel runs (a wrapped counter would index below the buffers); here the limit is
    lowered to what the torus's deeper levels need, and a limit it fits in changes nothing."""
    table = grid_patch_table(torus_net(), True, True)
    normal = vz.voxelize(device, table, 32, 26)
    level_items = max(n for _, n, _ in normal.stats["per_level"])
    monkeypatch.setattr(vz, "COUNTER_MAX", 4 * level_items - 1)
    with pytest.raises(ValueError, match="resolution: 32 needs .* subpatches .* 32-bit counters"):
        vz.voxelize(device, table, 32, 26)
    monkeypatch.setattr(vz, "COUNTER_MAX", 4 * level_items + normal.stats["leaves"])
    fits = vz.voxelize(device, table, 32, 26, initial_capacity=8)
    assert np.array_equal(fits.occupied, normal.occupied)


def test_without_frame_buffer_same_voxels(device):
    table = grid_patch_table(torus_net(), True, True)
    with_fb = vz.voxelize(device, table, 32, 18, frame_buffer=True)
    without = vz.voxelize(device, table, 32, 18, frame_buffer=False)
    assert without.frame_dev is None and without.stats["frame_bytes"] == 0
    assert np.array_equal(with_fb.occupied, without.occupied)


def test_frame_buffer_too_large(device, monkeypatch):
    """A frame buffer the device cannot hold: True raises naming it, None falls back to section 5.1.
    Two tiny patches at opposite corners of the grid: 1024^3 voxels but few leaves."""
    monkeypatch.setattr(type(device), "max_alloc_bytes", property(lambda self: 64 << 20))
    x, y = np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="ij")
    net = 0.001 * np.stack([x, y, 0 * x], axis=-1)
    table = vz.merge_tables([grid_patch_table(net), grid_patch_table(net + 1.0)])
    with pytest.raises(ValueError, match="frame buffer"):
        vz.voxelize(device, table, 1024, 26, frame_buffer=True)
    fallback = vz.voxelize(device, table, 1024, 26, frame_buffer=None)
    assert fallback.frame_dev is None and fallback.stats["frame_buffer"] is False
    assert 0 < fallback.nleaves < 1000


def test_merge_tables_keeps_every_patch(device):
    a = grid_patch_table(torus_net(), True, True)
    b = grid_patch_table(torus_net(shift=3.0), True, True)
    merged = vz.merge_tables([a, b])
    assert len(merged.first) == len(a.first) + len(b.first)
    assert np.array_equal(merged.neighbors[len(a.first):], b.neighbors + len(a.first))
    vox = vz.voxelize(device, merged, 32, 26)
    assert set(np.unique(vox.patch).tolist()) == set(range(len(merged.first)))


def test_grid_bounds_fix_the_grid(device):
    table = grid_patch_table(torus_net(), True, True)
    box = np.array([[-3.0, -2.0, -1.0], [5.0, 2.0, 1.0]])
    vox = vz.voxelize(device, table, 40, 26, grid_bounds=box)
    assert np.allclose(vox.origin, [-3.0, -4.0, -4.0], atol=1e-3) and np.isclose(vox.voxel_size * 40, 8.0, rtol=1e-3)
    alone = vz.voxelize(device, table, 40, 26)
    assert vox.voxel_size > alone.voxel_size
    with pytest.raises(ValueError, match="grid_bounds"):
        vz.voxelize(device, table, 40, 26, grid_bounds=box * 0.1)


def test_grid_bounds_need_only_hold_the_control_vertices(device, rng):
    """An open control mesh's patch table extrapolates boundary points beyond its vertices; a grid box
    holding every control vertex is accepted (with a NumPy integer connectivity) and holds the limit surface."""
    m, n = 5, 4
    x, z = np.meshgrid(np.arange(m, dtype=float), np.arange(n, dtype=float), indexing="ij")
    vertices = np.stack([x, rng.uniform(0, 1, x.shape), z], axis=-1).reshape(-1, 3)
    faces = [[i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j] for i in range(m - 1) for j in range(n - 1)]
    surface = SubdivisionSurface(vertices, faces)
    box = np.stack([vertices.min(axis=0), vertices.max(axis=0)])
    points = surface.patch_table(device).points
    assert np.any(points < box[0]) or np.any(points > box[1])     # what the check used to test
    vox = vz.voxelize(device, surface, 32, np.int64(18), grid_bounds=box)
    limit = surface.tessellate(segments=8).vertices
    assert np.all(limit >= vox.origin) and np.all(limit <= vox.origin + vox.voxel_size * 32)
    with pytest.raises(ValueError, match="grid_bounds: the box must contain every control point"):
        vz.voxelize(device, surface, 32, grid_bounds=box * 0.5)


@pytest.mark.parametrize("call, error, match", [
    (lambda d, t: vz.voxelize(d, t, 0), ValueError, "resolution"),
    (lambda d, t: vz.voxelize(d, t, 2048), ValueError, "resolution"),
    (lambda d, t: vz.voxelize(d, t, 16, connectivity=8), ValueError, "connectivity"),
    (lambda d, t: vz.voxelize(d, t, 16, connectivity=26.0), ValueError, "connectivity: expected one of 6, 18, 26, got 26.0"),
    (lambda d, t: vz.voxelize(d, "torus", 16), TypeError, "surface"),
    (lambda d, t: vz.voxelize(d, replace(t, points=t.points * np.nan), 16), ValueError, "finite"),
    (lambda d, t: vz.voxelize(d, replace(t, points=t.points[:10]), 16), ValueError, "beyond"),
    (lambda d, t: grid_patch_table(np.zeros((3, 5, 3))), ValueError, "net"),
])
def test_bad_input(device, call, error, match):
    with pytest.raises(error, match=match):
        call(device, grid_patch_table(torus_net(), True, True))


def oriented_edges(mesh):
    """Directed edges of ``mesh`` after welding equal vertex positions, and the welded vertex count."""
    welded, index = np.unique(mesh.vertices, axis=0, return_inverse=True)
    f = index.ravel()[mesh.faces]
    return np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), len(welded)


def closed_and_oriented(edges) -> bool:
    """Every edge has exactly two faces, which run along it in opposite directions."""
    directed, count = np.unique(edges, axis=0, return_counts=True)
    reverse = np.unique(edges[:, ::-1], axis=0)
    return bool(np.all(count == 1) and len(directed) == len(reverse) and np.array_equal(directed, reverse))


@pytest.mark.parametrize("resolution", [16, 47])
@pytest.mark.parametrize("shape, euler", [("torus", 0), ("catmark_cube", 2), ("catmark_pyramid", 2)])
def test_leaf_mesh_is_crack_free(device, shape, euler, resolution):
    """Section 5.3: leaves of mixed depth tessellate into a closed, consistently oriented mesh, while two
    triangles per leaf alone leave T-junction cracks. The pyramid's table has patches of two sizes (a
    side of one is half a side of its neighbour)."""
    if shape == "torus":
        table = grid_patch_table(torus_net(), True, True)
    else:
        table = SubdivisionSurface.load(require_models() / "ccss" / f"{shape}.obj").patch_table(device)
    vox = vz.voxelize(device, table, resolution)
    assert len(np.unique(vox.level)) >= 2                      # mixed depths occur
    leaves = vox.tessellate()
    mesh = leaves.mesh
    edges, nvertices = oriented_edges(mesh)
    assert nvertices == len(mesh.vertices)                     # no two vertices at one position
    assert closed_and_oriented(edges)
    assert nvertices - len(edges) // 2 + len(mesh.faces) == euler
    assert leaves.stats["polygons"] > 0 and leaves.stats["inserted"] > 0
    # evaluations of one point by two patches differ only by float32 rounding (a wrong side mapping
    # across patches would weld points a leaf apart)
    assert leaves.stats["weld_spread"] < 1e-3
    # the sides found to be one curve are those the table says have a neighbour
    a, b, _, span = vz.matching_sides(vox)
    matched = np.zeros(4 * len(table.first), bool)
    matched[np.concatenate([a, b])] = True
    assert np.array_equal(matched, np.asarray(table.neighbors).ravel() >= 0)
    assert leaves.stats["open_sides"] == 0
    # outward (du x dv) orientation: positive enclosed volume
    a, b, c = (mesh.vertices[mesh.faces[:, k]].astype(np.float64) for k in range(3))
    assert np.einsum("ij,ij->i", a, np.cross(b, c)).sum() > 0
    # every triangle belongs to a leaf and every sample vertex is its leaf corner's position
    sample = leaves.vertex_sample
    assert np.array_equal(np.unique(leaves.face_leaf), np.arange(vox.nleaves))
    corners = vox.corners.reshape(-1, 3)
    assert np.all(np.abs(mesh.vertices[sample >= 0] - corners[sample[sample >= 0]]) == 0)
    # without crack elimination (two triangles per leaf, corners welded) edges are left with one face
    naive = Mesh(corners, (4 * np.arange(vox.nleaves)[:, None, None] + np.array([[0, 1, 2], [0, 2, 3]])).reshape(-1, 3))
    assert not closed_and_oriented(oriented_edges(naive)[0])


def sides_by_geometry(vox):
    """Every pair of patch sides that are one curve, searched among all sides by a KD-tree (no table
    neighbours): (a, b, start, span) as vz.matching_sides returns them."""
    count = (1 << vz.SIDE_LOG) + 1
    points = vz.side_samples(vox)
    tol = vz.SIDE_MATCH * vox.voxel_size
    tree = cKDTree(points.reshape(-1, 3))
    ends = []
    for j in (0, count - 1):                       # (side a, side b, nearest sample of b) at a's start, end
        hits = cKDTree(points[:, j]).sparse_distance_matrix(tree, tol, output_type="ndarray")
        hit = np.stack([hits["i"], hits["j"] // count, hits["j"] % count], axis=1).astype(np.int64)
        hit = hit[np.lexsort((hits["v"], hit[:, 1], hit[:, 0]))]
        first = np.ones(len(hit), bool)
        first[1:] = np.any(hit[1:, :2] != hit[:-1, :2], axis=1)
        ends.append({(a, b): j for a, b, j in hit[first]})
    pairs = []
    for (a, b), j0 in ends[0].items():
        j1 = ends[1].get((a, b))
        span = None if j1 is None else j1 - j0
        if a == b or not span or abs(span) & (abs(span) - 1):
            continue
        steps = [(i, j0 * (count - 1) + i * span) for i in range(count)]      # b's t in 2^-2 SIDE_LOG units
        on = [(i, t // (count - 1)) for i, t in steps if t % (count - 1) == 0]
        if all(np.linalg.norm(points[a, i] - points[b, jb]) <= tol for i, jb in on):
            pairs.append((a, b, j0, span))
    return sorted(pairs)


@pytest.mark.parametrize("scene", ["torus", "cube", "toroidal_tet", "suzanne"])
def test_side_pairs_from_table_neighbours_are_those_found_by_geometry(device, scene):
    """The tessellation's side pairs start from the table's (topological) neighbours: on the voxel
    scenes they are exactly the pairs a search among every side finds by position alone."""
    from shadowcl.scene import Scene
    from shadowcl.voxel import scene_patches

    table = scene_patches(device, Scene.load(SCENES / "subdivision" / f"{scene}.toml"))
    vox = vz.voxelize(device, table, 32)
    a, b, start, span = vz.matching_sides(vox)
    assert len(a) > 0
    assert sorted(zip(a.tolist(), b.tolist(), start.tolist(), span.tolist())) == sides_by_geometry(vox)


def test_eval_points_match_reference(device, rng):
    table = SubdivisionSurface.load(require_models() / "ccss" / "catmark_pyramid.obj").patch_table(device)
    vox = vz.voxelize(device, table, 8)
    patch = rng.integers(0, len(table.first), 2000)
    u, v = rng.random(2000), rng.random(2000)
    u[:100], v[:100] = 0.0, 0.0                            # the extraordinary vertex itself
    u[100:200] = 1.0
    got = vox.evaluate(patch, u, v)
    want = ref.patch_eval(table.points, table.first, table.levels, patch, u.astype(np.float32), v.astype(np.float32))
    # float32: 16 control points of magnitude ~1 rounded to 2^-24 each, the basis too
    assert np.abs(got - want).max() < 1e-5
    with pytest.raises(ValueError, match="u, v"):
        vox.evaluate([0], [1.5], [0.0])
    with pytest.raises(ValueError, match="patch"):
        vox.evaluate([len(table.first)], [0.5], [0.5])


def test_open_surface_boundary_is_the_table_boundary(device):
    """On an open surface (the tent) only the table's boundary sides stay open: every one-face edge of
    the leaf mesh lies on one."""
    table = SubdivisionSurface.load(require_models() / "ccss" / "catmark_tent.obj").patch_table(device)
    vox = vz.voxelize(device, table, 24)
    leaves = vox.tessellate()
    assert leaves.stats["open_sides"] == int(np.sum(np.asarray(table.neighbors) < 0)) > 0
    f = leaves.mesh.faces
    assert oriented_edges(leaves.mesh)[1] == len(leaves.mesh.vertices)     # so mesh indices are welded ones
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    undirected, count = np.unique(np.sort(edges, axis=1), axis=0, return_counts=True)
    assert set(count.tolist()) == {1, 2}
    # a one-face edge joins two vertices on a boundary side: samples at u or v = 0 or 1 of a patch
    # whose side there has no neighbour
    sample = leaves.vertex_sample[undirected[count == 1]].ravel()
    assert np.all(sample >= 0)
    leaf, corner = sample // 4, sample % 4
    rect = vox.rect[leaf]
    u = rect[:, 0] + rect[:, 2] * np.isin(corner, (1, 2))
    v = rect[:, 1] + rect[:, 3] * np.isin(corner, (2, 3))
    nb = np.asarray(table.neighbors)[vox.patch[leaf]]
    on_open = (((v == 0) & (nb[:, 0] < 0)) | ((u == 1) & (nb[:, 1] < 0)) | ((v == 1) & (nb[:, 2] < 0))
               | ((u == 0) & (nb[:, 3] < 0)))
    assert np.all(on_open)


def test_leaves_come_out_in_the_same_order_every_run(device):
    """Leaves are appended by atomics in any order; the voxelizer sorts them so runs are reproducible."""
    table = grid_patch_table(torus_net(), True, True)
    first, second = vz.voxelize(device, table, 48, 26), vz.voxelize(device, table, 48, 26)
    assert len(first.leaves) > 1000
    np.testing.assert_array_equal(first.leaves, second.leaves)
    keys = first.leaves[:, :4].astype(np.int64)
    assert np.all(np.diff(np.lexsort(keys[:, ::-1].T)) == 1)      # sorted by (patch, level, iu, iv)
    np.testing.assert_array_equal(first.tessellate().mesh.faces, second.tessellate().mesh.faces)
