/* heatvox distance: geodesic distance around obstacles by the heat method. */
#include "cli.h"
#include "heatvox/petsc.h"

#include <ctype.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *CMD = "distance";

static int usage(FILE *out)
{
    fprintf(
        out,
        "usage: heatvox distance --sources FILE [--obstacles MASK.vdb [--obstacle-grid NAME]\n"
        "                        | --obstacle-mesh MESH | --obstacles none] -o OUT.vdb|OUT.h5\n"
        "                        [--npy OUT.npy] [--res N | --voxel-size H] [--bbox x0 y0 z0 "
        "x1 y1 z1]\n"
        "                        [--dim 2|3] [--pad P] [--t-scale K] [--backend "
        "auto|mg|fftw|opencl|petsc]\n"
        "                        [--coarse auto|geometric|aggregation] [--unreachable V]\n"
        "                        [--stages tiles|whole] [--units file|m] [--threads T] [-q] [-v]\n"
        "\n"
        "Geodesic distance from the sources through free space, around obstacles, by the\n"
        "heat method (heat.h). Writes a float grid named 'distance' (world units) and,\n"
        "when there are obstacles, a bool grid 'obstacles'.\n"
        "\n"
        "--sources may be given several times: the set-up (the obstacles' solvers) is\n"
        "made once and each source set's distance is a grid of its own in OUT.vdb,\n"
        "'distance', 'distance_2', ... (one JSON line each).\n"
        "\n"
        "Sources FILE: a mesh (.obj .ply .stl .off, or .gltf .glb .fbx .3mf .dae .x read\n"
        "through assimp: its surface is the source), or text,\n"
        "one source per line, '#' starts a comment:\n"
        "  x y z           a world point (2D grids: x y)\n"
        "  point x y z     the same\n"
        "  voxel i j k     a voxel of the output grid (2D: voxel i j)\n"
        "  mesh PATH       a mesh surface (PATH relative to the file's directory)\n"
        "\n"
        "Grid: with --obstacles MASK.vdb, the mask's voxels (its transform), over the mask's\n"
        "block grown to hold the sources (or --bbox); solid where a bool/mask grid is\n"
        "active, a level set is negative, another float grid is non-zero. Otherwise\n"
        "--bbox (default: the sources and obstacle mesh bounds plus --pad cells, default\n"
        "4) with --res cells along the longest axis (default 128) or --voxel-size.\n"
        "--obstacle-mesh marks the cells its triangles touch (a watertight shell).\n"
        "--dim 2: a 2D grid (bbox x0 y0 x1 y1), written as a one-voxel slab.\n"
        "--units m: meshes (obstacle and source) scaled to metres where the file states\n"
        "its unit; the sources' coordinates, --bbox and --voxel-size are then metres too\n"
        "(default file: every coordinate as written).\n"
        "\n"
        "--coarse: the solves' coarse levels with obstacles (solve.h): aggregation keeps\n"
        "walls one cell thin on every level (fewer iterations, a longer set-up); auto\n"
        "(default) takes it for the Poisson solve and geometric levels for the heat steps.\n"
        "--stages tiles (default): each stage's heat steps are solved on the 8^3 tiles its\n"
        "front reaches (with opencl on the device); whole: on the whole grid by the\n"
        "backend's solver (petsc always).\n"
        "-v: the cells each stage solved on.\n"
        "\n"
        "Cells no source can reach (sealed rooms, shell insides) and solid cells get\n"
        "--unreachable (default inf). Prints a JSON summary on stdout (not with -q).\n"
        "\n"
        "Builds with PETSc (make mpi): -o OUT.h5 writes the distance as HDF5 (dataset\n"
        "/distance, with the attributes spacing and origin) and an XDMF sidecar\n"
        "OUT.xmf for ParaView. Under mpirun -n P with --backend petsc, rank 0 reads\n"
        "the inputs, each rank computes the distance on its own box of the grid (the\n"
        "solves distributed over the ranks), the ranks write the HDF5 file together,\n"
        "and rank 0 gathers the result and writes the VDB and .npy\n"
        "files and prints.\n"
        "Exit codes: 0 success, 1 failure, 2 usage error.\n");
    return out == stdout ? HV_EXIT_OK : HV_EXIT_USAGE;
}

typedef struct {
    int *vox;
    size_t nvox, capvox;
    double *pts;
    size_t npts, cappts;
    hv_mesh *mesh; /* at most one mesh source */
    int dim;       /* dimension of the point records (2 or 3) */
} source_list;

static void free_sources(source_list *s)
{
    free(s->vox);
    free(s->pts);
    hv_mesh_destroy(&s->mesh);
}

static int push3(void **arr, size_t *n, size_t *cap, size_t elem, const void *v)
{
    if (*n == *cap) {
        size_t nc = *cap ? 2 * *cap : 16;
        void *p = realloc(*arr, nc * 3 * elem);
        if (!p)
            return -1;
        *arr = p;
        *cap = nc;
    }
    memcpy((char *)*arr + *n * 3 * elem, v, 3 * elem);
    (*n)++;
    return 0;
}

