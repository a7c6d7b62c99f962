/*
 * Stages 2-6 of the signed heat method on a grid (docs/METHOD.md, "Signed
 * heat method", "Pipeline"): splat the surface's vector area, diffuse it,
 * normalize it on cell faces, solve the Poisson equation and shift the zero
 * set onto the surface; on the CPU here, on an OpenCL device in sdf_cl.c.
 * sdf.c runs them where the heat method decides the sign or gives the
 * distance itself.
 */
#include "sdf_cl.h"
#include "sdf_internal.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* Faces whose diffused vector is below this many times the solver's error
 * bound count as decayed. */
#define SDF_NOISE_FACTOR 4.0

/* Face vector at the face between cells lo = c - s[a] and c, for the signed
 * (three components Y[0..2]) or unsigned (Y[0] scalar, gradient) field. */
static inline void face_vec(const float *const *Y, int unsig, const int n[3], const size_t s[3],
                            double h, int a, size_t c, const int idx[3], double v[3])
{
    size_t lo = c - s[a];
    if (!unsig) {
        for (int b = 0; b < 3; b++)
            v[b] = 0.5 * ((double)Y[b][c] + Y[b][lo]);
        return;
    }
    const float *u = Y[0];
    v[a] = ((double)u[c] - u[lo]) / h;
    for (int b = 0; b < 3; b++) {
        if (b == a)
            continue;
        /* Central differences at both cells, one-sided (mirror) at walls. */
        double g = 0;
        for (int side = 0; side < 2; side++) {
            size_t cc = side ? c : lo;
            int ib = idx[b];
            size_t up = ib < n[b] - 1 ? cc + s[b] : cc, dn = ib > 0 ? cc - s[b] : cc;
            g += ((double)u[up] - u[dn]) / (2 * h);
        }
        v[b] = 0.5 * g;
    }
}

/* Normalized flux through the face (axis a, between c - s[a] and c) from the
 * first level whose field is above its noise threshold; 0 if none. */
static inline double face_flux(float ***Y, int nlev, const double *tau, int unsig, const int n[3],
                               const size_t s[3], double h, int a, size_t c, const int idx[3],
                               int *dead)
{
    for (int k = 0; k < nlev; k++) {
        double v[3];
        face_vec((const float *const *)Y[k], unsig, n, s, h, a, c, idx, v);
        double len = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        if (len > tau[k]) {
            *dead = 0;
            return unsig ? -v[a] / len : v[a] / len;
        }
    }
    *dead = 1;
    return 0.0;
}

/* rhs = -div X for the Poisson solve (alpha = 0: -Lap phi = -div X). */
static size_t build_rhs(float ***Y, int nlev, const double *tau, int unsig, const hv_grid *g,
                        float *rhs)
{
    const int *n = g->n;
    const size_t s[3] = {1, (size_t)n[0], (size_t)n[0] * n[1]};
    const double h = g->h;
    size_t dead_total = 0;
#pragma omp parallel for collapse(2) schedule(static) reduction(+ : dead_total)
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                int idx[3] = {i, j, k};
                size_t c = (size_t)i + s[1] * j + s[2] * k;
                double div = 0;
                for (int a = 0; a < 3; a++) {
                    int dead;
                    if (idx[a] > 0) {
                        div -= face_flux(Y, nlev, tau, unsig, n, s, h, a, c, idx, &dead);
                        dead_total += dead;
                    }
                    if (idx[a] < n[a] - 1) {
                        int up[3] = {i, j, k};
                        up[a]++;
                        div += face_flux(Y, nlev, tau, unsig, n, s, h, a, c + s[a], up, &dead);
                    }
                }
                rhs[c] = (float)(-div / h);
            }
    return dead_total;
}

static double norm2(const float *v, size_t count)
{
    double acc = 0;
#pragma omp parallel for reduction(+ : acc) schedule(static)
    for (size_t c = 0; c < count; c++)
        acc += (double)v[c] * v[c];
    return acc;
}

/* The fields of stages 2-6, freed on every exit. */
typedef struct heat_work {
    const hv_quad *q;
    float *Y0[3];
    float **Y[9]; /* Y[level][component] */
    float *Ybuf;
    float *rhs;
    hv_solver *solver;
    hv_solver *heat; /* the level-0 diffusion, kept for the local shift */
} heat_work;

