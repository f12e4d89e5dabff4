/* voxelize.cl: Lai & Cheng's parameter-space voxelization (section 3) as a breadth-first work queue.
 *
 * A work item is a subpatch (patch, level, iu, iv): the parameter square [iu, iu + 1] x [iv, iv + 1]
 * scaled by 2^-level of patch `patch` of the patch table (subdivision.h). Every corner parameter is an
 * integer times 2^-level, exact in float32 for level <= 24, so a corner shared by two subpatches of a
 * patch is evaluated from bit-identical (u, v) and lands in the same voxel.
 *
 * Per item: evaluate the four corners (0: (u0, v0), 1: (u1, v0), 2: (u1, v1), 3: (u0, v1)), map each to
 * its voxel floor((p - origin) * inv_size) clamped to [0, R - 1]^3, and test that the four corner
 * voxels fit in a 2 x 2 x 2 block (the diagonals too: a ring of four diagonal steps would leave the
 * voxel in its middle empty, a hole) and that the corner voxels of each edge (0-1, 1-2, 2-3, 3-0) are
 * N-adjacent (CONNECTIVITY = 26: Chebyshev distance <= 1; 18: that and at most two
 * axes differ; 6: at most one axis differs, by one; equal voxels are adjacent). All that holds (or
 * level == MAX_DEPTH, or every edge shorter than MIN_EDGE voxels: counted as forced): a leaf; its record goes to `leaves` and its corner voxels
 * into the frame buffer. Otherwise four children go to the next level's queue.
 *
 * Fixed capacities: `counters[0]` counts children items wanted (written only below `out_capacity`),
 * `counters[1]` leaves (written only below `leaf_capacity`), `counters[2]` forced leaves. The host
 * checks both against the capacities and, on overflow, grows the buffers and reruns the level with the
 * leaf counter restored (frame-buffer writes are idempotent ORs). The host never launches a level whose
 * counters could pass INT_MAX (voxelize.COUNTER_MAX); a negative slot is refused here all the same.
 *
 * Leaf record (LEAF_WORDS = 20 32-bit words): patch, level, iu, iv (uint), the four corner positions
 * (12 float), the four corner voxels' linear indices (i * R + j) * R + k (uint; R <= 1024).
 * Frame buffer (FRAME_BUFFER = 1): 2 bits per voxel, 16 voxels per uint, voxel v in word v >> 4 at bit
 * 2 * (v & 15); voxelization ORs 3 ("occupied, state not yet determined", see voxel.cl).
 */
#include "subdivision.h"

#ifndef CONNECTIVITY
#define CONNECTIVITY 26
#endif
#ifndef FRAME_BUFFER
#define FRAME_BUFFER 1
#endif
#define MAX_DEPTH 24
#define MIN_EDGE (1.0f / 64.0f)
#define LEAF_WORDS 20

/* 1 when voxels a and b are equal or N-adjacent for N = CONNECTIVITY. */
INLINE int voxels_adjacent(int ai, int aj, int ak, int bi, int bj, int bk)
{
    const int di = abs(ai - bi), dj = abs(aj - bj), dk = abs(ak - bk);
    const int near = (di <= 1) & (dj <= 1) & (dk <= 1);
#if CONNECTIVITY == 26
    return near;
#elif CONNECTIVITY == 18
    return near & (di + dj + dk <= 2);
#else
    return near & (di + dj + dk <= 1);
#endif
}

/* The voxel of position p (clamped in float first, so any finite value gives a valid voxel). */
INLINE int voxel_coord(float p, float origin, float inv_size, int resolution)
{
    return (int)SC_MIN(SC_MAX(SC_FLOOR((p - origin) * inv_size), 0.0f), (float)(resolution - 1));
}

