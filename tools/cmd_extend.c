/* heatvox extend: extends scalar and vector grids of a VDB file off a level set. */
#include "cli.h"
#include "heatvox/petsc.h"

#include <math.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *CMD = "extend";

#define MAX_FIELDS 32
#define MAX_GRIDS 256

static int usage(FILE *out)
{
    fprintf(out,
            "usage: heatvox extend IN.vdb --levelset NAME --field NAME [--field NAME ...]\n"
            "                      -o OUT.vdb|OUT.h5\n"
            "                      [--band W] [--t-scale K] [--out-band W] [--dense] [--plain]\n"
            "                      [--backend auto|mg|fftw|opencl|petsc] [--threads T] [-q] [-v]\n"
            "\n"
            "Extends each --field (float/double: scalar; vec3s/vec3d: vector, e.g. a\n"
            "velocity) off the zero set of the level set by diffusion (heat.h): the values\n"
            "on cells with |phi| < W voxels (--band, default 1.5) are diffused with their\n"
            "weights, and every output cell takes the ratio at its closest point on the\n"
            "surface where phi is a distance, at itself elsewhere (clamped narrow-band level\n"
            "sets; larger diffusion times reach far cells). Vectors: magnitude and\n"
            "direction are diffused separately (vector heat method). All fields are solved\n"
            "together.\n"
            "  --t-scale K   diffusion time t = K h^2 (default 0.25)\n"
            "  --out-band W  only voxels with |phi| < W voxels\n"
            "  --dense       read the grids onto one dense block (their active boxes'\n"
            "                union) and extend over every voxel of it (or --out-band W)\n"
            "  --plain       no closest points: the diffusion ratio at every voxel\n"
            "\n"
            "A level set (class 'level set') is read and extended as a narrow band: 8^3\n"
            "tiles of its active voxels, never a dense block; the output voxels are its\n"
            "active voxels (with --out-band W, those with |phi| < W voxels), and the fields\n"
            "come back sparse, active there (--backend opencl: every step on the OpenCL\n"
            "device, the same values; auto takes it on a GPU). Other classes, and --dense,\n"
            "take the dense block, where fields come back fully active. All transforms\n"
            "must match.\n"
            "OUT.vdb gets the level set (a level set again) and the extended fields, with\n"
            "their names, voxel size, world placement, index coordinates and classes. Other\n"
            "grids of IN.vdb are not copied. Prints a JSON summary on stdout (not with -q);\n"
            "-v reports the tiles, levels and peak memory on stderr.\n"
            "\n"
            "Builds with PETSc (make mpi): -o OUT.h5 writes the dense block as HDF5, one\n"
            "dataset per grid (vectors as NAME_x, NAME_y, NAME_z) with the attributes\n"
            "spacing and origin, and an XDMF sidecar OUT.xmf for ParaView. Under\n"
            "mpirun -n P with --backend petsc (the dense block), rank 0 reads the block,\n"
            "each rank extends its own box with a ghost layer (the diffusion solved over\n"
            "all ranks; closest points past the layer read from the ranks that own\n"
            "them), and rank 0 gathers the result and writes the VDB file (the ranks\n"
            "write HDF5 together).\n"
            "Exit codes: 0 success, 1 failure, 2 usage error.\n");
    return out == stdout ? HV_EXIT_OK : HV_EXIT_USAGE;
}

/* The HDF5 datasets of a dense extension: the level set, then each field
 * (vector fields as NAME_x, NAME_y, NAME_z). */
typedef struct {
    char name[1 + 3 * MAX_FIELDS][300];
    const char *p[1 + 3 * MAX_FIELDS];
} h5_names;

static int h5_fields(h5_names *hn, const char *ls, const char *const *fields, int nfields,
                     const hv_extend_field *ef)
{
    int nh = 0;
    snprintf(hn->name[nh++], sizeof hn->name[0], "%s", ls);
    for (int q = 0; q < nfields; q++)
        for (int c = 0; c < ef[q].ncomp; c++, nh++) {
            if (ef[q].ncomp == 1)
                snprintf(hn->name[nh], sizeof hn->name[0], "%s", fields[q]);
            else
                snprintf(hn->name[nh], sizeof hn->name[0], "%s_%c", fields[q], "xyz"[c]);
        }
    for (int q = 0; q < nh; q++)
        hn->p[q] = hn->name[q];
    return nh;
}

