/* Private helpers shared by the solver backends (see backend.h). */
#include "backend.h"

#include <math.h>
#ifdef _OPENMP
#include <omp.h>
#endif
#include <stdlib.h>

void hv__project_mean(const hv_setup *s, double *u)
{
    if (!s->region) {
        double sum = 0;
#pragma omp parallel for reduction(+ : sum) schedule(static)
        for (size_t c = 0; c < s->count; c++)
            sum += u[c];
        double mean = sum / (double)s->count;
#pragma omp parallel for schedule(static)
        for (size_t c = 0; c < s->count; c++)
            u[c] -= mean;
        return;
    }
    /* Sums and counts per region, per thread (a static schedule), then added
     * up in thread order: the same result on every run with as many threads. */
    int nt = 1;
#ifdef _OPENMP
    nt = omp_get_max_threads();
#endif
    if (s->nregion == 1) {
        double part[2 * 8 * 64] = {0}; /* a cache line per thread, up to 64 threads */
        if (nt > 64)
            nt = 64;
#pragma omp parallel num_threads(nt)
        {
            int t = 0;
#ifdef _OPENMP
            t = omp_get_thread_num();
#endif
            double sum = 0, cnt = 0;
#pragma omp for schedule(static)
            for (size_t c = 0; c < s->count; c++)
                if (s->region[c] >= 0) {
                    sum += u[c];
                    cnt += 1;
                }
            part[16 * t] = sum;
            part[16 * t + 1] = cnt;
        }
        double sum = 0, cnt = 0;
        for (int t = 0; t < nt; t++) {
            sum += part[16 * t];
            cnt += part[16 * t + 1];
        }
        double mean = cnt > 0 ? sum / cnt : 0.0;
#pragma omp parallel for schedule(static)
        for (size_t c = 0; c < s->count; c++)
            u[c] = s->region[c] >= 0 ? u[c] - mean : 0.0;
        return;
    }
    /* Each thread's slice padded to whole cache lines: no false sharing. */
    const size_t used = (size_t)s->nregion * 2, per = (used + 15) & ~(size_t)7;
    double *acc = calloc(per * (size_t)nt, sizeof *acc);
    if (!acc)
        return;
#pragma omp parallel num_threads(nt)
    {
        int t = 0;
#ifdef _OPENMP
        t = omp_get_thread_num();
#endif
        double *a = acc + per * (size_t)t;
#pragma omp for schedule(static)
        for (size_t c = 0; c < s->count; c++)
            if (s->region[c] >= 0) {
                a[2 * s->region[c]] += u[c];
                a[2 * s->region[c] + 1] += 1;
            }
    }
    for (int t = 1; t < nt; t++)
        for (size_t q = 0; q < used; q++)
            acc[q] += acc[per * (size_t)t + q];
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < s->count; c++) {
        int r = s->region[c];
        u[c] = r >= 0 ? u[c] - acc[2 * r] / acc[2 * r + 1] : 0.0;
    }
    free(acc);
}

double hv__norm2(const hv_setup *s, const double *v)
{
    double nn = 0;
    const uint8_t *solid = s->p.solid;
#pragma omp parallel for reduction(+ : nn) schedule(static)
    for (size_t c = 0; c < s->count; c++)
        if (!solid || !solid[c])
            nn += v[c] * v[c];
    return sqrt(nn);
}
