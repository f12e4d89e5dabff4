/* angular.cl: the discretized shadow volume in angular coordinates (Thakur, Cheng & Miura).
 * Host: the package host/shadowcl/angular/ (frame, loops, table, method); NumPy reference:
 * host/shadowcl/reference/angular.py; tests: tests/test_angular.py.
 *
 * Frame (the host moves geometry into it in float64, then rounds): point light at the origin;
 * a "row" is a half-plane through the X axis (the poles are +-X), at angle
 *     theta = atan2(Y, -Z)                          (the paper's eq. 2, extended to the full circle)
 * and inside a row a direction is keyed by s = X / r = sin(psi), psi the angle from the plane X = 0
 * (monotone in the paper's phi = atan(X / -Z) on every row). Directional light (LIGHT_POINT 0):
 * light comes from +Z, a row is the plane Y = const and s = X.
 *
 * Table (CSR by row, rows sorted by s_lo): one record per (light-facing face, row whose band it meets),
 * 8 floats: s_lo, s_hi (the face's span over the whole row band, padded for float32: every direction of
 * the face whose row coordinate lies in the band has its s in it; the paper's pair of RE / visible-edge
 * crossings, visible edges thus entering "in duplicate"), then the face plane n.x = d (light on its
 * positive side), used for the depth test: exact depth instead of interpolating r between the pair's ends;
 * then the face index (int bits) and the running maximum of s_hi along the row (set by sort_rows). A
 * lookup tests the face itself (its plane, then its edges: record_blocks), never the plane past its edges.
 * A wide span is cut into records of at most piece_width (face_rows: 16 at most from the host's width),
 * so the running maximum stops lookups early.
 * An empty span (the face misses the band) is s_lo = 2 > s_hi = -2 and never matches.
 * The paper's table (host table="loops") puts loop pairs in the same record layout: s_lo, s_hi of a pair
 * of ridge-edge crossings (edge_rows, fill_edges, pair_rows below), the plane of the chord between them
 * (depth interpolated between the pair's ends), -(region + 1) in place of the face; the lookups are
 * the same kernels.
 *
 * Build options:
 *   LIGHT_POINT   1 point light at the origin, 0 directional light from +Z
 *   FULL_CIRCLE   1 rows cover [-pi, pi) and wrap around (light inside the scene)
 *   NORMALS       1 receivers come with unit normals (back-facing = shadow, offset eps)
 *   INPUT_F64     1 receivers are world float64 (moved into the frame here, in double), 0 frame float32
 */
#include "vecmath.h"
#include "lists.h"

#ifndef LIGHT_POINT
#define LIGHT_POINT 1
#endif
#ifndef FULL_CIRCLE
#define FULL_CIRCLE 0
#endif
#ifndef NORMALS
#define NORMALS 0
#endif

/* Receiver i in the frame, relative to the anchor (a point of the occluders, frame coordinates ax, ay, az:
 * see ANCHOR_ARGS): p = rot (row-major 3x3) @ (world - origin) - anchor in double for world input (the
 * normal rotated and normalised); float32 input is read as it is (the host moved it there already). */
INLINE void load_receiver(const __global input_t *points, const __global input_t *normals, int i,
                          const __global input_t *rot, input_t ox, input_t oy, input_t oz,
                          const float ax, const float ay, const float az,
                          float *px, float *py, float *pz, float *nx, float *ny, float *nz)
{
#if INPUT_F64
    const double x = points[3 * i] - ox, y = points[3 * i + 1] - oy, z = points[3 * i + 2] - oz;
    *px = (float)(rot[0] * x + rot[1] * y + rot[2] * z - (double)ax);
    *py = (float)(rot[3] * x + rot[4] * y + rot[5] * z - (double)ay);
    *pz = (float)(rot[6] * x + rot[7] * y + rot[8] * z - (double)az);
#if NORMALS
    const double a = normals[3 * i], b = normals[3 * i + 1], c = normals[3 * i + 2];
    const double len = sqrt(a * a + b * b + c * c);
    *nx = (float)((rot[0] * a + rot[1] * b + rot[2] * c) / len);
    *ny = (float)((rot[3] * a + rot[4] * b + rot[5] * c) / len);
    *nz = (float)((rot[6] * a + rot[7] * b + rot[8] * c) / len);
#endif
#else
    (void)rot; (void)ox; (void)oy; (void)oz; (void)ax; (void)ay; (void)az;
    LOAD3(points, i, *px, *py, *pz);
#if NORMALS
    LOAD3(normals, i, *nx, *ny, *nz);
#endif
#endif
}

#define REC 8             /* floats per record */
#define EMPTY_LO 2.0f
#define EMPTY_HI -2.0f
#define PI_F 3.14159265358979f

INLINE float row_coordinate(float y, float z)
{
#if LIGHT_POINT
    return atan2(y, -z);
#else
    (void)z;
    return y;
#endif
}

/* Row of coordinate t: rows of width dt from t0; -1 outside the table (never with FULL_CIRCLE). */
INLINE int row_of(float t, float t0, float inv_dt, int rows)
{
    int k = (int)SC_FLOOR((t - t0) * inv_dt);
#if FULL_CIRCLE
    k %= rows;
    return k < 0 ? k + rows : k;
#else
    return (k < 0 || k >= rows) ? -1 : k;
#endif
}

INLINE int wrap_row(int k, int rows)
{
#if FULL_CIRCLE
    k %= rows;
    return k < 0 ? k + rows : k;
#else
    (void)rows;
    return k;
#endif
}

#define MAX_PIECES 64         /* bounds the count whatever the extent's rounding (the host's width gives <= 17) */

