/* voxel.cl: Lai & Cheng's shadow determination on a voxelization (section 4) and the frame-buffer
 * states (section 5.2). Input: the leaves of kernels/voxelize.cl (LEAF_WORDS words each: patch, level,
 * iu, iv, 4 corner positions, 4 corner voxel ids). A *sample* is a leaf corner: sample s is corner
 * s & 3 of leaf s >> 2.
 *
 * Build options:
 *   LIGHT_POINT  1: point light at (lx, ly, lz); 0: directional light travelling along (lx, ly, lz) (unit)
 *   NVIEWS, PERSPECTIVE: the light-space grid (lightspace.h)
 *
 * Sample states: 1 lit, 2 shadowed, 3 "no cell" (behind a single perspective view: the host raises).
 * Both determinations first apply the rule every method shares: a sample whose normal faces away from
 * the light (N . (L - A) <= 0) is in shadow (section 4.1, "definitely in shadow").
 */
#include "subdivision.h"
#include "lightspace.h"
#include "ray_triangle.h"
#include "lists.h"

#ifndef LIGHT_POINT
#define LIGHT_POINT 1
#endif
#define LEAF_WORDS 20

/* Unit direction from a towards the light and the distance along it (directional: the depth along
 * the light's travel, measured from the plane through the origin). */
INLINE float to_light(float ax, float ay, float az, float lx, float ly, float lz, float *bx, float *by, float *bz)
{
#if LIGHT_POINT
    const float dx = lx - ax, dy = ly - ay, dz = lz - az;
    const float d = SC_SQRT(dx * dx + dy * dy + dz * dz);
    const float inv = d > 0.0f ? 1.0f / d : 0.0f;
    *bx = dx * inv; *by = dy * inv; *bz = dz * inv;
    return d;
#else
    *bx = -lx; *by = -ly; *bz = -lz;
    return ax * lx + ay * ly + az * lz;
#endif
}

/* Sample s = corner s & 3 of leaf s >> 2: its position A, normal N and unit direction b to the light.
 * 0 when N faces away from the light (N.b <= 0: in shadow, DESIGN.md's rule). */
INLINE int lit_side(__global const uint *leaves, __global const float *normals, int s, float lx, float ly, float lz,
                    float *ax, float *ay, float *az, float *nx, float *ny, float *nz, float *bx, float *by, float *bz)
{
    __global const uint *r = leaves + LEAF_WORDS * (s >> 2);
    const int c = s & 3;
    *ax = as_float(r[4 + 3 * c]); *ay = as_float(r[5 + 3 * c]); *az = as_float(r[6 + 3 * c]);
    *nx = normals[3 * s]; *ny = normals[3 * s + 1]; *nz = normals[3 * s + 2];
    to_light(*ax, *ay, *az, lx, ly, lz, bx, by, bz);
    return dot3(*nx, *ny, *nz, *bx, *by, *bz) > 0.0f;
}

/* Per leaf: its quad (12 floats, for the light-space lists), its two triangles (0, 1, 2) and (0, 2, 3)
 * (18 floats, for dot5 records), the unit normals du x dv at its corners (12 floats; at an
 * extraordinary vertex, where the derivatives vanish, a quarter step into the leaf), its sort key
 * (the centroid's distance to the light) and its corner voxels packed as i << 20 | j << 10 | k (4 uints;
 * R <= 1024), which the topology walk compares without divisions. */
