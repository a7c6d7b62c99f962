/*
 * The multigrid hierarchy on the host, shared by the CPU (mg_backend.c) and OpenCL
 * (cl/cl_backend.c) backends so that both coarsen the same way: level sizes by
 * semi-coarsening, coefficients by averaging (docs/METHOD.md, "Multigrid"),
 * Chebyshev bounds by power iteration and the bottom level's connected regions.
 */
#include "mg_level.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Face weight with plain levels, walls and out-of-range indices handled. */
static float level_w(const mg_level *L, int a, int i, int j, int k)
{
    int idx[3] = {i, j, k};
    for (int b = 0; b < 3; b++)
        if (idx[b] < 0 || idx[b] > L->n[b] - (b != a))
            return 0.0f;
    if (idx[a] == 0 || idx[a] == L->n[a])
        return 0.0f;
    return L->plain ? 1.0f : L->w[a][mg_face_index(L, a, i, j, k)];
}

static float level_a(const mg_level *L, int i, int j, int k)
{
    if (i < 0 || j < 0 || k < 0 || i >= L->n[0] || j >= L->n[1] || k >= L->n[2])
        return 0.0f;
    return L->plain ? 1.0f : L->a[(size_t)i + L->sy * j + L->sz * k];
}

double hv__mg_level_diag(const mg_level *L, int dim, double alpha, int i, int j, int k)
{
    double d = alpha * level_a(L, i, j, k);
    int idx[3] = {i, j, k};
    for (int b = 0; b < dim; b++) {
        int hi[3] = {i, j, k};
        hi[b] = idx[b] + 1;
        d += L->c[b] * (level_w(L, b, i, j, k) + level_w(L, b, hi[0], hi[1], hi[2]));
    }
    return d;
}

/* Row (j,k) of y = A x in double into yr (the row's n[0] values), x in T: the
 * first and last cells through the general stencil, the interior in a loop
 * without branches. */
#define APPLY_ROW(NAME, T)                                                                         \
    MG_KERNEL_512 static void NAME(const mg_level *L, int dim, double alpha, const T *x,           \
                                   double *yr, int j, int k)                                       \
    {                                                                                              \
        const struct {                                                                             \
            int dim;                                                                               \
            double alpha;                                                                          \
        } op = {dim, alpha}, *m = &op;                                                             \
        const int nx = L->n[0];                                                                    \
        const double cx = L->c[0], cy = L->c[1], cz = L->c[2];                                     \
        for (int i = 0; i<nx; i += nx - 1> 0 ? nx - 1 : 1) {                                       \
            size_t c = (size_t)i + L->sy * j + L->sz * k;                                          \
            double S, D;                                                                           \
            MG_STENCIL(L, m, x, i, j, k, c, S, D);                                                 \
            yr[i] = D * x[c] - S;                                                                  \
        }                                                                                          \
        if (nx < 3)                                                                                \
            return;                                                                                \
        if (L->plain) {                                                                            \
            const size_t base = L->sy * (size_t)j + L->sz * (size_t)k;                             \
            const double wym = j > 0, wyp = j < L->n[1] - 1;                                       \
            const double wzm = dim == 3 && k > 0, wzp = dim == 3 && k < L->n[2] - 1;               \
            const T *xr = x + base;                                                                \
            const T *ym = wym ? xr - L->sy : xr, *yp = wyp ? xr + L->sy : xr;                      \
            const T *zm = wzm ? xr - L->sz : xr, *zp = wzp ? xr + L->sz : xr;                      \
            const double d = alpha + 2 * cx + cy * (wym + wyp) + cz * (wzm + wzp);                 \
            for (int i = 1; i < nx - 1; i++)                                                       \
                yr[i] =                                                                            \
                    d * xr[i] - (cx * (xr[i - 1] + xr[i + 1]) + cy * (wym * ym[i] + wyp * yp[i]) + \
                                 cz * (wzm * zm[i] + wzp * zp[i]));                                \
            return;                                                                                \
        }                                                                                          \
        const mg_wrow R = mg_wrow_at(L, dim, j, k);                                                \
        const T *xr = x + R.base;                                                                  \
        const float *ar = L->a + R.base;                                                           \
        if (L->binary) {                                                                           \
            /* w_f = a_c a_nb: the cell weights give the faces, 6 bytes fewer per cell to read */  \
            const double wym = R.ym != 0, wyp = R.yp != 0, wzm = R.zm != 0, wzp = R.zp != 0;       \
            const float *aym = ar + R.ym, *ayp = ar + R.yp, *azm = ar + R.zm, *azp = ar + R.zp;    \
            for (int i = 1; i < nx - 1; i++) {                                                     \
                const double xl = ar[i - 1], xh = ar[i + 1], yl = wym * aym[i], yh = wyp * ayp[i]; \
                const double zl = wzm * azm[i], zh = wzp * azp[i];                                 \
                const double d = alpha + cx * (xl + xh) + cy * (yl + yh) + cz * (zl + zh);         \
                const double s = cx * (xl * xr[i - 1] + xh * xr[i + 1]) +                          \
                                 cy * (yl * xr[R.ym + i] + yh * xr[R.yp + i]) +                    \
                                 cz * (zl * xr[R.zm + i] + zh * xr[R.zp + i]);                     \
                yr[i] = ar[i] * (d * xr[i] - s);                                                   \
            }                                                                                      \
            return;                                                                                \
        }                                                                                          \
        if (R.wzl) {                                                                               \
            for (int i = 1; i < nx - 1; i++) {                                                     \
                const double wl = R.wx[i], wh = R.wx[i + 1], yl = R.wyl[i], yh = R.wyh[i];         \
                const double zl = R.wzl[i], zh = R.wzh[i];                                         \
                const double d = alpha * ar[i] + cx * (wl + wh) + cy * (yl + yh) + cz * (zl + zh); \
                yr[i] = d * xr[i] - (cx * (wl * xr[i - 1] + wh * xr[i + 1]) +                      \
                                     cy * (yl * xr[R.ym + i] + yh * xr[R.yp + i]) +                \
                                     cz * (zl * xr[R.zm + i] + zh * xr[R.zp + i]));                \
            }                                                                                      \
        } else {                                                                                   \
            for (int i = 1; i < nx - 1; i++) {                                                     \
                const double wl = R.wx[i], wh = R.wx[i + 1], yl = R.wyl[i], yh = R.wyh[i];         \
                const double d = alpha * ar[i] + cx * (wl + wh) + cy * (yl + yh);                  \
                yr[i] = d * xr[i] - (cx * (wl * xr[i - 1] + wh * xr[i + 1]) +                      \
                                     cy * (yl * xr[R.ym + i] + yh * xr[R.yp + i]));                \
            }                                                                                      \
        }                                                                                          \
    }

