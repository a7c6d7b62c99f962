/* Dense fields as parallel HDF5 with an XDMF sidecar (petsc.h), in builds made
 * with HV_HAVE_PETSC (make mpi): the block becomes a DMDA over
 * PETSC_COMM_WORLD, rank 0's fields are scattered to the ranks' boxes, and
 * PETSc's HDF5 viewer writes the boxes into one dataset per field
 * with MPI-IO (VecView on a DMDA vector: shape (nz, ny, nx), x fastest). The
 * grid's placement goes into attributes of each dataset and into the XDMF
 * file, which describes the cell corners as a co-rectilinear mesh and the
 * fields as cell-centred attributes. */
#include "heatvox/petsc.h"
#include "core/error.h"
#include "dmda.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#ifdef HV_HAVE_PETSC
#include <petscdmda.h>
#include <petscviewerhdf5.h>

/* The sidecar's name: path with ".h5" replaced by ".xmf", or ".xmf" appended. */
static hv_status xmf_name(const char *path, char *out, size_t size)
{
    const size_t len = strlen(path);
    const int h5 = len > 3 && !strcmp(path + len - 3, ".h5");
    const int n = snprintf(out, size, "%.*s.xmf", (int)(h5 ? len - 3 : len), path);
    if (n < 0 || (size_t)n >= size)
        return hv__error(HV_ERR_INVALID_ARG, "%s: path too long", path);
    return HV_OK;
}

static hv_status h5_fail(PetscErrorCode ierr, const char *path, const char *what)
{
    const char *text = NULL;
    PetscErrorMessage(ierr, &text, NULL);
    return hv__error(HV_ERR_IO, "%s: %s failed (PETSc error %d: %s)", path, what, (int)ierr,
                     text ? text : "?");
}

/* A float64 array attribute on the dataset /name. */
static hv_status put_attribute(PetscViewer v, const char *path, const char *name, const char *attr,
                               const double *val, int count)
{
    hid_t fid;
    if (PetscViewerHDF5GetFileId(v, &fid))
        return hv__error(HV_ERR_IO, "%s: no HDF5 file id", path);
    char ds_name[256];
    snprintf(ds_name, sizeof ds_name, "/%s", name);
    const hsize_t dims = (hsize_t)count;
    hid_t ds = H5Dopen2(fid, ds_name, H5P_DEFAULT);
    hid_t sp = H5Screate_simple(1, &dims, NULL);
    hid_t at = ds >= 0 && sp >= 0
                   ? H5Acreate2(ds, attr, H5T_NATIVE_DOUBLE, sp, H5P_DEFAULT, H5P_DEFAULT)
                   : -1;
    herr_t w = at >= 0 ? H5Awrite(at, H5T_NATIVE_DOUBLE, val) : -1;
    if (at >= 0)
        H5Aclose(at);
    if (sp >= 0)
        H5Sclose(sp);
    if (ds >= 0)
        H5Dclose(ds);
    if (w < 0)
        return hv__error(HV_ERR_IO, "%s: cannot write the attribute '%s' of '%s'", path, attr,
                         name);
    return HV_OK;
}