static const char *class_name(int c)
{
    switch (c) {
    case HV_VDB_LEVEL_SET: return "level set";
    case HV_VDB_FOG_VOLUME: return "fog volume";
    case HV_VDB_STAGGERED: return "staggered";
    default: return "unknown";
    }
}

static void list_grids(const char *path, const hv_vdb_grid_info *info, size_t count)
{
    fprintf(stderr, "heatvox extend: %s holds:", path);
    if (!count)
        fprintf(stderr, " no grids");
    for (size_t i = 0; i < count && i < MAX_GRIDS; i++)
        fprintf(stderr, " '%s' (%s)", info[i].name, info[i].value_type);
    fprintf(stderr, "\n");
}

static const hv_vdb_grid_info *find_grid(const hv_vdb_grid_info *info, size_t count,
                                         const char *name)
{
    for (size_t i = 0; i < count && i < MAX_GRIDS; i++)
        if (!strcmp(info[i].name, name))
            return &info[i];
    return NULL;
}

static int is_scalar(const char *t) { return !strcmp(t, "float") || !strcmp(t, "double"); }
static int is_vector(const char *t) { return !strcmp(t, "vec3s") || !strcmp(t, "vec3d"); }

/* Returns the heap's free pages to the system: OpenVDB's grids, read and
 * dropped, leave many small blocks behind that would otherwise stay resident
 * under the extension's and the writer's memory. */
static void release_freed(void)
{
#ifdef __GLIBC__
    malloc_trim(0);
#endif
}

/* What one run of the command extends: the parsed command line and the
 * input's grids. */
typedef struct extend_job {
    const char *in, *out, *ls, *fields[MAX_FIELDS];
    const char *h5; /* out when it names an HDF5 file, else NULL */
    int nfields, threads, dense;
    hv_extend_opts o;
    const hv_vdb_grid_info *info;
    size_t count;
    double t_start;
} extend_job;

static void warn_staggered(const extend_job *j, int q)
{
    const hv_vdb_grid_info *gi = find_grid(j->info, j->count, j->fields[q]);
    if (gi->grid_class == HV_VDB_STAGGERED && cli_verbose >= 0)
        fprintf(stderr,
                "heatvox extend: warning: '%s' is staggered; its components are "
                "extended as if they sat at voxel centres\n",
                j->fields[q]);
}

static void warn_weak(const hv_extend_stats *es)
{
    if (es->weak_cells && cli_verbose >= 0)
        fprintf(stderr,
                "heatvox extend: warning: %zu voxels are far beyond the diffusion's reach; "
                "their values are unreliable\n",
                es->weak_cells);
}

/* The output level set's band in voxels: its background, the largest |phi|
 * of the values. */
static double levelset_band(const float *v, size_t count, double h)
{
    double bg = 0;
    for (size_t c = 0; c < count; c++)
        bg = fmax(bg, fabs(v[c]));
    double band = bg / h;
    return band >= 1 ? band : 1;
}

/* ---- a narrow band in tiles ---- */

/* The level set and the fields as tiles of the block [lo, hi], extended on
 * them and written from them (hv_extend_tiles): no dense block. */
typedef struct tiles_run {
    hv_tiles *P, *fin[MAX_FIELDS][3];
    hv_extend_tiles_field tf[MAX_FIELDS];
    hv_extend_stats es;
    double t_setup;
} tiles_run;

static int read_tiles(const extend_job *j, const int lo[3], const int hi[3], tiles_run *r)
{
    int cls;
    hv_status st;
    double t0 = hv_now();
    if ((st = hv_vdb_read_float_tiles(j->in, j->ls, lo, hi, &r->P, &cls)))
        return cli_fail(CMD, j->in, st);
    for (int q = 0; q < j->nfields; q++) {
        int ncomp = 0;
        if ((st = hv_vdb_read_tiles_like(j->in, j->fields[q], r->P, r->fin[q], &ncomp)))
            return cli_fail(CMD, j->in, st);
        warn_staggered(j, q);
        r->tf[q].ncomp = ncomp;
        for (int c = 0; c < ncomp; c++)
            r->tf[q].v[c] = r->fin[q][c];
    }
    const double t_read = hv_now() - t0;
    release_freed();
    const hv_tiles *P = r->P;
    cli_info("heatvox extend: block %d x %d x %d, h = %g, %d fields, narrow band in %zu tiles of "
             "8^3 (%zu active voxels); read %.2f s, peak %.0f MB\n",
             P->n[0], P->n[1], P->n[2], P->h, j->nfields, P->count, P->active, t_read,
             hv_peak_rss() / 1e6);
    return 0;
}

