/*
 * Oriented point clouds to a closed surface (hv_points_surface, sdf.h): the
 * signed heat method with the points as its surface samples, the zero set
 * as a mesh, and the mesh's vertices moved onto the points.
 */
#include "sdf_internal.h"
#include "core/error.h"
#include "heatvox/vdb.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define PTS_K 6                            /* neighbours of the spacing estimate */
#define PTS_RINGS 4                        /* cell rings searched around a point */
#define PTS_FACING 0.5                     /* cosine above which a point faces a vertex's way */
#define PTS_HEAT_CELLS ((double)(1 << 22)) /* the heat grid's default bound */
#define PTS_NOISE_STRIDE 8                 /* every 8th cell of vertices measures the noise */
#define PTS_NOISE_FLOOR 0.1   /* a clean fit's residual, of sigma0 (bunny: 0.03-0.05) */
#define PTS_WIDEN 1.5         /* the kernel's width on noisy points, at most, of sigma0 */
#define PTS_FIT_NEFF 30.0     /* points a fit weighs, beyond which noise widens no kernel */
#define PTS_HEAT_ERR 0.05     /* the heat method's surface error, heat voxels */
#define PTS_MIN_RECOVER 4     /* points a recovered orientation needs, at least */
#define PTS_THIN_RAY 0.4      /* a thin part's rays' radius, block voxels, at least */
#define PTS_THIN_SHEET 0.5    /* a sheet's half thickness on them, block voxels, at least */
#define PTS_ROUNDS 4          /* heat rounds of a recovered orientation, at most */
#define PTS_FIT_SAMPLES 2048  /* candidates a vertex's fit weighs, at most */
#define PTS_LINES_SPREAD 0.25 /* median spread above which the line field gives directions */
#define PTS_LINES_T 0.25      /* the line field's heat step, of h^2 */
/* Peak memory of the surface beyond the cloud's own, measured (peak RSS of
 * heatvox sdf -o X.vdb on 1M and 2M points of the bunny at 64^3 and 256^3:
 * 130-150 bytes a point more with the normals given, 240-260 recovered),
 * with a margin: bytes a point, given or recovered orientation, and bytes a
 * cell of the heat grid. */
#define PTS_BYTES_GIVEN 160.0
#define PTS_BYTES_RECOVER 280.0
#define PTS_CELL_BYTES 60.0
#define PTS_ROUND_QUIET 1000 /* ... while more than one point in this many turns */

static double dist2(const double *a, const double *b)
{
    double d0 = a[0] - b[0], d1 = a[1] - b[1], d2 = a[2] - b[2];
    return d0 * d0 + d1 * d1 + d2 * d2;
}

/* Keeps the k smallest values of d2 in best (ascending), *m of them. */
static void keep_smallest(double *best, int *m, double d2)
{
    if (*m == PTS_K && d2 >= best[PTS_K - 1])
        return;
    int i = *m < PTS_K ? (*m)++ : PTS_K - 1;
    while (i > 0 && best[i - 1] > d2) {
        best[i] = best[i - 1];
        i--;
    }
    best[i] = d2;
}

/* The area point i stands for: pi d^2 / k, d its distance to the k-th
 * nearest neighbour (rings out until that is certain, or PTS_RINGS). */
static double point_area(const pt_bins *B, const hv_points *P, size_t i)
{
    const double *x = P->xyz + 3 * i;
    long q[3];
    hv__cell_of(B, x, q);
    double best[PTS_K];
    int m = 0;
    for (long r = 0; r <= PTS_RINGS; r++) {
        ring_iter it;
        uint32_t j;
        hv__ring_first(&it, q, r);
        while (hv__ring_next(B, &it, &j))
            if (j != i)
                keep_smallest(best, &m, dist2(x, P->xyz + 3 * (size_t)j));
        if (m == PTS_K && best[PTS_K - 1] <= (double)(r * r) * B->c * B->c)
            break;
    }
    if (m == PTS_K)
        return M_PI * best[PTS_K - 1] / PTS_K;
    const double reach = PTS_RINGS * B->c;
    return M_PI * reach * reach / (m + 1);
}

/* The k-th smallest of v[0..n) (v is reordered): Hoare's selection. */
static double select_kth(double *v, size_t n, size_t k)
{
    size_t lo = 0, hi = n - 1;
    while (lo < hi) {
        const double pivot = v[lo + (hi - lo) / 2];
        size_t i = lo, j = hi;
        while (i <= j) {
            while (v[i] < pivot)
                i++;
            while (v[j] > pivot)
                j--;
            if (i <= j) {
                double t = v[i];
                v[i] = v[j];
                v[j] = t;
                i++;
                if (j-- == 0)
                    break;
            }
        }
        if (k <= j)
            hi = j;
        else if (k >= i)
            lo = i;
        else
            break;
    }
    return v[k];
}

