/* Building meshes: the reader-side builder, welding by exact position, and the
 * mesh object's lifecycle. */
#include "mesh_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static hv_status grow(void **p, size_t *cap, size_t need, size_t elem, const char *path)
{
    if (need <= *cap)
        return HV_OK;
    size_t c = *cap ? *cap : 64;
    while (c < need) {
        if (c > SIZE_MAX / 2 / elem)
            return hv__error(HV_ERR_NOMEM, "%s: mesh too large", path ? path : "mesh");
        c *= 2;
    }
    void *q = realloc(*p, c * elem);
    if (!q)
        return hv__error(HV_ERR_NOMEM, "%s: out of memory for %zu elements", path ? path : "mesh",
                         c);
    *p = q;
    *cap = c;
    return HV_OK;
}

hv_status hv__u32vec_push(u32vec *v, uint32_t x)
{
    if (v->n == v->cap) {
        hv_status st = grow((void **)&v->a, &v->cap, v->n + 1, sizeof *v->a, NULL);
        if (st)
            return st;
    }
    v->a[v->n++] = x;
    return HV_OK;
}

void hv__u32vec_free(u32vec *v)
{
    free(v->a);
    v->a = NULL;
    v->n = v->cap = 0;
}

void hv__mb_init(mesh_builder *b, const char *path)
{
    memset(b, 0, sizeof *b);
    b->path = path;
}

void hv__mb_free(mesh_builder *b)
{
    free(b->v);
    free(b->t);
    hv__mb_init(b, b->path);
}

hv_status hv__mb_reserve_verts(mesh_builder *b, size_t n)
{
    if (n > MESH_MAX_COUNT - b->nv)
        return hv__error(HV_ERR_PARSE, "%s: more than %zu vertices", b->path, MESH_MAX_COUNT);
    size_t need = b->nv + n;
    if (need <= b->vcap)
        return HV_OK;
    double *q = realloc(b->v, need * 3 * sizeof *q);
    if (!q)
        return hv__error(HV_ERR_NOMEM, "%s: out of memory for %zu vertices", b->path, need);
    b->v = q;
    b->vcap = need;
    return HV_OK;
}

/* The index of the first coordinate of p[0..2] that is finite but beyond
 * MESH_MAX_COORD, or -1. */
static int absurd_coord(const double *p)
{
    for (int a = 0; a < 3; a++)
        if (isfinite(p[a]) && fabs(p[a]) > MESH_MAX_COORD)
            return a;
    return -1;
}

hv_status hv__mb_add_vertex(mesh_builder *b, double x, double y, double z)
{
    const double c[3] = {x, y, z};
    int a = absurd_coord(c);
    if (a >= 0) {
        char at[48] = "";
        if (b->line)
            snprintf(at, sizeof at, "line %zu: ", b->line);
        return hv__error(HV_ERR_NUMERIC,
                         "%s: %svertex %zu: coordinate %c = %g is beyond the bound +-%g heatvox "
                         "accepts (volumes and bounding boxes of such a mesh overflow)",
                         b->path, at, b->nv + 1, "xyz"[a], c[a], MESH_MAX_COORD);
    }
    if (b->nv == b->vcap) {
        if (b->nv >= MESH_MAX_COUNT)
            return hv__error(HV_ERR_PARSE, "%s: more than %zu vertices", b->path, MESH_MAX_COUNT);
        hv_status st = grow((void **)&b->v, &b->vcap, b->nv + 1, 3 * sizeof *b->v, b->path);
        if (st)
            return st;
    }
    if (!b->nonfinite_vertex && !(isfinite(x) && isfinite(y) && isfinite(z))) {
        b->nonfinite_vertex = b->nv + 1;
        b->nonfinite_line = b->line;
    }
    double *p = b->v + 3 * b->nv++;
    p[0] = x;
    p[1] = y;
    p[2] = z;
    return HV_OK;
}

