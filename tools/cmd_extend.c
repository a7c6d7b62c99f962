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
            "come back sparse, active there. Other classes, and --dense, take the dense\n"
            "block, where fields come back fully active. All transforms must match.\n"
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

/* The level set and the fields as tiles of the block [lo, hi], extended on
 * them and written from them (hv_extend_tiles): no dense block. */
static int extend_tiles(const char *in, const char *out, const hv_vdb_grid_info *info, size_t count,
                        const char *ls, const char *const *fields, int nfields, const int lo[3],
                        const int hi[3], const hv_extend_opts *o, double t_start)
{
    hv_tiles *P = NULL, *fin[MAX_FIELDS][3];
    hv_extend_tiles_field tf[MAX_FIELDS];
    memset(fin, 0, sizeof fin);
    memset(tf, 0, sizeof tf);
    hv_extender *e = NULL;
    hv_vdb_writer *w = NULL;
    int rc = 0, cls;
    hv_status st;
    double t0 = hv_now();
    if ((st = hv_vdb_read_float_tiles(in, ls, lo, hi, &P, &cls))) {
        rc = cli_fail(CMD, in, st);
        goto done;
    }
    for (int q = 0; q < nfields; q++) {
        int ncomp = 0;
        if ((st = hv_vdb_read_tiles_like(in, fields[q], P, fin[q], &ncomp))) {
            rc = cli_fail(CMD, in, st);
            goto done;
        }
        const hv_vdb_grid_info *gi = find_grid(info, count, fields[q]);
        if (gi->grid_class == HV_VDB_STAGGERED && cli_verbose >= 0)
            fprintf(stderr,
                    "heatvox extend: warning: '%s' is staggered; its components are "
                    "extended as if they sat at voxel centres\n",
                    fields[q]);
        tf[q].ncomp = ncomp;
        for (int c = 0; c < ncomp; c++)
            tf[q].v[c] = fin[q][c];
    }
    const double t_read = hv_now() - t0;
    release_freed();
    cli_info("heatvox extend: block %d x %d x %d, h = %g, %d fields, narrow band in %zu tiles of "
             "8^3 (%zu active voxels); read %.2f s, peak %.0f MB\n",
             P->n[0], P->n[1], P->n[2], P->h, nfields, P->count, P->active, t_read,
             hv_peak_rss() / 1e6);
    t0 = hv_now();
    if ((st = hv_extender_create(&e, 3, P->n, P->h, NULL, o))) {
        rc = cli_fail(CMD, in, st);
        goto done;
    }
    const double t_setup = hv_now() - t0;
    hv_extend_stats es;
    if ((st = hv_extend_tiles(e, P, nfields, tf, &es))) {
        rc = cli_fail(CMD, in, st);
        goto done;
    }
    cli_info("heatvox extend: %d levels; %zu source cells, %zu output cells (%zu at closest "
             "points), %zu cells in the first level's solve; work %.0f MB; set-up %.3f s, "
             "extension %.2f s (solves %.2f, evaluation %.2f), peak %.0f MB\n",
             es.levels, es.source_cells, es.cp_cells + es.ratio_cells, es.cp_cells, es.solve_cells,
             es.work_bytes / 1e6, t_setup, es.t_total, es.t_solve, es.t_eval, hv_peak_rss() / 1e6);
    if (es.weak_cells && cli_verbose >= 0)
        fprintf(stderr,
                "heatvox extend: warning: %zu voxels are far beyond the diffusion's reach; "
                "their values are unreliable\n",
                es.weak_cells);
    release_freed();
    /* Output: the fields, sparse, with names and classes, and the level set
     * (band = its background, the largest |phi| of the tiles); each set of
     * tiles is freed once the writer holds its copy. */
    double bg = 0;
    for (size_t c = 0; c < P->count * (size_t)(HV_TILE * HV_TILE * HV_TILE); c++)
        bg = fmax(bg, fabs(P->v[c]));
    double band = bg / P->h;
    if (!(band >= 1))
        band = 1;
    t0 = hv_now();
    const hv_vdb_grid_info *lsi = find_grid(info, count, ls);
    st = hv_vdb_writer_create(&w);
    if (!st)
        st = hv_vdb_writer_set_index_origin(w, lsi->index0_world);
    for (int q = 0; q < nfields && !st; q++) {
        const hv_vdb_grid_info *gi = find_grid(info, count, fields[q]);
        hv_tiles *const *t = fin[q];
        st = tf[q].ncomp == 3 ? hv_vdb_writer_add_vec3_tiles(w, t[0], t[1], t[2], fields[q])
                              : hv_vdb_writer_add_float_tiles(w, t[0], fields[q]);
        if (!st && gi->grid_class != HV_VDB_UNKNOWN)
            st = hv_vdb_writer_set_grid_meta(w, fields[q], "class", class_name(gi->grid_class));
        for (int c = 0; c < 3; c++)
            hv_tiles_destroy(&fin[q][c]);
    }
    const int n[3] = {P->n[0], P->n[1], P->n[2]};
    const double h = P->h;
    const size_t ntiles = P->count, nactive = P->active;
    if (!st)
        st = hv_vdb_writer_add_levelset_tiles(w, P, ls, band);
    hv_tiles_destroy(&P);
    char buf[512];
    snprintf(buf, sizeof buf, "heatvox extend: levelset %s, band %g, t_scale %g, narrow band%s, %s",
             ls, o->band, o->t_scale, o->out_band > 0 ? " (out-band)" : "",
             o->closest_point ? "closest point" : "plain");
    if (!st)
        st = hv_vdb_writer_set_meta(w, "heatvox_extend", buf);
    if (!st)
        st = hv_vdb_writer_write(w, out);
    if (st) {
        rc = cli_fail(CMD, out, st);
        goto done;
    }
    cli_info("heatvox extend: wrote %s in %.2f s, peak %.0f MB\n", out, hv_now() - t0,
             hv_peak_rss() / 1e6);
    if (cli_verbose >= 0)
        printf("{\"command\":\"extend\",\"path\":\"tiles\",\"grid\":[%d,%d,%d],\"h\":%g,"
               "\"fields\":%d,\"tiles\":%zu,\"active_voxels\":%zu,\"solves\":%d,\"levels\":%d,"
               "\"source_cells\":%zu,\"cp_cells\":%zu,\"ratio_cells\":%zu,\"weak_cells\":%zu,"
               "\"solve_cells\":%zu,\"work_mb\":%.1f,\"setup_seconds\":%.4f,"
               "\"extend_seconds\":%.3f,\"seconds\":%.3f,\"peak_rss_mb\":%.1f}\n",
               n[0], n[1], n[2], h, nfields, ntiles, nactive, es.solves, es.levels, es.source_cells,
               es.cp_cells, es.ratio_cells, es.weak_cells, es.solve_cells, es.work_bytes / 1e6,
               t_setup, es.t_total, hv_now() - t_start, hv_peak_rss() / 1e6);
done:
    hv_vdb_writer_destroy(&w);
    hv_extender_destroy(&e);
    hv_tiles_destroy(&P);
    for (int q = 0; q < MAX_FIELDS; q++)
        for (int c = 0; c < 3; c++)
            hv_tiles_destroy(&fin[q][c]);
    return rc;
}