/* face_rows: one work-item per table face. Writes the face plane (oriented with the light on its
 * positive side; all zeros for an edge-on or zero-area face), the first row (unwrapped), the number of
 * rows whose band [t0 + k dt, t0 + (k + 1) dt] meets the face's row-coordinate range widened by its pad
 * (the host sums them per row, times the pieces), that pad, and the pieces its span is cut into in every
 * row: its corners' s extent over piece_width, 1 to MAX_PIECES (a lookup's backward scan stops where the
 * row's running maximum of s_hi falls below s, so a span across the whole row, a ground under the
 * occluders, made every lookup walk the row back to its start). pad_t: the float32 error allowance of a
 * receiver's row coordinate (radians for a point light, where it grows as r / rho near the pole axis: the
 * pad is pad_t max(1, r / rho) over the corners; a length for a directional light). */
__kernel void face_rows(const __global float *vertices, const __global float *relative, const __global int *faces,
                        const __global int *face_ids, const int nfaces, const float t0, const float dt, const int rows,
                        const float anc_x, const float anc_y, const float anc_z, const float pad_t,
                        const float piece_width, __global float *planes, __global int *first_row,
                        __global int *row_count, __global float *pads, __global int *pieces)
{
    const int i = get_global_id(0);
    if (i >= nfaces) return;
    const int f = face_ids[i];
    float x0, y0, z0, x1, y1, z1, x2, y2, z2;
    /* Face plane n.x = d from the anchor-relative corners: exact to float32 near the occluders however
     * far the light (the light-centred corners carry the light's distance in their rounding). */
    LOAD3(relative, faces[3 * f], x0, y0, z0);
    LOAD3(relative, faces[3 * f + 1], x1, y1, z1);
    LOAD3(relative, faces[3 * f + 2], x2, y2, z2);
    const float ax = x1 - x0, ay = y1 - y0, az = z1 - z0, bx = x2 - x0, by = y2 - y0, bz = z2 - z0;
    float nx = ay * bz - az * by, ny = az * bx - ax * bz, nz = ax * by - ay * bx;
    float d = dot3(nx, ny, nz, x0, y0, z0);
#if LIGHT_POINT
    const float side = -(d + dot3(nx, ny, nz, anc_x, anc_y, anc_z));   /* n . (light - v0), the light at the origin */
#else
    (void)anc_x; (void)anc_y; (void)anc_z;
    const float side = nz;            /* n . (towards the light) */
#endif
    const float flip = side < 0.0f ? -1.0f : 1.0f;
    nx *= flip; ny *= flip; nz *= flip; d *= flip;
    const bool blocks = side != 0.0f;
    planes[4 * i] = blocks ? nx : 0.0f;
    planes[4 * i + 1] = blocks ? ny : 0.0f;
    planes[4 * i + 2] = blocks ? nz : 0.0f;
    planes[4 * i + 3] = blocks ? d : 0.0f;
    /* Row range: the rows whose band meets [tmin - pad, tmax + pad] */
    LOAD3(vertices, faces[3 * f], x0, y0, z0);
    LOAD3(vertices, faces[3 * f + 1], x1, y1, z1);
    LOAD3(vertices, faces[3 * f + 2], x2, y2, z2);
    float tmin, tmax, pad = pad_t;
    const float ta = row_coordinate(y0, z0), tb = row_coordinate(y1, z1), tc = row_coordinate(y2, z2);
    bool all_rows = false;
#if LIGHT_POINT
    /* unwrap round the first corner; a face round the X axis (the pole) spans every row */
    float db = tb - ta, dc = tc - ta;
    db += db > PI_F ? -2.0f * PI_F : (db < -PI_F ? 2.0f * PI_F : 0.0f);
    dc += dc > PI_F ? -2.0f * PI_F : (dc < -PI_F ? 2.0f * PI_F : 0.0f);
    tmin = ta + SC_MIN(0.0f, SC_MIN(db, dc));
    tmax = ta + SC_MAX(0.0f, SC_MAX(db, dc));
    /* the YZ projection (u, v) = (y, -z) contains the origin: edge functions of one sign */
    const float e0 = y0 * (-z1) - (-z0) * y1, e1 = y1 * (-z2) - (-z1) * y2, e2 = y2 * (-z0) - (-z2) * y0;
    all_rows = (e0 >= 0.0f && e1 >= 0.0f && e2 >= 0.0f) || (e0 <= 0.0f && e1 <= 0.0f && e2 <= 0.0f);
    /* a direction's theta rounds by ~ulp * r / rho (rho its distance from the pole axis) */
    const float rho = SC_MIN(SC_SQRT(y0 * y0 + z0 * z0), SC_MIN(SC_SQRT(y1 * y1 + z1 * z1), SC_SQRT(y2 * y2 + z2 * z2)));
    const float r = SC_MAX(SC_SQRT(x0 * x0 + y0 * y0 + z0 * z0),
                           SC_MAX(SC_SQRT(x1 * x1 + y1 * y1 + z1 * z1), SC_SQRT(x2 * x2 + y2 * y2 + z2 * z2)));
    pad = rho > r * pad_t ? pad_t * SC_MAX(1.0f, r / rho) : 2.0f * PI_F;
    all_rows = all_rows || tmax - tmin + 2.0f * pad >= 2.0f * PI_F;
#else
    tmin = SC_MIN(ta, SC_MIN(tb, tc));
    tmax = SC_MAX(ta, SC_MAX(tb, tc));
#endif
    int k0 = (int)SC_FLOOR((tmin - pad - t0) / dt);
    int k1 = (int)SC_FLOOR((tmax + pad - t0) / dt);
    if (all_rows) {
        k0 = 0;
        k1 = rows - 1;
    }
#if !FULL_CIRCLE
    k0 = max(k0, 0);
    k1 = min(k1, rows - 1);
#endif
    int n = blocks ? min(k1 - k0 + 1, rows) : 0;
    n = max(n, 0);
    first_row[i] = k0;
    row_count[i] = n;
    pads[i] = pad;
#if LIGHT_POINT
    const float sa = x0 / SC_MAX(SC_SQRT(x0 * x0 + y0 * y0 + z0 * z0), 1e-30f);
    const float sb = x1 / SC_MAX(SC_SQRT(x1 * x1 + y1 * y1 + z1 * z1), 1e-30f);
    const float sc = x2 / SC_MAX(SC_SQRT(x2 * x2 + y2 * y2 + z2 * z2), 1e-30f);
    const float extent = all_rows ? 2.0f : SC_MAX(sa, SC_MAX(sb, sc)) - SC_MIN(sa, SC_MIN(sb, sc));
#else
    const float extent = SC_MAX(x0, SC_MAX(x1, x2)) - SC_MIN(x0, SC_MIN(x1, x2));
#endif
    pieces[i] = clamp((int)ceil(extent / piece_width), 1, MAX_PIECES);
}