static int load_mesh_source(source_list *s, const char *path)
{
    if (s->mesh) {
        fprintf(stderr, "heatvox distance: %s: only one mesh source is supported\n", path);
        return HV_EXIT_USAGE;
    }
    hv_status st = hv_mesh_read(path, &s->mesh);
    if (st)
        return cli_fail(CMD, path, st);
    cli_mesh_note(CMD, path, s->mesh);
    return 0;
}

/* Parses the sources file (see usage). */
static int read_sources(const char *path, int dim, source_list *s)
{
    s->dim = dim;
    if (hv_mesh_format_by_extension(path))
        return load_mesh_source(s, path);
    FILE *f = fopen(path, "r");
    if (!f) {
        fprintf(stderr, "heatvox distance: %s: cannot open: %s\n", path, strerror(errno));
        return HV_EXIT_FAIL;
    }
    char line[4096];
    int lineno = 0, rc = 0;
    while (!rc && fgets(line, sizeof line, f)) {
        lineno++;
        char *hash = strchr(line, '#');
        if (hash)
            *hash = 0;
        char *p = line;
        while (isspace((unsigned char)*p))
            p++;
        if (!*p)
            continue;
        char kw[16] = "";
        if (isalpha((unsigned char)*p)) {
            int k = 0;
            while (isalpha((unsigned char)*p) && k < 15)
                kw[k++] = *p++;
            kw[k] = 0;
        }
        if (!strcmp(kw, "mesh")) {
            while (isspace((unsigned char)*p))
                p++;
            char *end = p + strlen(p);
            while (end > p && isspace((unsigned char)end[-1]))
                *--end = 0;
            if (!*p) {
                fprintf(stderr, "heatvox distance: %s:%d: 'mesh' needs a path\n", path, lineno);
                rc = HV_EXIT_FAIL;
                break;
            }
            char full[8192];
            const char *slash = strrchr(path, '/');
            int len = *p != '/' && slash
                          ? snprintf(full, sizeof full, "%.*s/%s", (int)(slash - path), path, p)
                          : snprintf(full, sizeof full, "%s", p);
            if (len < 0 || (size_t)len >= sizeof full) {
                fprintf(stderr, "heatvox distance: %s:%d: mesh path too long\n", path, lineno);
                rc = HV_EXIT_FAIL;
                break;
            }
            rc = load_mesh_source(s, full);
            continue;
        }
        if (*kw && strcmp(kw, "voxel") && strcmp(kw, "point")) {
            fprintf(stderr,
                    "heatvox distance: %s:%d: unknown record '%s' (expected x y z, point, voxel or "
                    "mesh)\n",
                    path, lineno, kw);
            rc = HV_EXIT_FAIL;
            break;
        }
        double v[4];
        int nv = 0;
        char *q = p;
        while (nv < 4) {
            while (isspace((unsigned char)*q))
                q++;
            if (!*q)
                break;
            char *end;
            v[nv] = strtod(q, &end);
            if (end == q || !isfinite(v[nv])) {
                nv = -1;
                break;
            }
            nv++;
            q = end;
        }
        while (nv >= 0 && isspace((unsigned char)*q))
            q++;
        if (nv != dim || *q) {
            fprintf(stderr, "heatvox distance: %s:%d: expected %d numbers%s\n", path, lineno, dim,
                    dim == 2 ? " (a 2D grid)" : "");
            rc = HV_EXIT_FAIL;
            break;
        }
        if (!strcmp(kw, "voxel")) {
            int iv[3] = {0, 0, 0};
            for (int a = 0; a < dim; a++) {
                if (v[a] != floor(v[a]) || fabs(v[a]) > 1e9) {
                    fprintf(stderr, "heatvox distance: %s:%d: voxel indices must be integers\n",
                            path, lineno);
                    rc = HV_EXIT_FAIL;
                    break;
                }
                iv[a] = (int)v[a];
            }
            if (!rc && push3((void **)&s->vox, &s->nvox, &s->capvox, sizeof(int), iv))
                rc = cli_fail(CMD, "reading sources", HV_ERR_NOMEM);
        } else {
            double pv[3] = {v[0], v[1], dim == 3 ? v[2] : 0};
            if (push3((void **)&s->pts, &s->npts, &s->cappts, sizeof(double), pv))
                rc = cli_fail(CMD, "reading sources", HV_ERR_NOMEM);
        }
    }
    fclose(f);
    if (!rc && !s->nvox && !s->npts && !s->mesh) {
        fprintf(stderr, "heatvox distance: %s: no sources\n", path);
        rc = HV_EXIT_FAIL;
    }
    return rc;
}