/* The points of the cells within `rings` rings around cell q into *buf
 * (grown as needed); their number, SIZE_MAX when out of memory. */
static size_t gather_block(const pt_bins *B, const long q[3], long rings, uint32_t **buf,
                           size_t *cap)
{
    size_t m = 0;
    for (long r = 0; r <= rings; r++) {
        ring_iter it;
        uint32_t j;
        hv__ring_first(&it, q, r);
        while (hv__ring_next(B, &it, &j)) {
            if (m == *cap) {
                size_t c = *cap ? 2 * *cap : 256;
                uint32_t *nb = realloc(*buf, c * sizeof *nb);
                if (!nb)
                    return SIZE_MAX;
                *buf = nb;
                *cap = c;
            }
            (*buf)[m++] = j;
        }
    }
    return m;
}

/* A thread's room for the k smallest squared distances of a cell's points. */
typedef struct knn_buf {
    double *best;
    int *found;
    size_t cap;
} knn_buf;

static int knn_reserve(knn_buf *K, size_t n)
{
    if (n <= K->cap)
        return 0;
    double *b = realloc(K->best, n * PTS_K * sizeof *b);
    if (b)
        K->best = b;
    int *f = b ? realloc(K->found, n * sizeof *f) : NULL;
    if (!f)
        return -1;
    K->found = f;
    K->cap = n;
    return 0;
}

/* The k nearest of the cell's points among the run of points from r0 (len
 * of them), in the sorted coordinates (relative to the bins' corner). */
static void knn_run(const pt_bins *B, uint32_t s0, uint32_t n0, uint32_t r0, uint32_t len,
                    knn_buf *K)
{
    for (uint32_t u = 0; u < n0; u++) {
        const float *x = B->sx + 3 * (size_t)(s0 + u);
        for (uint32_t v = 0; v < len; v++) {
            const float *y = B->sx + 3 * (size_t)(r0 + v);
            const float d0 = x[0] - y[0], d1 = x[1] - y[1], d2 = x[2] - y[2];
            if (r0 + v != s0 + u)
                keep_smallest(K->best + (size_t)u * PTS_K, &K->found[u],
                              (double)(d0 * d0 + d1 * d1 + d2 * d2));
        }
    }
}

/* The areas of the points in the cell of table slot t: the k nearest among
 * the 27 cells around it where that is certain (the k-th within a cell's
 * side), else point_area's search. Returns -1 when out of memory. */
static int cell_areas(const pt_bins *B, const hv_points *P, size_t t, knn_buf *K, double *area)
{
    long q[3];
    hv__slot_cell(B, t, q);
    const uint32_t s0 = B->start[t], n0 = B->len[t];
    if (knn_reserve(K, n0))
        return -1;
    memset(K->found, 0, n0 * sizeof *K->found);
    for (long d = 0; d < 27; d++) {
        uint32_t r0, len;
        if (hv__bins_find(B, hv__cell_key(q[0] + d % 3 - 1, q[1] + d / 3 % 3 - 1, q[2] + d / 9 - 1),
                          &r0, &len))
            knn_run(B, s0, n0, r0, len, K);
    }
    for (uint32_t u = 0; u < n0; u++) {
        const uint32_t i = B->order[s0 + u];
        const double kth = K->best[(size_t)u * PTS_K + PTS_K - 1];
        area[i] =
            K->found[u] == PTS_K && kth <= B->c * B->c ? M_PI * kth / PTS_K : point_area(B, P, i);
    }
    return 0;
}

/* 1. The areas, and the spacings they give (sqrt of the area) into R. */
static hv_status points_spacing(const pt_bins *B, const hv_points *P, double *area,
                                hv_points_report *R)
{
    const size_t n = P->count;
    int failed = 0;
#pragma omp parallel reduction(| : failed)
    {
        knn_buf K = {NULL, NULL, 0};
#pragma omp for schedule(dynamic, 64)
        for (size_t t = 0; t <= B->mask; t++)
            if (B->keys[t] != UINT64_MAX && !failed)
                failed |= cell_areas(B, P, t, &K, area) != 0;
        free(K.best);
        free(K.found);
    }
    if (failed)
        return hv__error(HV_ERR_NOMEM, "points: out of memory for the neighbour search");
    double *s = malloc(n * sizeof *s);
    if (!s)
        return hv__error(HV_ERR_NOMEM, "points: out of memory for %zu spacings", n);
    R->spacing_min = INFINITY;
    R->spacing_max = 0;
    for (size_t i = 0; i < n; i++) {
        s[i] = sqrt(area[i]);
        R->spacing_min = fmin(R->spacing_min, s[i]);
        R->spacing_max = fmax(R->spacing_max, s[i]);
    }
    R->spacing_median = select_kth(s, n, n / 2);
    free(s);
    return HV_OK;
}

