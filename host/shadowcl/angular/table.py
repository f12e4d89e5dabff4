"""The lookup table of one light on the device (sections 3-5, 7.1; see the package docstring): face records
(``face_rows``, ``fill_rows``), the paper's loop pairs (``edge_rows``, ``fill_edges``, ``pair_rows``) in the
same rows, the records per row counted on the host, rows sorted by ``s_lo``; and the table read back."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..lists import check_filled
from .frame import Frame

REC_FLOATS = 8                 # kernels/angular.cl: REC


@dataclass
class Table:
    """One light's lookup table on the device: ``offsets`` (rows + 1) int32 CSR and ``records``
    (entries x 8) float32 (``s_lo, s_hi, nx, ny, nz, d, face, running max of s_hi``; face as int32 bits),
    rows sorted by ``s_lo``; ``relative`` (anchor-relative float32 vertices) and ``faces``: the triangles a
    lookup tests a face record's hit against."""

    frame: Frame
    offsets: object
    records: object
    entries: int
    table_faces: np.ndarray
    relative: object
    faces: object

    @property
    def nbytes(self) -> int:
        return 4 * (self.frame.rows + 1) + 4 * REC_FLOATS * self.entries + self.relative.size + self.faces.size


def build_table(device, local_vertices: np.ndarray, faces: np.ndarray, table_faces: np.ndarray, frame: Frame,
                stats: dict | None = None, loops=None) -> Table:
    """The lookup table of ``table_faces`` (indices into ``faces``) with ``local_vertices`` in ``frame``, plus,
    when ``loops`` (a list of ridge-edge loops) is given, the pairs of the paper's loop table
    (:func:`loop_pairs`) in the same rows."""
    stats = {} if stats is None else stats
    dev, queue = device, device.queue
    t0 = time.perf_counter()
    n = len(table_faces)
    rows = frame.rows
    options = frame_options(frame)
    vertices_g = dev.to_device(np.ascontiguousarray(local_vertices, dtype=np.float32))
    relative_g = dev.to_device(np.ascontiguousarray(local_vertices - frame.anchor, dtype=np.float32))
    anchor = tuple(np.float32(c) for c in frame.anchor)
    faces_g = dev.to_device(np.ascontiguousarray(faces, dtype=np.int32))
    ids_g = dev.to_device(np.ascontiguousarray(table_faces, dtype=np.int32))
    planes_g = dev.empty(16 * max(n, 1), "face planes")
    first_g = dev.empty(4 * max(n, 1), "face first rows")
    nrows_g = dev.empty(4 * max(n, 1), "face row counts")
    pads_g = dev.empty(4 * max(n, 1), "face row pads")
    pieces_g = dev.empty(4 * max(n, 1), "face span pieces")
    scalars = (np.int32(n), np.float32(frame.t0), np.float32(frame.dt), np.int32(rows))
    if n:
        dev.kernel("angular.cl", "face_rows", options)(queue, (n,), None, vertices_g, relative_g, faces_g, ids_g,
                                                       *scalars, *anchor, np.float32(frame.pad_t),
                                                       np.float32(frame.piece_width), planes_g, first_g, nrows_g, pads_g,
                                                       pieces_g)
    counts = row_counts(dev.from_device(first_g, n, np.int32), dev.from_device(nrows_g, n, np.int32), rows,
                        dev.from_device(pieces_g, n, np.int32))
    pairs = None if loops is None else loop_pairs(dev, vertices_g, loops, frame, stats)
    npairs = np.zeros(rows, dtype=np.int64) if pairs is None else pairs[2]
    counts = counts + npairs
    t1 = time.perf_counter()
    # Exclusive prefix sum of one count per row: a few kB, cheaper on the host than a device scan's launches.
    offsets = np.zeros(rows + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    entries = int(offsets[-1])
    nbytes = 4 * REC_FLOATS * entries
    check_capacity(dev, entries, rows, "table records")
    offsets_g = dev.to_device(offsets.astype(np.int32))
    records_g = dev.empty(max(nbytes, 4 * REC_FLOATS), "angular table records")
    t2 = time.perf_counter()
    if entries:
        if pairs is not None:      # the loop pairs first in each row, the face records after them
            dev.kernel("angular.cl", "copy_pairs", options)(queue, (rows,), None, pairs[1], pairs[3], offsets_g,
                                                            np.int32(rows), np.int32(pairs[4]), pairs[0], records_g)
        cursor_g = dev.to_device(npairs.astype(np.int32))
        if n:
            dev.kernel("angular.cl", "fill_rows", options)(queue, (n,), None, vertices_g, faces_g, ids_g, *scalars,
                                                           np.float32(frame.pad_s), planes_g, first_g, nrows_g, pads_g,
                                                           pieces_g, offsets_g, cursor_g, records_g)
        check_filled(dev, cursor_g, "angular fill_rows", offsets)
        t2 = time.perf_counter()
        dev.kernel("angular.cl", "sort_rows", options)(queue, (rows,), None, offsets_g, np.int32(rows), records_g)
    queue.finish()
    t3 = time.perf_counter()
    stats.update(count_s=t1 - t0, fill_s=t2 - t1, sort_s=t3 - t2,
                 entries=entries, rows=rows, max_row=int(counts.max(initial=0)), table_bytes=4 * (rows + 1) + nbytes)
    return Table(frame, offsets_g, records_g, entries, np.asarray(table_faces, dtype=np.int32), relative_g, faces_g)


def loop_pairs(device, vertices_g, loops, frame: Frame, stats: dict):
    """The paper's loop table on the device (sections 3-4, 7.1 steps 1.3-1.5): every ridge edge's crossings
    with the rows it spans (counted, prefix-summed, filled: ``edge_rows``, ``fill_edges``), then per row
    the crossings sorted by (loop, s) and paired loop by loop with section 4's rule (``pair_rows``, one
    work-item per row: the pairing is a sequential scan per loop, cheap next to the fill). Returns
    (pairs buffer, its row offsets buffer, (rows,) pairs per row, that count's buffer); a pair record
    holds its span and the plane of its chord (depth interpolated between the pair's ends)."""
    dev, queue, rows = device, device.queue, frame.rows
    options = frame_options(frame)
    chains = [np.asarray(loop.vertices, dtype=np.int32) for loop in loops.loops]
    ridge = np.concatenate(chains) if chains else np.zeros(0, dtype=np.int32)
    length = np.array([len(c) for c in chains], dtype=np.int64)
    after = np.arange(1, len(ridge) + 1)
    after[np.cumsum(length) - 1] = np.cumsum(length) - length         # each chain's last edge closes it
    tails = np.concatenate([ridge, loops.creases[:, 0].astype(np.int32)])
    heads = np.concatenate([ridge[after] if len(ridge) else ridge, loops.creases[:, 1].astype(np.int32)])
    group = np.concatenate([loops.regions, loops.crease_regions]).astype(np.int32)
    ne, nridge = len(tails), len(tails) - len(loops.creases)
    tails_g, heads_g = dev.to_device(tails), dev.to_device(heads)
    first_g, count_g = dev.empty(4 * max(ne, 1), "edge first rows"), dev.empty(4 * max(ne, 1), "edge row counts")
    scalars = (np.int32(ne), np.float32(frame.t0), np.float32(frame.dt), np.int32(rows))
    if ne:
        dev.kernel("angular.cl", "edge_rows", options)(queue, (ne,), None, vertices_g, tails_g, heads_g, *scalars,
                                                       first_g, count_g)
    npoles = len(loops.poles)            # pole crossings: one per pierced lit face, in every row
    counts = row_counts(dev.from_device(first_g, ne, np.int32), dev.from_device(count_g, ne, np.int32), rows) + npoles
    offsets = np.zeros(rows + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    crossings = int(offsets[-1])
    check_capacity(dev, crossings, rows, "ridge-edge and crease crossings")
    offsets_g = dev.to_device(offsets.astype(np.int32))
    cross_g = dev.empty(4 * REC_FLOATS * max(crossings, 1), "ridge-edge crossings")
    queue_g = dev.empty(4 * max(crossings, 1), "pairing queue")
    npairs_g = dev.to_device(np.zeros(rows, dtype=np.int32))
    cap = 1                  # a row has fewer pairs than crossings unless a duplicate falls in several pairs (coils)
    if crossings:
        cursor_g = dev.to_device(np.full(rows, npoles, dtype=np.int32))
        if npoles:
            dev.kernel("angular.cl", "fill_poles", options)(
                queue, (rows,), None, dev.to_device(loops.poles.astype(np.float32)),
                dev.to_device(loops.pole_regions.astype(np.int32)), np.int32(npoles), np.int32(rows), offsets_g, cross_g)
        if ne:
            dev.kernel("angular.cl", "fill_edges", options)(
                queue, (ne,), None, vertices_g, tails_g, heads_g, dev.to_device(group), np.int32(ne), np.int32(nridge),
                *scalars[1:], first_g, count_g, offsets_g, cursor_g, cross_g)
        check_filled(dev, cursor_g, "angular fill_edges", offsets)
    queue.finish()
    t_pair = time.perf_counter()
    while True:
        check_capacity(dev, cap * crossings, rows, "loop pairs")
        pairs_g = dev.empty(4 * REC_FLOATS * max(cap * crossings, 1), "loop pairs")
        overflow_g = dev.to_device(np.zeros(1, dtype=np.int32))
        if crossings:
            dev.kernel("angular.cl", "pair_rows", options)(
                queue, (rows,), None, offsets_g, np.int32(rows), np.float32(frame.t0), np.float32(frame.dt),
                vertices_g, tails_g, heads_g, np.int32(cap), *(np.float32(c) for c in frame.anchor), cross_g, queue_g,
                pairs_g, npairs_g, overflow_g)
        if dev.from_device(overflow_g, 1, np.int32)[0] == 0:
            break
        cap *= 2
    npairs = dev.from_device(npairs_g, rows, np.int32).astype(np.int64)
    stats["pair_s"] = time.perf_counter() - t_pair          # the sort and section-4 pairing on the device
    stats.update(loops=len(chains), regions=len(np.unique(group)), ridge_edges=nridge, creases=ne - nridge, poles=npoles,
                 crossings=crossings, pairs=int(npairs.sum()), pair_capacity=cap)
    return pairs_g, offsets_g, npairs, npairs_g, cap


def check_capacity(device, entries: int, rows: int, what: str) -> None:
    """Raise ``ValueError`` (naming theta_resolution) when ``entries`` records do not fit one device buffer."""
    nbytes = 4 * REC_FLOATS * entries
    if entries >= 2**31 or nbytes > device.max_alloc_bytes:
        raise ValueError(f"theta_resolution: {rows} rows give {entries} {what} ({nbytes >> 20} MiB), more than "
                         f"the device holds in one buffer ({device.max_alloc_bytes >> 20} MiB); use fewer rows")


def row_counts(first: np.ndarray, count: np.ndarray, rows: int, per_row=None) -> np.ndarray:
    """(rows,) records per row from each item's first row (unwrapped), row count and records in each of its
    rows (``per_row``, default 1), by a difference array: per-row atomic counters on the device serialised
    on ~600 addresses (0.45 s for 600 k faces)."""
    w = np.ones(len(first), dtype=np.int64) if per_row is None else np.asarray(per_row, dtype=np.int64)
    start = np.mod(first.astype(np.int64), rows)
    end = start + count
    inside = end <= rows                                      # intervals that do not wrap round
    diff = np.bincount(start, w, minlength=rows + 1)[:rows + 1].astype(np.int64)
    diff -= np.bincount(np.where(inside, end, rows), w, minlength=rows + 1)[:rows + 1].astype(np.int64)
    wrapped = ~inside
    diff[0] += w[wrapped].sum()
    diff -= np.bincount(end[wrapped] - rows, w[wrapped], minlength=rows + 1)[:rows + 1].astype(np.int64)
    return np.cumsum(diff[:rows]).astype(np.int64)


def frame_options(frame: Frame, normals: bool = False) -> tuple[str, ...]:
    return (f"-DLIGHT_POINT={int(frame.point)}", f"-DFULL_CIRCLE={int(frame.full_circle)}", f"-DNORMALS={int(normals)}")


def table_entries(device, table: Table) -> dict:
    """The table read back: ``offsets``, ``row`` (E,), ``face`` (a face record's face, -(region + 1) for a
    loop pair), ``region`` (a loop pair's lit region, -1 for face records), ``s_lo``, ``s_hi``, ``plane``
    (E, 4), rows in order, each sorted by s_lo."""
    rows = table.frame.rows
    offsets = device.from_device(table.offsets, rows + 1, np.int32)
    rec = device.from_device(table.records, (max(table.entries, 1), REC_FLOATS), np.float32)[:table.entries]
    ident = rec[:, 6].view(np.int32)
    plane = rec[:, 2:6].astype(np.float64)
    plane[:, 3] += plane[:, :3] @ table.frame.anchor          # the kernels' offsets are relative to the anchor
    return dict(offsets=offsets, row=np.repeat(np.arange(rows), np.diff(offsets)), face=ident,
                region=np.where(ident < 0, -ident - 1, -1), s_lo=rec[:, 0], s_hi=rec[:, 1], plane=plane)
