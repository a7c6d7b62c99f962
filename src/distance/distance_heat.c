/* Unsigned geodesic distance by the heat method on grids with obstacles
 * (heat.h). One backward-Euler step decays like e^{-r/sqrt t} (docs/METHOD.md,
 * "Heat method"), so a double solve is trusted only ~30 sqrt(t) out; a larger
 * t reaches further but bends directions near walls (Neumann reflections) and
 * corners (6 voxels mean error at 128^2 with t = 512 h^2). Instead the
 * diffusion marches: each stage starts from a wavefront of the previous one,
 * with t kept small. The lattice and front rules are in distance_front.c; on
 * an fp64 OpenCL device the stages run in distance_cl.c. */
#include "distance_internal.h"
#include "distance_cl.h"
#include "core/error.h"
#include "heatvox/ops.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void hv_distance_opts_default(hv_distance_opts *o)
{
    memset(o, 0, sizeof *o);
    o->t_scale = 2;
    o->max_stages = 1000;
    o->diffuse_tol = 1e-11;
    o->poisson_tol = 1e-9;
    o->backend = HV_BACKEND_AUTO;
    o->unreachable = INFINITY;
    o->solid_value = INFINITY;
}

typedef hv_dist_box dist_ctx;

void hv__dist_box_init(hv_dist_box *b, int dim, const int n[3], double h, const uint8_t *solid)
{
    b->dim = dim;
    memcpy(b->n, n, sizeof b->n);
    b->h = h;
    b->solid = solid;
    b->count = (size_t)n[0] * n[1] * n[2];
    b->cs[0] = 1;
    b->cs[1] = (size_t)n[0];
    b->cs[2] = (size_t)n[0] * n[1];
    for (int a = 0; a < 3; a++) {
        b->lo[a] = 0;
        b->hi[a] = n[a];
        b->nface[a] =
            a < dim ? (size_t)(n[0] + (a == 0)) * (n[1] + (a == 1)) * (n[2] + (a == 2)) : 0;
    }
}

static size_t face_index(const dist_ctx *d, int a, int i, int j, int k)
{
    int m0 = d->n[0] + (a == 0), m1 = d->n[1] + (a == 1);
    return i + (size_t)m0 * (j + (size_t)m1 * k);
}

static int fluid(const dist_ctx *d, size_t c) { return !d->solid || !d->solid[c]; }

/* Cell (i, j, k) of the box is one of the owned cells. */
static int owned(const dist_ctx *d, int i, int j, int k)
{
    return i >= d->lo[0] && i < d->hi[0] && j >= d->lo[1] && j < d->hi[1] && k >= d->lo[2] &&
           k < d->hi[2];
}

/* Labels the connected fluid regions that contain a source cell. */
static hv_status label_regions(dist_ctx *d, const double *w, size_t *nregions, size_t *unreach)
{
    size_t n = d->count;
    d->region = malloc(n * sizeof *d->region);
    size_t *stack = malloc(n * sizeof *stack);
    if (!d->region || !stack) {
        free(stack);
        return hv__error(HV_ERR_NOMEM, "distance: out of memory labelling regions of %zu cells", n);
    }
    for (size_t c = 0; c < n; c++)
        d->region[c] = fluid(d, c) ? -2 : -1;
    int32_t nr = 0;
    for (size_t seed = 0; seed < n; seed++) {
        if (!(w[seed] > 0) || d->region[seed] != -2)
            continue;
        size_t top = 0;
        stack[top++] = seed;
        d->region[seed] = nr;
        while (top) {
            size_t c = stack[--top];
            size_t i = c % d->cs[1], j = (c / d->cs[1]) % (size_t)d->n[1], k = c / d->cs[2];
            size_t ijk[3] = {i, j, k};
            for (int a = 0; a < d->dim; a++) {
                if (ijk[a] > 0 && d->region[c - d->cs[a]] == -2) {
                    d->region[c - d->cs[a]] = nr;
                    stack[top++] = c - d->cs[a];
                }
                if (ijk[a] + 1 < (size_t)d->n[a] && d->region[c + d->cs[a]] == -2) {
                    d->region[c + d->cs[a]] = nr;
                    stack[top++] = c + d->cs[a];
                }
            }
        }
        nr++;
    }
    free(stack);
    size_t un = 0;
    for (size_t c = 0; c < n; c++)
        un += d->region[c] == -2;
    *nregions = (size_t)nr;
    *unreach = un;
    return HV_OK;
}

