/* Exact closest points on a triangle mesh (tri_buckets.h). */
#include "tri_buckets.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Closest point to p on triangle abc (Ericson, Real-Time Collision Detection,
 * 5.1.5: by the Voronoi regions of the vertices, edges and face). */
void tri_closest_point(const double p[3], const double *a, const double *b, const double *c,
                       double out[3])
{
    double ab[3], ac[3], ap[3], bp[3], cp[3];
    for (int k = 0; k < 3; k++) {
        ab[k] = b[k] - a[k];
        ac[k] = c[k] - a[k];
        ap[k] = p[k] - a[k];
        bp[k] = p[k] - b[k];
        cp[k] = p[k] - c[k];
    }
#define DOT(u, w) ((u)[0] * (w)[0] + (u)[1] * (w)[1] + (u)[2] * (w)[2])
    const double d1 = DOT(ab, ap), d2 = DOT(ac, ap), d3 = DOT(ab, bp), d4 = DOT(ac, bp);
    const double d5 = DOT(ab, cp), d6 = DOT(ac, cp);
#undef DOT
    double u = 0, w = 0; /* out = a + u ab + w ac */
    const double vc = d1 * d4 - d3 * d2, vb = d5 * d2 - d1 * d6, va = d3 * d6 - d5 * d4;
    if (d1 <= 0 && d2 <= 0) {
    } else if (d3 >= 0 && d4 <= d3) {
        u = 1;
    } else if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        u = d1 / (d1 - d3);
    } else if (d6 >= 0 && d5 <= d6) {
        w = 1;
    } else if (vb <= 0 && d2 >= 0 && d6 <= 0) {
        w = d2 / (d2 - d6);
    } else if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) {
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        u = 1 - w;
    } else {
        const double s = va + vb + vc;
        u = s > 0 ? vb / s : 0;
        w = s > 0 ? vc / s : 0;
    }
    for (int k = 0; k < 3; k++)
        out[k] = a[k] + u * ab[k] + w * ac[k];
}

typedef struct tri_pair {
    uint64_t key;
    uint32_t tri;
} tri_pair;

static int pair_cmp(const void *a, const void *b)
{
    const tri_pair *p = a, *q = b;
    return p->key < q->key ? -1 : p->key > q->key;
}

static inline uint64_t bucket_key(int i, int j, int k)
{
    return (uint64_t)i | (uint64_t)j << 21 | (uint64_t)k << 42;
}

static inline size_t bucket_slot(uint64_t key, size_t mask)
{
    return (size_t)((key * 0x9e3779b97f4a7c15ull) >> 24) & mask;
}

void tri_buckets_free(tri_buckets *b)
{
    free(b->key);
    free(b->first);
    free(b->count);
    free(b->tri);
    memset(b, 0, sizeof *b);
}

/* Each triangle's range of buckets, 6 ints (i0 j0 k0 i1 j1 k1) a triangle;
 * the number of (bucket, triangle) pairs in *npairs. */
static int *tri_ranges(const tri_buckets *b, size_t *npairs)
{
    const hv_mesh *m = b->m;
    int *range = malloc(m->ntris * 6 * sizeof *range);
    if (!range)
        return NULL;
    *npairs = 0;
    for (size_t t = 0; t < m->ntris; t++) {
        size_t cnt = 1;
        for (int a = 0; a < 3; a++) {
            double mn = INFINITY, mx = -INFINITY;
            for (int c = 0; c < 3; c++) {
                double x = m->verts[3 * m->tris[3 * t + c] + a];
                mn = fmin(mn, x);
                mx = fmax(mx, x);
            }
            int *r = range + 6 * t;
            r[a] = (int)floor((mn - b->lo[a]) / b->size);
            r[3 + a] = (int)floor((mx - b->lo[a]) / b->size);
            cnt *= (size_t)(r[3 + a] - r[a] + 1);
        }
        *npairs += cnt;
    }
    return range;
}

