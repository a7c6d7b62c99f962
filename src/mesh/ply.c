/* PLY (Turk 1994): ascii, binary_little_endian and binary_big_endian. The
 * `vertex` element gives x, y, z; `face` gives polygons through the list
 * `vertex_indices` (or `vertex_index`); `tristrips` gives strips with -1
 * restarts; every other element and property is skipped, which in binary means
 * walking each record with sizes from the header. */
#include "mesh_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef enum { T_NONE, T_I8, T_U8, T_I16, T_U16, T_I32, T_U32, T_F32, T_F64 } ply_type;

static const struct {
    const char *name;
    ply_type type;
} type_names[] = {
    {"char", T_I8},   {"int8", T_I8},     {"uchar", T_U8},   {"uint8", T_U8},
    {"short", T_I16}, {"int16", T_I16},   {"ushort", T_U16}, {"uint16", T_U16},
    {"int", T_I32},   {"int32", T_I32},   {"uint", T_U32},   {"uint32", T_U32},
    {"float", T_F32}, {"float32", T_F32}, {"double", T_F64}, {"float64", T_F64},
};

static const size_t type_size[] = {0, 1, 1, 2, 2, 4, 4, 4, 8};

typedef struct ply_prop {
    const char *name; /* points into the header; namelen bytes */
    size_t namelen;
    ply_type type;       /* scalar type, or list item type */
    ply_type count_type; /* T_NONE for scalars */
} ply_prop;

typedef struct ply_elem {
    const char *name;
    size_t namelen;
    uint64_t count;
    size_t line; /* header line declaring it */
    ply_prop *props;
    size_t nprops, cap;
} ply_elem;

enum { PLY_ASCII, PLY_LE, PLY_BE };

typedef struct ply_reader {
    const char *path;
    const char *p, *end; /* data cursor */
    const char *base;    /* start of the file, for byte offsets */
    size_t line;         /* ascii: current line */
    int format;
} ply_reader;

static int name_is(const char *s, size_t n, const char *w)
{
    return strlen(w) == n && memcmp(s, w, n) == 0;
}

static ply_type parse_type(const char *s, size_t n)
{
    for (size_t i = 0; i < sizeof type_names / sizeof type_names[0]; i++)
        if (name_is(s, n, type_names[i].name))
            return type_names[i].type;
    return T_NONE;
}

/* Splits a header line into words (at most max); returns their number. */
static size_t split_words(const char *s, const char *e, const char **w, size_t *wl, size_t max)
{
    size_t n = 0;
    while (s < e) {
        while (s < e && mesh_is_space(*s))
            s++;
        if (s >= e)
            break;
        const char *t = s;
        while (s < e && !mesh_is_space(*s))
            s++;
        if (n < max) {
            w[n] = t;
            wl[n] = (size_t)(s - t);
        }
        n++;
    }
    return n;
}

/* ---- values ---- */

static int is_int_type(ply_type t) { return t != T_F32 && t != T_F64; }

/* Binary: reads one value of type t at r->p; -1 when the data ends. */
static int bin_value(ply_reader *r, ply_type t, double *d, int64_t *i)
{
    size_t n = type_size[t];
    if ((size_t)(r->end - r->p) < n)
        return -1;
    unsigned char b[8];
    memcpy(b, r->p, n);
    r->p += n;
    if (n > 1 && r->format == PLY_BE)
        for (size_t k = 0; k < n / 2; k++) {
            unsigned char x = b[k];
            b[k] = b[n - 1 - k];
            b[n - 1 - k] = x;
        }
    uint64_t u = 0;
    for (size_t k = 0; k < n; k++)
        u |= (uint64_t)b[k] << (8 * k);
    int64_t v;
    switch (t) {
    case T_I8: v = (int8_t)u; break;
    case T_U8: v = (uint8_t)u; break;
    case T_I16: v = (int16_t)u; break;
    case T_U16: v = (uint16_t)u; break;
    case T_I32: v = (int32_t)(uint32_t)u; break;
    case T_U32: v = (uint32_t)u; break;
    case T_F32: {
        uint32_t w = (uint32_t)u;
        float f;
        memcpy(&f, &w, 4);
        *d = f;
        *i = 0;
        return 0;
    }
    case T_F64: {
        double f;
        memcpy(&f, &u, 8);
        *d = f;
        *i = 0;
        return 0;
    }
    default: return -1;
    }
    *i = v;
    *d = (double)v;
    return 0;
}