/* Initializes X: 0 on closed faces (walls, solid, regions without a source),
 * NaN (to be assigned) on open faces of reachable regions. Returns the number
 * of open faces whose upper cell is owned (each face counted on one rank). */
static size_t init_faces(dist_ctx *d)
{
    size_t open = 0;
    for (int a = 0; a < d->dim; a++) {
        const int na = d->n[a];
#pragma omp parallel for collapse(2) reduction(+ : open) schedule(static)
        for (int k = 0; k < d->n[2] + (a == 2); k++)
            for (int j = 0; j < d->n[1] + (a == 1); j++)
                for (int i = 0; i < d->n[0] + (a == 0); i++) {
                    int ijk[3] = {i, j, k};
                    size_t f = face_index(d, a, i, j, k);
                    float v = 0;
                    if (ijk[a] > 0 && ijk[a] < na) {
                        size_t R = i + (size_t)d->n[0] * (j + (size_t)d->n[1] * k),
                               L = R - d->cs[a];
                        if (d->region[L] >= 0 && d->region[R] >= 0) {
                            v = NAN;
                            open += owned(d, i, j, k);
                        }
                    }
                    d->X[a][f] = v;
                }
    }
    return open;
}

/* Differences of lu on the axis-b faces on both sides of cell c (those open and
 * trusted); returns the number found and adds them to *sum. */
static int transverse(const dist_ctx *d, const double *u, const uint8_t *ok, size_t c,
                      const int ijk[3], int b, double *sum)
{
    int m = 0;
    if (ijk[b] > 0) {
        size_t o = c - d->cs[b];
        if (ok[o]) {
            *sum += u[c] - u[o];
            m++;
        }
    }
    if (ijk[b] + 1 < d->n[b]) {
        size_t o = c + d->cs[b];
        if (ok[o]) {
            *sum += u[o] - u[c];
            m++;
        }
    }
    return m;
}

/* Assigns X on every unassigned open face whose cells are trusted (ok), from
 * psi = ln u(t) - ln u(4t): X = -grad psi / |grad psi|, the face's own
 * difference normalized with the mean of the open, trusted transverse face
 * differences around it. Differences of logarithms, not of u: u falls like
 * e^{-r/sqrt t}, and for an exponential a face difference (span h) and a mean
 * of transverse differences (span 2h) disagree by O(h^2/t) (3% on diagonals
 * at t = 2h^2: distances 3% short); ln u is nearly linear. Returns the number
 * of open faces still unassigned (of those init_faces counts). */
static size_t assign_faces(dist_ctx *d, const double *u, const uint8_t *ok, size_t *assigned)
{
    size_t left = 0, done = 0;
    for (int a = 0; a < d->dim; a++) {
#pragma omp parallel for collapse(2) reduction(+ : left, done) schedule(static)
        for (int k = 0; k < d->n[2] + (a == 2); k++)
            for (int j = 0; j < d->n[1] + (a == 1); j++)
                for (int i = 0; i < d->n[0] + (a == 0); i++) {
                    size_t f = face_index(d, a, i, j, k);
                    if (!isnan(d->X[a][f]))
                        continue;
                    const int mine = owned(d, i, j, k);
                    size_t R = i + (size_t)d->n[0] * (j + (size_t)d->n[1] * k), L = R - d->cs[a];
                    if (!(ok[L] && ok[R])) {
                        left += mine;
                        continue;
                    }
                    double D[3] = {0, 0, 0};
                    D[a] = u[L] - u[R];
                    int ijkR[3] = {i, j, k}, ijkL[3] = {i, j, k};
                    ijkL[a]--;
                    for (int b = 0; b < d->dim; b++) {
                        if (b == a)
                            continue;
                        double s = 0;
                        int m = transverse(d, u, ok, L, ijkL, b, &s) +
                                transverse(d, u, ok, R, ijkR, b, &s);
                        if (m)
                            D[b] = -s / m;
                    }
                    double dn = 0;
                    for (int b = 0; b < d->dim; b++)
                        dn += D[b] * D[b];
                    d->X[a][f] = dn > 0 ? (float)(D[a] / sqrt(dn)) : 0.0f;
                    done += mine;
                }
    }
    *assigned = done;
    return left;
}

