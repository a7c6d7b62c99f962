/* heatvox sdf: signed (or unsigned) distance volume of a triangle mesh, written
 * as an OpenVDB level set, a dense .npy array, and/or the zero level set as a
 * closed triangle mesh. */
#include "cli.h"

#include <errno.h>
#include <limits.h>
#include <libgen.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

static void help(void)
{
    printf("usage: heatvox sdf MESH [-o OUT.vdb] [--npy FILE] [--mesh-out OUT.obj|.ply|.stl]\n"
           "                   [options]\n"
           "\n"
           "Computes the signed distance field of a triangle mesh (OBJ, PLY, STL, OFF; glTF\n"
           "(.gltf, .glb), FBX, 3MF, COLLADA (.dae), DirectX (.x) through assimp) with\n"
           "the signed heat method on a regular grid, robust to holes, flipped faces,\n"
           "duplicated sheets, soups and self-intersections, and writes it as an OpenVDB\n"
           "level set (negative inside), a dense .npy array, and/or its zero level set as a\n"
           "closed, manifold, outward-oriented triangle mesh (at least one of the three).\n"
           "MESH may also be a point cloud (a scan): a text file .xyz, .pts or .xyzn with\n"
           "x y z nx ny nz or x y z per line, or a PLY file of vertices (with nx ny nz or\n"
           "without) and no faces. Its surface comes from the signed heat method with the\n"
           "points' normals (normals flipped on part of the cloud are outvoted) moved onto\n"
           "the points; a cloud without normals has them recovered first (--orient).\n"
           "Everything below applies to it as to a mesh (-v tells the points, their\n"
           "spacing, the orientation and how many normals were turned).\n"
           "Prints one summary line on stdout.\n"
           "\n"
           "grid (cell-centred; sample (i,j,k) at corner + (i+1/2, j+1/2, k+1/2) h):\n"
           "  --res N            cells along the longest axis of the padded box (default 128)\n"
           "  --voxel-size H     voxel size in mesh units (instead of --res)\n"
           "  --pad P            cells between the mesh bounds and the block boundary (default 4)\n"
           "  --bbox X0 Y0 Z0 X1 Y1 Z1\n"
           "                     outer boundary of the voxel block (with --res N: h = longest\n"
           "                     side / N); --pad is ignored\n"
           "  --units file|m     file (default): the file's coordinates, never rescaled; m:\n"
           "                     scaled to metres where the file states its unit (FBX's\n"
           "                     UnitScaleFactor), and then --voxel-size, --bbox, --offset\n"
           "                     and the output are metres\n"
           "output:\n"
           "  -o, --output FILE  the .vdb file\n"
           "  --band W           narrow band half width in voxels (default 3)\n"
           "  --dense            store every voxel of the block as active\n"
           "  A narrow band (-o without --dense, --npy, --mesh-out; a point cloud's own\n"
           "  surface as --mesh-out aside) is computed in 8^3 tiles near the surface,\n"
           "  never as the whole block: memory and time follow the\n"
           "  surface (--preview then computes its three slices alone). Its sign is the\n"
           "  winding number's (--sign heat, --heat, --unsigned and --no-repair take the\n"
           "  dense path).\n"
           "  --no-tiles         compute a narrow band on the dense block all the same\n"
           "                     (--unsigned always writes a dense float grid, class unknown)\n"
           "  --npy FILE         also write the dense field as a float32 .npy (z, y, x)\n"
           "  --preview FILE     also write a PNG of the middle x, y and z slices side by side\n"
           "                     (blue inside, red outside, black zero contour)\n"
           "  --name NAME        grid name in the .vdb (default \"sdf\")\n"
           "  --mesh-out FILE    also write the zero level set as a triangle mesh, OBJ, PLY\n"
           "                     (binary, double) or STL (binary) by the extension; closed at\n"
           "                     the walls of the block where the inside reaches them\n"
           "  --adaptivity A     with --mesh-out: 0 (default) one vertex per crossed voxel;\n"
           "                     up to 1: fewer, larger triangles where the surface is flat,\n"
           "                     none straying more than A/2 voxels from the zero set\n"
           "  Every output is written to a temporary name, and all are renamed together once\n"
           "  complete: when one fails, none is replaced.\n"
           "method:\n"
           "  --unsigned         unsigned distance to the mesh (no inside)\n"
           "  --heat             keep the heat method's own |phi| instead of the exact distance\n"
           "                     to the triangles (sign from the heat method either way)\n"
           "  --t-scale S        diffusion time t = (S h)^2 (default 1)\n"
           "  --heat-coarsen F   run the heat method (which then only decides the sign) on a\n"
           "                     grid F = 1..4 times coarser; default: 2 above 2^22 cells, else 1\n"
           "  --sign S           where the sign comes from: auto (default: the winding number\n"
           "                     of the repaired mesh when it stays open or the block cuts it,\n"
           "                     so that the answer does not depend on the block; the heat\n"
           "                     method otherwise), heat, or winding\n"
           "  --orient O         a point cloud's normals: auto (default: recovered when the\n"
           "                     file has none, else the file's), given, or recover (from\n"
           "                     the points alone, ignoring the file's normals)\n"
           "  --no-repair        skip mesh repair (weld, dedup, orientation, hole filling)\n"
           "  --domed-caps       close holes with caps that bulge like the wall around them\n"
           "                     (default: planar caps)\n"
           "shape (world units, applied in this order; with -o the band moves along):\n"
           "  --close R          grow by R, then shrink by R: fills gaps and cracks narrower\n"
           "                     than 2R (computes the dense block)\n"
           "  --open R           shrink by R, then grow by R: removes parts thinner than 2R\n"
           "                     (computes the dense block)\n"
           "  --offset D         move the surface out by D (in when D < 0)\n"
           "  --shell T          keep a wall of thickness T inside the surface (for printing)\n"
           "  The block is placed around the mesh grown by what --offset and --close add.\n"
           "  --backend B        linear solver: auto, mg, fftw, opencl (default auto)\n"
           "  --threads N        worker threads (default: all cores)\n"
           "  -v                 progress and details on stderr\n"
           "  -q                 no summary line\n"
           "  --help             this text\n"
           "\n"
           "exit: 0 success, 1 failure (unreadable mesh, bad geometry, I/O), 2 usage error\n");
}