/* World bounds of the point and mesh sources and the obstacle mesh; returns 0 if none. */
/* Adds mesh m's bounds to lo..hi; whether it had any. */
static int mesh_bounds_add(const hv_mesh *m, double lo[3], double hi[3])
{
    double ml[3], mh[3];
    if (!m || hv_mesh_bounds(m, ml, mh) != HV_OK)
        return 0;
    for (int a = 0; a < 3; a++) {
        lo[a] = fmin(lo[a], ml[a]);
        hi[a] = fmax(hi[a], mh[a]);
    }
    return 1;
}

/* The bounds of the ns source sets s and the obstacle mesh (may be NULL). */
static int source_bounds(const source_list *s, int ns, const hv_mesh *obst, double lo[3],
                         double hi[3])
{
    int any = 0;
    for (int a = 0; a < 3; a++) {
        lo[a] = INFINITY;
        hi[a] = -INFINITY;
    }
    for (int q = 0; q < ns; q++) {
        for (size_t i = 0; i < s[q].npts; i++)
            for (int a = 0; a < 3; a++) {
                lo[a] = fmin(lo[a], s[q].pts[3 * i + a]);
                hi[a] = fmax(hi[a], s[q].pts[3 * i + a]);
                any = 1;
            }
        any |= mesh_bounds_add(s[q].mesh, lo, hi);
    }
    return mesh_bounds_add(obst, lo, hi) | any;
}

/* Grid from a VDB mask: the named grid's transform; the box is --bbox or its
 * default block grown to hold the sources plus pad cells. */
static int grid_from_mask(const char *path, const char *name, const source_list *s, int ns,
                          int use_bbox, const double bbox[6], int pad, hv_grid **g,
                          double index0[3])
{
    hv_vdb_grid_info info[64];
    size_t count = 0;
    hv_status st = hv_vdb_list(path, info, 64, &count);
    if (st)
        return cli_fail(CMD, path, st);
    const hv_vdb_grid_info *gi = NULL;
    if (!name && count == 1)
        gi = &info[0];
    for (size_t i = 0; name && i < count && i < 64; i++)
        if (!strcmp(info[i].name, name))
            gi = &info[i];
    if (!gi) {
        fprintf(stderr, "heatvox distance: %s: ", path);
        if (name)
            fprintf(stderr, "no grid named '%s'; grids:", name);
        else
            fprintf(stderr, "%zu grids, name one with --obstacle-grid:", count);
        for (size_t i = 0; i < count && i < 64; i++)
            fprintf(stderr, " '%s' (%s)", info[i].name, info[i].value_type);
        fprintf(stderr, "\n");
        return HV_EXIT_FAIL;
    }
    if (!gi->uniform) {
        fprintf(stderr, "heatvox distance: %s: grid '%s' has a non-uniform or rotated transform\n",
                path, gi->name);
        return HV_EXIT_FAIL;
    }
    const double h = gi->voxel_size[0];
    hv_vdb_read_opts ro = {1, {0, 0, 0}, {0, 0, 0}};
    if (use_bbox) {
        for (int a = 0; a < 3; a++) {
            ro.box_lo[a] = (int)ceil((bbox[a] - gi->index0_world[a]) / h - 1e-9);
            ro.box_hi[a] = (int)floor((bbox[3 + a] - gi->index0_world[a]) / h + 1e-9);
            if (ro.box_hi[a] < ro.box_lo[a]) {
                fprintf(stderr, "heatvox distance: --bbox holds no voxel centre of '%s' along %c\n",
                        gi->name, "xyz"[a]);
                return HV_EXIT_USAGE;
            }
        }
    } else {
        if (gi->bbox_lo[0] > gi->bbox_hi[0]) {
            fprintf(stderr, "heatvox distance: %s: grid '%s' has no active voxels; give --bbox\n",
                    path, gi->name);
            return HV_EXIT_FAIL;
        }
        char buf[128];
        int lo[3], hi[3];
        memcpy(lo, gi->bbox_lo, sizeof lo);
        memcpy(hi, gi->bbox_hi, sizeof hi);
        if (hv_vdb_read_meta(path, gi->name, "heatvox_block_min", buf, sizeof buf) == HV_OK)
            sscanf(buf, "[%d, %d, %d]", &lo[0], &lo[1], &lo[2]);
        if (hv_vdb_read_meta(path, gi->name, "heatvox_block_max", buf, sizeof buf) == HV_OK)
            sscanf(buf, "[%d, %d, %d]", &hi[0], &hi[1], &hi[2]);
        hv_clear_error();
        double sl[3], sh[3];
        if (source_bounds(s, ns, NULL, sl, sh))
            for (int a = 0; a < 3; a++) {
                lo[a] = (int)fmin(lo[a], floor((sl[a] - gi->index0_world[a]) / h) - pad);
                hi[a] = (int)fmax(hi[a], ceil((sh[a] - gi->index0_world[a]) / h) + pad);
            }
        memcpy(ro.box_lo, lo, sizeof lo);
        memcpy(ro.box_hi, hi, sizeof hi);
    }
    st = hv_vdb_read_mask(path, gi->name, &ro, g);
    if (st)
        return cli_fail(CMD, path, st);
    memcpy(index0, gi->index0_world, 3 * sizeof *index0);
    return 0;
}