/* f = -div X (the Poisson solve's right-hand side for -Lap phi = f). */
static void divergence(const dist_ctx *d, double *f)
{
    const double ih = 1.0 / d->h;
#pragma omp parallel for collapse(2) schedule(static)
    for (int k = 0; k < d->n[2]; k++)
        for (int j = 0; j < d->n[1]; j++)
            for (int i = 0; i < d->n[0]; i++) {
                size_t c = i + (size_t)d->n[0] * (j + (size_t)d->n[1] * k);
                double s = 0;
                if (d->region[c] >= 0)
                    for (int a = 0; a < d->dim; a++) {
                        int lo[3] = {i, j, k};
                        size_t fl = face_index(d, a, lo[0], lo[1], lo[2]);
                        lo[a]++;
                        size_t fh = face_index(d, a, lo[0], lo[1], lo[2]);
                        s += (double)d->X[a][fh] - (double)d->X[a][fl];
                    }
                f[c] = -s * ih;
            }
}

static void sum_over(const dist_ctx *d, double *v, int n)
{
    if (d->hk && d->hk->sum)
        d->hk->sum(d->hk->user, v, n);
}

/* Builds the next front. psi = ln u(t) - ln u(4t) on trusted cells (ok) falls
 * by kappa(t) - kappa(4t) per voxel travelled away from the current front, with
 * the amplitude cancelled; on the lattice kappa depends on the direction nu of
 * travel, so the distance travelled is e = (psi0 - psi) / (kappa1(nu) -
 * kappa2(nu)), psi0 its value on the current front (weights w). Using e rather
 * than a level set of u keeps the fronts round: a level set of u is a ball of
 * the lattice's own metric (1% flat on the diagonals at t = 2h^2), and fronts
 * built on fronts would compound that. The new front sits at e = step voxels,
 * FRONT_MARGIN below the trust bound lthr of ln u(t); cells with e <= step join
 * the inside; w is overwritten with the new front's weights. Returns the number
 * of front cells (owned; 0: no progress possible). */