/* The heat method's grid: f times coarser than the block hv_sdf_compute
 * would place around the points' bounds, with cell counts that are
 * multiples of 8 (fast for FFTW and multigrid alike), centred on it. The
 * surface only needs it to find the inside and the surface near each point
 * (the projection does the rest), so by default f keeps it under
 * PTS_HEAT_CELLS. */
static hv_status points_grid(const hv_points *P, const hv_sdf_opts *o, hv_grid **gh,
                             hv_points_report *R)
{
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < P->count; i++)
        for (int a = 0; a < 3; a++) {
            lo[a] = fmin(lo[a], P->xyz[3 * i + a]);
            hi[a] = fmax(hi[a], P->xyz[3 * i + a]);
        }
    int n[3];
    double h, origin[3];
    hv_status st = hv__sdf_grid_place(o, lo, hi, n, &h, origin);
    if (st)
        return st;
    const double cells = (double)n[0] * n[1] * n[2];
    int f = o->heat_coarsen;
    if (f == 0)
        f = (int)fmin(4, fmax(1, ceil(cbrt(cells / PTS_HEAT_CELLS) - 1e-9)));
    R->h = f * h;
    R->coarsen = f;
    double org[3];
    for (int a = 0; a < 3; a++) {
        int m = (n[a] + f - 1) / f;
        R->n[a] = m >= 16 ? (m + 7) / 8 * 8 : m;
        org[a] = origin[a] + 0.5 * (n[a] * h - R->n[a] * R->h);
    }
    if ((st = hv_check_dims(3, R->n, R->h, 80)))
        return st;
    return hv_grid_create(gh, 3, R->n, R->h, org);
}

/* 2. Stages 2-6 of the signed heat method with the points as the surface
 * samples: vector area a_i n_i at p_i. phi into gh. */
static hv_status points_heat(const hv_points *P, const double *area, const hv_sdf_opts *o,
                             hv_grid *gh, hv_points_report *R)
{
    const size_t n = P->count;
    hv_quad q = {n, P->xyz, malloc(3 * n * sizeof(double)), (double *)area};
    if (!q.w)
        return hv__error(HV_ERR_NOMEM, "points: out of memory for %zu vector areas", n);
    for (size_t i = 0; i < 3 * n; i++)
        q.w[i] = area[i / 3] * P->normals[i];
    hv_sdf_opts ho = *o;
    ho.diffuse_tol = 1e-6;
    ho.poisson_tol = 1e-6;
    ho.local_shift = 1;
    ho.backend = hv_backend_resolve(o->backend, hv_grid_count(gh), 0);
    hv_sdf_stats *S = &R->heat;
    memset(S, 0, sizeof *S);
    memcpy(S->n, gh->n, sizeof S->n);
    S->h = gh->h;
    memcpy(S->origin, gh->origin, sizeof S->origin);
    const double width = o->t_scale * fmax(gh->h, R->spacing_median);
    S->t = width * width;
    S->levels = 1;
    S->surface_samples = n;
    hv_status st = hv__sdf_heat(&q, gh, 1, 0, &ho, S);
    free(q.w);
    return st;
}

/* The gradient of phi (trilinear) at x, by central differences half a
 * voxel apart. */
static void phi_gradient(const hv_grid *g, const double x[3], double grad[3])
{
    const double e = 0.5 * g->h;
    for (int a = 0; a < 3; a++) {
        double xp[3] = {x[0], x[1], x[2]}, xm[3] = {x[0], x[1], x[2]};
        xp[a] += e;
        xm[a] -= e;
        grad[a] = (hv__sdf_interp(g, g->v, xp) - hv__sdf_interp(g, g->v, xm)) / (2 * e);
    }
}

/* Each point's normal turned to face out of phi's inside (into nrm), and
 * how many had to be turned. */
static void points_orient(const hv_points *P, const double *area, const hv_grid *gh,
                          const unsigned char *held, double *nrm, hv_points_report *R)
{
    size_t against = 0;
    double a_against = 0, a_all = 0;
#pragma omp parallel for schedule(static) reduction(+ : against, a_against, a_all)
    for (size_t i = 0; i < P->count; i++) {
        double g[3];
        phi_gradient(gh, P->xyz + 3 * i, g);
        const double *m = P->normals + 3 * i;
        const int flip = m[0] * g[0] + m[1] * g[1] + m[2] * g[2] < 0 && !(held && held[i]);
        for (int a = 0; a < 3; a++)
            nrm[3 * i + a] = flip ? -m[a] : m[a];
        against += (size_t)flip;
        a_against += flip ? area[i] : 0;
        a_all += area[i];
    }
    R->normals_against = against;
    R->normal_agreement = a_all > 0 ? 1 - a_against / a_all : 0;
}

/* A vertex's fit to the points near it: its offset along u, and how
 * firmly the points hold it. */
typedef struct vfit {
    double d;    /* the offset (NAN where no point faces u's way) */
    double var;  /* the weighted variance of the points' heights about d */
    double neff; /* (sum w)^2 / sum w^2: how many points d averages */
} vfit;

