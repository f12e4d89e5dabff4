"""Device lists' shared host mechanisms (kernels/lists.h has the device side).

:func:`prefix_sum` turns per-segment counts into CSR offsets on the device; any program that includes
``lists.h`` carries its kernel, so the caller passes its own kernel lookup (no extra program build).
The segmented sort is ``lists.h``'s ``SC_DEFINE_SEGMENT_SORT``, called from the owning kernels.
:func:`check_filled` is the host's side of DESIGN.md's capacity rule for fills that write into slots a
count pass made: one check, one message, for every such fill.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import pyopencl as cl

SCAN_BLOCKS = 512           # work-items of the prefix sum


def prefix_sum(device, kernel: Callable[[str], cl.Kernel], counts: cl.Buffer, n: int, offsets: cl.Buffer,
               second_row: int = 0) -> int:
    """offsets = exclusive prefix sum of the ``n`` int ``counts`` (n + 1 entries); returns the total.

    With ``second_row`` > 0, ``counts`` holds two rows and element i is counts[i] + counts[second_row + i]
    (added as they are scanned, in place of a kernel adding them: kernels/lists.h).

    ``kernel(name)`` gives the kernel ``name`` of a program that includes ``lists.h``. Two launches of
    one kernel (one compile) on SCAN_BLOCKS work-items, each scanning a block serially (no local memory
    or barriers: DESIGN.md item 13; a work-group scan in local memory was measured 1.1-9x slower on PoCL,
    bench/lists.py); the total is summed in 64 bits, the offsets are valid when it fits an int (the
    caller checks).
    """
    queue = device.queue
    if n == 0:                          # no block to scan
        cl.enqueue_fill_buffer(queue, offsets, np.int32(0), 0, 4)
        return 0
    block = max(1024, -(-n // SCAN_BLOCKS))
    nblocks = -(-n // block)
    sums = device.scratch("lists: scan block sums", 8 * (nblocks + 1))
    scan = kernel("scan_blocks")
    for phase in (0, 1):          # the blocks' sums, then the offsets
        scan(queue, (nblocks,), None, counts, np.int32(n), np.int32(block), sums, offsets, np.int32(nblocks),
             np.int32(phase), np.int32(second_row))
    total = np.empty(1, np.int64)
    cl.enqueue_copy(queue, total, sums, src_offset=8 * nblocks)
    return int(total[0])


def check_filled(device, counter: cl.Buffer, what: str, offsets: np.ndarray | None = None) -> None:
    """Raise ``RuntimeError`` when the fill ``what`` met more entries than its count made room for.

    Such fills compute the same places as their count, so an overflow is a bug, not a size to grow and
    rerun; the kernels write nothing past a segment's slots and count what they did not write, in one of
    two ways: ``counter`` holds one int, the entries dropped (``offsets`` None); or it holds each
    segment's cursor (slots taken, the dropped ones included) and ``offsets`` ((segments + 1,) ints on
    the host) are the segments' slots.
    """
    first = ""
    if offsets is None:
        excess = int(device.from_device(counter, 1, np.int32)[0])
    else:
        slots = np.diff(np.asarray(offsets, dtype=np.int64))
        taken = device.from_device(counter, len(slots), np.int32).astype(np.int64)
        over = np.flatnonzero(taken > slots)
        excess = int(np.sum(taken[over] - slots[over]))
        if len(over):
            k = int(over[0])
            first = f" (first in segment {k}: {taken[k]} entries for {slots[k]} slots)"
    if excess:
        raise RuntimeError(f"{what} met {excess} entries more than its count made room for{first}; they were "
                           "not written (nothing out of bounds), but the lists would be incomplete: a bug")
