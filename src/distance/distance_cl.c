/*
 * The heat-method distance (distance_heat.c) with its fields on one OpenCL
 * device: the stages' diffusion solves, trust test, face assignment and next
 * front, the divergence, the Poisson solve and the output, in double where
 * the host path uses double (fp64 devices only). Same rules and constants as
 * the host path (distance_internal.h); the host reads back per stage the
 * solves' residual norms, two face counts, the front's weighted sums (one
 * double triple per work-group) and the front cell count, then phi at the
 * cells near the sources (for the offsets) and the distance once. With the
 * stages on tiles (the default) the host also reads two flags per tile (a
 * front weight, open faces left) and chooses the tiles as distance_band.c
 * does, and writes the band's tile list, neighbour slots and cell codes; the
 * band's Chebyshev sweeps run on the device (stats->host_bytes counts it). Its
 * kernels (kernels/distance.cl, fp64 only) are registered and built here
 * (hv_cl_module, src/cl/cl_core.h).
 */
#include "distance_cl.h"
#include "core/error.h"
#include "heatvox/ops.h"
#include "cl/cl_ops.h"
#include "solve/cl/solve_cl.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

extern const char hv__kernel_distance[]; /* kernels/, embedded by the Makefile */

/* The program is common.cl and distance.cl alone (the solver's kernels are
 * the solver's module, the reductions the grid operations'); dist_front_sums
 * writes its reduction tree out for the reason its comment gives. */
static const char *const dist_sources[] = {hv__kernel_distance, NULL};
enum {
    DK_FACES,
    DK_LOG,
    DK_ASSIGN,
    DK_FRONT_SUMS,
    DK_FRONT,
    DK_DIV,
    DK_GATHER,
    DK_OUTPUT,
    DK_TILE_FLAGS,
    DK_BAND_GATHER,
    DK_BAND_SCATTER,
    DK_BAND_SWEEP,
    DK_BAND_RESIDUAL
};
static const char *const dist_kernels[] = {"dist_faces",         "dist_log",
                                           "dist_assign",        "dist_front_sums",
                                           "dist_front",         "dist_div",
                                           "dist_gather",        "dist_output",
                                           "dist_tile_flags",    "dist_band_gather",
                                           "dist_band_scatter",  "dist_band_sweep",
                                           "dist_band_residual", NULL};
static const hv_cl_module dist_module = {"distance", dist_sources, dist_kernels, 1, 0};

/* The stages on tiles (distance_band.c): the tiles chosen on the host, from
 * per-tile flags the device computes; the band's cells on the device. */
typedef struct dist_cl_band {
    int on;
    hv_dist_box b; /* the host's tiles (its region borrowed) */
    cl_mem front, open, list, nbr, code, f, x[2];
    size_t cap; /* band cells the device buffers hold */
} dist_cl_band;

typedef struct dist_cl_work {
    hv_cl *cl;
    dist_cl_band bd;
    cl_mem region, X[3], w, u, u2, ok, inside, cnt, part, idx, gath, off, out;
    hv_solver *sv[2];   /* the whole stages' heat steps, made here */
    hv_solver *poisson; /* the hv_distance's, kept across queries */
    double *hpart;
    uint32_t *hidx;
    double *hval, *num;
    /* the grid's shape and launch ranges (work_shape) */
    int dim;
    cl_int N[4];
    size_t count, ngroups, g1[1], l1[1], gc[2], lc[2], gr, lr;
} dist_cl_work;

static void band_free(dist_cl_band *bd)
{
    cl_mem *m[] = {&bd->front, &bd->open, &bd->list, &bd->nbr,
                   &bd->code,  &bd->f,    &bd->x[0], &bd->x[1]};
    for (size_t i = 0; i < sizeof m / sizeof m[0]; i++)
        hv__cl_free(m[i]);
    hv__dist_tiles_free(&bd->b.tl);
}