static void heat_work_free(heat_work *w)
{
    for (int b = 0; b < 3; b++)
        hv_free(w->Y0[b]);
    for (int k = 0; k < 9; k++)
        free(w->Y[k]);
    hv_free(w->Ybuf);
    hv_free(w->rhs);
    hv_solver_destroy(&w->solver);
    hv_solver_destroy(&w->heat);
}

/* AUTO prefers FFTW on plain boxes; fall back to multigrid when this build
 * has no FFTW backend. FFTW transforms in single precision when the
 * tolerance allows it (float transforms reach relres ~4e-7). */
static hv_status solver_create(hv_solver **s, const hv_problem *p, const hv_solver_opts *so_in)
{
    hv_solver_opts so = *so_in;
    so.fftw_double = so.tol < 1e-6;
    hv_status st = hv_solver_create(s, p, &so);
    if (st == HV_ERR_UNSUPPORTED && so.backend == HV_BACKEND_AUTO) {
        so.backend = HV_BACKEND_MG;
        st = hv_solver_create(s, p, &so);
    }
    return st;
}

static hv_status stage(double f, const char *name) { return hv__progress(f, name); }

double hv__sdf_interp(const hv_grid *g, const float *v, const double x[3])
{
    size_t c0, step[3];
    double wt[8], val = 0;
    hv__trilinear(g, x, &c0, step, wt);
    for (int q = 0; q < 8; q++)
        val +=
            wt[q] * v[c0 + (q & 1 ? step[0] : 0) + (q & 2 ? step[1] : 0) + (q & 4 ? step[2] : 0)];
    return val;
}

/* Adds ncomp values per quadrature point (vals[vstride * p + b], or the area
 * when vals is NULL) / h^3 trilinearly to out[b]. Each thread owns a slab of
 * z-planes and takes the corners of every point that fall in it: no atomics,
 * and every cell sums its points in the same order whatever the thread
 * count. */
void hv__sdf_splat(const hv_grid *g, const hv_quad *q, int ncomp, const double *vals, int vstride,
                   float *const *out)
{
    const double inv_h3 = 1.0 / (g->h * g->h * g->h);
    const size_t plane = (size_t)g->n[0] * g->n[1];
    const int nz = g->n[2];
    if (!vals) {
        vals = q->area;
        vstride = 1;
        ncomp = 1;
    }
#pragma omp parallel
    {
        int tid = 0, nt = 1;
#ifdef _OPENMP
        tid = omp_get_thread_num();
        nt = omp_get_num_threads();
#endif
        const int z0 = (int)((long long)nz * tid / nt), z1 = (int)((long long)nz * (tid + 1) / nt);
        const double zs = 1.0 / g->h, zo = g->origin[2];
        for (size_t p = 0; p < q->count; p++) {
            /* Cheap reject on z before the weights. */
            double sz = (q->x[3 * p + 2] - zo) * zs - 0.5;
            int kz = sz <= 0 ? 0 : (int)sz;
            if (kz >= nz)
                kz = nz - 1;
            if (kz + 1 < z0 || kz >= z1)
                continue;
            size_t c0, step[3];
            double wt[8];
            hv__trilinear(g, q->x + 3 * p, &c0, step, wt);
            const int kb = (int)(c0 / plane), kt = kb + (step[2] ? 1 : 0);
            const double *v = vals + (size_t)vstride * p;
            for (int k = 0; k < 8; k++) {
                int z = k & 4 ? kt : kb;
                if (wt[k] == 0 || z < z0 || z >= z1)
                    continue;
                size_t c =
                    c0 + (k & 1 ? step[0] : 0) + (k & 2 ? step[1] : 0) + (k & 4 ? step[2] : 0);
                const double s = wt[k] * inv_h3;
                for (int b = 0; b < ncomp; b++)
                    out[b][c] += (float)(s * v[b]);
            }
        }
    }
}

/* Local zero-set correction, on the heat method's grid g. The heat method's
 * phi is not constant on the surface (X is not exactly a gradient: about
 * 0.1-0.4 voxel rms on a torus or the bunny), so one global shift leaves the
 * zero set off by up to a voxel in places. The residual
 * phi(x_q) at the surface samples is extended into the volume by normalized
 * convolution with the same heat kernel,
 *     c = K*(a r) / K*(a),   K = (I - t Lap)^-1,
 * and subtracted. It uses positions only, so flipped or duplicated faces do
 * not matter; where K*(a) has decayed below solver accuracy c fades to 0.
 * (A pointwise correction by phi at each cell's closest surface point, within
 * 3 voxels, was tried for the exact magnitude: inside-IoU beyond 1 voxel
 * 0.99824 against 0.99946 on bun_zipper_res4 at 64^3, which has holes.) */