static hv_status write_xmf(const char *tmp, const char *h5_path, int nfields, const hv_grid *g,
                           const char *const *names)
{
    FILE *fp = fopen(tmp, "w");
    if (!fp)
        return hv__error(HV_ERR_IO, "%s: cannot create the XDMF file", tmp);
    /* The data file relative to the sidecar: both lie in one directory. */
    const char *slash = strrchr(h5_path, '/');
    const char *base = slash ? slash + 1 : h5_path;
    const int d3 = g->dim == 3;
    char cells[96], corners[96], org[128], spc[128];
    if (d3) {
        snprintf(cells, sizeof cells, "%d %d %d", g->n[2], g->n[1], g->n[0]);
        snprintf(corners, sizeof corners, "%d %d %d", g->n[2] + 1, g->n[1] + 1, g->n[0] + 1);
        snprintf(org, sizeof org, "%.17g %.17g %.17g", g->origin[2], g->origin[1], g->origin[0]);
        snprintf(spc, sizeof spc, "%.17g %.17g %.17g", g->h, g->h, g->h);
    } else {
        snprintf(cells, sizeof cells, "%d %d", g->n[1], g->n[0]);
        snprintf(corners, sizeof corners, "%d %d", g->n[1] + 1, g->n[0] + 1);
        snprintf(org, sizeof org, "%.17g %.17g", g->origin[1], g->origin[0]);
        snprintf(spc, sizeof spc, "%.17g %.17g", g->h, g->h);
    }
    fprintf(fp,
            "<?xml version=\"1.0\" ?>\n"
            "<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n"
            "<Xdmf Version=\"3.0\">\n"
            " <Domain>\n"
            "  <Grid Name=\"heatvox\" GridType=\"Uniform\">\n"
            "   <Topology TopologyType=\"%s\" Dimensions=\"%s\"/>\n"
            "   <Geometry GeometryType=\"%s\">\n"
            "    <DataItem Dimensions=\"%d\" NumberType=\"Float\" Precision=\"8\" "
            "Format=\"XML\">%s</DataItem>\n"
            "    <DataItem Dimensions=\"%d\" NumberType=\"Float\" Precision=\"8\" "
            "Format=\"XML\">%s</DataItem>\n"
            "   </Geometry>\n",
            d3 ? "3DCoRectMesh" : "2DCoRectMesh", corners, d3 ? "ORIGIN_DXDYDZ" : "ORIGIN_DXDY",
            g->dim, org, g->dim, spc);
    for (int f = 0; f < nfields; f++)
        fprintf(fp,
                "   <Attribute Name=\"%s\" AttributeType=\"Scalar\" Center=\"Cell\">\n"
                "    <DataItem Dimensions=\"%s\" NumberType=\"Float\" Precision=\"8\" "
                "Format=\"HDF\">%s:/%s</DataItem>\n"
                "   </Attribute>\n",
                names[f], cells, base, names[f]);
    fprintf(fp, "  </Grid>\n </Domain>\n</Xdmf>\n");
    const int bad = ferror(fp) | fclose(fp);
    if (bad)
        return hv__error(HV_ERR_IO, "%s: cannot write the XDMF file", tmp);
    return HV_OK;
}

/* Every field into the file tmp (collective): rank 0's grids g, scattered
 * to the ranks' boxes; hdr is the block's shape on every rank. */
static hv_status write_fields(const char *tmp, const char *path, int nfields,
                              const hv_grid *const *g, const hv_grid *hdr, const char *const *names)
{
    hv_block_io B;
    Vec x = NULL;
    PetscViewer v = NULL;
    PetscErrorCode ierr = 0;
    hv_status st = hv__block_create(&B, hdr->dim, hdr->n);
    if (!st && (ierr = DMCreateGlobalVector(B.da, &x)))
        st = h5_fail(ierr, path, "setting up the distributed grid");
    if (!st && (ierr = PetscViewerHDF5Open(PETSC_COMM_WORLD, tmp, FILE_MODE_WRITE, &v)))
        st = h5_fail(ierr, path, "creating the HDF5 file");
    const double spacing[3] = {hdr->h, hdr->h, hdr->h};
    for (int f = 0; f < nfields && !st; f++) {
        /* rank 0 alone reads its grid: agreed before the collective write */
        if ((st = hv__petsc_agree(B.da, hv__block_in(&B, g ? g[f]->v : NULL, NULL, x))))
            break;
        if ((ierr = PetscObjectSetName((PetscObject)x, names[f])) || (ierr = VecView(x, v)))
            st = h5_fail(ierr, path, "writing a field");
        if (!st)
            st = put_attribute(v, path, names[f], "spacing", spacing, hdr->dim);
        if (!st)
            st = put_attribute(v, path, names[f], "origin", hdr->origin, hdr->dim);
    }
    if (v && (ierr = PetscViewerDestroy(&v)) && !st)
        st = h5_fail(ierr, path, "closing the HDF5 file");
    VecDestroy(&x);
    hv__block_destroy(&B);
    return st;
}

/* Rank 0's checks of its grids and names. */
static hv_status check_fields(const char *path, int nfields, const hv_grid *const *g,
                              const char *const *names)
{
    if (!g)
        return hv__error(HV_ERR_INVALID_ARG, "hv_petsc_write_h5: bad arguments");
    for (int f = 0; f < nfields; f++) {
        if (!g[f] || !g[f]->v || !names[f] || !names[f][0] || strlen(names[f]) > 200 ||
            strpbrk(names[f], "/<>&\"'"))
            return hv__error(HV_ERR_INVALID_ARG, "%s: field %d has no grid or a bad name", path, f);
        for (int q = 0; q < f; q++)
            if (!strcmp(names[q], names[f]))
                return hv__error(HV_ERR_INVALID_ARG, "%s: two fields named '%s'", path, names[f]);
        if (g[f]->dim != g[0]->dim || memcmp(g[f]->n, g[0]->n, sizeof g[0]->n) ||
            g[f]->h != g[0]->h || memcmp(g[f]->origin, g[0]->origin, sizeof g[0]->origin))
            return hv__error(HV_ERR_INVALID_ARG, "%s: field '%s' is on another block than '%s'",
                             path, names[f], names[0]);
    }
    return HV_OK;
}