static void work_free(dist_cl_work *k)
{
    band_free(&k->bd);
    hv_solver_destroy(&k->sv[0]);
    hv_solver_destroy(&k->sv[1]);
    cl_mem *m[] = {&k->region, &k->X[0], &k->X[1], &k->X[2], &k->w,    &k->u,   &k->u2, &k->ok,
                   &k->inside, &k->cnt,  &k->part, &k->idx,  &k->gath, &k->off, &k->out};
    for (size_t i = 0; i < sizeof m / sizeof m[0]; i++)
        hv__cl_free(m[i]);
    free(k->hpart);
    free(k->hidx);
    free(k->hval);
    free(k->num);
    hv__cl_close(&k->cl);
}

/* Reads the two counters and zeroes them. */
static hv_status read_counts(hv_cl *cl, cl_mem cnt, uint32_t out[2])
{
    hv__cl_read(cl, cnt, 0, 2 * sizeof(uint32_t), out);
    hv__cl_zero(cl, cnt, 2 * sizeof(uint32_t));
    return hv__cl_check(cl);
}

/* Sum of the ngroups partials of stride nsum at the slot j (read beforehand). */
static double sum_parts(const double *p, size_t ngroups, int nsum, int j)
{
    double s = 0;
    for (size_t g = 0; g < ngroups; g++)
        s += p[g * nsum + j];
    return s;
}

/* The Poisson restart guard of distance_heat.c (idle since the symmetric
 * preconditioner), on the host: rhs and u come from the device, u goes back. */
static hv_status poisson_restarts(dist_cl_work *k, const hv_grid *g, const int32_t *region,
                                  const hv_distance_opts *o, double *rel, hv_distance_stats *S)
{
    const size_t n = hv_grid_count(g), bytes = n * sizeof(double);
    double *rhs = hv_malloc(bytes), *u = hv_malloc(bytes), *Au = hv_malloc(bytes),
           *r = hv_malloc(bytes);
    hv_status st = HV_OK;
    if (!rhs || !u || !Au || !r) {
        st = hv__error(HV_ERR_NOMEM, "distance: out of memory for the Poisson restarts");
        goto out;
    }
    hv__cl_read(k->cl, k->u2, 0, bytes, rhs);
    hv__cl_read(k->cl, k->u, 0, bytes, u);
    if ((st = hv__cl_check(k->cl)))
        goto out;
    double fn = 0;
    for (size_t c = 0; c < n; c++)
        fn += rhs[c] * rhs[c];
    fn = sqrt(fn);
    for (int rs = 0; *rel > o->poisson_tol && rs < 30; rs++) {
        hv_apply_helmholtz_d(g->dim, g->n, g->h, g->solid, 0.0, 1.0, u, Au);
        double rr = 0;
        for (size_t c = 0; c < n; c++) {
            r[c] = region[c] >= 0 ? rhs[c] - Au[c] : 0.0;
            rr += r[c] * r[c];
        }
        *rel = fn > 0 ? sqrt(rr) / fn : 0;
        if (*rel <= o->poisson_tol)
            break;
        hv_solve_info pinfo;
        if ((st = hv_solver_solve_d(k->poisson, r, Au, &pinfo)))
            goto out;
        for (size_t c = 0; c < n; c++)
            u[c] += Au[c];
        S->poisson_iterations += pinfo.iterations;
        S->poisson_restarts++;
    }
    hv__cl_write(k->cl, k->u, 0, bytes, u);
    st = hv__cl_finish(k->cl);
out:
    hv_free(rhs);
    hv_free(u);
    hv_free(Au);
    hv_free(r);
    return st;
}

/* Opens the device and the distance kernels; *handled stays 0 on a device
 * without fp64, where the host path runs instead. */
static hv_status open_device(dist_cl_work *k, int *handled)
{
    hv_status st = hv__cl_open(&k->cl);
    if (st)
        return st;
    if (!k->cl->fp64) {
        hv__cl_close(&k->cl);
        return HV_OK;
    }
    *handled = 1;
    if ((st = hv__cl_module_open(k->cl, &dist_module)) || (st = hv__cl_ops_open(k->cl))) {
        hv__cl_close(&k->cl);
        return st;
    }
    return HV_OK;
}