/* Ascii: the next token, across lines; NULL at the end of the data. */
static const char *ascii_token(ply_reader *r)
{
    while (r->p < r->end && (mesh_is_space(*r->p) || *r->p == '\0')) {
        if (*r->p == '\n')
            r->line++;
        r->p++;
    }
    return r->p < r->end ? r->p : NULL;
}

static hv_status ascii_value(ply_reader *r, ply_type t, double *d, int64_t *i, const char *what)
{
    const char *s = ascii_token(r);
    if (!s)
        return hv__error(HV_ERR_PARSE, "%s: line %zu: data ends inside %s", r->path, r->line, what);
    const char *e;
    int ok;
    if (is_int_type(t)) {
        ok = hv__mesh_parse_i64(s, &e, i) == 0 && mesh_is_delim(*e);
        if (!ok) { /* some writers put integral values as "3.0" */
            double x;
            ok = hv__mesh_parse_double(s, &e, &x) == 0 && mesh_is_delim(*e);
            /* converting a double outside int64's range is undefined behaviour */
            if (ok && !(x >= -0x1p63 && x < 0x1p63))
                return hv__error(HV_ERR_PARSE,
                                 "%s: line %zu: %s '%s' is out of range for an "
                                 "integer property",
                                 r->path, r->line, what, hv__mesh_token_preview(s, r->end));
            ok = ok && x == (double)(int64_t)x;
            if (ok)
                *i = (int64_t)x;
        }
        if (ok)
            *d = (double)*i;
    } else {
        ok = hv__mesh_parse_double(s, &e, d) == 0 && mesh_is_delim(*e);
        *i = 0;
    }
    if (!ok)
        return hv__error(HV_ERR_PARSE, "%s: line %zu: malformed %s '%s'", r->path, r->line, what,
                         hv__mesh_token_preview(s, r->end));
    r->p = e;
    return HV_OK;
}

static hv_status read_value(ply_reader *r, ply_type t, double *d, int64_t *i, const char *what)
{
    if (r->format == PLY_ASCII)
        return ascii_value(r, t, d, i, what);
    size_t at = (size_t)(r->p - r->base);
    if (bin_value(r, t, d, i))
        return hv__error(HV_ERR_PARSE, "%s: byte %zu: data ends inside %s (file truncated?)",
                         r->path, at, what);
    return HV_OK;
}

/* Where we are, for messages: "line N" or "byte N". */
static const char *where(const ply_reader *r)
{
    static _Thread_local char buf[48];
    if (r->format == PLY_ASCII)
        snprintf(buf, sizeof buf, "line %zu", r->line);
    else
        snprintf(buf, sizeof buf, "byte %zu", (size_t)(r->p - r->base));
    return buf;
}

/* Reads a list count and checks that that many items can still follow. */
static hv_status read_count(ply_reader *r, const ply_prop *pr, uint64_t *count)
{
    double d;
    int64_t n;
    hv_status st = read_value(r, pr->count_type, &d, &n, "list count");
    if (st)
        return st;
    if (n < 0)
        return hv__error(HV_ERR_PARSE, "%s: %s: negative list length %lld", r->path, where(r),
                         (long long)n);
    size_t left = (size_t)(r->end - r->p);
    size_t min_item = r->format == PLY_ASCII ? 1 : type_size[pr->type];
    if ((uint64_t)n > left / min_item + 1)
        return hv__error(HV_ERR_PARSE, "%s: %s: list of %lld items but only %zu bytes remain",
                         r->path, where(r), (long long)n, left);
    *count = (uint64_t)n;
    return HV_OK;
}

static hv_status skip_prop(ply_reader *r, const ply_prop *pr)
{
    double d;
    int64_t i;
    if (pr->count_type == T_NONE)
        return read_value(r, pr->type, &d, &i, "a property value");
    uint64_t n;
    hv_status st = read_count(r, pr, &n);
    if (st)
        return st;
    if (r->format != PLY_ASCII) {
        size_t bytes = (size_t)n * type_size[pr->type];
        if (bytes > (size_t)(r->end - r->p))
            return hv__error(HV_ERR_PARSE, "%s: %s: data ends inside a list (file truncated?)",
                             r->path, where(r));
        r->p += bytes;
        return HV_OK;
    }
    for (uint64_t k = 0; k < n && !st; k++)
        st = read_value(r, pr->type, &d, &i, "a list item");
    return st;
}