static int parse_unreachable(const char *v, float *out)
{
    if (!strcmp(v, "inf") || !strcmp(v, "+inf")) {
        *out = INFINITY;
        return 0;
    }
    double d;
    if (cli_parse_double(v, &d))
        return -1;
    *out = (float)d;
    return 0;
}

/* The command line of heatvox distance. */
#define MAX_SETS 64

typedef struct dist_args {
    const char *sources; /* the first source set */
    const char *sets[MAX_SETS];
    int nsets;
    const char *mask, *mask_grid, *obst_mesh, *out, *npy;
    const char *h5; /* -o OUT.h5 (then out is NULL) */
    int res, dim, pad, use_bbox, threads, none;
    double vsize, bbox[6];
    hv_distance_opts o;
    int coarse; /* hv_coarse */
    int whole;  /* --stages whole */
    int units;  /* --units: CLI_UNITS_FILE or CLI_UNITS_M */
} dist_args;

/* --sources FILE, once per source set. */
static int take_sources(const char *cmd, const char *opt, char **v, int nv, void *dst)
{
    dist_args *A = dst;
    if (nv < 1)
        return -cli_usage_error(cmd, "%s needs 1 value", opt);
    if (A->nsets == MAX_SETS)
        return -cli_usage_error(cmd, "at most %d source sets (--sources)", MAX_SETS);
    A->sets[A->nsets++] = v[0];
    A->sources = A->sets[0];
    return 1;
}

/* --bbox: 6 numbers, or 4 with --dim 2 (which may come later: take what
 * parses). */
static int take_bbox(const char *cmd, const char *opt, char **v, int nv, void *dst)
{
    dist_args *A = dst;
    double *bb = A->bbox;
    int k = 0;
    while (k < 6 && k < nv && cli_parse_double(v[k], &bb[k]) == 0)
        k++;
    if (k != 4 && k != 6)
        return -cli_usage_error(cmd, "%s needs x0 y0 z0 x1 y1 z1 (or x0 y0 x1 y1 in 2D)", opt);
    if (k == 4) {
        const double b4[4] = {bb[0], bb[1], bb[2], bb[3]};
        const double b6[6] = {b4[0], b4[1], -0.5, b4[2], b4[3], 0.5};
        memcpy(bb, b6, sizeof b6);
    }
    A->use_bbox = k;
    return k;
}

/* --obstacles MASK.vdb, or none. */
static int take_obstacles(const char *cmd, const char *opt, char **v, int nv, void *dst)
{
    dist_args *A = dst;
    if (nv < 1)
        return -cli_usage_error(cmd, "%s needs 1 value", opt);
    if (!strcmp(v[0], "none"))
        A->none = 1;
    else
        A->mask = v[0];
    return 1;
}

/* --unreachable V: the value of cells no source reaches, solid ones too. */
static int take_unreachable(const char *cmd, const char *opt, char **v, int nv, void *dst)
{
    hv_distance_opts *o = dst;
    if (nv < 1)
        return -cli_usage_error(cmd, "%s needs 1 value", opt);
    if (parse_unreachable(v[0], &o->unreachable))
        return -cli_usage_error(cmd, "%s needs a number or inf, got '%s'", opt, v[0]);
    o->solid_value = o->unreachable;
    return 1;
}

static void help(void) { usage(stdout); }

