/* Which of the CPU multigrid's hand-written kernels this CPU runs (mg_cpu.h):
 * AVX-512, AVX2 with FMA, or the baseline, as HV_NO512 and HV_NOAVX2 allow. */
#include "mg_cpu.h"

#include <stdlib.h>
#include <string.h>

#if MG_AVX512
int hv__mg_avx512_state = -1;

int hv__mg_avx512_probe(void)
{
    const char *e = getenv("HV_NO512");
    hv__mg_avx512_state = __builtin_cpu_supports("avx512f") && !(e && *e && strcmp(e, "0")) ? 1 : 0;
    return hv__mg_avx512_state;
}

int hv__mg_avx2_state = -1;

int hv__mg_avx2_probe(void)
{
    const char *e = getenv("HV_NOAVX2");
    hv__mg_avx2_state = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
                                !(e && *e && strcmp(e, "0"))
                            ? 1
                            : 0;
    return hv__mg_avx2_state;
}
#endif