/* How far along u (unit) vertex v moves onto the points near it: the
 * weighted mean of the points' heights over the tangent plane of v, over
 * the candidates cand[0..m) within 2 sigma that face u's way, Gaussian
 * weights times their areas. On a curved surface a point at tangential
 * offset r lies r.S.r / 2 below that plane (S the shape operator) and its
 * normal leans out by S r, so r . n / 2 puts it back: each point's height
 * is taken halfway between the plane of u and its own tangent plane,
 * exact to second order whatever the curvatures and however the points
 * spread around v. A cloud far denser than the voxels (1M points at 64^3:
 * some 4000 candidates) gives every stride-th candidate, about
 * PTS_FIT_SAMPLES in all, the same weighted mean. */
static void vertex_fit(const hv_points *P, const double *area, const double *nrm,
                       const uint32_t *cand, size_t m, const double v[3], const double u[3],
                       double sigma, vfit *F)
{
    const double reach2 = 4 * sigma * sigma, inv2 = 1 / (sigma * sigma);
    const size_t stride = 1 + m / PTS_FIT_SAMPLES;
    double num = 0, den = 0, sq = 0, w2 = 0;
    for (size_t c = 0; c < m; c += stride) {
        const uint32_t j = cand[c];
        const double *p = P->xyz + 3 * (size_t)j, *n = nrm + 3 * (size_t)j;
        const double d2 = dist2(p, v), nu = n[0] * u[0] + n[1] * u[1] + n[2] * u[2];
        if (d2 > reach2 || nu < PTS_FACING)
            continue;
        const double r[3] = {p[0] - v[0], p[1] - v[1], p[2] - v[2]};
        const double z = r[0] * u[0] + r[1] * u[1] + r[2] * u[2];
        const double rn = r[0] * n[0] + r[1] * n[1] + r[2] * n[2] - z * nu; /* r_t . n */
        const double w = area[j] * exp(-d2 * inv2), e = z + 0.5 * rn;
        num += w * e;
        sq += w * e * e;
        den += w;
        w2 += w * w;
    }
    F->d = den > 0 ? num / den : NAN;
    F->var = den > 0 ? fmax(0, sq / den - F->d * F->d) : 0;
    F->neff = den > 0 ? den * den / w2 : 0;
}

/* The unit normal of phi's level set at x (NAN components where phi is
 * flat). */
static void unit_normal(const hv_grid *gh, const double x[3], double u[3])
{
    phi_gradient(gh, x, u);
    const double len = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    for (int a = 0; a < 3; a++)
        u[a] = len > 0 ? u[a] / len : NAN;
}

/* The fits of the vertices in the cells of V whose table slot is a
 * multiple of stride (F[i].d NAN for the others), and their unit normals
 * of phi (into un): the points within reach of a cell gathered once for
 * all its vertices. */
static hv_status project_fits(const pt_bins *B, const pt_bins *V, const hv_points *P,
                              const double *area, const double *nrm, const hv_grid *gh,
                              const hv_mesh *M, double sigma, size_t stride, vfit *F, double *un)
{
    const long rings = (long)ceil(2 * sigma / B->c);
    int failed = 0;
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < M->nverts; i++)
        F[i].d = NAN;
#pragma omp parallel reduction(| : failed)
    {
        uint32_t *buf = NULL;
        size_t cap = 0;
#pragma omp for schedule(dynamic, 16)
        for (size_t t = 0; t <= V->mask; t += stride) {
            if (V->keys[t] == UINT64_MAX || failed)
                continue;
            long q[3];
            hv__slot_cell(V, t, q);
            const size_t m = gather_block(B, q, rings, &buf, &cap);
            failed |= m == SIZE_MAX;
            for (uint32_t k = 0; k < V->len[t] && !failed; k++) {
                const size_t i = V->order[V->start[t] + k];
                double *u = un + 3 * i;
                unit_normal(gh, M->verts + 3 * i, u);
                if (!isnan(u[0]))
                    vertex_fit(P, area, nrm, buf, m, M->verts + 3 * i, u, sigma, F + i);
            }
        }
        free(buf);
    }
    return failed
               ? hv__error(HV_ERR_NOMEM, "points: out of memory gathering points for the surface")
               : HV_OK;
}

/* The points' scatter about the fits (the median variance of their
 * heights) and how many points a fit weighs (the median n_eff) on every
 * PTS_NOISE_STRIDE-th cell of vertices, into *s2 and *neff. */
