/* Point clouds: text files (.xyz, .pts: x y z per line, or x y z nx ny nz,
 * # comments, more columns ignored) and PLY files without faces, whose
 * vertices carry nx ny nz or not. Normals are scaled to unit length. */
#include "mesh_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

hv_status hv__points_reserve(points_builder *b, size_t n)
{
    if (n > MESH_MAX_COUNT - b->n)
        return hv__error(HV_ERR_NOMEM, "%s: more than %zu points", b->path, MESH_MAX_COUNT);
    if (b->n + n <= b->cap)
        return HV_OK;
    size_t cap = b->cap ? b->cap : 1024;
    while (cap < b->n + n)
        cap *= 2;
    double *x = realloc(b->xyz, 3 * cap * sizeof *x);
    if (x)
        b->xyz = x;
    double *m = x && b->values != 3 ? realloc(b->nrm, 3 * cap * sizeof *m) : NULL;
    if (!x || (b->values != 3 && !m))
        return hv__error(HV_ERR_NOMEM, "%s: out of memory for %zu points", b->path, cap);
    if (m)
        b->nrm = m;
    b->cap = cap;
    return HV_OK;
}

/* The first point fixes whether the cloud has normals; a later point must
 * agree. */
static hv_status points_values(points_builder *b, int values, const char *where)
{
    if (b->values == values)
        return HV_OK;
    if (b->values)
        return hv__error(HV_ERR_PARSE,
                         values == 3 ? "%s: %s: x y z without a normal, where the points before "
                                       "have normals (x y z nx ny nz)"
                                     : "%s: %s: a normal, where the points before have none "
                                       "(x y z)",
                         b->path, where);
    b->values = values;
    if (values == 3) { /* the first point: no normals kept */
        free(b->nrm);
        b->nrm = NULL;
    }
    return HV_OK;
}

hv_status hv__points_add(points_builder *b, const double *p, int values, const char *where)
{
    hv_status st = points_values(b, values, where);
    if (st)
        return st;
    for (int a = 0; a < values; a++)
        if (!isfinite(p[a]) || fabs(p[a]) > MESH_MAX_COORD)
            return hv__error(HV_ERR_NUMERIC, "%s: %s: %s %c is %g", b->path, where,
                             a < 3 ? "coordinate" : "normal component", "xyzxyz"[a], p[a]);
    double len = values == 6 ? sqrt(p[3] * p[3] + p[4] * p[4] + p[5] * p[5]) : 1;
    if (!(len > 1e-30))
        return hv__error(HV_ERR_NUMERIC, "%s: %s: the normal (%g %g %g) has no direction", b->path,
                         where, p[3], p[4], p[5]);
    if ((st = hv__points_reserve(b, 1)))
        return st;
    for (int a = 0; a < 3; a++)
        b->xyz[3 * b->n + a] = p[a];
    for (int a = 0; a < 3 && values == 6; a++) {
        b->nrm[3 * b->n + a] = p[3 + a] / len;
        b->negative |= p[3 + a] < 0;
    }
    b->nonunit |= fabs(len - 1) > 0.01;
    b->n++;
    return HV_OK;
}

/* The numbers on one text line (up to max); -1 on a word that is not one,
 * with its column in *bad and its place in *at. */
static int line_numbers(const char *s, const char *e, double *v, int max, int *bad, const char **at)
{
    int n = 0;
    while (s < e) {
        while (s < e && mesh_is_space(*s))
            s++;
        if (s >= e || *s == '#')
            break;
        const char *t;
        double d;
        if (hv__mesh_parse_double(s, &t, &d) || (t < e && !mesh_is_space(*t) && *t != '#')) {
            *bad = n + 1;
            *at = s;
            return -1;
        }
        if (n < max)
            v[n] = d;
        n++;
        s = t;
    }
    return n;
}

static hv_status read_text(const char *path, const char *buf, size_t len, points_builder *b)
{
    size_t line = 0;
    hv_status st = HV_OK;
    for (const char *p = buf, *end = buf + len; p < end && !st;) {
        const char *eol = memchr(p, '\n', (size_t)(end - p));
        eol = eol ? eol : end;
        line++;
        double v[6];
        const char *word = p;
        int bad = 0, n = line_numbers(p, eol, v, 6, &bad, &word);
        char at[48];
        snprintf(at, sizeof at, "line %zu", line);
        if (n < 0)
            st = hv__error(HV_ERR_PARSE, "%s: line %zu: column %d is not a number (%s)", path, line,
                           bad, hv__mesh_token_preview(word, eol));
        else if ((n > 0 && n < 3) || n == 4 || n == 5)
            st = hv__error(HV_ERR_PARSE,
                           "%s: line %zu: %d numbers; a point is x y z, or x y z nx ny nz", path,
                           line, n);
        else if (n >= 3)
            st = hv__points_add(b, v, n == 3 ? 3 : 6, at);
        p = eol + 1;
    }
    return st;
}