__kernel void leaf_geometry(__global const uint *leaves, int nleaves, __global const float *points,
                            __global const uint *first, __global const uint *levels, float lx, float ly, float lz,
                            int resolution, __global float *quads, __global float *tris, __global float *normals,
                            __global float *keys, __global uint *packed)
{
    const int l = get_global_id(0);
    if (l >= nleaves)
        return;
    __global const uint *r = leaves + LEAF_WORDS * l;
    const uint patch = r[0], level = r[1], iu = r[2], iv = r[3];
    const float step = as_float((127u - level) << 23);
    float c[12];
    for (int k = 0; k < 12; ++k) {
        c[k] = as_float(r[4 + k]);
        quads[12 * l + k] = c[k];
    }
    const int order[6] = {0, 1, 2, 0, 2, 3};
    for (int t = 0; t < 6; ++t)
        for (int k = 0; k < 3; ++k)
            tris[18 * l + 3 * t + k] = c[3 * order[t] + k];
    for (int q = 0; q < 4; ++q) {
        const float fu = (float)(iu + (uint)((q == 1) | (q == 2))), fv = (float)(iv + (uint)(q >= 2));
        float3 du, dv;
        patch_eval(points, first[patch], levels[patch], fu * step, fv * step, &du, &dv);
        float3 n = cross(du, dv);
        if (!(dot(n, n) > 0.0f)) {
            /* a quarter step towards the leaf's centre */
            const float su = ((q == 1) | (q == 2)) ? -0.25f : 0.25f, sv = (q >= 2) ? -0.25f : 0.25f;
            patch_eval(points, first[patch], levels[patch], (fu + su) * step, (fv + sv) * step, &du, &dv);
            n = cross(du, dv);
        }
        const float len = SC_SQRT(dot(n, n));
        n = len > 0.0f ? n / len : n;
        normals[12 * l + 3 * q] = n.x; normals[12 * l + 3 * q + 1] = n.y; normals[12 * l + 3 * q + 2] = n.z;
    }
    for (int q = 0; q < 4; ++q) {
        const uint id = r[16 + q], R = (uint)resolution;
        packed[4 * l + q] = (id / (R * R)) << 20 | ((id / R) % R) << 10 | (id % R);
    }
    const float mx = 0.25f * (c[0] + c[3] + c[6] + c[9]), my = 0.25f * (c[1] + c[4] + c[7] + c[10]);
    const float mz = 0.25f * (c[2] + c[5] + c[8] + c[11]);
    float bx, by, bz;
    keys[l] = to_light(mx, my, mz, lx, ly, lz, &bx, &by, &bz);
}

#define ITEM_NEARER(items, keys, i, j) (keys[items[i]] < keys[items[j]])
#define SWAP_ITEMS(items, i, j) { const int item_ = items[i]; items[i] = items[j]; items[j] = item_; }
SC_DEFINE_SEGMENT_SORT(sort_items, __global int *, __global const float *, ITEM_NEARER, SWAP_ITEMS)

/* Sorts each cell's list (CSR offsets/items over ncells cells) by keys[item], nearest the light first:
 * a shadowed sample's walk then usually stops at its first test (section 4.2). */
__kernel void sort_lists(__global const int *offsets, __global int *items, int ncells, __global const float *keys)
{
    const int cell = get_global_id(0);
    if (cell >= ncells)
        return;
    sort_items(items + offsets[cell], keys, offsets[cell + 1] - offsets[cell]);
}

/* 1 when some corner voxel of leaf q is within one voxel (Chebyshev) of voxel (i, j, k): q is the
 * sample's own leaf, a leaf sharing its corner or edge, or one closer than a voxel, none of which the
 * voxelization can tell from the sample's own surface. */
INLINE int near_leaf(__global const uint *packed, int q, uint voxel)
{
    int near = 0;
    for (int c = 0; c < 4; ++c) {
        const uint id = packed[4 * q + c];
        near |= (abs((int)(id >> 20) - (int)(voxel >> 20)) <= 1) &
                (abs((int)((id >> 10) & 1023u) - (int)((voxel >> 10) & 1023u)) <= 1) &
                (abs((int)(id & 1023u) - (int)(voxel & 1023u)) <= 1);
    }
    return near;
}

/* Topology-based determination (section 4.2): sample A is in shadow when its ray to the light hits one
 * of the two triangles (dot5, Badouel) of a leaf listed in A's cells that is not near A's voxel
 * (near_leaf). Lists sorted nearest first; the walk stops at the first hit. */
