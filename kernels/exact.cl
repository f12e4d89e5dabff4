/* exact.cl: exact hard shadows, receivers binned by light-space cell and classified LANES at a time
 * against their cells' lists (their fine cell's and their coarse cell's: lightspace.h).
 *
 * Meaning (DESIGN.md): a receiver p is in shadow when the segment from s to a point light (the ray
 * from s against a directional light's travel direction) hits a triangle at a distance greater than eps
 * from s and before the light; s = p + eps n when normals are given, else s = p. A normal facing away
 * from the light (n . (light - p) <= 0) is in shadow without testing.
 *
 * The passes: the count / scan / fill of the occluder lists (lightspace.cl) applied to the receivers,
 * then the walk in the irregular Z-buffer's traversal order (the receivers of a cell together):
 *   exact_bin_count  per LANES receivers: check them, start them (s, over lanes), find each one's fine
 *                    cell, write its Start (s and the cell) in the caller's order and count it in the
 *                    cell (its slot by atomic_inc on the cell's count, or _ends: two halves counted
 *                    serially in rows of their own); the code of a receiver needing no walk
 *   (device)         exclusive prefix sum of the counts (lists.prefix_sum)
 *   exact_bin_fill   per walking receiver: its Start, tagged with its index, at its place in its cell
 *                    (at its slot, or _ends: the two halves replayed, one filling the cells from the
 *                    front, one from the back)
 *   exact_classify   per packet of LANES consecutive binned receivers (tmin and the cells found again
 *                    from s, over lanes): the receivers of a cell share its list,
 *                    each triangle is loaded once and tested against all the packet's lanes still
 *                    unshadowed (plane and cone tests over lanes, the watertight test near edges:
 *                    ray_triangle.h), the walk ends when they are all shadowed; each answer is written
 *                    at its receiver's index.
 * A packet spanning several cells walks each of their lists with that cell's lanes. exact_classify_points
 * (LANES 1) is the other order: one receiver per work-item as given, no binning. Points a single
 * perspective view cannot place (behind it: only possible outside the prepared bounds) are binned in
 * one more cell, brute_cell = the grid's cell count, whose list is every triangle.
 *
 * Build options:
 *   LIGHT_POINT   1: point light at (lx, ly, lz); 0: directional light travelling along (lx, ly, lz) (unit)
 *   TEST_DOT5     0: watertight test (after the plane cull) on WT_FLOATS records; 1: dot5 on DOT5_FLOATS
 *   LISTS_LINKED  0: CSR lists (offsets, items); 1: linked lists (heads, nodes)
 *   INPUT_F64     1: points and normals arrive as float64 as the caller gave them, and are moved into
 *                 the working frame ((x - c) * inv_scale, inv_scale a power of two: shadowcl.frame), made
 *                 relative to (ox, oy, oz) and rounded here, exactly as the host would (needs
 *                 cl_khr_fp64); 0: they arrive as float32, already moved and relative (c 0, inv_scale 1)
 *   LANES         receivers per packet (vecmath.h)
 *   NVIEWS, PERSPECTIVE: the light-space grid (lightspace.h)
 * Everything else (normals given or not, coarse lists empty or not) is an argument: one program serves
 * a prepared method's every kernel and call (on PoCL each build costs ~0.2 s of a cold start).
 *
 * Codes in out[i]: 1 in shadow, 0 lit, 3 the point is not finite, 4 the normal is zero or not finite
 * (the host raises for 3 and 4), FAR (5) the point lies beyond the near box (answered by the host).
 */
#include "lightspace.h"
#include "ray_triangle.h"

#ifndef LIGHT_POINT
#define LIGHT_POINT 1
#endif
#ifndef TEST_DOT5
#define TEST_DOT5 0
#endif
#ifndef LISTS_LINKED
#define LISTS_LINKED 0
#endif

/* Whole packets of 8 move their receivers' rows and records as vectors, with clang's shuffles (the last,
 * partial packet one receiver at a time) */
#if LANES == 8 && defined(__clang__)
#define WHOLE_PACKETS 1
#else
#define WHOLE_PACKETS 0
#endif

#define SC_FINITE(x) ((x) - (x) == 0.0f)
/* A coordinate moved into the working frame and made relative to the local origin, in the input
 * precision (one receiver or lanes): as the host would, (x - c) * inv_scale - o */
#define FRAME_MOVE(x, c, inv_scale, o) (((x) - (c)) * (inv_scale) - (o))
/* A normal's squared length float32 holds well; outside it the normal is rescaled in the input precision */
#define NORMAL_LEN2_OK(len2) (((len2) > 1.0e-30f) & ((len2) < 1.0e30f))
#define WALK 0              /* receivers_start: the receiver needs a walk */
#define FAR 5               /* receivers_start: the point lies beyond the near box (Move), answered by the host */

#if LIGHT_POINT
#define TMAX 1.0f           /* t in units of |light - s| */
#else
#define TMAX SC_BIG
#endif

/* How the caller's points reach the working frame: moved ((x - c) * inv_scale) and made relative to
 * (ox, oy, oz) in the input precision, as the host would; and the near box (lo, hi) in those coordinates:
 * a point beyond it (an infinity too) is not walked but coded FAR, for the host to answer (shadowcl.Shadows
 * clips such receivers' segments; +-inf: none is). */
typedef struct {
    input_t cx, cy, cz, inv_scale, ox, oy, oz;
    input_t lo_x, lo_y, lo_z, hi_x, hi_y, hi_z;
} Move;

#define MOVE_ARGS                                                                                    \
    input_t cx, input_t cy, input_t cz, input_t inv_scale, input_t ox, input_t oy, input_t oz,        \
        input_t lo_x, input_t lo_y, input_t lo_z, input_t hi_x, input_t hi_y, input_t hi_z
#define MOVE_OF_ARGS {cx, cy, cz, inv_scale, ox, oy, oz, lo_x, lo_y, lo_z, hi_x, hi_y, hi_z}
#define BEYOND(m, x, y, z) (((x) < (m)->lo_x) | ((x) > (m)->hi_x) | ((y) < (m)->lo_y) | ((y) > (m)->hi_y) | \
                            ((z) < (m)->lo_z) | ((z) > (m)->hi_z))

/* Receiver i moved (Move), rounded to float32 in *px, *py, *pz: FAR beyond the near box, else 3 when it
 * is not finite (NaN: never beyond), else WALK. */
INLINE int receiver_point(int i, __global const input_t *points, const Move *m, float *px, float *py, float *pz)
{
    const input_t x = FRAME_MOVE(points[3 * i], m->cx, m->inv_scale, m->ox),
                  y = FRAME_MOVE(points[3 * i + 1], m->cy, m->inv_scale, m->oy),
                  z = FRAME_MOVE(points[3 * i + 2], m->cz, m->inv_scale, m->oz);
    *px = (float)x; *py = (float)y; *pz = (float)z;
    if (BEYOND(m, x, y, z))
        return FAR;
    return (SC_FINITE(*px) & SC_FINITE(*py) & SC_FINITE(*pz)) ? WALK : 3;
}

/* Receiver i's normal in float32, not yet unit: rescaled in the input precision first when its squared
 * length would under- or overflow float32. 4 when it is zero or not finite, else WALK. */
INLINE int receiver_normal(int i, __global const input_t *normals, float *nx, float *ny, float *nz)
{
    const input_t mx = normals[3 * i], my = normals[3 * i + 1], mz = normals[3 * i + 2];
    float x = (float)mx, y = (float)my, z = (float)mz;
    const float len2 = x * x + y * y + z * z;
    if (!NORMAL_LEN2_OK(len2)) {
        const input_t big = (mx < 0 ? -mx : mx) > (my < 0 ? -my : my) ? (mx < 0 ? -mx : mx) : (my < 0 ? -my : my);
        const input_t scale = big > (mz < 0 ? -mz : mz) ? big : (mz < 0 ? -mz : mz);
        if (!(scale > 0) || !(mx - mx == 0) || !(my - my == 0) || !(mz - mz == 0))
            return 4;
        x = (float)(mx / scale); y = (float)(my / scale); z = (float)(mz / scale);
    }
    *nx = x; *ny = y; *nz = z;
    return WALK;
}

/* The lanes' directions d from s towards the light: light - s (the whole segment) for a point light,
 * the reverse of a directional light's travel */
INLINE void to_light(lfloat sx, lfloat sy, lfloat sz, float lx, float ly, float lz, lfloat *dx, lfloat *dy, lfloat *dz)
{
#if LIGHT_POINT
    *dx = lx - sx; *dy = ly - sy; *dz = lz - sz;
#else
    *dx = (lfloat)(-lx); *dy = (lfloat)(-ly); *dz = (lfloat)(-lz);
#endif
}

/* The lanes' receivers base + j (lanes past n repeat receiver n - 1), one lane at a time: their points
 * (receiver_point) and, with normals, normals (receiver_normal; 1 where the point is not walked) in
 * the lanes, and their codes (WALK, 3, 4, FAR). */