static void work_shape(dist_cl_work *k, const hv_grid *g)
{
    k->dim = g->dim;
    k->N[0] = g->n[0];
    k->N[1] = g->n[1];
    k->N[2] = k->dim == 3 ? g->n[2] : 1;
    k->N[3] = k->dim;
    k->count = hv_grid_count(g);
    hv__cl_range1(k->count, k->g1, k->l1);
    hv__cl_range2((size_t)k->N[0], (size_t)k->N[1] * k->N[2], k->gc, k->lc);
    k->ngroups = hv__cl_range_red(k->count, &k->gr, &k->lr);
}

/* The launch range over the faces normal to axis a. */
static void face_range(const cl_int N[4], int a, size_t g2[2], size_t l2[2])
{
    hv__cl_range2((size_t)N[0] + (a == 0), (size_t)(N[1] + (a == 1)) * (N[2] + (a == 2)), g2, l2);
}

/* The buffers, and the faces closed (0) or open (NaN); *left counts the open
 * faces. */
static hv_status open_faces(dist_cl_work *k, const int32_t *region, const double *w0, size_t *left)
{
    hv_cl *cl = k->cl;
    const int dim = k->dim;
    const cl_int *N = k->N;
    const size_t count = k->count, dbytes = count * sizeof(double);
    size_t nface[3] = {0, 0, 0};
    size_t g2[2], l2[2];
    uint32_t cnt[2];
    hv_status st;
    for (int a = 0; a < dim; a++)
        nface[a] = (size_t)(N[0] + (a == 0)) * (N[1] + (a == 1)) * (N[2] + (a == 2));
    if ((st = hv__cl_alloc(cl, count * sizeof(int32_t), region, &k->region)) ||
        (st = hv__cl_alloc(cl, dbytes, w0, &k->w)) ||
        (st = hv__cl_alloc(cl, dbytes, NULL, &k->u)) ||
        (st = hv__cl_alloc(cl, dbytes, NULL, &k->u2)) ||
        (st = hv__cl_alloc(cl, count, NULL, &k->ok)) ||
        (st = hv__cl_alloc(cl, count, NULL, &k->inside)) ||
        (st = hv__cl_alloc(cl, 2 * sizeof(uint32_t), NULL, &k->cnt)) ||
        (st = hv__cl_alloc(cl, 3 * k->ngroups * sizeof(double), NULL, &k->part)))
        return st;
    if (!(k->hpart = malloc(3 * k->ngroups * sizeof *k->hpart)))
        return hv__error(HV_ERR_NOMEM, "distance: out of memory for partial sums");
    for (int a = 0; a < dim; a++)
        if ((st = hv__cl_alloc(cl, nface[a] * sizeof(float), NULL, &k->X[a])))
            return st;
    hv__cl_zero(cl, k->inside, count);
    hv__cl_zero(cl, k->cnt, 2 * sizeof(uint32_t));
    for (int a = 0; a < dim; a++) {
        face_range(N, a, g2, l2);
        hv__cl_args(cl, &dist_module, DK_FACES, "Iimmm", N, a, k->region, k->X[a], k->cnt);
        hv__cl_run(cl, &dist_module, DK_FACES, 2, g2, l2);
    }
    if ((st = read_counts(cl, k->cnt, cnt)))
        return st;
    *left = cnt[0];
    return HV_OK;
}

/* The host's tiles of the grid, and the per-tile flags' buffers. */
static hv_status band_open(dist_cl_work *k, const hv_grid *g, const int32_t *region)
{
    dist_cl_band *bd = &k->bd;
    hv__dist_box_init(&bd->b, g->dim, g->n, g->h, g->solid);
    bd->b.region = (int32_t *)region; /* read only */
    hv_status st = hv__dist_tiles_init(&bd->b, 1);
    if (st)
        return st;
    hv__dist_tiles_fluid(&bd->b);
    const size_t nt = bd->b.tl.count;
    if ((st = hv__cl_alloc(k->cl, nt, NULL, &bd->front)) ||
        (st = hv__cl_alloc(k->cl, nt * sizeof(int32_t), NULL, &bd->open)))
        return st;
    return HV_OK;
}

/* The tiles' shape as the band kernels take it: T, NT. */
static void band_shape(const hv_dist_tiles *T, cl_int t4[4], cl_int nt4[4])
{
    for (int a = 0; a < 3; a++) {
        t4[a] = T->tn[a];
        nt4[a] = T->nt[a];
    }
    t4[3] = (cl_int)T->cells;
    nt4[3] = (cl_int)T->count;
}

