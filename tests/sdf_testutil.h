/*
 * Test helpers for the signed-distance tests (header-only, static): analytic
 * meshes, defect makers, and truths computed independently of the library:
 * ray parity along grid rows (exact for closed meshes, whatever their
 * orientation) and a fast generalized winding number (Barill et al. 2018,
 * first-order dipole far field), which closes holes.
 */
#ifndef HV_TESTS_SDF_TESTUTIL_H
#define HV_TESTS_SDF_TESTUTIL_H

#include "heatvox/heatvox.h"
#include "heatvox/sdf.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------- meshes ---------- */

static hv_mesh *tu_mesh_new(size_t nv, size_t nt)
{
    hv_mesh *m = calloc(1, sizeof *m);
    m->nverts = nv;
    m->ntris = nt;
    m->verts = malloc((3 * nv + 1) * sizeof *m->verts);
    m->tris = malloc((3 * nt + 1) * sizeof *m->tris);
    return m;
}

static void tu_mesh_free(hv_mesh **m)
{
    if (!m || !*m)
        return;
    free((*m)->verts);
    free((*m)->tris);
    free(*m);
    *m = NULL;
}

static hv_mesh *tu_mesh_copy(const hv_mesh *s)
{
    hv_mesh *m = tu_mesh_new(s->nverts, s->ntris);
    memcpy(m->verts, s->verts, 3 * s->nverts * sizeof *m->verts);
    memcpy(m->tris, s->tris, 3 * s->ntris * sizeof *m->tris);
    return m;
}