/* Smallest number of data bytes a record of e can take. */
static size_t min_record_bytes(const ply_elem *e, int format)
{
    size_t s = 0;
    for (size_t k = 0; k < e->nprops; k++) {
        const ply_prop *pr = &e->props[k];
        if (format == PLY_ASCII)
            s += 2; /* a digit and a separator */
        else
            s += type_size[pr->count_type != T_NONE ? pr->count_type : pr->type];
    }
    return s;
}

/* ---- elements ---- */

typedef struct ply_state {
    mesh_builder b;
    u32vec poly;
    uint64_t max_index; /* largest face index seen, checked once vertices are known */
    char max_where[64];
    int has_faces;
    size_t strips_dropped;
} ply_state;

static hv_status note_index(ply_reader *r, ply_state *s, int64_t v)
{
    if (v < 0 || (uint64_t)v >= MESH_MAX_COUNT)
        return hv__error(HV_ERR_PARSE, "%s: %s: vertex index %lld out of range", r->path, where(r),
                         (long long)v);
    if ((uint64_t)v + 1 > s->max_index) {
        s->max_index = (uint64_t)v + 1;
        snprintf(s->max_where, sizeof s->max_where, "%s", where(r));
    }
    return hv__u32vec_push(&s->poly, (uint32_t)v);
}

static hv_status read_vertices(ply_reader *r, ply_state *s, const ply_elem *e)
{
    int ix[3] = {-1, -1, -1};
    for (size_t k = 0; k < e->nprops; k++)
        for (int a = 0; a < 3; a++)
            if (name_is(e->props[k].name, e->props[k].namelen,
                        (const char[]){(char)('x' + a), 0})) {
                if (e->props[k].count_type != T_NONE)
                    return hv__error(HV_ERR_PARSE, "%s: line %zu: vertex property %c is a list",
                                     r->path, e->line, 'x' + a);
                ix[a] = (int)k;
            }
    for (int a = 0; a < 3; a++)
        if (ix[a] < 0)
            return hv__error(HV_ERR_PARSE, "%s: line %zu: vertex element has no property %c",
                             r->path, e->line, 'x' + a);
    hv_status st = hv__mb_reserve_verts(&s->b, (size_t)e->count);
    for (uint64_t n = 0; n < e->count && !st; n++) {
        double x[3] = {0, 0, 0};
        for (size_t k = 0; k < e->nprops && !st; k++) {
            const ply_prop *pr = &e->props[k];
            if ((int)k == ix[0] || (int)k == ix[1] || (int)k == ix[2]) {
                int64_t i;
                double d;
                st = read_value(r, pr->type, &d, &i, "a vertex coordinate");
                x[(int)k == ix[0] ? 0 : (int)k == ix[1] ? 1 : 2] = d;
            } else {
                st = skip_prop(r, pr);
            }
        }
        s->b.line = r->format == PLY_ASCII ? r->line : 0;
        if (!st)
            st = hv__mb_add_vertex(&s->b, x[0], x[1], x[2]);
    }
    return st;
}

static const ply_prop *find_index_list(const ply_reader *r, const ply_elem *e, hv_status *st)
{
    *st = HV_OK;
    for (size_t k = 0; k < e->nprops; k++) {
        const ply_prop *pr = &e->props[k];
        if (name_is(pr->name, pr->namelen, "vertex_indices") ||
            name_is(pr->name, pr->namelen, "vertex_index")) {
            if (pr->count_type == T_NONE || !is_int_type(pr->type)) {
                *st = hv__error(HV_ERR_PARSE, "%s: line %zu: %.*s must be a list of integers",
                                r->path, e->line, (int)pr->namelen, pr->name);
                return NULL;
            }
            return pr;
        }
    }
    *st = hv__error(HV_ERR_PARSE, "%s: line %zu: element %.*s has no vertex_indices list", r->path,
                    e->line, (int)e->namelen, e->name);
    return NULL;
}