APPLY_ROW(apply_row_d, double)
APPLY_ROW(apply_row_f, float)

void hv__mg_level_apply_d(const mg_level *L, int dim, double alpha, const double *x, double *y)
{
#pragma omp parallel for collapse(2) schedule(static) if (L->count > 32768)
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++)
            apply_row_d(L, dim, alpha, x, y + L->sy * (size_t)j + L->sz * (size_t)k, j, k);
}

void hv__mg_level_apply_row_f(const mg_level *L, int dim, double alpha, const float *x,
                              double *yrow, int j, int k)
{
    apply_row_f(L, dim, alpha, x, yrow, j, k);
}

void hv__mg_level_apply_row_d(const mg_level *L, int dim, double alpha, const double *x,
                              double *yrow, int j, int k)
{
    apply_row_d(L, dim, alpha, x, yrow, j, k);
}

static hv_status level_alloc_coeffs(mg_level *L, int dim)
{
    L->a = hv_malloc(L->count * sizeof(float));
    L->dinv = hv_malloc(L->count * sizeof(float));
    if (!L->a || !L->dinv)
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for level coefficients");
    for (int b = 0; b < dim; b++) {
        size_t nf = (L->count / L->n[b]) * (size_t)(L->n[b] + 1);
        L->w[b] = hv_calloc(nf, sizeof(float));
        if (!L->w[b])
            return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for face weights");
    }
    return HV_OK;
}

/* v -= its region's mean, per connected region of the bottom level. */
static void bottom_project(const mg_level *L, double *v)
{
    if (L->nregion <= 0)
        return;
    double sum[64] = {0}, cnt[64] = {0};
    double *S = L->nregion <= 64 ? sum : calloc((size_t)L->nregion * 2, sizeof(double));
    double *N = L->nregion <= 64 ? cnt : S + L->nregion;
    if (!S)
        return;
    for (size_t c = 0; c < L->count; c++)
        if (L->region[c] >= 0) {
            S[L->region[c]] += v[c];
            N[L->region[c]] += 1;
        }
    for (size_t c = 0; c < L->count; c++)
        if (L->region[c] >= 0)
            v[c] -= S[L->region[c]] / N[L->region[c]];
    if (S != sum)
        free(S);
}