static void help(void) { usage(stdout); }

int cmd_extend(int argc, char **argv)
{
    const char *in = NULL, *out = NULL, *ls = NULL, *fields[MAX_FIELDS];
    int nfields = 0, threads = 0, dense_flag = 0;
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    const cli_opt opts[] = {
        {.names = "-q|-v", .kind = CLI_IGNORE},
        {.names = "--dense", .kind = CLI_FLAG, .dst = &dense_flag, .val = 1},
        {.names = "--plain", .kind = CLI_FLAG, .dst = &o.closest_point, .val = 0},
        {.names = "--levelset", .kind = CLI_STR, .dst = &ls},
        {.names = "--field", .kind = CLI_LIST, .dst = fields, .val = MAX_FIELDS, .given = &nfields},
        {.names = "-o|--output", .kind = CLI_STR, .dst = &out},
        {.names = "--band",
         .kind = CLI_DOUBLE,
         .dst = &o.band,
         .max = INFINITY,
         .flags = CLI_ABOVE,
         .needs = "a positive number of voxels"},
        {.names = "--t-scale",
         .kind = CLI_DOUBLE,
         .dst = &o.t_scale,
         .max = INFINITY,
         .flags = CLI_ABOVE,
         .needs = "a positive number"},
        {.names = "--out-band",
         .kind = CLI_DOUBLE,
         .dst = &o.out_band,
         .max = INFINITY,
         .flags = CLI_ABOVE,
         .needs = "a positive number of voxels"},
        {.names = "--backend", .kind = CLI_BACKEND, .dst = &o.backend, .val = CLI_BACKENDS_ALL},
        {.names = "--threads", .kind = CLI_THREADS, .dst = &threads},
        {.names = NULL},
    };
    int prc = cli_parse(CMD, argc, argv, opts, "input file", &in, help);
    if (prc >= 0)
        return prc;
    if (!in)
        return cli_usage_error(CMD, "an input IN.vdb is required");
    if (!ls)
        return cli_usage_error(CMD, "--levelset NAME is required");
    if (!nfields)
        return cli_usage_error(CMD, "give at least one --field NAME");
    if (!out)
        return cli_usage_error(CMD, "-o OUT.vdb is required");
    if (cli_check_ext(CMD, "-o", out, ".vdb .h5"))
        return HV_EXIT_USAGE;
    for (int q = 0; q < nfields; q++)
        if (!strcmp(fields[q], ls))
            return cli_usage_error(CMD, "--field '%s' is the level set", ls);
    int is_h5;
    if (cli_h5_output(CMD, out, &is_h5))
        return HV_EXIT_USAGE;
    const char *h5 = is_h5 ? out : NULL;
    if (cli_check_outputs(CMD, &out, 1, &in, 1))
        return HV_EXIT_FAIL;
    hv_set_threads(threads);
    double t_start = hv_now();

    /* What the file holds. */
    static hv_vdb_grid_info info[MAX_GRIDS];
    size_t count = 0;
    hv_status st = hv_vdb_list(in, info, MAX_GRIDS, &count);
    if (st)
        return cli_fail(CMD, in, st);
    const char *names[MAX_FIELDS + 1];
    names[0] = ls;
    for (int q = 0; q < nfields; q++)
        names[q + 1] = fields[q];
    int missing = 0;
    for (int q = 0; q <= nfields; q++) {
        const hv_vdb_grid_info *gi = find_grid(info, count, names[q]);
        if (!gi) {
            fprintf(stderr, "heatvox extend: %s: no grid named '%s' (%s)\n", in, names[q],
                    q ? "--field" : "--levelset");
            missing = 1;
        } else if (q == 0 ? !is_scalar(gi->value_type)
                          : !is_scalar(gi->value_type) && !is_vector(gi->value_type)) {
            fprintf(stderr, "heatvox extend: %s: grid '%s' holds %s values; %s\n", in, names[q],
                    gi->value_type,
                    q ? "fields must be float, double, vec3s or vec3d"
                      : "the level set must be float or double");
            missing = 1;
        } else if (!gi->uniform) {
            fprintf(stderr,
                    "heatvox extend: %s: grid '%s' has a non-uniform or rotated transform\n", in,
                    names[q]);
            missing = 1;
        }
    }
    if (missing) {
        list_grids(in, info, count);
        return HV_EXIT_FAIL;
    }
    const hv_vdb_grid_info *lsi = find_grid(info, count, ls);
    if (lsi->grid_class != HV_VDB_LEVEL_SET && cli_verbose >= 0)
        fprintf(stderr, "heatvox extend: warning: '%s' has class '%s', read as a signed distance\n",
                ls, class_name(lsi->grid_class));

    /* One block for all: transforms must agree (the shim names the grids that differ). */
    hv_vdb_read_opts ro = {1, {0, 0, 0}, {0, 0, 0}};
    if ((st = hv_vdb_common_box(in, names, (size_t)nfields + 1, ro.box_lo, ro.box_hi)))
        return cli_fail(CMD, in, st);
    if (!dense_flag && !h5 && lsi->grid_class == HV_VDB_LEVEL_SET &&
        (o.backend == HV_BACKEND_AUTO || o.backend == HV_BACKEND_MG))
        return extend_tiles(in, out, info, count, ls, fields, nfields, ro.box_lo, ro.box_hi, &o,
                            t_start);
    hv_grid *phi = NULL;
    hv_grid *fin[MAX_FIELDS][3], *fout[MAX_FIELDS][3];
    memset(fin, 0, sizeof fin);
    memset(fout, 0, sizeof fout);
    hv_extend_field ef[MAX_FIELDS];
    hv_extender *e = NULL;
    hv_vdb_writer *w = NULL;
    int rc = 0, cls;
    /* --backend petsc: the block is read by rank 0, extended on the ranks'
     * boxes (hv_petsc_extend_block) and written by rank 0. */
    const int spread = o.backend == HV_BACKEND_PETSC;
    const int reader = !spread || hv_mpi_rank() == 0;
    hv_extend_stats es;
    if (!reader) {
        for (int q = 0; q < nfields; q++) {
            ef[q].ncomp = is_vector(find_grid(info, count, fields[q])->value_type) ? 3 : 1;
            for (int c = 0; c < 3; c++) {
                ef[q].in[c] = NULL;
                ef[q].out[c] = NULL;
            }
        }
        const int n1[3] = {1, 1, 1}; /* rank 0's block is the block */
        if ((st = hv_petsc_extend_block(3, n1, 1, &o, NULL, nfields, ef, &es))) {
            rc = cli_fail(CMD, in, st);
        } else if (h5) { /* with rank 0, which holds the result */
            h5_names hn;
            const int nh = h5_fields(&hn, ls, fields, nfields, ef);
            if ((st = hv_petsc_write_h5(out, nh, NULL, hn.p)))
                rc = cli_fail(CMD, out, st);
        }
        goto done;
    }
    if ((st = hv_vdb_read_float(in, ls, &ro, &phi, &cls))) {
        rc = cli_fail(CMD, in, st);
        goto read_failed;
    }
    for (int q = 0; q < nfields; q++) {
        const hv_vdb_grid_info *gi = find_grid(info, count, fields[q]);
        int vec = is_vector(gi->value_type);
        st = vec ? hv_vdb_read_vec3(in, fields[q], &ro, &fin[q][0], &fin[q][1], &fin[q][2])
                 : hv_vdb_read_float(in, fields[q], &ro, &fin[q][0], NULL);
        if (st) {
            rc = cli_fail(CMD, in, st);
            goto read_failed;
        }
        if (gi->grid_class == HV_VDB_STAGGERED && cli_verbose >= 0)
            fprintf(stderr,
                    "heatvox extend: warning: '%s' is staggered; its components are "
                    "extended as if they sat at voxel centres\n",
                    fields[q]);
        ef[q].ncomp = vec ? 3 : 1;
        for (int c = 0; c < 3; c++) {
            ef[q].in[c] = NULL;
            ef[q].out[c] = NULL;
        }
        for (int c = 0; c < ef[q].ncomp; c++) {
            if ((st = hv_grid_create(&fout[q][c], 3, phi->n, phi->h, phi->origin))) {
                rc = cli_fail(CMD, "allocating outputs", st);
                goto read_failed;
            }
            ef[q].in[c] = fin[q][c]->v;
            ef[q].out[c] = fout[q][c]->v;
        }
    }
    cli_info("heatvox extend: block %d x %d x %d, h = %g, %d fields\n", phi->n[0], phi->n[1],
             phi->n[2], phi->h, nfields);

    if (spread) {
        if ((st = hv_petsc_extend_block(3, phi->n, phi->h, &o, phi->v, nfields, ef, &es))) {
            rc = cli_fail(CMD, in, st);
            goto done;
        }
    } else if ((st = hv_extender_create(&e, 3, phi->n, phi->h, NULL, &o)) ||
               (st = hv_extend_many(e, phi->v, nfields, ef, &es))) {
        rc = cli_fail(CMD, in, st);
        goto done;
    }
    if (es.weak_cells && !spread && cli_verbose >= 0)
        fprintf(stderr,
                "heatvox extend: warning: %zu voxels are far beyond the diffusion's reach; "
                "their values are unreliable\n",
                es.weak_cells);

    /* Output: the level set (band = its background, the largest |phi| on the block)
     * and the fields, with names and classes. */
    double bg = 0;
    for (size_t c = 0; c < hv_grid_count(phi); c++)
        bg = fmax(bg, fabs(phi->v[c]));
    double band = bg / phi->h;
    if (!(band >= 1))
        band = 1;
    st = hv_vdb_writer_create(&w);
    /* Same transform and index coordinates as the input's level set. */
    if (!st)
        st = hv_vdb_writer_set_index_origin(w, lsi->index0_world);
    if (!st)
        st = hv_vdb_writer_add_levelset(w, phi, ls, band, 0);
    for (int q = 0; q < nfields && !st; q++) {
        const hv_vdb_grid_info *gi = find_grid(info, count, fields[q]);
        st = ef[q].ncomp == 3
                 ? hv_vdb_writer_add_vec3(w, fout[q][0], fout[q][1], fout[q][2], fields[q])
                 : hv_vdb_writer_add_float(w, fout[q][0], fields[q]);
        /* OpenVDB keeps a grid's class in its "class" metadata string. */
        if (!st && gi->grid_class != HV_VDB_UNKNOWN && gi->grid_class != HV_VDB_LEVEL_SET)
            st = hv_vdb_writer_set_grid_meta(w, fields[q], "class", class_name(gi->grid_class));
        if (!st && gi->grid_class == HV_VDB_LEVEL_SET)
            st = hv_vdb_writer_set_grid_meta(w, fields[q], "class", "level set");
    }
    char buf[512];
    snprintf(buf, sizeof buf, "heatvox extend: levelset %s, band %g, t_scale %g, %s, %s", ls,
             o.band, o.t_scale, o.out_band > 0 ? "out-band" : "dense",
             o.closest_point ? "closest point" : "plain");
    if (!st)
        st = hv_vdb_writer_set_meta(w, "heatvox_extend", buf);
    if (h5) {
        /* Collective: the ranks write rank 0's result together (petsc.h); a
         * rank 0 that failed passes no grids, which fails every rank. */
        const hv_grid *hg[1 + 3 * MAX_FIELDS];
        h5_names hn;
        const int nh = h5_fields(&hn, ls, fields, nfields, ef);
        hg[0] = phi;
        for (int q = 0, k = 1; q < nfields; q++)
            for (int c = 0; c < ef[q].ncomp; c++)
                hg[k++] = fout[q][c];
        const hv_status hs = hv_petsc_write_h5(out, nh, st ? NULL : hg, hn.p);
        if (!st)
            st = hs;
    } else if (!st && hv_mpi_rank() == 0) { /* under mpirun, rank 0 writes */
        st = hv_vdb_writer_write(w, out);
    }
    if (st) {
        rc = cli_fail(CMD, out, st);
        goto done;
    }
    if (cli_verbose >= 0 && spread) /* the cell counts would be rank 0's box's */
        printf("{\"command\":\"extend\",\"path\":\"dense-distributed\",\"ranks\":%d,"
               "\"grid\":[%d,%d,%d],\"h\":%g,\"fields\":%d,\"solves\":%d,\"levels\":%d,"
               "\"extend_seconds\":%.3f,\"seconds\":%.3f}\n",
               hv_mpi_size(), phi->n[0], phi->n[1], phi->n[2], phi->h, nfields, es.solves,
               es.levels, es.t_total, hv_now() - t_start);
    else if (cli_verbose >= 0)
        printf("{\"command\":\"extend\",\"path\":\"dense\",\"grid\":[%d,%d,%d],\"h\":%g,"
               "\"fields\":%d,\"solves\":%d,"
               "\"levels\":%d,\"source_cells\":%zu,\"cp_cells\":%zu,\"ratio_cells\":%zu,"
               "\"weak_cells\":%zu,\"extend_seconds\":%.3f,\"seconds\":%.3f}\n",
               phi->n[0], phi->n[1], phi->n[2], phi->h, nfields, es.solves, es.levels,
               es.source_cells, es.cp_cells, es.ratio_cells, es.weak_cells, es.t_total,
               hv_now() - t_start);
    goto done;
read_failed:
    if (spread) { /* the other ranks wait in hv_petsc_extend_block: release them */
        hv_extend_field none[MAX_FIELDS];
        const int n1[3] = {1, 1, 1};
        for (int q = 0; q < nfields; q++) {
            memset(&none[q], 0, sizeof none[q]);
            none[q].ncomp = is_vector(find_grid(info, count, fields[q])->value_type) ? 3 : 1;
        }
        hv_petsc_extend_block(3, n1, 1, &o, NULL, nfields, none, &es);
    }
done:
    hv_vdb_writer_destroy(&w);
    hv_extender_destroy(&e);
    hv_grid_destroy(&phi);
    for (int q = 0; q < MAX_FIELDS; q++)
        for (int c = 0; c < 3; c++) {
            hv_grid_destroy(&fin[q][c]);
            hv_grid_destroy(&fout[q][c]);
        }
    return rc;
}