/* Reads the command line into A: -1 to go on, else the exit code. */
static int parse_args(int argc, char **argv, dist_args *A)
{
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "--bbox", .kind = CLI_FN, .dst = A, .fn = take_bbox},
        {.names = "--sources",
         .kind = CLI_FN,
         .dst = A,
         .val = 1,
         .fn = take_sources,
         .files = CLI_FILES_ANY},
        {.names = "--obstacles",
         .kind = CLI_FN,
         .dst = A,
         .val = 1,
         .fn = take_obstacles,
         .choices = "none",
         .files = ".vdb"},
        {.names = "--obstacle-grid", .kind = CLI_STR, .dst = &A->mask_grid},
        {.names = "--obstacle-mesh",
         .kind = CLI_STR,
         .dst = &A->obst_mesh,
         .files = CLI_FILES_TRIMESH},
        CLI_ROW_OUTPUT(&A->out, ".vdb .h5"),
        {.names = "--npy", .kind = CLI_STR, .dst = &A->npy, .files = ".npy"},
        CLI_ROW_RES(&A->res, 4, NULL),
        CLI_ROW_VOXEL_SIZE(&A->vsize, NULL),
        {.names = "--dim", .kind = CLI_INT, .dst = &A->dim, .min = 2, .max = 3, .needs = "2 or 3"},
        CLI_ROW_PAD(&A->pad),
        CLI_ROW_T_SCALE(&A->o.t_scale),
        CLI_ROW_UNITS(&A->units),
        CLI_ROW_BACKEND(&A->o.backend, CLI_BACKENDS_ALL),
        {.names = "--coarse",
         .kind = CLI_CHOICE,
         .dst = &A->coarse,
         .choices = "auto|geometric|aggregation",
         .needs = "auto, geometric or aggregation"},
        {.names = "--unreachable",
         .kind = CLI_FN,
         .dst = &A->o,
         .val = 1,
         .fn = take_unreachable,
         .choices = "inf"},
        {.names = "--stages",
         .kind = CLI_CHOICE,
         .dst = &A->whole,
         .choices = "tiles|whole",
         .needs = "tiles or whole"},
        CLI_ROW_THREADS(&A->threads),
        {.names = NULL},
    };
    const char *stray = NULL;
    int prc = cli_parse(CMD, argc, argv, opts, "argument", &stray, help);
    if (prc >= 0)
        return prc;
    if (stray)
        return cli_usage_error(CMD, "unexpected argument '%s' (the sources come with --sources)",
                               stray);
    A->o.coarse = (hv_coarse)A->coarse;
    A->o.whole_stages = A->whole;
    return -1;
}

/* The combinations of options that make no sense, and the outputs: -1 to go
 * on, else the exit code. */
static int check_args(dist_args *A)
{
    if (!A->sources)
        return cli_usage_error(CMD, "--sources is required");
    if (!A->out && !A->npy)
        return cli_usage_error(CMD, "give -o OUT.vdb (and/or --npy OUT.npy)");
    if (cli_check_ext(CMD, "-o", A->out, ".vdb .h5") || cli_check_ext(CMD, "--npy", A->npy, ".npy"))
        return HV_EXIT_USAGE;
    int is_h5;
    if (cli_h5_output(CMD, A->out, &is_h5))
        return HV_EXIT_USAGE;
    if (is_h5) {
        A->h5 = A->out;
        A->out = NULL;
    }
    const int dim = A->dim;
    if ((A->mask != NULL) + (A->obst_mesh != NULL) + A->none > 1)
        return cli_usage_error(
            CMD, "give one of --obstacles MASK.vdb, --obstacle-mesh, --obstacles none");
    if (A->mask && (A->res || A->vsize))
        return cli_usage_error(CMD, "--res/--voxel-size cannot be used with --obstacles MASK.vdb "
                                    "(its voxels are the grid)");
    if (A->mask && dim == 2)
        return cli_usage_error(
            CMD, "--dim 2 cannot be used with a VDB mask (a one-voxel-thick mask is fine in 3D)");
    if (A->obst_mesh && dim == 2)
        return cli_usage_error(CMD, "--obstacle-mesh needs a 3D grid");
    if (A->use_bbox && (A->use_bbox == 4) != (dim == 2))
        return cli_usage_error(CMD, "--bbox takes %d numbers for a %dD grid", dim == 2 ? 4 : 6,
                               dim);
    if (A->res && A->vsize)
        return cli_usage_error(CMD, "give --res or --voxel-size, not both");
    if (A->nsets > 1 && (A->npy || A->h5 || A->o.backend == HV_BACKEND_PETSC))
        return cli_usage_error(CMD, "several --sources write one grid each into -o OUT.vdb; "
                                    "--npy, OUT.h5 and --backend petsc take one");
    const char *outs[] = {A->out ? A->out : A->h5, A->npy};
    const char *ins[MAX_SETS + 2] = {A->mask, A->obst_mesh};
    for (int q = 0; q < A->nsets; q++)
        ins[2 + q] = A->sets[q];
    if (cli_check_outputs(CMD, outs, 2, ins, 2 + A->nsets))
        return HV_EXIT_FAIL;
    return -1;
}

/* The grid without a VDB mask: --bbox, or the sources' and the obstacle
 * mesh's bounds plus --pad cells, with --res cells along the longest axis or
 * --voxel-size; the obstacle mesh's cells marked solid. */