hv_status hv__mb_add_tri(mesh_builder *b, uint32_t a, uint32_t c1, uint32_t c2)
{
    if (b->nt == b->tcap) {
        if (b->nt >= MESH_MAX_COUNT)
            return hv__error(HV_ERR_PARSE, "%s: more than %zu triangles", b->path, MESH_MAX_COUNT);
        hv_status st = grow((void **)&b->t, &b->tcap, b->nt + 1, 3 * sizeof *b->t, b->path);
        if (st)
            return st;
    }
    uint32_t *p = b->t + 3 * b->nt++;
    p[0] = a;
    p[1] = c1;
    p[2] = c2;
    return HV_OK;
}

hv_status hv__mb_add_polygon(mesh_builder *b, const uint32_t *idx, size_t k)
{
    if (k < 3)
        return hv__error(HV_ERR_INTERNAL, "%s: polygon with %zu corners", b->path, k);
    for (size_t i = 1; i + 1 < k; i++) {
        hv_status st = hv__mb_add_tri(b, idx[0], idx[i], idx[i + 1]);
        if (st)
            return st;
    }
    if (k > 3)
        b->polygons_fanned++;
    return HV_OK;
}

/* ---- welding ---- */

static uint64_t dbits(double x)
{
    uint64_t u;
    memcpy(&u, &x, sizeof u);
    return u;
}

static uint64_t hash3(const double *p)
{
    uint64_t h = dbits(p[0]) * 0x9E3779B97F4A7C15ull;
    h ^= dbits(p[1]) + 0x632BE59BD9B4E019ull + (h << 6) + (h >> 2);
    h ^= dbits(p[2]) * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
    h ^= h >> 33;
    h *= 0xFF51AFD7ED558CCDull;
    h ^= h >> 33;
    return h;
}

hv_status hv__mesh_weld(const double *verts, size_t nverts, uint32_t *tris, size_t ntris,
                        double **wverts, size_t *wn, size_t *nreferenced)
{
    *wverts = NULL;
    *wn = 0;
    uint32_t *map = malloc((nverts ? nverts : 1) * sizeof *map);
    if (!map)
        return hv__error(HV_ERR_NOMEM, "out of memory welding %zu vertices", nverts);
    const uint32_t unused = UINT32_MAX;
    for (size_t i = 0; i < nverts; i++)
        map[i] = unused;
    size_t nref = 0;
    for (size_t i = 0; i < 3 * ntris; i++)
        if (map[tris[i]] == unused) {
            map[tris[i]] = 0;
            nref++;
        }
    size_t cap = 16;
    while (cap < 2 * nref)
        cap *= 2;
    uint32_t *table = malloc(cap * sizeof *table);
    double *out = malloc((nref ? nref : 1) * 3 * sizeof *out);
    if (!table || !out) {
        free(map);
        free(table);
        free(out);
        return hv__error(HV_ERR_NOMEM, "out of memory welding %zu vertices", nverts);
    }
    memset(table, 0xff, cap * sizeof *table);
    size_t n = 0;
    for (size_t i = 0; i < nverts; i++) {
        if (map[i] == unused)
            continue;
        double p[3];
        int has_nan = 0;
        for (int a = 0; a < 3; a++) {
            double x = verts[3 * i + a];
            p[a] = x == 0 ? 0.0 : x; /* -0 and +0 are the same position */
            has_nan |= isnan(x);
        }
        uint32_t id = UINT32_MAX;
        if (!has_nan) { /* NaN equals nothing, so NaN vertices stay apart */
            size_t h = (size_t)hash3(p) & (cap - 1);
            while (table[h] != UINT32_MAX) {
                const double *q = out + 3 * (size_t)table[h];
                if (q[0] == p[0] && q[1] == p[1] && q[2] == p[2]) {
                    id = table[h];
                    break;
                }
                h = (h + 1) & (cap - 1);
            }
            if (id == UINT32_MAX)
                table[h] = (uint32_t)n;
        }
        if (id == UINT32_MAX) {
            id = (uint32_t)n++;
            memcpy(out + 3 * (size_t)id, p, sizeof p);
        }
        map[i] = id;
    }
    for (size_t i = 0; i < 3 * ntris; i++)
        tris[i] = map[tris[i]];
    free(map);
    free(table);
    if (n < nref) {
        double *shrunk = realloc(out, (n ? n : 1) * 3 * sizeof *out);
        if (shrunk)
            out = shrunk;
    }
    *wverts = out;
    *wn = n;
    if (nreferenced)
        *nreferenced = nref;
    return HV_OK;
}