static hv_status points_noise(const pt_bins *B, const pt_bins *V, const hv_points *P,
                              const double *area, const double *nrm, const hv_grid *gh,
                              const hv_mesh *M, double sigma, vfit *F, double *un, double *s2,
                              double *neff)
{
    hv_status st = project_fits(B, V, P, area, nrm, gh, M, sigma, PTS_NOISE_STRIDE, F, un);
    double *var = st ? NULL : malloc(2 * M->nverts * sizeof *var);
    if (!st && !var)
        st = hv__error(HV_ERR_NOMEM, "points: out of memory for %zu vertices", M->nverts);
    double *ne = st ? NULL : var + M->nverts;
    size_t k = 0;
    for (size_t i = 0; !st && i < M->nverts; i++)
        if (!isnan(F[i].d)) {
            var[k] = F[i].var;
            ne[k++] = F[i].neff;
        }
    *s2 = k ? select_kth(var, k, k / 2) : 0;
    *neff = k ? select_kth(ne, k, k / 2) : 0;
    free(var);
    return st;
}

/* 4. The surface's vertices moved onto the points' local plane. On clean
 * points the fit within sigma0 = max(h, spacing) is what the points say.
 * Noisy points scatter about it by s (the fits' residual beyond what a
 * clean surface leaves, PTS_NOISE_FLOOR sigma0), and the offset of a fit
 * over n_eff points is uncertain by s / sqrt(n_eff), where the heat
 * method's surface, diffused over the points of a wider patch, is not:
 * the kernel widens with s, to PTS_WIDEN sigma0 at s = sigma0 / 5, but
 * no wider than makes the median fit weigh PTS_FIT_NEFF points (n_eff
 * grows as sigma^2): the bunny at 128^3 with 0.5 voxel of noise, 50 000
 * points (n_eff 13 at sigma0): 0.106 -> 0.104 voxel widened; 200 000
 * (n_eff 48): 0.068 unwidened, 0.076 widened. Each offset is weighed
 * against the heat method's own error b (PTS_HEAT_ERR heat voxels) as
 * independent estimates are, b^2 / (b^2 + s^2 / n_eff). */
static hv_status points_project(const pt_bins *B, const hv_points *P, const double *area,
                                const double *nrm, const hv_grid *gh, hv_mesh *M,
                                hv_points_report *R)
{
    const double sigma0 = fmax(gh->h / R->coarsen, R->spacing_median);
    const size_t nv = M->nverts;
    vfit *F = malloc(nv * sizeof *F);
    double *un = malloc(3 * nv * sizeof *un);
    pt_bins V;
    size_t cells, lonely = 0;
    memset(&V, 0, sizeof V);
    hv_status st = F && un ? hv__bins_build(&V, M->verts, nv, B->lo, B->c, &cells)
                           : hv__error(HV_ERR_NOMEM, "points: out of memory for %zu vertices", nv);
    double s2 = 0, n0 = 0;
    if (!st)
        st = points_noise(B, &V, P, area, nrm, gh, M, sigma0, F, un, &s2, &n0);
    const double floor = PTS_NOISE_FLOOR * sigma0, noise2 = fmax(0, s2 - floor * floor),
                 b = PTS_HEAT_ERR * gh->h;
    const double widen = fmin(PTS_WIDEN, 1 + sqrt(noise2) / (0.4 * sigma0));
    const double sigma = sigma0 * fmax(1, fmin(widen, n0 > 0 ? sqrt(PTS_FIT_NEFF / n0) : widen));
    if (!st)
        st = project_fits(B, &V, P, area, nrm, gh, M, sigma, 1, F, un);
    hv__bins_free(&V);
    double sum = 0, mx = 0;
#pragma omp parallel for schedule(static) if (!st) reduction(+ : lonely, sum) reduction(max : mx)
    for (size_t i = 0; i < (st ? 0 : nv); i++) {
        if (isnan(F[i].d)) {
            lonely++;
            continue;
        }
        double d = F[i].d * b * b / (b * b + noise2 / F[i].neff);
        d = fmax(-gh->h, fmin(gh->h, d));
        for (int a = 0; a < 3; a++)
            M->verts[3 * i + a] += d * un[3 * i + a];
        sum += fabs(d) / gh->h;
        mx = fmax(mx, fabs(d) / gh->h);
    }
    free(F);
    free(un);
    R->vertices = nv;
    R->vertices_unsupported = lonely;
    R->move_mean = nv > lonely ? sum / (double)(nv - lonely) : 0;
    R->move_max = mx;
    R->noise = sqrt(noise2);
    R->sigma = sigma;
    return st;
}

/* The cloud's checks: points, finite values (hv_points_read and
 * hv_points_from_arrays make sure of them; a caller's own struct may not). */
static hv_status points_check(const hv_points *P)
{
    if (!P || P->count == 0 || !P->xyz)
        return hv__error(HV_ERR_INVALID_ARG, "points: the cloud is empty (%zu points)",
                         P ? P->count : 0);
    if (P->count > UINT32_MAX)
        return hv__error(HV_ERR_INVALID_ARG, "points: %zu points, more than %u", P->count,
                         UINT32_MAX);
    for (size_t i = 0; i < 3 * P->count; i++)
        if (!isfinite(P->xyz[i]) || (P->normals && !isfinite(P->normals[i])))
            return hv__error(HV_ERR_NUMERIC, "points: point %zu has a NaN or Inf value", i / 3 + 1);
    return HV_OK;
}

