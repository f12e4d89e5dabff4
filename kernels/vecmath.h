/* vecmath.h: scalar vector helpers that PoCL inlines and vectorises across work-items.
 *
 * DESIGN.md item 14: on PoCL, vload3/cross/dot calls in a hot loop were not inlined and cost ~27x.
 * Every helper here is plain scalar arithmetic on float arguments, forced inline.
 *
 * Floating-point contraction is off for every file that includes this header: the watertight
 * ray/triangle test relies on a*b - c*d being rounded as two products and one subtraction, so that
 * the edge function of a shared edge is bit-for-bit the negation of its neighbour's.
 */
#ifndef SHADOWCL_VECMATH_H
#define SHADOWCL_VECMATH_H

#pragma OPENCL FP_CONTRACT OFF

#define INLINE inline __attribute__((always_inline))

/* Math through clang's builtins: PoCL does not inline the OpenCL library's fabs, fmin, fmax, floor and
 * sqrt (each is a call: measured 3x slower in a loop of them); the builtins become single instructions
 * with the same results. Other compilers get the OpenCL functions. */
#if defined(__clang__)
#define SC_ABS(x) __builtin_fabsf(x)
#define SC_MIN(a, b) __builtin_fminf((a), (b))
#define SC_MAX(a, b) __builtin_fmaxf((a), (b))
#define SC_FLOOR(x) __builtin_floorf(x)
#define SC_SQRT(x) __builtin_sqrtf(x)
#define SC_CTZ(x) __builtin_ctz(x)
#else
#define SC_ABS(x) fabs(x)
#define SC_MIN(a, b) fmin((a), (b))
#define SC_MAX(a, b) fmax((a), (b))
#define SC_FLOOR(x) floor(x)
#define SC_SQRT(x) sqrt(x)
#define SC_CTZ(x) (31 - clz((x) & (0u - (x))))
#endif

/* "Infinity" that stays finite: products with unit factors never overflow to inf or NaN. */
#define SC_BIG 1.0e30f

INLINE float dot3(float ax, float ay, float az, float bx, float by, float bz)
{
    return ax * bx + ay * by + az * bz;
}

/* Load element i of an array of 3-float records without vload3 (plain loads vectorise better). */
#define LOAD3(arr, i, x, y, z)            \
    do {                                  \
        const int _b = 3 * (i);           \
        (x) = (arr)[_b];                  \
        (y) = (arr)[_b + 1];              \
        (z) = (arr)[_b + 2];              \
    } while (0)

#endif