static int extend_on_tiles(const extend_job *j, tiles_run *r)
{
    hv_extender *e = NULL;
    hv_status st;
    double t0 = hv_now();
    if ((st = hv_extender_create(&e, 3, r->P->n, r->P->h, NULL, &j->o)))
        return cli_fail(CMD, j->in, st);
    r->t_setup = hv_now() - t0;
    st = hv_extend_tiles(e, r->P, j->nfields, r->tf, &r->es);
    hv_extender_destroy(&e);
    if (st)
        return cli_fail(CMD, j->in, st);
    const hv_extend_stats *es = &r->es;
    cli_info("heatvox extend: %d levels%s; %zu source cells, %zu output cells (%zu at closest "
             "points), %zu cells in the first level's solve; work %.0f MB; set-up %.3f s, "
             "extension %.2f s (solves %.2f, evaluation %.2f), peak %.0f MB\n",
             es->levels, es->on_device ? ", on the device" : "", es->source_cells,
             es->cp_cells + es->ratio_cells, es->cp_cells, es->solve_cells, es->work_bytes / 1e6,
             r->t_setup, es->t_total, es->t_solve, es->t_eval, hv_peak_rss() / 1e6);
    warn_weak(es);
    release_freed();
    return 0;
}

/* The fields, sparse, with names and classes, and the level set (band = its
 * background); each set of tiles is freed once the writer holds its copy. */
static hv_status write_tiles(const extend_job *j, tiles_run *r)
{
    hv_tiles *P = r->P;
    const double band = levelset_band(P->v, P->count * (size_t)(HV_TILE * HV_TILE * HV_TILE), P->h);
    const hv_vdb_grid_info *lsi = find_grid(j->info, j->count, j->ls);
    hv_vdb_writer *w = NULL;
    hv_status st = hv_vdb_writer_create(&w);
    if (!st)
        st = hv_vdb_writer_set_index_origin(w, lsi->index0_world);
    for (int q = 0; q < j->nfields && !st; q++) {
        const hv_vdb_grid_info *gi = find_grid(j->info, j->count, j->fields[q]);
        hv_tiles *const *t = r->fin[q];
        st = r->tf[q].ncomp == 3 ? hv_vdb_writer_add_vec3_tiles(w, t[0], t[1], t[2], j->fields[q])
                                 : hv_vdb_writer_add_float_tiles(w, t[0], j->fields[q]);
        if (!st && gi->grid_class != HV_VDB_UNKNOWN)
            st = hv_vdb_writer_set_grid_meta(w, j->fields[q], "class", class_name(gi->grid_class));
        for (int c = 0; c < 3; c++)
            hv_tiles_destroy(&r->fin[q][c]);
    }
    if (!st)
        st = hv_vdb_writer_add_levelset_tiles(w, P, j->ls, band);
    hv_tiles_destroy(&r->P);
    char buf[512];
    snprintf(buf, sizeof buf, "heatvox extend: levelset %s, band %g, t_scale %g, narrow band%s, %s",
             j->ls, j->o.band, j->o.t_scale, j->o.out_band > 0 ? " (out-band)" : "",
             j->o.closest_point ? "closest point" : "plain");
    if (!st)
        st = hv_vdb_writer_set_meta(w, "heatvox_extend", buf);
    if (!st)
        st = hv_vdb_writer_write(w, j->out);
    hv_vdb_writer_destroy(&w);
    return st;
}

