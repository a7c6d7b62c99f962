/* 2D curves read from the text format and SVG paths (heatvox/curves.h); the
 * curve type itself lives in src/mesh/curves2d.c. */
#include "heatvox/curves.h"
#include "core/error.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

/* Largest coordinate magnitude accepted: squares and cross products of
 * coordinate differences (distances, winding numbers) must stay finite in
 * double, and so must the extent of the bounds. */
#define CURVE_MAX_COORD 1e100

/* Pipes (FIFOs, such as a shell's <(...)) are read up to this many bytes. */
#define CURVE_MAX_PIPE_BYTES ((size_t)1 << 30)

static int coord_ok(double v) { return fabs(v) <= CURVE_MAX_COORD; }

/* ---- building ---- */

typedef struct builder {
    double *pts;
    size_t np, capp;
    size_t *start;
    uint8_t *closed;
    size_t nl, capl;
    int open; /* a polyline is being built */
    int nomem;
} builder;

static void b_begin(builder *b)
{
    if (b->nomem)
        return;
    if (b->nl + 2 > b->capl) {
        size_t cap = b->capl ? 2 * b->capl : 16;
        size_t *s = realloc(b->start, cap * sizeof *s);
        uint8_t *c = s ? realloc(b->closed, cap) : NULL;
        if (s)
            b->start = s;
        if (!s || !c) {
            b->nomem = 1;
            return;
        }
        b->closed = c;
        b->capl = cap;
    }
    b->start[b->nl] = b->np;
    b->closed[b->nl] = 0;
    b->open = 1;
}

static void b_point(builder *b, double x, double y)
{
    if (b->nomem)
        return;
    if (!b->open)
        b_begin(b);
    if (b->np == b->capp) {
        size_t cap = b->capp ? 2 * b->capp : 64;
        double *p = realloc(b->pts, 2 * cap * sizeof *p);
        if (!p) {
            b->nomem = 1;
            return;
        }
        b->pts = p;
        b->capp = cap;
    }
    b->pts[2 * b->np] = x;
    b->pts[2 * b->np + 1] = y;
    b->np++;
}

/* Ends the current polyline; one with fewer than two points is dropped. */
static void b_end(builder *b, int closed)
{
    if (!b->open || b->nomem)
        return;
    b->open = 0;
    size_t count = b->np - b->start[b->nl];
    if (count < 2) {
        b->np = b->start[b->nl];
        return;
    }
    b->closed[b->nl] = (uint8_t)(closed != 0);
    b->nl++;
}

static void b_free(builder *b)
{
    free(b->pts);
    free(b->start);
    free(b->closed);
}

static hv_status b_finish(builder *b, const char *name, hv_curves **out)
{
    b_end(b, 0);
    if (b->nomem) {
        b_free(b);
        return hv__error(HV_ERR_NOMEM, "%s: out of memory reading curves", name);
    }
    if (b->nl == 0) {
        b_free(b);
        return hv__error(HV_ERR_PARSE, "%s: no curve with a segment", name);
    }
    hv_curves *c = calloc(1, sizeof *c);
    if (!c) {
        b_free(b);
        return hv__error(HV_ERR_NOMEM, "%s: out of memory reading curves", name);
    }
    b->start[b->nl] = b->np;
    c->npoints = b->np;
    c->pts = b->pts;
    c->nlines = b->nl;
    c->start = b->start;
    c->closed = b->closed;
    *out = c;
    return HV_OK;
}

/* ---- numbers ---- */

/* Scans one number in SVG syntax ("1.5.5" is 1.5 then .5, "10-5" is 10 then
 * -5); returns the end or NULL when there is none at p. */
static const char *scan_number(const char *p, const char *end, double *v)
{
    const char *s = p;
    if (s < end && (*s == '+' || *s == '-'))
        s++;
    int digits = 0;
    while (s < end && *s >= '0' && *s <= '9')
        s++, digits++;
    if (s < end && *s == '.') {
        s++;
        while (s < end && *s >= '0' && *s <= '9')
            s++, digits++;
    }
    if (!digits)
        return NULL;
    if (s < end && (*s == 'e' || *s == 'E')) {
        const char *e = s + 1;
        if (e < end && (*e == '+' || *e == '-'))
            e++;
        if (e < end && *e >= '0' && *e <= '9') {
            while (e < end && *e >= '0' && *e <= '9')
                e++;
            s = e;
        }
    }
    char buf[64];
    size_t n = (size_t)(s - p);
    if (n >= sizeof buf)
        return NULL;
    memcpy(buf, p, n);
    buf[n] = '\0';
    *v = strtod(buf, NULL);
    return isfinite(*v) ? s : NULL;
}