static int grid_from_box(const dist_args *A, const source_list *src, int nvox, const hv_mesh *om,
                         hv_grid **g)
{
    const int dim = A->dim;
    double lo[3], hi[3];
    if (A->use_bbox) {
        for (int a = 0; a < 3; a++) {
            lo[a] = A->bbox[a];
            hi[a] = A->bbox[3 + a];
        }
    } else if (nvox) {
        return cli_usage_error(
            CMD, "voxel sources need --bbox or --obstacles MASK.vdb to define the grid");
    } else if (!source_bounds(src, A->nsets, om, lo, hi)) {
        return cli_usage_error(CMD, "cannot size the grid: give --bbox");
    }
    double ext = 0;
    for (int a = 0; a < dim; a++) {
        if (!(hi[a] >= lo[a]))
            return cli_usage_error(CMD, "--bbox is empty along %c", "xyz"[a]);
        ext = fmax(ext, hi[a] - lo[a]);
    }
    int padc = A->use_bbox ? 0 : A->pad;
    if (!(ext > 0) && !(A->vsize > 0))
        return cli_usage_error(CMD, "the sources span no volume: give --bbox or --voxel-size");
    double h = A->vsize > 0 ? A->vsize : ext / ((A->res ? A->res : 128) - 2 * padc);
    if (!(h > 0))
        return cli_usage_error(CMD, "--res is too small for --pad %d", padc);
    int n[3] = {1, 1, 1};
    double org[3] = {0, 0, 0};
    for (int a = 0; a < dim; a++) {
        n[a] = (int)ceil((hi[a] - lo[a]) / h - 1e-9) + 2 * padc;
        if (n[a] < 1)
            n[a] = 1;
        org[a] = 0.5 * (lo[a] + hi[a]) - 0.5 * n[a] * h;
    }
    if (dim == 2)
        org[2] = -0.5 * h;
    hv_status st = hv_grid_create(g, dim, n, h, org);
    if (!st && om)
        st = hv_mask_from_mesh(*g, om, NULL);
    if (st)
        return cli_fail(CMD, om ? A->obst_mesh : "creating the grid", st);
    return 0;
}

static int grid_from_bounds(const dist_args *A, const source_list *src, const hv_mesh *om,
                            hv_grid **g)
{
    int nvox = 0;
    for (int q = 0; q < A->nsets; q++)
        nvox |= src[q].nvox > 0;
    return grid_from_box(A, src, nvox, om, g);
}

/* s as a JSON string on stdout. */
static void json_string(const char *s)
{
    putchar('"');
    for (; *s; s++) {
        unsigned char c = (unsigned char)*s;
        if (c == '"' || c == '\\')
            printf("\\%c", c);
        else if (c < 0x20)
            printf("\\u%04x", c);
        else
            putchar(c);
    }
    putchar('"');
}

/* The name of source set q's grid: distance, distance_2, distance_3, ... */
static void set_name(int q, char *buf, size_t len)
{
    if (q == 0)
        snprintf(buf, len, "distance");
    else
        snprintf(buf, len, "distance_%d", q + 1);
}

/* Adds source set q's distance (g->v) to the VDB writer, with how it was made. */
static hv_status add_set(hv_vdb_writer *w, const dist_args *A, const hv_grid *g,
                         const hv_distance_stats *sd, int q)
{
    char name[32], buf[4200];
    set_name(q, name, sizeof name);
    hv_status st = hv_vdb_writer_add_float(w, g, name);
    snprintf(buf, sizeof buf, "heat method, t = %g h^2, %d stages, sources from %s", A->o.t_scale,
             sd->stages, A->sets[q]);
    if (!st)
        st = hv_vdb_writer_set_grid_meta(w, name, "heatvox_method", buf);
    snprintf(buf, sizeof buf, "%zu", sd->unreachable_cells);
    if (!st)
        st = hv_vdb_writer_set_grid_meta(w, name, "heatvox_unreachable_cells", buf);
    return st;
}

/* The outputs being written: their staged names, and the VDB's writer. */
typedef struct dist_outs {
    cli_outputs co;
    const char *npy, *vdb; /* staged names (NULL: not asked for) */
    hv_vdb_writer *w;
} dist_outs;

/* Stages the .npy (one source set) and opens the .vdb's writer (the sets'
 * grids are added as they are computed); a VDB mask's transform and index
 * space kept (index0). */
static int open_files(const dist_args *A, const double *index0, dist_outs *F)
{
    F->npy = A->npy ? cli_stage(CMD, &F->co, A->npy) : NULL;
    F->vdb = A->out && (!A->npy || F->npy) ? cli_stage(CMD, &F->co, A->out) : NULL;
    if ((A->npy && !F->npy) || (A->out && !F->vdb))
        return HV_EXIT_FAIL;
    if (!A->out)
        return 0;
    hv_status st = hv_vdb_writer_create(&F->w);
    if (!st && index0)
        st = hv_vdb_writer_set_index_origin(F->w, index0);
    return st ? cli_fail(CMD, A->out, st) : 0;
}

/* Writes the .npy of the one source set and the VDB with the obstacles. */
static int finish_files(const dist_args *A, const hv_grid *g, dist_outs *F)
{
    hv_status st;
    if (F->npy && (st = hv_write_npy(F->npy, g)))
        return cli_fail(CMD, A->npy, st);
    if (!F->w)
        return 0;
    st = g->solid ? hv_vdb_writer_add_mask(F->w, g, "obstacles") : HV_OK;
    if (!st)
        st = hv_vdb_writer_write(F->w, F->vdb);
    return st ? cli_fail(CMD, A->out, st) : 0;
}