/* Reads the index list of one record into s->poly. */
static hv_status read_index_list(ply_reader *r, ply_state *s, const ply_prop *pr, int strips)
{
    uint64_t n;
    hv_status st = read_count(r, pr, &n);
    s->poly.n = 0;
    for (uint64_t k = 0; k < n && !st; k++) {
        double d;
        int64_t v;
        st = read_value(r, pr->type, &d, &v, "a vertex index");
        if (st)
            break;
        if (strips && v < 0) {
            st = hv__u32vec_push(&s->poly, UINT32_MAX); /* strip restart */
            continue;
        }
        st = note_index(r, s, v);
    }
    return st;
}

static hv_status read_faces(ply_reader *r, ply_state *s, const ply_elem *e)
{
    hv_status st;
    const ply_prop *list = find_index_list(r, e, &st);
    if (!list)
        return st;
    s->has_faces = 1;
    for (uint64_t n = 0; n < e->count && !st; n++)
        for (size_t k = 0; k < e->nprops && !st; k++) {
            const ply_prop *pr = &e->props[k];
            if (pr != list) {
                st = skip_prop(r, pr);
                continue;
            }
            if (r->format == PLY_ASCII)
                ascii_token(r); /* so that the line below is the record's */
            char at[48];
            snprintf(at, sizeof at, "%s", where(r));
            st = read_index_list(r, s, pr, 0);
            if (!st && s->poly.n < 3)
                st = hv__error(HV_ERR_PARSE,
                               "%s: %s: face %llu has %zu corners (a face needs at least 3)",
                               r->path, at, (unsigned long long)n, s->poly.n);
            if (!st)
                st = hv__mb_add_polygon(&s->b, s->poly.a, s->poly.n);
        }
    return st;
}

/* Triangle strips: in each run between -1 restarts, triangle i is (s[i], s[i+1],
 * s[i+2]) for even i and (s[i+1], s[i], s[i+2]) for odd i, so that all keep the
 * winding of the first. Triangles repeating a vertex are the zero-area joins
 * writers use to stitch strips together, not faces: they are dropped. */
static hv_status read_strips(ply_reader *r, ply_state *s, const ply_elem *e)
{
    hv_status st;
    const ply_prop *list = find_index_list(r, e, &st);
    if (!list)
        return st;
    s->has_faces = 1;
    for (uint64_t n = 0; n < e->count && !st; n++)
        for (size_t k = 0; k < e->nprops && !st; k++) {
            const ply_prop *pr = &e->props[k];
            if (pr != list) {
                st = skip_prop(r, pr);
                continue;
            }
            st = read_index_list(r, s, pr, 1);
            size_t start = 0;
            for (size_t i = 0; i <= s->poly.n && !st; i++) {
                if (i < s->poly.n && s->poly.a[i] != UINT32_MAX)
                    continue;
                for (size_t j = start; j + 2 < i && !st; j++) {
                    uint32_t a = s->poly.a[j], b = s->poly.a[j + 1], c = s->poly.a[j + 2];
                    if (a == b || b == c || a == c) {
                        s->strips_dropped++;
                        continue;
                    }
                    st = (j - start) % 2 ? hv__mb_add_tri(&s->b, b, a, c)
                                         : hv__mb_add_tri(&s->b, a, b, c);
                }
                start = i + 1;
            }
        }
    return st;
}

static hv_status skip_element(ply_reader *r, const ply_elem *e)
{
    hv_status st = HV_OK;
    /* Records without properties hold nothing, however many are declared. */
    for (uint64_t n = 0; n < e->count && e->nprops && !st; n++)
        for (size_t k = 0; k < e->nprops && !st; k++)
            st = skip_prop(r, &e->props[k]);
    return st;
}

/* ---- header ---- */

static void free_elems(ply_elem *el, size_t n)
{
    for (size_t i = 0; i < n; i++)
        free(el[i].props);
    free(el);
}

/* The header as read so far: the format, the elements with their
 * properties, the number of the last line read. */
typedef struct ply_header {
    int format; /* -1 until a format line */
    ply_elem *el;
    size_t nel, elcap;
    size_t line;
    const char *data; /* the first byte after end_header */
} ply_header;