/* Icosphere: icosahedron split `level` times, vertices on the sphere, outward. */
static hv_mesh *tu_icosphere(int level, double radius, const double c[3])
{
    const double p = (1 + sqrt(5.0)) / 2;
    double v0[12][3] = {{-1, p, 0}, {1, p, 0}, {-1, -p, 0}, {1, -p, 0}, {0, -1, p}, {0, 1, p},
                        {0, -1, -p}, {0, 1, -p}, {p, 0, -1}, {p, 0, 1}, {-p, 0, -1}, {-p, 0, 1}};
    uint32_t f0[20][3] = {{0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                          {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8},
                          {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1}};
    size_t nt = 20, nv = 12;
    size_t maxt = 20, maxv = 12;
    for (int l = 0; l < level; l++)
        maxt *= 4;
    maxv = maxt / 2 + 2;
    double *V = malloc(3 * maxv * sizeof *V);
    uint32_t *T = malloc(3 * maxt * sizeof *T);
    for (int i = 0; i < 12; i++) {
        double r = sqrt(v0[i][0] * v0[i][0] + v0[i][1] * v0[i][1] + v0[i][2] * v0[i][2]);
        for (int d = 0; d < 3; d++)
            V[3 * i + d] = v0[i][d] / r;
    }
    memcpy(T, f0, sizeof f0);
    for (int l = 0; l < level; l++) {
        /* Midpoint cache: edge key -> vertex, linear probing. */
        size_t cap = 8 * nt + 16;
        uint64_t *key = malloc(cap * sizeof *key);
        uint32_t *val = malloc(cap * sizeof *val);
        for (size_t i = 0; i < cap; i++)
            key[i] = UINT64_MAX;
        uint32_t *NT = malloc(3 * 4 * nt * sizeof *NT);
        for (size_t f = 0; f < nt; f++) {
            uint32_t mid[3];
            for (int e = 0; e < 3; e++) {
                uint32_t a = T[3 * f + e], b = T[3 * f + (e + 1) % 3];
                uint64_t k = a < b ? ((uint64_t)a << 32 | b) : ((uint64_t)b << 32 | a);
                size_t hsh = (size_t)((k * 0x9E3779B97F4A7C15ull) % cap);
                while (key[hsh] != UINT64_MAX && key[hsh] != k)
                    hsh = (hsh + 1) % cap;
                if (key[hsh] == UINT64_MAX) {
                    key[hsh] = k;
                    double m3[3], r = 0;
                    for (int d = 0; d < 3; d++) {
                        m3[d] = 0.5 * (V[3 * a + d] + V[3 * b + d]);
                        r += m3[d] * m3[d];
                    }
                    r = sqrt(r);
                    for (int d = 0; d < 3; d++)
                        V[3 * nv + d] = m3[d] / r;
                    val[hsh] = (uint32_t)nv++;
                }
                mid[e] = val[hsh];
            }
            uint32_t a = T[3 * f], b = T[3 * f + 1], c2 = T[3 * f + 2];
            uint32_t q[4][3] = {{a, mid[0], mid[2]}, {mid[0], b, mid[1]}, {mid[2], mid[1], c2}, {mid[0], mid[1], mid[2]}};
            memcpy(NT + 12 * f, q, sizeof q);
        }
        free(T);
        T = NT;
        nt *= 4;
        free(key);
        free(val);
    }
    hv_mesh *m = tu_mesh_new(nv, nt);
    for (size_t i = 0; i < nv; i++)
        for (int d = 0; d < 3; d++)
            m->verts[3 * i + d] = c[d] + radius * V[3 * i + d];
    memcpy(m->tris, T, 3 * nt * sizeof *T);
    free(V);
    free(T);
    return m;
}

/* Torus around z: major radius R, tube radius r, nu x nv quads split in two, outward. */
static hv_mesh *tu_torus(double R, double r, int nu, int nv, const double c[3])
{
    hv_mesh *m = tu_mesh_new((size_t)nu * nv, 2 * (size_t)nu * nv);
    for (int i = 0; i < nu; i++)
        for (int j = 0; j < nv; j++) {
            double u = 2 * M_PI * i / nu, v = 2 * M_PI * j / nv;
            double *x = m->verts + 3 * ((size_t)i * nv + j);
            x[0] = c[0] + (R + r * cos(v)) * cos(u);
            x[1] = c[1] + (R + r * cos(v)) * sin(u);
            x[2] = c[2] + r * sin(v);
        }
    size_t f = 0;
    for (int i = 0; i < nu; i++)
        for (int j = 0; j < nv; j++) {
            uint32_t a = (uint32_t)(i * nv + j), b = (uint32_t)(((i + 1) % nu) * nv + j);
            uint32_t cc = (uint32_t)(((i + 1) % nu) * nv + (j + 1) % nv), d = (uint32_t)(i * nv + (j + 1) % nv);
            uint32_t t1[3] = {a, b, cc}, t2[3] = {a, cc, d};
            memcpy(m->tris + 3 * f++, t1, sizeof t1);
            memcpy(m->tris + 3 * f++, t2, sizeof t2);
        }
    return m;
}

/* Signed volume (positive for outward orientation). */
static double tu_signed_volume(const hv_mesh *m)
{
    double v = 0;
    for (size_t f = 0; f < m->ntris; f++) {
        const double *a = m->verts + 3 * (size_t)m->tris[3 * f], *b = m->verts + 3 * (size_t)m->tris[3 * f + 1],
                     *c = m->verts + 3 * (size_t)m->tris[3 * f + 2];
        v += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    return v / 6;
}

/* ---------- a small reader (OBJ, ascii PLY) for the shared meshes ---------- */

static hv_mesh *tu_read_obj(FILE *fp)
{
    size_t nv = 0, cv = 1024, nt = 0, ct = 1024;
    double *V = malloc(3 * cv * sizeof *V);
    uint32_t *T = malloc(3 * ct * sizeof *T);
    char line[65536];
    while (fgets(line, sizeof line, fp)) {
        if (line[0] == 'v' && line[1] == ' ') {
            if (nv == cv)
                V = realloc(V, 3 * (cv *= 2) * sizeof *V);
            if (sscanf(line + 2, "%lf %lf %lf", V + 3 * nv, V + 3 * nv + 1, V + 3 * nv + 2) == 3)
                nv++;
        } else if (line[0] == 'f' && line[1] == ' ') {
            long idx[256];
            int k = 0;
            char *s = line + 2, *e;
            while (k < 256) {
                long v = strtol(s, &e, 10);
                if (e == s)
                    break;
                idx[k++] = v < 0 ? (long)nv + v : v - 1;
                s = e;
                while (*s && *s != ' ' && *s != '\t')
                    s++;
            }
            for (int q = 1; q + 1 < k; q++) {
                if (nt == ct)
                    T = realloc(T, 3 * (ct *= 2) * sizeof *T);
                T[3 * nt] = (uint32_t)idx[0], T[3 * nt + 1] = (uint32_t)idx[q], T[3 * nt + 2] = (uint32_t)idx[q + 1];
                nt++;
            }
        }
    }
    hv_mesh *m = calloc(1, sizeof *m);
    m->verts = V, m->nverts = nv, m->tris = T, m->ntris = nt;
    return m;
}

static hv_mesh *tu_read_ply_ascii(FILE *fp)
{
    char line[4096];
    size_t nv = 0, nf = 0;
    int nprop = 0, in_vertex = 0;
    while (fgets(line, sizeof line, fp)) {
        if (!strncmp(line, "element vertex", 14))
            nv = strtoul(line + 14, NULL, 10), in_vertex = 1;
        else if (!strncmp(line, "element face", 12))
            nf = strtoul(line + 12, NULL, 10), in_vertex = 0;
        else if (!strncmp(line, "property", 8) && in_vertex)
            nprop++;
        else if (!strncmp(line, "end_header", 10))
            break;
    }
    hv_mesh *m = tu_mesh_new(nv, 0);
    for (size_t i = 0; i < nv; i++) {
        double x[16];
        for (int p = 0; p < nprop && p < 16; p++)
            if (fscanf(fp, "%lf", &x[p]) != 1)
                x[p] = 0;
        memcpy(m->verts + 3 * i, x, 3 * sizeof *x);
    }
    size_t ct = nf * 2 + 1, nt = 0;
    m->tris = realloc(m->tris, 3 * ct * sizeof *m->tris);
    for (size_t f = 0; f < nf; f++) {
        int k;
        long idx[64];
        if (fscanf(fp, "%d", &k) != 1)
            break;
        for (int q = 0; q < k && q < 64; q++)
            if (fscanf(fp, "%ld", &idx[q]) != 1)
                idx[q] = 0;
        for (int q = 1; q + 1 < k; q++) {
            if (nt == ct)
                m->tris = realloc(m->tris, 3 * (ct *= 2) * sizeof *m->tris);
            m->tris[3 * nt] = (uint32_t)idx[0], m->tris[3 * nt + 1] = (uint32_t)idx[q], m->tris[3 * nt + 2] = (uint32_t)idx[q + 1];
            nt++;
        }
    }
    m->ntris = nt;
    return m;
}

static const char *tu_shared_dir(void)
{
    const char *d = getenv("HEATVOX_SHARED");
    return d && *d ? d : "../shared";
}

/* Reads $HEATVOX_SHARED/meshes/<name>, or returns NULL (test skips). */
static hv_mesh *tu_load_shared(const char *name)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/meshes/%s", tu_shared_dir(), name);
    FILE *fp = fopen(path, "rb");
    if (!fp) {
        printf("SKIP: %s not found (set HEATVOX_SHARED)\n", path);
        return NULL;
    }
    size_t len = strlen(name);
    hv_mesh *m = (len > 4 && !strcmp(name + len - 4, ".ply")) ? tu_read_ply_ascii(fp) : tu_read_obj(fp);
    fclose(fp);
    return m;
}

/* ---------- defects (deterministic) ---------- */

static uint64_t tu_rng = 88172645463325252ull;
static double tu_rand(void)
{
    tu_rng ^= tu_rng << 13;
    tu_rng ^= tu_rng >> 7;
    tu_rng ^= tu_rng << 17;
    return (double)(tu_rng >> 11) / 9007199254740992.0;
}

static void tu_centroid(const hv_mesh *m, size_t f, double c[3])
{
    for (int d = 0; d < 3; d++)
        c[d] = (m->verts[3 * (size_t)m->tris[3 * f] + d] + m->verts[3 * (size_t)m->tris[3 * f + 1] + d] +
                m->verts[3 * (size_t)m->tris[3 * f + 2] + d]) / 3;
}

static double tu_diag(const hv_mesh *m)
{
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < m->nverts; i++)
        for (int d = 0; d < 3; d++)
            lo[d] = fmin(lo[d], m->verts[3 * i + d]), hi[d] = fmax(hi[d], m->verts[3 * i + d]);
    return sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) + (hi[2] - lo[2]) * (hi[2] - lo[2]));
}