/* Clip the convex polygon (px, py, pz)[0..n) to g(p) = gx x + gy y + gz z + g0 >= 0 (in place; at most 5
 * corners: a triangle cut by two planes). Returns the new corner count. */
INLINE int clip_polygon(float *px, float *py, float *pz, int n, float gx, float gy, float gz, float g0)
{
    float qx[5], qy[5], qz[5];
    int m = 0;
    for (int e = 0; e < n; ++e) {
        const int g = e + 1 == n ? 0 : e + 1;
        const float ge = gx * px[e] + gy * py[e] + gz * pz[e] + g0, gg = gx * px[g] + gy * py[g] + gz * pz[g] + g0;
        if (ge >= 0.0f && m < 5) {
            qx[m] = px[e]; qy[m] = py[e]; qz[m] = pz[e]; ++m;
        }
        if ((ge >= 0.0f) != (gg >= 0.0f) && m < 5) {
            const float t = ge / (ge - gg);
            qx[m] = px[e] + t * (px[g] - px[e]); qy[m] = py[e] + t * (py[g] - py[e]); qz[m] = pz[e] + t * (pz[g] - pz[e]);
            ++m;
        }
    }
    for (int j = 0; j < m; ++j) {
        px[j] = qx[j]; py[j] = qy[j]; pz[j] = qz[j];
    }
    return m;
}

/* Span of a face over row band [ta, tb]: the s interval of the directions of the face whose row coordinate
 * lies in the band (the face clipped to the band's wedge, point light, or slab, directional), widened by
 * pad_s; (EMPTY_LO, EMPTY_HI) when it misses the band. Point light: s = x / |p| has no extremum on the
 * unit sphere but at the poles +-X, so it is extreme at a corner of the clipped polygon or inside an edge,
 * where the edge's great circle comes nearest +-X (s = +-sqrt(1 - nx^2 / |n|^2), n = a x b); a band a
 * half-turn wide or more is not clipped (its wedge is not convex): the face's whole s extent. */
INLINE void band_span(float x0, float y0, float z0, float x1, float y1, float z1, float x2, float y2, float z2,
                      float ta, float tb, float pad_s, float *lo, float *hi)
{
    float px[5] = {x0, x1, x2}, py[5] = {y0, y1, y2}, pz[5] = {z0, z1, z2};
    int n = 3;
    *lo = EMPTY_LO;
    *hi = EMPTY_HI;
#if LIGHT_POINT
    /* theta >= ta: sin(theta - ta) >= 0, i.e. (0, cos ta, sin ta) . p >= 0; theta <= tb likewise */
    if (tb - ta < PI_F) {
        n = clip_polygon(px, py, pz, n, 0.0f, cos(ta), sin(ta), 0.0f);
        n = clip_polygon(px, py, pz, n, 0.0f, -cos(tb), -sin(tb), 0.0f);
    }
    if (n < 3) return;
    float s_lo = 1.0f, s_hi = -1.0f;
    for (int e = 0; e < n; ++e) {
        const int g = e + 1 == n ? 0 : e + 1;
        const float r = SC_SQRT(px[e] * px[e] + py[e] * py[e] + pz[e] * pz[e]);
        const float s = r > 0.0f ? px[e] / r : 0.0f;
        s_lo = SC_MIN(s_lo, s);
        s_hi = SC_MAX(s_hi, s);
        /* inside the edge: its great circle's nearest point to +X, c = X - (n_x / |n|^2) n, when the arc holds it */
        const float nx = py[e] * pz[g] - pz[e] * py[g], ny = pz[e] * px[g] - px[e] * pz[g], nz = px[e] * py[g] - py[e] * px[g];
        const float nn = nx * nx + ny * ny + nz * nz;
        if (!(nn > 0.0f)) continue;
        const float k = nx / nn, cx = 1.0f - k * nx, cy = -k * ny, cz = -k * nz;
        /* (a x c) . n and (c x b) . n: c between a and b on the arc (their signs flip together for -c) */
        const float u = dot3(py[e] * cz - pz[e] * cy, pz[e] * cx - px[e] * cz, px[e] * cy - py[e] * cx, nx, ny, nz);
        const float v = dot3(cy * pz[g] - cz * py[g], cz * px[g] - cx * pz[g], cx * py[g] - cy * px[g], nx, ny, nz);
        const float peak = SC_SQRT(SC_MAX(0.0f, 1.0f - k * nx));
        if (u >= 0.0f && v >= 0.0f) s_hi = SC_MAX(s_hi, peak);
        if (u <= 0.0f && v <= 0.0f) s_lo = SC_MIN(s_lo, -peak);
    }
#else
    n = clip_polygon(px, py, pz, n, 0.0f, 1.0f, 0.0f, -ta);
    n = clip_polygon(px, py, pz, n, 0.0f, -1.0f, 0.0f, tb);
    if (n < 2) return;
    float s_lo = px[0], s_hi = px[0];
    for (int e = 1; e < n; ++e) {
        s_lo = SC_MIN(s_lo, px[e]);
        s_hi = SC_MAX(s_hi, px[e]);
    }
#endif
    *lo = s_lo - pad_s;
    *hi = s_hi + pad_s;
}