INLINE lint receivers_load_lanes(int base, int n, __global const input_t *points, __global const input_t *normals,
                                 const Move *m, int with_normals, lfloat *sx, lfloat *sy, lfloat *sz, lfloat *nx,
                                 lfloat *ny, lfloat *nz)
{
    float px[LANES], py[LANES], pz[LANES], mx[LANES], my[LANES], mz[LANES];
    int code[LANES];
    for (int j = 0; j < LANES; ++j) {
        const int i = SC_IMIN(base + j, n - 1);
        code[j] = receiver_point(i, points, m, &px[j], &py[j], &pz[j]);
        mx[j] = my[j] = mz[j] = 1.0f;
        if (with_normals && code[j] == WALK)
            code[j] = receiver_normal(i, normals, &mx[j], &my[j], &mz[j]);
    }
    *sx = LANE_LOAD(float, px); *sy = LANE_LOAD(float, py); *sz = LANE_LOAD(float, pz);
    *nx = LANE_LOAD(float, mx); *ny = LANE_LOAD(float, my); *nz = LANE_LOAD(float, mz);
    return LANE_LOAD(int, code);
}

#if WHOLE_PACKETS
/* 4 and 8 input values in vectors; input4u at the input's own alignment, so that a row-major (N, 3)
 * array can be read 4 values at a time from any row (a vector load; vload4 is a library call on PoCL) */
typedef input_t input4u __attribute__((ext_vector_type(4), aligned(sizeof(input_t))));
typedef input_t input8 __attribute__((ext_vector_type(8)));

/* Rows r .. r + 7 of a row-major (N, 3) array, as columns: six loads of 4 values, then shuffles */
INLINE void load_rows8(__global const input_t *array, int r, input8 *x, input8 *y, input8 *z)
{
    __global const input4u *v = (__global const input4u *)(array + 3 * r);
    const input8 a = __builtin_shufflevector(v[0], v[1], 0, 1, 2, 3, 4, 5, 6, 7);   /* x0 y0 z0 x1 y1 z1 x2 y2 */
    const input8 b = __builtin_shufflevector(v[2], v[3], 0, 1, 2, 3, 4, 5, 6, 7);   /* z2 x3 y3 z3 x4 y4 z4 x5 */
    const input8 c = __builtin_shufflevector(v[4], v[5], 0, 1, 2, 3, 4, 5, 6, 7);   /* y5 z5 x6 y6 z6 x7 y7 z7 */
    *x = __builtin_shufflevector(__builtin_shufflevector(a, b, 0, 3, 6, 9, 12, 15, -1, -1), c, 0, 1, 2, 3, 4, 5, 10, 13);
    *y = __builtin_shufflevector(__builtin_shufflevector(a, b, 1, 4, 7, 10, 13, -1, -1, -1), c, 0, 1, 2, 3, 4, 8, 11, 14);
    *z = __builtin_shufflevector(__builtin_shufflevector(a, b, 2, 5, 8, 11, 14, -1, -1, -1), c, 0, 1, 2, 3, 4, 9, 12, 15);
}

/* receivers_load_lanes for 8 receivers all below n, over lanes from the start (vector loads, the move
 * and the rounding over lanes): the same bits. Returns 0 (and nothing is to be used) when a normal
 * needs receiver_normal's rescaling or is bad, which receivers_load_lanes handles. */
INLINE int receivers_load_rows(int base, __global const input_t *points, __global const input_t *normals,
                               const Move *m, int with_normals, lfloat *sx, lfloat *sy, lfloat *sz, lfloat *nx,
                               lfloat *ny, lfloat *nz, lint *codes)
{
    input8 x, y, z;
    load_rows8(points, base, &x, &y, &z);
    x = FRAME_MOVE(x, m->cx, m->inv_scale, m->ox);
    y = FRAME_MOVE(y, m->cy, m->inv_scale, m->oy);
    z = FRAME_MOVE(z, m->cz, m->inv_scale, m->oz);
    *sx = __builtin_convertvector(x, lfloat); *sy = __builtin_convertvector(y, lfloat);
    *sz = __builtin_convertvector(z, lfloat);
    const lint beyond = __builtin_convertvector(BEYOND(m, x, y, z), lint);
    *codes = beyond ? (lint)FAR : (SC_FINITE(*sx) & SC_FINITE(*sy) & SC_FINITE(*sz)) ? (lint)WALK : (lint)3;
    *nx = *ny = *nz = (lfloat)1.0f;
    if (with_normals) {
        load_rows8(normals, base, &x, &y, &z);
        *nx = __builtin_convertvector(x, lfloat); *ny = __builtin_convertvector(y, lfloat);
        *nz = __builtin_convertvector(z, lfloat);
        const lfloat len2 = *nx * *nx + *ny * *ny + *nz * *nz;
        if (LANE_ANY(!NORMAL_LEN2_OK(len2)))
            return 0;
    }
    return 1;
}
#endif

/* The lanes' receivers base + j (lanes past n repeat receiver n - 1): their codes (WALK, or 1 for a
 * normal facing away from the light, 3, 4, FAR: see the top) and the starts s of those to walk, s = p +
 * eps n with n made unit (p without normals). Whole packets of 8 load their rows as vectors; the rest,
 * and a packet with a normal to rescale, one receiver at a time. The arithmetic is over lanes. */
INLINE lint receivers_start(int base, int n, __global const input_t *points, __global const input_t *normals,
                            const Move *m, float lx, float ly, float lz, float eps, int with_normals, lfloat *psx,
                            lfloat *psy, lfloat *psz)
{
    lfloat sx, sy, sz, nx, ny, nz;
    lint codes;
#if WHOLE_PACKETS
    if (!(base + LANES <= n && receivers_load_rows(base, points, normals, m, with_normals, &sx, &sy, &sz, &nx, &ny,
                                                   &nz, &codes)))
#endif
        codes = receivers_load_lanes(base, n, points, normals, m, with_normals, &sx, &sy, &sz, &nx, &ny, &nz);
    if (with_normals) {
        const lfloat inv = 1.0f / LANE_SQRT(nx * nx + ny * ny + nz * nz);
        nx *= inv; ny *= inv; nz *= inv;
        lfloat dx, dy, dz;
        to_light(sx, sy, sz, lx, ly, lz, &dx, &dy, &dz);
        codes = ((codes == WALK) & (nx * dx + ny * dy + nz * dz <= 0.0f)) ? (lint)1 : codes;
        sx += eps * nx; sy += eps * ny; sz += eps * nz;
    }
    *psx = sx; *psy = sy; *psz = sz;
    return codes;
}

/* The start of the tested part of the lanes' segments, in units of the segment (point light) or of
 * length (directional): a hit counts only beyond eps from s. */
INLINE lfloat start_tmin(lfloat sx, lfloat sy, lfloat sz, float lx, float ly, float lz, float eps)
{
#if LIGHT_POINT
    lfloat dx, dy, dz;
    to_light(sx, sy, sz, lx, ly, lz, &dx, &dy, &dz);
    return eps / LANE_SQRT(dx * dx + dy * dy + dz * dz);
#else
    return (lfloat)eps;
#endif
}

/* The fine cell the started receivers (lanes) are binned in (brute_cell where the view cannot place
 * them), in *coarse their coarse cell (-1 for brute_cell) and in *sub the fine cell's bit in it */
INLINE lint receiver_cell(__constant const float *views, int brute_cell, lfloat sx, lfloat sy, lfloat sz, lint *coarse,
                          lint *sub)
{
    lfloat w;
    const lint cell = ls_point_cells_sub(views, sx, sy, sz, &w, coarse, sub);
#if PERSPECTIVE && NVIEWS == 1
    const lint placed = w > 0.0f;
    *coarse = placed ? *coarse : (lint)-1;
    return placed ? cell : (lint)brute_cell;
#else
    return cell;
#endif
}

/* A started receiver: its start s and a tag, 16 bytes. In the count pass's output (the caller's order) the
 * tag is its fine cell, where the fill places it; in the fill's output (cell by cell: the walk's input) it
 * is the receiver's index, so that the fill scatters one record per receiver, not a start and an index to
 * two places (the walk finds the cells again from s: the same floats give the same cells). */
typedef struct {
    float x, y, z;
    int tag;
} Start;

#if WHOLE_PACKETS
/* The Starts of 8 consecutive receivers (lanes), written as four 32-byte vector stores (the records
 * transposed from the lanes by shuffles). start must be 32-byte aligned. */
INLINE void store_starts8(__global Start *start, lfloat x, lfloat y, lfloat z, lint tag)
{
    const lfloat c = as_float8(tag);
    const lfloat xy_lo = __builtin_shufflevector(x, y, 0, 8, 1, 9, 2, 10, 3, 11);      /* x0 y0 x1 y1 x2 y2 x3 y3 */
    const lfloat xy_hi = __builtin_shufflevector(x, y, 4, 12, 5, 13, 6, 14, 7, 15);
    const lfloat zc_lo = __builtin_shufflevector(z, c, 0, 8, 1, 9, 2, 10, 3, 11);
    const lfloat zc_hi = __builtin_shufflevector(z, c, 4, 12, 5, 13, 6, 14, 7, 15);
    __global float8 *r = (__global float8 *)start;
    r[0] = __builtin_shufflevector(xy_lo, zc_lo, 0, 1, 8, 9, 2, 3, 10, 11);            /* x0 y0 z0 c0 x1 y1 z1 c1 */
    r[1] = __builtin_shufflevector(xy_lo, zc_lo, 4, 5, 12, 13, 6, 7, 14, 15);
    r[2] = __builtin_shufflevector(xy_hi, zc_hi, 0, 1, 8, 9, 2, 3, 10, 11);
    r[3] = __builtin_shufflevector(xy_hi, zc_hi, 4, 5, 12, 13, 6, 7, 14, 15);
}

