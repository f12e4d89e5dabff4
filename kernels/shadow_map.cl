/* shadow_map.cl: Williams' (1978) shadow test of receivers against the light's depth map(s).
 *
 * The depth maps themselves are drawn by raster.cl (one rasterizer, two views); this file only
 * transforms receivers into light space and compares. Conventions (host/shadowcl/views.py): clip =
 * matrix * (relative position, 1); depth = z / w, 1 nearest (reversed Z), 0 empty; texel (row, col)
 * samples screen ((col + 0.5), (row + 0.5)) with row 0 at the top.
 *
 * The host (host/shadowcl/shadow_map.py) specialises the kernel with -D:
 *   PERSPECTIVE  1: views are perspective (depth = near (far - w) / (w (far - near)) of the distance w
 *                along the view axis, near / w for a cube's infinite far; the ray from the light's eye);
 *                0: one orthographic view (depth = (far - distance) / (far - near), along the light)
 *   CUBE         1: six square faces +x -x +y -y +z -z, a point uses the face of its dominant axis
 *   RES          texels per side of every map
 *   FILTER       0 nearest texel, 1 bilinear depth (Williams), 2 percentage-closer k x k
 *   PCF_K        k of the percentage-closer filter (odd)
 *   BIAS         0 constant, 1 slope-scaled, 2 normal offset, 3 plane (the stored triangles' planes and
 *                exact tests at the receiver's ray instead of stored depths; needs the triangle maps)
 *   NORMALS      1: normals are given (facing test, slope and offset use them)
 *   DITHER       1: Williams' +-0.5 texel noise on the transformed coordinates
 */

#include "vecmath.h"
#include "ray_triangle.h"

#define VIEW_FLOATS 20 /* matrix (16, row-major), texel scale, near, far, near / far (perspective; 0: far infinite) */
#define TAN_MAX 16.0f  /* slope bias is capped there: beyond ~86 degrees it would lift the shadow off */