hv_status hv__mb_finish(mesh_builder *b, const char *format, hv_mesh **out)
{
    *out = NULL;
    hv_status st = HV_OK;
    if (b->nt == 0) {
        st = b->nv ? hv__error(HV_ERR_PARSE,
                               "%s: no triangles (%zu vertices and no faces: a "
                               "point cloud or lines, not a surface)",
                               b->path, b->nv)
                   : hv__error(HV_ERR_PARSE, "%s: no triangles (no vertices or faces found)",
                               b->path);
        hv__mb_free(b);
        return st;
    }
    for (size_t i = 0; i < 3 * b->nt; i++)
        if (b->t[i] >= b->nv) {
            st = hv__error(HV_ERR_INTERNAL, "%s: index %u past %zu vertices", b->path, b->t[i],
                           b->nv);
            hv__mb_free(b);
            return st;
        }
    hv_mesh *m = calloc(1, sizeof *m);
    if (!m) {
        hv__mb_free(b);
        return hv__error(HV_ERR_NOMEM, "%s: out of memory", b->path);
    }
    size_t nref = 0;
    st = hv__mesh_weld(b->v, b->nv, b->t, b->nt, &m->verts, &m->nverts, &nref);
    if (st) {
        free(m);
        hv__mb_free(b);
        return st;
    }
    m->tris = b->t;
    b->t = NULL;
    if (b->tcap > b->nt) {
        uint32_t *q = realloc(m->tris, b->nt * 3 * sizeof *q);
        if (q)
            m->tris = q;
    }
    m->ntris = b->nt;
    m->format = format;
    m->input_vertices = b->nv;
    m->unreferenced_vertices = b->nv - nref;
    m->polygons_fanned = b->polygons_fanned;
    m->nonfinite_vertex = b->nonfinite_vertex;
    m->nonfinite_line = b->nonfinite_line;
    hv__mb_free(b);
    *out = m;
    return HV_OK;
}

/* ---- the mesh object ---- */

hv_status hv_mesh_from_arrays(hv_mesh **out, const double *verts, size_t nverts,
                              const uint32_t *tris, size_t ntris)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_from_arrays: out is NULL");
    *out = NULL;
    if (ntris == 0)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_from_arrays: no triangles");
    if (!verts || !tris)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_from_arrays: %s is NULL",
                         verts ? "tris" : "verts");
    if (nverts > MESH_MAX_COUNT || ntris > MESH_MAX_COUNT)
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_mesh_from_arrays: %zu vertices, %zu triangles: at most %zu each",
                         nverts, ntris, MESH_MAX_COUNT);
    for (size_t i = 0; i < 3 * ntris; i++)
        if (tris[i] >= nverts)
            return hv__error(HV_ERR_INVALID_ARG,
                             "hv_mesh_from_arrays: triangle %zu uses vertex %u, but there are "
                             "only %zu vertices",
                             i / 3, tris[i], nverts);
    for (size_t i = 0; i < nverts; i++) {
        int a = absurd_coord(verts + 3 * i);
        if (a >= 0)
            return hv__error(HV_ERR_NUMERIC,
                             "hv_mesh_from_arrays: vertex %zu: coordinate %c = %g is beyond the "
                             "bound +-%g heatvox accepts",
                             i, "xyz"[a], verts[3 * i + a], MESH_MAX_COORD);
    }
    hv_mesh *m = calloc(1, sizeof *m);
    uint32_t *t = malloc(ntris * 3 * sizeof *t);
    if (!m || !t) {
        free(m);
        free(t);
        return hv__error(HV_ERR_NOMEM, "hv_mesh_from_arrays: out of memory for %zu triangles",
                         ntris);
    }
    memcpy(t, tris, ntris * 3 * sizeof *t);
    size_t nref = 0;
    hv_status st = hv__mesh_weld(verts, nverts, t, ntris, &m->verts, &m->nverts, &nref);
    if (st) {
        free(m);
        free(t);
        return st;
    }
    m->tris = t;
    m->ntris = ntris;
    m->input_vertices = nverts;
    m->unreferenced_vertices = nverts - nref;
    *out = m;
    return HV_OK;
}