__kernel void topology_shadow(__global const uint *leaves, int nsamples, __global const float *normals,
                              __global const uint *packed, __global const float *dot5, __constant float *views, __global const int *offsets,
                              __global const int *items, float lx, float ly, float lz, __global uchar *state)
{
    const int s = get_global_id(0);
    if (s >= nsamples)
        return;
    float ax, ay, az, nx, ny, nz, bx, by, bz;
    if (!lit_side(leaves, normals, s, lx, ly, lz, &ax, &ay, &az, &nx, &ny, &nz, &bx, &by, &bz)) {
        state[s] = 2;
        return;
    }
#if LIGHT_POINT
    const float dx = lx - ax, dy = ly - ay, dz = lz - az, tmax = 1.0f;
#else
    const float dx = -lx, dy = -ly, dz = -lz, tmax = SC_BIG;
#endif
    float w;
    int coarse;
    const int fine = ls_point_cells(views, ax, ay, az, &w, &coarse);
    if (!(w > 0.0f)) {
        state[s] = 3;
        return;
    }
    const uint voxel = packed[s];
    int hit = 0;
    for (int pass = 0; pass < 2 && !hit; ++pass) {
        const int cell = pass == 0 ? fine : coarse;
        for (int e = offsets[cell]; e < offsets[cell + 1] && !hit; ++e) {
            const int q = items[e];
            if (near_leaf(packed, q, voxel))
                continue;
            hit = dot5_hit(ax, ay, az, dx, dy, dz, dot5 + DOT5_FLOATS * (2 * q), 0.0f, tmax) |
                  dot5_hit(ax, ay, az, dx, dy, dz, dot5 + DOT5_FLOATS * (2 * q + 1), 0.0f, tmax);
        }
    }
    state[s] = hit ? 2 : 1;
}

/* Offset-based determination, step 1 (section 4.1): the projection plane keeps, per fine cell, the
 * smallest distance to the light of the samples projecting into it (positive floats order as their
 * bits, so atomic_min on the bits is a float min). */
__kernel void offset_depth(__global const uint *leaves, int nsamples, __constant float *views,
                           float lx, float ly, float lz, float depth_offset, volatile __global int *depth)
{
    const int s = get_global_id(0);
    if (s >= nsamples)
        return;
    __global const uint *r = leaves + LEAF_WORDS * (s >> 2);
    const int c = s & 3;
    const float ax = as_float(r[4 + 3 * c]), ay = as_float(r[5 + 3 * c]), az = as_float(r[6 + 3 * c]);
    float bx, by, bz, w;
    int coarse;
    const float d = to_light(ax, ay, az, lx, ly, lz, &bx, &by, &bz) + depth_offset;
    const int fine = ls_point_cells(views, ax, ay, az, &w, &coarse);
    if (w > 0.0f)
        atomic_min(&depth[fine], as_int(SC_MAX(d, 0.0f)));
}

/* Offset-based determination, step 2: move A by `offset` (sqrt(2) voxels) along its normal to A',
 * project A' along the beam through A (onto the plane through A across the beam: A'' = A' - ((A' - A).b) b)
 * and call A shadowed when A' is farther from the light than the nearest sample of A'''s cell. */
__kernel void offset_shadow(__global const uint *leaves, int nsamples, __global const float *normals,
                            __constant float *views, float lx, float ly, float lz, float depth_offset, float offset,
                            __global const int *depth, __global uchar *state)
{
    const int s = get_global_id(0);
    if (s >= nsamples)
        return;
    float ax, ay, az, nx, ny, nz, bx, by, bz;
    if (!lit_side(leaves, normals, s, lx, ly, lz, &ax, &ay, &az, &nx, &ny, &nz, &bx, &by, &bz)) {
        state[s] = 2;
        return;
    }
    /* A' and its projection A'' along the beam through A (b points to the light) */
    const float px = ax + offset * nx, py = ay + offset * ny, pz = az + offset * nz;
    const float along = offset * dot3(nx, ny, nz, bx, by, bz);
    const float qx = px - along * bx, qy = py - along * by, qz = pz - along * bz;
    float w, ex, ey, ez;
    int coarse;
    const int fine = ls_point_cells(views, qx, qy, qz, &w, &coarse);
    if (!(w > 0.0f)) {
        state[s] = 3;
        return;
    }
    const float d = to_light(ax, ay, az, lx, ly, lz, &ex, &ey, &ez) - along + depth_offset;
    state[s] = d > as_float(depth[fine]) ? 2 : 1;
}

