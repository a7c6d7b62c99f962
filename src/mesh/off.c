/* OFF (Geomview): an optional OFF/COFF/NOFF/CNOFF/STOFF... keyword, the counts
 * "nv nf [ne]" (possibly on the keyword's line), nv vertex lines "x y z ..." and
 * nf face lines "k i1 .. ik ...". Anything after the coordinates or indices on
 * a line (colours, normals, texture coordinates) is ignored; # starts a comment. */
#include "mesh_internal.h"

#include <string.h>

typedef struct off_cursor {
    const char *p, *end;
    size_t line;
} off_cursor;

/* Next line with something on it, comments and trailing space removed. */
static int next_line(off_cursor *c, const char **s, const char **e)
{
    while (c->p < c->end) {
        c->line++;
        const char *ls = c->p;
        const char *eol = memchr(ls, '\n', (size_t)(c->end - ls));
        if (!eol)
            eol = c->end;
        c->p = eol < c->end ? eol + 1 : c->end;
        const char *hash = memchr(ls, '#', (size_t)(eol - ls));
        const char *le = hash ? hash : eol;
        while (ls < le && mesh_is_space(*ls))
            ls++;
        while (le > ls && mesh_is_space(le[-1]))
            le--;
        if (ls < le) {
            *s = ls;
            *e = le;
            return 1;
        }
    }
    return 0;
}

static const char *skip_hspace(const char *p, const char *e)
{
    while (p < e && mesh_is_hspace(*p))
        p++;
    return p;
}

/* Reads an integer token from [*p, e); -1 if none or malformed. */
static int line_int(const char **p, const char *e, int64_t *v)
{
    const char *q = skip_hspace(*p, e), *t;
    if (q >= e || hv__mesh_parse_i64(q, &t, v) || (t < e && !mesh_is_delim(*t)) || t > e)
        return -1;
    *p = t;
    return 0;
}

static int is_off_keyword(const char *w, size_t n)
{
    static const char *const words[] = {"OFF",   "COFF",   "NOFF",   "CNOFF",
                                        "STOFF", "STCOFF", "STNOFF", "STCNOFF"};
    for (size_t i = 0; i < sizeof words / sizeof words[0]; i++)
        if (strlen(words[i]) == n && memcmp(words[i], w, n) == 0)
            return 1;
    return 0;
}