/* fill_rows: one work-item per table face; writes its records in every row it spans -- its span cut into
 * pieces[i] equal parts (ends shared bit for bit: an s on a cut lies in both), or as many empty records
 * when it misses the band -- each at the row's offset plus a slot taken from the row's cursor (offsets
 * from the exclusive prefix sum of counts). A slot past the row's end is not written; the cursor still
 * counts it and the host checks (lists.check_filled). */
__kernel void fill_rows(const __global float *vertices, const __global int *faces, const __global int *face_ids,
                        const int nfaces, const float t0, const float dt, const int rows, const float pad_s,
                        const __global float *planes, const __global int *first_row, const __global int *row_count,
                        const __global float *pads, const __global int *pieces, const __global int *offsets,
                        volatile __global int *cursor, __global float *records)
{
    const int i = get_global_id(0);
    if (i >= nfaces) return;
    const int n = row_count[i];
    if (n == 0) return;
    const int f = face_ids[i];
    float x0, y0, z0, x1, y1, z1, x2, y2, z2;
    LOAD3(vertices, faces[3 * f], x0, y0, z0);
    LOAD3(vertices, faces[3 * f + 1], x1, y1, z1);
    LOAD3(vertices, faces[3 * f + 2], x2, y2, z2);
    const int k0 = first_row[i], parts = pieces[i];
    const float pad = pads[i];
    for (int j = 0; j < n; ++j) {
        const int k = wrap_row(k0 + j, rows);
        float lo, hi;
        band_span(x0, y0, z0, x1, y1, z1, x2, y2, z2, t0 + (float)k * dt - pad, t0 + (float)(k + 1) * dt + pad, pad_s,
                  &lo, &hi);
        const float width = (hi - lo) / (float)parts;
        for (int part = 0; part < parts; ++part) {
            const int slot = offsets[k] + atomic_inc(&cursor[k]);
            if (slot >= offsets[k + 1]) continue;
            __global float *r = records + (size_t)REC * slot;
            const bool empty = lo > hi;
            r[0] = empty ? EMPTY_LO : (part == 0 ? lo : lo + (float)part * width);
            r[1] = empty ? EMPTY_HI : (part == parts - 1 ? hi : lo + (float)(part + 1) * width);
            r[2] = planes[4 * i];
            r[3] = planes[4 * i + 1];
            r[4] = planes[4 * i + 2];
            r[5] = planes[4 * i + 3];
            r[6] = as_float(f);
            r[7] = 0.0f;                   /* running max of s_hi, set by sort_rows */
        }
    }
}

INLINE void swap_records(__global float *rec, int a, int b)
{
    const float8 t = vload8(a, rec);
    vstore8(vload8(b, rec), a, rec);
    vstore8(t, b, rec);
}

/* Record a before record b: by s_lo, or (by_loop, crossings) by region (int bits in [5]), kind ([7]: ridge
 * crossings before crease duplicates), s, edge. */
INLINE bool record_before(const __global float *rec, int a, int b, bool by_loop)
{
    const __global float *ra = rec + REC * a, *rb = rec + REC * b;
    if (by_loop) {
        const int la = as_int(ra[5]), lb = as_int(rb[5]);
        if (la != lb) return la < lb;
        if (ra[7] != rb[7]) return ra[7] < rb[7];
        if (ra[0] != rb[0]) return ra[0] < rb[0];
        return as_int(ra[6]) < as_int(rb[6]);
    }
    return ra[0] < rb[0];
}

#define RECORD_BEFORE(rec, by_loop, a, b) record_before(rec, a, b, by_loop)
SC_DEFINE_SEGMENT_SORT(sort_records, __global float *, bool, RECORD_BEFORE, swap_records)

/* sort_rows: one work-item per row; sort of the row's records by s_lo, then the running maximum of
 * s_hi into each record's last float. */
__kernel void sort_rows(const __global int *offsets, const int rows, __global float *records)
{
    const int k = get_global_id(0);
    if (k >= rows) return;
    __global float *rec = records + (size_t)REC * offsets[k];
    const int n = offsets[k + 1] - offsets[k];
    sort_records(rec, false, n);
    /* r[7]: running maximum of s_hi along the row, so a lookup can stop scanning backwards */
    float run = -2.0f;
    for (int j = 0; j < n; ++j) {
        run = SC_MAX(run, rec[REC * j + 1]);
        rec[REC * j + 7] = run;
    }
}

/* ---- The paper's loop table (table="loops") ----------------------------------------------------------
 * An edge tail -> head crosses row k when the row's centre lies in the edge's row-coordinate range
 * (unwrapped the short way round for a point light). Edges [0, nridge) are ridge edges (loop order), the
 * rest concave creases between two lit faces, inserted in duplicate for depth (section 5). Crossing
 * record, 8 floats: s, x, y, z (the crossing point in the frame: its r = |(x, y, z)|), up (+1 towards
 * larger theta, -1 smaller), lit region (int bits: the pairing group), edge id (int bits), kind (0 ridge,
 * 1 crease duplicate). */

/* edge_rows: one work-item per ridge edge: first row (unwrapped) and number of rows it crosses. */
__kernel void edge_rows(const __global float *vertices, const __global int *tails, const __global int *heads,
                        const int nedges, const float t0, const float dt, const int rows,
                        __global int *first_row, __global int *row_count)
{
    const int i = get_global_id(0);
    if (i >= nedges) return;
    float x0, y0, z0, x1, y1, z1;
    LOAD3(vertices, tails[i], x0, y0, z0);
    LOAD3(vertices, heads[i], x1, y1, z1);
    const float ta = row_coordinate(y0, z0);
    float db = row_coordinate(y1, z1) - ta;
#if LIGHT_POINT
    db += db > PI_F ? -2.0f * PI_F : (db < -PI_F ? 2.0f * PI_F : 0.0f);
#endif
    const float tmin = ta + SC_MIN(0.0f, db), tmax = ta + SC_MAX(0.0f, db);
    int k0 = (int)ceil((tmin - t0) / dt - 0.5f);
    int k1 = (int)SC_FLOOR((tmax - t0) / dt - 0.5f);
#if !FULL_CIRCLE
    k0 = max(k0, 0);
    k1 = min(k1, rows - 1);
#endif
    first_row[i] = k0;
    row_count[i] = max(min(k1 - k0 + 1, rows), 0);
}