static size_t next_front(const dist_ctx *d, const double *psi, const double *lu, const uint8_t *ok,
                         double lthr, uint8_t *inside, double *w)
{
    double s[4] = {0, 0, 0, 0};
    for (int k = d->lo[2]; k < d->hi[2]; k++)
        for (int j = d->lo[1]; j < d->hi[1]; j++)
            for (int i = d->lo[0]; i < d->hi[0]; i++) {
                size_t c = i + (size_t)d->n[0] * (j + (size_t)d->n[1] * k);
                if (w[c] > 0 && ok[c]) {
                    s[0] += w[c] * psi[c];
                    s[1] += w[c] * lu[c];
                    s[2] += w[c];
                }
            }
    sum_over(d, s, 3);
    if (!(s[2] > 0))
        return 0;
    const double psi0 = s[0] / s[2], lu0 = s[1] / s[2];
    const double step = hv__dist_front_step(lu0, lthr, d->dim, d->tau[0]);
    if (!(step >= 2))
        return 0;
    size_t nf = 0;
#pragma omp parallel for collapse(2) reduction(+ : nf) schedule(static)
    for (int k = 0; k < d->n[2]; k++)
        for (int j = 0; j < d->n[1]; j++)
            for (int i = 0; i < d->n[0]; i++) {
                size_t c = i + (size_t)d->n[0] * (j + (size_t)d->n[1] * k);
                double v = 0;
                if (!inside[c] && ok[c]) {
                    int ijk[3] = {i, j, k};
                    double nu[3] = {0, 0, 0}, nn = 0;
                    for (int b = 0; b < d->dim; b++) {
                        double s = 0;
                        int m = transverse(d, psi, ok, c, ijk, b, &s);
                        nu[b] = m ? -s / m : 0;
                        nn += nu[b] * nu[b];
                    }
                    if (nn > 0) {
                        nn = sqrt(nn);
                        for (int b = 0; b < d->dim; b++)
                            nu[b] = fabs(nu[b]) / nn;
                        double dk = hv__dist_lattice_kappa(nu, d->dim, d->tau[0]) -
                                    hv__dist_lattice_kappa(nu, d->dim, d->tau[1]);
                        double e = (psi0 - psi[c]) / dk;
                        double s = (e - step) / FRONT_BAND;
                        if (fabs(s) < 1) {
                            v = (1 - s * s) * (1 - s * s);
                            nf += owned(d, i, j, k);
                        }
                        if (e <= step)
                            inside[c] = 1;
                    }
                }
                w[c] = v;
            }
    double fs = (double)nf;
    sum_over(d, &fs, 1);
    return (size_t)fs;
}

/* The 2-norm of v over the owned cells (and the ranks). */
static double norm2(const dist_ctx *d, const double *v)
{
    double s = 0;
    const int nj = d->hi[1] - d->lo[1];
#pragma omp parallel for collapse(2) reduction(+ : s) schedule(static)
    for (int k = d->lo[2]; k < d->hi[2]; k++)
        for (int jj = 0; jj < nj; jj++)
            for (int i = d->lo[0]; i < d->hi[0]; i++) {
                size_t c = i + (size_t)d->n[0] * (jj + d->lo[1] + (size_t)d->n[1] * k);
                s += v[c] * v[c];
            }
    sum_over(d, &s, 1);
    return sqrt(s);
}