/* Lowbias32 (C. Wellons): a well-mixed 32-bit hash; reference/shadow_map.py repeats it bit for bit. */
INLINE uint hash32(uint x)
{
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

/* Uniform in [-0.5, 0.5) from 24 bits of a hash: exact in float32 on every device. */
INLINE float centred_noise(const uint h)
{
    return (float)(h >> 8) * 0x1p-24f - 0.5f;
}

/* Distance along the view axis (perspective: from the eye; orthographic: from the view origin) of
 * a map or receiver depth. Empty texels (depth 0) come out infinitely (perspective) or far-plane far. */
INLINE float distance_of(const float depth, global const float *v)
{
#if PERSPECTIVE
    return depth > 0.0f ? v[17] / (depth * (1.0f - v[19]) + v[19]) : SC_BIG;
#else
    return v[18] - depth * (v[18] - v[17]);
#endif
}

INLINE float map_depth(global const float *map, const int row, const int col)
{
    return map[clamp(row, 0, RES - 1) * RES + clamp(col, 0, RES - 1)];
}

/* Fraction of the filter's samples around texel coordinates (s, t) (texel centres at integers) whose
 * stored surface is not nearer than the receiver at distance `reach` (its distance minus the bias). */
INLINE float lit_fraction(global const float *map, global const float *v, const float s, const float t,
                          const float reach)
{
#if FILTER == 1
    /* Williams: interpolate the light's depths at the exact (s, t). Depth is affine in screen space
     * over a plane (1 / distance in perspective), so a lit plane is reproduced exactly. */
    const float s0 = SC_FLOOR(s), t0 = SC_FLOOR(t), fs = s - s0, ft = t - t0;
    const int c = (int)s0, r = (int)t0;
    const float top = map_depth(map, r, c) + fs * (map_depth(map, r, c + 1) - map_depth(map, r, c));
    const float bottom = map_depth(map, r + 1, c) + fs * (map_depth(map, r + 1, c + 1) - map_depth(map, r + 1, c));
    return distance_of(top + ft * (bottom - top), v) >= reach ? 1.0f : 0.0f;
#else
    const int c = (int)SC_FLOOR(s + 0.5f), r = (int)SC_FLOOR(t + 0.5f);
#if FILTER == 0
    return distance_of(map_depth(map, r, c), v) >= reach ? 1.0f : 0.0f;
#else
    int lit = 0;
    for (int dr = -(PCF_K / 2); dr <= PCF_K / 2; ++dr)
        for (int dc = -(PCF_K / 2); dc <= PCF_K / 2; ++dc)
            lit += distance_of(map_depth(map, r + dr, c + dc), v) >= reach;
    return (float)lit / (float)(PCF_K * PCF_K);
#endif
#endif
}

/* Plane bias ------------------------------------------------------------------------------------- */

#define PRECISION_ULPS 16.0f /* float32 rounding of a relative position and of a triangle's plane, in FLT_EPSILON */

/* Triangle id stored at a texel (indices clamped to the map), -1 for none. */
INLINE int map_triangle(global const int *ids, const int row, const int col)
{
    return ids[clamp(row, 0, RES - 1) * RES + clamp(col, 0, RES - 1)];
}

/* What stored triangle f (-1: none) says about the ray s + lambda l from a receiver's start s (l unit,
 * towards the light), one of:
 * HIT     its exact (watertight) test hits for tmin < lambda < tmax;
 * BEHIND  the ray meets it at or behind s: -behind < lambda < tmin (the caller's window): the light
 *         sees the receiver's own surface (or one behind it) near this texel;
 * AHEAD   its plane, continued over the ray, crosses it more than `ahead` in front of s and before the
 *         light: the surface the texel stands for, in case the ray passes the stored triangle but meets
 *         the same surface beyond it (triangles smaller than a texel are not all in the map);
 * 0       none of these.
 * Plane distances are differences of positions near the maps' origin: precise for a light at any
 * distance. */
#define HIT 1
#define BEHIND 2
#define AHEAD 3

INLINE int triangle_verdict(global const float *vertices, global const int *faces, const int f, const WtRay *ray,
                            const float tmin, const float tmax, const float ahead, const float behind)
{
    if (f < 0)
        return 0;
    float ax, ay, az, bx, by, bz, cx, cy, cz;
    LOAD3(vertices, faces[3 * f], ax, ay, az);
    LOAD3(vertices, faces[3 * f + 1], bx, by, bz);
    LOAD3(vertices, faces[3 * f + 2], cx, cy, cz);
    const float ux = bx - ax, uy = by - ay, uz = bz - az, vx = cx - ax, vy = cy - ay, vz = cz - az;
    const float nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    const float facing = dot3(nx, ny, nz, ray->dx, ray->dy, ray->dz);
    const float lambda = dot3(nx, ny, nz, ax - ray->ox, ay - ray->oy, az - ray->oz) / facing;
    /* One watertight test over both intervals; the plane's lambda says which (they differ by rounding
     * only, where lambda is within rounding of tmin) */
    if (wt_hit(ray, ax, ay, az, bx, by, bz, cx, cy, cz, -behind, tmax))
        return lambda > tmin ? HIT : BEHIND;
    return facing != 0.0f && lambda > ahead && lambda < tmax ? AHEAD : 0;   /* a plane along the ray: none */
}

/* Visibility of the ray's start s projected at texel coordinates (s, t) from the stored triangles of
 * the texels the filter reads (nearest: the 3 x 3 around, as the texel's own triangle may not be the
 * one above s near a silhouette). A texel shadows s when its triangle is HIT, or AHEAD unless some
 * texel's triangle is BEHIND (then the light sees s's own surface there, and only an exact hit
 * shadows it: no plane continued from a neighbouring face across an edge). Nearest: in shadow
 * when any of the 3 x 3 is HIT or the own texel shadows; bilinear: lit when the texels not shadowing
 * carry at least half of the bilinear weight of the four around (a binary answer, as Williams'
 * interpolated depth gives); pcf: the fraction of the k x k texels not shadowing. */
INLINE float plane_lit_fraction(global const int *ids, global const float *vertices, global const int *faces,
                                const WtRay *ray, const float s, const float t, const float tmin, const float tmax,
                                const float ahead, const float behind)
{
    float hit = 0.0f, ahead_weight = 0.0f;   /* the weight of the texels HIT and AHEAD */
    int seen = 0;                            /* a texel's triangle is BEHIND */
#if FILTER == 1
    const float s0 = SC_FLOOR(s), t0 = SC_FLOOR(t), fs = s - s0, ft = t - t0;
    const int c = (int)s0, r = (int)t0;
    for (int dr = 0; dr <= 1; ++dr)
        for (int dc = 0; dc <= 1; ++dc) {
            const float weight = (dc ? fs : 1.0f - fs) * (dr ? ft : 1.0f - ft);
            const int f = map_triangle(ids, r + dr, c + dc);
            const int v = triangle_verdict(vertices, faces, f, ray, tmin, tmax, ahead, behind);
            hit += v == HIT ? weight : 0.0f;
            ahead_weight += v == AHEAD ? weight : 0.0f;
            seen |= v == BEHIND;
        }
    return 1.0f - hit - (seen ? 0.0f : ahead_weight) >= 0.5f ? 1.0f : 0.0f;
#else
    const int c = (int)SC_FLOOR(s + 0.5f), r = (int)SC_FLOOR(t + 0.5f);
#if FILTER == 0
#define SIDE 3
#else
#define SIDE PCF_K
#endif
    const int reach = SIDE / 2;
    /* Neighbouring texels mostly hold the same triangle: its verdict is reused from the texel to the
     * left or above rather than tested again (same answer, a few tests instead of SIDE^2). */
    int above_f[SIDE], above_v[SIDE];
    for (int k = 0; k < SIDE; ++k)
        above_f[k] = -2;
#if FILTER == 0
    /* The own texel first: in a shadow it is usually hit, and one hit decides */
    const int own_f = map_triangle(ids, r, c);
    const int own_v = triangle_verdict(vertices, faces, own_f, ray, tmin, tmax, ahead, behind);
    if (own_v == HIT)
        return 0.0f;
#endif
    for (int dr = -reach; dr <= reach; ++dr) {
        int left_f = -2, left_v = 0;
        for (int dc = -reach; dc <= reach; ++dc) {
            const int f = map_triangle(ids, r + dr, c + dc), k = dc + reach;
#if FILTER == 0
            const int v = f == own_f ? own_v : (f == left_f ? left_v : (f == above_f[k] ? above_v[k]
                          : triangle_verdict(vertices, faces, f, ray, tmin, tmax, ahead, behind)));
            if (v == HIT)
                return 0.0f;
#else
            const int v = f == left_f ? left_v : (f == above_f[k] ? above_v[k]
                          : triangle_verdict(vertices, faces, f, ray, tmin, tmax, ahead, behind));
#endif
            left_f = above_f[k] = f;
            left_v = above_v[k] = v;
            hit += v == HIT;
#if FILTER == 0
            ahead_weight += v == AHEAD && dr == 0 && dc == 0;   /* the own texel's plane only */
#else
            ahead_weight += v == AHEAD;
#endif
            seen |= v == BEHIND;
        }
    }
#undef SIDE
#if FILTER == 0
    return hit > 0.0f || (!seen && ahead_weight > 0.0f) ? 0.0f : 1.0f;
#else
    return 1.0f - (hit + (seen ? 0.0f : ahead_weight)) / (float)(PCF_K * PCF_K);
#endif
#endif
}

/* shadow_visibility: one work-item per receiver, n receivers.
 * In:  points (3 floats each, relative to the maps' origin), normals (3 floats each, unit; read only
 *      when NORMALS), to_light: the eye (PERSPECTIVE) or the unit direction towards the light;
 *      views (VIEW_FLOATS per view), map0..map5 (RES x RES depths, row-major: view k's map is mapk;
 *      a single view reads map0 only),
 *      ids0..ids5 (RES x RES triangle ids, -1 empty; read only when BIAS == 3), vertices (3 floats
 *      each, relative to the maps' origin) and faces (3 ints each) of the mesh drawn, extent: the
 *      largest |coordinate| of those vertices (sets the rounding allowance),
 *      bias = (constant, slope / offset coefficient) in texels, eps: DESIGN.md's offset (the start
 *      moves eps along the normal, and surfaces within eps of it along the ray do not shadow it),
 *      seed of the dither.
 * Out: visibility[i] in [0, 1]: the filtered fraction of the light's depth samples that do not
 *      occlude receiver i; 0 for a normal facing away from the light (dot <= 0).
 * Assumes every point projects in front of its view (inside the receiver bounds the views were
 * fitted to); texel indices are clamped to the map, so a point off the map reads its edge. */
kernel void shadow_visibility(global const float *points, global const float *normals, const float4 to_light,
                              global const float *views, global const float *map0, global const float *map1,
                              global const float *map2, global const float *map3, global const float *map4,
                              global const float *map5, global const int *ids0, global const int *ids1,
                              global const int *ids2, global const int *ids3, global const int *ids4,
                              global const int *ids5, global const float *vertices, global const int *faces,
                              const float extent, const float2 bias, const float eps,
                              const uint seed, const int n, global float *visibility)
{
    const int gid = get_global_id(0);
    if (gid >= n)
        return;
    float px = points[3 * gid], py = points[3 * gid + 1], pz = points[3 * gid + 2];

    /* Unit direction towards the light */
#if PERSPECTIVE
    float lx = to_light.x - px, ly = to_light.y - py, lz = to_light.z - pz;
    const float dist = SC_SQRT(dot3(lx, ly, lz, lx, ly, lz));
    lx /= dist, ly /= dist, lz /= dist;
#else
    const float lx = to_light.x, ly = to_light.y, lz = to_light.z;
#endif

    /* Pick the view */
#if CUBE
    const float ax = SC_ABS(px - to_light.x), ay = SC_ABS(py - to_light.y), az = SC_ABS(pz - to_light.z);
    const int axis = ax >= ay && ax >= az ? 0 : (ay >= az ? 1 : 2);
    const float along = axis == 0 ? px - to_light.x : (axis == 1 ? py - to_light.y : pz - to_light.z);
    const int face = 2 * axis + (along < 0.0f);
    global const float *v = views + VIEW_FLOATS * face;
    global const float *map = face < 3 ? (face == 0 ? map0 : (face == 1 ? map1 : map2))
                                       : (face == 3 ? map3 : (face == 4 ? map4 : map5));
    global const int *ids = face < 3 ? (face == 0 ? ids0 : (face == 1 ? ids1 : ids2))
                                     : (face == 3 ? ids3 : (face == 4 ? ids4 : ids5));
#else
    global const float *v = views;
    global const float *map = map0;
    global const int *ids = ids0;
#endif

    /* Texel footprint T at the receiver: a texel's widest extent across the light's ray, the bias's
     * unit. Perspective: texel size (tangent units) times the distance along the view axis (w); off
     * the axis by alpha a texel is that wide across the ray sideways, cos(alpha) narrower radially. */
#if PERSPECTIVE
    const float axial = v[12] * px + v[13] * py + v[14] * pz + v[15];   /* distance along the view axis */
    const float texel = v[16] * axial;
    const float eps_axial = eps * axial / dist;   /* eps along the ray, as a distance along the axis */
#else
    const float texel = v[16];
    const float eps_axial = eps;
#endif

    /* Facing test and bias */
    float offset = bias.x * texel; /* distance the receiver may lie behind the stored surface */
#if NORMALS
    const float nx = normals[3 * gid], ny = normals[3 * gid + 1], nz = normals[3 * gid + 2];
    const float cosine = dot3(nx, ny, nz, lx, ly, lz);
    if (cosine <= 0.0f) {
        visibility[gid] = 0.0f;
        return;
    }
    const float sine = SC_SQRT(SC_MAX(1.0f - cosine * cosine, 0.0f));
    px += eps * nx, py += eps * ny, pz += eps * nz;   /* DESIGN.md's start s = p + eps n */
#if BIAS == 1
    offset += bias.y * texel * SC_MIN(sine / cosine, TAN_MAX);
#elif BIAS == 2
    /* Normal offset: lifting the point r T sin(theta) off its plane puts the plane r T tan(theta)
     * behind it along the ray, what a lookup r texels away sees, without growing at grazing angles. */
    const float lift = bias.y * texel * sine;
    px += lift * nx, py += lift * ny, pz += lift * nz;
#endif
#endif

    /* Transform into light space */
    const float cx = v[0] * px + v[1] * py + v[2] * pz + v[3];
    const float cy = v[4] * px + v[5] * py + v[6] * pz + v[7];
    const float cz = v[8] * px + v[9] * py + v[10] * pz + v[11];
    const float cw = v[12] * px + v[13] * py + v[14] * pz + v[15];
    float s = (cx / cw + 1.0f) * (0.5f * RES) - 0.5f; /* texel coordinates, centres at integers */
    float t = (1.0f - cy / cw) * (0.5f * RES) - 0.5f;
#if DITHER
    s += centred_noise(hash32(seed ^ hash32(2u * (uint)gid)));
    t += centred_noise(hash32(seed ^ hash32(2u * (uint)gid + 1u)));
#endif

    /* Compare */
#if BIAS == 3
    /* The ray from the start towards the light; surfaces within eps (DESIGN.md) and float32 rounding
     * of the start do not shadow it, nor planes within the bias (the surface's curvature over the
     * texel the filter reads). */
    const WtRay ray = wt_setup(px, py, pz, lx, ly, lz);
    const float rounding = PRECISION_ULPS * FLT_EPSILON * (extent + SC_MAX(SC_MAX(SC_ABS(px), SC_ABS(py)), SC_ABS(pz)));
#if PERSPECTIVE
    const float tmax = dist;
#else
    const float tmax = SC_BIG;
#endif
#if NORMALS
    /* Facing the light (the test above), the receiver is lit by any surface the light sees at or
     * behind it; without normals only its own surface, within the bias, says so (a back face near
     * a silhouette would otherwise take the floor seen beyond it for light). */
    const float behind = SC_BIG;
#else
    const float behind = offset + eps + rounding;
#endif
    visibility[gid] = plane_lit_fraction(ids, vertices, faces, &ray, s, t, eps + rounding, tmax,
                                         offset + eps + rounding, behind);
#else
    visibility[gid] = lit_fraction(map, v, s, t, distance_of(cz / cw, v) - offset - eps_axial);
#endif
}
