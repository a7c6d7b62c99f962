/* Private helpers shared by the solver backends (see backend.h). */
#include "backend.h"

#include <math.h>
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
    double *acc = calloc((size_t)s->nregion * 2, sizeof *acc);
    if (!acc)
        return;
    for (size_t c = 0; c < s->count; c++)
        if (s->region[c] >= 0) {
            acc[2 * s->region[c]] += u[c];
            acc[2 * s->region[c] + 1] += 1;
        }
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
