/* Private to the CPU multigrid: which of its hand-written kernels this CPU
 * runs (mg_cpu.c), asked where a row chooses. */
#ifndef HV_SOLVE_MG_CPU_H
#define HV_SOLVE_MG_CPU_H

#include "mg_level.h"

/* MG_KERNEL (mg_level.h): row kernels built for AVX2 and the baseline;
 * MG_AVX512: the AVX-512 (and hand-written AVX2) kernels are built too. */
#if MG_MULTIVERSION
#define MG_AVX512 1
#include <immintrin.h>
#else
#define MG_AVX512 0
#endif

#if MG_AVX512
/* 1: the AVX-512 rows run, 0: they do not, -1: not asked yet. They run where
 * the CPU has them, unless HV_NO512 is set to anything but empty or 0 (the
 * tests run the other path that way). Asked once per row, so inline. */
extern int hv__mg_avx512_state;
int hv__mg_avx512_probe(void);
static inline int mg_avx512(void)
{
    return hv__mg_avx512_state >= 0 ? hv__mg_avx512_state : hv__mg_avx512_probe();
}

/* 1: the hand-written AVX2 + FMA kernels (the aggregation levels' products,
 * the binary rows of the fused pass) run where AVX-512's do not: the CPU has
 * both, unless HV_NOAVX2 is set to anything but empty or 0 (the tests run the
 * baseline C that way); 0: they do not; -1: not asked yet. */
extern int hv__mg_avx2_state;
int hv__mg_avx2_probe(void);

static inline int mg_avx2(void)
{
    return hv__mg_avx2_state >= 0 ? hv__mg_avx2_state : hv__mg_avx2_probe();
}
#endif

#endif