/* The device's per-tile flags (front weights, open faces without a
 * direction) into the host's tiles. */
static hv_status band_flags(dist_cl_work *k, hv_distance_stats *S)
{
    dist_cl_band *bd = &k->bd;
    hv_dist_tiles *T = &bd->b.tl;
    cl_int t4[4], nt4[4];
    band_shape(T, t4, nt4);
    size_t g1[1], l1[1];
    hv__cl_range1(T->count, g1, l1);
    hv__cl_args(k->cl, &dist_module, DK_TILE_FLAGS, "IIImmmmmm", k->N, t4, nt4, k->w, k->X[0],
                k->X[1], k->dim == 3 ? k->X[2] : NULL, bd->front, bd->open);
    hv__cl_run(k->cl, &dist_module, DK_TILE_FLAGS, 1, g1, l1);
    hv__cl_read(k->cl, bd->front, 0, T->count, T->front);
    hv__cl_read(k->cl, bd->open, 0, T->count * sizeof(int32_t), T->open_faces);
    S->host_bytes += (double)T->count * (1 + sizeof(int32_t));
    return hv__cl_check(k->cl);
}

/* Device buffers for the band's cells. */
static hv_status band_room(dist_cl_work *k)
{
    dist_cl_band *bd = &k->bd;
    const hv_dist_tiles *T = &bd->b.tl;
    const size_t n = T->nlist * T->cells;
    if (n <= bd->cap && bd->list)
        return HV_OK;
    const size_t cap = n + n / 4, tiles = cap / T->cells + 1;
    cl_mem *m[] = {&bd->list, &bd->nbr, &bd->code, &bd->f, &bd->x[0], &bd->x[1]};
    for (size_t i = 0; i < sizeof m / sizeof m[0]; i++)
        hv__cl_free(m[i]);
    hv_status st;
    if ((st = hv__cl_alloc(k->cl, tiles * sizeof(uint32_t), NULL, &bd->list)) ||
        (st = hv__cl_alloc(k->cl, 6 * tiles * sizeof(int32_t), NULL, &bd->nbr)) ||
        (st = hv__cl_alloc(k->cl, cap, NULL, &bd->code)) ||
        (st = hv__cl_alloc(k->cl, cap * sizeof(double), NULL, &bd->f)) ||
        (st = hv__cl_alloc(k->cl, cap * sizeof(double), NULL, &bd->x[0])) ||
        (st = hv__cl_alloc(k->cl, cap * sizeof(double), NULL, &bd->x[1])))
        return st;
    bd->cap = cap;
    return HV_OK;
}

/* The stage's tiles, chosen on the host, and their lists and codes uploaded;
 * f = the weights on the band. */
static hv_status band_stage(dist_cl_work *k, hv_distance_stats *S)
{
    dist_cl_band *bd = &k->bd;
    hv_dist_tiles *T = &bd->b.tl;
    hv_status st;
    if ((st = hv__dist_band_select(&bd->b, NULL)) || (st = band_room(k)))
        return st;
    const size_t n = T->nlist * T->cells;
    hv__cl_write(k->cl, bd->list, 0, T->nlist * sizeof(uint32_t), T->list);
    hv__cl_write(k->cl, bd->nbr, 0, 6 * T->nlist * sizeof(int32_t), T->nbr);
    hv__cl_write(k->cl, bd->code, 0, n, T->code);
    S->host_bytes += (double)T->nlist * (sizeof(uint32_t) + 6 * sizeof(int32_t)) + (double)n;
    cl_int t4[4], nt4[4];
    band_shape(T, t4, nt4);
    size_t g1[1], l1[1];
    hv__cl_range1(n, g1, l1);
    hv__cl_args(k->cl, &dist_module, DK_BAND_GATHER, "IIIlmmm", k->N, t4, nt4, n, bd->list, k->w,
                bd->f);
    hv__cl_run(k->cl, &dist_module, DK_BAND_GATHER, 1, g1, l1);
    return hv__cl_check(k->cl);
}

