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
#define NOINLINE __attribute__((noinline))   /* code emitted once: large, rarely hot or called per list, not per triangle */
/* Cold start: PoCL compiles a kernel at its first launch into the kernel and two work-group launchers,
 * each with the kernel inlined, so code inlined into a kernel is compiled three times. A kernel whose
 * work-item does much keeps its body (or its largest helper) in a NOINLINE function, compiled once:
 * measured first launches, CPU, exact_classify 0.36 -> 0.22 s, ls_csr 0.64 -> 0.25 s, the raster's
 * three 0.60 -> 0.27 s. A call per work-item costs nothing next to such a body, but check the warm
 * speed: ls_csr's whole body out of line was 11-19% slower (only ls_project is); kernels of a few loads
 * and stores stay inline. */

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
#define SC_IMIN(a, b) ((a) < (b) ? (a) : (b))   /* min(int, int) is a library call too */
/* A hint to bring the cache line at global pointer p in, to be read (write 0) or written (write 1).
 * OpenCL's prefetch is a library call; PoCL's CPU devices have one flat address space, so the pointer
 * goes through an integer to clang's builtin. */
#define SC_PREFETCH(p, write) __builtin_prefetch((const void *)(ulong)(p), (write))
#else
#define SC_ABS(x) fabs(x)
#define SC_MIN(a, b) fmin((a), (b))
#define SC_MAX(a, b) fmax((a), (b))
#define SC_FLOOR(x) floor(x)
#define SC_SQRT(x) sqrt(x)
#define SC_CTZ(x) (31 - clz((x) & (0u - (x))))
#define SC_IMIN(a, b) min((a), (b))
#define SC_PREFETCH(p, write) prefetch((p), 1)
#endif

/* Lanes: kernels that test one triangle against several receivers at once are written once over the
 * types lfloat / lint / ldouble, which are float / int / double when LANES is 1 (the default) and
 * OpenCL vectors of LANES elements otherwise (LANES = 4 or 8). Masks follow OpenCL's rule for the
 * type: a scalar comparison gives 1 or 0, a vector one -1 or 0; code that is written with comparisons,
 * &, |, ! and the ternary on masks (never ~ or arithmetic on them) means the same for both.
 * LANE_ANY(m) is true when any lane of mask m is set; LANE_LOAD(type, p) / LANE_STORE(v, p) move LANES
 * values between a private array and a lane value. All are written with swizzles or compiler builtins,
 * not any() or vloadn: PoCL calls its library for those (not inlined), and a call per triangle test
 * cost more than the lanes saved. LANE_ANY is clang's __builtin_reduce_or where the compiler has it
 * (PoCL: one vptest, against the swizzles' eight shuffles and ors; the walk 6-14 % faster on every
 * bench scene, docs/exact-speed.md), else the swizzles. */
#ifndef LANES
#define LANES 1
#endif
#define SC_CAT_(a, b) a##b
#define SC_CAT(a, b) SC_CAT_(a, b)
#if LANES == 1
#define SC_LANES_SUFFIX
#define LANE_ANY(m) ((m) != 0)
#define LANE_LOAD(type, p) ((p)[0])
#define LANE_STORE(v, p) ((p)[0] = (v))
#elif LANES == 4
#define SC_LANES_SUFFIX 4
#define LANE_ANY_SWIZZLED(m) (((m).s0 | (m).s1 | (m).s2 | (m).s3) != 0)
#define LANE_LOAD(type, p) ((type##4)((p)[0], (p)[1], (p)[2], (p)[3]))
#define LANE_STORE(v, p) ((p)[0] = (v).s0, (p)[1] = (v).s1, (p)[2] = (v).s2, (p)[3] = (v).s3)
#elif LANES == 8
#define SC_LANES_SUFFIX 8
#define LANE_ANY_SWIZZLED(m) ((((m).lo | (m).hi).s0 | ((m).lo | (m).hi).s1 | ((m).lo | (m).hi).s2 | ((m).lo | (m).hi).s3) != 0)
#define LANE_LOAD(type, p) ((type##8)((p)[0], (p)[1], (p)[2], (p)[3], (p)[4], (p)[5], (p)[6], (p)[7]))
#define LANE_STORE(v, p)                                                                             \
    ((p)[0] = (v).s0, (p)[1] = (v).s1, (p)[2] = (v).s2, (p)[3] = (v).s3, (p)[4] = (v).s4, (p)[5] = (v).s5, \
     (p)[6] = (v).s6, (p)[7] = (v).s7)
#else
#error "LANES must be 1, 4 or 8"
#endif
#if LANES > 1
#if defined(__has_builtin)
#if __has_builtin(__builtin_reduce_or)
#define LANE_ANY(m) (__builtin_reduce_or(m) != 0)
#endif
#endif
#ifndef LANE_ANY
#define LANE_ANY(m) LANE_ANY_SWIZZLED(m)
#endif
#endif
#if LANES == 1
#define LANE_SQRT(x) SC_SQRT(x)
#else
#define LANE_SQRT(x) sqrt(x)      /* a library call, but one per LANES values */
#endif
#define LANE_TYPE(t) SC_CAT(t, SC_LANES_SUFFIX)
/* Lane conversions int <-> float (C's rounding towards zero for float -> int), as single instructions:
 * OpenCL's convert_intN / convert_floatN are library calls on PoCL */
#if LANES == 1
#define LANE_TO_INT(x) ((int)(x))
#define LANE_TO_FLOAT(x) ((float)(x))
#elif defined(__clang__)
#define LANE_TO_INT(x) __builtin_convertvector((x), lint)
#define LANE_TO_FLOAT(x) __builtin_convertvector((x), lfloat)
#else
#define LANE_TO_INT(x) SC_CAT(convert_int, SC_LANES_SUFFIX)(x)
#define LANE_TO_FLOAT(x) SC_CAT(convert_float, SC_LANES_SUFFIX)(x)
#endif
typedef LANE_TYPE(float) lfloat;
typedef LANE_TYPE(int) lint;
#if defined(__clang__)
#define SC_LABS(x) __builtin_elementwise_abs(x)   /* lfloat: a single instruction, not a library call */
#else
#define SC_LABS(x) fabs(x)
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

/* The precision of a call's input arrays: INPUT_F64 1 reads the caller's float64 points and normals as
 * they are (needs cl_khr_fp64: the kernels move and round them as the host would), 0 float32. */
#ifndef INPUT_F64
#define INPUT_F64 0
#endif
#if INPUT_F64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double input_t;
#else
typedef float input_t;
#endif

#endif
