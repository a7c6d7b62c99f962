/* Writing a mesh as OBJ, binary PLY or binary STL, each through a temporary
 * file renamed into place when complete. Binary files are little endian
 * whatever the host, written byte by byte. */
#include "mesh_internal.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>

/* Checks the mesh, names the temporary beside path and opens it. */
static hv_status open_tmp(const hv_mesh *m, const char *path, const char *fn, char *tmp,
                          size_t tmpsize, FILE **f)
{
    *f = NULL;
    if (!m || !path)
        return hv__error(HV_ERR_INVALID_ARG, "%s: NULL argument", fn);
    for (size_t i = 0; i < 3 * m->ntris; i++)
        if (m->tris[i] >= m->nverts)
            return hv__error(HV_ERR_INVALID_ARG, "%s: triangle %zu uses vertex %u of %zu", path,
                             i / 3, m->tris[i], m->nverts);
    hv_status st;
    *f = hv__tmp_open(path, tmp, tmpsize, &st);
    return *f ? HV_OK : st;
}

/* Closes f and renames tmp to path, or removes tmp when anything failed. */
static hv_status finish(FILE *f, const char *tmp, const char *path)
{
    int bad = ferror(f);
    int e = errno;
    if (fclose(f) != 0 && !bad) {
        bad = 1;
        e = errno;
    }
    if (bad) {
        hv_tmp_discard(tmp);
        return hv__error(HV_ERR_IO, "%s: write failed: %s", path, strerror(e ? e : EIO));
    }
    return hv_tmp_commit(tmp, path);
}

hv_status hv_mesh_write_obj(const hv_mesh *m, const char *path)
{
    char tmp[PATH_MAX];
    FILE *f;
    hv_status st = open_tmp(m, path, "hv_mesh_write_obj", tmp, sizeof tmp, &f);
    if (st)
        return st;
    fprintf(f, "# heatvox %s: %zu vertices, %zu triangles\n", hv_version(), m->nverts, m->ntris);
    for (size_t i = 0; i < m->nverts; i++) {
        const double *p = m->verts + 3 * i;
        fprintf(f, "v %.17g %.17g %.17g\n", p[0], p[1], p[2]);
    }
    for (size_t t = 0; t < m->ntris; t++) {
        const uint32_t *c = m->tris + 3 * t;
        fprintf(f, "f %lu %lu %lu\n", (unsigned long)c[0] + 1, (unsigned long)c[1] + 1,
                (unsigned long)c[2] + 1);
    }
    return finish(f, tmp, path);
}

static unsigned char *put_u32(unsigned char *b, uint32_t u)
{
    for (int k = 0; k < 4; k++)
        b[k] = (unsigned char)(u >> (8 * k));
    return b + 4;
}

static unsigned char *put_f32(unsigned char *b, float x)
{
    uint32_t u;
    memcpy(&u, &x, sizeof u);
    return put_u32(b, u);
}

static unsigned char *put_f64(unsigned char *b, double x)
{
    uint64_t u;
    memcpy(&u, &x, sizeof u);
    for (int k = 0; k < 8; k++)
        b[k] = (unsigned char)(u >> (8 * k));
    return b + 8;
}

hv_status hv_mesh_write_ply(const hv_mesh *m, const char *path)
{
    char tmp[PATH_MAX];
    FILE *f;
    hv_status st = open_tmp(m, path, "hv_mesh_write_ply", tmp, sizeof tmp, &f);
    if (st)
        return st;
    fprintf(f,
            "ply\nformat binary_little_endian 1.0\ncomment heatvox %s\n"
            "element vertex %zu\nproperty double x\nproperty double y\nproperty double z\n"
            "element face %zu\nproperty list uchar uint vertex_indices\nend_header\n",
            hv_version(), m->nverts, m->ntris);
    unsigned char rec[24];
    for (size_t i = 0; i < m->nverts && !ferror(f); i++) {
        unsigned char *b = rec;
        for (int a = 0; a < 3; a++)
            b = put_f64(b, m->verts[3 * i + a]);
        fwrite(rec, 1, 24, f);
    }
    for (size_t t = 0; t < m->ntris && !ferror(f); t++) {
        unsigned char *b = rec;
        *b++ = 3;
        for (int k = 0; k < 3; k++)
            b = put_u32(b, m->tris[3 * t + k]);
        fwrite(rec, 1, 13, f);
    }
    return finish(f, tmp, path);
}

hv_status hv_mesh_write_stl(const hv_mesh *m, const char *path)
{
    if (m && m->ntris > UINT32_MAX)
        return hv__error(HV_ERR_INVALID_ARG, "%s: %zu triangles: binary STL holds at most %lu",
                         path ? path : "STL", m->ntris, (unsigned long)UINT32_MAX);
    char tmp[PATH_MAX];
    FILE *f;
    hv_status st = open_tmp(m, path, "hv_mesh_write_stl", tmp, sizeof tmp, &f);
    if (st)
        return st;
    /* The 80-byte header must not start with "solid" (readers that look at it
     * would take the file for ascii). */
    unsigned char head[84] = {0};
    snprintf((char *)head, 80, "heatvox %s binary STL", hv_version());
    put_u32(head + 80, (uint32_t)m->ntris);
    fwrite(head, 1, sizeof head, f);
    unsigned char rec[50];
    for (size_t t = 0; t < m->ntris && !ferror(f); t++) {
        const double *p[3];
        for (int k = 0; k < 3; k++)
            p[k] = m->verts + 3 * m->tris[3 * t + k];
        double u[3], v[3], n[3];
        for (int a = 0; a < 3; a++) {
            u[a] = p[1][a] - p[0][a];
            v[a] = p[2][a] - p[0][a];
        }
        n[0] = u[1] * v[2] - u[2] * v[1];
        n[1] = u[2] * v[0] - u[0] * v[2];
        n[2] = u[0] * v[1] - u[1] * v[0];
        double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        unsigned char *b = rec;
        for (int a = 0; a < 3; a++) /* a degenerate facet gets the zero normal */
            b = put_f32(b, len > 0 && isfinite(len) ? (float)(n[a] / len) : 0.0f);
        for (int k = 0; k < 3; k++)
            for (int a = 0; a < 3; a++)
                b = put_f32(b, (float)p[k][a]);
        b[0] = b[1] = 0; /* attribute byte count */
        fwrite(rec, 1, 50, f);
    }
    return finish(f, tmp, path);
}

hv_status hv_mesh_write(const hv_mesh *m, const char *path)
{
    if (!m || !path)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_write: NULL argument");
    const char *slash = strrchr(path, '/');
    const char *dot = strrchr(path, '.');
    const char *ext = dot && (!slash || dot > slash) ? dot + 1 : "";
    if (!strcasecmp(ext, "obj"))
        return hv_mesh_write_obj(m, path);
    if (!strcasecmp(ext, "ply"))
        return hv_mesh_write_ply(m, path);
    if (!strcasecmp(ext, "stl"))
        return hv_mesh_write_stl(m, path);
    return hv__error(HV_ERR_INVALID_ARG,
                     "%s: cannot tell the mesh format from the extension (.obj, .ply or .stl)",
                     path);
}
