"""The tessellation grid of a control mesh: which (face, u, v) points a tessellation evaluates, each
shared point once, and the triangles over them, vectorised over all samples (it replaced a per-face x
(s + 1)^2 Python loop).

A quad is one segments x segments grid of samples; an n-gon has n sub-faces of (segments / 2)^2 cells.
Samples are visited faces in order, then sub-faces, rows, columns. A sample inside a (sub-)face is a
point of its own; one on a control vertex or edge is named by the vertex or by (edge, step along it
from its lesser vertex), one on an n-gon's spoke by (face, spoke, step), its centre by the face: equal
names are one point. Points are numbered in order of first appearance and take (face, u, v) from there.
"""

from __future__ import annotations

import numpy as np

VERTEX, EDGE, CENTRE, SPOKE = range(4)     # kinds of names of shared samples


def tessellation(faces: list, segments: int):
    """(face, u, v) of every tessellation vertex, the (T, 3) triangles (two per cell, cells in order)
    and (face, u, v) of every cell's centre, for control ``faces`` (a list of vertex-index arrays) and
    ``segments`` per control edge (even when a face is not a quad)."""
    s = int(segments)
    sizes = np.array([len(f) for f in faces], dtype=np.int64)
    flat = np.concatenate(faces).astype(np.int64)
    offsets = np.r_[0, np.cumsum(sizes)[:-1]]
    # Sub-face records (face, j): one per quad, n per n-gon, with rec_size^2 cells each
    nrec = np.where(sizes == 4, 1, sizes)
    rec_face = np.repeat(np.arange(len(faces)), nrec)
    rec_j = np.arange(len(rec_face)) - np.repeat(np.cumsum(nrec) - nrec, nrec)
    rec_size = np.where(sizes[rec_face] == 4, s, s // 2)
    count = (rec_size + 1) ** 2
    rec_start = np.r_[0, np.cumsum(count)[:-1]]
    total = int(count.sum())

    # Samples on a sub-face's rim may be shared; the others are points of their own
    rim = _rim_samples(rec_size, rec_start)
    r = np.repeat(np.arange(len(rec_face)), np.where(rec_size > 0, 4 * rec_size, 1))
    local = rim - rec_start[r]
    size, f, j, n = rec_size[r], rec_face[r], rec_j[r], sizes[rec_face[r]]
    b, a = local // (size + 1), local % (size + 1)
    names = _rim_names(flat, offsets, s, f, j, n, a, b, size)
    _, first, inverse = np.unique(names, axis=0, return_index=True, return_inverse=True)
    representative = np.arange(total)                      # each sample's first sample of the same point
    representative[rim] = rim[first][inverse.reshape(-1)]
    is_first = representative == np.arange(total)
    vertex = (np.cumsum(is_first) - 1)[representative]

    # (face, u, v) of each point, from its first sample
    src = np.flatnonzero(is_first)
    r = np.searchsorted(rec_start, src, side="right") - 1
    size, j, n = rec_size[r], rec_j[r], sizes[rec_face[r]]
    b, a = (src - rec_start[r]) // (size + 1), (src - rec_start[r]) % (size + 1)
    ngon_side = (n != 4) & (a == size)           # u = j + 1 would select sub-face j + 1: named from there
    with np.errstate(divide="ignore", invalid="ignore"):   # size 0 (segments 1) has no sub-face samples
        u = np.where(ngon_side, np.where(b == size, n, (j + 1) % n + b / size), j + a / size)
        v = np.where(ngon_side, 1.0, b / size)

    # Cells (record, row, column), two triangles each: (p00, p10, p11), (p00, p11, p01)
    cells = rec_size ** 2
    cr = np.repeat(np.arange(len(rec_face)), cells)
    cl = np.arange(int(cells.sum())) - np.repeat(np.cumsum(cells) - cells, cells)
    csize = rec_size[cr]
    cb, ca = cl // csize, cl % csize
    p00 = rec_start[cr] + cb * (csize + 1) + ca
    p00, p10, p01, p11 = (vertex[p] for p in (p00, p00 + 1, p00 + csize + 1, p00 + csize + 2))
    triangles = np.stack([np.stack([p00, p10, p11], 1), np.stack([p00, p11, p01], 1)], 1).reshape(-1, 3)
    centres = (rec_face[cr], rec_j[cr] + (ca + 0.5) / csize, (cb + 0.5) / csize)
    return rec_face[r], u.astype(np.float64), v.astype(np.float64), triangles, centres


def _rim_samples(rec_size: np.ndarray, rec_start: np.ndarray) -> np.ndarray:
    """Sorted sample ids of every record's rim (row or column 0 or size), 4 * size per record."""
    ids = []
    for size in np.unique(rec_size):             # one or two sizes: quads and n-gon sub-faces
        size = int(size)
        grid = np.arange((size + 1) ** 2).reshape(size + 1, size + 1)
        border = np.zeros_like(grid, dtype=bool)
        border[[0, -1]] = border[:, [0, -1]] = True
        ids.append(rec_start[rec_size == size, None] + np.flatnonzero(border)[None])
    ids = np.concatenate([i.reshape(-1) for i in ids])
    return np.sort(ids)


def _rim_names(flat, offsets, s, f, j, n, a, b, size) -> np.ndarray:
    """(N, 4) int64 names of rim samples: equal rows are one point (see the module doc)."""
    quad = n == 4
    # The control edge (x -> y, step t from x) a sample lies on; t = -1: not on one
    x, y, t = np.full((3, len(f)), -1, dtype=np.int64)
    rules = ((quad & (b == 0), 0, 1, a), (quad & (b != 0) & (a == s), 1, 2, b),
             (quad & (b != 0) & (a != s) & (b == s), 2, 3, s - a),
             (quad & (b != 0) & (a != s) & (b != s) & (a == 0), 3, 0, s - b),
             (~quad & (b == 0), j, j + 1, a), (~quad & (b != 0) & (a == 0), j - 1, j, s - b))
    for where, cx, cy, ct in rules:
        k = np.flatnonzero(where)
        x[k] = flat[offsets[f[k]] + np.broadcast_to(cx, f.shape)[k] % n[k]]
        y[k] = flat[offsets[f[k]] + np.broadcast_to(cy, f.shape)[k] % n[k]]
        t[k] = ct[k]
    names = np.zeros((len(f), 4), dtype=np.int64)
    at_x, at_y = (t == 0), (t == s)
    names[at_x, 0], names[at_x, 1] = VERTEX, x[at_x]
    names[at_y, 0], names[at_y, 1] = VERTEX, y[at_y]
    mid = (t > 0) & (t < s)
    forward = x[mid] < y[mid]
    names[mid] = np.stack([np.full(mid.sum(), EDGE), np.where(forward, x[mid], y[mid]),
                           np.where(forward, y[mid], x[mid]), np.where(forward, t[mid], s - t[mid])], axis=1)
    inner = ~quad & (t < 0)                           # an n-gon sub-face's spokes and centre
    centre = inner & (a == size) & (b == size)
    spoke_a, spoke_b = inner & ~centre & (a == size), inner & ~centre & (b == size)
    names[centre, 0], names[centre, 1] = CENTRE, f[centre]
    names[spoke_a] = np.stack([np.full(spoke_a.sum(), SPOKE), f[spoke_a], j[spoke_a], b[spoke_a]], axis=1)
    names[spoke_b] = np.stack([np.full(spoke_b.sum(), SPOKE), f[spoke_b], (j[spoke_b] - 1) % n[spoke_b],
                               a[spoke_b]], axis=1)
    return names