static hv_status local_shift(heat_work *w, const hv_grid *g, const hv_sdf_opts *o, hv_sdf_stats *S)
{
    const size_t count = hv_grid_count(g);
    float *phi = g->v;
    hv_status st = HV_OK;
    double *res = malloc(w->q->count * sizeof *res);
    float *f0 = hv_calloc(count, sizeof(float)), *f1 = hv_calloc(count, sizeof(float));
    float *num = hv_malloc(count * sizeof(float)), *den = hv_malloc(count * sizeof(float));
    if (!res || !f0 || !f1 || !num || !den) {
        st = hv__error(HV_ERR_NOMEM, "sdf: out of memory for the zero-set correction (%zu cells)",
                       count);
        goto out;
    }
#pragma omp parallel for schedule(static)
    for (size_t p = 0; p < w->q->count; p++)
        res[p] = w->q->area[p] * hv__sdf_interp(g, phi, w->q->x + 3 * p);
    hv__sdf_splat(g, w->q, 1, res, 1, &f0);
    hv__sdf_splat(g, w->q, 1, NULL, 1, &f1);
    if (!w->heat) {
        hv_solver_opts so;
        hv_solver_opts_default(&so);
        so.backend = o->backend;
        so.tol = o->diffuse_tol;
        so.max_iter = 100;
        hv_problem pb = {3, {g->n[0], g->n[1], g->n[2]}, g->h, NULL, 1.0, S->t};
        if ((st = solver_create(&w->heat, &pb, &so)))
            goto out;
    }
    hv_solve_info info;
    if ((st = hv_solver_solve(w->heat, f0, num, &info)))
        goto out;
    S->diffuse_iterations += info.iterations;
    if ((st = hv_solver_solve(w->heat, f1, den, &info)))
        goto out;
    S->diffuse_iterations += info.iterations;
    hv_solver_destroy(&w->heat);
    /* Noise bound of den as for the normals (||e|| <= relres ||f||); the
     * correction is tapered to zero between 1e3 and 1e2 times it. */
    const double tau = fmax(info.relres, o->diffuse_tol) * sqrt(norm2(f1, count));
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < count; c++) {
        double d = den[c];
        if (!(d > 100 * tau))
            continue;
        double taper = d >= 1000 * tau ? 1.0 : (d - 100 * tau) / (900 * tau);
        phi[c] -= (float)(taper * num[c] / d);
    }
    double rms = 0, asum = 0;
#pragma omp parallel for reduction(+ : rms, asum) schedule(static)
    for (size_t p = 0; p < w->q->count; p++) {
        double v = hv__sdf_interp(g, phi, w->q->x + 3 * p);
        rms += w->q->area[p] * v * v;
        asum += w->q->area[p];
    }
    S->surface_rms_after = sqrt(rms / asum) / g->h;
out:
    hv_solver_destroy(&w->heat);
    free(res);
    hv_free(f0), hv_free(f1), hv_free(num), hv_free(den);
    return st;
}

/* The common case of build_rhs (one level, signed field), each face once:
 * F[a][c] = normalized flux through the face between c - s[a] and c (0 on
 * the walls), then rhs = -div F. F may alias the diffused Y0 buffers. */
