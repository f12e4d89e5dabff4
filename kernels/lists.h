/* lists.h: the device lists' shared mechanisms: the exclusive prefix sum of per-segment counts (host side
 * shadowcl.lists.prefix_sum; a program that includes this header has its kernels) and the one segmented
 * sort (voxel's cell lists, angular's rows and loops).
 *
 * One work-item sorts one segment in place, without scratch. SC_DEFINE_SEGMENT_SORT(name, SEGMENT,
 * CONTEXT, BEFORE, SWAP) defines
 *
 *     INLINE void name(SEGMENT segment, CONTEXT context, int n)
 *
 * sorting elements 0..n-1 of `segment` so that none is BEFORE one ahead of it. BEFORE(segment, context,
 * i, j) is true when element i goes strictly before element j; SWAP(segment, i, j) exchanges them
 * (either may be a macro: their arguments have no side effects).
 * Segments shorter than SC_SORT_SHORT get an insertion sort (the common short list: fewest compares and
 * moves); longer ones a heapsort (O(n log n) on the long rows of dense scenes). Elements that compare
 * equal come out in no promised order.
 */
#ifndef SHADOWCL_LISTS_H
#define SHADOWCL_LISTS_H

#include "vecmath.h"

/* Exclusive prefix sum in two launches of one kernel (one compile on PoCL, where a kernel's first launch
 * compiles it), each work-item g scanning block g of counts serially (no local memory, no barriers:
 * DESIGN.md item 13).
 *   phase 0: sums[g] = the block's total (long).
 *   phase 1: offsets[i] = sum of counts[0..i); offsets[n] = total, and sums[nblocks] = total (long).
 *            Work-item g adds up the block sums before its block itself (at most SCAN_BLOCKS of them:
 *            cheaper than a third launch). Valid when the total fits an int (host checks).
 * Element i is counts[i], or with second_row > 0 counts[i] + counts[second_row + i]: two rows of counts
 * added as they are scanned (the exact method's receivers, counted by two owners: kernels/exact.cl). */
__kernel void scan_blocks(__global const int *counts, int n, int block, __global long *sums,
                          __global int *offsets, int nblocks, int phase, int second_row)
{
#define SCAN_COUNT(i) (counts[i] + (second_row ? counts[second_row + (i)] : 0))
    const int g = get_global_id(0);
    const int start = g * block;
    if (start >= n)
        return;
    const int end = min(n, start + block);
    if (phase == 0) {
        long s = 0;
        for (int i = start; i < end; ++i)
            s += SCAN_COUNT(i);
        sums[g] = s;
        return;
    }
    long before = 0;
    for (int k = 0; k < g; ++k)
        before += sums[k];
    int run = (int)before;
    for (int i = start; i < end; ++i) {
        offsets[i] = run;
        run += SCAN_COUNT(i);
    }
    if (g == nblocks - 1) {
        const long total = before + sums[g];
        offsets[n] = (int)total;
        sums[nblocks] = total;
    }
#undef SCAN_COUNT
}

#define SC_SORT_SHORT 16

#define SC_DEFINE_SEGMENT_SORT(name, SEGMENT, CONTEXT, BEFORE, SWAP)                                 \
INLINE void name(SEGMENT segment, CONTEXT context, int n)                                            \
{                                                                                                    \
    if (n < SC_SORT_SHORT) {                                                                         \
        for (int i = 1; i < n; ++i)                                                                  \
            for (int j = i; j > 0 && BEFORE(segment, context, j, j - 1); --j)                        \
                SWAP(segment, j, j - 1);                                                             \
        return;                                                                                      \
    }                                                                                                \
    for (int start = n / 2 - 1, end = n; end > 1;) {                                                 \
        int root;                                                                                    \
        if (start >= 0) {                                                                            \
            root = start--;                                                                          \
        } else {                                                                                     \
            --end;                                                                                   \
            SWAP(segment, 0, end);                                                                   \
            root = 0;                                                                                \
        }                                                                                            \
        for (int child = 2 * root + 1; child < end; child = 2 * root + 1) {                          \
            if (child + 1 < end && BEFORE(segment, context, child, child + 1)) ++child;              \
            if (!BEFORE(segment, context, root, child)) break;                                       \
            SWAP(segment, root, child);                                                              \
            root = child;                                                                            \
        }                                                                                            \
    }                                                                                                \
}

#endif