/* Removes every face within radius frac*diag of `holes` random face centroids. */
static void tu_defect_holes(hv_mesh *m, int holes, double frac)
{
    double r = frac * tu_diag(m), seeds[64][3];
    for (int s = 0; s < holes && s < 64; s++)
        tu_centroid(m, (size_t)(tu_rand() * m->ntris) % m->ntris, seeds[s]);
    size_t k = 0;
    for (size_t f = 0; f < m->ntris; f++) {
        double c[3];
        tu_centroid(m, f, c);
        int cut = 0;
        for (int s = 0; s < holes && s < 64 && !cut; s++)
            cut = (c[0] - seeds[s][0]) * (c[0] - seeds[s][0]) + (c[1] - seeds[s][1]) * (c[1] - seeds[s][1]) +
                      (c[2] - seeds[s][2]) * (c[2] - seeds[s][2]) < r * r;
        if (!cut)
            memmove(m->tris + 3 * k++, m->tris + 3 * f, 3 * sizeof *m->tris);
    }
    m->ntris = k;
}

static void tu_flip_face(hv_mesh *m, size_t f)
{
    uint32_t t = m->tris[3 * f + 1];
    m->tris[3 * f + 1] = m->tris[3 * f + 2];
    m->tris[3 * f + 2] = t;
}