hv_status hv__mesh_read_off(const char *path, const char *buf, size_t len, hv_mesh **out)
{
    *out = NULL;
    const unsigned char *u = (const unsigned char *)buf;
    if (len >= 2 && ((u[0] == 0xFE && u[1] == 0xFF) || (u[0] == 0xFF && u[1] == 0xFE)))
        return hv__error(HV_ERR_PARSE, "%s: UTF-16 text (byte order mark); save it as ASCII", path);
    off_cursor c = {buf, buf + len, 0};
    if (len >= 3 && u[0] == 0xEF && u[1] == 0xBB && u[2] == 0xBF)
        c.p += 3;
    const char *s, *e;
    if (!next_line(&c, &s, &e))
        return hv__error(HV_ERR_PARSE, "%s: no OFF header or counts", path);

    /* keyword, then the counts on the same line or the next */
    if (!((*s >= '0' && *s <= '9') || *s == '+')) {
        const char *w = s;
        while (s < e && !mesh_is_delim(*s))
            s++;
        if (!is_off_keyword(w, (size_t)(s - w)))
            return hv__error(HV_ERR_PARSE,
                             "%s: line %zu: '%s' is not an OFF header heatvox reads (OFF, COFF, "
                             "NOFF, CNOFF, STOFF; 4OFF and nOFF are not supported)",
                             path, c.line, hv__mesh_token_preview(w, e));
        s = skip_hspace(s, e);
        if (s >= e && !next_line(&c, &s, &e))
            return hv__error(HV_ERR_PARSE, "%s: no vertex and face counts after the header", path);
    }
    int64_t nv, nf;
    size_t count_line = c.line;
    if (line_int(&s, e, &nv) || line_int(&s, e, &nf) || nv < 0 || nf < 0)
        return hv__error(HV_ERR_PARSE, "%s: line %zu: expected 'vertices faces [edges]' counts",
                         path, count_line);

    /* A vertex line takes at least 6 bytes ("0 0 0\n") and a face line 8
     * ("3 0 1 2\n"): counts the file cannot hold are refused before allocating. */
    size_t left = (size_t)(c.end - c.p) + 1;
    if ((uint64_t)nv > left / 6 || (uint64_t)nf > left / 8 ||
        (uint64_t)nv * 6 + (uint64_t)nf * 8 > left)
        return hv__error(HV_ERR_PARSE,
                         "%s: line %zu: declares %lld vertices and %lld faces, but only %zu bytes "
                         "follow (need at least %.0f)",
                         path, count_line, (long long)nv, (long long)nf, left - 1,
                         (double)nv * 6 + (double)nf * 8 - 1);

    mesh_builder b;
    hv__mb_init(&b, path);
    u32vec poly = {0};
    hv_status st = hv__mb_reserve_verts(&b, (size_t)nv);
    for (int64_t i = 0; i < nv && !st; i++) {
        if (!next_line(&c, &s, &e)) {
            st = hv__error(HV_ERR_PARSE, "%s: file ends after %lld of %lld vertices", path,
                           (long long)i, (long long)nv);
            break;
        }
        double x[3];
        for (int a = 0; a < 3 && !st; a++) {
            const char *q = skip_hspace(s, e), *t = q;
            if (q >= e || hv__mesh_parse_double(q, &t, &x[a]) || (t < e && !mesh_is_delim(*t)))
                st = hv__error(HV_ERR_PARSE, "%s: line %zu: vertex %lld: malformed coordinate '%s'",
                               path, c.line, (long long)i,
                               q < e ? hv__mesh_token_preview(q, e) : "");
            s = t;
        }
        b.line = c.line;
        if (!st)
            st = hv__mb_add_vertex(&b, x[0], x[1], x[2]);
    }
    for (int64_t i = 0; i < nf && !st; i++) {
        if (!next_line(&c, &s, &e)) {
            st = hv__error(HV_ERR_PARSE, "%s: file ends after %lld of %lld faces", path,
                           (long long)i, (long long)nf);
            break;
        }
        int64_t k;
        if (line_int(&s, e, &k)) {
            st = hv__error(HV_ERR_PARSE, "%s: line %zu: face %lld: malformed corner count '%s'",
                           path, c.line, (long long)i, hv__mesh_token_preview(s, e));
            break;
        }
        if (k < 3 || (uint64_t)k > (size_t)(e - s)) {
            st = hv__error(HV_ERR_PARSE, "%s: line %zu: face %lld has %lld corners%s", path, c.line,
                           (long long)i, (long long)k,
                           k < 3 ? " (a face needs at least 3)" : ", more than the line holds");
            break;
        }
        poly.n = 0;
        for (int64_t j = 0; j < k && !st; j++) {
            int64_t v;
            if (line_int(&s, e, &v))
                st = hv__error(HV_ERR_PARSE,
                               "%s: line %zu: face %lld: corner %lld missing or "
                               "malformed",
                               path, c.line, (long long)i, (long long)j);
            else if (v < 0 || v >= nv)
                st = hv__error(HV_ERR_PARSE,
                               "%s: line %zu: face %lld: vertex index %lld out of range (%lld "
                               "vertices)",
                               path, c.line, (long long)i, (long long)v, (long long)nv);
            else
                st = hv__u32vec_push(&poly, (uint32_t)v);
        }
        if (!st)
            st = hv__mb_add_polygon(&b, poly.a, poly.n);
    }
    hv__u32vec_free(&poly);
    if (st) {
        hv__mb_free(&b);
        return st;
    }
    return hv__mb_finish(&b, "OFF", out);
}