static int extend_tiles(const extend_job *j, const int lo[3], const int hi[3])
{
    tiles_run r;
    memset(&r, 0, sizeof r);
    int rc = read_tiles(j, lo, hi, &r);
    if (!rc)
        rc = extend_on_tiles(j, &r);
    if (rc)
        goto done;
    const int n[3] = {r.P->n[0], r.P->n[1], r.P->n[2]};
    const double h = r.P->h;
    const size_t ntiles = r.P->count, nactive = r.P->active;
    double t0 = hv_now();
    hv_status st = write_tiles(j, &r);
    if (st) {
        rc = cli_fail(CMD, j->out, st);
        goto done;
    }
    cli_info("heatvox extend: wrote %s in %.2f s, peak %.0f MB\n", j->out, hv_now() - t0,
             hv_peak_rss() / 1e6);
    const hv_extend_stats *es = &r.es;
    if (cli_verbose >= 0)
        printf("{\"command\":\"extend\",\"path\":\"tiles\",\"grid\":[%d,%d,%d],\"h\":%g,"
               "\"fields\":%d,\"tiles\":%zu,\"active_voxels\":%zu,\"solves\":%d,\"levels\":%d,"
               "\"source_cells\":%zu,\"cp_cells\":%zu,\"ratio_cells\":%zu,\"weak_cells\":%zu,"
               "\"solve_cells\":%zu,\"work_mb\":%.1f,\"setup_seconds\":%.4f,"
               "\"extend_seconds\":%.3f,\"seconds\":%.3f,\"peak_rss_mb\":%.1f}\n",
               n[0], n[1], n[2], h, j->nfields, ntiles, nactive, es->solves, es->levels,
               es->source_cells, es->cp_cells, es->ratio_cells, es->weak_cells, es->solve_cells,
               es->work_bytes / 1e6, r.t_setup, es->t_total, hv_now() - j->t_start,
               hv_peak_rss() / 1e6);
done:
    hv_tiles_destroy(&r.P);
    for (int q = 0; q < MAX_FIELDS; q++)
        for (int c = 0; c < 3; c++)
            hv_tiles_destroy(&r.fin[q][c]);
    return rc;
}

/* ---- a dense block ---- */

typedef struct dense_run {
    hv_grid *phi, *fin[MAX_FIELDS][3], *fout[MAX_FIELDS][3];
    hv_extend_field ef[MAX_FIELDS];
    hv_extend_stats es;
} dense_run;

static void dense_free(dense_run *r)
{
    hv_grid_destroy(&r->phi);
    for (int q = 0; q < MAX_FIELDS; q++)
        for (int c = 0; c < 3; c++) {
            hv_grid_destroy(&r->fin[q][c]);
            hv_grid_destroy(&r->fout[q][c]);
        }
}

/* Each field's components, without arrays (the ranks other than 0 under
 * --backend petsc, and a rank 0 that failed to read). */
static void fields_without_arrays(const extend_job *j, hv_extend_field *ef)
{
    for (int q = 0; q < j->nfields; q++) {
        memset(&ef[q], 0, sizeof ef[q]);
        ef[q].ncomp = is_vector(find_grid(j->info, j->count, j->fields[q])->value_type) ? 3 : 1;
    }
}

/* The level set, the fields and their outputs on the block ro. */
static int read_dense(const extend_job *j, const hv_vdb_read_opts *ro, dense_run *r)
{
    int cls;
    hv_status st;
    if ((st = hv_vdb_read_float(j->in, j->ls, ro, &r->phi, &cls)))
        return cli_fail(CMD, j->in, st);
    const hv_grid *phi = r->phi;
    for (int q = 0; q < j->nfields; q++) {
        const hv_vdb_grid_info *gi = find_grid(j->info, j->count, j->fields[q]);
        int vec = is_vector(gi->value_type);
        hv_grid **in = r->fin[q];
        st = vec ? hv_vdb_read_vec3(j->in, j->fields[q], ro, &in[0], &in[1], &in[2])
                 : hv_vdb_read_float(j->in, j->fields[q], ro, &in[0], NULL);
        if (st)
            return cli_fail(CMD, j->in, st);
        warn_staggered(j, q);
        hv_extend_field *ef = &r->ef[q];
        memset(ef, 0, sizeof *ef);
        ef->ncomp = vec ? 3 : 1;
        for (int c = 0; c < ef->ncomp; c++) {
            if ((st = hv_grid_create(&r->fout[q][c], 3, phi->n, phi->h, phi->origin)))
                return cli_fail(CMD, "allocating outputs", st);
            ef->in[c] = in[c]->v;
            ef->out[c] = r->fout[q][c]->v;
        }
    }
    cli_info("heatvox extend: block %d x %d x %d, h = %g, %d fields\n", phi->n[0], phi->n[1],
             phi->n[2], phi->h, j->nfields);
    return 0;
}

/* The extension on the block: by this process, or with --backend petsc on
 * every rank's box (hv_petsc_extend_block). */