/* The (bucket, triangle) pairs sorted by bucket, or NULL. */
static tri_pair *sorted_pairs(const tri_buckets *b, size_t *npairs)
{
    int *range = tri_ranges(b, npairs);
    tri_pair *pairs = range ? malloc(*npairs * sizeof *pairs) : NULL;
    if (!pairs) {
        free(range);
        return NULL;
    }
    size_t np = 0;
    for (size_t t = 0; t < b->m->ntris; t++) {
        const int *r = range + 6 * t;
        for (int k = r[2]; k <= r[5]; k++)
            for (int j = r[1]; j <= r[4]; j++)
                for (int i = r[0]; i <= r[3]; i++)
                    pairs[np++] = (tri_pair){bucket_key(i, j, k), (uint32_t)t};
    }
    free(range);
    qsort(pairs, *npairs, sizeof *pairs, pair_cmp);
    return pairs;
}

/* The hash table over the sorted pairs: one slot per bucket (open
 * addressing), its triangles a run of b->tri. */
static hv_status hash_pairs(tri_buckets *b, const tri_pair *pairs, size_t npairs)
{
    size_t nkeys = 0;
    for (size_t p = 0; p < npairs; p++)
        nkeys += !p || pairs[p].key != pairs[p - 1].key;
    size_t cap = 16;
    while (cap < 2 * nkeys)
        cap *= 2;
    b->mask = cap - 1;
    b->key = calloc(cap, sizeof *b->key);
    b->first = malloc(cap * sizeof *b->first);
    b->count = malloc(cap * sizeof *b->count);
    b->tri = malloc(npairs * sizeof *b->tri);
    if (!b->key || !b->first || !b->count || !b->tri)
        return HV_ERR_NOMEM;
    for (size_t p = 0, s = 0; p < npairs; p++) {
        b->tri[p] = pairs[p].tri;
        if (p && pairs[p].key == pairs[p - 1].key) {
            b->count[s]++;
            continue;
        }
        s = bucket_slot(pairs[p].key, b->mask);
        while (b->key[s])
            s = (s + 1) & b->mask;
        b->key[s] = pairs[p].key + 1;
        b->first[s] = (uint32_t)p;
        b->count[s] = 1;
    }
    return HV_OK;
}

hv_status tri_buckets_build(tri_buckets *b, const hv_mesh *m, double size)
{
    memset(b, 0, sizeof *b);
    b->m = m;
    b->size = size;
    double hi[3];
    hv_status st = hv_mesh_bounds(m, b->lo, hi);
    if (st)
        return st;
    for (int a = 0; a < 3; a++) {
        b->lo[a] -= size;
        if ((hi[a] - b->lo[a]) / size > (1 << 20))
            return HV_ERR_INVALID_ARG;
    }
    size_t npairs = 0;
    tri_pair *pairs = sorted_pairs(b, &npairs);
    st = pairs ? hash_pairs(b, pairs, npairs) : HV_ERR_NOMEM;
    free(pairs);
    if (st)
        tri_buckets_free(b);
    return st;
}

int tri_buckets_closest(const tri_buckets *b, const double x[3], double r, double cp[3])
{
    int lo[3], hi[3];
    for (int a = 0; a < 3; a++) {
        lo[a] = (int)fmax(0, floor((x[a] - r - b->lo[a]) / b->size));
        hi[a] = (int)fmin(1 << 20, floor((x[a] + r - b->lo[a]) / b->size));
    }
    double best = INFINITY;
    for (int k = lo[2]; k <= hi[2]; k++)
        for (int j = lo[1]; j <= hi[1]; j++)
            for (int i = lo[0]; i <= hi[0]; i++) {
                const uint64_t key = bucket_key(i, j, k);
                size_t s = bucket_slot(key, b->mask);
                while (b->key[s] && b->key[s] != key + 1)
                    s = (s + 1) & b->mask;
                if (!b->key[s])
                    continue;
                for (uint32_t e = b->first[s]; e < b->first[s] + b->count[s]; e++) {
                    const uint32_t *t = b->m->tris + 3 * (size_t)b->tri[e];
                    const double *v = b->m->verts;
                    double q[3];
                    tri_closest_point(x, v + 3 * t[0], v + 3 * t[1], v + 3 * t[2], q);
                    double d = 0;
                    for (int a = 0; a < 3; a++)
                        d += (q[a] - x[a]) * (q[a] - x[a]);
                    if (d < best) {
                        best = d;
                        memcpy(cp, q, sizeof q);
                    }
                }
            }
    return best < INFINITY ? 0 : -1;
}
