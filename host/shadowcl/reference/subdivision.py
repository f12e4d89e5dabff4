"""Reference Catmull-Clark limit surface (float64, plain Python/NumPy, independent of the patch table).

Written from the rules, not from host/shadowcl/subdivision.py:

- :func:`refine` is one Catmull-Clark step with "edge and corner" boundaries (boundary edge points are
  midpoints, boundary vertices (a + 6 v + b) / 8, single-face boundary vertices stay), done with dicts.
- :func:`vertex_limit` is the closed-form limit position of a vertex of an all-quad neighbourhood:
  interior (n^2 v + 4 sum(edge neighbours) + sum(diagonals)) / (n (n + 5)), boundary (a + 4 v + b) / 6,
  corner v.
- :meth:`RefinedSurface.limit_point` evaluates the limit surface exactly at dyadic parameters (u, v
  multiples of 2^-k): such a point is a vertex of the k-times refined mesh, so it is that vertex's limit
  position. :meth:`RefinedSurface.bspline_point` evaluates any (u, v) as the bicubic B-spline of the
  first refined quad around it whose corners are regular (exact there; None nearer an EV). The face
  parameter conventions are those documented in host/shadowcl/subdivision.py (quads: (0,0) at v0,
  (1,0) at v1, (1,1) at v2; n-gons: Ptex sub-faces with u in [0, n]).
"""

from __future__ import annotations

import numpy as np


class ControlMesh:
    """A polygon mesh as float64 points and lists of vertex indices, with edge -> faces lookups."""

    def __init__(self, points, faces):
        self.points = np.asarray(points, dtype=np.float64)
        self.faces = [list(map(int, f)) for f in faces]
        self.edge_faces: dict[tuple[int, int], list[int]] = {}
        self.vertex_faces: dict[int, list[int]] = {}
        for fi, face in enumerate(self.faces):
            for k, a in enumerate(face):
                b = face[(k + 1) % len(face)]
                self.edge_faces.setdefault((min(a, b), max(a, b)), []).append(fi)
                self.vertex_faces.setdefault(a, []).append(fi)

    def is_boundary_edge(self, a: int, b: int) -> bool:
        """Whether edge (a, b) has one face."""
        return len(self.edge_faces[(min(a, b), max(a, b))]) == 1

    def boundary_neighbours(self, v: int) -> list[int]:
        """The vertices joined to v by boundary edges (none for an interior vertex)."""
        out = []
        for f in self.vertex_faces[v]:
            face = self.faces[f]
            k = face.index(v)
            for w in (face[k - 1], face[(k + 1) % len(face)]):
                if self.is_boundary_edge(v, w) and w not in out:
                    out.append(w)
        return out


def refine(mesh: ControlMesh) -> tuple[ControlMesh, list[list[int]]]:
    """One Catmull-Clark step. Returns the refined mesh and, per old face, its child face ids: child j
    of face f is the quad (vertex point of v_j, edge point (v_j, v_j+1), face point, edge point (v_j-1, v_j))."""
    pts = mesh.points
    new_points: list[np.ndarray] = []
    vertex_index: dict[int, int] = {}
    face_point = [pts[face].mean(axis=0) for face in mesh.faces]
    for v in sorted(mesh.vertex_faces):
        faces = mesh.vertex_faces[v]
        neighbours = mesh.boundary_neighbours(v)
        if neighbours and len(faces) == 1:
            p = pts[v]
        elif neighbours:
            a, b = neighbours
            p = (pts[a] + 6.0 * pts[v] + pts[b]) / 8.0
        else:
            n = len(faces)
            ring = {w for f in faces for w in _adjacent(mesh.faces[f], v)}
            f_avg = np.mean([face_point[f] for f in faces], axis=0)
            r_avg = np.mean([(pts[v] + pts[w]) / 2.0 for w in ring], axis=0)
            p = (f_avg + 2.0 * r_avg + (n - 3.0) * pts[v]) / n
        vertex_index[v] = len(new_points)
        new_points.append(p)
    edge_index: dict[tuple[int, int], int] = {}
    for (a, b), faces in mesh.edge_faces.items():
        if len(faces) == 1:
            p = (pts[a] + pts[b]) / 2.0
        else:
            p = (pts[a] + pts[b] + face_point[faces[0]] + face_point[faces[1]]) / 4.0
        edge_index[(a, b)] = len(new_points)
        new_points.append(p)
    face_index = []
    for fp in face_point:
        face_index.append(len(new_points))
        new_points.append(fp)
    new_faces, children = [], []
    for fi, face in enumerate(mesh.faces):
        ids = []
        for j, v in enumerate(face):
            nxt, prv = face[(j + 1) % len(face)], face[j - 1]
            ids.append(len(new_faces))
            new_faces.append([vertex_index[v], edge_index[(min(v, nxt), max(v, nxt))], face_index[fi],
                              edge_index[(min(v, prv), max(v, prv))]])
        children.append(ids)
    return ControlMesh(np.array(new_points), new_faces), children