typedef struct pts_work {
    pt_bins B;    /* cells of the heat grid's size */
    pt_bins near; /* cells of about 1.5 spacings, for the nearest neighbours */
    double *area, *nrm;
    double *dir;         /* the recovered normals (step 0), NULL with the given ones */
    unsigned char *held; /* their points on thin parts: the rays' signs, kept by the rounds */
    hv_grid *gh;
    hv_mesh *M;
} pts_work;

static void pts_work_free(pts_work *w)
{
    hv__bins_free(&w->B);
    hv__bins_free(&w->near);
    free(w->area);
    free(w->nrm);
    free(w->dir);
    free(w->held);
    hv_grid_destroy(&w->gh);
    hv_mesh_destroy(&w->M);
}

/* 3. The zero set of phi as a closed mesh. */
static hv_status points_mesh(const hv_grid *gh, hv_mesh **M)
{
    hv_status st = hv_grid_to_mesh(gh, 0.0, 0.0, M);
    if (st == HV_ERR_INVALID_ARG && !*M)
        return hv__error(HV_ERR_INVALID_ARG,
                         "points: the heat method found no inside (the normals do not enclose a "
                         "volume in the block)");
    return st;
}

typedef struct edge_ref {
    uint32_t a, b; /* a < b */
    uint32_t at;   /* 3 * triangle + corner of the edge's start */
} edge_ref;

static int cmp_edge(const void *x, const void *y)
{
    const edge_ref *e = x, *f = y;
    return e->a != f->a ? (e->a < f->a ? -1 : 1) : e->b != f->b ? (e->b < f->b ? -1 : 1) : 0;
}

/* Every triangle of *M split in four at its edges' midpoints, each
 * midpoint shared by the triangles of its edge: vertices half a voxel
 * apart for the projection to move onto the points. */
static hv_status subdivide(hv_mesh **M)
{
    const hv_mesh *m = *M;
    const size_t nt = m->ntris, ne = 3 * nt;
    edge_ref *E = malloc(ne * sizeof *E);
    uint32_t *mid = malloc(ne * sizeof *mid), *T = malloc(12 * nt * sizeof *T);
    double *V = malloc(3 * (m->nverts + ne) * sizeof *V);
    hv_status st = HV_OK;
    if (!E || !mid || !T || !V) {
        st = hv__error(HV_ERR_NOMEM, "points: out of memory subdividing %zu triangles", nt);
        goto out;
    }
    for (size_t i = 0; i < ne; i++) {
        uint32_t a = m->tris[i], b = m->tris[i - i % 3 + (i % 3 + 1) % 3];
        E[i] = (edge_ref){a < b ? a : b, a < b ? b : a, (uint32_t)i};
    }
    qsort(E, ne, sizeof *E, cmp_edge);
    memcpy(V, m->verts, 3 * m->nverts * sizeof *V);
    size_t nv = m->nverts;
    for (size_t i = 0; i < ne; i++) {
        if (i == 0 || cmp_edge(&E[i], &E[i - 1])) {
            for (int c = 0; c < 3; c++)
                V[3 * nv + c] =
                    0.5 * (m->verts[3 * (size_t)E[i].a + c] + m->verts[3 * (size_t)E[i].b + c]);
            nv++;
        }
        mid[E[i].at] = (uint32_t)(nv - 1);
    }
    for (size_t t = 0; t < nt; t++) {
        const uint32_t *v = m->tris + 3 * t, *e = mid + 3 * t; /* e[k]: edge v[k] v[k+1] */
        const uint32_t four[12] = {v[0], e[0], e[2], v[1], e[1], e[0],
                                   v[2], e[2], e[1], e[0], e[1], e[2]};
        memcpy(T + 12 * t, four, sizeof four);
    }
    hv_mesh *out = NULL;
    if (!(st = hv_mesh_from_arrays(&out, V, nv, T, 4 * nt))) {
        hv_mesh_destroy(M);
        *M = out;
    }
out:
    free(E), free(mid), free(T), free(V);
    return st;
}

/* The median of the points' spreads (sdf_orient.c): how far the cloud's
 * neighbourhoods are from planes. */
static hv_status median_spread(const float *spread, size_t n, double *med)
{
    double *v = malloc(n * sizeof *v);
    if (!v)
        return hv__error(HV_ERR_NOMEM, "points: out of memory for %zu spreads", n);
    for (size_t i = 0; i < n; i++)
        v[i] = spread[i];
    *med = select_kth(v, n, n / 2);
    free(v);
    return HV_OK;
}

/* The directions of a noisy cloud from its diffused line field instead
 * (points_lines.c), each kept on its own axis's side. */