static size_t build_rhs1(float *const *Y, double tau, const hv_grid *g, float *const *F, float *rhs)
{
    const int *n = g->n;
    const size_t s[3] = {1, (size_t)n[0], (size_t)n[0] * n[1]};
    /* Faces carry the mean of two cells; compare the sum with 2 tau. */
    const float tau2 = (float)(4 * tau * tau);
    size_t dead = 0;
    const float *Yx = Y[0], *Yy = Y[1], *Yz = Y[2];
#pragma omp parallel for collapse(2) schedule(static) reduction(+ : dead)
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++) {
            const size_t row = s[1] * j + s[2] * k;
            for (int a = 0; a < 3; a++) {
                float *Fa = F[a] + row;
                if ((a == 1 && j == 0) || (a == 2 && k == 0)) {
                    for (int i = 0; i < n[0]; i++)
                        Fa[i] = 0;
                    continue;
                }
                const ptrdiff_t off = (ptrdiff_t)s[a];
                const float *ya = Y[a] + row;
                const float *x0 = Yx + row, *y0 = Yy + row, *z0 = Yz + row;
                int i0 = a == 0 ? 1 : 0;
                if (a == 0)
                    Fa[0] = 0;
                size_t dl = 0;
                for (int i = i0; i < n[0]; i++) {
                    float vx = x0[i] + x0[i - off], vy = y0[i] + y0[i - off],
                          vz = z0[i] + z0[i - off];
                    float l2 = vx * vx + vy * vy + vz * vz;
                    float va = ya[i] + ya[i - off];
                    int live = l2 > tau2;
                    Fa[i] = live ? va / sqrtf(l2) : 0.0f;
                    dl += !live;
                }
                dead += dl;
            }
        }
    const float inv_h = (float)(1.0 / g->h);
#pragma omp parallel for collapse(2) schedule(static)
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++) {
            const size_t row = s[1] * j + s[2] * k;
            const float *fx = F[0] + row, *fy = F[1] + row, *fz = F[2] + row;
            const int yup = j < n[1] - 1, zup = k < n[2] - 1;
            float *r = rhs + row;
            for (int i = 0; i < n[0]; i++) {
                float div = (i < n[0] - 1 ? fx[i + 1] : 0.0f) - fx[i];
                div += (yup ? fy[i + s[1]] : 0.0f) - fy[i];
                div += (zup ? fz[i + s[2]] : 0.0f) - fz[i];
                r[i] = -div * inv_h;
            }
        }
    return dead;
}

hv_status hv__sdf_upsample(const hv_grid *gh, const float *v, const hv_grid *g, float *out)
{
    int *base[3] = {NULL, NULL, NULL};
    float *frac[3] = {NULL, NULL, NULL};
    size_t step[3] = {1, (size_t)gh->n[0], (size_t)gh->n[0] * gh->n[1]};
    hv_status st = HV_OK;
    for (int a = 0; a < 3; a++) {
        base[a] = malloc((size_t)g->n[a] * sizeof(int));
        frac[a] = malloc((size_t)g->n[a] * sizeof(float));
        if (!base[a] || !frac[a]) {
            st = hv__error(HV_ERR_NOMEM, "sdf: out of memory");
            goto out;
        }
        for (int i = 0; i < g->n[a]; i++) {
            double x = g->origin[a] + (i + 0.5) * g->h;
            double s = (x - gh->origin[a]) / gh->h - 0.5;
            int i0 = (int)floor(s), nh = gh->n[a];
            double f = s - i0;
            if (nh == 1 || s <= 0)
                i0 = 0, f = 0;
            else if (i0 >= nh - 1)
                i0 = nh - 2, f = 1; /* past the last centre: its value, as hv__trilinear clamps */
            base[a][i] = i0;
            frac[a][i] = (float)f;
        }
    }
#pragma omp parallel for collapse(2) schedule(static)
    for (int k = 0; k < g->n[2]; k++)
        for (int j = 0; j < g->n[1]; j++) {
            const float fz = frac[2][k], fy = frac[1][j];
            const size_t sz = gh->n[2] > 1 ? step[2] : 0, sy = gh->n[1] > 1 ? step[1] : 0;
            const float *p00 = v + (size_t)base[2][k] * step[2] + (size_t)base[1][j] * step[1];
            const float *p01 = p00 + sy, *p10 = p00 + sz, *p11 = p00 + sz + sy;
            const float w00 = (1 - fz) * (1 - fy), w01 = (1 - fz) * fy, w10 = fz * (1 - fy),
                        w11 = fz * fy;
            float *o = out + ((size_t)k * g->n[1] + j) * g->n[0];
            const int sx = gh->n[0] > 1;
            for (int i = 0; i < g->n[0]; i++) {
                const int b = base[0][i];
                const float fx = frac[0][i];
                float lo = w00 * p00[b] + w01 * p01[b] + w10 * p10[b] + w11 * p11[b];
                float hi =
                    w00 * p00[b + sx] + w01 * p01[b + sx] + w10 * p10[b + sx] + w11 * p11[b + sx];
                o[i] = lo + fx * (hi - lo);
            }
        }
out:
    for (int a = 0; a < 3; a++) {
        free(base[a]);
        free(frac[a]);
    }
    return st;
}