static double dot_d(const double *a, const double *b, size_t n)
{
    double s = 0;
    for (size_t i = 0; i < n; i++)
        s += a[i] * b[i];
    return s;
}

void hv__mg_bottom_cg(const mg_level *L, int dim, double alpha, const float *f, float *u,
                      double *work)
{
    const size_t n = L->count;
    double *x = work, *b = x + n, *r = b + n, *p = r + n, *q = p + n;
    for (size_t c = 0; c < n; c++) {
        x[c] = 0;
        b[c] = f[c];
    }
    if (alpha == 0)
        bottom_project(L, b);
    double bn = sqrt(dot_d(b, b, n));
    if (bn > 0) {
        memcpy(r, b, n * sizeof *r);
        memcpy(p, r, n * sizeof *p);
        double rr = dot_d(r, r, n);
        for (int it = 0; it < 4 * (int)n + 50 && sqrt(rr) > 1e-12 * bn; it++) {
            hv__mg_level_apply_d(L, dim, alpha, p, q);
            double pq = dot_d(p, q, n);
            if (!(pq > 0))
                break;
            double al = rr / pq;
            for (size_t c = 0; c < n; c++) {
                x[c] += al * p[c];
                r[c] -= al * q[c];
            }
            double rr2 = dot_d(r, r, n);
            double be = rr2 / rr;
            rr = rr2;
            for (size_t c = 0; c < n; c++)
                p[c] = r[c] + be * p[c];
        }
        if (alpha == 0)
            bottom_project(L, x);
    }
    for (size_t c = 0; c < n; c++)
        u[c] = (float)x[c];
}

void hv__mg_level_free_coeffs(mg_level *L)
{
    hv_free(L->a);
    hv_free(L->dinv);
    L->a = L->dinv = NULL;
    for (int b = 0; b < 3; b++) {
        hv_free(L->w[b]);
        L->w[b] = NULL;
    }
}

static void level_fill_dinv(const mg_hierarchy *H, mg_level *L)
{
#pragma omp parallel for collapse(2) schedule(static)
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++)
            for (int i = 0; i < L->n[0]; i++) {
                double d = hv__mg_level_diag(L, H->dim, H->alpha, i, j, k);
                L->dinv[(size_t)i + L->sy * j + L->sz * k] = d > 0 ? (float)(1.0 / d) : 0.0f;
            }
}

/* Fine level from the solid mask: a = fluid, w = 1 between two fluid cells. */
static hv_status level_from_mask(const mg_hierarchy *H, mg_level *L, const uint8_t *solid)
{
    hv_status st = level_alloc_coeffs(L, H->dim);
    if (st)
        return st;
    for (size_t c = 0; c < L->count; c++)
        L->a[c] = solid[c] ? 0.0f : 1.0f;
    for (int b = 0; b < H->dim; b++) {
        size_t stride = b == 0 ? 1 : b == 1 ? L->sy : L->sz;
#pragma omp parallel for collapse(2) schedule(static)
        for (int k = 0; k < L->n[2] + (b == 2); k++)
            for (int j = 0; j < L->n[1] + (b == 1); j++)
                for (int i = 0; i < L->n[0] + (b == 0); i++) {
                    int idx[3] = {i, j, k};
                    float w = 0.0f;
                    if (idx[b] > 0 && idx[b] < L->n[b]) {
                        size_t hi = (size_t)i + L->sy * j + L->sz * k;
                        w = (!solid[hi] && !solid[hi - stride]) ? 1.0f : 0.0f;
                    }
                    L->w[b][mg_face_index(L, b, i, j, k)] = w;
                }
    }
    level_fill_dinv(H, L);
    L->binary = 1;
    return HV_OK;
}

/* Coarse coefficients from fine ones (docs/METHOD.md, "Multigrid"): a = mean
 * of children, face weight = mean of the fine faces that tile the coarse face. */