/* 8 consecutive Start records (32-byte aligned) as lanes: four 32-byte loads, transposed by shuffles
 * (store_starts8's inverse) */
INLINE void load_starts8(__global const Start *start, lfloat *x, lfloat *y, lfloat *z, lint *tag)
{
    __global const float8 *r = (__global const float8 *)start;
    const lfloat r0 = r[0], r1 = r[1], r2 = r[2], r3 = r[3];      /* r0: x0 y0 z0 c0 x1 y1 z1 c1 */
    const lfloat lo = __builtin_shufflevector(r0, r1, 0, 4, 8, 12, 1, 5, 9, 13);   /* x0 x1 x2 x3 y0 y1 y2 y3 */
    const lfloat hi = __builtin_shufflevector(r2, r3, 0, 4, 8, 12, 1, 5, 9, 13);   /* x4 .. x7 y4 .. y7 */
    const lfloat lo2 = __builtin_shufflevector(r0, r1, 2, 6, 10, 14, 3, 7, 11, 15);  /* z0 .. z3 c0 .. c3 */
    const lfloat hi2 = __builtin_shufflevector(r2, r3, 2, 6, 10, 14, 3, 7, 11, 15);
    *x = __builtin_shufflevector(lo, hi, 0, 1, 2, 3, 8, 9, 10, 11);
    *y = __builtin_shufflevector(lo, hi, 4, 5, 6, 7, 12, 13, 14, 15);
    *z = __builtin_shufflevector(lo2, hi2, 0, 1, 2, 3, 8, 9, 10, 11);
    *tag = as_int8(__builtin_shufflevector(lo2, hi2, 4, 5, 6, 7, 12, 13, 14, 15));
}
#endif

/* Receivers decided without a walk. Each plane cell (a square of 2^PLANE_SHIFT fine cells in a coarse cell)
 * may have a plane (exact_cell_planes), n.x = c_hi, with every triangle that a receiver of the cell can walk
 * (its fine cells' lists, and the coarse cell's entries that touch them) on or behind it, in exact
 * arithmetic on the triangles' float32 corners: a lane whose tested part of the segment stays strictly in
 * front of it meets none of them, and is lit. The plane is a triangle T's, and when T covers the whole cell
 * as the light sees it (every line from the light through the cell, the cell enlarged by PLANE_CELL_MARGIN,
 * passes through T by more than the cone test's bound), a lane whose tested part starts behind T (n.x <
 * c_lo: T's corners lie in c_lo <= n.x <= c_top) and ends in front of it (n.x > c_top) crosses T, and is in
 * shadow. Most receivers on a ground plane, or on a solid's faces, are decided so in the count pass and
 * never binned, filled or walked.
 * Along the segment n.(s + t d) = n.s + t n.d. The float32 sums n.s and n.d (4 products, FP_CONTRACT off)
 * are off by at most 4 ulps of their terms' magnitudes ms, md; PLANE_ULPS allowed. The walk's tmin = eps /
 * |d| (eps for a directional light) lies in [eps / D, eps / M] for D = |d|_1 and M = max |d_i|, each rounded
 * outwards: lit when n.s - c_hi + (eps / D) n.d > 0 (n.d >= 0) by more than the rounding (multiplied by D:
 * no division), in shadow when n.s + (eps / M) n.d < c_lo and n.(s + d) > c_top (a point light; a
 * directional light's ray goes on) by more than it, with |d|_1 within the cell's reach (point light: 16
 * times T's distance from the light, so that the computed segment's direction, off by ~1e-7, stays in the
 * enlarged cell where it meets T). A cell with no triangle is (0, 0, 0, -1, -inf): every lane lit; no plane
 * is c_hi = inf; no cover c_lo = -inf. Lanes outside `walking` are neither. */
#define PLANE_ULPS 16.0f
/* The plane cells: PLANE_CELLS per coarse cell; a lane's from its coarse cell (relative to the first) and
 * its fine cell's bit in it (LS_SUB_OF). 4 x 4 fine cells: against 2 x 2 and 8 x 8 (interleaved, one-shot,
 * 1.2 M receivers) best or level on the default scene, light_inside and city_block, with normals and without
 * (docs/exact-speed.md). */
#ifndef PLANE_SHIFT
#define PLANE_SHIFT 2       /* the host passes shadowcl.exact.PLANE_SHIFT */
#endif
#define PLANE_CELLS ((LS_COARSE >> PLANE_SHIFT) * (LS_COARSE >> PLANE_SHIFT))
#define PLANE_CELL(coarse, sub)                                                                      \
    ((coarse) * PLANE_CELLS + (((sub) & (LS_COARSE - 1)) >> PLANE_SHIFT) +                           \
     (((sub) >> LS_COARSE_SHIFT) >> PLANE_SHIFT) * (LS_COARSE >> PLANE_SHIFT))
INLINE lint decided_by_plane(__global const float8 *planes, int first_coarse, float extent, lint walking, lint coarse,
                             lint sub, lfloat sx, lfloat sy, lfloat sz, float lx, float ly, float lz, float eps,
                             lint *shadow)
{
    walking = walking & (SC_LABS(sx) <= extent) & (SC_LABS(sy) <= extent) & (SC_LABS(sz) <= extent);
    int at[LANES];
    LANE_STORE(walking ? PLANE_CELL(coarse - first_coarse, sub) : (lint)0, at);
#if WHOLE_PACKETS
    /* the lanes' planes as 8 vector loads, transposed by shuffles (an 8 x 8 transpose in 24) */
    lfloat nx, ny, nz, c_hi, c_lo, c_top, reach;
    {
        const float8 r0 = planes[at[0]], r1 = planes[at[1]], r2 = planes[at[2]], r3 = planes[at[3]];
        const float8 r4 = planes[at[4]], r5 = planes[at[5]], r6 = planes[at[6]], r7 = planes[at[7]];
#define UNPACK(a, b, hi) __builtin_shufflevector(a, b, 0 + 2 * (hi), 8 + 2 * (hi), 1 + 2 * (hi), 9 + 2 * (hi), \
                                                 4 + 2 * (hi), 12 + 2 * (hi), 5 + 2 * (hi), 13 + 2 * (hi))
#define PAIRS(a, b, hi) __builtin_shufflevector(a, b, 0 + 2 * (hi), 1 + 2 * (hi), 8 + 2 * (hi), 9 + 2 * (hi), \
                                                4 + 2 * (hi), 5 + 2 * (hi), 12 + 2 * (hi), 13 + 2 * (hi))
#define HALVES(a, b, hi) __builtin_shufflevector(a, b, 0 + 4 * (hi), 1 + 4 * (hi), 2 + 4 * (hi), 3 + 4 * (hi), \
                                                 8 + 4 * (hi), 9 + 4 * (hi), 10 + 4 * (hi), 11 + 4 * (hi))
        const float8 t0 = UNPACK(r0, r1, 0), t1 = UNPACK(r0, r1, 1), t2 = UNPACK(r2, r3, 0), t3 = UNPACK(r2, r3, 1);
        const float8 t4 = UNPACK(r4, r5, 0), t5 = UNPACK(r4, r5, 1), t6 = UNPACK(r6, r7, 0), t7 = UNPACK(r6, r7, 1);
        const float8 u0 = PAIRS(t0, t2, 0), u1 = PAIRS(t0, t2, 1), u2 = PAIRS(t1, t3, 0), u3 = PAIRS(t1, t3, 1);
        const float8 u4 = PAIRS(t4, t6, 0), u5 = PAIRS(t4, t6, 1), u6 = PAIRS(t5, t7, 0), u7 = PAIRS(t5, t7, 1);
        nx = HALVES(u0, u4, 0); ny = HALVES(u1, u5, 0); nz = HALVES(u2, u6, 0); c_hi = HALVES(u3, u7, 0);
        c_lo = HALVES(u0, u4, 1); c_top = HALVES(u1, u5, 1); reach = HALVES(u2, u6, 1);
#undef UNPACK
#undef PAIRS
#undef HALVES
    }
#else
    float px[LANES], py[LANES], pz[LANES], phi[LANES], plo[LANES], ptop[LANES], preach[LANES];
    for (int j = 0; j < LANES; ++j) {
        const float8 q = planes[at[j]];
        px[j] = q.s0; py[j] = q.s1; pz[j] = q.s2; phi[j] = q.s3; plo[j] = q.s4; ptop[j] = q.s5; preach[j] = q.s6;
    }
    const lfloat nx = LANE_LOAD(float, px), ny = LANE_LOAD(float, py), nz = LANE_LOAD(float, pz);
    const lfloat c_hi = LANE_LOAD(float, phi), c_lo = LANE_LOAD(float, plo), c_top = LANE_LOAD(float, ptop);
    const lfloat reach = LANE_LOAD(float, preach);