/* fill_edges: one work-item per ridge edge; its crossing record in every row it crosses, at the row's
 * offset plus a slot from the row's cursor; past the row's end nothing is written (as fill_rows). */
__kernel void fill_edges(const __global float *vertices, const __global int *tails, const __global int *heads,
                         const __global int *group, const int nedges, const int nridge, const float t0, const float dt,
                         const int rows,
                         const __global int *first_row, const __global int *row_count,
                         const __global int *offsets, volatile __global int *cursor, __global float *crossings)
{
    const int i = get_global_id(0);
    if (i >= nedges) return;
    const int n = row_count[i];
    float x0, y0, z0, x1, y1, z1;
    LOAD3(vertices, tails[i], x0, y0, z0);
    LOAD3(vertices, heads[i], x1, y1, z1);
    for (int j = 0; j < n; ++j) {
        const int k = wrap_row(first_row[i] + j, rows);
        const float tk = t0 + ((float)k + 0.5f) * dt;
#if LIGHT_POINT
        const float my = cos(tk), mz = sin(tk);
        const float a = my * y0 + mz * z0, b = my * y1 + mz * z1;
        const float up = a < b ? 1.0f : -1.0f;   /* moving towards the plane's positive side: larger theta */
#else
        const float a = y0 - tk, b = y1 - tk;
        const float up = a < b ? 1.0f : -1.0f;
#endif
        const float t = a != b ? SC_MIN(SC_MAX(a / (a - b), 0.0f), 1.0f) : 0.5f;
        const float cx = x0 + t * (x1 - x0), cy = y0 + t * (y1 - y0), cz = z0 + t * (z1 - z0);
#if LIGHT_POINT
        const float r = SC_SQRT(cx * cx + cy * cy + cz * cz);
        const float s = r > 0.0f ? cx / r : 0.0f;
#else
        const float s = cx;
#endif
        const int slot = offsets[k] + atomic_inc(&cursor[k]);
        if (slot >= offsets[k + 1]) continue;
        __global float *c = crossings + (size_t)REC * slot;
        c[0] = s; c[1] = cx; c[2] = cy; c[3] = cz; c[4] = up;
        c[5] = as_float(group[i]);
        c[6] = as_float(i);
        c[7] = i < nridge ? 0.0f : 1.0f;
    }
}

/* Unit direction of crossing c's ridge edge, turned towards larger theta. */
INLINE void edge_direction(const __global float *vertices, const __global int *tails, const __global int *heads,
                           const __global float *c, float *ux, float *uy, float *uz)
{
    const int e = as_int(c[6]);
    if (e < 0) {                       /* a pole crossing: no edge */
        *ux = *uy = *uz = 0.0f;
        return;
    }
    float x0, y0, z0, x1, y1, z1;
    LOAD3(vertices, tails[e], x0, y0, z0);
    LOAD3(vertices, heads[e], x1, y1, z1);
    const float sign = c[4] / SC_MAX(SC_SQRT((x1 - x0) * (x1 - x0) + (y1 - y0) * (y1 - y0) + (z1 - z0) * (z1 - z0)),
                                     1e-30f);
    *ux = sign * (x1 - x0); *uy = sign * (y1 - y0); *uz = sign * (z1 - z0);
}

/* fill_poles: one work-item per row; the pole crossings (x = poles[j], the pole axis piercing a lit face
 * of region pole_regions[j]) at the row's first slots. s = sign(x); up as a ridge crossing there would go:
 * lit faces turn counter-clockwise to the light and (X, m) is counter-clockwise seen from it, so a region
 * lies at larger s where its boundary goes down (-1: the -X pole opens a span) and the +X pole closes one. */
__kernel void fill_poles(const __global float *poles, const __global int *pole_regions, const int npoles,
                         const int rows, const __global int *offsets, __global float *crossings)
{
    const int k = get_global_id(0);
    if (k >= rows) return;
    for (int j = 0; j < npoles && offsets[k] + j < offsets[k + 1]; ++j) {   /* the host counts npoles a row */
        __global float *c = crossings + (size_t)REC * (offsets[k] + j);
        const float x = poles[j];
        c[0] = x > 0.0f ? 1.0f : -1.0f;
        c[1] = x; c[2] = 0.0f; c[3] = 0.0f;
        c[4] = x > 0.0f ? 1.0f : -1.0f;
        c[5] = as_float(pole_regions[j]);
        c[6] = as_float(-1);
        c[7] = 0.0f;
    }
}

/* The pair record of crossings A (entering) and B (leaving) of one loop in row tk: s_lo, s_hi, then a
 * plane through A and B, oriented with the light on its positive side, then -(loop + 1) (int bits) and 0.
 * In the row's centre plane the ray to a receiver meets it on the chord AB: the depth interpolated between
 * the pair's ends (section 5's "simple trigonometry"). Off the centre plane (a receiver's theta is up to
 * half a row away) it extends along the mean of the two ridge edges' directions, so a cap bounded by its
 * loop (a planar face, a terminator's plane) keeps its own depth; along the row plane's normal instead,
 * receivers on the occluder's own lit cap fell on the wrong side of it (half of them, cube over plane). */
