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

typedef struct dist_ctx {
    int dim, n[3];
    size_t count, cs[3]; /* cells, cell strides */
    double h;
    const uint8_t *solid;
    double tau[2];   /* h^2 / t of the two diffusion times */
    int32_t *region; /* >= 0: region with a source; -1 solid; -2 fluid without source */
    float *X[3];     /* face directions; NaN = not assigned yet */
    size_t nface[3];
} dist_ctx;

static size_t face_index(const dist_ctx *d, int a, int i, int j, int k)
{
    int m0 = d->n[0] + (a == 0), m1 = d->n[1] + (a == 1);
    return i + (size_t)m0 * (j + (size_t)m1 * k);
}

static int fluid(const dist_ctx *d, size_t c) { return !d->solid || !d->solid[c]; }

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
 * of open faces. */
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
                            open++;
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
 * of open faces still unassigned. */
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
                    size_t R = i + (size_t)d->n[0] * (j + (size_t)d->n[1] * k), L = R - d->cs[a];
                    if (!(ok[L] && ok[R])) {
                        left++;
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
                    done++;
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
 * of front cells (0: no progress possible). */
static size_t next_front(const dist_ctx *d, const double *psi, const double *lu, const uint8_t *ok,
                         double lthr, uint8_t *inside, double *w)
{
    double s0 = 0, s1 = 0, sw = 0;
    for (size_t c = 0; c < d->count; c++)
        if (w[c] > 0 && ok[c]) {
            s0 += w[c] * psi[c];
            s1 += w[c] * lu[c];
            sw += w[c];
        }
    if (!(sw > 0))
        return 0;
    const double psi0 = s0 / sw, lu0 = s1 / sw;
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
                            nf++;
                        }
                        if (e <= step)
                            inside[c] = 1;
                    }
                }
                w[c] = v;
            }
    return nf;
}

static hv_status make_solver(hv_solver **s, const dist_ctx *d, double alpha, double beta,
                             double tol, hv_backend backend)
{
    hv_problem p = {d->dim, {d->n[0], d->n[1], d->n[2]}, d->h, d->solid, alpha, beta};
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = backend;
    o.tol = tol;
    o.max_iter = 200;
    return hv_solver_create(s, &p, &o);
}

