/* Shared by the generated dyn_*.c files (rrr_pin.sim.dyngen): the batch bound and the
 * per-function instruction-set clones.
 *
 * RRR_DYN_CLONES: with GCC or Clang on x86-64 and ifunc support, each function is compiled
 * twice, for the x86-64 baseline and for AVX2, and the loader picks the one the CPU runs
 * (function multiversioning); elsewhere one portable version. Never -march=native: the wheel
 * may move to another machine. The C is compiled with -ffp-contract=off (CMakeLists.txt), so
 * both clones, and every lane of a vector, round each operation alike.
 */
#pragma once

#define RRR_DYN_BMAX 16

#if defined(RRR_DYN_MULTIVERSION) && defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  #define RRR_DYN_CLONES __attribute__((target_clones("avx2", "default")))
#else
  #define RRR_DYN_CLONES
#endif