#endif
    lfloat dx, dy, dz;
    to_light(sx, sy, sz, lx, ly, lz, &dx, &dy, &dz);
    const float u = PLANE_ULPS * 0.5f * FLT_EPSILON;
    const lfloat ns = nx * sx + ny * sy + nz * sz, nd = nx * dx + ny * dy + nz * dz;
    const lfloat ms = SC_LABS(nx * sx) + SC_LABS(ny * sy) + SC_LABS(nz * sz);
    const lfloat md = SC_LABS(nx * dx) + SC_LABS(ny * dy) + SC_LABS(nz * dz);
    const lfloat B = nd - u * md;                          /* <= n.d */
    const lfloat A = (ns - c_hi) - u * (ms + SC_LABS(c_hi));
#if LIGHT_POINT
    const lfloat ax = SC_LABS(dx), ay = SC_LABS(dy), az = SC_LABS(dz);
    const lfloat M = (ax > ay) ? ((ax > az) ? ax : az) : ((ay > az) ? ay : az);
    const lfloat d1 = ax + ay + az;
    const lfloat D = d1 * (1.0f + 0x1p-20f);
    const lfloat t_hi = (eps * (1.0f + 0x1p-20f)) / M;
    const lfloat end = (ns - u * ms) + B;                  /* <= n.(s + d) */
    const lint ends_in_front = (end > c_top + u * (SC_LABS(c_top) + ms + md)) & (d1 <= reach);
#else
    const lfloat D = (lfloat)1.0f;
    const lfloat t_hi = (lfloat)eps;
    /* the ray goes on; it meets T's slab within the cell's reach */
    const lint ends_in_front = c_top - (ns - u * ms) <= reach * B;
#endif
    const lfloat AD = A * D, eB = eps * B;
    const lfloat starts = (ns + u * ms) + t_hi * (nd + u * md);     /* >= n.(s + tmin d) */
    *shadow = walking & (B > 0.0f) & ends_in_front & (starts < c_lo - u * (SC_LABS(c_lo) + ms + t_hi * md));
    return walking & (B >= 0.0f) & (AD + eB > u * (SC_LABS(AD) + eB));
}

/* Does T (a watertight record) cover the plane cell of fine cells [i0, i1) x [j0, j1) of view v (a border
 * cell to the view's domain), enlarged by PLANE_CELL_MARGIN fine cells: are the enlarged cell's four corner
 * lines (from the light, or along a directional light's travel) inside T's three edge planes by more than
 * the cone test's bound? The corners solved from the view's rows in float32 (off by ~1e-6 of a cell's
 * coordinates, far inside the margin); the margin also covers the receivers' cells' rounding and the
 * computed segments' direction. */
#define PLANE_CELL_MARGIN 0.125f
INLINE int covers_cell(__global const float *r, __constant const float *v, int i0, int i1, int j0, int j1,
                       float lx, float ly, float lz)
{
    /* rows a, b, c of the system (the cube: M d = (x, y, 1) w for the direction d from the light; orthographic:
     * [Mx; My; travel] p = (x - cx, y - cy, 0)), solved by Cramer's rule */
    const float a0 = v[4], a1 = v[5], a2 = v[6], b0 = v[8], b1 = v[9], b2 = v[10];
#if PERSPECTIVE
    const float c0 = v[12], c1 = v[13], c2 = v[14];
#else
    const float c0 = lx, c1 = ly, c2 = lz;
#endif
    const float k00 = b1 * c2 - b2 * c1, k01 = a2 * c1 - a1 * c2, k02 = a1 * b2 - a2 * b1;
    const float k10 = b2 * c0 - b0 * c2, k11 = a0 * c2 - a2 * c0, k12 = a2 * b0 - a0 * b2;
    const float k20 = b0 * c1 - b1 * c0, k21 = a1 * c0 - a0 * c1, k22 = a0 * b1 - a1 * b0;
    const float det = a0 * k00 + a1 * k10 + a2 * k20;
    if (!(SC_ABS(det) > 0.0f))
        return 0;
    /* a border cell reaches the view's domain (lightspace.h): a cube face's edge; an unbounded one is not
     * covered */
    const float x0 = (i0 == 0) ? v[20] : (float)i0, x1 = (i1 == VIEW_NX(v)) ? v[21] : (float)i1;
    const float y0 = (j0 == 0) ? v[22] : (float)j0, y1 = (j1 == VIEW_NY(v)) ? v[23] : (float)j1;
    if (!(SC_MAX(SC_MAX(SC_ABS(x0), SC_ABS(x1)), SC_MAX(SC_ABS(y0), SC_ABS(y1))) < 0.5f * SC_BIG))
        return 0;
    for (int corner = 0; corner < 4; ++corner) {
        const float x = (corner & 1) ? x1 + PLANE_CELL_MARGIN : x0 - PLANE_CELL_MARGIN;
        const float y = (corner & 2) ? y1 + PLANE_CELL_MARGIN : y0 - PLANE_CELL_MARGIN;
#if PERSPECTIVE
        const float e0 = x, e1 = y, e2 = 1.0f;
        const float sign = -1.0f;        /* the cone test's x is light - point: minus the direction */
#else
        const float e0 = x - v[7], e1 = y - v[11], e2 = 0.0f;
        const float sign = 1.0f;         /* the cone test's x is the point */
#endif
        const float inv = sign / det;
        const float px = (k00 * e0 + k01 * e1 + k02 * e2) * inv;
        const float py = (k10 * e0 + k11 * e1 + k12 * e2) * inv;
        const float pz = (k20 * e0 + k21 * e1 + k22 * e2) * inv;
        const float bound = r[25] * (SC_ABS(px) + SC_ABS(py) + SC_ABS(pz)) + r[26];
        for (int e = 0; e < 3; ++e)
            if (!(r[16 + 3 * e] * px + r[17 + 3 * e] * py + r[18 + 3 * e] * pz - r[27 + e] > bound))
                return 0;
    }
    return 1;
}

/* The planes of plane cell `part` of coarse cell `cell` for decided_by_plane, from its triangles' watertight
 * records (corners, unit normal, the light's side fL and its bound; the edge planes): T is one of them, its
 * plane oriented
 * towards the light (either winding: a plane has no front of its own here): of those whose plane certainly
 * misses the light and has the centroid of the cell's corners behind it (within eps), the one nearest to
 * the centroid (a slab's top face, not its sides or bottom). c_hi is T's plane moved out past every corner
 * of the cell's triangles by their rounding; none when a corner lies more than eps in front of it (the
 * plane could then decide no receiver lying on its face), or when the cell's lists hold more than
 * PLANE_MAX_ENTRIES entries: a ground's cells hold a few, and a cell crowded with a model's triangles
 * seldom has a plane (bunny: the planes' kernel 5.7 ms with no limit). Returned as a float8: n, c_hi, c_lo,
 * c_top, reach, 0. */
#define PLANE_MAX_ENTRIES 64
#define CELL_TRIANGLES(...)                                                                          \
    for (int k = offsets[cell]; k < offsets[cell + 1]; ++k) {                                        \
        if (cell_masks && !(cell_masks[k - offsets[cell]] & region))                                 \
            continue;                                                                                \
        __global const float *r = records + WT_FLOATS * items[k];                                    \
        __VA_ARGS__                                                                                  \
    }                                                                                                \
    for (int j = j0; j < j1; ++j)                                                                    \
        for (int i = i0; i < i1; ++i)                                                                \
            for (int k = offsets[base0 + j * nx + i]; k < offsets[base0 + j * nx + i + 1]; ++k) {    \
                __global const float *r = records + WT_FLOATS * items[k];                            \
                __VA_ARGS__                                                                          \
            }