static hv_status header_format(const char *path, size_t line, const char **w, const size_t *wl,
                               size_t nw, const char *eol, int *format)
{
    if (nw >= 2 && name_is(w[1], wl[1], "ascii"))
        *format = PLY_ASCII;
    else if (nw >= 2 && name_is(w[1], wl[1], "binary_little_endian"))
        *format = PLY_LE;
    else if (nw >= 2 && name_is(w[1], wl[1], "binary_big_endian"))
        *format = PLY_BE;
    else
        return hv__error(HV_ERR_PARSE, "%s: line %zu: unknown PLY format '%s'", path, line,
                         nw >= 2 ? hv__mesh_token_preview(w[1], eol) : "");
    return HV_OK;
}

/* "element NAME COUNT" */
static hv_status header_element(const char *path, ply_header *H, const char **w, const size_t *wl,
                                size_t nw)
{
    int64_t count;
    const char *e;
    if (nw != 3 || hv__mesh_parse_i64(w[2], &e, &count) || e != w[2] + wl[2] || count < 0)
        return hv__error(HV_ERR_PARSE, "%s: line %zu: expected 'element NAME COUNT'", path,
                         H->line);
    if (H->nel == H->elcap) {
        size_t c = H->elcap ? 2 * H->elcap : 8;
        ply_elem *q = realloc(H->el, c * sizeof *q);
        if (!q)
            return hv__error(HV_ERR_NOMEM, "%s: out of memory", path);
        H->el = q;
        H->elcap = c;
    }
    H->el[H->nel++] = (ply_elem){w[1], wl[1], (uint64_t)count, H->line, NULL, 0, 0};
    return HV_OK;
}

/* "property TYPE NAME" or "property list COUNT_TYPE TYPE NAME", of the last
 * element. */
static hv_status header_property(const char *path, ply_header *H, const char **w, const size_t *wl,
                                 size_t nw)
{
    const size_t line = H->line;
    if (!H->nel)
        return hv__error(HV_ERR_PARSE, "%s: line %zu: property before any element", path, line);
    ply_prop pr = {0};
    if (nw == 5 && name_is(w[1], wl[1], "list")) {
        pr.count_type = parse_type(w[2], wl[2]);
        pr.type = parse_type(w[3], wl[3]);
        pr.name = w[4];
        pr.namelen = wl[4];
        if (pr.count_type == T_NONE || pr.type == T_NONE || !is_int_type(pr.count_type))
            return hv__error(HV_ERR_PARSE, "%s: line %zu: bad list types '%.*s %.*s'", path, line,
                             (int)wl[2], w[2], (int)wl[3], w[3]);
    } else if (nw == 3) {
        pr.type = parse_type(w[1], wl[1]);
        pr.name = w[2];
        pr.namelen = wl[2];
        if (pr.type == T_NONE)
            return hv__error(HV_ERR_PARSE, "%s: line %zu: unknown property type '%.*s'", path, line,
                             (int)wl[1], w[1]);
    } else {
        return hv__error(HV_ERR_PARSE, "%s: line %zu: malformed property line", path, line);
    }
    ply_elem *e = &H->el[H->nel - 1];
    if (e->nprops == e->cap) {
        size_t c = e->cap ? 2 * e->cap : 8;
        ply_prop *q = realloc(e->props, c * sizeof *q);
        if (!q)
            return hv__error(HV_ERR_NOMEM, "%s: out of memory", path);
        e->props = q;
        e->cap = c;
    }
    e->props[e->nprops++] = pr;
    return HV_OK;
}

/* The header lines up to end_header. H->el is the caller's to free, also on
 * failure. */
static hv_status read_header(const char *path, const char *buf, const char *end, ply_header *H)
{
    hv_status st = HV_OK;
    for (const char *p = buf; p < end && !st;) {
        H->line++;
        const char *eol = memchr(p, '\n', (size_t)(end - p));
        if (!eol)
            return hv__error(HV_ERR_PARSE, "%s: line %zu: header has no end_header line", path,
                             H->line);
        const char *w[6];
        size_t wl[6];
        size_t nw = split_words(p, eol, w, wl, 6);
        const char *next = eol + 1;
        if (H->line == 1 || nw == 0) {
            /* "ply" */
        } else if (name_is(w[0], wl[0], "end_header")) {
            H->data = next;
            break;
        } else if (name_is(w[0], wl[0], "comment") || name_is(w[0], wl[0], "obj_info")) {
        } else if (name_is(w[0], wl[0], "format")) {
            st = header_format(path, H->line, w, wl, nw, eol, &H->format);
        } else if (name_is(w[0], wl[0], "element")) {
            st = header_element(path, H, w, wl, nw);
        } else if (name_is(w[0], wl[0], "property")) {
            st = header_property(path, H, w, wl, nw);
        } else {
            /* some exporters write free text without "comment" (Blender 2.4x) */
            hv__log(HV_LOG_DEBUG, "%s: line %zu: skipping unknown header line", path, H->line);
        }
        p = next;
    }
    if (!st && !H->data)
        st = hv__error(HV_ERR_PARSE, "%s: header has no end_header line", path);
    if (!st && H->format < 0)
        st = hv__error(HV_ERR_PARSE, "%s: header has no format line", path);
    return st;
}