INLINE void write_pair(__global float *out, const __global float *ca, const __global float *cb, float tk,
                       const __global float *vertices, const __global int *tails, const __global int *heads,
                       const float anc_x, const float anc_y, const float anc_z)
{
    float ax, ay, az, bx, by, bz;
    edge_direction(vertices, tails, heads, ca, &ax, &ay, &az);
    edge_direction(vertices, tails, heads, cb, &bx, &by, &bz);
    const float ex = cb[1] - ca[1], ey = cb[2] - ca[2], ez = cb[3] - ca[3];
    float mx = ax + bx, my = ay + by, mz = az + bz;
    {   /* fall back to the row plane's normal when the mean direction is (nearly) along the chord */
        const float cx = ey * mz - ez * my, cy = ez * mx - ex * mz, cz = ex * my - ey * mx;
        const float e2 = ex * ex + ey * ey + ez * ez, m2 = mx * mx + my * my + mz * mz;
        if (cx * cx + cy * cy + cz * cz <= 1e-6f * e2 * m2) {
#if LIGHT_POINT
            mx = 0.0f; my = cos(tk); mz = sin(tk);
#else
            mx = 0.0f; my = 1.0f; mz = 0.0f;
#endif
        }
    }
    float nx = ey * mz - ez * my, ny = ez * mx - ex * mz, nz = ex * my - ey * mx;
    float d = dot3(nx, ny, nz, ca[1], ca[2], ca[3]);
#if LIGHT_POINT
    const float side = -d;
#else
    const float side = nz;
#endif
    const float flip = side < 0.0f ? -1.0f : (side > 0.0f ? 1.0f : 0.0f);   /* 0: degenerate, never blocks */
    out[0] = SC_MIN(ca[0], cb[0]);
    out[1] = SC_MAX(ca[0], cb[0]);
    out[2] = nx * flip; out[3] = ny * flip; out[4] = nz * flip;
    out[5] = (d - dot3(nx, ny, nz, anc_x, anc_y, anc_z)) * flip;     /* relative to the anchor, as face records */
    out[6] = as_float(-(as_int(ca[5]) + 1));
    out[7] = 0.0f;
}

/* pair_rows: one work-item per row. Sorts the row's crossings by (region, kind, s) and pairs each lit
 * region's ridge crossings by section 4's rule: in s order, a crossing going the way the region's first
 * one goes (or any while none waits) waits; one going the other way pairs with the oldest waiting (first
 * in, first out), so the chains leaving a local theta peak bound one span and coils pair correctly; a
 * region's outer loop and its holes pair together (a torus lit from above: its hole stays lit). Each pair
 * is then cut at the region's crease duplicates inside it (section 5): A h1, h1 h2, ..., hn B.
 * Output: pairs[cap * offsets[k] + p], p < npairs[k] <= cap * (crossings of row k); more sets overflow[0]
 * (the host grows cap and reruns). queue: int scratch as long as the crossings. */
__kernel void pair_rows(const __global int *offsets, const int rows, const float t0, const float dt,
                        const __global float *vertices, const __global int *tails, const __global int *heads,
                        const int cap, const float anc_x, const float anc_y, const float anc_z,
                        __global float *crossings, __global int *queue, __global float *pairs,
                        __global int *npairs, volatile __global int *overflow)
{
    const int k = get_global_id(0);
    if (k >= rows) return;
    const int base = offsets[k], n = offsets[k + 1] - offsets[k], limit = cap * n;
    __global float *c = crossings + (size_t)REC * base;
    __global float *out = pairs + (size_t)REC * cap * base;
    __global int *q = queue + base;
    sort_records(c, true, n);
    const float tk = t0 + ((float)k + 0.5f) * dt;
    int p = 0;
    for (int g = 0; g < n;) {
        const int region = as_int(c[REC * g + 5]);
        const float opener = c[REC * g + 4];
        int head = 0, tail = 0, j = g;
        for (; j < n && as_int(c[REC * j + 5]) == region && c[REC * j + 7] == 0.0f; ++j) {
            if (c[REC * j + 4] == opener || head == tail) {
                q[tail++] = j;
                continue;
            }
            /* pair (q[head], j), cut at the region's duplicates inside it (they follow its ridge crossings) */
            int from = q[head++];
            const float lo = c[REC * from], hi = c[REC * j];
            int d = j + 1;
            while (d < n && as_int(c[REC * d + 5]) == region && c[REC * d + 7] == 0.0f) ++d;
            for (; d < n && as_int(c[REC * d + 5]) == region; ++d) {
                const float sd = c[REC * d];
                if (sd <= lo || sd >= hi) continue;
                if (p < limit) write_pair(out + REC * p, c + REC * from, c + REC * d, tk, vertices, tails, heads, anc_x, anc_y, anc_z);
                ++p;
                from = d;
            }
            if (p < limit) write_pair(out + REC * p, c + REC * from, c + REC * j, tk, vertices, tails, heads, anc_x, anc_y, anc_z);
            ++p;
        }
        while (j < n && as_int(c[REC * j + 5]) == region) ++j;       /* skip the region's duplicates */
        g = j;
    }
    if (p > limit) atomic_max(overflow, p - limit);
    npairs[k] = min(p, limit);
}

/* copy_pairs: one work-item per row; its npairs[k] pair records (from cap * src_offsets[k]) to
 * dst_offsets[k] (the merged table). */
__kernel void copy_pairs(const __global int *src_offsets, const __global int *npairs, const __global int *dst_offsets,
                         const int rows, const int cap, const __global float *pairs, __global float *records)
{
    const int k = get_global_id(0);
    if (k >= rows) return;
    const int n = npairs[k];
    for (int j = 0; j < n; ++j)
        vstore8(vload8(cap * src_offsets[k] + j, pairs), dst_offsets[k] + j, records);
}

/* Edge function of edge (vertex i, vertex j) at p (all anchor-relative): its sign says on which side of the
 * plane through the light and the edge p lies (point light: det(vi - L, vj - L, p - L), written as
 * ((vi - L) x (vj - vi)) . (p - vi) so that only the first factor carries the light's distance; directional:
 * the 2D cross product in XY). Computed from the lower vertex index and negated for the other order, so
 * two faces sharing the edge get the same value bit for bit: a ray through a shared edge is inside both
 * (or neither has a gap), the test is watertight. */