static void report(const dist_args *A, const hv_grid *g, const hv_distance_stats *sd, int q,
                   double t_start)
{
    if (A->nsets > 1) {
        char name[32];
        set_name(q, name, sizeof name);
        printf("{\"command\":\"distance\",\"grid_name\":\"%s\",\"sources\":", name);
        json_string(A->sets[q]);
        printf(",");
    } else {
        printf("{\"command\":\"distance\",");
    }
    printf("\"grid\":[%d,%d,%d],\"h\":%g,\"stages\":%d,"
           "\"source_cells\":%zu,\"regions\":%zu,\"unreachable_cells\":%zu,\"dead_faces\":%zu,"
           "\"backend\":\"%s\",\"diffuse_iterations\":%d,\"diffuse_seconds\":%.3f,"
           "\"poisson_iterations\":%d,\"poisson_seconds\":%.3f,\"seconds\":%.3f",
           g->n[0], g->n[1], g->n[2], g->h, sd->stages, sd->source_cells, sd->regions,
           sd->unreachable_cells, sd->dead_faces, hv_backend_name(sd->backend),
           sd->diffuse_iterations, sd->t_diffuse, sd->poisson_iterations, sd->t_poisson,
           hv_now() - t_start);
    const double cells = (double)g->n[0] * g->n[1] * g->n[2];
    printf(",\"cells_solved\":%zu,\"cells_solved_grids\":%.2f,\"splat_seconds\":%.3f,"
           "\"normalize_seconds\":%.3f,\"setup_seconds\":%.3f,\"query_seconds\":%.3f",
           sd->cells_solved, (double)sd->cells_solved / cells, sd->t_splat, sd->t_normalize,
           sd->t_setup, sd->t_total - sd->t_setup);
    if (sd->backend == HV_BACKEND_OPENCL)
        printf(",\"host_bytes\":%.0f", sd->host_bytes);
    cli_json_device(sd->backend);
    printf("}\n");
}

/* A rank other than 0 under mpirun with --backend petsc: its box of rank 0's
 * grid, and its part of the HDF5 file. */
static int other_rank(const dist_args *A)
{
    hv_distance_stats sd;
    hv_status st;
    if ((st = hv_petsc_distance_block(NULL, NULL, NULL, &sd)))
        return cli_fail(CMD, A->sources, st);
    if (A->h5 && (st = hv_petsc_write_h5(A->h5, 1, NULL, (const char *const[]){"distance"})))
        return cli_fail(CMD, A->h5, st);
    return 0;
}

/* The source sets, the obstacle mesh and the grid (from the VDB mask, or from
 * bounds); with a mask, *have_index0 = 1 and index0 its index origin. */
static int read_inputs(const dist_args *A, source_list *src, hv_mesh **om, hv_grid **g,
                       double index0[3], int *have_index0)
{
    int rc = 0;
    for (int q = 0; !rc && q < A->nsets; q++)
        rc = read_sources(A->sets[q], A->dim, &src[q]);
    if (rc)
        return rc;
    for (int q = 0; q < A->nsets; q++)
        if (src[q].mesh)
            cli_mesh_units(CMD, A->sets[q], src[q].mesh, A->units);
    if (A->obst_mesh) {
        hv_status st = hv_mesh_read(A->obst_mesh, om);
        if (st)
            return cli_fail(CMD, A->obst_mesh, st);
        cli_mesh_note(CMD, A->obst_mesh, *om);
        cli_mesh_units(CMD, A->obst_mesh, *om, A->units);
    }
    if (!A->mask)
        return grid_from_bounds(A, src, *om, g);
    if ((rc = grid_from_mask(A->mask, A->mask_grid, src, A->nsets, A->use_bbox == 6, A->bbox,
                             A->pad, g, index0)))
        return rc;
    *have_index0 = 1;
    return 0;
}

/* The notes on stderr after source set q's distance. */
static void set_notes(const dist_args *A, int q, const hv_distance_stats *sd)
{
    const char *pre = A->nsets > 1 ? A->sets[q] : NULL;
    if (sd->sources_in_solid)
        fprintf(stderr,
                "heatvox distance: %s%swarning: %zu sources lie in obstacles and were skipped\n",
                pre ? pre : "", pre ? ": " : "", sd->sources_in_solid);
    if (sd->unreachable_cells && cli_verbose >= 0)
        fprintf(stderr, "heatvox distance: %s%s%zu cells no source can reach (value %g)\n",
                pre ? pre : "", pre ? ": " : "", sd->unreachable_cells, (double)A->o.unreachable);
    if (cli_verbose > 0)
        for (int l = 0; l < sd->stages && l < 8; l++)
            fprintf(stderr, "heatvox distance: stage %d: %zu cells solved, %zu faces assigned\n",
                    l + 1, sd->stage_cells[l], sd->faces_per_stage[l]);
}