/* sum of the partials of a . b over the band's n cells (read back). */
static double band_dot(dist_cl_work *k, cl_mem a, cl_mem b, size_t n, hv_distance_stats *S)
{
    size_t g[1], l[1];
    const size_t ng = hv__cl_range_red(n, g, l);
    hv__cl_dot_parts_d(k->cl, a, b, n, k->part);
    hv__cl_read(k->cl, k->part, 0, ng * sizeof(double), k->hpart);
    S->host_bytes += (double)ng * sizeof(double);
    return sum_parts(k->hpart, ng, 1, 0);
}

/* (I - s Lap) x = f on the band by the host's Chebyshev sweeps; x into dst
 * (zeroed first) on the core tiles' cells; the measured residual in info. */
static hv_status band_chebyshev(dist_cl_work *k, double s, double tol, cl_mem dst,
                                hv_solve_info *info, hv_distance_stats *S)
{
    dist_cl_band *bd = &k->bd;
    const hv_dist_tiles *T = &bd->b.tl;
    const size_t n = T->nlist * T->cells, ncore = T->ncore * T->cells;
    const int sweeps = hv__dist_band_sweeps(k->dim, s, tol);
    const double r2 = hv__dist_band_rho2(k->dim, s);
    cl_int t4[4], nt4[4];
    band_shape(T, t4, nt4);
    size_t g1[1], l1[1];
    hv__cl_range1(n, g1, l1);
    cl_mem cur = bd->x[0], prev = bd->x[1];
    hv__cl_zero(k->cl, cur, n * sizeof(double));
    hv__cl_zero(k->cl, prev, n * sizeof(double));
    double omega = 1;
    for (int it = 0; it < sweeps; it++) {
        hv__cl_args(k->cl, &dist_module, DK_BAND_SWEEP, "Ilmmmmmaa", t4, n, bd->nbr, bd->code,
                    bd->f, cur, prev, s, omega);
        hv__cl_run(k->cl, &dist_module, DK_BAND_SWEEP, 1, g1, l1);
        cl_mem t = cur;
        cur = prev;
        prev = t;
        omega = hv__dist_band_omega(omega, r2, it);
    }
    hv__cl_args(k->cl, &dist_module, DK_BAND_RESIDUAL, "Ilmmmmma", t4, n, bd->nbr, bd->code, bd->f,
                cur, prev, s);
    hv__cl_run(k->cl, &dist_module, DK_BAND_RESIDUAL, 1, g1, l1);
    const double rr = band_dot(k, prev, prev, n, S), ff = band_dot(k, bd->f, bd->f, n, S);
    hv__cl_zero(k->cl, dst, k->count * sizeof(double));
    hv__cl_range1(ncore, g1, l1);
    hv__cl_args(k->cl, &dist_module, DK_BAND_SCATTER, "IIIlmmm", k->N, t4, nt4, ncore, bd->list,
                cur, dst);
    hv__cl_run(k->cl, &dist_module, DK_BAND_SCATTER, 1, g1, l1);
    memset(info, 0, sizeof *info);
    info->iterations = sweeps;
    info->relres = ff > 0 ? sqrt(rr / ff) : 0;
    info->backend = HV_BACKEND_OPENCL;
    return hv__cl_check(k->cl);
}

/* The heat steps' tolerance: the band's, as on the host (distance_march.c). */
static double stage_tol(const dist_cl_work *k, const hv_distance_opts *o)
{
    return k->bd.on ? fmin(o->diffuse_tol, DIST_BAND_TOL) : o->diffuse_tol;
}

/* A stage's two diffusions on the band. */
static hv_status diffuse_band(dist_cl_work *k, const hv_distance_opts *o, int l,
                              hv_solve_info info[2], hv_distance_stats *S)
{
    hv_status st = band_stage(k, S);
    for (int q = 0; !st && q < 2; q++) {
        const double s = o->t_scale * (q ? T_RATIO : 1);
        st = band_chebyshev(k, s, stage_tol(k, o), q ? k->u2 : k->u, &info[q], S);
        S->diffuse_iterations += info[q].iterations;
        S->diffuse_relres = fmax(S->diffuse_relres, info[q].relres);
    }
    const size_t cells = hv__dist_band_cells(&k->bd.b);
    S->cells_solved += cells;
    if (l < 8)
        S->stage_cells[l] = cells;
    return st;
}

