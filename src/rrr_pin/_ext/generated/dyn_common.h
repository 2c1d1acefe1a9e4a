/* Shared by the generated dyn_*.c files (rrr_pin.sim.dyngen): the batch bound, the
 * per-function instruction-set clones and the sines and cosines of the joint angles.
 *
 * RRR_DYN_CLONES: with GCC or Clang on x86-64 and ifunc support, each function is compiled
 * twice, for the x86-64 baseline and for AVX2, and the loader picks the one the CPU runs
 * (function multiversioning); elsewhere one portable version. Never -march=native: the wheel
 * may move to another machine. The C is compiled with -ffp-contract=off (CMakeLists.txt), so
 * both clones, and every lane of a vector, round each operation alike.
 */
#pragma once

#include <math.h>

#define RRR_DYN_BMAX 16

#if defined(RRR_DYN_MULTIVERSION) && defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  #define RRR_DYN_CLONES __attribute__((target_clones("avx2", "default")))
#else
  #define RRR_DYN_CLONES
#endif

/* rrr_dyn_sincos: s[k] = sin(q[k]), c[k] = cos(q[k]), k < m.
 *
 * RRR_DYN_LIBMVEC (glibc on x86-64, CMakeLists.txt): by glibc's vector math library (libmvec,
 * the x86-64 vector function ABI: 4 lanes with AVX2, 2 with SSE), about 10x faster than the
 * scalar calls, which took some 60 % of a forward-dynamics call (measured, generator 2); its
 * results are within 4 ulp (glibc's manual), a few ulp from the scalar sin and cos. Every angle
 * goes through the vector function, a short last chunk padded with zeros, so an angle's sine
 * does not depend on its place in the batch; the CPU picks AVX2 or SSE as it picks the clones.
 * Otherwise the scalar calls.
 */
#if defined(RRR_DYN_LIBMVEC) && defined(__x86_64__) && defined(__GNUC__)
typedef double rrr_dyn_v2d __attribute__((vector_size(16)));
typedef double rrr_dyn_v4d __attribute__((vector_size(32)));
rrr_dyn_v2d _ZGVbN2v_sin(rrr_dyn_v2d);
rrr_dyn_v2d _ZGVbN2v_cos(rrr_dyn_v2d);
rrr_dyn_v4d _ZGVdN4v_sin(rrr_dyn_v4d);
rrr_dyn_v4d _ZGVdN4v_cos(rrr_dyn_v4d);

__attribute__((target("avx2"))) static void rrr_dyn_sincos4(int m, const double * q, double * s,
                                                             double * c)
{
  int k = 0;
  for (; k + 4 <= m; k += 4)
  {
    rrr_dyn_v4d x;
    __builtin_memcpy(&x, q + k, sizeof x);
    const rrr_dyn_v4d a = _ZGVdN4v_sin(x), b = _ZGVdN4v_cos(x);
    __builtin_memcpy(s + k, &a, sizeof a);
    __builtin_memcpy(c + k, &b, sizeof b);
  }
  if (k < m)  // the last angles, padded with zeros: the same vector function
  {
    rrr_dyn_v4d x = {0.0, 0.0, 0.0, 0.0};
    for (int i = 0; k + i < m; ++i)
      x[i] = q[k + i];
    const rrr_dyn_v4d a = _ZGVdN4v_sin(x), b = _ZGVdN4v_cos(x);
    for (int i = 0; k + i < m; ++i)
    {
      s[k + i] = a[i];
      c[k + i] = b[i];
    }
  }
}

static void rrr_dyn_sincos2(int m, const double * q, double * s, double * c)
{
  int k = 0;
  for (; k + 2 <= m; k += 2)
  {
    rrr_dyn_v2d x;
    __builtin_memcpy(&x, q + k, sizeof x);
    const rrr_dyn_v2d a = _ZGVbN2v_sin(x), b = _ZGVbN2v_cos(x);
    __builtin_memcpy(s + k, &a, sizeof a);
    __builtin_memcpy(c + k, &b, sizeof b);
  }
  if (k < m)  // the last angles, padded with zeros: the same vector function
  {
    rrr_dyn_v2d x = {0.0, 0.0};
    for (int i = 0; k + i < m; ++i)
      x[i] = q[k + i];
    const rrr_dyn_v2d a = _ZGVbN2v_sin(x), b = _ZGVbN2v_cos(x);
    for (int i = 0; k + i < m; ++i)
    {
      s[k + i] = a[i];
      c[k + i] = b[i];
    }
  }
}

static inline void rrr_dyn_sincos(int m, const double * q, double * s, double * c)
{
  if (__builtin_cpu_supports("avx2"))
    rrr_dyn_sincos4(m, q, s, c);
  else
    rrr_dyn_sincos2(m, q, s, c);
}
#else
static inline void rrr_dyn_sincos(int m, const double * q, double * s, double * c)
{
  for (int k = 0; k < m; ++k)
  {
    s[k] = sin(q[k]);
    c[k] = cos(q[k]);
  }
}
#endif