static hv_status level_coarsen(const mg_hierarchy *H, const mg_level *F, mg_level *C)
{
    int even = F->plain;
    for (int b = 0; b < H->dim; b++)
        if (F->coarsen[b] && F->n[b] % 2)
            even = 0;
    if (even) { /* a plain level halved along even axes stays plain */
        C->plain = 1;
        return HV_OK;
    }
    hv_status st = level_alloc_coeffs(C, H->dim);
    if (st)
        return st;
    int nchild = 1;
    for (int b = 0; b < H->dim; b++)
        nchild *= F->coarsen[b] ? 2 : 1;
    const int *co = F->coarsen;
#pragma omp parallel for collapse(2) schedule(static)
    for (int K = 0; K < C->n[2]; K++)
        for (int J = 0; J < C->n[1]; J++)
            for (int I = 0; I < C->n[0]; I++) {
                double sum = 0;
                for (int dk = 0; dk <= co[2]; dk++)
                    for (int dj = 0; dj <= co[1]; dj++)
                        for (int di = 0; di <= co[0]; di++)
                            sum += level_a(F, co[0] ? 2 * I + di : I, co[1] ? 2 * J + dj : J,
                                           co[2] ? 2 * K + dk : K);
                C->a[(size_t)I + C->sy * J + C->sz * K] = (float)(sum / nchild);
            }
    for (int b = 0; b < H->dim; b++) {
        int nface = nchild / (co[b] ? 2 : 1);
#pragma omp parallel for collapse(2) schedule(static)
        for (int K = 0; K < C->n[2] + (b == 2); K++)
            for (int J = 0; J < C->n[1] + (b == 1); J++)
                for (int I = 0; I < C->n[0] + (b == 0); I++) {
                    int CI[3] = {I, J, K};
                    double sum = 0;
                    int lim[3];
                    for (int e = 0; e < 3; e++)
                        lim[e] = (e == b) ? 0 : co[e];
                    for (int dk = 0; dk <= lim[2]; dk++)
                        for (int dj = 0; dj <= lim[1]; dj++)
                            for (int di = 0; di <= lim[0]; di++) {
                                int d[3] = {di, dj, dk}, f[3];
                                for (int e = 0; e < 3; e++)
                                    f[e] = co[e] ? 2 * CI[e] + d[e] : CI[e];
                                sum += level_w(F, b, f[0], f[1], f[2]);
                            }
                    C->w[b][mg_face_index(C, b, I, J, K)] = (float)(sum / nface);
                }
    }
    /* A coarse level whose weights all equal one inside is plain. */
    int plain = 1;
    for (size_t c = 0; c < C->count && plain; c++)
        plain = C->a[c] == 1.0f;
    for (int b = 0; b < H->dim && plain; b++)
        for (int K = 0; K < C->n[2] + (b == 2) && plain; K++)
            for (int J = 0; J < C->n[1] + (b == 1) && plain; J++)
                for (int I = 0; I < C->n[0] + (b == 0) && plain; I++) {
                    int CI[3] = {I, J, K};
                    if (CI[b] > 0 && CI[b] < C->n[b])
                        plain = C->w[b][mg_face_index(C, b, I, J, K)] == 1.0f;
                }
    if (plain) {
        hv__mg_level_free_coeffs(C);
        C->plain = 1;
    } else {
        level_fill_dinv(H, C);
    }
    return HV_OK;
}

/* Connected regions of a level: cells with a > 0 joined through faces w > 0. */
static hv_status level_regions(const mg_hierarchy *H, mg_level *L)
{
    L->region = malloc(L->count * sizeof(int32_t));
    size_t *stack = malloc(L->count * sizeof(size_t));
    if (!L->region || !stack) {
        free(stack);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory labelling regions");
    }
    for (size_t c = 0; c < L->count; c++)
        L->region[c] = -1;
    int nr = 0;
    for (size_t seed = 0; seed < L->count; seed++) {
        int si = (int)(seed % L->n[0]), sj = (int)((seed / L->sy) % L->n[1]),
            sk = (int)(seed / L->sz);
        if (L->region[seed] >= 0 || level_a(L, si, sj, sk) == 0.0f)
            continue;
        size_t top = 0;
        stack[top++] = seed;
        L->region[seed] = nr;
        while (top) {
            size_t c = stack[--top];
            int idx[3] = {(int)(c % L->n[0]), (int)((c / L->sy) % L->n[1]), (int)(c / L->sz)};
            for (int b = 0; b < H->dim; b++)
                for (int sgn = 0; sgn < 2; sgn++) {
                    int f[3] = {idx[0], idx[1], idx[2]};
                    f[b] += sgn; /* face index: lo face = idx, hi face = idx + 1 */
                    if (level_w(L, b, f[0], f[1], f[2]) == 0.0f)
                        continue;
                    size_t stride = b == 0 ? 1 : b == 1 ? L->sy : L->sz;
                    size_t nb = sgn ? c + stride : c - stride;
                    if (L->region[nb] < 0) {
                        L->region[nb] = nr;
                        stack[top++] = nb;
                    }
                }
        }
        nr++;
    }
    free(stack);
    L->nregion = nr;
    return HV_OK;
}