/* One line rewritten in place on a terminal, one line per stage otherwise,
 * with the peak memory so far: a stage's own peak shows at the next line. */
static int on_progress(double fraction, const char *stage, void *user)
{
    int tty = *(const int *)user;
    fprintf(stderr, "%sheatvox sdf: %-10s %3d%%  peak %6.0f MB%s", tty ? "\r" : "", stage,
            (int)(100 * fraction + 0.5), hv_peak_rss() / 1e6, tty && fraction < 1 ? "" : "\n");
    fflush(stderr);
    return 0;
}

/* A block too large for this machine is the resolution asked for, not the
 * mesh: a usage error that names the option. */
static int too_large(const hv_sdf_opts *o, int have_h, int tiles, const char *out)
{
    char opt[64];
    if (have_h)
        snprintf(opt, sizeof opt, "--voxel-size %g", o->voxel_size);
    else
        snprintf(opt, sizeof opt, "--res %d", o->res);
    const char *msg = hv_last_error();
    fprintf(stderr, "heatvox sdf: %s: %s\n", opt, strncmp(msg, "sdf: ", 5) ? msg : msg + 5);
    if (!tiles && out)
        fprintf(stderr, "heatvox sdf: a narrow band alone (-o without --dense, --npy or "
                        "--mesh-out) is computed near the surface only and needs far less\n");
    fprintf(stderr, "(lower --res or raise --voxel-size; see heatvox sdf --help)\n");
    return HV_EXIT_USAGE;
}

/* The extensions hv_mesh_write knows: .obj, .ply, .stl, any case. */
static int mesh_ext_ok(const char *path)
{
    const char *slash = strrchr(path, '/'), *dot = strrchr(path, '.');
    if (!dot || (slash && dot < slash))
        return 0;
    return !strcasecmp(dot, ".obj") || !strcasecmp(dot, ".ply") || !strcasecmp(dot, ".stl");
}

/* Writes m to path (a staged temporary) in the format final's extension names. */
static hv_status write_mesh_as(const hv_mesh *m, const char *final, const char *path)
{
    const char *dot = strrchr(final, '.');
    if (!strcasecmp(dot, ".ply"))
        return hv_mesh_write_ply(m, path);
    if (!strcasecmp(dot, ".stl"))
        return hv_mesh_write_stl(m, path);
    return hv_mesh_write_obj(m, path);
}