NOINLINE float8 cell_plane(int cell, int part, __constant const float *views, __global const int *offsets,
                           __global const int *items, __global const ulong *masks, __global const float *records,
                           int first_coarse, float lx, float ly, float lz, float eps, float extent)
{
    const float8 none = (float8)(0.0f, 0.0f, 0.0f, INFINITY, -INFINITY, INFINITY, 0.0f, 0.0f);
    int view = 0;
    for (int k = 1; k < NVIEWS; ++k)
        view = (cell >= VIEW_BASE1(views + VIEW_FLOATS * k)) ? k : view;
    __constant const float *v = views + VIEW_FLOATS * view;
    const int nx = VIEW_NX(v), ny = VIEW_NY(v), base0 = VIEW_BASE0(v), nx1 = VIEW_NX1(v);
    const int ci = (cell - VIEW_BASE1(v)) % nx1, cj = (cell - VIEW_BASE1(v)) / nx1;
    /* the plane cell's fine cells, and their bits in the coarse entries' masks */
    const int side = 1 << PLANE_SHIFT, across = LS_COARSE >> PLANE_SHIFT;
    const int pi = part % across, pj = part / across;
    const int i0 = (ci << LS_COARSE_SHIFT) + pi * side, i1 = SC_IMIN(i0 + side, nx);
    const int j0 = (cj << LS_COARSE_SHIFT) + pj * side, j1 = SC_IMIN(j0 + side, ny);
    if (i0 >= nx || j0 >= ny)
        return none;                                       /* beyond the grid: no receiver is there */
    ulong region = 0;
    for (int j = j0; j < j1; ++j)
        for (int i = i0; i < i1; ++i)
            region |= (ulong)1 << LS_SUB_OF(i, j);
    /* (split lists have no masks: every coarse entry counts) */
    __global const ulong *cell_masks = masks ? masks + (offsets[cell] - offsets[first_coarse]) : 0;
    int entries = 0;
    for (int k = offsets[cell]; k < offsets[cell + 1]; ++k)
        entries += !cell_masks || (cell_masks[k - offsets[cell]] & region);
    for (int j = j0; j < j1; ++j)
        entries += offsets[base0 + j * nx + i1] - offsets[base0 + j * nx + i0];
    if (!entries)
        return (float8)(0.0f, 0.0f, 0.0f, -1.0f, -INFINITY, INFINITY, 0.0f, 0.0f);
    if (entries > PLANE_MAX_ENTRIES)
        return none;
    /* the centroid of the cell's corners: a plane with every corner behind it has it behind too */
    float gx = 0.0f, gy = 0.0f, gz = 0.0f;
    CELL_TRIANGLES({
        gx += r[0] + r[3] + r[6]; gy += r[1] + r[4] + r[7]; gz += r[2] + r[5] + r[8];
    })
    gx /= 3.0f * (float)entries; gy /= 3.0f * (float)entries; gz /= 3.0f * (float)entries;
    __global const float *best = 0;
    float best_side = 0.0f, best_h = -INFINITY;
    CELL_TRIANGLES({
        if (SC_ABS(r[12]) > r[13]) {
            const float side = r[12] > 0.0f ? 1.0f : -1.0f;
            const float h = side * (r[9] * (gx - r[0]) + r[10] * (gy - r[1]) + r[11] * (gz - r[2]));
            if (h <= eps && h > best_h) {
                best = r;
                best_side = side;
                best_h = h;
            }
        }
    })
    if (!best)
        return none;
    const float bx = best_side * best[9], by = best_side * best[10], bz = best_side * best[11];
    const float c = bx * best[0] + by * best[1] + bz * best[2];
    /* the most (the least) an exact n.p - c may be over corners p: computed value plus (minus) 8 ulps of
     * its terms */
    const float u = 8.0f * 0.5f * FLT_EPSILON;
#define CORNER_SPREAD(p, f, m)                                                                       \
    const float f = bx * (p)[0] + by * (p)[1] + bz * (p)[2] - c;                                   \
    const float m = SC_ABS(bx * (p)[0]) + SC_ABS(by * (p)[1]) + SC_ABS(bz * (p)[2]) + SC_ABS(c);
    float own = 0.0f;                                      /* T's own corners' spread about c */
    for (int q = 0; q < 9; q += 3) {
        CORNER_SPREAD(best + q, f, m)
        own = SC_MAX(own, SC_ABS(f) + u * m);
    }
    float8 out = none;
    if (covers_cell(best, v, i0, i1, j0, j1, lx, ly, lz)) {
        out.s4 = (c - own) - u * (SC_ABS(c) + own);
        out.s5 = (c + own) + u * (SC_ABS(c) + own);
#if LIGHT_POINT
        out.s6 = 16.0f * (SC_ABS(best[12]) - best[13]);    /* |d|_1 beyond it: no shadow decided */
#else
        out.s6 = extent;                                   /* T farther along the ray: none either */
#endif
    }
    out.s0 = bx; out.s1 = by; out.s2 = bz;
    float most = -INFINITY;
    CELL_TRIANGLES({
        for (int q = 0; q < 9; q += 3) {
            CORNER_SPREAD(r + q, f, m)
            most = SC_MAX(most, f + u * m);
        }
        if (most > eps)
            return out;
    })
#undef CORNER_SPREAD
    /* c + most rounded up: its rounding and the bound's own stay below 4 ulps of |c| + |most| */
    out.s3 = (c + most) + u * (SC_ABS(c) + SC_ABS(most));
    return out;
}
#undef CELL_TRIANGLES

/* The planes of the plane cells of coarse cells first_coarse + k, k < ncoarse (PLANE_CELLS each), for
 * decided_by_plane (CSR lists: offsets, items, the coarse entries' fine masks; watertight records; the light
 * as the walk's) */
__kernel void exact_cell_planes(__constant const float *views, __global const int *offsets, __global const int *items,
                                __global const ulong *masks, __global const float *records, float lx, float ly,
                                float lz, float eps, float extent, int first_coarse, int ncoarse,
                                __global float8 *planes)
{
    const int k = get_global_id(0);
    if (k < ncoarse * PLANE_CELLS)
        planes[k] = cell_plane(first_coarse + k / PLANE_CELLS, k % PLANE_CELLS, views, offsets, items, masks,
                               records, first_coarse, lx, ly, lz, eps, extent);
}

#define BIN_ARGS                                                                                     \
    __global const input_t *points, __global const input_t *normals, int n, MOVE_ARGS,                \
        __constant const float *views, int brute_cell, float lx, float ly, float lz, float eps, int with_normals

/* Pass 1's work on the packet of receivers base .. base + LANES - 1 (those below n): out[i] (the code of
 * a receiver needing no walk, else 0) written, and the lanes' starts and cells (-1 for a receiver needing
 * no walk) in *sx, *sy, *sz and *cells, which the callers store. Contract: points (n x 3, float32 relative
 * to the local origin, or float64 with INPUT_F64, the frame's move and the origin in m), normals likewise
 * if with_normals (any non-zero length); views: the grid the lists were built on. */
INLINE void bin_packet(int base, __global const input_t *points, __global const input_t *normals, int n,
                       const Move *m, __constant const float *views, int brute_cell, float lx, float ly, float lz,
                       float eps, int with_normals, __global const float8 *planes, int first_coarse,
                       float plane_extent, __global uchar *out, lfloat *sx, lfloat *sy, lfloat *sz, lint *cells)
{
    lint codes = receivers_start(base, n, points, normals, m, lx, ly, lz, eps, with_normals, sx, sy, sz);
    lint coarse = (lint)-1, sub;
    *cells = (codes == WALK) ? receiver_cell(views, brute_cell, *sx, *sy, *sz, &coarse, &sub) : (lint)-1;
    if (first_coarse >= 0) {
        lint shadow;
        const lint lit = decided_by_plane(planes, first_coarse, plane_extent, (*cells >= 0) & (coarse >= 0), coarse,
                                          sub, *sx, *sy, *sz, lx, ly, lz, eps, &shadow);
        codes = shadow ? (lint)1 : codes;
        *cells = (lit | shadow) ? (lint)-1 : *cells;
    }
#if WHOLE_PACKETS
    if (base + LANES <= n) {
        *(__global uchar8 *)(out + base) = __builtin_convertvector(codes, uchar8);
        return;
    }
#endif
    int code[LANES];
    LANE_STORE(codes, code);
    for (int j = 0; j < LANES && base + j < n; ++j)
        out[base + j] = (uchar)code[j];
}

/* Pass 1 also counts each walking receiver in its cell, in counts, which the prefix sum turns into the
 * fill's offsets. Two ways, the host picks one for its device:
 *   exact_bin_count       one packet per work-item: every receiver's start, tagged with its cell, at its
 *                         index in start, and its slot (rank in its cell, slot[i]; -1 for a receiver
 *                         needing no walk) by atomic_inc on its cell's count (a GPU's
 *                         way, or a CPU's with many cores; counts: brute_cell + 1 ints, zeroed). The
 *                         atomics come last and back to back: each drains the stores before it, and
 *                         interleaved with the starts' stores they cost twice as much (bunny bench: the
 *                         pass 21 -> 15 ms).
 *   exact_bin_count_ends  2 work-items (local size 1), each binning half the packets serially and counting
 *                         them in a row of its own, counts[end * ROW + cell], ROW = brute_cell + 2 + LANES:
 *                         no atomics (on a 2-core CPU the pass 8.6-10.4 -> 5.0-8.2 ms), and no cache line
 *                         shared between the two (counters interleaved, (cell, owner) side by side, went
 *                         back and forth between the cores: 9.3 ms against 9.6 with atomics).
 *                         exact_bin_fill_ends fills the first half's places from the cells' fronts, the
 *                         second's from their backs, so that the offsets stay one per cell (per (cell,
 *                         owner) offsets made the fill 5.2 -> 8.5 ms on ogre) and a cell's receivers stay
 *                         together. counts: 2 ROW ints, zeroed; the prefix sum adds the rows (lists.h
 *                         second_row). After a row's cells come LANES counters of the receivers that need
 *                         no walk, one per lane (not scanned), so that the loop has no branch, and no
 *                         chain of increments of one counter (with most receivers decided by
 *                         decided_by_plane, one counter for them all cost the pass ~2 ms on the default
 *                         scene); last, how many walk. Only those are written: packed from the end's
 *                         first receiver on (pack_walkers), so that the fill reads nothing of the rest. */