hv_status hv__dist_march(hv_dist_box *d, const hv_distance_opts *o, double *w, double *u,
                         double *u2, uint8_t *inside, uint8_t *ok, float *ref, float *out,
                         hv_distance_stats *S)
{
    hv_status st = HV_OK;
    double t0 = hv_now();
    double counts[2] = {(double)init_faces(d), 0};
    sum_over(d, counts, 1);
    size_t open = (size_t)counts[0], left = open;
    S->t_splat += hv_now() - t0;

    /* Stages: diffuse from the current front; trust the faces where u is above the
     * solve's error bound; the next front is a level set of u a margin inside the
     * trusted zone, beyond the current front (a wavefront of the distance, so by
     * Huygens' principle its own distance field continues the source's). */
    d->tau[0] = 1.0 / o->t_scale;
    d->tau[1] = 1.0 / (o->t_scale * T_RATIO);
    int idle = 0;
    for (int l = 0; l < o->max_stages && left > 0; l++) {
        /* the share of open faces with a direction: how far the stages have got */
        if (d->whole &&
            (st = hv__progress(0.05 + 0.6 * (double)(open - left) / (double)open, "diffuse")))
            return st;
        t0 = hv_now();
        hv_solve_info info[2];
        for (int q = 0; q < 2; q++) {
            if ((st = d->hk->solve(d->hk->user, q, w, q ? u2 : u, &info[q])))
                return st;
            S->diffuse_iterations += info[q].iterations;
            S->diffuse_relres = fmax(S->diffuse_relres, info[q].relres);
        }
        S->backend = info[0].backend;
        S->t_diffuse += hv_now() - t0;
        t0 = hv_now();
        double wn = norm2(d, w);
        double lthr = hv__dist_trust_log(fmax(info[0].relres, o->diffuse_tol), wn, o->t_scale);
        double lthr2 =
            hv__dist_trust_log(fmax(info[1].relres, o->diffuse_tol), wn, o->t_scale * T_RATIO);
#pragma omp parallel for schedule(static)
        for (size_t c = 0; c < d->count; c++) {
            double l1 = u[c] > 0 ? log(u[c]) : -INFINITY, l2 = u2[c] > 0 ? log(u2[c]) : -INFINITY;
            ok[c] = d->region[c] >= 0 && l1 > lthr && l2 > lthr2;
            u[c] = l1;
            u2[c] = ok[c] ? l1 - l2 : -INFINITY;
        }
        size_t got = 0;
        left = assign_faces(d, u2, ok, &got);
        counts[0] = (double)left;
        counts[1] = (double)got;
        sum_over(d, counts, 2);
        left = (size_t)counts[0];
        got = (size_t)counts[1];
        if (l < 8)
            S->faces_per_stage[l] = got;
        S->stages = l + 1;
        idle = got ? 0 : idle + 1;
        if (idle == 2) /* two stages without a new face: the rest is out of reach */
            break;
        if (left && !next_front(d, u2, u, ok, lthr, inside, w))
            break;
        S->t_normalize += hv_now() - t0;
    }
    S->dead_faces = left;
    if (left)
        for (int a = 0; a < d->dim; a++)
            for (size_t f = 0; f < d->nface[a]; f++)
                if (isnan(d->X[a][f]))
                    d->X[a][f] = 0;

    /* Poisson: -Lap phi = -div X, then shift each region so its sources sit at 0. */
    t0 = hv_now();
    if (d->whole && (st = hv__progress(0.7, "poisson")))
        return st;
    divergence(d, w);
    hv_solve_info pinfo;
    if ((st = d->hk->solve(d->hk->user, 2, w, u, &pinfo)))
        return st;
    S->poisson_iterations = pinfo.iterations;
    S->poisson_relres = pinfo.relres;
    S->t_poisson = hv_now() - t0;

    /* The Poisson solve rounds the cone at a source off over a voxel or two: fit
     * the offset on the shell 1.5h..3h around the sources, where phi should be the
     * distance to the nearest source item (cells closer count a thousandth, so that
     * a grid too small for a shell still gets an offset). */
    double *num = calloc(2 * S->regions + 1, sizeof *num);
    if (!num)
        st = hv__error(HV_ERR_NOMEM, "distance: out of memory");
    if (!d->whole) { /* every rank sums, or none does */
        double bad = st != HV_OK;
        sum_over(d, &bad, 1);
        if (bad > 0) {
            free(num);
            return st ? st : hv__error(HV_ERR_NOMEM, "distance: out of memory on another rank");
        }
    } else if (st) {
        return st;
    }
    for (int k = d->lo[2]; k < d->hi[2]; k++)
        for (int j = d->lo[1]; j < d->hi[1]; j++)
            for (int i = d->lo[0]; i < d->hi[0]; i++) {
                size_t c = i + (size_t)d->n[0] * (j + (size_t)d->n[1] * k);
                if (ref[c] <= HV_DIST_REF_RADIUS * d->h && d->region[c] >= 0) {
                    double wt = ref[c] >= 1.5 * d->h ? 1.0 : 1e-3;
                    num[2 * d->region[c]] += wt * (u[c] - ref[c]);
                    num[2 * d->region[c] + 1] += wt;
                }
            }
    sum_over(d, num, (int)(2 * S->regions));
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < d->count; c++) {
        int32_t r = d->region[c];
        if (r >= 0) {
            double v = u[c] - num[2 * r] / num[2 * r + 1];
            out[c] = (float)(v > 0 ? v : 0);
        } else {
            out[c] = r == -1 ? o->solid_value : o->unreachable;
        }
    }
    free(num);
    return HV_OK;
}