/* The preview of a run in tiles, without its dense block: each middle slice
 * computed as a block one cell thick on the run's lattice. Such a block cuts
 * the mesh, so its sign is the winding number's (HV_SDF_SIGN_AUTO), as the
 * tiles' is: the slices show what the dense block would hold there. */
static hv_status preview_slices(const hv_mesh *m, const hv_sdf_opts *o, const hv_sdf_stats *S,
                                const char *path)
{
    hv_grid *s[3] = {NULL, NULL, NULL};
    hv_status st = HV_OK;
    for (int a = 0; a < 3 && !st; a++) {
        hv_sdf_opts so = *o;
        so.use_bbox = 1;
        so.voxel_size = S->h;
        so.band_only = 0;
        for (int b = 0; b < 3; b++) {
            so.bbox[b] = S->origin[b];
            so.bbox[3 + b] = S->origin[b] + S->n[b] * S->h;
        }
        so.bbox[a] = S->origin[a] + (S->n[a] / 2) * S->h;
        so.bbox[3 + a] = so.bbox[a] + S->h;
        hv_grid *g = NULL;
        if (!(st = hv_sdf_compute(m, &so, &g, NULL)))
            st = hv_grid_slice(g, a, 0, &s[a]);
        hv_grid_destroy(&g);
    }
    if (!st)
        st = hv_png_write_slices(path, (const hv_grid *const *)s, 3, 0);
    for (int a = 0; a < 3; a++)
        hv_grid_destroy(&s[a]);
    return st;
}

/* Fails early, before any computing, when the output cannot be created. */
static int check_writable(const char *path)
{
    char *copy = strdup(path);
    if (!copy)
        return -1;
    const char *dir = dirname(copy);
    int ok = access(dir, W_OK | X_OK) == 0;
    int err = errno;
    if (ok && access(path, F_OK) == 0 && access(path, W_OK) != 0) {
        ok = 0;
        err = errno;
    }
    if (!ok)
        fprintf(stderr, "heatvox sdf: cannot write %s: %s\n", path, strerror(err));
    free(copy);
    return ok ? 0 : -1;
}

/* " close=R open=R offset=D shell=T" for the output's parameters, or "". */
static const char *morph_text(const hv_sdf_opts *o)
{
    static char buf[160];
    buf[0] = 0;
    if (o->close > 0 || o->open > 0 || o->offset != 0 || o->shell > 0)
        snprintf(buf, sizeof buf, " close=%.9g open=%.9g offset=%.9g shell=%.9g", o->close, o->open,
                 o->offset, o->shell);
    return buf;
}

/* The command line of heatvox sdf. */
typedef struct sdf_args {
    const char *mesh_path, *out, *npy, *name, *preview, *mesh_out;
    double band, adaptivity;
    int have_adaptivity, dense, have_res, have_h, have_bbox, threads, no_tiles, units;
    hv_sdf_opts o;
} sdf_args;

/* The checks that involve several options. */
static int check_args(sdf_args *A)
{
    hv_sdf_opts *o = &A->o;
    for (int k = 0; A->have_bbox && k < 3; k++)
        if (!(o->bbox[3 + k] > o->bbox[k]))
            return cli_usage_error("sdf", "--bbox: %c1 (%g) must exceed %c0 (%g)", "XYZ"[k],
                                   o -> bbox[3 + k], "XYZ"[k], o -> bbox[k]);
    o->use_bbox = A->have_bbox;
    if (!A->mesh_path)
        return cli_usage_error("sdf", "no mesh given");
    if (!A->out && !A->npy && !A->mesh_out)
        return cli_usage_error("sdf",
                               "no output given (-o OUT.vdb, --npy FILE or --mesh-out FILE)");
    if (cli_check_ext("sdf", "-o", A->out, ".vdb") ||
        cli_check_ext("sdf", "--npy", A->npy, ".npy") ||
        cli_check_ext("sdf", "--preview", A->preview, ".png"))
        return HV_EXIT_USAGE;
    if (A->mesh_out && o->unsigned_distance)
        return cli_usage_error("sdf", "--mesh-out needs a signed distance: an unsigned one has no "
                                      "zero level set (drop --unsigned)");
    if (A->mesh_out && !mesh_ext_ok(A->mesh_out))
        return cli_usage_error("sdf", "--mesh-out %s: the extension must be .obj, .ply or .stl",
                               A->mesh_out);
    if (A->have_adaptivity && !A->mesh_out)
        return cli_usage_error("sdf", "--adaptivity applies to --mesh-out, which is not given");
    if (A->have_res && A->have_h)
        return cli_usage_error("sdf", "give either --res or --voxel-size, not both");
    if ((o->close > 0 || o->open > 0 || o->offset != 0 || o->shell > 0) && o->unsigned_distance)
        return cli_usage_error("sdf", "--close, --open, --offset and --shell need a signed "
                                      "distance (drop --unsigned)");
    return -1;
}