__kernel void exact_bin_count(BIN_ARGS, __global const float8 *planes, int first_coarse, float plane_extent,
                              __global int *counts, __global int *slot, __global uchar *out, __global Start *start)
{
    const int base = LANES * get_global_id(0);
    if (base >= n)
        return;
    const Move m = MOVE_OF_ARGS;
    lfloat sx, sy, sz;
    lint cells;
    bin_packet(base, points, normals, n, &m, views, brute_cell, lx, ly, lz, eps, with_normals, planes, first_coarse,
               plane_extent, out, &sx, &sy, &sz, &cells);
    int cell[LANES];
    LANE_STORE(cells, cell);
#if WHOLE_PACKETS
    if (base + LANES <= n)
        store_starts8(start + base, sx, sy, sz, cells);
    else
#endif
    {
        float x[LANES], y[LANES], z[LANES];
        LANE_STORE(sx, x); LANE_STORE(sy, y); LANE_STORE(sz, z);
        for (int j = 0; j < LANES && base + j < n; ++j) {
            const Start r = {x[j], y[j], z[j], cell[j]};
            start[base + j] = r;
        }
    }
    for (int j = 0; j < LANES && base + j < n; ++j)
        slot[base + j] = (cell[j] >= 0) ? atomic_inc(&counts[cell[j]]) : -1;
}

/* The walking lanes (cell >= 0) of the packet at base (those below n), packed from start[k] and cell_of[k]
 * on: their starts tagged with their index (the fill's output records) and their cells; returns k past
 * them. Branch-free within a packet: every lane is written at k, which only a walking lane moves on (k
 * never passes base + j: the packing stays within the receivers already seen). */
INLINE int pack_walkers(int k, int base, int n, lfloat sx, lfloat sy, lfloat sz, const int *cell,
                        __global Start *start, __global int *cell_of)
{
    float x[LANES], y[LANES], z[LANES];
    LANE_STORE(sx, x); LANE_STORE(sy, y); LANE_STORE(sz, z);
    for (int j = 0; j < LANES && base + j < n; ++j) {
        const Start r = {x[j], y[j], z[j], base + j};
        start[k] = r;
        cell_of[k] = cell[j];
        k += cell[j] >= 0;
    }
    return k;
}

__kernel void exact_bin_count_ends(BIN_ARGS, __global const float8 *planes, int first_coarse, float plane_extent,
                                   int per_end, __global int *counts, __global uchar *out, __global Start *start,
                                   __global int *cell_of)
{
    const int end = get_global_id(0), spare = brute_cell + 1;
    const int first = end * per_end * LANES, last = SC_IMIN(n, first + per_end * LANES);
    __global int *row = counts + end * (brute_cell + 2 + LANES);
    const Move m = MOVE_OF_ARGS;
    int k = first;
    for (int base = first; base < last; base += LANES) {
        lfloat sx, sy, sz;
        lint cells;
        bin_packet(base, points, normals, n, &m, views, brute_cell, lx, ly, lz, eps, with_normals, planes,
                   first_coarse, plane_extent, out, &sx, &sy, &sz, &cells);
        int cell[LANES];
        LANE_STORE(cells, cell);
        if (LANE_ANY(cells >= 0))
            k = pack_walkers(k, base, n, sx, sy, sz, cell, start, cell_of);
        for (int j = 0; j < LANES && base + j < n; ++j)
            ++row[cell[j] >= 0 ? cell[j] : spare + j];
    }
    row[spare + LANES] = k - first;
}

/* Pass 2's look-ahead for its scattered writes. Against none, interleaved in one process, medians of 11,
 * the pass in ms with / without normals: bunny 9.3 -> 5.6 / 9.5 -> 6.7, ogre 5.9 -> 4.7 / 7.6 -> 5.1,
 * default 5.0 -> 4.9 / 6.8 -> 4.7, light_inside 4.4 -> 5.3 / 6.7 -> 5.3 (16 and 32 ahead did no better). */
#define FILL_AHEAD 64

/* Pass 2: every walking receiver copies its start, tagged with its index, to its place in its cell of
 * binned (the cell's slots from offsets: the exclusive prefix sum of pass 1's counts), so that they list
 * the receivers cell by cell. A receiver past its cell's count (a bug) would overwrite another or go
 * outside its cell: it is not written but counted in *dropped, which the host checks. Two ways, after
 * pass 1's two:
 *   exact_bin_fill       per receiver, its place offsets[cell] + slot[i] (exact_bin_count's atomic ranks).
 *   exact_bin_fill_ends  exact_bin_count_ends' two work-items replay their packed walkers (start, already
 *                        tagged, and cell_of) in the same order, each taking its cell's places from its
 *                        row of counts down to zero: the first half from the cell's front, the second
 *                        from its back. No slot per receiver to write and read back (4 bytes each way),
 *                        no atomics, and nothing read of the receivers needing no walk; the counts end
 *                        at zero. */
__kernel void exact_bin_fill(int n, __global const Start *start, __global const int *slot,
                             __global const int *counts, __global const int *offsets, __global Start *binned,
                             __global volatile int *dropped)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    /* The places are scattered over the whole binned array: ask for the line of the receiver FILL_AHEAD
     * on before it is written (with the write hint) */
    const int ahead = i + FILL_AHEAD;
    if (ahead < n && slot[ahead] >= 0)
        SC_PREFETCH(binned + offsets[start[ahead].tag] + slot[ahead], 1);
    const int s = slot[i];
    if (s >= 0) {
        const Start r = start[i];
        if (s < counts[r.tag]) {
            const Start tagged = {r.x, r.y, r.z, i};
            binned[offsets[r.tag] + s] = tagged;
        } else {
            atomic_inc(dropped);
        }
    }
}

__kernel void exact_bin_fill_ends(int per_end, __global const Start *start, __global const int *cell_of,
                                  __global int *counts, int second_row, __global const int *offsets,
                                  __global Start *binned, __global volatile int *dropped)
{
    const int end = get_global_id(0);
    __global int *row = counts + end * second_row;
    const int first = end * per_end * LANES, last = first + row[second_row - 1];   /* its packed walkers */
    int lost = 0;
    for (int k = first; k < last; ++k) {
        const int ahead = k + FILL_AHEAD;
        if (ahead < last) {
            const int c = cell_of[ahead];         /* its place as it stands now: the same line or the next */
            SC_PREFETCH(binned + (end ? offsets[c + 1] - row[c] : offsets[c] + row[c] - 1), 1);
        }
        const int c = cell_of[k];
        const int left = row[c] - 1;              /* this end's places left in the cell after this one */
        if (left < 0) {
            ++lost;
            continue;
        }
        row[c] = left;
        binned[end ? offsets[c + 1] - 1 - left : offsets[c] + left] = start[k];
    }
    if (lost)
        atomic_add(dropped, lost);
}

/* A packet's lanes: their starts, directions to the light, intervals, the L1 norm of the cone test's
 * vector (d for a point light, s for a directional one: ray_triangle.h wt_cone) and watertight set-up */
typedef struct {
    lfloat sx, sy, sz, dx, dy, dz, tmin, cone_norm;
#if !TEST_DOT5
    WtRay ray;
#endif
} Packet;

/* The lanes starting at s with interval (tmin, TMAX) towards the light */
INLINE Packet packet(lfloat sx, lfloat sy, lfloat sz, lfloat tmin, float lx, float ly, float lz)
{
    Packet p;
    p.sx = sx; p.sy = sy; p.sz = sz; p.tmin = tmin;
    to_light(sx, sy, sz, lx, ly, lz, &p.dx, &p.dy, &p.dz);
#if LIGHT_POINT
    p.cone_norm = SC_LABS(p.dx) + SC_LABS(p.dy) + SC_LABS(p.dz);
#else
    p.cone_norm = SC_LABS(sx) + SC_LABS(sy) + SC_LABS(sz);
#endif
#if !TEST_DOT5
    p.ray = wt_setup(p.sx, p.sy, p.sz, p.dx, p.dy, p.dz);
#endif
    return p;
}

/* The lanes of `active` that triangle t shadows. Watertight: the plane test, then the cone test over the
 * lanes the plane does not cull; only lanes neither test settles (near an edge or a vertex of the
 * triangle, or a plane the segment grazes) take the watertight test: classify 4-51 % faster on the
 * bench scenes, the same masks (shadowcl/exact.py's docstring has the figures). */
INLINE lint packet_hits(const Packet *p, __global const float *tris, int t, lint active)
{
#if TEST_DOT5
    return active & dot5_hit(p->sx, p->sy, p->sz, p->dx, p->dy, p->dz, tris + DOT5_FLOATS * t, p->tmin, (lfloat)TMAX);
#else
    __global const float *r = tris + WT_FLOATS * t;
    lint crossing, inside;
    active = active & !wt_plane(r, p->sx, p->sy, p->sz, p->dx, p->dy, p->dz, p->tmin, &crossing);
    if (!LANE_ANY(active))
        return (lint)0;
#if LIGHT_POINT
    const lint outside = wt_cone(r, p->dx, p->dy, p->dz, p->cone_norm, &inside);
#else
    const lint outside = wt_cone(r, p->sx, p->sy, p->sz, p->cone_norm, &inside);
#endif
    const lint sure = active & crossing & inside, unsure = active & !outside & !sure;
    if (!LANE_ANY(unsure))
        return sure;
    return sure | (unsure & wt_hit(&p->ray, r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], p->tmin, (lfloat)TMAX));