/* 2. Splat the surface's vector area (unsigned: its area) onto the grid. */
static hv_status heat_splat(heat_work *w, const hv_grid *gh, int unsig)
{
    const size_t hcount = hv_grid_count(gh);
    const int ncomp = unsig ? 1 : 3;
    for (int b = 0; b < ncomp; b++)
        if (!(w->Y0[b] = hv_calloc(hcount, sizeof(float))))
            return hv__error(HV_ERR_NOMEM, "sdf: out of memory for the surface field (%zu cells)",
                             hcount);
    if (unsig)
        hv__sdf_splat(gh, w->q, 1, NULL, 1, w->Y0);
    else
        hv__sdf_splat(gh, w->q, 3, w->q->w, 3, w->Y0);
    return HV_OK;
}

/* 3. Diffuse: one backward-Euler step per level (times S->t 16^k), the
 * components sharing a solver; tau[k] the noise threshold of level k. With
 * the local shift the level-0 solver stays in w->heat. */
static hv_status heat_diffuse(heat_work *w, const hv_grid *gh, int nlev, int unsig,
                              const hv_sdf_opts *o, const hv_solver_opts *so, double tau[9],
                              hv_sdf_stats *S)
{
    double tt = hv_now();
    const size_t hcount = hv_grid_count(gh);
    const int ncomp = unsig ? 1 : 3;
    const int keep_heat = !unsig && o->local_shift;
    hv_status st;
    w->Ybuf = hv_malloc((size_t)nlev * ncomp * hcount * sizeof(float));
    if (!w->Ybuf)
        return hv__error(HV_ERR_NOMEM, "sdf: out of memory for %d diffused fields of %zu cells",
                         nlev * ncomp, hcount);
    double f2 = 0;
    for (int b = 0; b < ncomp; b++)
        f2 += norm2(w->Y0[b], hcount);
    for (int k = 0; k < nlev; k++) {
        if (!(w->Y[k] = malloc(3 * sizeof(float *))))
            return hv__error(HV_ERR_NOMEM, "sdf: out of memory");
        for (int b = 0; b < ncomp; b++)
            w->Y[k][b] = w->Ybuf + ((size_t)k * ncomp + b) * hcount;
        double t = S->t * pow(16.0, k);
        hv_problem pb = {3, {gh->n[0], gh->n[1], gh->n[2]}, gh->h, NULL, 1.0, t};
        if ((st = stage(0.1 + 0.5 * k / nlev, "diffuse")))
            return st;
        if ((st = solver_create(&w->solver, &pb, so)))
            return st;
        for (int b = 0; b < ncomp; b++) {
            hv_solve_info info;
            if ((st = hv_solver_solve(w->solver, w->Y0[b], w->Y[k][b], &info)))
                return st;
            S->diffuse_iterations += info.iterations;
            S->diffuse_relres = fmax(S->diffuse_relres, info.relres);
            S->backend = info.backend;
        }
        if (k == 0 && keep_heat) {
            w->heat = w->solver;
            w->solver = NULL;
        } else {
            hv_solver_destroy(&w->solver);
        }
        /* ||e||_2 <= ||r||_2 <= relres ||f||_2 since (I - t Lap) >= I; for the
         * unsigned gradient the bound grows by 2/h per component. */
        double bound = fmax(S->diffuse_relres, o->diffuse_tol) * sqrt(f2);
        tau[k] = SDF_NOISE_FACTOR * bound * (unsig ? 2.0 * sqrt(3.0) / gh->h : 1.0);
    }
    S->t_diffuse = hv_now() - tt;
    return HV_OK;
}

/* 4. Normalize on faces, divergence into w->rhs; the splat and the diffused
 * fields are freed. */
static hv_status heat_normalize(heat_work *w, const hv_grid *gh, int nlev, int unsig,
                                const double tau[9], hv_sdf_stats *S)
{
    hv_status st;
    if ((st = stage(0.6, "normalize")))
        return st;
    double tt = hv_now();
    const size_t hcount = hv_grid_count(gh);
    if (!(w->rhs = hv_malloc(hcount * sizeof(float))))
        return hv__error(HV_ERR_NOMEM, "sdf: out of memory for the divergence (%zu cells)", hcount);
    if (nlev == 1 && !unsig)
        S->dead_faces = build_rhs1(w->Y[0], tau[0], gh, w->Y0, w->rhs);
    else
        S->dead_faces = build_rhs(w->Y, nlev, tau, unsig, gh, w->rhs);
    for (int b = 0; b < (unsig ? 1 : 3); b++) {
        hv_free(w->Y0[b]);
        w->Y0[b] = NULL;
    }
    hv_free(w->Ybuf);
    w->Ybuf = NULL;
    S->t_normalize = hv_now() - tt;
    return HV_OK;
}