/* argv into *A: -1, or the exit code (help, usage error). */
static int parse_args(int argc, char **argv, sdf_args *A)
{
    memset(A, 0, sizeof *A);
    A->name = "sdf";
    A->band = 3.0;
    hv_sdf_opts *o = &A->o;
    hv_sdf_opts_default(o);
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "MESH", .kind = CLI_WORDS, .files = CLI_FILES_MESH},
        CLI_ROW_OUTPUT(&A->out, ".vdb"),
        {.names = "--npy", .kind = CLI_STR, .dst = &A->npy, .files = ".npy"},
        {.names = "--preview", .kind = CLI_STR, .dst = &A->preview, .files = ".png"},
        {.names = "--mesh-out", .kind = CLI_STR, .dst = &A->mesh_out, .files = ".obj .ply .stl"},
        {.names = "--adaptivity",
         .kind = CLI_DOUBLE,
         .dst = &A->adaptivity,
         .max = 1,
         .needs = "a number in [0, 1]",
         .given = &A->have_adaptivity},
        {.names = "--name", .kind = CLI_STR, .dst = &A->name, .min = 1},
        CLI_ROW_RES(&o->res, 1, &A->have_res),
        CLI_ROW_VOXEL_SIZE(&o->voxel_size, &A->have_h),
        CLI_ROW_PAD(&o->pad),
        {.names = "--bbox",
         .kind = CLI_DOUBLES,
         .dst = o->bbox,
         .val = 6,
         .needs = "6 finite numbers",
         .given = &A->have_bbox},
        CLI_ROW_BAND("--band", &A->band),
        CLI_ROW_DENSE(&A->dense),
        {.names = "--no-tiles", .kind = CLI_FLAG, .dst = &A->no_tiles, .val = 1},
        {.names = "--unsigned", .kind = CLI_FLAG, .dst = &o->unsigned_distance, .val = 1},
        {.names = "--heat", .kind = CLI_FLAG, .dst = &o->magnitude, .val = HV_SDF_HEAT},
        CLI_ROW_T_SCALE(&o->t_scale),
        {.names = "--heat-coarsen",
         .kind = CLI_INT,
         .dst = &o->heat_coarsen,
         .min = 1,
         .max = 4,
         .needs = "an integer in 1..4"},
        CLI_ROW_SIGN(&o->sign),
        {.names = "--orient",
         .kind = CLI_CHOICE,
         .dst = &o->orient,
         .choices = "auto|given|recover",
         .needs = "auto, given or recover"},
        CLI_ROW_NO_REPAIR(&o->repair),
        CLI_ROW_UNITS(&A->units),
        {.names = "--domed-caps",
         .kind = CLI_OR,
         .dst = &o->repair,
         .val = HV_SDF_REPAIR_DOMED_CAPS},
        CLI_ROW_BACKEND(&o->backend, CLI_BACKENDS_LOCAL),
        CLI_ROW_THREADS(&A->threads),
        {.names = "--close",
         .kind = CLI_DOUBLE,
         .dst = &o->close,
         .max = INFINITY,
         .flags = CLI_ABOVE,
         .needs = "a positive distance"},
        {.names = "--open",
         .kind = CLI_DOUBLE,
         .dst = &o->open,
         .max = INFINITY,
         .flags = CLI_ABOVE,
         .needs = "a positive distance"},
        {.names = "--offset",
         .kind = CLI_DOUBLE,
         .dst = &o->offset,
         .min = -INFINITY,
         .max = INFINITY,
         .needs = "a distance"},
        {.names = "--shell",
         .kind = CLI_DOUBLE,
         .dst = &o->shell,
         .max = INFINITY,
         .flags = CLI_ABOVE,
         .needs = "a positive thickness"},
        {.names = NULL},
    };
    int rc = cli_parse("sdf", argc, argv, opts, "mesh", &A->mesh_path, help);
    if (rc >= 0 || (rc = check_args(A)) >= 0)
        return rc;
    if (!A->have_h)
        o->voxel_size = 0;
    o->threads = A->threads;
    /* A narrow-band level set alone needs exact values only in its band (the
     * rest is the background with the heat method's sign): skip the sweeps. */
    if (!A->dense && !A->npy && !A->preview && !o->unsigned_distance &&
        o->magnitude == HV_SDF_EXACT)
        o->band_only = A->band;
    return -1;
}