/* Frame-buffer states from sample states (section 5.2): occupied voxels hold 3 after voxelization.
 * Phase 0: every lit sample clears its voxel's "shadowed" bit (3 -> 1, lit). Phase 1 (after phase 0):
 * every shadowed sample whose voxel is still 3 clears the "lit" bit (3 -> 2, shadowed). A voxel with
 * both lit and shadowed samples ends lit. */
__kernel void write_states(__global const uint *leaves, int nsamples, __global const uchar *state, int phase,
                           volatile __global uint *frame)
{
    const int s = get_global_id(0);
    if (s >= nsamples)
        return;
    const uint id = leaves[LEAF_WORDS * (s >> 2) + 16 + (s & 3)];
    const uint shift = 2u * (id & 15u);
    if (phase == 0 && state[s] == 1)
        atomic_and(&frame[id >> 4], ~(2u << shift));
    if (phase == 1 && state[s] == 2 && ((frame[id >> 4] >> shift) & 3u) == 3u)
        atomic_and(&frame[id >> 4], ~(1u << shift));
}

/* The state (0 empty, 1 lit, 2 shadowed) of linear voxel id v: from the 2-bit frame buffer `frame`
 * (SPARSE 0), or by binary search in the sorted voxel ids `keys` (nkeys, uint) with their `values` (SPARSE
 * 1: section 5.1, no frame buffer). */
#ifndef SPARSE
#define SPARSE 0
#endif
INLINE uint voxel_state(const __global uint *frame, const __global uint *keys, const __global uchar *values,
                        int nkeys, uint v)
{
#if SPARSE
    int lo = 0, hi = nkeys;
    while (lo < hi) {
        const int mid = (lo + hi) >> 1;
        if (keys[mid] < v) lo = mid + 1; else hi = mid;
    }
    return lo < nkeys && keys[lo] == v ? (uint)values[lo] : 0u;
#else
    return (frame[v >> 4] >> (2u * (v & 15u))) & 3u;
#endif
}

/* lookup_states: one work-item per linear voxel id; states[i] = its state. */
__kernel void lookup_states(const __global uint *ids, int n, const __global uint *frame, const __global uint *keys,
                            const __global uchar *values, int nkeys, __global uchar *states)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    states[i] = (uchar)voxel_state(frame, keys, values, nkeys, ids[i]);
}

/* locate_states: one work-item per point, given its voxel (i, j, k) (computed on the host in float64,
 * possibly outside the grid). Its voxel's id and state when occupied, else the first occupied voxel
 * among `offsets` (noffsets (di, dj, dk), nearest first: classify's search), else id -1, state 0. */
__kernel void locate_states(const __global int *ijk, int n, int resolution, const __global int *offsets, int noffsets,
                            const __global uint *frame, const __global uint *keys, const __global uchar *values,
                            int nkeys, __global int *ids, __global uchar *states)
{
    const int p = get_global_id(0);
    if (p >= n) return;
    const int x = ijk[3 * p], y = ijk[3 * p + 1], z = ijk[3 * p + 2];
    int id = -1;
    uint state = 0u;
    for (int j = -1; j < noffsets && state == 0u; ++j) {     /* j = -1: the point's own voxel */
        const int cx = j < 0 ? x : x + offsets[3 * j], cy = j < 0 ? y : y + offsets[3 * j + 1],
                  cz = j < 0 ? z : z + offsets[3 * j + 2];
        if (cx < 0 || cy < 0 || cz < 0 || cx >= resolution || cy >= resolution || cz >= resolution)
            continue;
        const uint v = ((uint)cx * (uint)resolution + (uint)cy) * (uint)resolution + (uint)cz;
        state = voxel_state(frame, keys, values, nkeys, v);
        if (state != 0u) id = (int)v;
    }
    ids[p] = id;
    states[p] = (uchar)state;
}
