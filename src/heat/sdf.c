/*
 * The signed heat method on a cell-centred grid (Feng & Crane 2024), with the
 * grid-specific choices described in docs/METHOD.md ("Discretization",
 * "Signed heat method"):
 *   - t tied to the grid, t = (t_scale h)^2, not to the mesh's edge lengths;
 *   - the normalized field lives on cell faces (MAC) and the Poisson operator
 *     is exactly div(grad), which keeps the zero set in place;
 *   - far from the surface the diffused field decays like e^{-r/sqrt(t)} below
 *     solver accuracy; faces where it has are either served by a longer
 *     diffusion (far levels, t x16 each) or left with X = 0, where phi is then
 *     harmonic and keeps the sign of its surroundings (maximum principle);
 *   - by default |phi| is replaced by the exact distance to the triangles and
 *     the heat method supplies only the sign, its robust part.
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

/* Estimated bytes per cell of the whole pipeline, for hv_check_dims. */
#define SDF_BYTES_PER_CELL 96
/* Faces whose diffused vector is below this many times the solver's error
 * bound count as decayed. */
#define SDF_NOISE_FACTOR 4.0
/* Rasterization radius of the exact distance, in voxels. */
#define SDF_EXACT_BAND 2.0
/* Narrow bands up to this many voxels are rasterized whole. */
#define SDF_RASTER_MAX 4.0

void hv_sdf_opts_default(hv_sdf_opts *o)
{
    memset(o, 0, sizeof *o);
    o->res = 128;
    o->pad = 4;
    o->round_to = 8;
    o->magnitude = HV_SDF_EXACT;
    o->t_scale = 1.0;
    o->far_levels = -1;
    o->local_shift = 1;
    o->max_hole = 0.5;
    o->near_sign = 1.0;
    o->repair = HV_SDF_REPAIR_ALL;
    o->backend = HV_BACKEND_AUTO;
    o->diffuse_tol = 0; /* auto, see resolve_auto */
    o->poisson_tol = 0;
    o->heat_coarsen = 0;
}

/* Tolerances. Where the heat method only decides the sign (exact magnitude,
 * signed), phi's value never reaches the output: what matters is where it
 * changes sign, and that moves by about the solve error over |grad phi| = 1,
 * far below a voxel at these tolerances. The diffused field is normalized, so
 * its relative error stays at the tolerance where it is above the noise
 * threshold (faces below SDF_NOISE_FACTOR times the error bound count as
 * decayed, X = 0), and the local shift's reach follows it too: on
 * bun_zipper_res4 at 64^3 (holes) inside-IoU beyond 1 voxel was 0.99949 at
 * 1e-10, 0.99946 at 1e-6, 0.99868 at 1e-5. 1e-6 (heat) and 1e-4 (Poisson)
 * let FFTW use single-precision transforms (relres ~6e-7 for the heat solves,
 * ~1e-5 for the Poisson solve) and multigrid stop after a few cycles. Where phi is the
 * output (HV_SDF_HEAT, unsigned), the tight tolerances stay. Every backend
 * gets the same tolerances. The heat grid: coarsening by 2 only on large
 * grids, where the solves would otherwise dominate; within a voxel of the
 * surface the sign then comes from pseudonormals where the mesh is clean
 * (on the bunny at 256^3, 73 of 13.6 M cells change sign against the full-
 * resolution heat method, all near its filled holes, where the winding
 * number sides with the coarse grid in 43 of them). */
#define SDF_SIGN_TOL 1e-6
#define SDF_SIGN_POISSON_TOL 1e-4
#define SDF_COARSEN_CELLS ((size_t)1 << 22)
static void resolve_auto(hv_sdf_opts *o)
{
    const int sign_only = o->magnitude == HV_SDF_EXACT && !o->unsigned_distance;
    if (o->diffuse_tol == 0)
        o->diffuse_tol = sign_only ? SDF_SIGN_TOL : 1e-10;
    if (o->poisson_tol == 0)
        o->poisson_tol = sign_only ? SDF_SIGN_POISSON_TOL : 1e-8;
}