/* The closing line on stdout (and with -v the solver's details on stderr);
 * t: seconds to read, to make the mesh, to write, in all. */
static void report(const sdf_args *A, const hv_sdf_stats *Sp, const hv_vdb_sink_stats *vs,
                   int tiles, size_t tris, size_t mesh_tris, const double t[4])
{
    const hv_sdf_stats S = *Sp;
    const char *mesh_path = A->mesh_path, *out = A->out, *npy = A->npy, *mesh_out = A->mesh_out;
    const double band = A->band, adaptivity = A->adaptivity;
    const double t_read = t[0], t_mesh = t[1], tw = t[2], total = t[3];
    const hv_sdf_repair_report *R = &S.repair;
    char mesh_note[4200] = "";
    if (cli_verbose >= 1 && tiles)
        fprintf(stderr,
                "heatvox sdf: %zu triangles in, %zu after repair; narrow band of %g voxels in "
                "%zu tiles of 8^3 (%zu active voxels, %zu rasterized); sign from %s: %zu cells "
                "by pseudonormals, %zu winding-number evaluations (%.2f s%s)\n",
                tris, R->triangles_out, band, S.tiles, S.active_voxels, S.band_cells,
                cli_sign_name(S.sign), S.near_sign_cells, S.winding_evals, S.t_sign,
                S.backend == HV_BACKEND_OPENCL ? ", on the device" : "");
    if (cli_verbose >= 1 && tiles)
        fprintf(stderr,
                "heatvox sdf: the band went into the .vdb's tree as it was computed: %zu "
                "batches, at most %zu tiles in flight (%.0f MB); tree of %zu leaves, %.0f MB, "
                "%zu of them packed into %.0f MB of compressed values (allowed for: %.0f MB, "
                "%zu tiles near enough); leaves built and packed in %.2f s, flood fill %.2f s; "
                "file written in %.2f s\n",
                vs->batches, S.tiles_in_flight,
                S.tiles_in_flight * (HV_TILE * HV_TILE * HV_TILE * 4.0 + 8 * 8 + 12) / 1e6,
                vs->leaves, vs->tree_bytes / 1e6, vs->packed_leaves, vs->packed_bytes / 1e6,
                vs->tree_bytes_bound / 1e6, S.tiles_bound, vs->t_leaves, vs->t_fill, t[2]);
    else if (cli_verbose >= 1)
        fprintf(stderr,
                "heatvox sdf: %zu triangles in, %zu after repair; solver %s: diffuse %d iterations "
                "(relres %.1e), poisson %d (relres %.1e); surface rms %.3f -> %.3f voxels; "
                "%zu dead faces; sign from %s (%zu winding-number evaluations, %.2f s); %zu "
                "cells signed by pseudonormals (%zu changed)\n",
                tris, R->triangles_out, hv_backend_name(S.backend), S.diffuse_iterations,
                S.diffuse_relres, S.poisson_iterations, S.poisson_relres, S.surface_rms_before,
                S.surface_rms_after, S.dead_faces, cli_sign_name(S.sign), S.winding_evals, S.t_sign,
                S.near_sign_cells, S.near_sign_changed);
    if (cli_verbose >= 0 && mesh_out)
        snprintf(mesh_note, sizeof mesh_note, " | mesh %s: %zu triangles, adaptivity %g", mesh_out,
                 mesh_tris, adaptivity);
    if (cli_verbose >= 0)
        printf(
            "sdf %s -> %s: grid %dx%dx%d h=%.6g | s: read %.2f repair %.2f splat %.2f diffuse %.2f "
            "normalize %.2f poisson %.2f shift %.2f redistance %.2f mesh %.2f write %.2f total "
            "%.2f | peak %.0f MB | defects: tris %zu->%zu welded %zu degenerate %zu duplicate %zu "
            "flipped %zu holes %zu/%zu filled, boundary %zu nonmanifold %zu inconsistent "
            "%zu->%zu%s\n",
            mesh_path,
            out   ? out
            : npy ? npy
                  : mesh_out,
            S.n[0], S.n[1], S.n[2], S.h, t_read, S.t_repair, S.t_splat, S.t_diffuse, S.t_normalize,
            S.t_poisson, S.t_shift, S.t_redistance, t_mesh, tw, total, hv_peak_rss() / 1e6,
            R->triangles_in, R->triangles_out, R->vertices_welded, R->degenerate_removed,
            R->duplicates_removed, R->faces_flipped, R->holes_filled,
            R->holes_filled + R->holes_left_open, R->boundary_edges, R->nonmanifold_edges,
            R->inconsistent_before, R->inconsistent_after, mesh_note);
}

