/* Oriented points drawn on a triangle mesh (points_sample.h). */
#include "points_sample.h"

#include <heatvox/core.h>

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void points_sample_opts_default(points_sample_opts *o)
{
    memset(o, 0, sizeof *o);
    o->count = 100000;
    o->seed = 1;
    o->density_ratio = 1;
}

void points_set_free(points_set *p)
{
    free(p->xyz);
    free(p->normal);
    memset(p, 0, sizeof *p);
}

static int fail(char *err, size_t size, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err, size, fmt, ap);
    va_end(ap);
    return -1;
}

/* ---- random numbers: splitmix64 (Steele, Lea and Flood 2014) ---- */

static uint64_t rng_next(uint64_t *s)
{
    uint64_t z = (*s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

/* Uniform in [0, 1). */
static double rng_uniform(uint64_t *s) { return (double)(rng_next(s) >> 11) * 0x1p-53; }

/* Standard normal (Box-Muller; one of the pair). */
static double rng_gauss(uint64_t *s)
{
    const double u = 1 - rng_uniform(s), v = rng_uniform(s);
    return sqrt(-2 * log(u)) * cos(2 * M_PI * v);
}

/* ---- the surface: triangles by cumulative area ---- */

typedef struct surface {
    const hv_mesh *m;
    double *cum; /* cum[t]: area of triangles 0..t */
    double sign; /* -1 where the signed volume is negative: normals reversed */
    double xlo, xhi;
} surface;

/* Twice the area vector of triangle t (b - a) x (c - a). */
static void tri_cross(const hv_mesh *m, size_t t, double n[3])
{
    const double *a = m->verts + 3 * m->tris[3 * t], *b = m->verts + 3 * m->tris[3 * t + 1],
                 *c = m->verts + 3 * m->tris[3 * t + 2];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    n[0] = u[1] * w[2] - u[2] * w[1];
    n[1] = u[2] * w[0] - u[0] * w[2];
    n[2] = u[0] * w[1] - u[1] * w[0];
}

static int surface_init(surface *S, const hv_mesh *m)
{
    memset(S, 0, sizeof *S);
    S->m = m;
    double lo[3], hi[3];
    if (!m->ntris || hv_mesh_bounds(m, lo, hi) || !(S->cum = malloc(m->ntris * sizeof *S->cum)))
        return -1;
    S->xlo = lo[0];
    S->xhi = hi[0];
    double total = 0, volume = 0;
    for (size_t t = 0; t < m->ntris; t++) {
        double n[3];
        tri_cross(m, t, n);
        const double area = 0.5 * sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        total += isfinite(area) ? area : 0;
        S->cum[t] = total;
        const double *a = m->verts + 3 * m->tris[3 * t];
        volume += (a[0] * n[0] + a[1] * n[1] + a[2] * n[2]) / 6;
    }
    S->sign = volume < 0 ? -1 : 1;
    return total > 0 ? 0 : -1;
}

/* A triangle with probability proportional to its area, a point uniform in it
 * (Osada et al. 2002, square root of one variable) and the unit normal. */
static void surface_draw(const surface *S, uint64_t *rng, double p[3], double n[3])
{
    const hv_mesh *m = S->m;
    const double u = rng_uniform(rng) * S->cum[m->ntris - 1];
    size_t lo = 0, hi = m->ntris - 1;
    while (lo < hi) { /* the first t with cum[t] > u */
        const size_t mid = lo + (hi - lo) / 2;
        if (S->cum[mid] > u)
            hi = mid;
        else
            lo = mid + 1;
    }
    const uint32_t *t = m->tris + 3 * lo;
    const double r1 = sqrt(rng_uniform(rng)), r2 = rng_uniform(rng);
    const double w[3] = {1 - r1, r1 * (1 - r2), r1 * r2};
    for (int a = 0; a < 3; a++)
        p[a] = w[0] * m->verts[3 * t[0] + a] + w[1] * m->verts[3 * t[1] + a] +
               w[2] * m->verts[3 * t[2] + a];
    tri_cross(m, lo, n);
    const double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int a = 0; a < 3; a++)
        n[a] *= S->sign / len;
}

int points_surface_point(const hv_mesh *m, uint64_t seed, double p[3])
{
    surface S;
    if (surface_init(&S, m)) {
        free(S.cum);
        return -1;
    }
    double n[3];
    surface_draw(&S, &seed, p, n);
    free(S.cum);
    return 0;
}

/* ---- the defects ---- */

/* Whether a drawn point stays: the density falling along x, the hole. */
static int keep(const surface *S, const points_sample_opts *o, uint64_t *rng, const double p[3])
{
    if (o->density_ratio > 1) {
        const double x = S->xhi > S->xlo ? (p[0] - S->xlo) / (S->xhi - S->xlo) : 0;
        if (rng_uniform(rng) >= 1 - (1 - 1 / o->density_ratio) * x)
            return 0;
    }
    if (o->hole_radius > 0) {
        double d2 = 0;
        for (int a = 0; a < 3; a++)
            d2 += (p[a] - o->hole_center[a]) * (p[a] - o->hole_center[a]);
        if (d2 < o->hole_radius * o->hole_radius)
            return 0;
    }
    return 1;
}

static void add_noise(const points_sample_opts *o, uint64_t *rng, double p[3], const double n[3])
{
    if (!(o->noise > 0))
        return;
    if (o->noise_isotropic) {
        for (int a = 0; a < 3; a++)
            p[a] += o->noise * rng_gauss(rng);
        return;
    }
    const double g = o->noise * rng_gauss(rng);
    for (int a = 0; a < 3; a++)
        p[a] += g * n[a];
}

/* Reverses round(fraction * count) normals, a random subset (partial
 * Fisher-Yates shuffle of the indices). */
static int flip_some(points_set *P, double fraction, uint64_t *rng)
{
    const size_t k = (size_t)llround(fmin(fmax(fraction, 0), 1) * (double)P->count);
    if (!k)
        return 0;
    size_t *idx = malloc(P->count * sizeof *idx);
    if (!idx)
        return -1;
    for (size_t i = 0; i < P->count; i++)
        idx[i] = i;
    for (size_t i = 0; i < k; i++) {
        const size_t j = i + (size_t)(rng_uniform(rng) * (double)(P->count - i));
        const size_t t = idx[i];
        idx[i] = idx[j];
        idx[j] = t;
        for (int a = 0; a < 3; a++)
            P->normal[3 * idx[i] + a] = -P->normal[3 * idx[i] + a];
    }
    free(idx);
    return 0;
}

/* Draws until count points are kept; fails past 1000 draws a point. */
static int draw_kept(const surface *S, const points_sample_opts *o, uint64_t *rng, points_set *P)
{
    const double limit = 1000.0 * (double)o->count + 1e6;
    double draws = 0;
    while (P->count < o->count) {
        if (++draws > limit)
            return -1;
        double *p = P->xyz + 3 * P->count, *n = P->normal + 3 * P->count;
        surface_draw(S, rng, p, n);
        if (!keep(S, o, rng, p))
            continue;
        add_noise(o, rng, p, n);
        P->count++;
    }
    return 0;
}

int points_sample(const hv_mesh *m, const points_sample_opts *o, points_set *out, char *err,
                  size_t errsize)
{
    memset(out, 0, sizeof *out);
    surface S;
    if (surface_init(&S, m)) {
        free(S.cum);
        return fail(err, errsize, "the mesh has no finite area to sample");
    }
    uint64_t rng = o->seed;
    int rc = -1;
    out->xyz = malloc(3 * o->count * sizeof *out->xyz);
    out->normal = malloc(3 * o->count * sizeof *out->normal);
    if (!out->xyz || !out->normal)
        fail(err, errsize, "out of memory for %zu points", o->count);
    else if (draw_kept(&S, o, &rng, out))
        fail(err, errsize, "the options keep almost no point (%zu of %zu after 1000 draws each)",
             out->count, o->count);
    else if (flip_some(out, o->flip_fraction, &rng))
        fail(err, errsize, "out of memory");
    else
        rc = 0;
    free(S.cum);
    if (rc)
        points_set_free(out);
    return rc;
}

/* ---- the .xyz file ---- */

static int write_lines(FILE *f, const points_set *p)
{
    if (fprintf(f, "# x y z nx ny nz: %zu oriented points\n", p->count) < 0)
        return -1;
    for (size_t i = 0; i < p->count; i++) {
        const double *x = p->xyz + 3 * i, *n = p->normal + 3 * i;
        if (fprintf(f, "%.9g %.9g %.9g %.7g %.7g %.7g\n", x[0], x[1], x[2], n[0], n[1], n[2]) < 0)
            return -1;
    }
    return 0;
}

int points_write_xyz(const points_set *p, const char *path, char *err, size_t errsize)
{
    char tmp[4096];
    if (hv_tmp_name(path, tmp, sizeof tmp))
        return fail(err, errsize, "%s", hv_last_error());
    FILE *f = fopen(tmp, "w");
    if (!f) {
        const int e = errno;
        hv_tmp_discard(tmp);
        return fail(err, errsize, "%s: cannot create: %s", path, strerror(e));
    }
    int bad = write_lines(f, p);
    int e = errno;
    if (fclose(f) && !bad) {
        bad = -1;
        e = errno;
    }
    if (bad) {
        hv_tmp_discard(tmp);
        return fail(err, errsize, "%s: write error: %s", path, strerror(e));
    }
    if (hv_tmp_commit(tmp, path))
        return fail(err, errsize, "%s", hv_last_error());
    return 0;
}
