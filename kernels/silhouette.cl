/* silhouette.cl: brute-force silhouette (ridge) edges against a point or directional light.
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