INLINE float edge_function(const __global float *rel, int i, int j, float px, float py, float pz,
                           float anc_x, float anc_y, float anc_z)
{
    const int a = min(i, j), b = max(i, j);
    float ax, ay, az, bx, by, bz;
    LOAD3(rel, a, ax, ay, az);
    LOAD3(rel, b, bx, by, bz);
    const float ex = bx - ax, ey = by - ay, ez = bz - az, qx = px - ax, qy = py - ay, qz = pz - az;
#if LIGHT_POINT
    const float lx = ax + anc_x, ly = ay + anc_y, lz = az + anc_z;
    const float value = dot3(ly * ez - lz * ey, lz * ex - lx * ez, lx * ey - ly * ex, qx, qy, qz);
#else
    (void)az; (void)bz; (void)qz; (void)anc_x; (void)anc_y; (void)anc_z;
    const float value = ex * qy - ey * qx;
#endif
    return i < j ? value : -value;
}

/* The face of record r blocks the segment from p to the light, further than eps from p. p (px, py, pz) and
 * the plane's offset r[5] are relative to the anchor (an, its position from the light): the height of p
 * over the plane, dq = n.p - d, is then as exact as float32 near the occluders allows, whatever the
 * light's distance; n.(p + an) is p's own offset from the light's plane parallel to it. A face record
 * (r[6] >= 0, the face) then needs the segment to cross the triangle itself (rel, faces: anchor-relative
 * corners): its span covers the whole row band, so its plane must not count past the face's edges. Given
 * the plane hit, the segment's line meets the plane once, so the three edge functions of one sign (either,
 * zero included) say the hit lies in the triangle. A loop pair's chord plane (r[6] < 0) is used as is. */
INLINE bool record_blocks(const __global float *r, const __global float *rel, const __global int *faces,
                          float px, float py, float pz, float anc_x, float anc_y, float anc_z, float dist, float eps)
{
    const float dq = dot3(r[2], r[3], r[4], px, py, pz) - r[5];
#if LIGHT_POINT
    /* light-centred: hit at t p, t = d / q in (0, 1) when q < d < 0; its distance from p is
     * (1 - t) |p| = (q - d) / q |p| > eps */
    const float q = dot3(r[2], r[3], r[4], px + anc_x, py + anc_y, pz + anc_z);
    if (!(dq * dist < eps * q)) return false;
#else
    (void)dist;
    if (!(-dq > eps * r[4])) return false;                 /* hit (d - q) / nz above p, nz > 0 */
#endif
    const int f = as_int(r[6]);
    if (f < 0) return true;
    const int i0 = faces[3 * f], i1 = faces[3 * f + 1], i2 = faces[3 * f + 2];
    const float e0 = edge_function(rel, i0, i1, px, py, pz, anc_x, anc_y, anc_z);
    const float e1 = edge_function(rel, i1, i2, px, py, pz, anc_x, anc_y, anc_z);
    const float e2 = edge_function(rel, i2, i0, px, py, pz, anc_x, anc_y, anc_z);
    return (e0 >= 0.0f && e1 >= 0.0f && e2 >= 0.0f) || (e0 <= 0.0f && e1 <= 0.0f && e2 <= 0.0f);
}

/* Receiver set-up: row, key s and distance; with normals a back-facing receiver is shadowed (code 1)
 * and the others are moved eps along the normal. Returns -1 for "shadowed by facing", else the row
 * (-2 outside the table: lit). */
INLINE int receiver_row(float *px, float *py, float *pz, float anc_x, float anc_y, float anc_z, float nx, float ny, float nz,
                        float eps, float t0, float inv_dt, int rows, float *s, float *dist)
{
#if NORMALS
#if LIGHT_POINT
    if (dot3(nx, ny, nz, -(*px + anc_x), -(*py + anc_y), -(*pz + anc_z)) <= 0.0f) return -1;
#else
    if (nz <= 0.0f) return -1;
#endif
    *px += eps * nx; *py += eps * ny; *pz += eps * nz;
#else
    (void)nx; (void)ny; (void)nz;
#endif
    const float lx = *px + anc_x, ly = *py + anc_y, lz = *pz + anc_z;   /* light-centred */
    *dist = SC_SQRT(lx * lx + ly * ly + lz * lz);
#if LIGHT_POINT
    *s = *dist > 0.0f ? lx / *dist : 0.0f;
#else
    *s = lx;
#endif
    const int k = row_of(row_coordinate(ly, lz), t0, inv_dt, rows);
    return k < 0 ? -2 : k;
}

/* Section 7 step 2 over one row [begin, end) (sorted by s_lo, r[7] the running max of s_hi): the record
 * that blocks p, or -1. A binary search finds the records starting at or before s; the scan goes
 * backwards from there and stops where the running max of s_hi falls below s (no earlier record can
 * contain s). Also returns, for scan-line runs, the largest s_hi below s among the records starting at
 * or before s (prev_hi), the first s_lo after s (next_lo, the paper's nextX), and up to two records
 * containing s that do not block p (c0, c1; inside counts them all). */