static void tu_defect_flip_random(hv_mesh *m, double frac)
{
    for (size_t f = 0; f < m->ntris; f++)
        if (tu_rand() < frac)
            tu_flip_face(m, f);
}

/* Flips every face on the +x side of the mean vertex: a coherently flipped half. */
static void tu_defect_flip_half(hv_mesh *m)
{
    double mx = 0;
    for (size_t i = 0; i < m->nverts; i++)
        mx += m->verts[3 * i];
    mx /= (double)m->nverts;
    for (size_t f = 0; f < m->ntris; f++) {
        double c[3];
        tu_centroid(m, f, c);
        if (c[0] > mx)
            tu_flip_face(m, f);
    }
}

/* Unwelds: three private vertices per triangle. */
static void tu_defect_soup(hv_mesh *m)
{
    double *V = malloc(9 * m->ntris * sizeof *V);
    for (size_t f = 0; f < m->ntris; f++)
        for (int k = 0; k < 3; k++) {
            memcpy(V + 9 * f + 3 * k, m->verts + 3 * (size_t)m->tris[3 * f + k], 3 * sizeof *V);
            m->tris[3 * f + k] = (uint32_t)(3 * f + k);
        }
    free(m->verts);
    m->verts = V;
    m->nverts = 3 * m->ntris;
}

/* Appends a copy of a fraction of the faces, every other copy reversed. */
static void tu_defect_duplicate(hv_mesh *m, double frac)
{
    size_t nt = m->ntris, add = 0;
    m->tris = realloc(m->tris, 3 * 2 * nt * sizeof *m->tris);
    for (size_t f = 0; f < nt; f++)
        if (tu_rand() < frac) {
            uint32_t *t = m->tris + 3 * (nt + add);
            memcpy(t, m->tris + 3 * f, 3 * sizeof *t);
            if (add & 1) {
                uint32_t s = t[1];
                t[1] = t[2], t[2] = s;
            }
            add++;
        }
    m->ntris = nt + add;
}