hv_status hv__mesh_from_arrays_as_is(hv_mesh **out, const double *verts, size_t nverts,
                                     const uint32_t *tris, size_t ntris)
{
    *out = NULL;
    if (ntris == 0 || nverts == 0 || nverts > MESH_MAX_COUNT || ntris > MESH_MAX_COUNT)
        return hv__error(HV_ERR_INVALID_ARG, "mesh: %zu vertices, %zu triangles: need 1..%zu each",
                         nverts, ntris, MESH_MAX_COUNT);
    for (size_t i = 0; i < 3 * ntris; i++)
        if (tris[i] >= nverts)
            return hv__error(HV_ERR_INTERNAL, "mesh: triangle %zu uses vertex %u of %zu", i / 3,
                             tris[i], nverts);
    hv_mesh *m = calloc(1, sizeof *m);
    if (m) {
        m->verts = malloc(nverts * 3 * sizeof *m->verts);
        m->tris = malloc(ntris * 3 * sizeof *m->tris);
    }
    if (!m || !m->verts || !m->tris) {
        hv_mesh_destroy(&m);
        return hv__error(HV_ERR_NOMEM, "mesh: out of memory for %zu triangles", ntris);
    }
    memcpy(m->verts, verts, nverts * 3 * sizeof *m->verts);
    memcpy(m->tris, tris, ntris * 3 * sizeof *m->tris);
    m->nverts = nverts;
    m->ntris = ntris;
    *out = m;
    return HV_OK;
}

hv_status hv_mesh_clone(const hv_mesh *m, hv_mesh **out)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_clone: out is NULL");
    *out = NULL;
    if (!m)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_clone: mesh is NULL");
    hv_mesh *c = calloc(1, sizeof *c);
    if (!c)
        return hv__error(HV_ERR_NOMEM, "hv_mesh_clone: out of memory");
    *c = *m;
    c->verts = malloc((m->nverts ? m->nverts : 1) * 3 * sizeof *c->verts);
    c->tris = malloc((m->ntris ? m->ntris : 1) * 3 * sizeof *c->tris);
    if (!c->verts || !c->tris) {
        hv_mesh_destroy(&c);
        return hv__error(HV_ERR_NOMEM, "hv_mesh_clone: out of memory for %zu triangles", m->ntris);
    }
    if (m->nverts)
        memcpy(c->verts, m->verts, m->nverts * 3 * sizeof *c->verts);
    if (m->ntris)
        memcpy(c->tris, m->tris, m->ntris * 3 * sizeof *c->tris);
    *out = c;
    return HV_OK;
}

void hv_mesh_destroy(hv_mesh **m)
{
    if (!m || !*m)
        return;
    free((*m)->verts);
    free((*m)->tris);
    free(*m);
    *m = NULL;
}

hv_status hv_mesh_bounds(const hv_mesh *m, double lo[3], double hi[3])
{
    if (!m || !lo || !hi)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_bounds: NULL argument");
    for (int a = 0; a < 3; a++) {
        lo[a] = INFINITY;
        hi[a] = -INFINITY;
    }
    size_t nfinite = 0;
    for (size_t i = 0; i < m->nverts; i++) {
        const double *p = m->verts + 3 * i;
        if (!isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2]))
            continue;
        nfinite++;
        for (int a = 0; a < 3; a++) {
            if (p[a] < lo[a])
                lo[a] = p[a];
            if (p[a] > hi[a])
                hi[a] = p[a];
        }
    }
    if (!nfinite)
        return hv__error(HV_ERR_NUMERIC, "hv_mesh_bounds: none of the %zu vertices is finite",
                         m->nverts);
    return HV_OK;
}