def _adjacent(face: list[int], v: int) -> tuple[int, int]:
    k = face.index(v)
    return face[k - 1], face[(k + 1) % len(face)]


def vertex_limit(mesh: ControlMesh, v: int) -> np.ndarray:
    """Closed-form limit position of vertex v (its faces must be quads)."""
    pts = mesh.points
    faces = mesh.vertex_faces[v]
    neighbours = mesh.boundary_neighbours(v)
    if neighbours and len(faces) == 1:
        return pts[v].copy()
    if neighbours:
        a, b = neighbours
        return (pts[a] + 4.0 * pts[v] + pts[b]) / 6.0
    n = len(faces)
    edge_sum = np.zeros(3)
    diagonal_sum = np.zeros(3)
    for f in faces:
        face = mesh.faces[f]
        assert len(face) == 4, "vertex_limit needs an all-quad neighbourhood"
        k = face.index(v)
        edge_sum += pts[face[(k + 1) % 4]]
        diagonal_sum += pts[face[(k + 2) % 4]]
    return (n * n * pts[v] + 4.0 * edge_sum + diagonal_sum) / (n * (n + 5.0))


class RefinedSurface:
    """A control mesh refined ``levels`` times globally, for exact limit points at dyadic parameters."""

    def __init__(self, vertices, faces, levels: int):
        self.meshes = [ControlMesh(vertices, faces)]
        self.children = []
        for _ in range(levels):
            mesh, children = refine(self.meshes[-1])
            self.meshes.append(mesh)
            self.children.append(children)
        self.levels = levels

    def limit_point(self, face: int, u: float, v: float) -> np.ndarray:
        """Exact limit position at (face, u, v); u and v must be multiples of 2^-levels (2^-(levels-1) on
        an n-gon, whose sub-faces are already once refined)."""
        scale = 2 ** (self.levels - (len(self.meshes[0].faces[face]) != 4))
        if abs(u * scale - round(u * scale)) > 1e-9 or abs(v * scale - round(v * scale)) > 1e-9:
            raise ValueError(f"u, v: ({u}, {v}) are not multiples of 1/{scale}")
        return vertex_limit(self.meshes[-1], self.vertex_at(face, u, v))

    def vertex_at(self, face: int, u: float, v: float) -> int:
        """The vertex of the finest mesh at dyadic (face, u, v)."""
        level, face, s, t = self._descend(face, u, v, lambda level, face, s, t: s in (0.0, 1.0) and t in (0.0, 1.0))
        corners = self.meshes[level].faces[face]
        return corners[{(0.0, 0.0): 0, (1.0, 0.0): 1, (1.0, 1.0): 2, (0.0, 1.0): 3}[(s, t)]]

    def bspline_point(self, face: int, u: float, v: float, min_level: int = 0):
        """Limit position at any (face, u, v) from the bicubic B-spline of the first quad containing it,
        at level >= ``min_level``, whose corners are all regular; None if none is (too near an EV)."""

        def regular_quad(level, face, s, t):
            mesh = self.meshes[level]
            return level >= min_level and all(_regular(mesh, c) for c in mesh.faces[face])

        try:
            level, face, s, t = self._descend(face, u, v, regular_quad)
        except IndexError:  # ran out of levels
            return None
        net = _bspline_net(self.meshes[level], self.meshes[level].faces[face])
        return _basis(t) @ np.einsum("i,jix->jx", _basis(s), net)

    def _descend(self, face: int, u: float, v: float, stop):
        """(level, face, s, t): descend through child quads from (face, u, v) until ``stop`` holds."""
        n = len(self.meshes[0].faces[face])
        level = 0
        if n != 4:
            # Ptex sub-face j is child j of the n-gon, in its own (u, v).
            j = min(int(np.floor(u)), n - 1)
            face, u, level = self.children[0][face][j], u - j, 1
        s, t = u, v
        while not stop(level, face, s, t):
            # Child j sits in quadrant j with its corner 0 at the quad's corner j, rotated by j.
            j = {(0, 0): 0, (1, 0): 1, (1, 1): 2, (0, 1): 3}[(int(s >= 0.5), int(t >= 0.5))]
            s2, t2 = 2.0 * s - (j in (1, 2)), 2.0 * t - (j in (2, 3))
            s, t = [(s2, t2), (t2, 1.0 - s2), (1.0 - s2, 1.0 - t2), (1.0 - t2, s2)][j]
            face = self.children[level][face][j]
            level += 1
        return level, face, s, t