static int extend_dense_block(const extend_job *j, int spread, dense_run *r)
{
    const hv_grid *phi = r->phi;
    hv_status st;
    if (spread) {
        st = hv_petsc_extend_block(3, phi->n, phi->h, &j->o, phi->v, j->nfields, r->ef, &r->es);
    } else {
        hv_extender *e = NULL;
        st = hv_extender_create(&e, 3, phi->n, phi->h, NULL, &j->o);
        if (!st)
            st = hv_extend_many(e, phi->v, j->nfields, r->ef, &r->es);
        hv_extender_destroy(&e);
    }
    if (st)
        return cli_fail(CMD, j->in, st);
    if (!spread)
        warn_weak(&r->es);
    return 0;
}

/* The HDF5 datasets of the block, written by the ranks together (petsc.h);
 * a rank 0 that failed passes no grids (r NULL), which fails every rank. */
static hv_status write_dense_h5(const extend_job *j, const dense_run *r, const hv_extend_field *ef)
{
    const hv_grid *hg[1 + 3 * MAX_FIELDS];
    h5_names hn;
    const int nh = h5_fields(&hn, j->ls, j->fields, j->nfields, ef);
    if (r) {
        hg[0] = r->phi;
        for (int q = 0, k = 1; q < j->nfields; q++)
            for (int c = 0; c < ef[q].ncomp; c++)
                hg[k++] = r->fout[q][c];
    }
    return hv_petsc_write_h5(j->out, nh, r ? hg : NULL, hn.p);
}

/* The level set (band = its background, the largest |phi| on the block) and
 * the fields, with names and classes, in the input's transform and index
 * coordinates. */
static hv_status fill_dense_writer(const extend_job *j, const dense_run *r, hv_vdb_writer *w)
{
    const hv_grid *phi = r->phi;
    const double band = levelset_band(phi->v, hv_grid_count(phi), phi->h);
    const hv_vdb_grid_info *lsi = find_grid(j->info, j->count, j->ls);
    hv_status st = hv_vdb_writer_set_index_origin(w, lsi->index0_world);
    if (!st)
        st = hv_vdb_writer_add_levelset(w, phi, j->ls, band, 0);
    for (int q = 0; q < j->nfields && !st; q++) {
        const hv_vdb_grid_info *gi = find_grid(j->info, j->count, j->fields[q]);
        hv_grid *const *f = r->fout[q];
        st = r->ef[q].ncomp == 3 ? hv_vdb_writer_add_vec3(w, f[0], f[1], f[2], j->fields[q])
                                 : hv_vdb_writer_add_float(w, f[0], j->fields[q]);
        /* OpenVDB keeps a grid's class in its "class" metadata string. */
        if (!st && gi->grid_class != HV_VDB_UNKNOWN && gi->grid_class != HV_VDB_LEVEL_SET)
            st = hv_vdb_writer_set_grid_meta(w, j->fields[q], "class", class_name(gi->grid_class));
        if (!st && gi->grid_class == HV_VDB_LEVEL_SET)
            st = hv_vdb_writer_set_grid_meta(w, j->fields[q], "class", "level set");
    }
    char buf[512];
    snprintf(buf, sizeof buf, "heatvox extend: levelset %s, band %g, t_scale %g, %s, %s", j->ls,
             j->o.band, j->o.t_scale, j->o.out_band > 0 ? "out-band" : "dense",
             j->o.closest_point ? "closest point" : "plain");
    if (!st)
        st = hv_vdb_writer_set_meta(w, "heatvox_extend", buf);
    return st;
}

/* OUT.h5 by every rank, or OUT.vdb by rank 0 under mpirun. */
static int write_dense(const extend_job *j, const dense_run *r)
{
    hv_vdb_writer *w = NULL;
    hv_status st = hv_vdb_writer_create(&w);
    if (!st)
        st = fill_dense_writer(j, r, w);
    if (j->h5) {
        const hv_status hs = write_dense_h5(j, st ? NULL : r, r->ef);
        if (!st)
            st = hs;
    } else if (!st && hv_mpi_rank() == 0) {
        st = hv_vdb_writer_write(w, j->out);
    }
    hv_vdb_writer_destroy(&w);
    return st ? cli_fail(CMD, j->out, st) : 0;
}