/* One level of the queue. items_in: n_in uint4 (patch, level, iu, iv); items_out: next level's queue. */
__kernel void voxelize_level(__global const float *points, __global const uint *first, __global const uint *levels,
                             __global const uint *items_in, int n_in, __global uint *items_out, int out_capacity,
                             __global uint *leaves, int leaf_capacity, volatile __global int *counters,
                             __global uint *frame, float ox, float oy, float oz, float inv_size, int resolution)
{
    const int gid = get_global_id(0);
    if (gid >= n_in)
        return;
    const uint patch = items_in[4 * gid], level = items_in[4 * gid + 1];
    const uint iu = items_in[4 * gid + 2], iv = items_in[4 * gid + 3];
    const float step = as_float((127u - level) << 23);  /* 2^-level, exact */
    const uint f = first[patch], nlev = levels[patch];

    /* Evaluate the corners and find their voxels */
    float pos[12];
    int vox[12];
    for (int c = 0; c < 4; ++c) {
        const uint cu = iu + (uint)((c == 1) | (c == 2)), cv = iv + (uint)(c >= 2);
        const float3 p = patch_eval(points, f, nlev, (float)cu * step, (float)cv * step, 0, 0);
        pos[3 * c] = p.x; pos[3 * c + 1] = p.y; pos[3 * c + 2] = p.z;
        vox[3 * c] = voxel_coord(p.x, ox, inv_size, resolution);
        vox[3 * c + 1] = voxel_coord(p.y, oy, inv_size, resolution);
        vox[3 * c + 2] = voxel_coord(p.z, oz, inv_size, resolution);
    }
    /* Small enough when the corner voxels fit in a 2 x 2 x 2 block and each edge's are N-adjacent */
    int small = 1;
    float longest = 0.0f;
    for (int a = 0; a < 4; ++a) {
        const int b = (a + 1) & 3, c = (a + 2) & 3;
        small &= voxels_adjacent(vox[3 * a], vox[3 * a + 1], vox[3 * a + 2], vox[3 * b], vox[3 * b + 1], vox[3 * b + 2]);
        small &= (abs(vox[3 * a] - vox[3 * c]) <= 1) & (abs(vox[3 * a + 1] - vox[3 * c + 1]) <= 1) &
                 (abs(vox[3 * a + 2] - vox[3 * c + 2]) <= 1);
        const float ex = pos[3 * a] - pos[3 * b], ey = pos[3 * a + 1] - pos[3 * b + 1], ez = pos[3 * a + 2] - pos[3 * b + 2];
        longest = SC_MAX(longest, ex * ex + ey * ey + ez * ez);
    }
    /* Edges shorter than MIN_EDGE voxels that still skip a voxel run along a voxel edge or corner:
     * splitting cannot separate them further, so they become forced leaves */
    const int tiny = longest * inv_size * inv_size < MIN_EDGE * MIN_EDGE;

    if (!small && !tiny && level < MAX_DEPTH) {
        /* Split: four children at level + 1 */
        const int slot = atomic_add(&counters[0], 4);
        if (slot < 0 || slot > out_capacity - 4)
            return;
        for (int c = 0; c < 4; ++c) {
            __global uint *o = items_out + 4 * ((size_t)slot + c);
            o[0] = patch; o[1] = level + 1u; o[2] = 2u * iu + (uint)(c & 1); o[3] = 2u * iv + (uint)(c >> 1);
        }
        return;
    }
    /* Leaf: record it and mark its corner voxels */
    if (!small)
        atomic_inc(&counters[2]);
    const int slot = atomic_inc(&counters[1]);
    uint ids[4];
    for (int c = 0; c < 4; ++c)
        ids[c] = ((uint)vox[3 * c] * (uint)resolution + (uint)vox[3 * c + 1]) * (uint)resolution + (uint)vox[3 * c + 2];
#if FRAME_BUFFER
    for (int c = 0; c < 4; ++c)
        atomic_or(&frame[ids[c] >> 4], 3u << (2u * (ids[c] & 15u)));
#endif
    if (slot < 0 || slot >= leaf_capacity)
        return;
    __global uint *r = leaves + (size_t)LEAF_WORDS * slot;
    r[0] = patch; r[1] = level; r[2] = iu; r[3] = iv;
    for (int k = 0; k < 12; ++k)
        r[4 + k] = as_uint(pos[k]);
    for (int c = 0; c < 4; ++c)
        r[16 + c] = ids[c];
}

/* Limit positions of `count` points: out[3 i .. 3 i + 2] = patch_eval of patch `patch[i]` at
 * (uv[2 i], uv[2 i + 1]). The crack-free tessellation (voxelize.py: tessellate) samples patch sides with
 * it to find which sides, or pieces of sides, are one curve. */
__kernel void eval_points(global const float* points, global const uint* first, global const uint* levels,
                          global const uint* patch, global const float* uv, int count, global float* out)
{
    const int i = get_global_id(0);
    if (i >= count) return;
    const uint p = patch[i];
    const float3 x = patch_eval(points, first[p], levels[p], uv[2 * i], uv[2 * i + 1], 0, 0);
    out[3 * i] = x.x;
    out[3 * i + 1] = x.y;
    out[3 * i + 2] = x.z;
}