def _regular(mesh: ControlMesh, v: int) -> bool:
    """Interior with 4 quads, boundary with 2 quads, or a corner (1 quad)."""
    faces = mesh.vertex_faces[v]
    if any(len(mesh.faces[f]) != 4 for f in faces):
        return False
    return len(faces) <= 2 if mesh.boundary_neighbours(v) else len(faces) == 4


def _basis(t: float) -> np.ndarray:
    return np.array([(1 - t) ** 3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1, t**3]) / 6.0


def _beyond(mesh: ControlMesh, c: int, p: int):
    """The neighbour of c across from neighbour p (sharing no face with c and p), or None."""
    faces = mesh.vertex_faces[c]
    ring = {w for f in faces for w in _adjacent(mesh.faces[f], c)}
    for w in ring - {p}:
        if not any(p in mesh.faces[f] and w in mesh.faces[f] for f in faces):
            return w
    return None


def _diagonal(mesh: ControlMesh, c: int, p: int, q: int):
    """The vertex opposite c in the face at c that holds neither p nor q, or None."""
    for f in mesh.vertex_faces[c]:
        face = mesh.faces[f]
        if p not in face and q not in face:
            return face[(face.index(c) + 2) % 4]
    return None


def _bspline_net(mesh: ControlMesh, quad: list[int]) -> np.ndarray:
    """(4, 4, 3) control net [j][i] of a quad with regular corners; phantoms reflect across boundaries."""
    pts = mesh.points
    grid: dict[tuple[int, int], np.ndarray] = {}
    inner = {(1, 1): quad[0], (2, 1): quad[1], (2, 2): quad[2], (1, 2): quad[3]}
    for (i, j), c in inner.items():
        grid[(i, j)] = pts[c]
    for (i, j), c in inner.items():
        di, dj = (-1 if i == 1 else 1), (-1 if j == 1 else 1)  # outwards from the quad
        p, q = inner[(i - di, j)], inner[(i, j - dj)]
        for key, vertex in (((i + di, j), _beyond(mesh, c, p)), ((i, j + dj), _beyond(mesh, c, q)),
                            ((i + di, j + dj), _diagonal(mesh, c, p, q))):
            if vertex is not None:
                grid[key] = pts[vertex]
    real = set(grid)
    for i in range(4):
        for j in range(4):
            if (i, j) in grid or (i in (0, 3) and j in (0, 3)):
                continue
            if i in (0, 3):  # reflect through the boundary column
                a, b = (1, 2) if i == 0 else (2, 1)
                grid[(i, j)] = 2 * grid[(a, j)] - grid[(b, j)]
            else:
                a, b = (1, 2) if j == 0 else (2, 1)
                grid[(i, j)] = 2 * grid[(i, a)] - grid[(i, b)]
    for i in (0, 3):
        for j in (0, 3):
            if (i, j) in grid:
                continue
            ia, ib = (1, 2) if i == 0 else (2, 1)
            ja, jb = (1, 2) if j == 0 else (2, 1)
            if (i, ja) in real:  # the boundary runs along j: reflect across it
                grid[(i, j)] = 2 * grid[(i, ja)] - grid[(i, jb)]
            else:
                grid[(i, j)] = 2 * grid[(ia, j)] - grid[(ib, j)]
    return np.array([[grid[(i, j)] for i in range(4)] for j in range(4)])