/* 5. Poisson: phi (gh->v) from the divergence, with the diffusion's solver
 * options but the Poisson tolerance. */
static hv_status heat_poisson(heat_work *w, hv_grid *gh, const hv_sdf_opts *o,
                              const hv_solver_opts *diffuse_so, hv_sdf_stats *S)
{
    hv_status st;
    if ((st = stage(0.65, "poisson")))
        return st;
    double tt = hv_now();
    hv_problem pb = {3, {gh->n[0], gh->n[1], gh->n[2]}, gh->h, NULL, 0.0, 1.0};
    hv_solver_opts so = *diffuse_so;
    so.tol = o->poisson_tol;
    if ((st = solver_create(&w->solver, &pb, &so)))
        return st;
    hv_solve_info info;
    if ((st = hv_solver_solve(w->solver, w->rhs, gh->v, &info)))
        return st;
    S->poisson_iterations = info.iterations;
    S->poisson_relres = info.relres;
    S->backend = info.backend;
    hv_solver_destroy(&w->solver);
    hv_free(w->rhs);
    w->rhs = NULL;
    S->t_poisson = hv_now() - tt;
    return HV_OK;
}

/* 6. Shift: area-weighted mean of phi at the surface samples to zero; then,
 * with o->local_shift (signed), the zero-set correction. */
static hv_status heat_shift(heat_work *w, hv_grid *gh, const hv_sdf_opts *o, int unsig,
                            hv_sdf_stats *S)
{
    hv_status st;
    if ((st = stage(0.8, "shift")))
        return st;
    double tt = hv_now();
    const size_t hcount = hv_grid_count(gh);
    float *phi = gh->v;
    double num = 0, den = 0, rms = 0;
#pragma omp parallel for reduction(+ : num, den, rms) schedule(static)
    for (size_t p = 0; p < w->q->count; p++) {
        double val = hv__sdf_interp(gh, phi, w->q->x + 3 * p);
        num += w->q->area[p] * val;
        den += w->q->area[p];
        rms += w->q->area[p] * val * val;
    }
    S->shift = den > 0 ? num / den : 0;
    S->surface_rms_before = sqrt(fmax(0.0, rms / den - S->shift * S->shift)) / gh->h;
    const float sh = (float)S->shift;
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < hcount; c++)
        phi[c] -= sh;
    S->surface_rms_after = S->surface_rms_before;
    if (o->local_shift && !unsig) {
        if ((st = local_shift(w, gh, o, S)))
            return st;
    }
    S->t_shift = hv_now() - tt;
    return HV_OK;
}

hv_status hv__sdf_heat(const hv_quad *q, hv_grid *gh, int nlev, int unsig, const hv_sdf_opts *o,
                       hv_sdf_stats *S)
{
    heat_work W, *w = &W;
    memset(w, 0, sizeof *w);
    w->q = q;
    hv_status st = HV_OK;
    double tt = hv_now();
    /* Backend opencl: stages 2-6 keep their fields on the device (sdf_cl.c). */
    if (o->backend == HV_BACKEND_OPENCL) {
        st = hv__sdf_heat_cl(q, gh, nlev, unsig, o, S);
        goto out;
    }
    if ((st = heat_splat(w, gh, unsig)))
        goto out;
    S->t_splat += hv_now() - tt;
    double tau[9] = {0};
    hv_solver_opts so;
    hv_solver_opts_default(&so);
    so.backend = o->backend;
    so.tol = o->diffuse_tol;
    so.max_iter = 100;
    st = heat_diffuse(w, gh, nlev, unsig, o, &so, tau, S);
    if (!st)
        st = heat_normalize(w, gh, nlev, unsig, tau, S);
    if (!st)
        st = heat_poisson(w, gh, o, &so, S);
    if (!st)
        st = heat_shift(w, gh, o, unsig, S);
out:
    heat_work_free(w);
    return st;
}