/* ---- one process, the whole grid ------------------------------------------ */

typedef struct local_solves {
    const dist_ctx *d;
    const hv_distance_opts *o;
    hv_solver *sv[3]; /* the two heat steps, then Poisson */
    double t;
    int restarts; /* of the Poisson solve */
} local_solves;

/* Poisson, with restarts (defect correction) on the residual, a guard: CG
 * with a preconditioner that is not symmetric stalls near 3e-2 in long
 * corridors; with the symmetric cycle (P^T restriction, reversed
 * post-smoothing) every test scene (serpentine and maze included) converges
 * without one, and check_distance asserts that. */
static hv_status local_poisson(local_solves *L, const double *rhs, double *u, hv_solve_info *info)
{
    const dist_ctx *d = L->d;
    hv_solver_destroy(&L->sv[0]);
    hv_solver_destroy(&L->sv[1]);
    hv_status st =
        hv__dist_solver(&L->sv[2], d->dim, d->n, d->h, d->solid, 0.0, 1.0, L->o->poisson_tol,
                        L->o->backend, hv__dist_poisson_coarse(L->o, d->solid));
    if (st || (st = hv_solver_solve_d(L->sv[2], rhs, u, info)))
        return st;
    double fn = norm2(d, rhs), rel = info->relres;
    int its = info->iterations, restarts = 0;
    double *Au = NULL;
    for (int rs = 0; rel > L->o->poisson_tol && rs < 30; rs++) {
        if (!Au && !(Au = hv_malloc(2 * d->count * sizeof *Au)))
            return hv__error(HV_ERR_NOMEM, "distance: out of memory for the Poisson restarts");
        double *r = Au + d->count;
        hv_apply_helmholtz_d(d->dim, d->n, d->h, d->solid, 0.0, 1.0, u, Au);
#pragma omp parallel for schedule(static)
        for (size_t c = 0; c < d->count; c++)
            r[c] = d->region[c] >= 0 ? rhs[c] - Au[c] : 0.0;
        rel = fn > 0 ? norm2(d, r) / fn : 0;
        if (rel <= L->o->poisson_tol)
            break;
        if ((st = hv_solver_solve_d(L->sv[2], r, Au, info)))
            break;
#pragma omp parallel for schedule(static)
        for (size_t c = 0; c < d->count; c++)
            u[c] += Au[c];
        its += info->iterations;
        restarts++;
    }
    hv_free(Au);
    info->iterations = its;
    L->restarts = restarts;
    info->relres = rel;
    return st;
}

static hv_status local_solve(void *user, int q, const double *f, double *u, hv_solve_info *info)
{
    local_solves *L = user;
    if (q == 2)
        return local_poisson(L, f, u, info);
    hv_status st;
    if (!L->sv[q] && (st = hv__dist_solver(&L->sv[q], L->d->dim, L->d->n, L->d->h, L->d->solid, 1.0,
                                           L->t * (q ? T_RATIO : 1), L->o->diffuse_tol,
                                           L->o->backend, L->o->coarse)))
        return st;
    return hv_solver_solve_d(L->sv[q], f, u, info);
}