/* Largest eigenvalue of D^-1 A on a plain level: Gershgorin's bound, which
 * a row of the interior attains up to O(1/n^2) (off-diagonal sum / diagonal
 * grows with the neighbours a row has). */
static double plain_lmax(const mg_hierarchy *H, const mg_level *L)
{
    double off = 0;
    for (int b = 0; b < H->dim; b++)
        off += L->c[b] * (L->n[b] > 2 ? 2 : L->n[b] - 1);
    double d = H->alpha + off;
    return d > 0 ? 1.0 + off / d : 2.0;
}

/* Cells per partial sum of the power iteration: the sums add in a fixed
 * order whatever the thread count, so the estimate does not depend on it. */
#define LMAX_CHUNK 65536

/* The power iteration's step: y = D^-1 A x, and (x.y, x.x, y.y). */
static void lmax_step(const mg_hierarchy *H, const mg_level *L, const double *dg, const double *x,
                      double *y, double *part, double sums[3])
{
    size_t n = L->count, nchunk = (n + LMAX_CHUNK - 1) / LMAX_CHUNK;
    hv__mg_level_apply_d(L, H->dim, H->alpha, x, y);
#pragma omp parallel for schedule(static)
    for (size_t q = 0; q < nchunk; q++) {
        double dot = 0, xx = 0, yy = 0;
        size_t end = (q + 1) * LMAX_CHUNK < n ? (q + 1) * LMAX_CHUNK : n;
        for (size_t c = q * LMAX_CHUNK; c < end; c++) {
            y[c] = dg[c] > 0 ? y[c] / dg[c] : 0;
            dot += x[c] * y[c];
            xx += x[c] * x[c];
            yy += y[c] * y[c];
        }
        part[3 * q] = dot;
        part[3 * q + 1] = xx;
        part[3 * q + 2] = yy;
    }
    sums[0] = sums[1] = sums[2] = 0;
    for (size_t q = 0; q < nchunk; q++)
        for (int t = 0; t < 3; t++)
            sums[t] += part[3 * q + t];
}

/* Largest eigenvalue of D^-1 A (Chebyshev bounds): exact bound on plain
 * levels, else a few power iterations from a hashed start vector. */
static double estimate_lmax(const mg_hierarchy *H, const mg_level *L)
{
    if (L->plain)
        return plain_lmax(H, L);
    size_t n = L->count, nchunk = (n + LMAX_CHUNK - 1) / LMAX_CHUNK;
    double *x = malloc(n * sizeof *x), *y = malloc(n * sizeof *y), *dg = malloc(n * sizeof *dg);
    double *part = malloc(3 * nchunk * sizeof *part);
    double lam = 2.0;
    if (!x || !y || !dg || !part)
        goto done;
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < n; c++) {
        dg[c] = L->dinv[c] > 0 ? 1.0 / L->dinv[c] : 0.0;
        uint64_t h = (c + 1) * 0x9E3779B97F4A7C15ull;
        h ^= h >> 31;
        h *= 0xBF58476D1CE4E5B9ull;
        h ^= h >> 29;
        x[c] = (double)(h >> 40) / (double)(1u << 24) - 0.5;
    }
    for (int it = 0; it < 12; it++) {
        double sums[3];
        lmax_step(H, L, dg, x, y, part, sums);
        lam = sums[1] > 0 ? sums[0] / sums[1] : 2.0;
        double nrm = sqrt(sums[2]);
        if (!(nrm > 0))
            break;
#pragma omp parallel for schedule(static)
        for (size_t c = 0; c < n; c++)
            x[c] = y[c] / nrm;
    }
    lam *= 1.1;
done:
    free(x);
    free(y);
    free(dg);
    free(part);
    return lam > 2.0 ? 2.0 : (lam < 0.1 ? 0.1 : lam);
}