static hv_status lines_directions(const hv_points *P, const hv_sdf_opts *o, pts_work *w,
                                  hv_points_report *R)
{
    pt_lines L;
    const double h = w->gh->h;
    hv_status st = hv__lines_build(&L, P, w->area, w->dir, w->gh, PTS_LINES_T * h * h,
                                   hv_backend_resolve(o->backend, hv_grid_count(w->gh), 0));
    if (st)
        return st;
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < P->count; i++) {
        double v[3];
        hv__lines_at(&L, P->xyz + 3 * i, w->dir + 3 * i, v);
        memcpy(w->dir + 3 * i, v, sizeof v);
    }
    R->orient_lines = 1;
    R->orient_line_iterations = L.iterations;
    hv__lines_free(&L);
    return HV_OK;
}

/* 0. The normals of a cloud without them (or whose normals are not to be
 * trusted): directions from the neighbourhoods of about two voxels of the
 * block, from the diffused line field where the cloud is noisy, turned
 * consistently and outward (sdf_orient.c). */
static hv_status points_recover(const hv_points *P, const hv_sdf_opts *o, pts_work *w,
                                hv_points_report *R)
{
    const double rho = fmax(2 * w->gh->h / R->coarsen, 3 * R->spacing_median);
    /* Cells of side rho: the 27 around a point's own hold its
     * neighbourhood, with fewer points to pass over than the cells of a
     * coarsened heat grid (three block voxels wide at 512^3) would hold. */
    pt_bins A;
    size_t cells;
    float *spread = malloc(P->count * sizeof *spread);
    if (!spread)
        return hv__error(HV_ERR_NOMEM, "points: out of memory for %zu spreads", P->count);
    hv_status st = hv__bins_build(&A, P->xyz, P->count, w->gh->origin, rho, &cells);
    if (!st)
        st = hv__points_axes(&A, rho, w->dir, spread);
    hv__bins_free(&A);
    if (!st)
        st = median_spread(spread, P->count, &R->orient_spread);
    if (!st && R->orient_spread > PTS_LINES_SPREAD)
        st = lines_directions(P, o, w, R);
    /* Thin parts: rays a little wider than the points' spacing, so that
     * none passes between them, and sheets half a voxel thick; not on a
     * cloud as noisy as the line field's, whose sheets are thicker than
     * the thin parts (0.5 voxel of noise on the cow: 11.6% of the points on
     * their true side with the rays, 96.6% without). */
    const double hb = w->gh->h / R->coarsen;
    const pt_thin T = {spread, fmax(PTS_THIN_RAY * hb, 1.5 * R->spacing_median),
                       fmax(PTS_THIN_SHEET * hb, 2 * R->spacing_median), w->held};
    if (!st)
        st = hv__points_propagate(&w->near, P, w->area, R->orient_lines ? NULL : &T, w->dir, R);
    free(spread);
    return st;
}

/* 2. The heat method, and the normals turned to face out of phi's inside.
 * With recovered normals, rounds: the turned normals go through the heat
 * method again while more than one point in PTS_ROUND_QUIET turns (the
 * rounds' time counts as the orientation's). */
static hv_status points_heat_orient(hv_points *Q, const hv_sdf_opts *o, pts_work *w,
                                    hv_points_report *R)
{
    for (;;) {
        double tt = hv_now();
        hv_status st = points_heat(Q, w->area, o, w->gh, R);
        if (st)
            return st;
        points_orient(Q, w->area, w->gh, w->held, w->nrm, R);
        R->t_heat = hv_now() - tt;
        if (!w->dir || R->orient_rounds >= PTS_ROUNDS ||
            R->normals_against * PTS_ROUND_QUIET <= Q->count)
            return HV_OK;
        R->orient_rounds++;
        R->orient_turned += R->normals_against;
        R->t_orient += R->t_heat;
        memcpy(w->dir, w->nrm, 3 * Q->count * sizeof *w->dir);
    }
}

/* A cloud too large for this machine's memory is refused before the work:
 * what the steps take (PTS_BYTES_*), the cloud's own and the heat grid's. */
static hv_status points_memory(const hv_points *P, int recover, const hv_points_report *R)
{
    const double cells = (double)R->n[0] * R->n[1] * R->n[2];
    const double own = (P->normals ? 48.0 : 24.0) * (double)P->count;
    const double need = (recover ? PTS_BYTES_RECOVER : PTS_BYTES_GIVEN) * (double)P->count + own +
                        PTS_CELL_BYTES * cells;
    if (need <= (double)hv__memory_limit(NULL))
        return HV_OK;
    char lim[96];
    return hv__error(HV_ERR_NOMEM,
                     "points: %zu points%s need about %.3g GB for the surface (%.0f bytes a "
                     "point), more than %s: thin the cloud (every k-th point) or split it",
                     P->count, recover ? " without normals" : "", need / 1e9,
                     need / (double)P->count, hv__memory_limit_text(lim, sizeof lim));
}