/* The data, element by element: the first vertex element, faces and strips
 * read, everything else skipped. */
static hv_status read_elements(ply_reader *r, ply_state *s, const ply_header *H)
{
    hv_status st = HV_OK;
    int seen_vertex = 0;
    for (size_t k = 0; k < H->nel && !st; k++) {
        const ply_elem *e = &H->el[k];
        /* Every record takes at least min bytes: a count the file cannot hold is
         * refused before anything is allocated for it. */
        size_t min = min_record_bytes(e, H->format);
        size_t left = (size_t)(r->end - r->p);
        if (e->count && min && e->count > (left + 2) / min)
            st = hv__error(HV_ERR_PARSE,
                           "%s: line %zu: element %.*s declares %llu records but only %zu bytes of "
                           "data remain (at least %zu bytes each)",
                           r->path, e->line, (int)e->namelen, e->name, (unsigned long long)e->count,
                           left, min);
        else if (e->nprops == 0)
            continue;
        else if (name_is(e->name, e->namelen, "vertex") && !seen_vertex) {
            seen_vertex = 1;
            st = read_vertices(r, s, e);
        } else if (name_is(e->name, e->namelen, "face"))
            st = read_faces(r, s, e);
        else if (name_is(e->name, e->namelen, "tristrips"))
            st = read_strips(r, s, e);
        else
            st = skip_element(r, e);
    }
    return st;
}

hv_status hv__mesh_read_ply(const char *path, const char *buf, size_t len, hv_mesh **out)
{
    *out = NULL;
    const char *end = buf + len;
    if (len < 4 || strncmp(buf, "ply", 3) || (buf[3] != '\n' && buf[3] != '\r'))
        return hv__error(HV_ERR_PARSE, "%s: not a PLY file (does not start with \"ply\")", path);
    ply_header H = {-1, NULL, 0, 0, 0, NULL};
    hv_status st = read_header(path, buf, end, &H);
    if (st) {
        free_elems(H.el, H.nel);
        return st;
    }

    ply_reader r = {path, H.data, end, buf, H.line + 1, H.format};
    ply_state s;
    memset(&s, 0, sizeof s);
    hv__mb_init(&s.b, path);
    st = read_elements(&r, &s, &H);
    free_elems(H.el, H.nel);
    if (!st && s.max_index > s.b.nv)
        st = hv__error(HV_ERR_PARSE, "%s: %s: vertex index %llu out of range (%zu vertices)", path,
                       s.max_where, (unsigned long long)(s.max_index - 1), s.b.nv);
    if (!st && !s.has_faces)
        st = hv__error(HV_ERR_PARSE,
                       "%s: no triangles (no face or tristrips element: a point cloud?)", path);
    hv__u32vec_free(&s.poly);
    if (st) {
        hv__mb_free(&s.b);
        return st;
    }
    if (s.strips_dropped)
        hv__log(HV_LOG_DEBUG, "%s: dropped %zu zero-area stitching triangles from strips", path,
                s.strips_dropped);
    static const char *const names[] = {"PLY ascii", "PLY binary_little_endian",
                                        "PLY binary_big_endian"};
    return hv__mb_finish(&s.b, names[H.format], out);
}

/* ---- point clouds ---- */

/* Whether the header declares vertices and no faces or strips (a point
 * cloud); 0 for anything else, including headers that do not parse. */
