/* silhouette.cl: brute-force silhouette (ridge) edges against a point or directional light, and the
 * walks that track them from frame to frame (at the end of the file).
 * Host: the package host/shadowcl/silhouette/ (classify, loops, tracking); NumPy reference:
 * host/shadowcl/reference/silhouette.py; tests: tests/test_silhouette.py.
 *
 * Two passes, one work-item per face then one per edge: each face's facing is computed once (an
 * edge-only kernel would recompute every face for each of its three edges), and the facing array is
 * what a shadow volume's caps need next.
 *
 * Facing: n = (v1 - v0) x (v2 - v0) by the right-hand rule (unnormalised), s = n . (L - v0) for a point
 * light at L, s = -(n . d) for a directional light travelling along d. A face is light-facing when
 * s > 0 strictly: a face whose plane contains the light, and a zero-area face (n = 0), faces no light.
 * vecmath.h turns contraction off, so a face with a repeated corner gets n = 0 exactly, as in float64.
 *
 * Build options:
 *   LIGHT_POINT   1: point light at (lx, ly, lz); 0: directional light travelling along (lx, ly, lz)
 */
#include "vecmath.h"

#ifndef LIGHT_POINT
#define LIGHT_POINT 1
#endif

/* Edge codes (host: shadowcl.silhouette): 0 no silhouette; +1 / -1 silhouette whose light-facing face
 * runs along / against the edge (first vertex to second / second to first); SIL_NONMANIFOLD. */
#define SIL_NONE 0
#define SIL_NONMANIFOLD 2    /* three or more faces: not classified, the host reports it */

#define NO_FACE -1
#define MANY_FACES -2

INLINE bool light_facing(const __global float *vertices, const __global int *faces, int f,
                         float lx, float ly, float lz)
{
    float x0, y0, z0, x1, y1, z1, x2, y2, z2;
    LOAD3(vertices, faces[3 * f], x0, y0, z0);
    LOAD3(vertices, faces[3 * f + 1], x1, y1, z1);
    LOAD3(vertices, faces[3 * f + 2], x2, y2, z2);
    const float ax = x1 - x0, ay = y1 - y0, az = z1 - z0;
    const float bx = x2 - x0, by = y2 - y0, bz = z2 - z0;
    const float nx = ay * bz - az * by, ny = az * bx - ax * bz, nz = ax * by - ay * bx;
#if LIGHT_POINT
    return dot3(nx, ny, nz, lx - x0, ly - y0, lz - z0) > 0.0f;
#else
    return -dot3(nx, ny, nz, lx, ly, lz) > 0.0f;
#endif
}

/* face_facing: facing[f] = 1 when face f is light-facing (see the file comment), else 0.
 * vertices: (V, 3) float; faces: (F, 3) int, every index < V; nfaces = F. */
__kernel void face_facing(const __global float *vertices, const __global int *faces, const int nfaces,
                          const float lx, const float ly, const float lz, __global uchar *facing)
{
    const int f = get_global_id(0);
    if (f >= nfaces)
        return;
    facing[f] = light_facing(vertices, faces, f, lx, ly, lz) ? 1 : 0;
}

/* classify_edges: the silhouette code of every edge from its faces' facing.
 * edge_faces: (E, 2) int, the edge's faces; the second is NO_FACE for a border edge (one face) and
 * MANY_FACES for an edge with three or more faces. edge_sense: (E, 2) char, +1 when that face runs along
 * the edge from its first vertex to its second, -1 against. facing: from face_facing.
 * code[e]: an edge with exactly one light-facing face is a silhouette, and a border edge is one when
 * its face is light-facing (so the volume of an open mesh closes); the sign is that face's sense.
 */
__kernel void classify_edges(const __global int *edge_faces, const __global char *edge_sense,
                             const int nedges, const __global uchar *facing, __global char *code)
{
    const int e = get_global_id(0);
    if (e >= nedges)
        return;
    const int f0 = edge_faces[2 * e], f1 = edge_faces[2 * e + 1];
    if (f1 == MANY_FACES) {
        code[e] = SIL_NONMANIFOLD;
        return;
    }
    const bool lit0 = facing[f0] != 0;
    const bool lit1 = f1 != NO_FACE && facing[f1] != 0;
    /* Exactly one light-facing face; a border edge's missing face counts as not light-facing. */
    code[e] = lit0 == lit1 ? SIL_NONE : (lit0 ? edge_sense[2 * e] : edge_sense[2 * e + 1]);
}

/* ---- Tracking (Fawad, Wang & Wu, sections III.B-C) ------------------------------------------------
 * Half-edge tables (host: shadowcl.silhouette.HalfEdges): half-edge h = 3 f + k is face f's edge k,
 * from faces[h] to faces[3 f + (k + 1) % 3]; twin[h] is the other face's half-edge on that edge (-1 on
 * a border: the missing face faces no light); edge_of[h] its edge. claim[e] == stamp marks an edge
 * found this frame (stamp grows by one a frame, so claim is never cleared). The walks recompute a
 * face's facing at each visit rather than caching it: a few dozen flops against a global write.
 * Seeds are appended to seeds[] through counters[TRACK_SEEDS]: one slot per candidate at most.
 *
 * Build options (besides LIGHT_POINT):
 *   MAX_WALK   steps of a III.B walk before it counts as lost
 */
#ifndef MAX_WALK
#define MAX_WALK 16
#endif

#define TRACK_FOUND 0        /* counters[]: half-edges appended to found[] */
#define TRACK_STALE 1        /* last frame's edges that are no longer silhouettes */
#define TRACK_LOST 2         /* III.B walks out of steps or walled in */
#define TRACK_UNCLOSED 3     /* III.C walks out of steps (an inconsistent table) */
#define TRACK_SEEDS 4        /* seeds appended */