static hv_status points_run(const hv_points *P, const hv_sdf_opts *o, pts_work *w,
                            hv_points_report *R)
{
    const int recover =
        o->orient == HV_ORIENT_RECOVER || (o->orient == HV_ORIENT_AUTO && !P->normals);
    if (!recover && !P->normals)
        return hv__error(HV_ERR_INVALID_ARG,
                         "points: the cloud has no normals, and the orientation is to be the "
                         "given one (recover it, or give x y z nx ny nz)");
    if (recover && P->count < PTS_MIN_RECOVER)
        return hv__error(HV_ERR_INVALID_ARG,
                         "points: %zu points without normals; recovering their orientation "
                         "needs at least %d",
                         P->count, PTS_MIN_RECOVER);
    if (recover && hv__points_flat(P))
        return hv__error(HV_ERR_INVALID_ARG,
                         "points: the %zu points lie on a plane or a line: no orientation to "
                         "recover (no inside)",
                         P->count);
    R->recovered = recover;
    hv_status st;
    double tt = hv_now();
    size_t cells, near_cells;
    if ((st = points_grid(P, o, &w->gh, R)) || (st = points_memory(P, recover, R)) ||
        (st = hv__bins_build(&w->B, P->xyz, P->count, w->gh->origin, w->gh->h, &cells)))
        return st;
    /* A surface through `cells` cells of side c holds about cells c^2 of
     * area: the spacing s0 it gives sizes the cells of the neighbour
     * search, so that its first ring holds the 6th neighbour (1M points on
     * the bunny: with cells of 1.5 s0, 10% of the points had to search
     * farther and that took half the time; with 2 s0, 0.1%). */
    const double s0 = w->gh->h * sqrt((double)cells / (double)P->count);
    if ((st = hv__bins_build(&w->near, P->xyz, P->count, w->gh->origin, fmin(w->gh->h, 2 * s0),
                             &near_cells)))
        return st;
    w->area = malloc(P->count * sizeof *w->area);
    w->nrm = malloc(3 * P->count * sizeof *w->nrm);
    if (recover) {
        w->dir = malloc(3 * P->count * sizeof *w->dir);
        w->held = calloc(P->count, 1);
    }
    if (!w->area || !w->nrm || (recover && (!w->dir || !w->held)))
        return hv__error(HV_ERR_NOMEM, "points: out of memory for %zu points", P->count);
    if ((st = points_spacing(&w->near, P, w->area, R)))
        return st;
    R->t_spacing = hv_now() - tt;
    hv_points Q = *P;
    if (w->dir) {
        tt = hv_now();
        if ((st = points_recover(P, o, w, R)))
            return st;
        Q.normals = w->dir;
        R->t_orient = hv_now() - tt;
    }
    if ((st = points_heat_orient(&Q, o, w, R)))
        return st;
    for (size_t i = 0; w->dir && P->normals && i < P->count; i++) {
        const double *a = P->normals + 3 * i, *b = w->nrm + 3 * i;
        R->orient_disagree += a[0] * b[0] + a[1] * b[1] + a[2] * b[2] < 0;
    }
    tt = hv_now();
    /* On a heat grid that is the block's own, the surface's vertices are
     * a voxel apart: halved, they follow the points between (bunny from
     * 20 000 points at 64^3: mean distance 0.041 -> 0.034 voxel, the
     * largest 0.62 -> 0.40); a coarser heat grid is for large blocks, whose
     * time goes to the band of the surface's triangles. */
    if ((st = points_mesh(w->gh, &w->M)) || (R->coarsen == 1 && (st = subdivide(&w->M))))
        return st;
    R->t_mesh = hv_now() - tt;
    tt = hv_now();
    if ((st = points_project(&w->B, &Q, w->area, w->nrm, w->gh, w->M, R)))
        return st;
    R->t_project = hv_now() - tt;
    return HV_OK;
}

hv_status hv_points_surface(const hv_points *P, const hv_sdf_opts *opts, hv_mesh **out,
                            hv_points_report *report)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_points_surface: out is NULL");
    *out = NULL;
    hv_sdf_opts o;
    if (opts)
        o = *opts;
    else
        hv_sdf_opts_default(&o);
    hv_points_report R;
    memset(&R, 0, sizeof R);
    pts_work w;
    memset(&w, 0, sizeof w);
    hv_status st = hv__sdf_check_opts(&o);
    if (!st)
        st = points_check(P);
    if (!st && o.threads > 0)
        hv_set_threads(o.threads);
    const double t0 = hv_now();
    if (!st) {
        R.points = P->count;
        st = points_run(P, &o, &w, &R);
    }
    R.t_total = hv_now() - t0;
    if (!st) {
        *out = w.M;
        w.M = NULL;
    }
    pts_work_free(&w);
    if (report)
        *report = R;
    return st;
}
