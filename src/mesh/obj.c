/* Wavefront OBJ: `v` and `f` records; everything else (vt, vn, vp, l, p, g, o,
 * s, usemtl, mtllib, comments, unknown records) is skipped. */
#include "mesh_internal.h"

#include <string.h>

static int word_is(const char *s, size_t n, const char *w)
{
    return strlen(w) == n && memcmp(s, w, n) == 0;
}

static const char *skip_hspace(const char *p, const char *eol)
{
    while (p < eol && mesh_is_hspace(*p))
        p++;
    return p;
}

hv_status hv__mesh_read_obj(const char *path, const char *buf, size_t len, hv_mesh **out)
{
    *out = NULL;
    const unsigned char *u = (const unsigned char *)buf;
    if (len >= 2 && ((u[0] == 0xFE && u[1] == 0xFF) || (u[0] == 0xFF && u[1] == 0xFE)))
        return hv__error(HV_ERR_PARSE,
                         "%s: UTF-16 text (byte order mark); save the OBJ as UTF-8 or ASCII", path);
    const char *p = buf, *end = buf + len;
    if (len >= 3 && u[0] == 0xEF && u[1] == 0xBB && u[2] == 0xBF)
        p += 3; /* UTF-8 byte order mark */

    mesh_builder b;
    hv__mb_init(&b, path);
    u32vec corners = {0};
    hv_status st = HV_OK;
    size_t line = 0;
    /* Positive indices may point past the vertices read so far (some writers put
     * faces first); the largest is checked at the end. */
    uint64_t max_forward = 0;
    size_t max_forward_line = 0;

    while (p < end && !st) {
        line++;
        const char *eol = memchr(p, '\n', (size_t)(end - p));
        if (!eol)
            eol = end;
        const char *next = eol < end ? eol + 1 : end;
        const char *lend = eol;
        if (lend > p && lend[-1] == '\r')
            lend--;
        const char *q = skip_hspace(p, lend);
        const char *kw = q;
        while (q < lend && !mesh_is_delim(*q))
            q++;
        size_t kwlen = (size_t)(q - kw);

        if (word_is(kw, kwlen, "v")) {
            double x[3];
            for (int a = 0; a < 3; a++) {
                q = skip_hspace(q, lend);
                const char *e;
                if (q >= lend) {
                    st = hv__error(HV_ERR_PARSE, "%s: line %zu: vertex has %d coordinates, needs 3",
                                   path, line, a);
                    break;
                }
                if (hv__mesh_parse_double(q, &e, &x[a]) || (e < lend && !mesh_is_delim(*e)) ||
                    e > lend) {
                    st = hv__error(HV_ERR_PARSE, "%s: line %zu: malformed number '%s'", path, line,
                                   hv__mesh_token_preview(q, lend));
                    break;
                }
                q = e;
            }
            b.line = line;
            if (!st)
                st = hv__mb_add_vertex(&b, x[0], x[1], x[2]);
        } else if (word_is(kw, kwlen, "f") || word_is(kw, kwlen, "fo")) {
            corners.n = 0;
            for (;;) {
                q = skip_hspace(q, lend);
                if (q >= lend)
                    break;
                const char *e;
                int64_t i;
                if (hv__mesh_parse_i64(q, &e, &i) ||
                    (e < lend && !mesh_is_delim(*e) && *e != '/')) {
                    st = hv__error(HV_ERR_PARSE, "%s: line %zu: malformed face corner '%s'", path,
                                   line, hv__mesh_token_preview(q, lend));
                    break;
                }
                /* skip /vt/vn */
                while (e < lend && !mesh_is_delim(*e))
                    e++;
                int64_t idx;
                if (i > 0) {
                    idx = i - 1;
                    if ((uint64_t)i > b.nv && (uint64_t)i > max_forward) {
                        max_forward = (uint64_t)i;
                        max_forward_line = line;
                    }
                } else if (i < 0) {
                    idx = (int64_t)b.nv + i;
                    if (idx < 0) {
                        st = hv__error(HV_ERR_PARSE,
                                       "%s: line %zu: relative vertex index %lld points before the "
                                       "first vertex (%zu vertices so far)",
                                       path, line, (long long)i, b.nv);
                        break;
                    }
                } else {
                    st = hv__error(HV_ERR_PARSE,
                                   "%s: line %zu: vertex index 0 (OBJ indices start at 1)", path,
                                   line);
                    break;
                }
                if ((uint64_t)idx >= MESH_MAX_COUNT) {
                    st = hv__error(HV_ERR_PARSE, "%s: line %zu: vertex index %lld too large", path,
                                   line, (long long)i);
                    break;
                }
                st = hv__u32vec_push(&corners, (uint32_t)idx);
                if (st)
                    break;
                q = e;
            }
            if (!st && corners.n < 3)
                st = hv__error(HV_ERR_PARSE,
                               "%s: line %zu: face with %zu corners (a face needs at least 3)",
                               path, line, corners.n);
            if (!st)
                st = hv__mb_add_polygon(&b, corners.a, corners.n);
        }
        p = next;
    }
    hv__u32vec_free(&corners);
    if (!st && max_forward > b.nv)
        st = hv__error(HV_ERR_PARSE,
                       "%s: line %zu: vertex index %llu out of range (the file has %zu vertices)",
                       path, max_forward_line, (unsigned long long)max_forward, b.nv);
    if (st) {
        hv__mb_free(&b);
        return st;
    }
    return hv__mb_finish(&b, "OBJ", out);
}