static int heat_factor(const hv_sdf_opts *o, const int n[3])
{
    if (o->magnitude != HV_SDF_EXACT || o->unsigned_distance)
        return 1;
    if (o->heat_coarsen > 0)
        return o->heat_coarsen;
    return (size_t)n[0] * n[1] * n[2] > SDF_COARSEN_CELLS ? 2 : 1;
}

static hv_status check_opts(const hv_sdf_opts *o)
{
    if (!(o->voxel_size >= 0) || !isfinite(o->voxel_size))
        return hv__error(HV_ERR_INVALID_ARG, "sdf: voxel size must be positive and finite, got %g",
                         o->voxel_size);
    if (o->voxel_size == 0 && o->res <= 0)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: resolution must be positive, got %d", o->res);
    if (o->pad < 0)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: padding must be >= 0 cells, got %d", o->pad);
    if (!o->use_bbox && o->voxel_size == 0 && o->res <= 2 * o->pad)
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf: resolution %d leaves no cells inside a padding of %d on each side",
                         o->res, o->pad);
    if (o->round_to < 0 || o->round_to > 64)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: round_to must be in [0, 64], got %d",
                         o->round_to);
    if (!(o->t_scale > 0) || !isfinite(o->t_scale) || o->t_scale > 1e4)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: t scale must be in (0, 1e4], got %g",
                         o->t_scale);
    if (o->far_levels < -1 || o->far_levels > 8)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: far levels must be in [-1, 8], got %d",
                         o->far_levels);
    if (o->magnitude != HV_SDF_EXACT && o->magnitude != HV_SDF_HEAT)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: unknown magnitude mode %d", (int)o->magnitude);
    if (!(o->max_hole >= 0) || !isfinite(o->max_hole))
        return hv__error(HV_ERR_INVALID_ARG, "sdf: max hole size must be finite and >= 0, got %g",
                         o->max_hole);
    if (o->repair & ~(unsigned)(HV_SDF_REPAIR_ALL | HV_SDF_REPAIR_DOMED_CAPS))
        return hv__error(HV_ERR_INVALID_ARG, "sdf: unknown repair flags 0x%x", o->repair);
    if (!(o->diffuse_tol == 0 || (o->diffuse_tol >= 1e-12 && o->diffuse_tol < 1)) ||
        !(o->poisson_tol == 0 || (o->poisson_tol >= 1e-12 && o->poisson_tol < 1)))
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf: tolerances must be 0 (auto) or in [1e-12, 1), got %g and %g",
                         o->diffuse_tol, o->poisson_tol);
    if (o->heat_coarsen < 0 || o->heat_coarsen > 4)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: heat coarsening must be in [0, 4], got %d",
                         o->heat_coarsen);
    if (!(o->near_sign >= 0) || o->near_sign > 16)
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf: near-sign width must be in [0, 16] voxels, got %g", o->near_sign);
    if (o->sign != HV_SDF_SIGN_AUTO && o->sign != HV_SDF_SIGN_HEAT &&
        o->sign != HV_SDF_SIGN_WINDING)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: unknown sign source %d", (int)o->sign);
    if (o->sign == HV_SDF_SIGN_WINDING && o->magnitude == HV_SDF_EXACT && !o->unsigned_distance &&
        (o->repair & (HV_SDF_REPAIR_ORIENT | HV_SDF_REPAIR_OUTWARD)) !=
            (HV_SDF_REPAIR_ORIENT | HV_SDF_REPAIR_OUTWARD))
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf: the winding-number sign needs the repair's orientation steps "
                         "(a mesh as given may be oriented any way)");
    if (o->threads < 0 || o->threads > HV_MAX_THREADS)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: thread count must be in [0, %d], got %d",
                         HV_MAX_THREADS, o->threads);
    if (o->use_bbox) {
        for (int a = 0; a < 6; a++)
            if (!isfinite(o->bbox[a]))
                return hv__error(HV_ERR_INVALID_ARG,
                                 "sdf: bounding box coordinate %d is not finite", a);
        for (int a = 0; a < 3; a++)
            if (!(o->bbox[3 + a] > o->bbox[a]))
                return hv__error(HV_ERR_INVALID_ARG,
                                 "sdf: bounding box is empty along %c (%g to %g)", "xyz"[a],
                                 o -> bbox[a], o -> bbox[3 + a]);
    }
    return HV_OK;
}