/* What a run made: the dense field, or (in tiles) the .vdb writer that took
 * the band as it was computed, with what that cost. */
typedef struct {
    hv_grid *g;
    hv_vdb_writer *w;
    hv_vdb_sink_stats vs;
} sdf_result;

/* The field of m: in tiles streamed into a .vdb writer's level set (so that
 * the band is never held twice), else the dense grid. */
static hv_status compute(const sdf_args *A, const hv_mesh *m, const hv_sdf_opts *o, int tiles,
                         sdf_result *r, hv_sdf_stats *S)
{
    if (!tiles)
        return hv_sdf_compute(m, o, &r->g, S);
    hv_tiles_sink sink;
    hv_status st;
    if ((st = hv_vdb_writer_create(&r->w)) ||
        (st = hv_vdb_writer_levelset_sink(r->w, A->name, A->band, &r->vs, &sink)))
        return st;
    return hv_sdf_stream_tiles(m, o, A->band, &sink, S);
}

/* The .vdb into tmp: the writer's level set from tiles, else the dense
 * grid's (an unsigned distance is no level set: a plain float grid). */
static hv_status write_vdb(const sdf_args *A, sdf_result *r, const char *params, const char *tmp)
{
    hv_status st = HV_OK;
    if (!r->w && !(st = hv_vdb_writer_create(&r->w)))
        st = A->o.unsigned_distance
                 ? hv_vdb_writer_add_float(r->w, r->g, A->name)
                 : hv_vdb_writer_add_levelset(r->w, r->g, A->name, A->band, A->dense);
    if (st || (st = hv_vdb_writer_set_meta(r->w, "source", A->mesh_path)) ||
        (st = hv_vdb_writer_set_meta(r->w, "heatvox_version", hv_version())) ||
        (st = hv_vdb_writer_set_meta(r->w, "heatvox_command", "sdf")) ||
        (st = hv_vdb_writer_set_meta(r->w, "parameters", params)))
        return st;
    return hv_vdb_writer_write(r->w, tmp);
}