/* A stage's two diffusions of the front's weights w: for t into u, for
 * T_RATIO t into u2. */
static hv_status diffuse(dist_cl_work *k, const hv_grid *g, const hv_distance_opts *o,
                         hv_solve_info info[2], hv_distance_stats *S)
{
    hv_status st;
    if ((st = hv__cl_finish(k->cl)))
        return st;
    for (int q = 0; q < 2; q++) {
        if (!k->sv[q] &&
            (st = hv__dist_solver(&k->sv[q], g->dim, g->n, g->h, g->solid, 1.0,
                                  S->t * (q ? T_RATIO : 1), o->diffuse_tol, HV_BACKEND_OPENCL,
                                  hv__dist_poisson_coarse(o, g->solid))))
            return st;
        if ((st = hv__cl_solver_solve_d(k->sv[q], k->w, q ? k->u2 : k->u, &info[q])))
            return st;
        S->diffuse_iterations += info[q].iterations;
        S->diffuse_relres = fmax(S->diffuse_relres, info[q].relres);
    }
    S->cells_solved += k->count;
    if (S->stages < 8)
        S->stage_cells[S->stages] = k->count;
    return HV_OK;
}

/* ||w||, then the trust bounds (*lthr: the one for t), the cells trusted and
 * the faces they assign; cnt: the faces left open, those assigned. */
static hv_status assign_faces(dist_cl_work *k, const hv_distance_opts *o,
                              const hv_solve_info info[2], double *lthr, uint32_t cnt[2])
{
    hv_cl *cl = k->cl;
    size_t g2[2], l2[2];
    hv_status st;
    hv__cl_dot_parts_d(cl, k->w, k->w, k->count, k->part);
    hv__cl_read(cl, k->part, 0, k->ngroups * sizeof(double), k->hpart);
    if ((st = hv__cl_check(cl)))
        return st;
    const double wn = sqrt(sum_parts(k->hpart, k->ngroups, 1, 0));
    *lthr = hv__dist_trust_log(fmax(info[0].relres, stage_tol(k, o)), wn, o->t_scale);
    const double lthr2 =
        hv__dist_trust_log(fmax(info[1].relres, stage_tol(k, o)), wn, o->t_scale * T_RATIO);
    hv__cl_args(cl, &dist_module, DK_LOG, "lmmmmaa", k->count, k->region, k->u, k->u2, k->ok, *lthr,
                lthr2);
    hv__cl_run(cl, &dist_module, DK_LOG, 1, k->g1, k->l1);
    for (int a = 0; a < k->dim; a++) {
        face_range(k->N, a, g2, l2);
        hv__cl_args(cl, &dist_module, DK_ASSIGN, "Iimmmm", k->N, a, k->u2, k->ok, k->X[a], k->cnt);
        hv__cl_run(cl, &dist_module, DK_ASSIGN, 2, g2, l2);
    }
    return read_counts(cl, k->cnt, cnt);
}

/* next_front: the front's level of psi and ln u, then the cell pass. *moved
 * stays 0 where the front ends: no weight on it, a step under 2 voxels, or no
 * cell in the next one. */
static hv_status next_front(dist_cl_work *k, double lthr, const double tau[2], int *moved)
{
    hv_cl *cl = k->cl;
    uint32_t cnt[2];
    hv_status st;
    *moved = 0;
    hv__cl_args(cl, &dist_module, DK_FRONT_SUMS, "lmmmmm", k->count, k->w, k->u2, k->u, k->ok,
                k->part);
    hv__cl_run(cl, &dist_module, DK_FRONT_SUMS, 1, &k->gr, &k->lr);
    hv__cl_read(cl, k->part, 0, 3 * k->ngroups * sizeof(double), k->hpart);
    if ((st = hv__cl_check(cl)))
        return st;
    const double sw = sum_parts(k->hpart, k->ngroups, 3, 2);
    if (!(sw > 0))
        return HV_OK;
    const double psi0 = sum_parts(k->hpart, k->ngroups, 3, 0) / sw;
    const double lu0 = sum_parts(k->hpart, k->ngroups, 3, 1) / sw;
    const double full = hv__dist_front_step(lu0, lthr, k->dim, tau[0]);
    const double step = fmin(full, k->bd.on ? hv__dist_core_step(&k->bd.b.tl) : INFINITY);
    if (!(step >= 2))
        return HV_OK;
    if (k->bd.on)
        hv__dist_core_next(&k->bd.b.tl, full, k->dim, tau[0]);
    hv__cl_args(cl, &dist_module, DK_FRONT, "Immmmaaaaam", k->N, k->u2, k->ok, k->inside, k->w,
                psi0, step, tau[0], tau[1], FRONT_BAND, k->cnt);
    hv__cl_run(cl, &dist_module, DK_FRONT, 2, k->gc, k->lc);
    if ((st = read_counts(cl, k->cnt, cnt)))
        return st;
    *moved = cnt[0] != 0;
    return HV_OK;
}

