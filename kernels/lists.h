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

/* Exclusive prefix sum in two launches of work-groups of SC_SCAN_GROUP work-items, each work-item
 * owning per_item consecutive counts: a work-group adds up its items' sums in local memory, then every
 * work-group scans its items' sums in local memory after the sums of the groups before it. */
#define SC_SCAN_GROUP 128

/* Inclusive sum of x over the work-group's items up to this one, by Hillis-Steele steps in `buf`
 * (SC_SCAN_GROUP longs); on return buf holds every item's result (buf[SC_SCAN_GROUP - 1]: the group's
 * sum) until the group's next barrier. Every work-item of the group must call it. */
INLINE long sc_group_scan(long x, __local long *buf)
{
    const int l = get_local_id(0);
    buf[l] = x;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int d = 1; d < SC_SCAN_GROUP; d <<= 1) {
        const long before = l >= d ? buf[l - d] : 0;
        barrier(CLK_LOCAL_MEM_FENCE);
        x += before;
        buf[l] = x;
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    return x;
}

/* The sum of work-item i's counts [i * per_item, (i + 1) * per_item) within [0, n). */
INLINE long sc_item_sum(__global const int *counts, int n, int start, int per_item)
{
    const int end = min(n, start + per_item);
    long s = 0;
    for (int i = start; i < end; ++i)
        s += counts[i];
    return s;
}

/* sums[g] = the sum of work-group g's counts. */
__kernel __attribute__((reqd_work_group_size(SC_SCAN_GROUP, 1, 1)))
void scan_group_sums(__global const int *counts, int n, int per_item, __global long *sums)
{
    __local long buf[SC_SCAN_GROUP];
    const long s = sc_group_scan(sc_item_sum(counts, n, get_global_id(0) * per_item, per_item), buf);
    if (get_local_id(0) == SC_SCAN_GROUP - 1)
        sums[get_group_id(0)] = s;
}

/* offsets[i] = sum of counts[0..i); offsets[n] = total, and sums[ngroups] = total (long). Work-group g
 * first adds up the sums of the groups before it (at most a few hundred: host SCAN_GROUPS), strided
 * over its items. Valid when the total fits an int (host checks). */
__kernel __attribute__((reqd_work_group_size(SC_SCAN_GROUP, 1, 1)))
void scan_groups(__global const int *counts, int n, int per_item, __global long *sums, __global int *offsets,
                 int ngroups)
{
    __local long buf[SC_SCAN_GROUP];
    const int l = get_local_id(0), g = get_group_id(0);
    long part = 0;
    for (int k = l; k < g; k += SC_SCAN_GROUP)
        part += sums[k];
    sc_group_scan(part, buf);
    const long before = buf[SC_SCAN_GROUP - 1];
    barrier(CLK_LOCAL_MEM_FENCE);                  /* everyone has read it before buf is reused */
    const int start = get_global_id(0) * per_item;
    const long own = sc_item_sum(counts, n, start, per_item);
    const long through = before + sc_group_scan(own, buf);
    int run = (int)(through - own);
    const int end = min(n, start + per_item);
    for (int i = start; i < end; ++i) {
        offsets[i] = run;
        run += counts[i];
    }
    if (g == ngroups - 1 && l == SC_SCAN_GROUP - 1) {
        offsets[n] = (int)through;
        sums[ngroups] = through;
    }
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
