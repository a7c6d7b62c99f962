/* STL, binary and ascii. Binary is recognised by its size (84 + 50 n bytes for
 * the n in its header), whatever the 80-byte header says: many binary files
 * start with "solid". Every facet brings its own 3 vertices; welding joins them. */
#include "mesh_internal.h"

#include <string.h>

static float le_float(const unsigned char *b)
{
    uint32_t u = (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

static hv_status read_binary(const char *path, const char *buf, hv_mesh **out)
{
    const unsigned char *u = (const unsigned char *)buf;
    size_t n = (size_t)u[80] | (size_t)u[81] << 8 | (size_t)u[82] << 16 | (size_t)u[83] << 24;
    mesh_builder b;
    hv__mb_init(&b, path);
    hv_status st = hv__mb_reserve_verts(&b, 3 * n);
    for (size_t t = 0; t < n && !st; t++) {
        const unsigned char *f = u + 84 + 50 * t + 12; /* skip the normal */
        for (int k = 0; k < 3 && !st; k++)
            st = hv__mb_add_vertex(&b, le_float(f + 12 * k), le_float(f + 12 * k + 4),
                                   le_float(f + 12 * k + 8));
        if (!st)
            st =
                hv__mb_add_tri(&b, (uint32_t)(3 * t), (uint32_t)(3 * t + 1), (uint32_t)(3 * t + 2));
    }
    if (st) {
        hv__mb_free(&b);
        return st;
    }
    return hv__mb_finish(&b, "STL binary", out);
}

typedef struct stl_cursor {
    const char *p, *end;
    size_t line;
} stl_cursor;

/* Next white-space separated word; its length in *n; NULL at the end. */
static const char *next_word(stl_cursor *c, size_t *n)
{
    while (c->p < c->end && mesh_is_space(*c->p)) {
        if (*c->p == '\n')
            c->line++;
        c->p++;
    }
    if (c->p >= c->end)
        return NULL;
    const char *w = c->p;
    while (c->p < c->end && !mesh_is_delim(*c->p))
        c->p++;
    *n = (size_t)(c->p - w);
    if (*n == 0) { /* a NUL byte in text */
        c->p++;
        *n = 1;
    }
    return w;
}

static void skip_line(stl_cursor *c)
{
    const char *nl = memchr(c->p, '\n', (size_t)(c->end - c->p));
    c->p = nl ? nl : c->end;
}

static int is_word(const char *w, size_t n, const char *s)
{
    return w && strlen(s) == n && memcmp(w, s, n) == 0;
}

static hv_status expect(stl_cursor *c, const char *path, const char *word)
{
    size_t n;
    const char *w = next_word(c, &n);
    if (!is_word(w, n, word))
        return hv__error(HV_ERR_PARSE, "%s: line %zu: expected '%s', found '%s'", path, c->line,
                         word, w ? hv__mesh_token_preview(w, c->end) : "end of file");
    return HV_OK;
}

static hv_status read_numbers(stl_cursor *c, const char *path, double *x, int k, const char *what)
{
    for (int a = 0; a < k; a++) {
        size_t n;
        const char *w = next_word(c, &n);
        const char *e;
        if (!w || hv__mesh_parse_double(w, &e, &x[a]) || e != w + n)
            return hv__error(HV_ERR_PARSE, "%s: line %zu: malformed %s coordinate '%s'", path,
                             c->line, what, w ? hv__mesh_token_preview(w, c->end) : "end of file");
    }
    return HV_OK;
}

/* A facet's normal: three numbers, or none (some writers leave them out;
 * STL normals are never used, so that is said once, under -v). */
static hv_status facet_normal(stl_cursor *c, const char *path, int *bare)
{
    stl_cursor peek = *c;
    size_t n;
    const char *w = next_word(&peek, &n);
    if (is_word(w, n, "outer")) {
        if (!(*bare)++)
            hv__log(HV_LOG_INFO,
                    "%s: line %zu: 'facet normal' without numbers (STL normals are "
                    "not used)",
                    path, c->line);
        return HV_OK;
    }
    double x[3];
    return read_numbers(c, path, x, 3, "normal");
}

static hv_status read_ascii(const char *path, const char *buf, size_t len, hv_mesh **out)
{
    stl_cursor c = {buf, buf + len, 1};
    mesh_builder b;
    hv__mb_init(&b, path);
    u32vec loop = {0};
    hv_status st = HV_OK;
    int in_solid = 0, solids = 0, bare_normals = 0;
    size_t n;
    const char *w;
    while (!st && (w = next_word(&c, &n))) {
        if (is_word(w, n, "solid")) {
            if (in_solid) {
                st = hv__error(HV_ERR_PARSE, "%s: line %zu: 'solid' inside a solid", path, c.line);
                break;
            }
            in_solid = 1;
            solids++;
            skip_line(&c); /* the name */
        } else if (is_word(w, n, "endsolid")) {
            if (!in_solid) {
                st = hv__error(HV_ERR_PARSE, "%s: line %zu: 'endsolid' without 'solid'", path,
                               c.line);
                break;
            }
            in_solid = 0;
            skip_line(&c);
        } else if (is_word(w, n, "facet") && in_solid) {
            double x[3];
            size_t at = c.line;
            if ((st = expect(&c, path, "normal")) || (st = facet_normal(&c, path, &bare_normals)) ||
                (st = expect(&c, path, "outer")) || (st = expect(&c, path, "loop")))
                break;
            loop.n = 0;
            while (!st) {
                w = next_word(&c, &n);
                if (is_word(w, n, "endloop"))
                    break;
                if (!is_word(w, n, "vertex")) {
                    st = hv__error(HV_ERR_PARSE,
                                   "%s: line %zu: expected 'vertex' or 'endloop', "
                                   "found '%s'",
                                   path, c.line,
                                   w ? hv__mesh_token_preview(w, c.end) : "end of file");
                    break;
                }
                b.line = c.line;
                if (!(st = read_numbers(&c, path, x, 3, "vertex")) &&
                    !(st = hv__mb_add_vertex(&b, x[0], x[1], x[2])))
                    st = hv__u32vec_push(&loop, (uint32_t)(b.nv - 1));
            }
            if (st || (st = expect(&c, path, "endfacet")))
                break;
            if (loop.n < 3)
                st = hv__error(HV_ERR_PARSE, "%s: line %zu: facet with %zu vertices", path, at,
                               loop.n);
            else
                st = hv__mb_add_polygon(&b, loop.a, loop.n);
        } else {
            st = hv__error(HV_ERR_PARSE, "%s: line %zu: expected %s, found '%s'", path, c.line,
                           in_solid ? "'facet' or 'endsolid'" : "'solid'",
                           hv__mesh_token_preview(w, c.end));
        }
    }
    hv__u32vec_free(&loop);
    if (!st && in_solid)
        hv__log(HV_LOG_DEBUG, "%s: last solid has no 'endsolid'", path);
    if (!st && solids == 0)
        st = hv__error(HV_ERR_PARSE, "%s: no 'solid' in the file", path);
    if (st) {
        hv__mb_free(&b);
        return st;
    }
    return hv__mb_finish(&b, "STL ascii", out);
}

hv_status hv__mesh_read_stl(const char *path, const char *buf, size_t len, hv_mesh **out)
{
    *out = NULL;
    if (len >= 84) {
        const unsigned char *u = (const unsigned char *)buf;
        uint64_t n =
            (uint64_t)u[80] | (uint64_t)u[81] << 8 | (uint64_t)u[82] << 16 | (uint64_t)u[83] << 24;
        if ((uint64_t)len == 84 + 50 * n)
            return read_binary(path, buf, out);
    }
    const unsigned char *u = (const unsigned char *)buf;
    size_t bom = len >= 3 && u[0] == 0xEF && u[1] == 0xBB && u[2] == 0xBF ? 3 : 0;
    const char *p = buf + bom;
    while (p < buf + len && mesh_is_space(*p))
        p++;
    if (strncmp(p, "solid", 5) == 0 && mesh_is_delim(p[5]))
        return read_ascii(path, buf + bom, len - bom, out);
    if (len >= 2 && ((u[0] == 0xFE && u[1] == 0xFF) || (u[0] == 0xFF && u[1] == 0xFE)))
        return hv__error(HV_ERR_PARSE, "%s: UTF-16 text (byte order mark); save it as ASCII", path);
    if (len >= 84) {
        uint64_t n =
            (uint64_t)u[80] | (uint64_t)u[81] << 8 | (uint64_t)u[82] << 16 | (uint64_t)u[83] << 24;
        return hv__error(HV_ERR_PARSE,
                         "%s: binary STL header declares %llu triangles (%llu bytes) but the file "
                         "has %zu bytes",
                         path, (unsigned long long)n, (unsigned long long)(84 + 50 * n), len);
    }
    return hv__error(HV_ERR_PARSE,
                     "%s: neither ascii STL (no 'solid') nor binary STL (%zu bytes, less than the "
                     "84-byte header)",
                     path, len);
}