static hv_status hv_petsc_write_h5_body(const char *path, int nfields, const hv_grid *const *g,
                                        const char *const *names)
{
    if (!path || nfields < 1 || !names)
        return hv__error(HV_ERR_INVALID_ARG, "hv_petsc_write_h5: bad arguments");
    hv_status st = hv_petsc_init();
    if (st)
        return st;
    int rank = 0;
    MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
    /* Rank 0's block: checked there, its shape sent to every rank. */
    double h[9] = {0};
    if (!rank && !(st = check_fields(path, nfields, g, names))) {
        h[0] = 1;
        h[1] = g[0]->dim;
        h[2] = g[0]->h;
        for (int a = 0; a < 3; a++) {
            h[3 + a] = g[0]->n[a];
            h[6 + a] = g[0]->origin[a];
        }
    }
    (void)MPI_Bcast(h, 9, MPI_DOUBLE, 0, PETSC_COMM_WORLD);
    if (!h[0])
        return rank ? hv__error(HV_ERR_INVALID_ARG, "%s: rank 0's fields are not writable", path)
                    : st;
    hv_grid hdr;
    memset(&hdr, 0, sizeof hdr);
    hdr.dim = (int)h[1];
    hdr.h = h[2];
    for (int a = 0; a < 3; a++) {
        hdr.n[a] = (int)h[3 + a];
        hdr.origin[a] = h[6 + a];
    }
    char xmf[4096], tmp[4096 + 64], xtmp[4096 + 64];
    if ((st = xmf_name(path, xmf, sizeof xmf)))
        return st;
    /* Rank 0 names the temporaries; every rank opens the same one. */
    int ok = 1;
    if (!rank) {
        ok = !hv_tmp_name(path, tmp, sizeof tmp);
        if (ok && hv_tmp_name(xmf, xtmp, sizeof xtmp)) {
            hv_tmp_discard(tmp);
            ok = 0;
        }
    }
    (void)MPI_Bcast(&ok, 1, MPI_INT, 0, PETSC_COMM_WORLD);
    if (!ok)
        return rank ? hv__error(HV_ERR_IO, "%s: rank 0 could not name a temporary", path)
                    : hv__error(HV_ERR_IO, "%s: cannot name a temporary file", path);
    (void)MPI_Bcast(tmp, (int)sizeof tmp, MPI_CHAR, 0, PETSC_COMM_WORLD);
    st = write_fields(tmp, path, nfields, rank ? NULL : g, &hdr, names);
    /* Rank 0 writes the sidecar and renames both; the others learn how it went. */
    int fail = st != HV_OK;
    MPI_Allreduce(MPI_IN_PLACE, &fail, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
    if (!rank) {
        /* The sidecar first: if the data file's rename then fails, the
         * sidecar is removed again, and neither is left. */
        int xmf_in_place = 0;
        if (!fail && !(st = write_xmf(xtmp, path, nfields, g[0], names)) &&
            !(st = hv_tmp_commit(xtmp, xmf))) {
            xmf_in_place = 1;
            if ((st = hv_tmp_commit(tmp, path)))
                unlink(xmf);
        }
        if (fail || st) {
            hv_tmp_discard(tmp);
            if (!xmf_in_place)
                hv_tmp_discard(xtmp);
            if (!st)
                st = hv__error(HV_ERR_IO, "%s: another rank failed to write its part", path);
        }
    }
    int bad = st != HV_OK;
    (void)MPI_Bcast(&bad, 1, MPI_INT, 0, PETSC_COMM_WORLD);
    if (bad && !st)
        st = hv__error(HV_ERR_IO, "%s: rank 0 could not complete the file", path);
    return st;
}

hv_status hv_petsc_write_h5(const char *path, int nfields, const hv_grid *const *g,
                            const char *const *names)
{
    HV_PETSC_QUIETLY(hv_petsc_write_h5_body(path, nfields, g, names));
}

#else /* without PETSc */

hv_status hv_petsc_write_h5(const char *path, int nfields, const hv_grid *const *g,
                            const char *const *names)
{
    (void)nfields;
    (void)g;
    (void)names;
    return hv__error(HV_ERR_UNSUPPORTED,
                     "%s: HDF5 output needs heatvox built with MPI and PETSc (make mpi)",
                     path ? path : "(null)");
}

#endif