def tessellation_grid(faces, segments: int):
    """The tessellation grid by a per-sample loop over a dictionary of point names (the library's
    first version, kept as the reference of shadowcl.subdivision.tessellation): (face, u, v) of every
    vertex (shared points once, in order of first appearance), the (T, 3) triangles (two per cell) and
    (face, u, v) of every cell's centre."""
    keys: dict[tuple, int] = {}
    face_of, us, vs = [], [], []
    triangles, centres = [], []

    def edge_key(x, y, t):
        if t == 0:
            return ("v", x)
        if t == segments:
            return ("v", y)
        return ("e", x, y, t) if x < y else ("e", y, x, segments - t)

    for f, corners in enumerate(faces):
        corners = corners.tolist()
        n = len(corners)
        size = segments if n == 4 else segments // 2
        for j in range(1 if n == 4 else n):
            grid = np.empty((size + 1, size + 1), dtype=np.int64)
            for b in range(size + 1):
                for a in range(size + 1):
                    if n == 4:
                        key = _quad_key(f, corners, a, b, segments, edge_key)
                    else:
                        key = _ngon_key(f, corners, j, a, b, size, segments, edge_key)
                    index = keys.get(key)
                    if index is None:
                        index = keys[key] = len(face_of)
                        face_of.append(f)
                        if n != 4 and a == size:
                            # u = j + 1 would select sub-face j + 1: name the point from there.
                            u_, v_ = (n, 1.0) if b == size else ((j + 1) % n + b / size, 1.0)
                        else:
                            u_, v_ = j + a / size, b / size
                        us.append(u_)
                        vs.append(v_)
                    grid[b, a] = index
            p00, p10 = grid[:-1, :-1].ravel(), grid[:-1, 1:].ravel()
            p01, p11 = grid[1:, :-1].ravel(), grid[1:, 1:].ravel()
            pair = np.stack([np.stack([p00, p10, p11], 1), np.stack([p00, p11, p01], 1)], 1)
            triangles.append(pair.reshape(-1, 3))
            cu, cv = np.meshgrid((np.arange(size) + 0.5) / size, (np.arange(size) + 0.5) / size)
            centres.append(np.stack([np.full(cu.size, f), j + cu.ravel(), cv.ravel()]))
    centres = np.concatenate(centres, axis=1)
    return (np.array(face_of), np.array(us, dtype=np.float64), np.array(vs, dtype=np.float64),
            np.concatenate(triangles), (centres[0].astype(np.int64), centres[1], centres[2]))

def _quad_key(f, c, a, b, s, edge_key) -> tuple:
    if b == 0:
        return edge_key(c[0], c[1], a)
    if a == s:
        return edge_key(c[1], c[2], b)
    if b == s:
        return edge_key(c[2], c[3], s - a)
    if a == 0:
        return edge_key(c[3], c[0], s - b)
    return ("f", f, a, b)

def _ngon_key(f, c, j, a, b, h, s, edge_key) -> tuple:
    n = len(c)
    if b == 0:
        return edge_key(c[j], c[(j + 1) % n], a)
    if a == 0:
        return edge_key(c[j - 1], c[j], s - b)
    if a == h and b == h:
        return ("c", f)
    if a == h:
        return ("l", f, j, b)
    if b == h:
        return ("l", f, (j - 1) % n, a)
    return ("f", f, j, a, b)