/* ---------- truths ---------- */

/* 2D edge sign with symbolic perturbation p + (eps, eps^2): never zero for a
 * non-degenerate edge, and the same for every triangle sharing the edge. */
static int tu_edge_sign(double au, double av, double bu, double bv, double pu, double pv)
{
    double e = (bu - au) * (pv - av) - (bv - av) * (pu - au);
    if (e != 0)
        return e > 0 ? 1 : -1;
    if (bv != av)
        return -(bv - av) > 0 ? 1 : -1;
    return (bu - au) > 0 ? 1 : -1;
}

typedef struct tu_hit {
    size_t row;
    double x;
} tu_hit;

static int tu_cmp_hit(const void *pa, const void *pb)
{
    const tu_hit *a = pa, *b = pb;
    if (a->row != b->row)
        return a->row < b->row ? -1 : 1;
    return a->x < b->x ? -1 : a->x > b->x;
}

/* inside[c] = 1 where a ray along +x from the cell centre crosses the mesh an
 * odd number of times (exact for closed meshes of any orientation). */
static void tu_ray_parity(const hv_mesh *m, const hv_grid *g, uint8_t *inside)
{
    size_t cap = 1 << 16, nh = 0;
    tu_hit *H = malloc(cap * sizeof *H);
    for (size_t f = 0; f < m->ntris; f++) {
        const double *P[3];
        for (int k = 0; k < 3; k++)
            P[k] = m->verts + 3 * (size_t)m->tris[3 * f + k];
        double area = (P[1][1] - P[0][1]) * (P[2][2] - P[0][2]) - (P[1][2] - P[0][2]) * (P[2][1] - P[0][1]);
        if (area == 0)
            continue;
        int orient = area > 0 ? 1 : -1;
        double ylo = fmin(P[0][1], fmin(P[1][1], P[2][1])), yhi = fmax(P[0][1], fmax(P[1][1], P[2][1]));
        double zlo = fmin(P[0][2], fmin(P[1][2], P[2][2])), zhi = fmax(P[0][2], fmax(P[1][2], P[2][2]));
        int j0 = (int)ceil((ylo - g->origin[1]) / g->h - 0.5), j1 = (int)floor((yhi - g->origin[1]) / g->h - 0.5);
        int k0 = (int)ceil((zlo - g->origin[2]) / g->h - 0.5), k1 = (int)floor((zhi - g->origin[2]) / g->h - 0.5);
        if (j0 < 0) j0 = 0;
        if (k0 < 0) k0 = 0;
        if (j1 > g->n[1] - 1) j1 = g->n[1] - 1;
        if (k1 > g->n[2] - 1) k1 = g->n[2] - 1;
        for (int k = k0; k <= k1; k++)
            for (int j = j0; j <= j1; j++) {
                double pu = g->origin[1] + (j + 0.5) * g->h, pv = g->origin[2] + (k + 0.5) * g->h;
                int s0 = tu_edge_sign(P[0][1], P[0][2], P[1][1], P[1][2], pu, pv);
                int s1 = tu_edge_sign(P[1][1], P[1][2], P[2][1], P[2][2], pu, pv);
                int s2 = tu_edge_sign(P[2][1], P[2][2], P[0][1], P[0][2], pu, pv);
                if (s0 != orient || s1 != orient || s2 != orient)
                    continue;
                /* Barycentric x of the crossing. */
                double l0 = ((P[1][1] - pu) * (P[2][2] - pv) - (P[1][2] - pv) * (P[2][1] - pu)) / area;
                double l1 = ((P[2][1] - pu) * (P[0][2] - pv) - (P[2][2] - pv) * (P[0][1] - pu)) / area;
                double x = l0 * P[0][0] + l1 * P[1][0] + (1 - l0 - l1) * P[2][0];
                if (nh == cap)
                    H = realloc(H, (cap *= 2) * sizeof *H);
                H[nh].row = (size_t)j + (size_t)g->n[1] * k;
                H[nh++].x = x;
            }
    }
    qsort(H, nh, sizeof *H, tu_cmp_hit);
    size_t rows = (size_t)g->n[1] * g->n[2], h0 = 0;
    for (size_t r = 0; r < rows; r++) {
        size_t h1 = h0;
        while (h1 < nh && H[h1].row == r)
            h1++;
        size_t q = h0;
        for (int i = 0; i < g->n[0]; i++) {
            double x = g->origin[0] + (i + 0.5) * g->h;
            while (q < h1 && H[q].x < x)
                q++;
            inside[i + (size_t)g->n[0] * r] = (uint8_t)((q - h0) & 1);
        }
        h0 = h1;
    }
    free(H);
}