static void report_dense(const extend_job *j, const dense_run *r, int spread)
{
    const hv_grid *phi = r->phi;
    const hv_extend_stats *es = &r->es;
    if (spread) /* the cell counts would be rank 0's box's */
        printf("{\"command\":\"extend\",\"path\":\"dense-distributed\",\"ranks\":%d,"
               "\"grid\":[%d,%d,%d],\"h\":%g,\"fields\":%d,\"solves\":%d,\"levels\":%d,"
               "\"extend_seconds\":%.3f,\"seconds\":%.3f}\n",
               hv_mpi_size(), phi->n[0], phi->n[1], phi->n[2], phi->h, j->nfields, es->solves,
               es->levels, es->t_total, hv_now() - j->t_start);
    else
        printf("{\"command\":\"extend\",\"path\":\"dense\",\"grid\":[%d,%d,%d],\"h\":%g,"
               "\"fields\":%d,\"solves\":%d,"
               "\"levels\":%d,\"source_cells\":%zu,\"cp_cells\":%zu,\"ratio_cells\":%zu,"
               "\"weak_cells\":%zu,\"extend_seconds\":%.3f,\"seconds\":%.3f}\n",
               phi->n[0], phi->n[1], phi->n[2], phi->h, j->nfields, es->solves, es->levels,
               es->source_cells, es->cp_cells, es->ratio_cells, es->weak_cells, es->t_total,
               hv_now() - j->t_start);
}

/* A rank other than 0 under mpirun with --backend petsc: its box of rank 0's
 * block (which is the block), and its part of the HDF5 file. */
static int other_rank(const extend_job *j)
{
    hv_extend_field ef[MAX_FIELDS];
    hv_extend_stats es;
    const int n1[3] = {1, 1, 1};
    fields_without_arrays(j, ef);
    hv_status st = hv_petsc_extend_block(3, n1, 1, &j->o, NULL, j->nfields, ef, &es);
    if (st)
        return cli_fail(CMD, j->in, st);
    if (j->h5 && (st = write_dense_h5(j, NULL, ef)))
        return cli_fail(CMD, j->out, st);
    return 0;
}

/* The dense block ro: read, extended, written. --backend petsc: the block
 * is read by rank 0, extended on the ranks' boxes and written by rank 0. */
static int extend_dense(const extend_job *j, const hv_vdb_read_opts *ro)
{
    const int spread = j->o.backend == HV_BACKEND_PETSC;
    if (spread && hv_mpi_rank() != 0)
        return other_rank(j);
    dense_run r;
    memset(&r, 0, sizeof r);
    int rc = read_dense(j, ro, &r);
    if (rc && spread) { /* the other ranks wait in hv_petsc_extend_block: release them */
        hv_extend_field none[MAX_FIELDS];
        const int n1[3] = {1, 1, 1};
        fields_without_arrays(j, none);
        hv_petsc_extend_block(3, n1, 1, &j->o, NULL, j->nfields, none, &r.es);
    }
    if (!rc)
        rc = extend_dense_block(j, spread, &r);
    if (!rc)
        rc = write_dense(j, &r);
    if (!rc && cli_verbose >= 0)
        report_dense(j, &r, spread);
    dense_free(&r);
    return rc;
}

/* ---- the command ---- */

static void help(void) { usage(stdout); }

/* Reads the command line into j: -1 to go on, else the exit code. */
static int parse_args(int argc, char **argv, extend_job *j)
{
    hv_extend_opts *o = &j->o;
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "IN.vdb", .kind = CLI_WORDS, .files = ".vdb"},
        CLI_ROW_DENSE(&j->dense),
        {.names = "--plain", .kind = CLI_FLAG, .dst = &o->closest_point, .val = 0},
        {.names = "--levelset", .kind = CLI_STR, .dst = &j->ls},
        {.names = "--field",
         .kind = CLI_LIST,
         .dst = j->fields,
         .val = MAX_FIELDS,
         .given = &j->nfields},
        CLI_ROW_OUTPUT(&j->out, ".vdb .h5"),
        CLI_ROW_BAND("--band", &o->band),
        CLI_ROW_T_SCALE(&o->t_scale),
        CLI_ROW_BAND("--out-band", &o->out_band),
        CLI_ROW_BACKEND(&o->backend, CLI_BACKENDS_ALL),
        CLI_ROW_THREADS(&j->threads),
        {.names = NULL},
    };
    int prc = cli_parse(CMD, argc, argv, opts, "input file", &j->in, help);
    if (prc >= 0)
        return prc;
    if (!j->in)
        return cli_usage_error(CMD, "an input IN.vdb is required");
    if (!j->ls)
        return cli_usage_error(CMD, "--levelset NAME is required");
    if (!j->nfields)
        return cli_usage_error(CMD, "give at least one --field NAME");
    if (!j->out)
        return cli_usage_error(CMD, "-o OUT.vdb is required");
    if (cli_check_ext(CMD, "-o", j->out, ".vdb .h5"))
        return HV_EXIT_USAGE;
    for (int q = 0; q < j->nfields; q++)
        if (!strcmp(j->fields[q], j->ls))
            return cli_usage_error(CMD, "--field '%s' is the level set", j->ls);
    int is_h5;
    if (cli_h5_output(CMD, j->out, &is_h5))
        return HV_EXIT_USAGE;
    j->h5 = is_h5 ? j->out : NULL;
    if (cli_check_outputs(CMD, &j->out, 1, &j->in, 1))
        return HV_EXIT_FAIL;
    return -1;
}

