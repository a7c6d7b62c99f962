/* The stages of the heat-method distance (distance_internal.h; docs/METHOD.md,
 * "Heat method"): on a box (the whole grid, or a rank's box on a DMDA), each
 * stage diffuses from the current front, assigns the face directions where the
 * heat is trusted and places the next front; then the Poisson solve and the
 * shift. A stage's loops run over its tiles (distance_band.c): in band mode
 * the tiles near the front, whose heat steps distance_band.c solves, and
 * otherwise every tile of the box, with the solves by the hooks. */
#include "distance_internal.h"
#include "core/error.h"
#include "heatvox/ops.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

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
hv_status hv__dist_label_regions(dist_ctx *d, const double *w, size_t *nregions, size_t *unreach)
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
 * psi = ln u(t) - ln u(T_RATIO t): X = -grad psi / |grad psi|, the face's own
 * difference normalized with the mean of the open, trusted transverse face
 * differences around it. Differences of logarithms, not of u: u falls like
 * e^{-r/sqrt t}, and for an exponential a face difference (span h) and a mean
 * of transverse differences (span 2h) disagree by O(h^2/t) (3% on diagonals
 * at t = 2h^2: distances 3% short); ln u is nearly linear. Returns the number
 * of open faces still unassigned (of those init_faces counts). */
static void assign_face(dist_ctx *d, const double *u, const uint8_t *ok, int a, int i, int j, int k)
{
    size_t R = i + (size_t)d->n[0] * (j + (size_t)d->n[1] * k), L = R - d->cs[a];
    double D[3] = {0, 0, 0};
    D[a] = u[L] - u[R];
    int ijkR[3] = {i, j, k}, ijkL[3] = {i, j, k};
    ijkL[a]--;
    for (int b = 0; b < d->dim; b++) {
        if (b == a)
            continue;
        double s = 0;
        int m = transverse(d, u, ok, L, ijkL, b, &s) + transverse(d, u, ok, R, ijkR, b, &s);
        if (m)
            D[b] = -s / m;
    }
    double dn = 0;
    for (int b = 0; b < d->dim; b++)
        dn += D[b] * D[b];
    d->X[a][face_index(d, a, i, j, k)] = dn > 0 ? (float)(D[a] / sqrt(dn)) : 0.0f;
}

/* Assigns the unassigned open faces whose cells are both trusted; a face is
 * visited from its upper cell, in the core tiles (every trusted cell is in
 * one). Returns the number assigned whose upper cell is owned. */