static double norm2(const double *v, size_t n)
{
    double s = 0;
#pragma omp parallel for reduction(+ : s) schedule(static)
    for (size_t c = 0; c < n; c++)
        s += v[c] * v[c];
    return sqrt(s);
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
    if (!(o.t_scale > 0) || !isfinite(o.t_scale))
        return hv__error(HV_ERR_INVALID_ARG, "distance: t_scale must be positive, got %g",
                         o.t_scale);
    if (o.max_stages < 1)
        return hv__error(HV_ERR_INVALID_ARG, "distance: max_stages must be >= 1, got %d",
                         o.max_stages);
    if ((src->nvoxels && !src->voxels) || (src->npoints && !src->points))
        return hv__error(HV_ERR_INVALID_ARG, "distance: source counts given without arrays");
    hv_distance_stats lst;
    hv_distance_stats *S = stats ? stats : &lst;
    memset(S, 0, sizeof *S);

    dist_ctx d = {0};
    d.dim = g->dim;
    memcpy(d.n, g->n, sizeof d.n);
    d.h = g->h;
    d.count = hv_grid_count(g);
    /* AUTO on a GPU: the pipeline on the device, as for an explicit opencl. */
    if (hv_backend_resolve(o.backend, d.count, g->solid != NULL) == HV_BACKEND_OPENCL)
        o.backend = HV_BACKEND_OPENCL;
    d.cs[0] = 1;
    d.cs[1] = (size_t)d.n[0];
    d.cs[2] = (size_t)d.n[0] * d.n[1];
    d.solid = g->solid;
    hv_status st = hv_check_dims(d.dim, d.n, d.h, 2 * sizeof(double) + 3 * sizeof(float) + 4);
    if (st)
        return st;

    double *w = hv_calloc(d.count, sizeof *w), *u = hv_malloc(d.count * sizeof *u);
    double *u2 = hv_malloc(d.count * sizeof *u2);
    uint8_t *inside = calloc(d.count, 1), *ok = malloc(d.count);
    float *ref = hv_malloc(d.count * sizeof *ref);
    hv_solver *sv[2] = {NULL, NULL};
    if (!w || !u || !u2 || !inside || !ok || !ref) {
        st = hv__error(HV_ERR_NOMEM, "distance: out of memory for a %d x %d x %d grid", d.n[0],
                       d.n[1], d.n[2]);
        goto done;
    }
    for (int a = 0; a < d.dim; a++) {
        d.nface[a] = (size_t)(d.n[0] + (a == 0)) * (d.n[1] + (a == 1)) * (d.n[2] + (a == 2));
        if (!(d.X[a] = hv_malloc(d.nface[a] * sizeof(float)))) {
            st = hv__error(HV_ERR_NOMEM, "distance: out of memory for face arrays");
            goto done;
        }
    }

    /* Sources. */
    double t0 = hv_now();
    for (size_t c = 0; c < d.count; c++)
        ref[c] = INFINITY;
    if ((st = hv__dist_splat(g, src, w, ref, &S->sources_in_solid)))
        goto done;
    for (size_t c = 0; c < d.count; c++)
        S->source_cells += w[c] > 0;
    if (!S->source_cells) {
        st = hv__error(HV_ERR_INVALID_ARG,
                       "distance: no source lands on a fluid cell (%zu in solid "
                       "cells)",
                       S->sources_in_solid);
        goto done;
    }
    if ((st = label_regions(&d, w, &S->regions, &S->unreachable_cells)))
        goto done;
    double sq = sqrt(o.t_scale) * d.h;
    S->t = sq * sq;
    if (o.backend == HV_BACKEND_OPENCL) { /* the rest on the device (fp64 devices) */
        int handled = 0;
        S->t_splat = hv_now() - t0;
        st = hv__distance_heat_cl(g, &o, d.region, S->regions, w, ref, S, &handled);
        if (st || handled)
            goto done;
    }
    size_t open = init_faces(&d), left = open;
    S->t_splat = hv_now() - t0;

    /* Stages: diffuse from the current front; trust the faces where u is above the
     * solve's error bound; the next front is a level set of u a margin inside the
     * trusted zone, beyond the current front (a wavefront of the distance, so by
     * Huygens' principle its own distance field continues the source's). */
    d.tau[0] = 1.0 / o.t_scale;
    d.tau[1] = 1.0 / (o.t_scale * T_RATIO);
    int idle = 0;
    for (int l = 0; l < o.max_stages && left > 0; l++) {
        /* the share of open faces with a direction: how far the stages have got */
        if ((st = hv__progress(0.05 + 0.6 * (double)(open - left) / (double)open, "diffuse")))
            goto done;
        t0 = hv_now();
        hv_solve_info info[2];
        for (int q = 0; q < 2; q++) {
            if (!sv[q] && (st = make_solver(&sv[q], &d, 1.0, S->t * (q ? T_RATIO : 1),
                                            o.diffuse_tol, o.backend)))
                goto done;
            if ((st = hv_solver_solve_d(sv[q], w, q ? u2 : u, &info[q])))
                goto done;
            S->diffuse_iterations += info[q].iterations;
            S->diffuse_relres = fmax(S->diffuse_relres, info[q].relres);
        }
        S->backend = info[0].backend;
        S->t_diffuse += hv_now() - t0;
        t0 = hv_now();
        double wn = norm2(w, d.count);
        double lthr = hv__dist_trust_log(fmax(info[0].relres, o.diffuse_tol), wn, o.t_scale);
        double lthr2 =
            hv__dist_trust_log(fmax(info[1].relres, o.diffuse_tol), wn, o.t_scale * T_RATIO);
#pragma omp parallel for schedule(static)
        for (size_t c = 0; c < d.count; c++) {
            double l1 = u[c] > 0 ? log(u[c]) : -INFINITY, l2 = u2[c] > 0 ? log(u2[c]) : -INFINITY;
            ok[c] = d.region[c] >= 0 && l1 > lthr && l2 > lthr2;
            u[c] = l1;
            u2[c] = ok[c] ? l1 - l2 : -INFINITY;
        }
        size_t got = 0;
        left = assign_faces(&d, u2, ok, &got);
        if (l < 8)
            S->faces_per_stage[l] = got;
        S->stages = l + 1;
        idle = got ? 0 : idle + 1;
        if (idle == 2) /* two stages without a new face: the rest is out of reach */
            break;
        if (left && !next_front(&d, u2, u, ok, lthr, inside, w))
            break;
        S->t_normalize += hv_now() - t0;
    }
    S->dead_faces = left;
    if (left)
        for (int a = 0; a < d.dim; a++)
            for (size_t f = 0; f < d.nface[a]; f++)
                if (isnan(d.X[a][f]))
                    d.X[a][f] = 0;

    /* Poisson: -Lap phi = -div X, then shift each region so its sources sit at 0. */
    t0 = hv_now();
    hv_solver_destroy(&sv[0]);
    hv_solver_destroy(&sv[1]);
    if ((st = hv__progress(0.7, "poisson")))
        goto done;
    double *rhs = hv_malloc(d.count * sizeof *rhs);
    if (!rhs) {
        st = hv__error(HV_ERR_NOMEM, "distance: out of memory for the Poisson right-hand side");
        goto done;
    }
    divergence(&d, rhs);
    if ((st = make_solver(&sv[0], &d, 0.0, 1.0, o.poisson_tol, o.backend))) {
        hv_free(rhs);
        goto done;
    }
    hv_solve_info pinfo;
    st = hv_solver_solve_d(sv[0], rhs, u, &pinfo);
    S->poisson_iterations = pinfo.iterations;
    /* Restarts (defect correction) on the residual, a guard: before the
     * multigrid preconditioner was made symmetric (P^T restriction, reversed
     * post-smoothing) CG stalled near 3e-2 in long corridors; now every test
     * scene (serpentine and maze included) converges without one, and
     * check_distance asserts that. */
    double fn = norm2(rhs, d.count), rel = pinfo.relres;
    for (int rs = 0; !st && rel > o.poisson_tol && rs < 30; rs++) {
        double *Au = u2, *r = w;
        hv_apply_helmholtz_d(d.dim, d.n, d.h, d.solid, 0.0, 1.0, u, Au);
#pragma omp parallel for schedule(static)
        for (size_t c = 0; c < d.count; c++)
            r[c] = d.region[c] >= 0 ? rhs[c] - Au[c] : 0.0;
        rel = fn > 0 ? norm2(r, d.count) / fn : 0;
        if (rel <= o.poisson_tol)
            break;
        if ((st = hv_solver_solve_d(sv[0], r, Au, &pinfo)))
            break;
#pragma omp parallel for schedule(static)
        for (size_t c = 0; c < d.count; c++)
            u[c] += Au[c];
        S->poisson_iterations += pinfo.iterations;
        S->poisson_restarts++;
    }
    hv_free(rhs);
    hv_solver_destroy(&sv[0]);
    if (st)
        goto done;
    S->poisson_relres = rel;
    S->t_poisson = hv_now() - t0;

    double *num = calloc(2 * S->regions, sizeof *num);
    if (!num) {
        st = hv__error(HV_ERR_NOMEM, "distance: out of memory");
        goto done;
    }
    /* The Poisson solve rounds the cone at a source off over a voxel or two: fit
     * the offset on the shell 1.5h..3h around the sources, where phi should be the
     * distance to the nearest source item (cells closer count a thousandth, so that
     * a grid too small for a shell still gets an offset). */
    for (size_t c = 0; c < d.count; c++)
        if (ref[c] <= HV_DIST_REF_RADIUS * d.h && d.region[c] >= 0) {
            double wt = ref[c] >= 1.5 * d.h ? 1.0 : 1e-3;
            num[2 * d.region[c]] += wt * (u[c] - ref[c]);
            num[2 * d.region[c] + 1] += wt;
        }
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < d.count; c++) {
        int32_t r = d.region[c];
        if (r >= 0) {
            double v = u[c] - num[2 * r] / num[2 * r + 1];
            g->v[c] = (float)(v > 0 ? v : 0);
        } else {
            g->v[c] = r == -1 ? o.solid_value : o.unreachable;
        }
    }
    free(num);

done:
    hv_solver_destroy(&sv[0]);
    hv_solver_destroy(&sv[1]);
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