/* Each source set's distance on one hv_distance (the set-up once), added to
 * the VDB as it comes; the last set's values stay in g. */
static int compute_sets(const dist_args *A, const source_list *src, hv_grid *g, dist_outs *F,
                        hv_distance_stats *sd)
{
    hv_distance *D = NULL;
    hv_status st = hv_distance_create(&D, g, &A->o);
    if (st)
        return cli_fail(CMD, A->sources, st);
    int rc = 0;
    for (int q = 0; !rc && q < A->nsets; q++) {
        const hv_distance_sources ds = {src[q].vox, src[q].nvox, src[q].pts, src[q].npts,
                                        src[q].mesh};
        if ((st = hv_distance_query(D, &ds, g, &sd[q])))
            rc = cli_fail(CMD, A->sets[q], st);
        else if (F->w && (st = add_set(F->w, A, g, &sd[q], q)))
            rc = cli_fail(CMD, A->out, st);
        else
            set_notes(A, q, &sd[q]);
    }
    hv_distance_destroy(&D);
    return rc;
}

/* -o OUT.h5 (one source set): the distance as HDF5, by rank 0's process alone
 * or, under mpirun with --backend petsc, with the other ranks. */
static int write_h5(const dist_args *A, const hv_grid *g)
{
    hv_status st;
    if (A->h5 && (st = hv_petsc_write_h5(A->h5, 1, (const hv_grid *const[]){g},
                                         (const char *const[]){"distance"})))
        return cli_fail(CMD, A->h5, st);
    return 0;
}

/* --backend petsc under mpirun, rank 0: the one source set over the ranks. */
static int compute_spread(const dist_args *A, const source_list *src, hv_grid *g,
                          hv_distance_stats *sd)
{
    const hv_distance_sources ds = {src->vox, src->nvox, src->pts, src->npts, src->mesh};
    hv_status st = hv_petsc_distance_block(g, &ds, &A->o, sd);
    if (st)
        return cli_fail(CMD, A->sources, st);
    set_notes(A, 0, sd);
    return write_h5(A, g);
}

/* Reads, computes and writes. --backend petsc under mpirun: rank 0 reads the
 * inputs and builds the grid, every rank computes its box
 * (hv_petsc_distance_block), and rank 0 writes; the ranks write HDF5
 * together. */
static int run(const dist_args *A)
{
    const int spread = A->o.backend == HV_BACKEND_PETSC && hv_petsc_available();
    if (spread && hv_mpi_rank() > 0)
        return other_rank(A);
    double t_start = hv_now(), index0[3] = {0, 0, 0};
    int have_index0 = 0;
    source_list src[MAX_SETS] = {{0}};
    dist_outs F = {0};
    hv_mesh *om = NULL;
    hv_grid *g = NULL;
    hv_distance_stats sd[MAX_SETS];
    int released = !spread;
    int rc = read_inputs(A, src, &om, &g, index0, &have_index0);
    if (rc)
        goto done;
    cli_info("heatvox distance: grid %d x %d x %d, h = %g\n", g->n[0], g->n[1], g->n[2], g->h);
    released = 1;
    if (spread) {
        hv_status st = HV_OK;
        if ((rc = compute_spread(A, src, g, sd)) || hv_mpi_rank() > 0 ||
            (rc = open_files(A, have_index0 ? index0 : NULL, &F)))
            goto done;
        if (F.w && (st = add_set(F.w, A, g, sd, 0))) {
            rc = cli_fail(CMD, A->out, st);
            goto done;
        }
    } else if ((rc = open_files(A, have_index0 ? index0 : NULL, &F)) ||
               (rc = compute_sets(A, src, g, &F, sd)) || (rc = write_h5(A, g))) {
        goto done;
    }
    if ((rc = finish_files(A, g, &F)) || (rc = cli_commit(CMD, &F.co)))
        goto done;
    for (int q = 0; cli_verbose >= 0 && q < A->nsets; q++)
        report(A, g, &sd[q], q, t_start);
done:
    if (!released) /* the other ranks wait in hv_petsc_distance_block: release them */
        hv_petsc_distance_block(NULL, NULL, NULL, NULL);
    hv_vdb_writer_destroy(&F.w);
    cli_discard(&F.co);
    for (int q = 0; q < A->nsets; q++)
        free_sources(&src[q]);
    hv_mesh_destroy(&om);
    hv_grid_destroy(&g);
    return rc;
}

int cmd_distance(int argc, char **argv)
{
    dist_args A = {.dim = 3, .pad = 4};
    hv_distance_opts_default(&A.o);
    int rc = parse_args(argc, argv, &A);
    if (rc < 0)
        rc = check_args(&A);
    if (rc >= 0)
        return rc;
    hv_set_threads(A.threads);
    return run(&A);
}