#endif
}

/* The walk asks for the record PREFETCH_AHEAD entries on: a list's entries are scattered triangles, whose
 * records (then 64 bytes each: 4.4 MB for bunny's 69 k triangles) miss the core's caches. Against none,
 * interleaved in one process, medians of 15, classify in ms, with / without normals: bunny 36.6 -> 33.1 /
 * 53.9 -> 50.3, ogre 40.8 -> 37.3 / 64.8 -> 58.4; the small scenes (default, light_inside) within noise.
 * 2 and 8 entries ahead did no better. The first line of a 128-byte watertight record only: asking for
 * the second (the cone test's) too gave the same minima (2026-12-07, classify ms, light_inside without
 * normals 20.0 -> 20.5, with 9.9 -> 9.8; default with 6.1 -> 6.0). */
#define PREFETCH_AHEAD 4
#define RECORD_FLOATS (TEST_DOT5 ? DOT5_FLOATS : WT_FLOATS)

/* `hit` or'ed with the lanes in `active` that a triangle of cell c's list shadows (brute_cell's list:
 * every triangle); stops when every active lane is shadowed. masks (CSR coarse lists; else NULL): the
 * list's entries' fine cells (lightspace.cl ls_fine_mask), an entry skipped unless it sets one of
 * `fine` (the bits of the fine cells the active lanes are in). */
NOINLINE lint walk_list(int c, lint active, lint hit, const Packet *p, __global const float *tris, int ntris,
                        int brute_cell, __global const int *lists_a, __global const int *lists_b,
                        __global const ulong *masks, ulong fine)
{
    active = active & !hit;
    if (c == brute_cell) {
        for (int t = 0; t < ntris && LANE_ANY(active); ++t) {
            const lint h = packet_hits(p, tris, t, active);
            hit = hit | h;
            active = active & !h;
        }
        return hit;
    }
#if LISTS_LINKED
    for (int node = lists_a[c]; node >= 0 && LANE_ANY(active); node = lists_b[2 * node + 1]) {
        const lint h = packet_hits(p, tris, lists_b[2 * node], active);
#else
    const int begin = lists_a[c], end = lists_a[c + 1];
    for (int k = begin; k < end && LANE_ANY(active); ++k) {
        if (masks && !(masks[k - begin] & fine))
            continue;
        if (k + PREFETCH_AHEAD < end)
            SC_PREFETCH(tris + RECORD_FLOATS * lists_b[k + PREFETCH_AHEAD], 0);
        const lint h = packet_hits(p, tris, lists_b[k], active);
#endif
        hit = hit | h;
        active = active & !h;
    }
    return hit;
}

/* `hit` after walking, for each distinct cell among the valid lanes' `cell` (int per lane, -1: none),
 * that cell's list with the lanes in it. Coarse cells (sub: each lane's fine cell's bit in its coarse
 * cell; NULL for fine cells) with masks (the coarse entries' fine cells, from the first coarse cell's
 * entries on; NULL: none) skip the entries that touch none of the lanes' fine cells. */
INLINE lint walk_cells(const int *cell, const int *sub, lint valid, lint hit, const Packet *p,
                       __global const float *tris, int ntris, int brute_cell, __global const int *lists_a,
                       __global const int *lists_b, __global const ulong *masks, int first_coarse)
{
    const lint cells = LANE_LOAD(int, cell);
    lint todo = valid & (cells >= 0);                 /* lanes whose cell is still to walk */
    for (int j = 0; j < LANES && LANE_ANY(todo); ++j) {
        const lint here = todo & (cells == cell[j]);  /* empty when lane j's cell was walked already */
        if (LANE_ANY(here)) {
            __global const ulong *list_masks = 0;
            ulong fine = 0;
#if !LISTS_LINKED
            if (sub && masks && cell[j] != brute_cell) {
                int lanes[LANES];
                LANE_STORE(here, lanes);
                for (int m = 0; m < LANES; ++m)
                    fine |= lanes[m] ? (ulong)1 << sub[m] : (ulong)0;
                list_masks = masks + (lists_a[cell[j]] - lists_a[first_coarse]);
            }
#endif
            hit = walk_list(cell[j], here, hit, p, tris, ntris, brute_cell, lists_a, lists_b, list_masks, fine);
            todo = todo & !here;
        }
    }
    return hit;
}

/* Pass 3. Contract: binned: nbinned starts tagged with their receivers' indices, pass 2's; views: the grid;
 * tris: triangle records (see TEST_DOT5); lists_a, lists_b: (offsets, items) or (heads, nodes) over the
 * grid's cells; coarse_masks: the CSR coarse entries' fine cells (lightspace.py Lists.fine_masks) or NULL;
 * (lx, ly, lz): light position (relative) or direction; eps: as pass 1's; walk_coarse: 0 when no primitive
 * is coarse (the coarse lists are empty). Writes out[index] for every binned receiver (of n). */
NOINLINE void exact_classify_item(int base, __global const Start *binned, int nbinned, __constant const float *views,
                                  __global const float *tris, int ntris, int brute_cell, __global const int *lists_a,
                                  __global const int *lists_b, __global const ulong *coarse_masks, float lx, float ly,
                                  float lz, float eps, int walk_coarse, int n, __global uchar *out)
{
    /* The lanes' receivers; lanes past the end repeat the last one and are not valid */
    lfloat x, y, z;
    lint tags;
#if WHOLE_PACKETS
    if (base + LANES <= nbinned) {
        load_starts8(binned + base, &x, &y, &z, &tags);
    } else
#endif
    {
        float sx[LANES], sy[LANES], sz[LANES];
        int tag[LANES];
        for (int j = 0; j < LANES; ++j) {
            const Start r = binned[SC_IMIN(base + j, nbinned - 1)];
            sx[j] = r.x; sy[j] = r.y; sz[j] = r.z; tag[j] = r.tag;
        }
        x = LANE_LOAD(float, sx); y = LANE_LOAD(float, sy); z = LANE_LOAD(float, sz); tags = LANE_LOAD(int, tag);
    }
    int fine[LANES], coarse[LANES], sub[LANES], index[LANES], lane[LANES];
    lint coarse_lanes, sub_lanes;
    const lint fine_lanes = receiver_cell(views, brute_cell, x, y, z, &coarse_lanes, &sub_lanes);
    LANE_STORE(fine_lanes, fine); LANE_STORE(coarse_lanes, coarse); LANE_STORE(sub_lanes, sub);
    LANE_STORE(tags, index);
    for (int j = 0; j < LANES; ++j)
        lane[j] = base + j;
    const lint valid = LANE_LOAD(int, lane) < nbinned;
    const Packet p = packet(x, y, z, start_tmin(x, y, z, lx, ly, lz, eps), lx, ly, lz);
    lint hit = walk_cells(fine, 0, valid, (lint)0, &p, tris, ntris, brute_cell, lists_a, lists_b, 0, 0);
    if (walk_coarse)
        hit = walk_cells(coarse, sub, valid, hit, &p, tris, ntris, brute_cell, lists_a, lists_b, coarse_masks,
                         VIEW_BASE1(views));
    int hit_lane[LANES];
    LANE_STORE(hit, hit_lane);
    for (int j = 0; j < LANES && base + j < nbinned; ++j)
        if ((uint)index[j] < (uint)n)        /* pass 2 filled every slot: the host checked its count */
            out[index[j]] = (uchar)(hit_lane[j] != 0);
}

/* Pass 3's kernel: work-item g classifies the packet from binned receiver LANES g (its body is a NOINLINE
 * function: vecmath.h says why) */
__kernel void exact_classify(__global const Start *binned, int nbinned,
                             __constant const float *views, __global const float *tris, int ntris, int brute_cell,
                             __global const int *lists_a, __global const int *lists_b,
                             __global const ulong *coarse_masks, float lx, float ly, float lz, float eps,
                             int walk_coarse, int n, __global uchar *out)
{
    const int base = LANES * get_global_id(0);
    if (base < nbinned)
        exact_classify_item(base, binned, nbinned, views, tris, ntris, brute_cell, lists_a, lists_b,
                            coarse_masks, lx, ly, lz, eps, walk_coarse, n, out);
}

#if LANES == 1
/* The caller's order instead, one receiver per work-item, fused (no binning): cheaper where walks are
 * short and end early (exact.py's module docstring). Arguments as exact_bin_count's, then the walk's; writes out[i]
 * and counts in *behind (zeroed) the points binned in brute_cell. */
__kernel void exact_classify_points(BIN_ARGS, __global const float *tris, int ntris, __global const int *lists_a,
                                    __global const int *lists_b, __global const ulong *coarse_masks, int walk_coarse,
                                    __global int *behind, __global uchar *out)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    float sx, sy, sz;
    const Move m = MOVE_OF_ARGS;
    const int code = receivers_start(i, n, points, normals, &m, lx, ly, lz, eps, with_normals, &sx, &sy, &sz);
    if (code != WALK) {
        out[i] = (uchar)code;
        return;
    }
    int coarse, sub;
    const int fine = receiver_cell(views, brute_cell, sx, sy, sz, &coarse, &sub);
    if (fine == brute_cell)
        atomic_inc(behind);
    const Packet p = packet(sx, sy, sz, start_tmin(sx, sy, sz, lx, ly, lz, eps), lx, ly, lz);
    int hit = walk_cells(&fine, 0, 1, 0, &p, tris, ntris, brute_cell, lists_a, lists_b, 0, 0);
    if (walk_coarse && coarse >= 0) {
        hit = walk_cells(&coarse, &sub, 1, hit, &p, tris, ntris, brute_cell, lists_a, lists_b, coarse_masks,
                         VIEW_BASE1(views));
    }
    out[i] = (uchar)(hit != 0);
}
#endif

