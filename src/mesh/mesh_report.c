/* The defect report: edge use counts, orientation agreement, duplicate and
 * degenerate faces, components. Everything is a sort of packed keys (LSD radix,
 * stable) followed by a scan of equal runs: O(n) passes, no hashing surprises. */
#include "mesh_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Stable LSD radix sort of (key, val) pairs by key, 8 bits per pass; passes on
 * which every key has the same byte are skipped. */
static void radix_sort(uint64_t *key, uint32_t *val, uint64_t *tk, uint32_t *tv, size_t n)
{
    for (int shift = 0; shift < 64; shift += 8) {
        size_t count[256] = {0};
        for (size_t i = 0; i < n; i++)
            count[(key[i] >> shift) & 0xff]++;
        if (n == 0 || count[(key[0] >> shift) & 0xff] == n)
            continue;
        size_t sum = 0;
        for (int d = 0; d < 256; d++) {
            size_t c = count[d];
            count[d] = sum;
            sum += c;
        }
        for (size_t i = 0; i < n; i++) {
            size_t o = count[(key[i] >> shift) & 0xff]++;
            tk[o] = key[i];
            tv[o] = val[i];
        }
        memcpy(key, tk, n * sizeof *key);
        memcpy(val, tv, n * sizeof *val);
    }
}

static uint32_t uf_find(uint32_t *parent, uint32_t x)
{
    while (parent[x] != x) {
        parent[x] = parent[parent[x]];
        x = parent[x];
    }
    return x;
}

static void uf_union(uint32_t *parent, uint32_t a, uint32_t b)
{
    a = uf_find(parent, a);
    b = uf_find(parent, b);
    if (a != b) {
        if (a < b)
            parent[b] = a;
        else
            parent[a] = b;
    }
}

static uint32_t max_corner(const uint32_t *t)
{
    uint32_t m = t[0] > t[1] ? t[0] : t[1];
    return m > t[2] ? m : t[2];
}

static int collapsed(const uint32_t *t) { return t[0] == t[1] || t[1] == t[2] || t[0] == t[2]; }

/* Non-finite vertices, degenerate faces (repeated corners or zero normal)
 * and the signed volume (the divergence theorem over the finite faces). */
static void count_vertices_faces(const hv_mesh *m, hv_mesh_report *r)
{
    const size_t nt = m->ntris;
    for (size_t i = 0; i < m->nverts; i++) {
        const double *p = m->verts + 3 * i;
        if (!isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2]))
            r->nonfinite_vertices++;
    }
    double vol = 0;
    for (size_t t = 0; t < nt; t++) {
        const uint32_t *c = m->tris + 3 * t;
        if (collapsed(c)) {
            r->degenerate_faces++;
            continue;
        }
        const double *a = m->verts + 3 * (size_t)c[0], *b = m->verts + 3 * (size_t)c[1],
                     *d = m->verts + 3 * (size_t)c[2];
        double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        double v[3] = {d[0] - a[0], d[1] - a[1], d[2] - a[2]};
        double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                       u[0] * v[1] - u[1] * v[0]};
        if (n[0] == 0 && n[1] == 0 && n[2] == 0)
            r->degenerate_faces++;
        double det = a[0] * (b[1] * d[2] - b[2] * d[1]) - a[1] * (b[0] * d[2] - b[2] * d[0]) +
                     a[2] * (b[0] * d[1] - b[1] * d[0]);
        if (isfinite(det))
            vol += det / 6.0;
    }
    r->signed_volume = vol;
}

/* Keys and values to sort, with the radix sort's scratch (3 ntris each). */
typedef struct sort_buf {
    uint64_t *key, *tk;
    uint32_t *val, *tv;
} sort_buf;

static void sort_buf_free(sort_buf *b)
{
    free(b->key);
    free(b->tk);
    free(b->val);
    free(b->tv);
}

/* Duplicates: sort the triangles by their sorted corner triple (two stable
 * passes: by the largest corner, then by the two smaller ones). */
static void count_duplicates(const hv_mesh *m, sort_buf *sb, hv_mesh_report *r)
{
    const size_t nt = m->ntris;
    uint64_t *key = sb->key;
    uint32_t *val = sb->val;
    for (size_t t = 0; t < nt; t++) {
        uint32_t a = m->tris[3 * t], b = m->tris[3 * t + 1], c = m->tris[3 * t + 2], x;
        if (a > b)
            x = a, a = b, b = x;
        if (b > c)
            x = b, b = c, c = x;
        if (a > b)
            x = a, a = b, b = x;
        key[t] = c;
        val[t] = (uint32_t)t;
    }
    radix_sort(key, val, sb->tk, sb->tv, nt);
    for (size_t i = 0; i < nt; i++) {
        const uint32_t *c = m->tris + 3 * (size_t)val[i];
        uint32_t a = c[0], b = c[1], d = c[2], x;
        if (a > b)
            x = a, a = b, b = x;
        if (b > d)
            x = b, b = d, d = x;
        if (a > b)
            x = a, a = b, b = x;
        key[i] = (uint64_t)a << 32 | b;
    }
    radix_sort(key, val, sb->tk, sb->tv, nt);
    /* Within a run of equal (a, b) the largest corners ascend (the sort is
     * stable), so repeated vertex sets are neighbours. */
    for (size_t k = 1; k < nt; k++)
        if (key[k] == key[k - 1] && max_corner(m->tris + 3 * (size_t)val[k]) ==
                                        max_corner(m->tris + 3 * (size_t)val[k - 1]))
            r->duplicate_faces++;
}