/* Fast generalized winding number. */
typedef struct tu_node {
    double c[3], N[3], r;
    int left, right; /* children, or -1 */
    size_t first, count;
} tu_node;

typedef struct tu_wn {
    const hv_mesh *m;
    size_t *order;
    tu_node *nodes;
    int nn, cap;
    double beta;
} tu_wn;

static double tu_solid_angle(const double *p, const double *a, const double *b, const double *c)
{
    double A[3], B[3], C[3];
    for (int d = 0; d < 3; d++)
        A[d] = a[d] - p[d], B[d] = b[d] - p[d], C[d] = c[d] - p[d];
    double la = sqrt(A[0] * A[0] + A[1] * A[1] + A[2] * A[2]), lb = sqrt(B[0] * B[0] + B[1] * B[1] + B[2] * B[2]),
           lc = sqrt(C[0] * C[0] + C[1] * C[1] + C[2] * C[2]);
    double det = A[0] * (B[1] * C[2] - B[2] * C[1]) - A[1] * (B[0] * C[2] - B[2] * C[0]) + A[2] * (B[0] * C[1] - B[1] * C[0]);
    double den = la * lb * lc + (A[0] * B[0] + A[1] * B[1] + A[2] * B[2]) * lc +
                 (A[0] * C[0] + A[1] * C[1] + A[2] * C[2]) * lb + (B[0] * C[0] + B[1] * C[1] + B[2] * C[2]) * la;
    return 2 * atan2(det, den);
}

static int tu_wn_build(tu_wn *W, size_t first, size_t count, int axis_hint)
{
    if (W->nn == W->cap)
        W->nodes = realloc(W->nodes, (W->cap = W->cap ? 2 * W->cap : 1024) * sizeof *W->nodes);
    int id = W->nn++;
    tu_node nd;
    memset(&nd, 0, sizeof nd);
    nd.first = first, nd.count = count, nd.left = nd.right = -1;
    double asum = 0, lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t q = first; q < first + count; q++) {
        size_t f = W->order[q];
        const double *a = W->m->verts + 3 * (size_t)W->m->tris[3 * f], *b = W->m->verts + 3 * (size_t)W->m->tris[3 * f + 1],
                     *c = W->m->verts + 3 * (size_t)W->m->tris[3 * f + 2];
        double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        double n[3] = {0.5 * (u[1] * v[2] - u[2] * v[1]), 0.5 * (u[2] * v[0] - u[0] * v[2]), 0.5 * (u[0] * v[1] - u[1] * v[0])};
        double A = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (int d = 0; d < 3; d++) {
            nd.N[d] += n[d];
            nd.c[d] += A * (a[d] + b[d] + c[d]) / 3;
            double cc = (a[d] + b[d] + c[d]) / 3;
            lo[d] = fmin(lo[d], cc), hi[d] = fmax(hi[d], cc);
        }
        asum += A;
    }
    for (int d = 0; d < 3; d++)
        nd.c[d] = asum > 0 ? nd.c[d] / asum : 0.5 * (lo[d] + hi[d]);
    for (size_t q = first; q < first + count; q++)
        for (int k = 0; k < 3; k++) {
            const double *x = W->m->verts + 3 * (size_t)W->m->tris[3 * W->order[q] + k];
            double r = sqrt((x[0] - nd.c[0]) * (x[0] - nd.c[0]) + (x[1] - nd.c[1]) * (x[1] - nd.c[1]) +
                            (x[2] - nd.c[2]) * (x[2] - nd.c[2]));
            nd.r = fmax(nd.r, r);
        }
    if (count > 8) {
        int ax = 0;
        for (int d = 1; d < 3; d++)
            if (hi[d] - lo[d] > hi[ax] - lo[ax])
                ax = d;
        double mid = 0.5 * (lo[ax] + hi[ax]);
        size_t i = first, j = first + count;
        while (i < j) {
            double c[3];
            tu_centroid(W->m, W->order[i], c);
            if (c[ax] < mid)
                i++;
            else {
                size_t t = W->order[i];
                W->order[i] = W->order[--j];
                W->order[j] = t;
            }
        }
        if (i == first || i == first + count)
            i = first + count / 2;
        W->nodes[id] = nd;
        int l = tu_wn_build(W, first, i - first, ax);
        int r = tu_wn_build(W, i, first + count - i, ax);
        W->nodes[id].left = l, W->nodes[id].right = r;
        return id;
    }
    (void)axis_hint;
    W->nodes[id] = nd;
    return id;
}