INLINE int row_lookup(const __global float *records, const __global float *rel, const __global int *faces, int begin, int end, float s, float px, float py, float pz,
                      float anc_x, float anc_y, float anc_z, float dist, float eps, float *prev_hi, float *next_lo,
                      int *c0, int *c1, int *inside)
{
    int lo = begin, hi = end;
    while (lo < hi) {
        const int mid = (lo + hi) >> 1;
        if (records[(size_t)REC * mid] <= s) lo = mid + 1;
        else hi = mid;
    }
    *next_lo = lo < end ? records[(size_t)REC * lo] : 2.0f;
    *prev_hi = -2.0f;
    *c0 = *c1 = -1;
    *inside = 0;
    for (int j = lo - 1; j >= begin; --j) {
        const __global float *r = records + (size_t)REC * j;
        if (r[7] < s) {
            *prev_hi = SC_MAX(*prev_hi, r[7]);
            break;
        }
        if (r[1] >= s) {
            if (record_blocks(r, rel, faces, px, py, pz, anc_x, anc_y, anc_z, dist, eps)) return j;
            *c1 = *inside == 1 ? j : *c1;
            *c0 = *inside == 0 ? j : *c0;
            ++*inside;
        } else {
            *prev_hi = SC_MAX(*prev_hi, r[1]);
        }
    }
    return -1;
}

/* angular_classify: one work-item per receiver (frame coordinates, unit frame normals when NORMALS).
 * out[i] = 1 in shadow, 0 lit: row_lookup, first hit wins. */
__kernel void angular_classify(const __global input_t *points, const __global input_t *normals, const int n,
                               const __global input_t *rot, const input_t ox, const input_t oy, const input_t oz,
                               const float anc_x, const float anc_y, const float anc_z, const float t0, const float inv_dt, const int rows, const float eps,
                               const __global int *offsets, const __global float *records,
                               const __global float *rel, const __global int *faces, __global uchar *out)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    float px, py, pz, nx = 0.0f, ny = 0.0f, nz = 0.0f, s, dist;
    load_receiver(points, normals, i, rot, ox, oy, oz, anc_x, anc_y, anc_z, &px, &py, &pz, &nx, &ny, &nz);
    const int k = receiver_row(&px, &py, &pz, anc_x, anc_y, anc_z, nx, ny, nz, eps, t0, inv_dt, rows, &s, &dist);
    uchar shadow = k == -1;
    if (k >= 0) {
        float prev_hi, next_lo;
        int c0, c1, inside;
        shadow = row_lookup(records, rel, faces, offsets[k], offsets[k + 1], s, px, py, pz, anc_x, anc_y, anc_z, dist, eps, &prev_hi, &next_lo,
                            &c0, &c1, &inside) >= 0;
    }
    out[i] = shadow;
}

INLINE bool record_hits(const __global float *records, const __global float *rel, const __global int *faces, int j, float s, float px, float py, float pz, float anc_x,
                        float anc_y, float anc_z, float dist, float eps)
{
    const __global float *r = records + (size_t)REC * j;
    return j >= 0 && r[0] <= s && s <= r[1] && record_blocks(r, rel, faces, px, py, pz, anc_x, anc_y, anc_z, dist, eps);
}

/* angular_runs: one work-item per scan line of the camera image; its receivers are
 * [line_start[l], line_start[l + 1]) in left-to-right order. A lookup (section 7 step 2) leaves a run
 * state valid for the following receivers of the same row while their s stays in an interval:
 *  - shadow: the hitting record's span; a receiver in it that the record still blocks is in shadow;
 *  - lit: the open interval between the last span ending before s and the next span starting after s
 *    (the paper's nextX), when at most two spans contain s (the receiver's own lit face, usually): no
 *    other span can contain a receiver in the interval, so re-testing those two decides it.
 * Anything else makes a full lookup: the result is bit for bit the per-receiver one.
 * lookups[l] counts the full lookups of line l. */
__kernel void angular_runs(const __global input_t *points, const __global input_t *normals,
                           const __global input_t *rot, const input_t ox, const input_t oy, const input_t oz,
                           const float anc_x, const float anc_y, const float anc_z, const __global int *line_start, const int lines, const float t0, const float inv_dt, const int rows, const float eps,
                           const __global int *offsets, const __global float *records,
                           const __global float *rel, const __global int *faces, __global uchar *out,
                           __global int *lookups)
{
    const int l = get_global_id(0);
    if (l >= lines) return;
    int cur_row = -3, mode = 0, c0 = -1, c1 = -1, count = 0;     /* mode 0 none, 1 shadow run, 2 lit run */
    float lo = 1.0f, hi = -1.0f;
    const int end_i = line_start[l + 1];
    for (int i = line_start[l]; i < end_i; ++i) {
        float px, py, pz, nx = 0.0f, ny = 0.0f, nz = 0.0f, s, dist;
        load_receiver(points, normals, i, rot, ox, oy, oz, anc_x, anc_y, anc_z, &px, &py, &pz, &nx, &ny, &nz);
        const int k = receiver_row(&px, &py, &pz, anc_x, anc_y, anc_z, nx, ny, nz, eps, t0, inv_dt, rows, &s, &dist);
        if (k < 0) {
            out[i] = k == -1;
            continue;
        }
        if (k == cur_row && mode != 0 && (mode == 1 ? (s >= lo && s <= hi) : (s > lo && s < hi))) {
            if (record_hits(records, rel, faces, c0, s, px, py, pz, anc_x, anc_y, anc_z, dist, eps) || record_hits(records, rel, faces, c1, s, px, py, pz, anc_x, anc_y, anc_z, dist, eps)) {
                out[i] = 1;
                continue;
            }
            if (mode == 2) {
                out[i] = 0;
                continue;
            }
        }
        /* full lookup */
        ++count;
        cur_row = k;
        float prev_hi, next_lo;
        int inside;
        const int hit = row_lookup(records, rel, faces, offsets[k], offsets[k + 1], s, px, py, pz, anc_x, anc_y, anc_z, dist, eps, &prev_hi, &next_lo,
                                   &c0, &c1, &inside);
        if (hit >= 0) {
            mode = 1;
            c0 = hit;
            c1 = -1;
            lo = records[(size_t)REC * hit];
            hi = records[(size_t)REC * hit + 1];
        } else {
            mode = inside <= 2 ? 2 : 0;
            lo = prev_hi;
            hi = next_lo;
        }
        out[i] = hit >= 0;
    }
    lookups[l] = count;
}