int cmd_sdf(int argc, char **argv)
{
    sdf_args A;
    int rc = parse_args(argc, argv, &A);
    if (rc >= 0)
        return rc;
    const char *mesh_path = A.mesh_path, *out = A.out, *npy = A.npy;
    const char *preview = A.preview, *mesh_out = A.mesh_out;
    const double band = A.band, adaptivity = A.adaptivity;
    const int dense = A.dense, have_h = A.have_h, no_tiles = A.no_tiles;
    hv_sdf_opts o = A.o;
    const char *outs[] = {out, npy, preview, mesh_out};
    if (cli_check_outputs("sdf", outs, 4, &mesh_path, 1))
        return HV_EXIT_FAIL;
    for (int k = 0; k < 4; k++)
        if (outs[k] && check_writable(outs[k]))
            return HV_EXIT_FAIL;
    static int tty;
    tty = isatty(2);
    /* Progress is for a person watching a terminal; -v adds the details at
     * the end, never progress lines in a log. */
    if (cli_verbose >= 0 && tty)
        hv_set_progress(on_progress, &tty);

    double t0 = hv_now();
    hv_mesh *m = NULL;
    hv_points_report pr;
    hv_status st = cli_read_shape(mesh_path, &o, &m, &pr);
    if (st)
        return cli_fail("sdf", mesh_path, st);
    cli_points_note("sdf", mesh_path, &pr);
    if (!pr.points)
        cli_mesh_note("sdf", mesh_path, m);
    cli_mesh_units("sdf", mesh_path, pr.points ? NULL : m, A.units);
    double t_read = hv_now() - t0;
    /* A cloud's surface is the output's zero set: --mesh-out writes it as it
     * is (the grid's zero set taken again would stray from it by the
     * extraction's error), unless the shape was moved or merged. */
    const int own_surface = mesh_out && cli_own_surface(&pr, &o, adaptivity);
    /* A narrow-band level set alone (and a cloud's own surface beside it),
     * where the options allow: tiles. */
    const int tiles = out && !dense && !npy && (!mesh_out || own_surface) && !no_tiles &&
                      !hv_sdf_tiles_refusal(&o, 1);
    sdf_result r = {0};
    hv_sdf_stats S;
    st = compute(&A, m, &o, tiles, &r, &S);
    hv_grid *g = r.g;
    hv_set_progress(NULL, NULL);
    if (st) {
        if (st == HV_ERR_CANCELLED)
            fputc('\n', stderr);
        hv_vdb_writer_destroy(&r.w);
        hv_mesh_destroy(&m);
        if (st == HV_ERR_NOMEM)
            return too_large(&o, have_h, tiles, out);
        return cli_fail("sdf", mesh_path, st);
    }
    size_t tris = m->ntris;
    /* The preview of a run in tiles computes its slices from the mesh. */
    if (!(tiles && preview) && !own_surface)
        hv_mesh_destroy(&m);

    /* Output. */
    double tw = hv_now();
    char params[512];
    snprintf(params, sizeof params,
             "grid=%dx%dx%d voxel_size=%.9g origin=%.9g,%.9g,%.9g t_scale=%g mode=%s magnitude=%s "
             "repair=0x%x backend=%s band=%g heat_coarsen=%d sign=%s%s%s%s",
             S.n[0], S.n[1], S.n[2], S.h, S.origin[0], S.origin[1], S.origin[2], o.t_scale,
             o.unsigned_distance ? "unsigned" : "signed",
             o.magnitude == HV_SDF_EXACT ? "exact" : "heat", o.repair, hv_backend_name(S.backend),
             band, S.heat_coarsen, cli_sign_name(S.sign), morph_text(&o), dense ? " dense" : "",
             tiles ? " tiles" : "");
    /* Every output is staged; they are renamed together once all are written. */
    cli_outputs co = {0};
    const char *tmp[4] = {NULL, NULL, NULL, NULL};
    for (int k = 0; k < 4; k++)
        if (outs[k] && !(tmp[k] = cli_stage("sdf", &co, outs[k]))) {
            cli_discard(&co);
            hv_grid_destroy(&g);
            hv_vdb_writer_destroy(&r.w);
            hv_mesh_destroy(&m);
            return HV_EXIT_FAIL;
        }
    const char *failed = NULL;
    if (out && (st = write_vdb(&A, &r, params, tmp[0])))
        failed = out;
    hv_vdb_writer_destroy(&r.w);
    if (!st && npy && (st = hv_write_npy(tmp[1], g)))
        failed = npy;
    if (!st && preview &&
        (st = tiles ? preview_slices(m, &o, &S, tmp[2]) : hv_png_write_preview(tmp[2], g, 0)))
        failed = preview;
    double t_mesh = hv_now();
    size_t mesh_tris = 0;
    if (!st && own_surface) {
        mesh_tris = m->ntris;
        if ((st = write_mesh_as(m, mesh_out, tmp[3])))
            failed = mesh_out;
    } else if (!st && mesh_out) {
        hv_mesh *iso = NULL;
        if (!(st = hv_grid_to_mesh(g, 0.0, adaptivity, &iso))) {
            mesh_tris = iso->ntris;
            st = write_mesh_as(iso, mesh_out, tmp[3]);
        }
        hv_mesh_destroy(&iso);
        if (st)
            failed = mesh_out;
    }
    t_mesh = hv_now() - t_mesh;
    hv_mesh_destroy(&m);
    hv_grid_destroy(&g);
    if (st) {
        cli_fail("sdf", failed, st);
        if (co.n > 1)
            fprintf(stderr,
                    "heatvox sdf: no output was written: the outputs land together or not at "
                    "all, and %s failed\n",
                    failed);
        cli_discard(&co);
        return HV_EXIT_FAIL;
    }
    if (cli_commit("sdf", &co))
        return HV_EXIT_FAIL;
    tw = hv_now() - tw - t_mesh;

    const double t[4] = {t_read, t_mesh, tw, hv_now() - t0};
    report(&A, &S, &r.vs, tiles, tris, mesh_tris, t);
    return HV_EXIT_OK;
}
