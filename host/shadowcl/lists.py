"""Device lists' shared host mechanisms (kernels/lists.h has the device side).

:func:`prefix_sum` turns per-segment counts into CSR offsets on the device; any program that includes
``lists.h`` carries its kernel, so the caller passes its own kernel lookup (no extra program build).
The segmented sort is ``lists.h``'s ``SC_DEFINE_SEGMENT_SORT``, called from the owning kernels.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import pyopencl as cl

SCAN_BLOCKS = 512           # work-items of the prefix sum


def prefix_sum(device, kernel: Callable[[str], cl.Kernel], counts: cl.Buffer, n: int, offsets: cl.Buffer) -> int:
    """offsets = exclusive prefix sum of the ``n`` int ``counts`` (n + 1 entries); returns the total.

    ``kernel(name)`` gives the kernel ``name`` of a program that includes ``lists.h``. Two launches of
    one kernel (one compile) on SCAN_BLOCKS work-items, each scanning a block serially (no local memory
    or barriers: DESIGN.md item 13); the total is summed in 64 bits, the offsets are valid when it fits
    an int (the caller checks).
    """
    queue = device.queue
    block = max(1024, -(-n // SCAN_BLOCKS))
    nblocks = -(-n // block)
    sums = device.scratch("lists: scan block sums", 8 * (nblocks + 1))
    scan = kernel("scan_blocks")
    for phase in (0, 1):          # the blocks' sums, then the offsets
        scan(queue, (nblocks,), None, counts, np.int32(n), np.int32(block), sums, offsets, np.int32(nblocks),
             np.int32(phase))
    total = np.empty(1, np.int64)
    cl.enqueue_copy(queue, total, sums, src_offset=8 * nblocks)
    return int(total[0])