int hv__ply_is_points(const char *buf, size_t len)
{
    if (len < 4 || strncmp(buf, "ply", 3) || (buf[3] != '\n' && buf[3] != '\r'))
        return 0;
    ply_header H = {-1, NULL, 0, 0, 0, NULL};
    hv_status st = read_header("", buf, buf + len, &H);
    int vertices = 0, faces = 0;
    for (size_t k = 0; !st && k < H.nel; k++) {
        const ply_elem *e = &H.el[k];
        if (name_is(e->name, e->namelen, "vertex"))
            vertices += e->count > 0;
        else if (name_is(e->name, e->namelen, "face") || name_is(e->name, e->namelen, "tristrips"))
            faces += e->count > 0;
    }
    free_elems(H.el, H.nel);
    if (st)
        hv_clear_error();
    return !st && vertices && !faces;
}

/* The places of x y z nx ny nz among e's properties; without all three of
 * nx ny nz the cloud is unoriented (ix[3..5] -1). */
static hv_status point_props(const ply_reader *r, const ply_elem *e, int ix[6])
{
    static const char *const names[6] = {"x", "y", "z", "nx", "ny", "nz"};
    for (int a = 0; a < 6; a++) {
        ix[a] = -1;
        for (size_t k = 0; k < e->nprops; k++)
            if (name_is(e->props[k].name, e->props[k].namelen, names[a])) {
                if (e->props[k].count_type != T_NONE)
                    return hv__error(HV_ERR_PARSE, "%s: line %zu: vertex property %s is a list",
                                     r->path, e->line, names[a]);
                ix[a] = (int)k;
            }
    }
    for (int a = 0; a < 3; a++)
        if (ix[a] < 0)
            return hv__error(HV_ERR_PARSE, "%s: line %zu: vertex element has no property %s",
                             r->path, e->line, names[a]);
    if (ix[3] < 0 || ix[4] < 0 || ix[5] < 0)
        ix[3] = ix[4] = ix[5] = -1;
    return HV_OK;
}

static hv_status read_point_records(ply_reader *r, const ply_elem *e, points_builder *b)
{
    int ix[6];
    hv_status st = point_props(r, e, ix);
    const int values = ix[3] < 0 ? 3 : 6;
    if (!st)
        st = hv__points_reserve(b, (size_t)e->count);
    for (uint64_t n = 0; n < e->count && !st; n++) {
        double p[6] = {0, 0, 0, 0, 0, 0};
        char at[64];
        if (r->format == PLY_ASCII)
            snprintf(at, sizeof at, "line %zu", r->line);
        else
            snprintf(at, sizeof at, "point %llu", (unsigned long long)n + 1);
        for (size_t k = 0; k < e->nprops && !st; k++) {
            int a = 0;
            while (a < values && ix[a] != (int)k)
                a++;
            int64_t i;
            st = a < values ? read_value(r, e->props[k].type, &p[a], &i, "a point coordinate")
                            : skip_prop(r, &e->props[k]);
        }
        if (!st)
            st = hv__points_add(b, p, values, at);
    }
    return st;
}

hv_status hv__points_read_ply(const char *path, const char *buf, size_t len, points_builder *b)
{
    const char *end = buf + len;
    if (len < 4 || strncmp(buf, "ply", 3) || (buf[3] != '\n' && buf[3] != '\r'))
        return hv__error(HV_ERR_PARSE, "%s: not a PLY file (does not start with \"ply\")", path);
    ply_header H = {-1, NULL, 0, 0, 0, NULL};
    hv_status st = read_header(path, buf, end, &H);
    ply_reader r = {path, H.data, end, buf, H.line + 1, H.format};
    int done = 0;
    for (size_t k = 0; k < H.nel && !st && !done; k++) {
        const ply_elem *e = &H.el[k];
        size_t min = min_record_bytes(e, H.format), left = (size_t)(r.end - r.p);
        if (e->count && min && e->count > (left + 2) / min)
            st = hv__error(HV_ERR_PARSE,
                           "%s: line %zu: element %.*s declares %llu records but only %zu bytes of "
                           "data remain (the file is truncated, or its header is wrong)",
                           path, e->line, (int)e->namelen, e->name, (unsigned long long)e->count,
                           left);
        else if (name_is(e->name, e->namelen, "vertex")) {
            st = read_point_records(&r, e, b);
            done = 1;
        } else
            st = skip_element(&r, e);
    }
    free_elems(H.el, H.nel);
    if (!st && !done)
        st = hv__error(HV_ERR_PARSE, "%s: no vertex element", path);
    return st;
}