/* The device's stages for hv__dist_stages: the work, the query's grid and
 * options. */
typedef struct cl_stages {
    dist_cl_work *k;
    const hv_grid *g;
    const hv_distance_opts *o;
    double tau[2];
} cl_stages;

static hv_status cl_diffuse(void *self, int l, hv_solve_info info[2], hv_distance_stats *S)
{
    cl_stages *C = self;
    hv_status st =
        C->k->bd.on ? diffuse_band(C->k, C->o, l, info, S) : diffuse(C->k, C->g, C->o, info, S);
    if (!st)
        S->backend = info[0].backend;
    return st;
}

static hv_status cl_assign(void *self, const hv_solve_info info[2], double *lthr, size_t *got,
                           size_t *left)
{
    cl_stages *C = self;
    uint32_t cnt[2] = {0, 0};
    hv_status st = assign_faces(C->k, C->o, info, lthr, cnt);
    *left = cnt[0];
    *got = cnt[1];
    return st;
}

static hv_status cl_advance(void *self, double lthr, int *moved, hv_distance_stats *S)
{
    cl_stages *C = self;
    hv_status st = next_front(C->k, lthr, C->tau, moved);
    if (!st && *moved && C->k->bd.on)
        st = band_flags(C->k, S);
    return st;
}

/* Poisson: -Lap phi = -div X (unassigned faces count 0), rhs in u2, phi in u,
 * by the object's solver. */
static hv_status poisson(dist_cl_work *k, const hv_grid *g, const int32_t *region,
                         const hv_distance_opts *o, hv_distance_stats *S)
{
    hv_cl *cl = k->cl;
    hv_status st;
    double t0 = hv_now();
    hv_solver_destroy(&k->sv[0]);
    hv_solver_destroy(&k->sv[1]);
    if ((st = hv__progress(0.7, "poisson")))
        return st;
    hv__cl_args(cl, &dist_module, DK_DIV, "Immmmam", k->N, k->region, k->X[0], k->X[1],
                k->dim == 3 ? k->X[2] : NULL, 1.0 / g->h, k->u2);
    hv__cl_run(cl, &dist_module, DK_DIV, 2, k->gc, k->lc);
    if ((st = hv__cl_finish(cl)))
        return st;
    hv_solve_info pinfo;
    if ((st = hv__cl_solver_solve_d(k->poisson, k->u2, k->u, &pinfo)))
        return st;
    S->poisson_iterations = pinfo.iterations;
    double rel = pinfo.relres;
    if (rel > o->poisson_tol && (st = poisson_restarts(k, g, region, o, &rel, S)))
        return st;
    S->poisson_relres = rel;
    S->t_poisson = hv_now() - t0;
    return HV_OK;
}

/* Offsets: phi at the cells near the sources, fitted per region on the host
 * in the host path's order, into k->num[0 .. nregions - 1]. */