/* Edges: one entry per corner of each proper triangle, keyed by the
 * undirected edge; the value is the corner (3 t + k), so the direction is
 * recovered from the triangle. The triangles sharing an edge are joined in
 * parent (nt entries): the edge-connected components. */
static void count_edges(const hv_mesh *m, sort_buf *sb, uint32_t *parent, hv_mesh_report *r)
{
    const size_t nt = m->ntris;
    uint64_t *key = sb->key;
    uint32_t *val = sb->val;
    size_t n = 0;
    for (size_t t = 0; t < nt; t++) {
        const uint32_t *c = m->tris + 3 * t;
        parent[t] = (uint32_t)t;
        if (collapsed(c))
            continue;
        for (int k = 0; k < 3; k++) {
            uint32_t a = c[k], b = c[(k + 1) % 3];
            key[n] = a < b ? (uint64_t)a << 32 | b : (uint64_t)b << 32 | a;
            val[n++] = (uint32_t)(3 * t + (size_t)k);
        }
    }
    radix_sort(key, val, sb->tk, sb->tv, n);
    for (size_t i = 0; i < n;) {
        size_t j = i + 1;
        while (j < n && key[j] == key[i])
            j++;
        size_t uses = j - i;
        r->edges++;
        if (uses == 1)
            r->boundary_edges++;
        else if (uses > 2)
            r->nonmanifold_edges++;
        else {
            uint32_t h0 = val[i], h1 = val[i + 1];
            uint32_t a0 = m->tris[h0], a1 = m->tris[h1];
            /* consistent neighbours traverse the shared edge in opposite directions */
            if (a0 == a1)
                r->inconsistent_edges++;
        }
        for (size_t k = i + 1; k < j; k++)
            uf_union(parent, val[i] / 3, val[k] / 3);
        i = j;
    }
    for (size_t t = 0; t < nt; t++)
        if (!collapsed(m->tris + 3 * t) && uf_find(parent, (uint32_t)t) == t)
            r->components++;
}

/* Vertex-connected components: union the corners of every triangle, then
 * count the distinct roots of used vertices. *parent (nt entries) grows to
 * one per vertex; the caller frees it, also on failure. */
static hv_status count_vertex_components(const hv_mesh *m, uint32_t **parent, hv_mesh_report *r)
{
    const size_t nt = m->ntris;
    uint32_t *vp = realloc(*parent, (m->nverts > nt ? m->nverts : nt) * sizeof *vp);
    if (vp)
        *parent = vp;
    unsigned char *seen = calloc(m->nverts ? m->nverts : 1, 1);
    if (!vp || !seen) {
        free(seen);
        return hv__error(HV_ERR_NOMEM, "hv_mesh_report_compute: out of memory");
    }
    for (size_t i = 0; i < m->nverts; i++)
        vp[i] = (uint32_t)i;
    for (size_t t = 0; t < nt; t++) {
        const uint32_t *c = m->tris + 3 * t;
        uf_union(vp, c[0], c[1]);
        uf_union(vp, c[1], c[2]);
    }
    for (size_t i = 0; i < 3 * nt; i++) {
        uint32_t root = uf_find(vp, m->tris[i]);
        if (!seen[root]) {
            seen[root] = 1;
            r->vertex_components++;
        }
    }
    free(seen);
    return HV_OK;
}

hv_status hv_mesh_report_compute(const hv_mesh *m, hv_mesh_report *r)
{
    if (!m || !r)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_report_compute: NULL argument");
    memset(r, 0, sizeof *r);
    size_t nt = m->ntris;
    r->vertices = m->nverts;
    r->triangles = nt;
    r->polygons_fanned = m->polygons_fanned;
    r->input_vertices = m->input_vertices;
    r->unreferenced_vertices = m->unreferenced_vertices;
    if (nt > MESH_MAX_COUNT / 3)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_report_compute: %zu triangles is too many",
                         nt);
    for (size_t i = 0; i < 3 * nt; i++)
        if (m->tris[i] >= m->nverts)
            return hv__error(HV_ERR_INVALID_ARG,
                             "hv_mesh_report_compute: triangle %zu uses vertex %u of %zu", i / 3,
                             m->tris[i], m->nverts);
    count_vertices_faces(m, r);
    if (nt == 0)
        return HV_OK;

    size_t ne = 3 * nt;
    sort_buf b;
    b.key = malloc(ne * sizeof *b.key);
    b.tk = malloc(ne * sizeof *b.tk);
    b.val = malloc(ne * sizeof *b.val);
    b.tv = malloc(ne * sizeof *b.tv);
    uint32_t *parent = malloc(nt * sizeof *parent);
    if (!b.key || !b.tk || !b.val || !b.tv || !parent) {
        sort_buf_free(&b);
        free(parent);
        return hv__error(HV_ERR_NOMEM, "hv_mesh_report_compute: out of memory for %zu triangles",
                         nt);
    }
    count_duplicates(m, &b, r);
    count_edges(m, &b, parent, r);
    hv_status st = count_vertex_components(m, &parent, r);
    sort_buf_free(&b);
    free(parent);
    return st;
}
