/* Writing a mesh as OBJ through a temporary file renamed into place. */
#include "mesh_internal.h"

#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <string.h>

hv_status hv_mesh_write_obj(const hv_mesh *m, const char *path)
{
    if (!m || !path)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_write_obj: NULL argument");
    for (size_t i = 0; i < 3 * m->ntris; i++)
        if (m->tris[i] >= m->nverts)
            return hv__error(HV_ERR_INVALID_ARG, "%s: triangle %zu uses vertex %u of %zu", path,
                             i / 3, m->tris[i], m->nverts);
    char tmp[PATH_MAX];
    hv_status st = hv_tmp_name(path, tmp, sizeof tmp);
    if (st)
        return st;
    FILE *f = fopen(tmp, "w");
    if (!f) {
        int e = errno;
        hv_tmp_discard(tmp);
        return hv__error(HV_ERR_IO, "%s: cannot create: %s", tmp, strerror(e));
    }
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
    int bad = ferror(f);
    int e = errno;
    if (fclose(f) != 0 && !bad) {
        bad = 1;
        e = errno;
    }
    if (bad) {
        hv_tmp_discard(tmp);
        return hv__error(HV_ERR_IO, "%s: write failed: %s", path, strerror(e));
    }
    return hv_tmp_commit(tmp, path);
}
