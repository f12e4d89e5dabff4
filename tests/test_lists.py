"""kernels/lists.h: the segmented sort shared by voxel's cell lists and angular's rows, against NumPy.

Driven through the two kernels that use it (voxel.cl sort_lists: int items by a key table; angular.cl
sort_rows: 8-float records by s_lo, then the running maximum of s_hi) on random segments whose lengths
straddle the insertion/heapsort switch (SC_SORT_SHORT = 16) and on the hard cases: empty and single
segments, ties, all-equal keys, sorted and reversed input. Also lists.check_filled, the fills' one
overflow check. (The prefix sum is tested with the light-space lists that use it: test_lightspace.)
"""

import numpy as np
import pyopencl as cl
import pytest

from shadowcl.lists import check_filled

SHORT = 16   # SC_SORT_SHORT in kernels/lists.h


def segments(rng, keys_for):
    """Lengths and per-segment keys: random, then the hard cases."""
    lengths, keys = [], []
    for n in list(rng.integers(0, 3 * SHORT, 300)) + [0, 1, 2, SHORT - 1, SHORT, SHORT + 1, 500]:
        lengths.append(n)
        keys.append(keys_for(n))
    for n in (SHORT - 1, SHORT, 200):
        for special in (np.zeros(n), np.arange(n, dtype=float), np.arange(n, 0, -1, dtype=float)):
            lengths.append(n)
            keys.append(special)
    offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32)
    return offsets, np.concatenate(keys).astype(np.float32)


def test_voxel_sort_lists_orders_each_cell_by_key(device, rng):
    offsets, keys = segments(rng, lambda n: rng.integers(0, 5, n))      # few distinct keys: many ties
    items = rng.permutation(len(keys)).astype(np.int32)
    keys_by_item = np.empty_like(keys)
    keys_by_item[items] = keys                  # the item at position p has key keys[p]
    items_g = cl.Buffer(device.context, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=items)
    cells = len(offsets) - 1
    device.kernel("voxel.cl", "sort_lists", ("-DLIGHT_POINT=1", "-DNVIEWS=1", "-DPERSPECTIVE=1"))(
        device.queue, (cells,), None, device.to_device(offsets), items_g, np.int32(cells),
        device.to_device(keys_by_item))
    out = np.empty_like(items)
    cl.enqueue_copy(device.queue, out, items_g)
    for a, b in zip(offsets[:-1], offsets[1:]):
        np.testing.assert_array_equal(keys_by_item[out[a:b]], np.sort(keys[a:b]))   # sorted by key
        np.testing.assert_array_equal(np.sort(out[a:b]), np.sort(items[a:b]))      # same items


def test_angular_sort_rows_orders_each_row_by_s_lo(device, rng):
    offsets, s_lo = segments(rng, lambda n: np.round(rng.uniform(-1, 1, n), 1))
    records = rng.uniform(-1, 1, (len(s_lo), 8)).astype(np.float32)
    records[:, 0] = s_lo
    records[:, 6] = np.arange(len(s_lo), dtype=np.int32).view(np.float32)    # the face index (int bits): identifies a record
    records_g = cl.Buffer(device.context, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=records)
    rows = len(offsets) - 1
    device.kernel("angular.cl", "sort_rows", ())(device.queue, (rows,), None, device.to_device(offsets),
                                                  np.int32(rows), records_g)
    out = np.empty_like(records)
    cl.enqueue_copy(device.queue, out, records_g)
    for a, b in zip(offsets[:-1], offsets[1:]):
        row, before = out[a:b], records[a:b]
        np.testing.assert_array_equal(row[:, 0], np.sort(before[:, 0]))
        faces = row[:, 6].view(np.int32)
        np.testing.assert_array_equal(np.sort(faces), np.arange(a, b))
        np.testing.assert_array_equal(row[:, :7], records[faces, :7])             # records moved whole
        np.testing.assert_array_equal(row[:, 7], np.maximum.accumulate(np.maximum(row[:, 1], -2.0)))


def test_check_filled_raises_on_a_dropped_count(device):
    """lists.check_filled, the one overflow check of fills (lightspace's CSR fill and exact's binning
    drive it through their kernels with tiny capacities in test_lightspace / test_exact): a counter of
    dropped entries, zero passes, any other count raises with the count and the fill's name."""
    check_filled(device, device.to_device(np.zeros(1, np.int32)), "a fill")
    with pytest.raises(RuntimeError, match=r"^a fill met 3 entries more than its count made room for; "):
        check_filled(device, device.to_device(np.array([3], np.int32)), "a fill")


@pytest.mark.parametrize("n", [0, 1, 17])
def test_check_filled_compares_cursors_with_their_segments(device, n):
    """The cursor form: per-segment cursors within their slots pass (full, short or empty segments); one
    past raises naming the first such segment, its cursor and its slots, and the total excess."""
    rng = np.random.default_rng(n)
    offsets = np.concatenate([[0], np.cumsum(rng.integers(0, 4, n))])
    slots = np.diff(offsets).astype(np.int32)
    check_filled(device, device.to_device(np.maximum(slots - 1, 0)), "rows", offsets)
    check_filled(device, device.to_device(slots), "rows", offsets)
    if n == 0:
        return
    taken = slots.copy()
    taken[n // 2] += 2
    taken[-1] += 1
    first = n // 2                       # n = 1: both additions fall on segment 0
    with pytest.raises(RuntimeError, match=rf"^rows met 3 entries more than its count made room for \(first in "
                                          rf"segment {first}: {taken[first]} entries for {slots[first]} slots\)"):
        check_filled(device, device.to_device(taken), "rows", offsets)