static const char *skip_sep(const char *p, const char *end)
{
    while (p < end && (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r' || *p == ','))
        p++;
    return p;
}

/* ---- text format ---- */

static hv_status text_coord_error(const char *name, int line, double v)
{
    return hv__error(HV_ERR_NUMERIC,
                     "%s: line %d: coordinate %g is beyond the bound +-%g heatvox "
                     "accepts",
                     name, line, v, CURVE_MAX_COORD);
}

static hv_status parse_text(const char *text, size_t len, const char *name, hv_curves **out)
{
    builder b = {0};
    const char *p = text, *end = text + len;
    int line = 0;
    while (p < end) {
        const char *eol = memchr(p, '\n', (size_t)(end - p));
        const char *le = eol ? eol : end;
        line++;
        const char *hash = memchr(p, '#', (size_t)(le - p));
        const char *stop = hash ? hash : le;
        const char *q = skip_sep(p, stop);
        if (q < stop) {
            char cmd = *q;
            double v[2];
            if (cmd == 'M' || cmd == 'L') {
                q++;
                for (int k = 0; k < 2; k++) {
                    q = skip_sep(q, stop);
                    const char *r = scan_number(q, stop, &v[k]);
                    if (!r) {
                        b_free(&b);
                        return hv__error(HV_ERR_PARSE, "%s: line %d: '%c' needs two numbers", name,
                                         line, cmd);
                    }
                    if (!coord_ok(v[k])) {
                        b_free(&b);
                        return text_coord_error(name, line, v[k]);
                    }
                    q = r;
                }
                if (skip_sep(q, stop) != stop) {
                    b_free(&b);
                    return hv__error(HV_ERR_PARSE, "%s: line %d: unexpected text after '%c x y'",
                                     name, line, cmd);
                }
                if (cmd == 'M') {
                    b_end(&b, 0);
                    b_begin(&b);
                } else if (!b.open) {
                    b_free(&b);
                    return hv__error(HV_ERR_PARSE,
                                     "%s: line %d: 'L' without a current polyline "
                                     "(start one with M x y)",
                                     name, line);
                }
                b_point(&b, v[0], v[1]);
            } else if (cmd == 'Z') {
                if (!b.open) {
                    b_free(&b);
                    return hv__error(HV_ERR_PARSE, "%s: line %d: 'Z' without a current polyline",
                                     name, line);
                }
                if (skip_sep(q + 1, stop) != stop) {
                    b_free(&b);
                    return hv__error(HV_ERR_PARSE, "%s: line %d: unexpected text after 'Z'", name,
                                     line);
                }
                b_end(&b, 1);
            } else {
                /* A whole polyline of numbers. */
                b_end(&b, 0);
                b_begin(&b);
                int count = 0;
                double x = 0;
                while ((q = skip_sep(q, stop)) < stop) {
                    const char *r = scan_number(q, stop, &v[0]);
                    if (!r) {
                        b_free(&b);
                        return hv__error(HV_ERR_PARSE,
                                         "%s: line %d: expected M, L, Z or numbers, found '%.*s'",
                                         name, line, (int)(stop - q > 12 ? 12 : stop - q), q);
                    }
                    if (!coord_ok(v[0])) {
                        b_free(&b);
                        return text_coord_error(name, line, v[0]);
                    }
                    q = r;
                    if (count++ % 2)
                        b_point(&b, x, v[0]);
                    else
                        x = v[0];
                }
                if (count % 2 || count < 4) {
                    b_free(&b);
                    return hv__error(HV_ERR_PARSE,
                                     "%s: line %d: a polyline needs an even count of at least 4 "
                                     "numbers, got %d",
                                     name, line, count);
                }
                b_end(&b, 0);
            }
        }
        p = eol ? eol + 1 : end;
    }
    return b_finish(&b, name, out);
}

/* ---- SVG ---- */

typedef struct svg_state {
    builder *b;
    const char *name, *base;
    double cx, cy; /* current point */
    double sx, sy; /* subpath start */
    double qx, qy; /* last control point (for S and T) */
    char last;     /* last command, upper case */
    int after_close;
} svg_state;

/* Points are stored with y negated (SVG's y points down). */
static void svg_line_to(svg_state *s, double x, double y)
{
    if (s->after_close || !s->b->open) {
        b_end(s->b, 0);
        b_begin(s->b);
        b_point(s->b, s->cx, -s->cy);
        s->after_close = 0;
    }
    b_point(s->b, x, -y);
    s->cx = x;
    s->cy = y;
}

static void svg_bezier(svg_state *s, const double *c, int cubic)
{
    double x0 = s->cx, y0 = s->cy;
    for (int k = 1; k <= 16; k++) {
        double t = k / 16.0, u = 1 - t, x, y;
        if (cubic) {
            x = u * u * u * x0 + 3 * u * u * t * c[0] + 3 * u * t * t * c[2] + t * t * t * c[4];
            y = u * u * u * y0 + 3 * u * u * t * c[1] + 3 * u * t * t * c[3] + t * t * t * c[5];
        } else {
            x = u * u * x0 + 2 * u * t * c[0] + t * t * c[2];
            y = u * u * y0 + 2 * u * t * c[1] + t * t * c[3];
        }
        svg_line_to(s, x, y);
    }
}

static hv_status svg_coord_error(const svg_state *s, const char *at, double v)
{
    return hv__error(HV_ERR_NUMERIC,
                     "%s: byte %ld: coordinate %g is beyond the bound +-%g heatvox accepts",
                     s->name, (long)(at - s->base), v, CURVE_MAX_COORD);
}

static hv_status parse_path_data(svg_state *s, const char *p, const char *end)
{
    char cmd = 0;
    s->after_close = 0;
    s->cx = s->cy = s->sx = s->sy = 0;
    s->last = 0;
    for (;;) {
        p = skip_sep(p, end);
        if (p >= end)
            break;
        if ((*p >= 'A' && *p <= 'Z') || (*p >= 'a' && *p <= 'z')) {
            cmd = *p++;
            if (strchr("MmLlHhVvZzCcSsQqTt", cmd) == NULL)
                return hv__error(cmd == 'A' || cmd == 'a' ? HV_ERR_UNSUPPORTED : HV_ERR_PARSE,
                                 "%s: byte %ld: path command '%c' is not supported%s", s->name,
                                 (long)(p - 1 - s->base), cmd,
                                 cmd == 'A' || cmd == 'a' ? " (arcs: convert them to curves)" : "");
            if (cmd == 'Z' || cmd == 'z') {
                if (s->b->open) {
                    b_end(s->b, 1);
                }
                s->cx = s->sx;
                s->cy = s->sy;
                s->after_close = 1;
                s->last = 'Z';
                continue;
            }
        } else if (!cmd) {
            return hv__error(HV_ERR_PARSE, "%s: byte %ld: path data must start with a command",
                             s->name, (long)(p - s->base));
        } else if (cmd == 'Z' || cmd == 'z') {
            return hv__error(HV_ERR_PARSE, "%s: byte %ld: numbers after 'Z'", s->name,
                             (long)(p - s->base));
        }
        char up = (char)(cmd & ~0x20);
        int rel = cmd != up;
        int want = up == 'H' || up == 'V' ? 1 : up == 'C' ? 6 : up == 'S' || up == 'Q' ? 4 : 2;
        double v[6];
        const char *at = skip_sep(p, end); /* for messages */
        for (int k = 0; k < want; k++) {
            p = skip_sep(p, end);
            const char *r = scan_number(p, end, &v[k]);
            if (!r)
                return hv__error(HV_ERR_PARSE, "%s: byte %ld: expected a number for '%c'", s->name,
                                 (long)(p - s->base), cmd);
            p = r;
        }
        double ox = rel ? s->cx : 0, oy = rel ? s->cy : 0;
        switch (up) {
        case 'M':
            b_end(s->b, 0);
            s->cx = s->sx = v[0] + ox;
            s->cy = s->sy = v[1] + oy;
            b_begin(s->b);
            b_point(s->b, s->cx, -s->cy);
            s->after_close = 0;
            cmd = rel ? 'l' : 'L'; /* further pairs are line-tos */
            break;
        case 'L': svg_line_to(s, v[0] + ox, v[1] + oy); break;
        case 'H': svg_line_to(s, v[0] + ox, s->cy); break;
        case 'V': svg_line_to(s, s->cx, v[0] + (rel ? s->cy : 0)); break;
        case 'C':
        case 'S':
        case 'Q':
        case 'T': {
            double c[6];
            int cubic = up == 'C' || up == 'S';
            int k = 0;
            if (up == 'S' || up == 'T') {
                /* reflection of the previous control point, or the current point */
                int smooth = (up == 'S' && (s->last == 'C' || s->last == 'S')) ||
                             (up == 'T' && (s->last == 'Q' || s->last == 'T'));
                c[0] = smooth ? 2 * s->cx - s->qx : s->cx;
                c[1] = smooth ? 2 * s->cy - s->qy : s->cy;
                k = 2;
            }
            for (int i = 0; i < want; i += 2) {
                c[k++] = v[i] + ox;
                c[k++] = v[i + 1] + oy;
            }
            /* the flattened points are convex combinations of these */
            for (int i = 0; i < k; i++)
                if (!coord_ok(c[i]))
                    return svg_coord_error(s, at, c[i]);
            /* the control point next to the end, for a following S or T */
            s->qx = cubic ? c[2] : c[0];
            s->qy = cubic ? c[3] : c[1];
            svg_bezier(s, c, cubic);
            break;
        }
        }
        if (!coord_ok(s->cx) || !coord_ok(s->cy))
            return svg_coord_error(s, at, coord_ok(s->cx) ? s->cy : s->cx);
        s->last = up == 'M' ? 'L' : up;
    }
    b_end(s->b, 0);
    return HV_OK;
}

static hv_status parse_points(svg_state *s, const char *p, const char *end, int closed)
{
    b_end(s->b, 0);
    b_begin(s->b);
    int count = 0;
    double x = 0, v;
    while ((p = skip_sep(p, end)) < end) {
        const char *r = scan_number(p, end, &v);
        if (!r)
            return hv__error(HV_ERR_PARSE, "%s: byte %ld: expected a number in points", s->name,
                             (long)(p - s->base));
        if (!coord_ok(v))
            return svg_coord_error(s, p, v);
        p = r;
        if (count++ % 2)
            b_point(s->b, x, -v);
        else
            x = v;
    }
    if (count % 2)
        return hv__error(HV_ERR_PARSE, "%s: byte %ld: odd number of coordinates in points", s->name,
                         (long)(end - s->base));
    b_end(s->b, closed);
    return HV_OK;
}

/* Finds attribute `attr` inside the tag [p, end); returns its value span. */
static int find_attr(const char *p, const char *end, const char *attr, const char **vs,
                     const char **ve)
{
    size_t al = strlen(attr);
    while (p < end) {
        /* attribute name */
        while (p < end && (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r'))
            p++;
        const char *ns = p;
        while (p < end && *p != '=' && *p != ' ' && *p != '\t' && *p != '\n' && *p != '\r' &&
               *p != '>' && *p != '/')
            p++;
        const char *ne = p;
        while (p < end && (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r'))
            p++;
        if (p < end && *p == '=') {
            p++;
            while (p < end && (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r'))
                p++;
            if (p < end && (*p == '"' || *p == '\'')) {
                char q = *p++;
                const char *s = p;
                while (p < end && *p != q)
                    p++;
                if ((size_t)(ne - ns) == al && !strncmp(ns, attr, al)) {
                    *vs = s;
                    *ve = p;
                    return 1;
                }
                if (p < end)
                    p++;
            }
        } else if (ne == ns) {
            p++;
        }
    }
    return 0;
}

static hv_status parse_svg(const char *text, size_t len, const char *name, hv_curves **out)
{
    builder b = {0};
    svg_state s;
    memset(&s, 0, sizeof s);
    s.b = &b;
    s.name = name;
    s.base = text;
    const char *p = text, *end = text + len;
    hv_status st = HV_OK;
    while (st == HV_OK && (p = memchr(p, '<', (size_t)(end - p))) != NULL) {
        if (end - p >= 4 && !strncmp(p, "<!--", 4)) {
            const char *c = p + 4;
            while (c + 3 <= end && strncmp(c, "-->", 3))
                c++;
            p = c + 3 <= end ? c + 3 : end;
            continue;
        }
        const char *tag = p + 1;
        /* the end of the tag: the first '>' outside quotes */
        const char *q = tag;
        char quote = 0;
        while (q < end && (quote || *q != '>')) {
            if (quote && *q == quote)
                quote = 0;
            else if (!quote && (*q == '"' || *q == '\''))
                quote = *q;
            q++;
        }
        if (q >= end) {
            st = hv__error(HV_ERR_PARSE, "%s: byte %ld: unterminated tag", name, (long)(p - text));
            break;
        }
        size_t tl = 0;
        while (tag + tl < q && tag[tl] != ' ' && tag[tl] != '\t' && tag[tl] != '\n' &&
               tag[tl] != '\r' && tag[tl] != '/')
            tl++;
        const char *vs, *ve;
        if (tl == 4 && !strncmp(tag, "path", 4)) {
            if (find_attr(tag + tl, q, "d", &vs, &ve))
                st = parse_path_data(&s, vs, ve);
        } else if ((tl == 7 && !strncmp(tag, "polygon", 7)) ||
                   (tl == 8 && !strncmp(tag, "polyline", 8))) {
            if (find_attr(tag + tl, q, "points", &vs, &ve))
                st = parse_points(&s, vs, ve, tl == 7);
        }
        p = q + 1;
    }
    if (st) {
        b_free(&b);
        return st;
    }
    return b_finish(&b, name, out);
}

/* ---- public ---- */

hv_status hv_curves_parse(const char *text, size_t len, int svg, const char *name, hv_curves **out)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_curves_parse: out is NULL");
    *out = NULL;
    if (!text)
        return hv__error(HV_ERR_INVALID_ARG, "hv_curves_parse: text is NULL");
    if (!name)
        name = "curves";
    return svg ? parse_svg(text, len, name, out) : parse_text(text, len, name, out);
}

hv_status hv_curves_read(const char *path, hv_curves **out)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_curves_read: out is NULL");
    *out = NULL;
    if (!path)
        return hv__error(HV_ERR_INVALID_ARG, "hv_curves_read: path is NULL");
    /* Regular files and pipes only: a device such as /dev/zero never ends. */
    struct stat sb;
    if (stat(path, &sb) != 0)
        return hv__error(HV_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    if (!S_ISREG(sb.st_mode) && !S_ISFIFO(sb.st_mode))
        return hv__error(HV_ERR_IO, "%s: is %s; curves are read from regular files or pipes", path,
                         S_ISDIR(sb.st_mode)   ? "a directory"
                         : S_ISCHR(sb.st_mode) ? "a character device"
                         : S_ISBLK(sb.st_mode) ? "a block device"
                                               : "not a regular file");
    FILE *f = fopen(path, "rb");
    if (!f)
        return hv__error(HV_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    if (fstat(fileno(f), &sb) != 0 || (!S_ISREG(sb.st_mode) && !S_ISFIFO(sb.st_mode))) {
        fclose(f);
        return hv__error(HV_ERR_IO, "%s: not a regular file or pipe", path);
    }
    size_t cap = 1 << 16, len = 0;
    char *text = malloc(cap);
    for (;;) {
        if (!text) {
            fclose(f);
            return hv__error(HV_ERR_NOMEM, "%s: out of memory", path);
        }
        len += fread(text + len, 1, cap - len, f);
        if (len < cap)
            break;
        if (len > CURVE_MAX_PIPE_BYTES) {
            free(text);
            fclose(f);
            return hv__error(HV_ERR_IO,
                             "%s: more than %zu MiB of curves; heatvox reads at most "
                             "that",
                             path, CURVE_MAX_PIPE_BYTES >> 20);
        }
        cap *= 2;
        char *t = realloc(text, cap);
        if (!t)
            free(text);
        text = t;
    }
    int err = ferror(f);
    fclose(f);
    if (err) {
        free(text);
        return hv__error(HV_ERR_IO, "%s: read error", path);
    }
    const char *dot = strrchr(path, '.');
    const char *slash = strrchr(path, '/');
    int svg = dot && (!slash || dot > slash) && !strcasecmp(dot, ".svg");
    if (!svg) {
        /* content sniffing: an XML or SVG document */
        size_t i = 0;
        while (i < len && (text[i] == ' ' || text[i] == '\n' || text[i] == '\r' || text[i] == '\t'))
            i++;
        svg = i < len && text[i] == '<';
    }
    hv_status st = hv_curves_parse(text, len, svg, path, out);
    free(text);
    return st;
}