/* Bounds of the vertices used by triangles; checks indices and finiteness. */
static hv_status used_bounds(const hv_mesh *m, double lo[3], double hi[3])
{
    if (!m || m->ntris == 0 || m->nverts == 0 || !m->tris || !m->verts)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: the mesh is empty (%zu vertices, %zu triangles)",
                         m ? m->nverts : 0, m ? m->ntris : 0);
    for (int a = 0; a < 3; a++)
        lo[a] = INFINITY, hi[a] = -INFINITY;
    for (size_t i = 0; i < 3 * m->ntris; i++) {
        uint32_t v = m->tris[i];
        if (v >= m->nverts)
            return hv__error(HV_ERR_INVALID_ARG, "sdf: triangle %zu uses vertex %u of %zu", i / 3,
                             v, m->nverts);
        const double *x = m->verts + 3 * (size_t)v;
        for (int a = 0; a < 3; a++) {
            if (!isfinite(x[a]))
                return hv__error(HV_ERR_NUMERIC, "sdf: vertex %u has a non-finite coordinate (%g)",
                                 v, x[a]);
            lo[a] = x[a] < lo[a] ? x[a] : lo[a];
            hi[a] = x[a] > hi[a] ? x[a] : hi[a];
        }
    }
    return HV_OK;
}

static int levels_for(const hv_sdf_opts *oin, const int n[3])
{
    hv_sdf_opts ro = *oin, *o = &ro;
    resolve_auto(o);
    if (o->far_levels >= 0)
        return 1 + o->far_levels;
    if (o->magnitude == HV_SDF_EXACT && !o->unsigned_distance)
        return 1;
    /* The field stays above the solver's error bound for roughly
     * r < sqrt(t) ln(1/tol) / 2 (measured margin); add levels until that
     * covers the block's diagonal. */
    double diag = sqrt((double)n[0] * n[0] + (double)n[1] * n[1] + (double)n[2] * n[2]);
    double reach = o->t_scale * 0.5 * log(1.0 / o->diffuse_tol);
    int L = 1;
    while (reach < diag && L < 9) {
        reach *= 4;
        L++;
    }
    return L;
}

hv_status hv_sdf_grid_for_mesh(const hv_mesh *m, const hv_sdf_opts *opts, int n[3], double *h,
                               double origin[3])
{
    hv_sdf_opts def;
    if (!opts) {
        hv_sdf_opts_default(&def);
        opts = &def;
    }
    if (!n || !h || !origin)
        return hv__error(HV_ERR_INVALID_ARG, "hv_sdf_grid_for_mesh: NULL output");
    hv_status st = check_opts(opts);
    double lo[3], hi[3];
    if (st || (st = used_bounds(m, lo, hi)))
        return st;
    if (opts->use_bbox) {
        const double *b = opts->bbox;
        double L = fmax(b[3] - b[0], fmax(b[4] - b[1], b[5] - b[2]));
        *h = opts->voxel_size > 0 ? opts->voxel_size : L / opts->res;
        for (int a = 0; a < 3; a++) {
            double c = ceil((b[3 + a] - b[a]) / *h - 1e-9);
            if (!(c < 1e9))
                return hv__error(HV_ERR_INVALID_ARG, "sdf: voxel size %g gives %g cells along %c",
                                 *h, c, "xyz"[a]);
            n[a] = c < 1 ? 1 : (int)c;
            origin[a] = b[a];
        }
    } else {
        double L = fmax(hi[0] - lo[0], fmax(hi[1] - lo[1], hi[2] - lo[2]));
        if (opts->voxel_size > 0)
            *h = opts->voxel_size;
        else if (L > 0)
            *h = L / (opts->res - 2 * opts->pad);
        else
            return hv__error(
                HV_ERR_INVALID_ARG,
                "sdf: the mesh has no extent (all vertices at one point); give a voxel size");
        int longest = (hi[0] - lo[0] == L) ? 0 : (hi[1] - lo[1] == L) ? 1 : 2;
        for (int a = 0; a < 3; a++) {
            double c = ceil((hi[a] - lo[a]) / *h - 1e-9) + 2.0 * opts->pad;
            if (!(c < 1e9))
                return hv__error(HV_ERR_INVALID_ARG, "sdf: voxel size %g gives %g cells along %c",
                                 *h, c, "xyz"[a]);
            n[a] = c < 1 ? 1 : (int)c;
            /* Extra padding for multigrid; the longest axis keeps --res exactly. */
            int r = opts->round_to > 1 ? opts->round_to : 1;
            if (r > 1 && !(opts->voxel_size == 0 && a == longest) && n[a] % r)
                n[a] += r - n[a] % r;
            origin[a] = 0.5 * (lo[a] + hi[a]) - 0.5 * n[a] * *h;
        }
    }
    int L = levels_for(opts, n);
    return hv_check_dims(3, n, *h, SDF_BYTES_PER_CELL + 12 * (size_t)L);
}

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