/* Whether the face of half-edge h faces the light; h = -1 (no face) does not. */
INLINE bool lit_half(const __global float *vertices, const __global int *faces, int h, float lx, float ly, float lz)
{
    return h >= 0 && light_facing(vertices, faces, h / 3, lx, ly, lz);
}

INLINE void append(__global int *list, __global int *count, int item)
{
    list[atomic_inc(count)] = item;
}

/* seed_edges: one work-item per listed half-edge (an edge tested every frame: borders, concave
 * edges); when its edge is a silhouette, append the light-facing half-edge to seeds[]. */
__kernel void seed_edges(const __global float *vertices, const __global int *faces, const __global int *twin,
                         const __global int *listed, const int nlisted, const float lx, const float ly,
                         const float lz, __global int *seeds, __global int *counters)
{
    const int i = get_global_id(0);
    if (i >= nlisted)
        return;
    const int h = listed[i], t = twin[h];
    const bool here = lit_half(vertices, faces, h, lx, ly, lz);
    if (here != lit_half(vertices, faces, t, lx, ly, lz))
        append(seeds, &counters[TRACK_SEEDS], here ? h : t);
}

/* track_previous: one work-item per edge of last frame's silhouette, given as its light-facing
 * half-edge previous[i]. Still a silhouette (either way round): a seed. Otherwise a III.B walk from
 * the face that turned, away from the other: across light-facing faces until a left or right
 * neighbour faces away (both faces now light-facing), or across faces facing away until one faces
 * the light (both facing away); left and right in turn, a missing neighbour a wall; the edge found is
 * a seed. Counts stale edges and lost walks. */
__kernel void track_previous(const __global float *vertices, const __global int *faces, const __global int *twin,
                             const __global int *previous, const int nprevious, const float lx, const float ly,
                             const float lz, __global int *seeds, __global int *counters)
{
    const int i = get_global_id(0);
    if (i >= nprevious)
        return;
    const int h = previous[i], t = twin[h];
    const bool here = lit_half(vertices, faces, h, lx, ly, lz);
    const bool there = lit_half(vertices, faces, t, lx, ly, lz);
    if (here != there) {
        append(seeds, &counters[TRACK_SEEDS], here ? h : t);
        return;
    }
    atomic_inc(&counters[TRACK_STALE]);
    const bool want = here;                      /* walk across faces with this facing */
    int at = here ? t : h;                       /* the half-edge the walk entered the current face by */
    bool left_first = true;
    for (int step = 0; step < MAX_WALK; ++step) {
        const int f = at / 3, k = at % 3;
        const int hl = 3 * f + (k + 1) % 3, hr = 3 * f + (k + 2) % 3;
        const int tl = twin[hl], tr = twin[hr];
        const bool lit_l = lit_half(vertices, faces, tl, lx, ly, lz);
        const bool lit_r = lit_half(vertices, faces, tr, lx, ly, lz);
        if (want ? !lit_l : lit_l) {
            append(seeds, &counters[TRACK_SEEDS], want ? hl : tl);
            return;
        }
        if (want ? !lit_r : lit_r) {
            append(seeds, &counters[TRACK_SEEDS], want ? hr : tr);
            return;
        }
        if (tl < 0 && tr < 0)
            break;                                                      /* walled in */
        at = (left_first ? tl >= 0 : tr < 0) ? tl : tr;
        left_first = !left_first;
    }
    atomic_inc(&counters[TRACK_LOST]);
}

/* complete_loops: one work-item per seed (nseeds of them). Section III.C: claim the seed's edge (if
 * another work-item holds it, stop: that one walks on from it), append it to found[], then turn around
 * the seed's tail through light-facing faces; the first edge whose other face faces away (or is
 * missing) is the next silhouette edge of the loop: claim it, append its light-facing half-edge and
 * turn around its other vertex; stop at an edge already claimed. Whoever claims an edge walks on from
 * it, so every loop holding a seed is covered, each edge appended once: found[] needs one slot per
 * edge (capacity, checked: counters[TRACK_FOUND] counts the appends). */
__kernel void complete_loops(const __global float *vertices, const __global int *faces, const __global int *twin,
                             const __global int *edge_of, const __global int *seeds, const int nseeds,
                             const float lx, const float ly, const float lz, const int stamp, __global int *claim,
                             __global int *found, const int capacity, const int max_steps, __global int *counters)
{
    const int i = get_global_id(0);
    if (i >= nseeds)
        return;
    int side = seeds[i], pivot = faces[side], steps = 0;
    for (bool first = true; steps < max_steps; first = false) {
        if (atomic_xchg(&claim[edge_of[side]], stamp) == stamp)
            return;                                                       /* met a claimed edge */
        const int slot = atomic_inc(&counters[TRACK_FOUND]);
        if (slot < capacity)
            found[slot] = side;
        if (!first) {                                                     /* turn around its other end */
            const int tail = faces[side], head = faces[3 * (side / 3) + ((side % 3) + 1) % 3];
            pivot = tail == pivot ? head : tail;
        }
        /* Turn around the pivot through light-facing faces to the next silhouette edge. */
        for (int h = side;; h = twin[side]) {
            const int k = h % 3;
            side = 3 * (h / 3) + (faces[h] == pivot ? (k + 2) % 3 : (k + 1) % 3);
            if (++steps >= max_steps || !lit_half(vertices, faces, twin[side], lx, ly, lz))
                break;
        }
    }
    atomic_inc(&counters[TRACK_UNCLOSED]);
}