static int has_ext(const char *path, const char *ext)
{
    const char *slash = strrchr(path, '/');
    const char *dot = strrchr(slash ? slash + 1 : path, '.');
    return dot && !strcasecmp(dot, ext);
}

static int text_points_path(const char *path)
{
    return has_ext(path, ".xyz") || has_ext(path, ".pts") || has_ext(path, ".xyzn");
}

int hv_points_file(const char *path)
{
    if (!path)
        return 0;
    if (text_points_path(path))
        return 1;
    if (!has_ext(path, ".ply"))
        return 0;
    FILE *f = fopen(path, "rb");
    if (!f)
        return 0;
    char buf[8192];
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    fclose(f);
    buf[n] = '\0';
    return hv__ply_is_points(buf, n);
}

/* Normals that are not of unit length and have no negative component
 * anywhere are no outward normals of a closed shape: most likely colours in
 * the last three columns. */
static hv_status check_normals(const points_builder *b)
{
    if (b->n == 0)
        return hv__error(HV_ERR_PARSE, "%s: no points", b->path);
    if (b->values == 6 && !b->negative && b->nonunit && b->n >= 8)
        return hv__error(HV_ERR_INVALID_ARG,
                         "%s: no normal has a negative component in %zu points: columns 4-6 look "
                         "like colours, not normals (a point is x y z nx ny nz)",
                         b->path, b->n);
    return HV_OK;
}

static hv_status points_finish(points_builder *b, const char *format, hv_points **out)
{
    hv_points *P = calloc(1, sizeof *P);
    if (!P)
        return hv__error(HV_ERR_NOMEM, "%s: out of memory", b->path);
    P->count = b->n;
    P->xyz = b->xyz;
    P->normals = b->nrm;
    P->format = format;
    b->xyz = b->nrm = NULL;
    *out = P;
    return HV_OK;
}

hv_status hv_points_read(const char *path, hv_points **out)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_points_read: out is NULL");
    *out = NULL;
    if (!path || !*path)
        return hv__error(HV_ERR_INVALID_ARG, "hv_points_read: empty path");
    char *buf;
    size_t len;
    hv_status st = hv__mesh_read_file(path, &buf, &len);
    if (st)
        return st;
    points_builder b = {path, NULL, NULL, 0, 0, 0, 0, 0};
    const int ply = len >= 4 && !strncmp(buf, "ply", 3) && (buf[3] == '\n' || buf[3] == '\r');
    st = ply ? hv__points_read_ply(path, buf, len, &b) : read_text(path, buf, len, &b);
    free(buf);
    if (!st)
        st = check_normals(&b);
    if (!st)
        st = points_finish(&b, ply ? "PLY points" : "text points", out);
    free(b.xyz);
    free(b.nrm);
    return st;
}

hv_status hv_points_from_arrays(hv_points **out, const double *xyz, const double *normals,
                                size_t count)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_points_from_arrays: out is NULL");
    *out = NULL;
    if (!xyz || count == 0)
        return hv__error(HV_ERR_INVALID_ARG, "hv_points_from_arrays: %zu points, positions %s",
                         count, xyz ? "given" : "NULL");
    const int values = normals ? 6 : 3;
    points_builder b = {"points", NULL, NULL, 0, 0, 0, 0, values};
    hv_status st = hv__points_reserve(&b, count);
    for (size_t i = 0; i < count && !st; i++) {
        double p[6];
        char at[48];
        memcpy(p, xyz + 3 * i, 3 * sizeof *p);
        if (normals)
            memcpy(p + 3, normals + 3 * i, 3 * sizeof *p);
        snprintf(at, sizeof at, "point %zu", i + 1);
        st = hv__points_add(&b, p, values, at);
    }
    if (!st)
        st = points_finish(&b, NULL, out);
    free(b.xyz);
    free(b.nrm);
    return st;
}

void hv_points_destroy(hv_points **p)
{
    if (!p || !*p)
        return;
    free((*p)->xyz);
    free((*p)->normals);
    free(*p);
    *p = NULL;
}