/* The cone test's half of a watertight record (ray_triangle.h WT_FLOATS), at c: the edge planes of
 * triangle v through the light at (lx, ly, lz) (point light: m_k = p_k x p_k+1, p_k = v_k - light) or
 * along its travel (lx, ly, lz) (directional: m_k = (v_k+1 - v_k) x travel, w_k = m_k . v_k), times
 * `side`, the sign of the plane test's fL: then every point whose line to the light passes through the
 * triangle, and its third corner, give each plane a positive value (x = light - point for a point light,
 * the point for a directional one; m_0 . (v_2 - light) = (v_0 - light) . (u x v) = -fL |u x v|).
 * The bound on a value's rounding (FP_CONTRACT is off): the computed m_k is off by at most 4u |p_k| |p_k+1|
 * per component (u = FLT_EPSILON / 2: the differences' and products' rounding), and the dot product
 * with the kernel's computed d adds 4u |m_k| |d|_1, so |error| <= 8u max_k |p_k| |p_k+1| |d|_1; for a
 * directional light 7u |v_k+1 - v_k| (|s|_1 + |v_k|_1) with the offsets. tau is twice that factor (room
 * for the bound's own rounding) and sigma = tau max_k |v_k|_1 (0 for a point light). A degenerate
 * triangle's planes may be anything: its plane test never reports a crossing, so the cone only culls. */
INLINE void wt_cone_record(const float *v, float lx, float ly, float lz, float side, __global float *c)
{
    float p[9], scale = 0.0f, reach = 0.0f;
    for (int k = 0; k < 3; ++k) {
#if LIGHT_POINT
        p[3 * k] = v[3 * k] - lx; p[3 * k + 1] = v[3 * k + 1] - ly; p[3 * k + 2] = v[3 * k + 2] - lz;
#else
        reach = SC_MAX(reach, SC_ABS(v[3 * k]) + SC_ABS(v[3 * k + 1]) + SC_ABS(v[3 * k + 2]));
#endif
    }
    for (int k = 0; k < 3; ++k) {
        const int j = (k + 1) % 3;
#if LIGHT_POINT
        const float ax = p[3 * k], ay = p[3 * k + 1], az = p[3 * k + 2];
        const float bx = p[3 * j], by = p[3 * j + 1], bz = p[3 * j + 2];
        scale = SC_MAX(scale, SC_SQRT(ax * ax + ay * ay + az * az) * SC_SQRT(bx * bx + by * by + bz * bz));
#else
        const float ax = v[3 * j] - v[3 * k], ay = v[3 * j + 1] - v[3 * k + 1], az = v[3 * j + 2] - v[3 * k + 2];
        const float bx = lx, by = ly, bz = lz;
        scale = SC_MAX(scale, SC_SQRT(ax * ax + ay * ay + az * az));
#endif
        const float mx = side * (ay * bz - az * by), my = side * (az * bx - ax * bz), mz = side * (ax * by - ay * bx);
        c[3 * k] = mx; c[3 * k + 1] = my; c[3 * k + 2] = mz;
#if LIGHT_POINT
        c[11 + k] = 0.0f;
#else
        c[11 + k] = mx * v[3 * k] + my * v[3 * k + 1] + mz * v[3 * k + 2];
#endif
    }
    c[9] = 8.0f * FLT_EPSILON * scale + 1.0e-30f;
    c[10] = c[9] * reach;
    c[14] = 0.0f; c[15] = 0.0f;
}

/* Watertight record of triangle v (9 floats) and the light (point: its relative position; directional:
 * the direction its light travels): see WT_FLOATS in ray_triangle.h. */
INLINE void wt_record(const float *v, float lx, float ly, float lz, __global float *r)
{
    for (int k = 0; k < 9; ++k)
        r[k] = v[k];
    const float ux = v[3] - v[0], uy = v[4] - v[1], uz = v[5] - v[2];
    const float vx = v[6] - v[0], vy = v[7] - v[1], vz = v[8] - v[2];
    float nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    const float len = SC_SQRT(nx * nx + ny * ny + nz * nz);
    const float inv = (len > 0.0f) ? 1.0f / len : 0.0f;
    nx *= inv; ny *= inv; nz *= inv;
    /* How far the computed unit normal may lean off the true one: the cross product's rounding is
     * ~eps |u| |v| per component, over |u x v| = |u| |v| sin(angle), so a sliver's normal leans by
     * ~eps / sin(angle) (2e-4 at an aspect of 4e-4); NORMAL_ULPS of it, and 1e-6 for the rest. */
    const float lean = (len > 0.0f) ? NORMAL_ULPS * FLT_EPSILON * SC_SQRT(ux * ux + uy * uy + uz * uz) *
                                          SC_SQRT(vx * vx + vy * vy + vz * vz) * inv : 0.0f;
    const float rel = 1.0e-6f + lean;
#if LIGHT_POINT
    const float ax = lx - v[0], ay = ly - v[1], az = lz - v[2];
    r[12] = nx * ax + ny * ay + nz * az;
    r[13] = rel * (SC_ABS(ax) + SC_ABS(ay) + SC_ABS(az)) + 1.0e-30f;
#else
    r[12] = -(nx * lx + ny * ly + nz * lz);
    r[13] = rel;
#endif
    r[9] = nx; r[10] = ny; r[11] = nz;
    r[14] = rel; r[15] = 0.0f;
    wt_cone_record(v, lx, ly, lz, r[12] > 0.0f ? 1.0f : -1.0f, r + 16);
}

/* Dot5 record of triangle v (9 floats): see DOT5_FLOATS in ray_triangle.h. */
INLINE void dot5_record(const float *v, __global float *r)
{
    const float p0x = v[0], p0y = v[1], p0z = v[2];
    const float ux = v[3] - p0x, uy = v[4] - p0y, uz = v[5] - p0z;
    const float vx = v[6] - p0x, vy = v[7] - p0y, vz = v[8] - p0z;
    float nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    const float uu = dot3(ux, uy, uz, ux, uy, uz), uv = dot3(ux, uy, uz, vx, vy, vz), vv = dot3(vx, vy, vz, vx, vy, vz);
    const float den = uv * uv - uu * vv;
    float inv = 1.0f / den;
    if (!(den != 0.0f) || !(nx != 0.0f || ny != 0.0f || nz != 0.0f)) {
        nx = 0.0f; ny = 0.0f; nz = 0.0f; inv = 0.0f;
    }
    r[0] = p0x; r[1] = p0y; r[2] = p0z;
    r[3] = nx; r[4] = ny; r[5] = nz;
    r[6] = ux; r[7] = uy; r[8] = uz;
    r[9] = vx; r[10] = vy; r[11] = vz;
    r[12] = uu * inv; r[13] = uv * inv; r[14] = vv * inv; r[15] = 0.0f;
}

/* Per triangle t: its corners gathered from relative float32 vertices and int faces into tris (9 floats;
 * copied bit for bit, so triangles sharing a vertex share its floats: what watertightness needs) and its
 * test's record into rec (TEST_DOT5's kind; the light as in wt_record). One kernel for both: on PoCL each
 * kernel's first launch costs a compile. */
__kernel void triangle_records(__global const float *vertices, __global const int *faces, int ntris, float lx,
                               float ly, float lz, __global float *tris, __global float *rec)
{
    const int t = get_global_id(0);
    if (t >= ntris)
        return;
    float v[9];
    for (int k = 0; k < 3; ++k) {
        LOAD3(vertices, faces[3 * t + k], v[3 * k], v[3 * k + 1], v[3 * k + 2]);
        tris[9 * t + 3 * k] = v[3 * k];
        tris[9 * t + 3 * k + 1] = v[3 * k + 1];
        tris[9 * t + 3 * k + 2] = v[3 * k + 2];
    }
#if TEST_DOT5
    dot5_record(v, rec + DOT5_FLOATS * t);
#else
    wt_record(v, lx, ly, lz, rec + WT_FLOATS * t);
#endif
}

/* Dot5 records from 9-float triangles (the voxel method's). */
__kernel void dot5_records(__global const float *tris, int ntris, __global float *rec)
{
    const int t = get_global_id(0);
    if (t >= ntris)
        return;
    float v[9];
    for (int k = 0; k < 9; ++k)
        v[k] = tris[9 * t + k];
    dot5_record(v, rec + DOT5_FLOATS * t);
}