static hv_status fit_offsets(dist_cl_work *k, const hv_grid *g, const int32_t *region,
                             const float *ref, size_t nregions)
{
    hv_cl *cl = k->cl;
    const size_t count = k->count;
    hv_status st;
    size_t m = 0;
    for (size_t c = 0; c < count; c++)
        m += ref[c] <= HV_DIST_REF_RADIUS * g->h && region[c] >= 0;
    k->hidx = malloc((m ? m : 1) * sizeof *k->hidx);
    k->hval = malloc((m ? m : 1) * sizeof *k->hval);
    k->num = calloc(2 * nregions + 1, sizeof *k->num);
    if (!k->hidx || !k->hval || !k->num)
        return hv__error(HV_ERR_NOMEM, "distance: out of memory");
    m = 0;
    for (size_t c = 0; c < count; c++)
        if (ref[c] <= HV_DIST_REF_RADIUS * g->h && region[c] >= 0)
            k->hidx[m++] = (uint32_t)c;
    if (m) {
        if ((st = hv__cl_alloc(cl, m * sizeof(uint32_t), k->hidx, &k->idx)) ||
            (st = hv__cl_alloc(cl, m * sizeof(double), NULL, &k->gath)))
            return st;
        size_t gg[1], lg[1];
        hv__cl_range1(m, gg, lg);
        hv__cl_args(cl, &dist_module, DK_GATHER, "mmml", k->u, k->idx, k->gath, m);
        hv__cl_run(cl, &dist_module, DK_GATHER, 1, gg, lg);
        hv__cl_read(cl, k->gath, 0, m * sizeof(double), k->hval);
        if ((st = hv__cl_check(cl)))
            return st;
    }
    for (size_t q = 0; q < m; q++) {
        const size_t c = k->hidx[q];
        const double wt = ref[c] >= 1.5 * g->h ? 1.0 : 1e-3;
        k->num[2 * region[c]] += wt * (k->hval[q] - ref[c]);
        k->num[2 * region[c] + 1] += wt;
    }
    for (size_t r = 0; r < nregions; r++)
        k->num[r] = k->num[2 * r] / k->num[2 * r + 1];
    return HV_OK;
}

/* The distance into g->v: phi less its region's offset on free cells, the
 * solid and unreachable values elsewhere. */
static hv_status write_output(dist_cl_work *k, hv_grid *g, const hv_distance_opts *o,
                              size_t nregions)
{
    hv_cl *cl = k->cl;
    hv_status st;
    if ((st = hv__cl_alloc(cl, (nregions ? nregions : 1) * sizeof(double), k->num, &k->off)) ||
        (st = hv__cl_alloc(cl, k->count * sizeof(float), NULL, &k->out)))
        return st;
    hv__cl_args(cl, &dist_module, DK_OUTPUT, "lmmmffm", k->count, k->region, k->u, k->off,
                (double)o->solid_value, (double)o->unreachable, k->out);
    hv__cl_run(cl, &dist_module, DK_OUTPUT, 1, k->g1, k->l1);
    hv__cl_read(cl, k->out, 0, k->count * sizeof(float), g->v);
    return hv__cl_check(cl);
}

hv_status hv__distance_heat_cl(hv_grid *g, const hv_distance_opts *o, hv_solver *psolver,
                               const int32_t *region, size_t nregions, const double *w0,
                               const float *ref, hv_distance_stats *S, int *handled)
{
    dist_cl_work k;
    memset(&k, 0, sizeof k);
    k.poisson = psolver;
    *handled = 0;
    const char *env = getenv("HEATVOX_DISTANCE_CL");
    if (env && !strcmp(env, "0")) /* tests: the host path with the same backend */
        return HV_OK;
    hv_status st = open_device(&k, handled);
    if (st || !*handled)
        return st;
    work_shape(&k, g);
    double t0 = hv_now();
    size_t left = 0;
    k.bd.on = !o->whole_stages;
    if ((st = open_faces(&k, region, w0, &left)) ||
        (k.bd.on && ((st = band_open(&k, g, region)) || (st = band_flags(&k, S)))))
        goto done;
    S->t_splat += hv_now() - t0;
    cl_stages C = {&k, g, o, {1.0 / o->t_scale, 1.0 / (o->t_scale * T_RATIO)}};
    const hv_dist_stage_ops ops = {&C, cl_diffuse, cl_assign, cl_advance};
    if ((st = hv__dist_stages(&ops, o, left, 1, &left, S)))
        goto done;
    S->dead_faces = left;
    if ((st = poisson(&k, g, region, o, S)) || (st = fit_offsets(&k, g, region, ref, nregions)))
        goto done;
    st = write_output(&k, g, o, nregions);
done:
    work_free(&k);
    return st;
}