void hv__mg_hierarchy_free(mg_hierarchy *H)
{
    for (int l = 0; l < H->nlev; l++) {
        hv__mg_level_free_coeffs(&H->lv[l]);
        free(H->lv[l].region);
        H->lv[l].region = NULL;
    }
    H->nlev = 0;
}

hv_status hv__mg_hierarchy_build(mg_hierarchy *H, const hv_setup *s, int with_lmax)
{
    return hv__mg_hierarchy_build_to(H, s, with_lmax, MG_MAX_LEVELS);
}

hv_status hv__mg_hierarchy_build_to(mg_hierarchy *H, const hv_setup *s, int with_lmax,
                                    int max_levels)
{
    memset(H, 0, sizeof *H);
    H->dim = s->p.dim;
    H->alpha = s->p.alpha;
    hv_status st = HV_OK;

    mg_level *L = &H->lv[0];
    for (int b = 0; b < 3; b++) {
        L->n[b] = b < H->dim ? s->p.n[b] : 1;
        L->c[b] = b < H->dim ? s->p.beta / (s->p.h * s->p.h) : 0.0;
    }
    double hh[3] = {s->p.h, s->p.h, s->p.h};
    H->nlev = 1;
    for (;;) {
        L = &H->lv[H->nlev - 1];
        L->count = (size_t)L->n[0] * L->n[1] * L->n[2];
        L->sy = (size_t)L->n[0];
        L->sz = (size_t)L->n[0] * L->n[1];
        if (H->nlev == 1) {
            L->plain = s->p.solid == NULL;
            if (!L->plain && (st = level_from_mask(H, L, s->p.solid)))
                goto fail;
        } else if ((st = level_coarsen(H, &H->lv[H->nlev - 2], L))) {
            goto fail;
        }
        if (with_lmax)
            L->lmax = estimate_lmax(H, L);
        /* Semi-coarsen: halve the axes of finest spacing that still have > 2 cells. */
        double hmin = INFINITY;
        for (int b = 0; b < H->dim; b++)
            if (L->n[b] > 2 && hh[b] < hmin)
                hmin = hh[b];
        int any = 0;
        for (int b = 0; b < H->dim; b++) {
            L->coarsen[b] = L->n[b] > 2 && hh[b] <= hmin * 1.01;
            any |= L->coarsen[b];
        }
        if (!any || L->count <= MG_BOTTOM_CELLS || H->nlev >= max_levels) {
            for (int b = 0; b < 3; b++)
                L->coarsen[b] = 0;
            break;
        }
        mg_level *C = &H->lv[H->nlev];
        for (int b = 0; b < 3; b++) {
            C->n[b] = L->coarsen[b] ? (L->n[b] + 1) / 2 : L->n[b];
            C->c[b] = L->coarsen[b] ? L->c[b] / 4 : L->c[b];
            if (L->coarsen[b])
                hh[b] *= 2;
        }
        H->nlev++;
    }
    if (H->alpha == 0 && max_levels == MG_MAX_LEVELS &&
        (st = level_regions(H, &H->lv[H->nlev - 1])))
        goto fail;
    return HV_OK;
fail:
    hv__mg_hierarchy_free(H);
    return st;
}

/* Traffic model of one outer iteration, in bytes. A red-black sweep streams u
 * and f and writes u: once per colour, or once in all on plain 3D levels where
 * the two colours are fused plane by plane. A Jacobi or Chebyshev step computes
 * the residual (reads u, f, writes r) and then updates d and u (reads r, d, u,
 * writes d, u). Weighted levels read their coefficients (a, w, 1/diag) in every
 * pass. The residual reads u, f and writes r; restriction reads r and writes the
 * coarse f; prolongation reads the coarse u and updates u. The double defect
 * correction reads x and f and writes the float right-hand side, then adds the
 * correction into x.
 *
 * With `fused` (the CPU backend) fusable levels (plain 3D, mg_internal.h: mg_level_fusable)
 * move less: the first sweep from zero reads f and writes u (no clearing pass),
 * the last pre-sweep also forms the residual and restricts it (the fine residual
 * is never stored: only the coarse f is written), the first post-sweep also adds
 * the prolongation (reads the coarse u), and other levels clear u before the
 * cycle (a write). A binary level (the fine level of a mask) reads only 1/diag
 * there, the smoother and residual taking the plain stencil (mg_rows.c). The correction of a plain fine level is one pass: reads x,
 * the correction and f, writes x and the next float right-hand side. */
