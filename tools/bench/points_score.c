/* Scores of a reconstructed surface against the true mesh (points_score.h). */
#include "points_score.h"
#include "points_sample.h"

#include <heatvox/sdf.h>

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

static int fail(char *err, size_t size, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err, size, fmt, ap);
    va_end(ap);
    return -1;
}

void points_truth_free(points_truth *T)
{
    hv_grid_destroy(&T->phi);
    tri_buckets_free(&T->b);
    T->m = NULL;
}

int points_truth_init(points_truth *T, const hv_mesh *m, int res, char *err, size_t errsize)
{
    memset(T, 0, sizeof *T);
    T->m = m;
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = res;
    o.sign = HV_SDF_SIGN_WINDING;
    hv_status st = hv_sdf_compute(m, &o, &T->phi, NULL);
    if (st)
        return fail(err, errsize, "the true distance: %s: %s", hv_status_str(st), hv_last_error());
    if ((st = tri_buckets_build(&T->b, m, 2 * T->phi->h))) {
        points_truth_free(T);
        return fail(err, errsize, "bucketing the true triangles: %s", hv_status_str(st));
    }
    return 0;
}

/* ---- inside-IoU ---- */

/* r's signed distance on the block of T->phi (the winding number's sign; only
 * the sign is used, so the exact distance is computed near r alone). */
static int inside_of(const points_truth *T, const hv_mesh *r, hv_grid **out, char *err,
                     size_t errsize)
{
    const hv_grid *g = T->phi;
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.sign = HV_SDF_SIGN_WINDING;
    o.use_bbox = 1;
    o.voxel_size = g->h;
    o.round_to = 1;
    o.band_only = 2;
    for (int a = 0; a < 3; a++) {
        o.bbox[a] = g->origin[a];
        o.bbox[3 + a] = g->origin[a] + g->n[a] * g->h;
    }
    hv_status st = hv_sdf_compute(r, &o, out, NULL);
    if (st)
        return fail(err, errsize, "its distance: %s: %s", hv_status_str(st), hv_last_error());
    if (memcmp((*out)->n, g->n, sizeof g->n)) {
        hv_grid_destroy(out);
        return fail(err, errsize, "its distance came on another block than the truth's");
    }
    return 0;
}

static double iou(const hv_grid *a, const hv_grid *b)
{
    size_t both = 0, either = 0;
    for (size_t c = 0; c < hv_grid_count(a); c++) {
        const int ia = a->v[c] < 0, ib = b->v[c] < 0;
        both += ia && ib;
        either += ia || ib;
    }
    return either ? (double)both / (double)either : 1;
}

/* ---- distance to the true surface ---- */

/* Trilinear interpolation of the cell-centred g at world point p, clamped to
 * the block. */
static double trilinear(const hv_grid *g, const double p[3])
{
    int i0[3];
    double w[3];
    for (int a = 0; a < 3; a++) {
        const double x = fmin(fmax((p[a] - g->origin[a]) / g->h - 0.5, 0), g->n[a] - 1);
        i0[a] = (int)fmin(floor(x), g->n[a] > 1 ? g->n[a] - 2 : 0);
        w[a] = g->n[a] > 1 ? x - i0[a] : 0;
    }
    double s = 0;
    for (int c = 0; c < 8; c++) {
        const int d[3] = {c & 1, c >> 1 & 1, c >> 2 & 1};
        double wt = 1;
        size_t idx = 0, stride = 1;
        for (int a = 0; a < 3; a++) {
            wt *= d[a] ? w[a] : 1 - w[a];
            idx += (size_t)(i0[a] + (d[a] && g->n[a] > 1)) * stride;
            stride *= (size_t)g->n[a];
        }
        s += wt * g->v[idx];
    }
    return s;
}

static double dist3(const double a[3], const double b[3])
{
    return sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                (a[2] - b[2]) * (a[2] - b[2]));
}

/* Over every triangle, for points so far that the buckets would cost more. */
static double brute_distance(const hv_mesh *m, const double p[3])
{
    double best = INFINITY;
    for (size_t t = 0; t < m->ntris; t++) {
        const uint32_t *v = m->tris + 3 * t;
        double q[3];
        tri_closest_point(p, m->verts + 3 * v[0], m->verts + 3 * v[1], m->verts + 3 * v[2], q);
        best = fmin(best, dist3(p, q));
    }
    return best;
}

/* The exact distance from p to the true triangles: searched within the
 * interpolated distance plus a voxel, a wider radius while the closest point
 * found lies beyond it. */
static double exact_distance(const points_truth *T, const double p[3])
{
    double r = fabs(trilinear(T->phi, p)) + T->phi->h;
    for (;;) {
        const double side = 2 * r / T->b.size + 1;
        if (side * side * side > (double)T->m->ntris)
            return brute_distance(T->m, p);
        double cp[3];
        if (!tri_buckets_closest(&T->b, p, r, cp) && dist3(p, cp) <= r)
            return dist3(p, cp);
        r *= 2;
    }
}

static double mesh_area(const hv_mesh *m)
{
    double area = 0;
    for (size_t t = 0; t < m->ntris; t++) {
        const double *a = m->verts + 3 * m->tris[3 * t], *b = m->verts + 3 * m->tris[3 * t + 1],
                     *c = m->verts + 3 * m->tris[3 * t + 2];
        const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        const double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
                             u[0] * w[1] - u[1] * w[0]};
        area += 0.5 * sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    }
    return area;
}

/* Samples of r, 4 a square voxel (between 20000 and 10^6), each at its
 * exact distance to the truth. */
static int surface_distance(const points_truth *T, const hv_mesh *r, points_score *s, char *err,
                            size_t errsize)
{
    const double h = T->phi->h;
    points_sample_opts o;
    points_sample_opts_default(&o);
    o.count = (size_t)fmin(fmax(4 * mesh_area(r) / (h * h), 20000), 1e6);
    points_set P;
    if (points_sample(r, &o, &P, err, errsize))
        return -1;
    double sum = 0, most = 0;
#pragma omp parallel for schedule(dynamic, 256) reduction(+ : sum) reduction(max : most)
    for (size_t i = 0; i < P.count; i++) {
        const double d = exact_distance(T, P.xyz + 3 * i) / h;
        sum += d;
        most = fmax(most, d);
    }
    s->samples = P.count;
    s->mean_dist_vox = sum / (double)P.count;
    s->max_dist_vox = most;
    points_set_free(&P);
    return 0;
}

int points_score_mesh(const points_truth *T, const hv_mesh *r, points_score *s, char *err,
                      size_t errsize)
{
    memset(s, 0, sizeof *s);
    hv_grid *in = NULL;
    if (inside_of(T, r, &in, err, errsize))
        return -1;
    s->iou = iou(T->phi, in);
    hv_grid_destroy(&in);
    return surface_distance(T, r, s, err, errsize);
}