static double tu_wn_eval(const tu_wn *W, int id, const double p[3])
{
    const tu_node *nd = &W->nodes[id];
    double d[3] = {nd->c[0] - p[0], nd->c[1] - p[1], nd->c[2] - p[2]};
    double dist = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (dist > W->beta * nd->r)
        return (nd->N[0] * d[0] + nd->N[1] * d[1] + nd->N[2] * d[2]) / (4 * M_PI * dist * dist * dist);
    if (nd->left < 0) {
        double w = 0;
        for (size_t q = nd->first; q < nd->first + nd->count; q++) {
            const uint32_t *t = W->m->tris + 3 * W->order[q];
            w += tu_solid_angle(p, W->m->verts + 3 * (size_t)t[0], W->m->verts + 3 * (size_t)t[1],
                                W->m->verts + 3 * (size_t)t[2]);
        }
        return w / (4 * M_PI);
    }
    return tu_wn_eval(W, nd->left, p) + tu_wn_eval(W, nd->right, p);
}

/* inside[c] = 1 where the generalized winding number of the raw mesh exceeds 1/2. */
static void tu_winding(const hv_mesh *m, const hv_grid *g, uint8_t *inside)
{
    tu_wn W;
    memset(&W, 0, sizeof W);
    W.m = m;
    W.beta = 3.0;
    W.order = malloc(m->ntris * sizeof *W.order);
    for (size_t f = 0; f < m->ntris; f++)
        W.order[f] = f;
    tu_wn_build(&W, 0, m->ntris, 0);
#pragma omp parallel for collapse(2) schedule(dynamic, 4)
    for (int k = 0; k < g->n[2]; k++)
        for (int j = 0; j < g->n[1]; j++)
            for (int i = 0; i < g->n[0]; i++) {
                double p[3];
                hv_grid_cell_center(g, i, j, k, p);
                inside[i + (size_t)g->n[0] * (j + (size_t)g->n[1] * k)] = tu_wn_eval(&W, 0, p) > 0.5;
            }
    free(W.order);
    free(W.nodes);
}

/* IoU of {phi < 0} against truth. */
static double tu_iou(const hv_grid *phi, const uint8_t *inside)
{
    size_t I = 0, U = 0, n = hv_grid_count(phi);
    for (size_t c = 0; c < n; c++) {
        int a = phi->v[c] < 0, b = inside[c] != 0;
        I += a && b;
        U += a || b;
    }
    return U ? (double)I / (double)U : 1.0;
}

#endif