hv_status hv_distance_compute(hv_grid *g, const hv_distance_sources *src,
                              const hv_distance_opts *opts, hv_distance_stats *stats)
{
    double t_start = hv_now();
    if (!g || !src)
        return hv__error(HV_ERR_INVALID_ARG, "hv_distance_compute: NULL argument");
    hv_distance_opts o;
    if (opts)
        o = *opts;
    else
        hv_distance_opts_default(&o);
    hv_status st = hv__dist_check_opts(&o, src);
    if (st)
        return st;
    hv_distance_stats lst;
    hv_distance_stats *S = stats ? stats : &lst;
    memset(S, 0, sizeof *S);

    dist_ctx d = {0};
    hv__dist_box_init(&d, g->dim, g->n, g->h, g->solid);
    d.whole = 1;
    /* The backend, chosen here once for every solve: AUTO on a GPU runs the
     * pipeline on the device, as an explicit opencl does. */
    o.backend = hv_backend_resolve(o.backend, d.count, g->solid != NULL);
    if ((st = hv_check_dims(d.dim, d.n, d.h, 2 * sizeof(double) + 3 * sizeof(float) + 4)))
        return st;

    double *w = hv_calloc(d.count, sizeof *w), *u = hv_malloc(d.count * sizeof *u);
    double *u2 = hv_malloc(d.count * sizeof *u2);
    uint8_t *inside = calloc(d.count, 1), *ok = malloc(d.count);
    float *ref = hv_malloc(d.count * sizeof *ref);
    local_solves L = {&d, &o, {NULL, NULL, NULL}, 0, 0};
    const hv_dist_hooks hk = {&L, NULL, local_solve};
    d.hk = &hk;
    if (!w || !u || !u2 || !inside || !ok || !ref) {
        st = hv__error(HV_ERR_NOMEM, "distance: out of memory for a %d x %d x %d grid", d.n[0],
                       d.n[1], d.n[2]);
        goto done;
    }
    for (int a = 0; a < d.dim; a++)
        if (!(d.X[a] = hv_malloc(d.nface[a] * sizeof(float)))) {
            st = hv__error(HV_ERR_NOMEM, "distance: out of memory for face arrays");
            goto done;
        }

    /* Sources. */
    double t0 = hv_now();
    for (size_t c = 0; c < d.count; c++)
        ref[c] = INFINITY;
    if ((st = hv__dist_splat(g, NULL, src, w, ref, &S->sources_in_solid)))
        goto done;
    for (size_t c = 0; c < d.count; c++)
        S->source_cells += w[c] > 0;
    if ((st = hv__dist_no_source(S)))
        goto done;
    if ((st = label_regions(&d, w, &S->regions, &S->unreachable_cells)))
        goto done;
    double sq = sqrt(o.t_scale) * d.h;
    S->t = L.t = sq * sq;
    S->t_splat = hv_now() - t0;
    if (o.backend == HV_BACKEND_OPENCL) { /* the rest on the device (fp64 devices) */
        int handled = 0;
        st = hv__distance_heat_cl(g, &o, d.region, S->regions, w, ref, S, &handled);
        if (st || handled)
            goto done;
    }
    st = hv__dist_march(&d, &o, w, u, u2, inside, ok, ref, g->v, S);
    S->poisson_restarts = L.restarts;

done:
    for (int q = 0; q < 3; q++)
        hv_solver_destroy(&L.sv[q]);
    hv_free(w);
    hv_free(u);
    hv_free(u2);
    free(inside);
    free(ok);
    hv_free(ref);
    for (int a = 0; a < 3; a++)
        hv_free(d.X[a]);
    free(d.region);
    S->t_total = hv_now() - t_start;
    return st;
}

hv_status hv__dist_check_opts(const hv_distance_opts *o, const hv_distance_sources *src)
{
    if (!(o->t_scale > 0) || !isfinite(o->t_scale))
        return hv__error(HV_ERR_INVALID_ARG, "distance: t_scale must be positive, got %g",
                         o->t_scale);
    if (o->max_stages < 1)
        return hv__error(HV_ERR_INVALID_ARG, "distance: max_stages must be >= 1, got %d",
                         o->max_stages);
    if ((src->nvoxels && !src->voxels) || (src->npoints && !src->points))
        return hv__error(HV_ERR_INVALID_ARG, "distance: source counts given without arrays");
    return HV_OK;
}

hv_status hv__dist_no_source(const hv_distance_stats *S)
{
    if (S->source_cells)
        return HV_OK;
    return hv__error(HV_ERR_INVALID_ARG,
                     "distance: no source lands on a fluid cell (%zu in solid cells)",
                     S->sources_in_solid);
}
