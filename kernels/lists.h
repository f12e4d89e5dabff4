/* lists.h: the one segmented sort of the device lists (voxel's cell lists, angular's rows and loops).
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