typedef struct sdf_work {
    hv_mesh *repaired;
    hv_quad q;
    float *Y0[3];
    float **Y[9]; /* Y[level][component] */
    float *Ybuf;
    float *rhs;
    float *dist;
    uint32_t *tri;
    hv_solver *solver;
    hv_solver *heat; /* the level-0 diffusion, kept for the local shift */
    hv_grid *g;      /* the output grid */
    hv_grid *gh;     /* the heat method's grid when it is not g */
} sdf_work;

static void work_free(sdf_work *w)
{
    hv_mesh_destroy(&w->repaired);
    hv__quad_free(&w->q);
    for (int b = 0; b < 3; b++)
        hv_free(w->Y0[b]);
    for (int k = 0; k < 9; k++)
        free(w->Y[k]);
    hv_free(w->Ybuf);
    hv_free(w->rhs);
    hv_free(w->dist);
    hv_free(w->tri);
    hv_solver_destroy(&w->solver);
    hv_solver_destroy(&w->heat);
    hv_grid_destroy(&w->g);
    hv_grid_destroy(&w->gh);
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

/* Trilinear interpolation of v at x. */
static double interp(const hv_grid *g, const float *v, const double x[3])
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
static void splat(const hv_grid *g, const hv_quad *q, int ncomp, const double *vals, int vstride,
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
static hv_status local_shift(sdf_work *w, const hv_grid *g, const hv_sdf_opts *o, hv_sdf_stats *S)
{
    const size_t count = hv_grid_count(g);
    float *phi = g->v;
    hv_status st = HV_OK;
    double *res = malloc(w->q.count * sizeof *res);
    float *f0 = hv_calloc(count, sizeof(float)), *f1 = hv_calloc(count, sizeof(float));
    float *num = hv_malloc(count * sizeof(float)), *den = hv_malloc(count * sizeof(float));
    if (!res || !f0 || !f1 || !num || !den) {
        st = hv__error(HV_ERR_NOMEM, "sdf: out of memory for the zero-set correction (%zu cells)",
                       count);
        goto out;
    }
#pragma omp parallel for schedule(static)
    for (size_t p = 0; p < w->q.count; p++)
        res[p] = w->q.area[p] * interp(g, phi, w->q.x + 3 * p);
    splat(g, &w->q, 1, res, 1, &f0);
    splat(g, &w->q, 1, NULL, 1, &f1);
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
    for (size_t p = 0; p < w->q.count; p++) {
        double v = interp(g, phi, w->q.x + 3 * p);
        rms += w->q.area[p] * v * v;
        asum += w->q.area[p];
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

/* out (on g) = trilinear interpolation of v (on gh) at g's cell centres. */
static hv_status upsample(const hv_grid *gh, const float *v, const hv_grid *g, float *out)
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

/* HV_SDF_SIGN_AUTO: the heat method's sign depends on where the block ends
 * when the repaired mesh is still open (its inside runs out of a wide opening
 * to the nearest walls) or when the block cuts the mesh (the heat method sees
 * only the part inside); the winding number of the repaired mesh is the same
 * in any block. It needs the repair's orientation. lo, hi: the input mesh's
 * bounds (repair moves no vertex). */
static int wants_winding(const hv_sdf_opts *o, const hv_sdf_repair_report *r, const double lo[3],
                         const double hi[3], const int n[3], double h, const double origin[3])
{
    if (o->sign != HV_SDF_SIGN_AUTO)
        return o->sign == HV_SDF_SIGN_WINDING;
    const unsigned orient = HV_SDF_REPAIR_ORIENT | HV_SDF_REPAIR_OUTWARD;
    if ((o->repair & orient) != orient)
        return 0;
    if (r->boundary_edges > 0)
        return 1;
    for (int a = 0; a < 3; a++)
        if (lo[a] < origin[a] || hi[a] > origin[a] + n[a] * h)
            return 1;
    return 0;
}

hv_status hv_sdf_compute(const hv_mesh *m, const hv_sdf_opts *opts, hv_grid **out,
                         hv_sdf_stats *stats)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_sdf_compute: out is NULL");
    *out = NULL;
    hv_sdf_opts o;
    if (opts)
        o = *opts;
    else
        hv_sdf_opts_default(&o);
    hv_sdf_stats S;
    memset(&S, 0, sizeof S);
    sdf_work w;
    memset(&w, 0, sizeof w);
    hv_status st = check_opts(&o);
    double lo[3], hi[3];
    if (st || (st = used_bounds(m, lo, hi)))
        return st;
    resolve_auto(&o);
    if (o.threads > 0)
        hv_set_threads(o.threads);
    const int unsig = o.unsigned_distance != 0;
    const int exact = o.magnitude == HV_SDF_EXACT;
    double t0 = hv_now(), tt;

    /* 1. Repair. */
    const hv_mesh *M = m;
    if ((st = stage(0.0, "repair")))
        return st;
    tt = hv_now();
    if (o.repair) {
        if ((st = hv_sdf_repair(m,
                                unsig ? (o.repair & (HV_SDF_REPAIR_WELD | HV_SDF_REPAIR_DEGENERATE |
                                                     HV_SDF_REPAIR_DUPLICATES))
                                      : o.repair,
                                o.max_hole, &w.repaired, &S.repair)))
            return st;
        M = w.repaired;
    } else {
        S.repair.vertices_in = S.repair.vertices_out = m->nverts;
        S.repair.triangles_in = S.repair.triangles_out = m->ntris;
    }
    S.t_repair = hv_now() - tt;

    /* Grid. */
    int n[3];
    double h, origin[3];
    if ((st = hv_sdf_grid_for_mesh(M, &o, n, &h, origin)))
        goto done;
    if ((st = hv_grid_create(&w.g, 3, n, h, origin)))
        goto done;
    const size_t count = hv_grid_count(w.g);
    memcpy(S.n, n, sizeof S.n);
    S.h = h;
    memcpy(S.origin, origin, sizeof S.origin);
    /* With the exact magnitude (signed) only the heat method's sign is used,
     * and it may run on a grid f times coarser. */
    const int sign_only = exact && !unsig;
    /* Where the heat method's sign would depend on the block, the winding
     * number of the repaired mesh decides instead (sign_winding.c). */
    const int wn_sign = sign_only && wants_winding(&o, &S.repair, lo, hi, n, h, origin);
    S.sign = !sign_only ? HV_SDF_SIGN_AUTO : wn_sign ? HV_SDF_SIGN_WINDING : HV_SDF_SIGN_HEAT;
    const int need_heat = !(unsig && exact) && !wn_sign;
    const int f = heat_factor(&o, n);
    S.heat_coarsen = need_heat ? f : 0;
    int nh[3];
    double hh = f * h;
    for (int a = 0; a < 3; a++)
        nh[a] = (n[a] + f - 1) / f;
    if (need_heat && sign_only && f > 1) {
        if ((st = hv_grid_create(&w.gh, 3, nh, hh, origin)))
            goto done;
    }
    const hv_grid *gh = w.gh ? w.gh : w.g;
    const size_t hcount = hv_grid_count(gh);
    /* AUTO on a GPU: stages 2-6 on the device, as for an explicit opencl. */
    if (need_heat && hv_backend_resolve(o.backend, hcount, 0) == HV_BACKEND_OPENCL)
        o.backend = HV_BACKEND_OPENCL;
    const int nlev = need_heat ? levels_for(&o, nh) : 0;
    S.levels = nlev;
    S.t = (o.t_scale * hh) * (o.t_scale * hh);

    /* 2. Splat. */
    if ((st = stage(0.05, "splat")))
        goto done;
    tt = hv_now();
    double blo[3], bhi[3];
    for (int a = 0; a < 3; a++) {
        blo[a] = origin[a];
        bhi[a] = origin[a] + n[a] * h;
    }
    if ((st = hv__quad_build(M, hh, blo, bhi, &w.q)))
        goto done;
    S.surface_samples = w.q.count;
    if (w.q.count == 0) {
        st = hv__error(HV_ERR_INVALID_ARG, "sdf: no part of the mesh lies inside the grid block");
        goto done;
    }
    const int ncomp = unsig ? 1 : 3;
    /* Backend opencl: stages 2-6 keep their fields on the device (sdf_cl.c). */
    const int on_device = need_heat && o.backend == HV_BACKEND_OPENCL;
    if (on_device) {
        S.t_splat = hv_now() - tt;
        if ((st = hv__sdf_heat_cl(&w.q, (hv_grid *)gh, nlev, unsig, &o, &S)))
            goto done;
    }
    if (need_heat && !on_device) {
        for (int b = 0; b < ncomp; b++)
            if (!(w.Y0[b] = hv_calloc(hcount, sizeof(float)))) {
                st = hv__error(HV_ERR_NOMEM, "sdf: out of memory for the surface field (%zu cells)",
                               hcount);
                goto done;
            }
        if (unsig)
            splat(gh, &w.q, 1, NULL, 1, w.Y0);
        else
            splat(gh, &w.q, 3, w.q.w, 3, w.Y0);
    }
    if (!on_device)
        S.t_splat = hv_now() - tt;

    /* 3. Diffuse: one backward-Euler step per level, the components sharing a solver. */
    tt = hv_now();
    double tau[9] = {0};
    const int keep_heat = need_heat && !unsig && o.local_shift;
    if (need_heat && !on_device) {
        w.Ybuf = hv_malloc((size_t)nlev * ncomp * hcount * sizeof(float));
        if (!w.Ybuf) {
            st = hv__error(HV_ERR_NOMEM, "sdf: out of memory for %d diffused fields of %zu cells",
                           nlev * ncomp, hcount);
            goto done;
        }
        double f2 = 0;
        for (int b = 0; b < ncomp; b++)
            f2 += norm2(w.Y0[b], hcount);
        hv_solver_opts so;
        hv_solver_opts_default(&so);
        so.backend = o.backend;
        so.tol = o.diffuse_tol;
        so.max_iter = 100;
        for (int k = 0; k < nlev; k++) {
            if (!(w.Y[k] = malloc(3 * sizeof(float *)))) {
                st = hv__error(HV_ERR_NOMEM, "sdf: out of memory");
                goto done;
            }
            for (int b = 0; b < ncomp; b++)
                w.Y[k][b] = w.Ybuf + ((size_t)k * ncomp + b) * hcount;
            double t = S.t * pow(16.0, k);
            hv_problem pb = {3, {nh[0], nh[1], nh[2]}, hh, NULL, 1.0, t};
            if ((st = stage(0.1 + 0.5 * k / nlev, "diffuse")))
                goto done;
            if ((st = solver_create(&w.solver, &pb, &so)))
                goto done;
            for (int b = 0; b < ncomp; b++) {
                hv_solve_info info;
                if ((st = hv_solver_solve(w.solver, w.Y0[b], w.Y[k][b], &info)))
                    goto done;
                S.diffuse_iterations += info.iterations;
                S.diffuse_relres = fmax(S.diffuse_relres, info.relres);
                S.backend = info.backend;
            }
            if (k == 0 && keep_heat) {
                w.heat = w.solver;
                w.solver = NULL;
            } else {
                hv_solver_destroy(&w.solver);
            }
            /* ||e||_2 <= ||r||_2 <= relres ||f||_2 since (I - t Lap) >= I; for the
             * unsigned gradient the bound grows by 2/h per component. */
            double bound = fmax(S.diffuse_relres, o.diffuse_tol) * sqrt(f2);
            tau[k] = SDF_NOISE_FACTOR * bound * (unsig ? 2.0 * sqrt(3.0) / hh : 1.0);
        }
    }
    if (!on_device)
        S.t_diffuse = hv_now() - tt;

    float *phi = gh->v;
    if (need_heat && !on_device) {
        /* 4. Normalize on faces, divergence. */
        if ((st = stage(0.6, "normalize")))
            goto done;
        tt = hv_now();
        if (!(w.rhs = hv_malloc(hcount * sizeof(float)))) {
            st = hv__error(HV_ERR_NOMEM, "sdf: out of memory for the divergence (%zu cells)",
                           hcount);
            goto done;
        }
        if (nlev == 1 && !unsig)
            S.dead_faces = build_rhs1(w.Y[0], tau[0], gh, w.Y0, w.rhs);
        else
            S.dead_faces = build_rhs(w.Y, nlev, tau, unsig, gh, w.rhs);
        for (int b = 0; b < ncomp; b++) {
            hv_free(w.Y0[b]);
            w.Y0[b] = NULL;
        }
        hv_free(w.Ybuf);
        w.Ybuf = NULL;
        S.t_normalize = hv_now() - tt;

        /* 5. Poisson. */
        if ((st = stage(0.65, "poisson")))
            goto done;
        tt = hv_now();
        hv_problem pb = {3, {nh[0], nh[1], nh[2]}, hh, NULL, 0.0, 1.0};
        hv_solver_opts so;
        hv_solver_opts_default(&so);
        so.backend = o.backend;
        so.tol = o.poisson_tol;
        so.max_iter = 100;
        if ((st = solver_create(&w.solver, &pb, &so)))
            goto done;
        hv_solve_info info;
        if ((st = hv_solver_solve(w.solver, w.rhs, phi, &info)))
            goto done;
        S.poisson_iterations = info.iterations;
        S.poisson_relres = info.relres;
        S.backend = info.backend;
        hv_solver_destroy(&w.solver);
        hv_free(w.rhs);
        w.rhs = NULL;
        S.t_poisson = hv_now() - tt;
    }
    if (need_heat && !on_device) {
        /* 6. Shift: area-weighted mean of phi at the surface samples to zero. */
        if ((st = stage(0.8, "shift")))
            goto done;
        tt = hv_now();
        double num = 0, den = 0, rms = 0;
#pragma omp parallel for reduction(+ : num, den, rms) schedule(static)
        for (size_t p = 0; p < w.q.count; p++) {
            double val = interp(gh, phi, w.q.x + 3 * p);
            num += w.q.area[p] * val;
            den += w.q.area[p];
            rms += w.q.area[p] * val * val;
        }
        S.shift = den > 0 ? num / den : 0;
        S.surface_rms_before = sqrt(fmax(0.0, rms / den - S.shift * S.shift)) / hh;
        const float sh = (float)S.shift;
#pragma omp parallel for schedule(static)
        for (size_t c = 0; c < hcount; c++)
            phi[c] -= sh;
        S.surface_rms_after = S.surface_rms_before;
        if (o.local_shift && !unsig) {
            if ((st = local_shift(&w, gh, &o, &S)))
                goto done;
        }
        S.t_shift = hv_now() - tt;
    }

    /* 7. Exact magnitude with the heat method's sign. */
    if (exact) {
        if ((st = stage(0.85, "redistance")))
            goto done;
        tt = hv_now();
        if (!(w.dist = hv_malloc(count * sizeof(float)))) {
            st = hv__error(HV_ERR_NOMEM, "sdf: out of memory for the exact distance (%zu cells)",
                           count);
            goto done;
        }
        const int want_tri = !unsig && o.near_sign > 0;
        if (want_tri && !(w.tri = hv_malloc(count * sizeof *w.tri))) {
            st = hv__error(HV_ERR_NOMEM, "sdf: out of memory for nearest triangles (%zu cells)",
                           count);
            goto done;
        }
        /* A narrow band needs exact values within band_only voxels only;
         * farther cells get (band_only + 1) h. */
        const double cap = o.band_only > 0 ? o.band_only * h : INFINITY;
        /* A narrow band up to SDF_RASTER_MAX voxels is rasterized whole
         * (exact, no dilation): at 3 voxels on the bunny at 256^3 that took
         * 1.07 CPU s against 1.96 for a 2-voxel raster plus dilation, which
         * pays a descent for most cells. */
        const double raster = o.band_only > 0 && o.band_only <= SDF_RASTER_MAX
                                  ? fmax(SDF_EXACT_BAND, o.band_only)
                                  : SDF_EXACT_BAND;
        if ((st = hv__exact_distance(M, w.g, raster, cap, w.dist, w.tri, &S.band_cells)))
            goto done;
        float *res = w.g->v;
        const float *dist = w.dist;
        const float far = (float)((o.band_only + 1) * h);
        if (unsig) {
#pragma omp parallel for schedule(static)
            for (size_t c = 0; c < count; c++)
                res[c] = isinf(dist[c]) ? far : dist[c];
        } else {
            /* Near the surface, where the heat sign is least sure, the clean
             * nearest feature's pseudonormal decides. */
            const uint32_t *tri = w.tri;
            hv_pseudo ps;
            const int have_ps = o.near_sign > 0 || wn_sign;
            if (have_ps && (st = hv__pseudo_build(M, &ps)))
                goto done;
            const float dlim = (float)(o.near_sign * h), hlim = (float)(1.5 * o.near_sign * h);
            size_t changed = 0, used = 0;
            if (wn_sign) {
                /* The winding number's sign, pseudonormals included. */
                double ts = hv_now();
                st = hv__winding_sign(M, w.g, dist, tri, &ps, o.near_sign * h, res,
                                      &S.winding_evals, &used);
                S.t_sign = hv_now() - ts;
                if (st) {
                    hv__pseudo_free(&ps);
                    goto done;
                }
            } else if (gh != w.g && (st = upsample(gh, phi, w.g, res))) {
                /* The heat sign on the output grid. */
                if (have_ps)
                    hv__pseudo_free(&ps);
                goto done;
            }
            const int use_ps = o.near_sign > 0 && !wn_sign;
#pragma omp parallel for collapse(2) schedule(dynamic, 16) reduction(+ : changed, used)
            for (int k = 0; k < n[2]; k++)
                for (int j = 0; j < n[1]; j++)
                    for (int i = 0; i < n[0]; i++) {
                        size_t c = (size_t)i + (size_t)n[0] * ((size_t)j + (size_t)n[1] * k);
                        float d = dist[c], sg = res[c];
                        if (use_ps && d < dlim && fabsf(sg) < hlim && tri[c] != UINT32_MAX) {
                            double p[3];
                            hv_grid_cell_center(w.g, i, j, k, p);
                            int s = hv__pseudo_sign(&ps, M, tri[c], p, sg < 0 ? -1 : 1);
                            if (s) {
                                used++;
                                if ((s < 0) != (sg < 0)) {
                                    sg = (float)s;
                                    changed++;
                                }
                            }
                        }
                        d = isinf(d) ? far : d;
                        res[c] = sg < 0 ? -d : d;
                    }
            S.near_sign_cells = used;
            S.near_sign_changed = changed;
            if (have_ps)
                hv__pseudo_free(&ps);
        }
        S.t_redistance = hv_now() - tt;
    }
    if ((st = stage(1.0, "done")))
        goto done;
    S.t_total = hv_now() - t0;
    *out = w.g;
    w.g = NULL;
done:
    work_free(&w);
    if (stats)
        *stats = S;
    return st;
}