static size_t assign_faces(dist_ctx *d, const double *u, const uint8_t *ok)
{
    const hv_dist_tiles *T = &d->tl;
    size_t done = 0;
#pragma omp parallel for schedule(dynamic, 16) reduction(+ : done)
    for (size_t q = 0; q < T->ncore; q++) {
        int lo[3], len[3], here = 0;
        hv__dist_tile_cells(d, T->list[q], lo, len);
        for (int k = lo[2]; k < lo[2] + len[2]; k++)
            for (int j = lo[1]; j < lo[1] + len[1]; j++)
                for (int i = lo[0]; i < lo[0] + len[0]; i++) {
                    size_t R = i + d->cs[1] * j + d->cs[2] * k;
                    if (!ok[R])
                        continue;
                    const int ijk[3] = {i, j, k};
                    for (int a = 0; a < d->dim; a++)
                        if (ijk[a] > 0 && ok[R - d->cs[a]] &&
                            isnan(d->X[a][face_index(d, a, i, j, k)])) {
                            assign_face(d, u, ok, a, i, j, k);
                            done += owned(d, i, j, k);
                            here++;
                        }
                }
        if (T->band)
            T->open_faces[T->list[q]] -= here;
    }
    return done;
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

/* Builds the next front. psi = ln u(t) - ln u(T_RATIO t) on trusted cells (ok) falls
 * by kappa(t) - kappa(T_RATIO t) per voxel travelled away from the current front, with
 * the amplitude cancelled; on the lattice kappa depends on the direction nu of
 * travel, so the distance travelled is e = (psi0 - psi) / (kappa1(nu) -
 * kappa2(nu)), psi0 its value on the current front (weights w). Using e rather
 * than a level set of u keeps the fronts round: a level set of u is a ball of
 * the lattice's own metric (1% flat on the diagonals at t = 2h^2), and fronts
 * built on fronts would compound that. The new front sits at e = step voxels,
 * FRONT_MARGIN below the trust bound lthr of ln u(t); cells with e <= step join
 * the inside; w is overwritten with the new front's weights. Returns the number
 * of front cells (owned; 0: no progress possible). */
/* Sums over the owned cells of the current front (w > 0, trusted) of w psi,
 * w lu and w, over the core tiles (the front's tiles are core). */
static void front_sums(const dist_ctx *d, const double *psi, const double *lu, const uint8_t *ok,
                       const double *w, double s[3])
{
    const hv_dist_tiles *T = &d->tl;
    double a = 0, b = 0, c = 0;
#pragma omp parallel for schedule(dynamic, 16) reduction(+ : a, b, c)
    for (size_t q = 0; q < T->ncore; q++) {
        int lo[3], len[3];
        hv__dist_tile_cells(d, T->list[q], lo, len);
        for (int k = lo[2]; k < lo[2] + len[2]; k++)
            for (int j = lo[1]; j < lo[1] + len[1]; j++)
                for (int i = lo[0]; i < lo[0] + len[0]; i++) {
                    size_t x = i + d->cs[1] * j + d->cs[2] * k;
                    if (w[x] > 0 && ok[x] && owned(d, i, j, k)) {
                        a += w[x] * psi[x];
                        b += w[x] * lu[x];
                        c += w[x];
                    }
                }
    }
    s[0] = a;
    s[1] = b;
    s[2] = c;
}

/* Where the next front goes: psi on the current front, the step, and bounds
 * on kappa(t) - kappa(T_RATIO t) over every direction of travel. */
typedef struct front_rule {
    double psi0, step, dk_lo, dk_hi;
} front_rule;

/* kappa(t) - kappa(T_RATIO t) along the axis and the diagonals (the lattice's
 * extremes), widened by 2%: a cell whose distance travelled lies off the
 * front's band for every value between them needs no Newton solve. */
static void front_bounds(const dist_ctx *d, front_rule *F)
{
    const double r2 = sqrt(0.5), r3 = sqrt(1.0 / 3);
    const double nus[3][3] = {{1, 0, 0}, {r2, r2, 0}, {r3, r3, r3}};
    F->dk_lo = INFINITY;
    F->dk_hi = 0;
    for (int q = 0; q < d->dim; q++) {
        double dk = hv__dist_lattice_kappa(nus[q], d->dim, d->tau[0]) -
                    hv__dist_lattice_kappa(nus[q], d->dim, d->tau[1]);
        F->dk_lo = fmin(F->dk_lo, dk);
        F->dk_hi = fmax(F->dk_hi, dk);
    }
    F->dk_lo *= 0.98;
    F->dk_hi *= 1.02;
}

/* Cell c of the next front: its weight (0 off the front), and whether it
 * joins the inside (e <= step). */
static double front_weight(const dist_ctx *d, const double *psi, const uint8_t *ok, size_t c,
                           const int ijk[3], const front_rule *F, int *in)
{
    const double psi0 = F->psi0, step = F->step;
    double nu[3] = {0, 0, 0}, nn = 0;
    for (int b = 0; b < d->dim; b++) {
        double s = 0;
        int m = transverse(d, psi, ok, c, ijk, b, &s);
        nu[b] = m ? -s / m : 0;
        nn += nu[b] * nu[b];
    }
    *in = 0;
    if (!(nn > 0))
        return 0;
    const double num = psi0 - psi[c];
    const double e_lo = num / (num >= 0 ? F->dk_hi : F->dk_lo),
                 e_hi = num / (num >= 0 ? F->dk_lo : F->dk_hi);
    if (e_hi < step - FRONT_BAND) { /* inside, off the front's band, whatever the direction */
        *in = 1;
        return 0;
    }
    if (e_lo > step + FRONT_BAND)
        return 0;
    nn = sqrt(nn);
    for (int b = 0; b < d->dim; b++)
        nu[b] = fabs(nu[b]) / nn;
    double dk = hv__dist_lattice_kappa(nu, d->dim, d->tau[0]) -
                hv__dist_lattice_kappa(nu, d->dim, d->tau[1]);
    double e = (psi0 - psi[c]) / dk, s = (e - step) / FRONT_BAND;
    *in = e <= step;
    return fabs(s) < 1 ? (1 - s * s) * (1 - s * s) : 0;
}

/* The new front's weights on the cells of core tile q (w is 0 beyond the core
 * tiles: the current front's cells are in them); in band mode the tile's
 * front flag and its count of cells not yet inside. Returns the owned front
 * cells. */
static size_t front_tile(dist_ctx *d, size_t q, const double *psi, const uint8_t *ok,
                         const front_rule *F, uint8_t *inside, double *w)
{
    hv_dist_tiles *T = &d->tl;
    int lo[3], len[3], any = 0;
    hv__dist_tile_cells(d, T->list[q], lo, len);
    size_t nf = 0;
    for (int k = lo[2]; k < lo[2] + len[2]; k++)
        for (int j = lo[1]; j < lo[1] + len[1]; j++)
            for (int i = lo[0]; i < lo[0] + len[0]; i++) {
                size_t c = i + d->cs[1] * j + d->cs[2] * k;
                double v = 0;
                if (!inside[c] && ok[c]) {
                    const int ijk[3] = {i, j, k};
                    int in;
                    v = front_weight(d, psi, ok, c, ijk, F, &in);
                    if (in)
                        inside[c] = 1;
                    if (v > 0) {
                        nf += owned(d, i, j, k);
                        any = 1;
                    }
                }
                w[c] = v;
            }
    if (T->band)
        T->front[T->list[q]] = (uint8_t)any;
    return nf;
}

static size_t next_front(dist_ctx *d, const double *psi, const double *lu, const uint8_t *ok,
                         double lthr, uint8_t *inside, double *w)
{
    double s[3];
    front_sums(d, psi, lu, ok, w, s);
    sum_over(d, s, 3);
    if (!(s[2] > 0))
        return 0;
    const double psi0 = s[0] / s[2], lu0 = s[1] / s[2];
    const double full = hv__dist_front_step(lu0, lthr, d->dim, d->tau[0]);
    const double step = fmin(full, hv__dist_core_step(&d->tl));
    if (!(step >= 2))
        return 0;
    front_rule F = {psi0, step, 0, 0};
    front_bounds(d, &F);
    hv_dist_tiles *T = &d->tl;
    if (T->band && T->front)
        for (size_t q = 0; q < T->ncore; q++)
            T->front[T->list[q]] = 0;
    size_t nf = 0;
#pragma omp parallel for schedule(dynamic, 16) reduction(+ : nf)
    for (size_t q = 0; q < T->ncore; q++)
        nf += front_tile(d, q, psi, ok, &F, inside, w);
    if (T->band)
        hv__dist_core_next(T, full, d->dim, d->tau[0]);
    double fs = (double)nf;
    sum_over(d, &fs, 1);
    return (size_t)fs;
}

/* The 2-norm of v over the owned cells (and the ranks). */
/* The 2-norm of v over the owned cells of the core tiles (and the ranks):
 * the front weights' norm (they lie on core tiles). */
static double core_norm2(const dist_ctx *d, const double *v)
{
    const hv_dist_tiles *T = &d->tl;
    double s = 0;
#pragma omp parallel for schedule(dynamic, 16) reduction(+ : s)
    for (size_t q = 0; q < T->ncore; q++) {
        int lo[3], len[3];
        hv__dist_tile_cells(d, T->list[q], lo, len);
        for (int k = lo[2]; k < lo[2] + len[2]; k++)
            for (int j = lo[1]; j < lo[1] + len[1]; j++)
                for (int i = lo[0]; i < lo[0] + len[0]; i++)
                    if (owned(d, i, j, k)) {
                        double x = v[i + d->cs[1] * j + d->cs[2] * k];
                        s += x * x;
                    }
    }
    sum_over(d, &s, 1);
    return sqrt(s);
}

double hv__dist_norm2(const dist_ctx *d, const double *v)
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

/* The heat steps' tolerance: on the band tighter (DIST_BAND_TOL), so that the
 * trusted zone, and the step, reach further. */
static double stage_tol(const dist_ctx *d, const hv_distance_opts *o)
{
    return d->tl.band ? fmin(o->diffuse_tol, DIST_BAND_TOL) : o->diffuse_tol;
}

/* The stage's two heat steps: on the band, or by the hooks on the box. */
static hv_status stage_solve(dist_ctx *d, const hv_distance_opts *o, int l, const double *w,
                             double *u, double *u2, uint8_t *ok, hv_solve_info info[2],
                             hv_distance_stats *S)
{
    hv_status st;
    size_t cells = d->count;
    if (d->tl.band) {
        if ((st = hv__dist_band_select(d, ok)) ||
            (st = hv__dist_band_solve(d, w, u, u2, stage_tol(d, o), info)))
            return st;
        cells = hv__dist_band_cells(d);
    } else {
        for (int q = 0; q < 2; q++)
            if ((st = d->hk->solve(d->hk->user, q, w, q ? u2 : u, &info[q])))
                return st;
    }
    for (int q = 0; q < 2; q++) {
        S->diffuse_iterations += info[q].iterations;
        S->diffuse_relres = fmax(S->diffuse_relres, info[q].relres);
    }
    S->cells_solved += cells;
    if (l < 8)
        S->stage_cells[l] = cells;
    S->backend = info[0].backend;
    return HV_OK;
}

/* ok: the core tiles' cells where both heat steps are above their trust
 * bounds; u becomes ln u(t), u2 psi = ln u(t) - ln u(T_RATIO t) on trusted cells. */
static void stage_trust(dist_ctx *d, double *u, double *u2, uint8_t *ok, double lthr, double lthr2)
{
    const hv_dist_tiles *T = &d->tl;
#pragma omp parallel for schedule(dynamic, 16)
    for (size_t q = 0; q < T->ncore; q++) {
        int lo[3], len[3];
        hv__dist_tile_cells(d, T->list[q], lo, len);
        for (int k = lo[2]; k < lo[2] + len[2]; k++)
            for (int j = lo[1]; j < lo[1] + len[1]; j++) {
                size_t c = lo[0] + d->cs[1] * j + d->cs[2] * k;
                for (int i = 0; i < len[0]; i++, c++) {
                    double l1 = u[c] > 0 ? log(u[c]) : -INFINITY,
                           l2 = u2[c] > 0 ? log(u2[c]) : -INFINITY;
                    ok[c] = d->region[c] >= 0 && l1 > lthr && l2 > lthr2;
                    u[c] = l1;
                    u2[c] = ok[c] ? l1 - l2 : -INFINITY;
                }
            }
    }
}

hv_status hv__dist_stages(const hv_dist_stage_ops *ops, const hv_distance_opts *o, size_t open,
                          int progress, size_t *left_out, hv_distance_stats *S)
{
    size_t left = open;
    hv_status st = HV_OK;
    int idle = 0;
    for (int l = 0; l < o->max_stages && left > 0; l++) {
        /* the share of open faces with a direction: how far the stages have got */
        if (progress &&
            (st = hv__progress(0.05 + 0.6 * (double)(open - left) / (double)open, "diffuse")))
            break;
        double t0 = hv_now();
        hv_solve_info info[2];
        if ((st = ops->diffuse(ops->self, l, info, S)))
            break;
        S->t_diffuse += hv_now() - t0;
        t0 = hv_now();
        double lthr;
        size_t got;
        if ((st = ops->assign(ops->self, info, &lthr, &got, &left)))
            break;
        if (l < 8)
            S->faces_per_stage[l] = got;
        S->stages = l + 1;
        idle = got > 0 ? 0 : idle + 1;
        if (idle == 2) /* two stages without a new face: the rest is out of reach */
            break;
        int moved = 1;
        if (left && (st = ops->advance(ops->self, lthr, &moved, S)))
            break;
        if (!moved)
            break;
        S->t_normalize += hv_now() - t0;
    }
    *left_out = left;
    return st;
}

/* The host's stages: the box's fields and the open faces left. */
typedef struct host_stages {
    dist_ctx *d;
    const hv_distance_opts *o;
    double *w, *u, *u2;
    uint8_t *inside, *ok;
    size_t left;
} host_stages;

static hv_status host_diffuse(void *self, int l, hv_solve_info info[2], hv_distance_stats *S)
{
    host_stages *H = self;
    return stage_solve(H->d, H->o, l, H->w, H->u, H->u2, H->ok, info, S);
}

static hv_status host_assign(void *self, const hv_solve_info info[2], double *lthr, size_t *got,
                             size_t *left)
{
    host_stages *H = self;
    dist_ctx *d = H->d;
    const double tol = stage_tol(d, H->o), wn = core_norm2(d, H->w);
    *lthr = hv__dist_trust_log(fmax(info[0].relres, tol), wn, H->o->t_scale);
    const double lthr2 = hv__dist_trust_log(fmax(info[1].relres, tol), wn, H->o->t_scale * T_RATIO);
    stage_trust(d, H->u, H->u2, H->ok, *lthr, lthr2);
    double n = (double)assign_faces(d, H->u2, H->ok);
    sum_over(d, &n, 1);
    *got = (size_t)n;
    H->left -= *got;
    *left = H->left;
    return HV_OK;
}

static hv_status host_advance(void *self, double lthr, int *moved, hv_distance_stats *S)
{
    host_stages *H = self;
    *moved = next_front(H->d, H->u2, H->u, H->ok, lthr, H->inside, H->w) != 0;
    return HV_OK;
}

/* The stages on the host's box: the open faces set up, then the loop.
 * Returns the open faces left unassigned. */
static hv_status stages(dist_ctx *d, const hv_distance_opts *o, double *w, double *u, double *u2,
                        uint8_t *inside, uint8_t *ok, size_t *left_out, hv_distance_stats *S)
{
    double t0 = hv_now();
    double counts[1] = {(double)init_faces(d)};
    sum_over(d, counts, 1);
    S->t_splat += hv_now() - t0;
    d->tau[0] = 1.0 / o->t_scale;
    d->tau[1] = 1.0 / (o->t_scale * T_RATIO);
    if (d->tl.band)
        hv__dist_tiles_start(d, w);
    host_stages H = {d, o, w, u, u2, inside, ok, (size_t)counts[0]};
    const hv_dist_stage_ops ops = {&H, host_diffuse, host_assign, host_advance};
    return hv__dist_stages(&ops, o, H.left, d->whole, left_out, S);
}

static hv_status march(hv_dist_box *d, const hv_distance_opts *o, double *w, double *u, double *u2,
                       uint8_t *inside, uint8_t *ok, float *ref, float *out, hv_distance_stats *S)
{
    size_t left = 0;
    hv_status st = stages(d, o, w, u, u2, inside, ok, &left, S);
    if (st)
        return st;
    double t0;
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
    if (d->tl.band) /* the heat steps ran on the band: the backend is the Poisson solve's */
        S->backend = pinfo.backend;
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

hv_status hv__dist_march(hv_dist_box *d, const hv_distance_opts *o, double *w, double *u,
                         double *u2, uint8_t *inside, uint8_t *ok, float *ref, float *out,
                         hv_distance_stats *S)
{
    hv_status st = hv__dist_tiles_init(d, d->band);
    if (!st)
        st = march(d, o, w, u, u2, inside, ok, ref, out, S);
    hv__dist_tiles_free(&d->tl);
    return st;
}