static void model(const mg_level *lv, int nlev, int dim, hv_smoother smoother, int pre, int post,
                  int pcg, int fused, hv_solver_stats *st)
{
    st->levels = nlev;
    double bytes = 0;
    size_t mem = 0;
    for (int l = 0; l < nlev; l++) {
        const mg_level *L = &lv[l];
        memcpy(st->n[l], L->n, sizeof st->n[l]);
        st->plain[l] = L->plain;
        double cells = (double)L->count;
        double coef = L->plain ? 0 : fused && L->binary ? 4.0 : 4.0 * (2 + dim);
        /* the CPU fuses every 3D level's sweeps, the device plain levels' */
        int rb_fused =
            (L->plain || fused) && dim == 3 && L->n[2] >= 3 && L->n[1] >= 8 && L->n[0] <= 4096;
        double sweep = smoother == HV_SMOOTH_RBGS ? (rb_fused ? 1 : 2) * (12 + coef) : 32 + coef;
        int steps = smoother == HV_SMOOTH_CHEBYSHEV ? 2 * (pre + post) : pre + post;
        mem += L->count * (3 + (smoother != HV_SMOOTH_RBGS)) * sizeof(float);
        if (!L->plain)
            mem += L->count * (2 + dim) * sizeof(float);
        if (l + 1 == nlev) {
            bytes += cells * 8 * 40; /* bottom CG: a few dozen iterations on a tiny level */
            continue;
        }
        double coarse = (double)lv[l + 1].count;
        if (!fused) {
            bytes += cells * (steps * sweep + (12 + coef) + 4 + 8) + cells / 2;
            continue;
        }
        int whole = smoother == HV_SMOOTH_RBGS && !pcg && pre >= 1 && post >= 1 && rb_fused &&
                    L->n[0] <= 4096;
        if (whole) {
            int zero_sweep = pre >= 2;
            bytes += cells * (zero_sweep ? 8 : 4 + 12) + cells * 12 * (pre - 1 - zero_sweep);
            bytes += cells * 12 + coarse * 4; /* last pre-sweep + residual + restriction */
            int prolong_fused = lv[l + 1].plain && lv[l + 1].n[0] <= 4096;
            bytes += prolong_fused ? cells * 12 + coarse * 4 : cells * (8 + 12) + coarse * 4;
            bytes += cells * 12 * (post - 1);
        } else {
            bytes += cells * (4 + steps * sweep + (12 + coef) + 4 + 8) + coarse * 8;
            if (smoother != HV_SMOOTH_RBGS)
                bytes += cells * 4 * 2; /* clearing d before each smoothing phase */
        }
    }
    double n0 = (double)lv[0].count;
    st->bytes_per_cycle = fused && !pcg ? bytes : 0;
    if (fused && !pcg) /* x + e and f - A x in one pass; with solid cells two (mg_backend.c) */
        bytes += n0 * (lv[0].plain ? 8 + 4 + 8 + 8 + 4 : (8 + 4 + 4 + 8) + (8 + 8 + 4 + 4));
    else if (fused) /* CPU PCG (mg_backend.c): q = A p with p.q; x, r, f; r.z; p (float) */
        bytes += n0 * ((4 + 4 + 8) + (8 + 8 + 4 + 8 + 8 + 8 + 4) + (8 + 4) + (4 + 4 + 4));
    else
        bytes += n0 * (8 + 8 + 4 + 8 + 4 + 8);
    /* double work on the fine level: the residual; PCG also A p (double) and p
     * (float on the CPU, double on the device, with z) */
    mem += lv[0].count * (pcg ? (fused ? 2 * sizeof(double) + sizeof(float) : 4 * sizeof(double))
                              : sizeof(double));
    st->bytes_per_iteration = bytes;
    st->memory_bytes = mem;
}

void hv__mg_model_stats(const mg_level *lv, int nlev, int dim, hv_smoother smoother, int pre,
                        int post, int pcg, hv_solver_stats *st)
{
    model(lv, nlev, dim, smoother, pre, post, pcg, 0, st);
}

void hv__mg_model_stats_cpu(const mg_level *lv, int nlev, int dim, hv_smoother smoother, int pre,
                            int post, int pcg, hv_solver_stats *st)
{
    model(lv, nlev, dim, smoother, pre, post, pcg, 1, st);
}