/* Whether the level set and each field exist with values the extension
 * takes and uniform transforms; names every problem, then lists the grids. */
static int check_grids(const extend_job *j, const char *const *names)
{
    int missing = 0;
    for (int q = 0; q <= j->nfields; q++) {
        const hv_vdb_grid_info *gi = find_grid(j->info, j->count, names[q]);
        if (!gi) {
            fprintf(stderr, "heatvox extend: %s: no grid named '%s' (%s)\n", j->in, names[q],
                    q ? "--field" : "--levelset");
            missing = 1;
        } else if (q == 0 ? !is_scalar(gi->value_type)
                          : !is_scalar(gi->value_type) && !is_vector(gi->value_type)) {
            fprintf(stderr, "heatvox extend: %s: grid '%s' holds %s values; %s\n", j->in, names[q],
                    gi->value_type,
                    q ? "fields must be float, double, vec3s or vec3d"
                      : "the level set must be float or double");
            missing = 1;
        } else if (!gi->uniform) {
            fprintf(stderr,
                    "heatvox extend: %s: grid '%s' has a non-uniform or rotated transform\n", j->in,
                    names[q]);
            missing = 1;
        }
    }
    if (missing) {
        list_grids(j->in, j->info, j->count);
        return HV_EXIT_FAIL;
    }
    const hv_vdb_grid_info *lsi = find_grid(j->info, j->count, j->ls);
    if (lsi->grid_class != HV_VDB_LEVEL_SET && cli_verbose >= 0)
        fprintf(stderr, "heatvox extend: warning: '%s' has class '%s', read as a signed distance\n",
                j->ls, class_name(lsi->grid_class));
    return 0;
}

int cmd_extend(int argc, char **argv)
{
    extend_job j;
    memset(&j, 0, sizeof j);
    hv_extend_opts_default(&j.o);
    int rc = parse_args(argc, argv, &j);
    if (rc >= 0)
        return rc;
    hv_set_threads(j.threads);
    j.t_start = hv_now();

    /* What the file holds. */
    static hv_vdb_grid_info info[MAX_GRIDS];
    hv_status st = hv_vdb_list(j.in, info, MAX_GRIDS, &j.count);
    if (st)
        return cli_fail(CMD, j.in, st);
    j.info = info;
    const char *names[MAX_FIELDS + 1];
    names[0] = j.ls;
    for (int q = 0; q < j.nfields; q++)
        names[q + 1] = j.fields[q];
    if ((rc = check_grids(&j, names)))
        return rc;

    /* One block for all: transforms must agree (the shim names the grids that differ). */
    hv_vdb_read_opts ro = {1, {0, 0, 0}, {0, 0, 0}};
    if ((st = hv_vdb_common_box(j.in, names, (size_t)j.nfields + 1, ro.box_lo, ro.box_hi)))
        return cli_fail(CMD, j.in, st);
    const int level_set = find_grid(info, j.count, j.ls)->grid_class == HV_VDB_LEVEL_SET;
    if (!j.dense && !j.h5 && level_set &&
        (j.o.backend == HV_BACKEND_AUTO || j.o.backend == HV_BACKEND_MG ||
         j.o.backend == HV_BACKEND_OPENCL))
        return extend_tiles(&j, ro.box_lo, ro.box_hi);
    return extend_dense(&j, &ro);
}
