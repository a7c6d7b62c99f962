/* heatvox batch: job options, the resume sidecar, and the job one worker runs;
 * also the text helpers the batch files share. */
#include "batch.h"
#include "cli.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* ---- text: a growing buffer, and strings for the driver ---- */

void bb_printf(batch_buf *b, const char *fmt, ...)
{
    for (;;) {
        va_list ap;
        va_start(ap, fmt);
        size_t room = b->cap - b->len;
        int n = vsnprintf(b->s ? b->s + b->len : NULL, b->s ? room : 0, fmt, ap);
        va_end(ap);
        if (n < 0)
            return;
        if (b->s && (size_t)n < room) {
            b->len += (size_t)n;
            return;
        }
        size_t cap = b->cap ? b->cap : 256;
        while (cap < b->len + (size_t)n + 1)
            cap *= 2;
        char *s = realloc(b->s, cap);
        if (!s)
            return;
        b->s = s;
        b->cap = cap;
    }
}

void bb_json_string(batch_buf *b, const char *s)
{
    if (!s) {
        bb_printf(b, "null");
        return;
    }
    bb_printf(b, "\"");
    for (const unsigned char *p = (const unsigned char *)s; *p; p++) {
        if (*p == '"' || *p == '\\')
            bb_printf(b, "\\%c", *p);
        else if (*p == '\n')
            bb_printf(b, "\\n");
        else if (*p < 0x20)
            bb_printf(b, "\\u%04x", *p);
        else
            bb_printf(b, "%c", *p);
    }
    bb_printf(b, "\"");
}

void bb_free(batch_buf *b)
{
    free(b->s);
    b->s = NULL;
    b->len = b->cap = 0;
}

char *batch_xstrdup(const char *s)
{
    char *d = strdup(s);
    if (!d) {
        fprintf(stderr, "heatvox batch: out of memory\n");
        exit(HV_EXIT_FAIL);
    }
    return d;
}

char *batch_xprintf(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    char *s = NULL;
    int n = vasprintf(&s, fmt, ap);
    va_end(ap);
    if (n < 0) {
        fprintf(stderr, "heatvox batch: out of memory\n");
        exit(HV_EXIT_FAIL);
    }
    return s;
}

/* ---- options ---- */

static const char *const mesh_exts[] = {NULL, "obj", "ply", "stl"};

void batch_opts_default(batch_opts *o)
{
    memset(o, 0, sizeof *o);
    hv_sdf_opts_default(&o->sdf);
    o->format = BATCH_VDB;
    o->band = 3.0;
}

static int bad(char *err, size_t size, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static int bad(char *err, size_t size, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err, size, fmt, ap);
    va_end(ap);
    return -1;
}

/* --res N: the cell count wins over a --voxel-size given before it (by the
 * command line, under a manifest line's). */
static int take_res(const char *cmd, const char *opt, char **v, int nv, void *dst)
{
    hv_sdf_opts *o = dst;
    int n;
    if (nv < 1)
        return -cli_usage_error(cmd, "%s needs 1 value", opt);
    if (cli_parse_int(v[0], &n) || n < 2)
        return -cli_usage_error(cmd, "%s needs an integer >= 2, got '%s'", opt, v[0]);
    o->res = n;
    o->voxel_size = 0;
    return 1;
}

static int take_bbox(const char *cmd, const char *opt, char **v, int nv, void *dst)
{
    hv_sdf_opts *o = dst;
    if (nv < 6)
        return -cli_usage_error(cmd, "%s needs 6 values", opt);
    for (int d = 0; d < 6; d++)
        if (cli_parse_double(v[d], &o->bbox[d]))
            return -cli_usage_error(cmd, "%s needs 6 finite numbers, got '%s'", opt, v[d]);
    for (int d = 0; d < 3; d++)
        if (!(o->bbox[d] < o->bbox[d + 3]))
            return -cli_usage_error(cmd, "%s: the %c range is empty", opt, "xyz"[d]);
    o->use_bbox = 1;
    return 6;
}

#define JOB_OPTS BATCH_JOB_OPTS

/* The job options over o: the batch command's (passed on to every worker)
 * and each manifest line's. */
static void job_options(batch_opts *o, cli_opt t[JOB_OPTS + 1])
{
    hv_sdf_opts *s = &o->sdf;
    const cli_opt rows[JOB_OPTS + 1] = {
        {.names = "--res", .kind = CLI_FN, .dst = s, .val = 1, .fn = take_res},
        CLI_ROW_VOXEL_SIZE(&s->voxel_size, NULL),
        CLI_ROW_PAD(&s->pad),
        {.names = "--bbox", .kind = CLI_FN, .dst = s, .val = 6, .fn = take_bbox},
        {.names = "--round-to",
         .kind = CLI_INT,
         .dst = &s->round_to,
         .min = 1,
         .max = INT_MAX,
         .needs = "an integer >= 1"},
        {.names = "--unsigned", .kind = CLI_FLAG, .dst = &s->unsigned_distance, .val = 1},
        {.names = "--heat", .kind = CLI_FLAG, .dst = &s->magnitude, .val = HV_SDF_HEAT},
        {.names = "--exact", .kind = CLI_FLAG, .dst = &s->magnitude, .val = HV_SDF_EXACT},
        CLI_ROW_T_SCALE(&s->t_scale),
        {.names = "--far-levels",
         .kind = CLI_INT,
         .dst = &s->far_levels,
         .min = -1,
         .max = INT_MAX,
         .needs = "an integer >= -1"},
        CLI_ROW_NO_REPAIR(&s->repair),
        {.names = "--orient",
         .kind = CLI_CHOICE,
         .dst = &s->orient,
         .choices = "auto|given|recover",
         .needs = "auto, given or recover"},
        CLI_ROW_UNITS(&o->units),
        CLI_ROW_BACKEND(&s->backend, CLI_BACKENDS_LOCAL),
        {.names = "--diffuse-tol",
         .kind = CLI_DOUBLE,
         .dst = &s->diffuse_tol,
         .min = 1e-12,
         .max = 1 - 0x1p-53,
         .needs = "a number in [1e-12, 1)"},
        {.names = "--poisson-tol",
         .kind = CLI_DOUBLE,
         .dst = &s->poisson_tol,
         .min = 1e-12,
         .max = 1 - 0x1p-53,
         .needs = "a number in [1e-12, 1)"},
        {.names = "--threads",
         .kind = CLI_INT,
         .dst = &s->threads,
         .max = HV_MAX_THREADS,
         .needs = "an integer in [0, " BATCH_STR(HV_MAX_THREADS) "]"},
        CLI_ROW_BAND("--band", &o->band),
        CLI_ROW_DENSE(&o->dense),
        {.names = "--format",
         .kind = CLI_CHOICE,
         .dst = &o->format,
         .val = BATCH_VDB,
         .choices = "vdb|exr",
         .needs = "vdb or exr"},
        {.names = "--preview", .kind = CLI_FLAG, .dst = &o->preview, .val = 1},
        {.names = "--mesh-out-format",
         .kind = CLI_CHOICE,
         .dst = &o->mesh_format,
         .val = BATCH_MESH_OBJ,
         .choices = "obj|ply|stl",
         .needs = "obj, ply or stl"},
        {.names = "--adaptivity",
         .kind = CLI_DOUBLE,
         .dst = &o->adaptivity,
         .max = 1,
         .needs = "a number in [0, 1]"},
        {.names = NULL},
    };
    memcpy(t, rows, sizeof rows);
}

int batch_opt_arity(const char *name)
{
    batch_opts o;
    cli_opt t[JOB_OPTS + 1];
    job_options(&o, t);
    const cli_opt *r = cli_find_opt(t, name);
    return r ? cli_opt_arity(r) : -1;
}

int batch_opts_forward(cli_opt *t, int (*fn)(const char *, const char *, char **, int, void *),
                       void *dst)
{
    batch_opts o;
    job_options(&o, t);
    for (int i = 0; i < JOB_OPTS; i++) {
        const int k = cli_opt_arity(&t[i]);
        t[i] = (cli_opt){.names = t[i].names,
                         .kind = CLI_FN,
                         .dst = dst,
                         .val = k,
                         .fn = fn,
                         .needs = t[i].needs,
                         .choices = cli_opt_choices(&t[i]),
                         .files = t[i].files};
    }
    return JOB_OPTS;
}

int batch_opts_parse(int argc, char **argv, batch_opts *o, char *err, size_t errsize)
{
    cli_opt t[JOB_OPTS + 1];
    job_options(o, t);
    return cli_parse_quiet(argc, argv, t, err, errsize);
}

int batch_opts_check(const batch_opts *o, char *err, size_t errsize)
{
    if (o->mesh_format != BATCH_MESH_NONE && o->sdf.unsigned_distance)
        return bad(err, errsize,
                   "--mesh-out-format needs a signed distance: an unsigned one has no zero "
                   "level set (drop --unsigned)");
    return 0;
}

void batch_opts_canonical(const batch_opts *o, char *buf, size_t size)
{
    const hv_sdf_opts *s = &o->sdf;
    int n = snprintf(buf, size,
                     "res=%d voxel_size=%.17g pad=%d round_to=%d unsigned=%d magnitude=%d "
                     "t_scale=%.17g far_levels=%d repair=%u backend=%s diffuse_tol=%.17g "
                     "poisson_tol=%.17g format=%s preview=%d",
                     s->voxel_size > 0 ? 0 : s->res, s->voxel_size, s->use_bbox ? 0 : s->pad,
                     s->round_to, s->unsigned_distance, (int)s->magnitude, s->t_scale,
                     s->far_levels, s->repair, hv_backend_name(s->backend), s->diffuse_tol,
                     s->poisson_tol, batch_ext(o->format) + 1, o->preview);
    if (n > 0 && (size_t)n < size && s->use_bbox)
        n += snprintf(buf + n, size - (size_t)n, " bbox=%.17g,%.17g,%.17g,%.17g,%.17g,%.17g",
                      s->bbox[0], s->bbox[1], s->bbox[2], s->bbox[3], s->bbox[4], s->bbox[5]);
    if (n > 0 && (size_t)n < size && o->format == BATCH_VDB)
        n += snprintf(buf + n, size - (size_t)n, " band=%.17g dense=%d", o->band, o->dense);
    /* Only with a mesh, so that the hashes of outputs without one stay as they were. */
    if (n > 0 && (size_t)n < size && s->orient != HV_ORIENT_AUTO) /* hashes as before without it */
        n += snprintf(buf + n, size - (size_t)n, " orient=%d", (int)s->orient);
    if (n > 0 && (size_t)n < size && o->mesh_format != BATCH_MESH_NONE)
        snprintf(buf + n, size - (size_t)n, " mesh=%s adaptivity=%.17g", mesh_exts[o->mesh_format],
                 o->adaptivity);
}

void batch_hash(const char *text, char hex[17])
{
    uint64_t h = 0xcbf29ce484222325ull;
    for (const unsigned char *p = (const unsigned char *)text; *p; p++)
        h = (h ^ *p) * 0x100000001b3ull;
    snprintf(hex, 17, "%016llx", (unsigned long long)h);
}

const char *batch_ext(int format) { return format == BATCH_VDB ? ".vdb" : ".exr"; }

void batch_sidecar_path(const char *output, char *buf, size_t size)
{
    snprintf(buf, size, "%s.heatvox.json", output);
}

void batch_preview_path(const char *output, char *buf, size_t size)
{
    const char *slash = strrchr(output, '/');
    const char *dot = strrchr(output, '.');
    int len = dot && (!slash || dot > slash) ? (int)(dot - output) : (int)strlen(output);
    snprintf(buf, size, "%.*s.png", len, output);
}

void batch_mesh_path(const char *output, int mesh_format, char *buf, size_t size)
{
    const char *slash = strrchr(output, '/');
    const char *dot = strrchr(output, '.');
    int len = dot && (!slash || dot > slash) ? (int)(dot - output) : (int)strlen(output);
    snprintf(buf, size, "%.*s.%s", len, output,
             mesh_format > BATCH_MESH_NONE && mesh_format <= BATCH_MESH_STL ? mesh_exts[mesh_format]
                                                                            : "mesh");
}

/* ---- resume ---- */

static int newer_or_same(const struct stat *a, const struct stat *b)
{
    if (a->st_mtim.tv_sec != b->st_mtim.tv_sec)
        return a->st_mtim.tv_sec > b->st_mtim.tv_sec;
    return a->st_mtim.tv_nsec >= b->st_mtim.tv_nsec;
}

static char *read_small_file(const char *path, size_t max)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    char *s = malloc(max + 1);
    size_t n = s ? fread(s, 1, max, f) : 0;
    fclose(f);
    if (s)
        s[n] = '\0';
    return s;
}

int batch_up_to_date(const char *input, const char *output, const batch_opts *o, const char *hash)
{
    struct stat si, so;
    if (stat(input, &si) != 0 || stat(output, &so) != 0 || !newer_or_same(&so, &si))
        return 0;
    char side[4200];
    batch_sidecar_path(output, side, sizeof side);
    char *text = read_small_file(side, 1 << 16);
    if (!text)
        return 0;
    batch_buf want_input = {0}, want_hash = {0};
    bb_printf(&want_input, "\"input\":");
    bb_json_string(&want_input, input);
    bb_printf(&want_hash, "\"options_hash\":\"%s\"", hash);
    int ok = want_input.s && want_hash.s && strstr(text, want_input.s) && strstr(text, want_hash.s);
    bb_free(&want_input);
    bb_free(&want_hash);
    free(text);
    if (ok && o->preview) {
        char png[4200];
        struct stat sp;
        batch_preview_path(output, png, sizeof png);
        ok = stat(png, &sp) == 0 && newer_or_same(&sp, &si);
    }
    if (ok && o->mesh_format != BATCH_MESH_NONE) {
        char mesh[4200];
        struct stat sm;
        batch_mesh_path(output, o->mesh_format, mesh, sizeof mesh);
        ok = stat(mesh, &sm) == 0 && newer_or_same(&sm, &si);
    }
    return ok;
}

/* ---- the job ---- */

int batch_mkdirs(const char *dir)
{
    char d[4096];
    if (snprintf(d, sizeof d, "%s", dir) >= (int)sizeof d) {
        errno = ENAMETOOLONG;
        return -1;
    }
    for (char *p = d + 1; *p; p++)
        if (*p == '/') {
            *p = '\0';
            if (mkdir(d, 0777) != 0 && errno != EEXIST)
                return -1;
            *p = '/';
        }
    if (mkdir(d, 0777) != 0 && errno != EEXIST)
        return -1;
    return 0;
}

/* Creates the directory that will hold `path`. */
static int mkdir_parents(const char *path)
{
    char dir[4096];
    snprintf(dir, sizeof dir, "%s", path);
    char *slash = strrchr(dir, '/');
    if (!slash || slash == dir)
        return 0;
    *slash = '\0';
    return batch_mkdirs(dir);
}

/* Message of the last library error, starting with the file name. */
static void error_text(hv_status st, const char *file, char *buf, size_t size)
{
    const char *msg = hv_last_error();
    size_t fl = strlen(file);
    if (!strncmp(msg, file, fl) && msg[fl] == ':')
        snprintf(buf, size, "%s", msg);
    else
        snprintf(buf, size, "%s: %s%s%s", file, hv_status_str(st), *msg ? ": " : "", msg);
}

static int write_sidecar(const char *input, const char *output, const char *canon, const char *hash,
                         double seconds, char *err, size_t errsize)
{
    char side[4200], tmp[4200];
    batch_sidecar_path(output, side, sizeof side);
    hv_status st = hv_tmp_name(side, tmp, sizeof tmp);
    if (st) {
        error_text(st, side, err, errsize);
        return -1;
    }
    batch_buf b = {0};
    bb_printf(&b, "{\"heatvox\":\"%s\",\"input\":", hv_version());
    bb_json_string(&b, input);
    bb_printf(&b, ",\"output\":");
    bb_json_string(&b, output);
    bb_printf(&b, ",\"options\":");
    bb_json_string(&b, canon);
    bb_printf(&b, ",\"options_hash\":\"%s\",\"seconds\":%.3f}\n", hash, seconds);
    FILE *f = fopen(tmp, "w");
    int ok = f && b.s && fputs(b.s, f) >= 0;
    if (f && fclose(f) != 0)
        ok = 0;
    bb_free(&b);
    if (!ok) {
        hv_tmp_discard(tmp);
        snprintf(err, errsize, "%.900s: cannot write the sidecar: %s", side, strerror(errno));
        return -1;
    }
    if ((st = hv_tmp_commit(tmp, side)) != HV_OK) {
        error_text(st, side, err, errsize);
        return -1;
    }
    return 0;
}

/* The volume: w already holds the band streamed into it (wants_tiles), else
 * the dense grid g goes in. */
static int write_volume(const char *output, const hv_grid *g, hv_vdb_writer *w, const batch_opts *o,
                        const char *input, const char *canon, char *err, size_t errsize)
{
    hv_status st = HV_OK;
    if (o->format == BATCH_EXR) {
        st = hv_exr_write(output, g, "distance");
    } else {
        if (!w && !(st = hv_vdb_writer_create(&w)))
            st = hv_vdb_writer_add_levelset(w, g, "sdf", o->band, o->dense);
        if (!st)
            st = hv_vdb_writer_set_meta(w, "source", input);
        if (!st)
            st = hv_vdb_writer_set_meta(w, "heatvox_options", canon);
        if (!st)
            st = hv_vdb_writer_write(w, output);
        hv_vdb_writer_destroy(&w);
    }
    if (st) {
        error_text(st, output, err, errsize);
        return -1;
    }
    return 0;
}

/* One job: what it computed, how long each stage took, and where it stopped. */
typedef struct job {
    const char *input, *output;
    batch_opts o;
    char err[1024], canon[1024], hash[17];
    const char *stage; /* the stage that failed, NULL once all are done */
    double t0, t_read, t_report, t_write, t_preview, t_mesh;
    char mesh_path[4200];
    size_t mesh_tris;
    int have_mesh, have_rep, have_stats;
    hv_mesh *m;
    hv_grid *g;
    hv_vdb_writer *w; /* the band streamed in as it was computed (wants_tiles) */
    hv_mesh_report rep;
    hv_sdf_stats stats;
    hv_points_report points; /* points.points > 0 for a point cloud */
} job;

/* A cloud's mesh is its own surface (heatvox sdf --mesh-out's rule). */
static int own_surface(const job *J)
{
    return J->o.mesh_format != BATCH_MESH_NONE &&
           cli_own_surface(&J->points, &J->o.sdf, J->o.adaptivity);
}

/* A narrow-band .vdb alone (and a cloud's own surface beside it) is
 * computed in tiles where the options allow (the rule of heatvox sdf and
 * the library, hv_sdf_tiles_refusal). */
static int wants_tiles(const job *J)
{
    const batch_opts *o = &J->o;
    return o->format == BATCH_VDB && !o->dense && !o->preview &&
           (o->mesh_format == BATCH_MESH_NONE || own_surface(J)) &&
           !hv_sdf_tiles_refusal(&o->sdf, 1);
}

/* The zero level set as a mesh beside the volume (a cloud's: its surface). */
static int job_mesh(job *J)
{
    J->stage = "mesh";
    batch_mesh_path(J->output, J->o.mesh_format, J->mesh_path, sizeof J->mesh_path);
    double t = hv_now();
    hv_mesh *iso = NULL;
    hv_status st = own_surface(J) ? HV_OK : hv_grid_to_mesh(J->g, 0.0, J->o.adaptivity, &iso);
    if (!st) {
        const hv_mesh *m = iso ? iso : J->m;
        J->mesh_tris = m->ntris;
        st = hv_mesh_write(m, J->mesh_path);
    }
    hv_mesh_destroy(&iso);
    J->t_mesh = hv_now() - t;
    if (st) {
        error_text(st, J->mesh_path, J->err, sizeof J->err);
        return -1;
    }
    J->have_mesh = 1;
    return 0;
}

/* The volume and what goes beside it: preview, mesh, and last the sidecar,
 * so that an output whose preview or mesh failed is not taken as up to
 * date. */
static int job_write(job *J)
{
    J->stage = "write";
    if (mkdir_parents(J->output) != 0) {
        snprintf(J->err, sizeof J->err, "%s: cannot create its directory: %s", J->output,
                 strerror(errno));
        return -1;
    }
    double t = hv_now();
    int wr = write_volume(J->output, J->g, J->w, &J->o, J->input, J->canon, J->err, sizeof J->err);
    J->w = NULL; /* write_volume took it */
    J->t_write = hv_now() - t;
    if (wr)
        return -1;
    if (J->o.preview) {
        J->stage = "preview";
        char png[4200];
        batch_preview_path(J->output, png, sizeof png);
        t = hv_now();
        hv_status st = hv_png_write_preview(png, J->g, 0);
        J->t_preview = hv_now() - t;
        if (st) {
            error_text(st, png, J->err, sizeof J->err);
            return -1;
        }
    }
    if (J->o.mesh_format != BATCH_MESH_NONE && job_mesh(J))
        return -1;
    J->stage = "sidecar";
    return write_sidecar(J->input, J->output, J->canon, J->hash, hv_now() - J->t0, J->err,
                         sizeof J->err);
}

/* The narrow band, in tiles streamed into the .vdb writer's level set. */
static hv_status job_stream(job *J)
{
    hv_tiles_sink sink;
    hv_status st;
    if ((st = hv_vdb_writer_create(&J->w)) ||
        (st = hv_vdb_writer_levelset_sink(J->w, "sdf", J->o.band, NULL, &sink)))
        return st;
    return hv_sdf_stream_tiles(J->m, &J->o.sdf, J->o.band, &sink, &J->stats);
}

/* Reads the mesh, reports its defects, computes the distance and writes. */
static int job_run(job *J)
{
    J->stage = "read";
    double t = hv_now();
    hv_status st = cli_read_shape(J->input, &J->o.sdf, &J->m, &J->points);
    J->t_read = hv_now() - t;
    if (st) {
        error_text(st, J->input, J->err, sizeof J->err);
        return -1;
    }
    if (!J->points.points)
        cli_mesh_units(NULL, J->input, J->m, J->o.units);
    t = hv_now();
    J->have_rep = hv_mesh_report_compute(J->m, &J->rep) == HV_OK;
    J->t_report = hv_now() - t;
    J->stage = "sdf";
    st = wants_tiles(J) ? job_stream(J) : hv_sdf_compute(J->m, &J->o.sdf, &J->g, &J->stats);
    if (st) {
        error_text(st, J->input, J->err, sizeof J->err);
        return -1;
    }
    J->have_stats = 1;
    if (job_write(J))
        return -1;
    J->stage = NULL;
    return 0;
}

static void report_times(batch_buf *b, const job *J)
{
    const hv_sdf_stats *s = &J->stats;
    bb_printf(b, ",\"seconds\":{\"read\":%.4f,\"report\":%.4f", J->t_read, J->t_report);
    if (J->have_stats)
        bb_printf(b,
                  ",\"repair\":%.4f,\"splat\":%.4f,\"diffuse\":%.4f,\"normalize\":%.4f"
                  ",\"poisson\":%.4f,\"shift\":%.4f,\"redistance\":%.4f,\"sdf\":%.4f",
                  s->t_repair, s->t_splat, s->t_diffuse, s->t_normalize, s->t_poisson, s->t_shift,
                  s->t_redistance, s->t_total);
    bb_printf(b, ",\"write\":%.4f,\"preview\":%.4f,\"mesh\":%.4f,\"total\":%.4f}", J->t_write,
              J->t_preview, J->t_mesh, hv_now() - J->t0);
}

static void report_defects(batch_buf *b, const job *J)
{
    const hv_mesh_report *r = &J->rep;
    if (!J->have_rep) {
        bb_printf(b, ",\"defects\":null");
        return;
    }
    bb_printf(b,
              ",\"defects\":{\"vertices\":%zu,\"triangles\":%zu,\"boundary_edges\":%zu"
              ",\"nonmanifold_edges\":%zu,\"inconsistent_edges\":%zu,\"duplicate_faces\":%zu"
              ",\"degenerate_faces\":%zu,\"nonfinite_vertices\":%zu,\"components\":%zu}",
              r->vertices, r->triangles, r->boundary_edges, r->nonmanifold_edges,
              r->inconsistent_edges, r->duplicate_faces, r->degenerate_faces, r->nonfinite_vertices,
              r->components);
}

/* The repair's and the solver's counts, and the tiles of a narrow band. */
static void report_repair(batch_buf *b, const job *J)
{
    const hv_sdf_stats *s = &J->stats;
    const hv_sdf_repair_report *r = &s->repair;
    bb_printf(b,
              ",\"repair\":{\"vertices_welded\":%zu,\"degenerate_removed\":%zu"
              ",\"duplicates_removed\":%zu,\"faces_flipped\":%zu,\"components_flipped\":%zu"
              ",\"holes_filled\":%zu,\"holes_left_open\":%zu"
              ",\"boundary_edges\":%zu,\"inconsistent_after\":%zu}"
              ",\"solver\":{\"levels\":%d,\"diffuse_iterations\":%d,\"diffuse_relres\":%.3g"
              ",\"poisson_iterations\":%d,\"poisson_relres\":%.3g,\"dead_faces\":%zu}",
              r->vertices_welded, r->degenerate_removed, r->duplicates_removed, r->faces_flipped,
              r->components_flipped, r->holes_filled, r->holes_left_open, r->boundary_edges,
              r->inconsistent_after, s->levels, s->diffuse_iterations, s->diffuse_relres,
              s->poisson_iterations, s->poisson_relres, s->dead_faces);
    if (s->tiles)
        bb_printf(b, ",\"tiles\":%zu,\"active_voxels\":%zu,\"sign\":\"%s\"", s->tiles,
                  s->active_voxels, cli_sign_name(s->sign));
}

/* A point cloud's surface: the points, their spacing, the normals turned. */
static void report_points(batch_buf *b, const job *J)
{
    const hv_points_report *p = &J->points;
    if (!p->points)
        return;
    bb_printf(b,
              ",\"points\":{\"count\":%zu,\"spacing\":%.9g,\"normals_turned\":%zu"
              ",\"normal_agreement\":%.6f,\"vertices_unsupported\":%zu,\"orientation\":\"%s\""
              ",\"orient_rounds\":%d,\"orient_seconds\":%.3f,\"orient_spread\":%.4f"
              ",\"orient_lines\":%s,\"orient_thin_votes\":%zu,\"orient_thin_turned\":%zu}",
              p->points, p->spacing_median, p->normals_against, p->normal_agreement,
              p->vertices_unsupported, p->recovered ? "recovered" : "given", p->orient_rounds,
              p->t_orient, p->orient_spread, p->orient_lines ? "true" : "false",
              p->orient_thin_votes, p->orient_thin_turned);
}

/* The job's JSON line on stdout (batch --report's format). */
static void report_line(const job *J)
{
    const int ok = J->stage == NULL;
    const hv_sdf_stats *s = &J->stats;
    batch_buf b = {0};
    bb_printf(&b, "{\"file\":");
    bb_json_string(&b, J->input);
    bb_printf(&b, ",\"output\":");
    bb_json_string(&b, J->output);
    bb_printf(&b, ",\"status\":\"%s\",\"error\":", ok ? "ok" : "failed");
    bb_json_string(&b, ok ? NULL : J->err);
    bb_printf(&b, ",\"stage\":");
    bb_json_string(&b, J->stage);
    bb_printf(&b, ",\"options\":");
    bb_json_string(&b, J->canon);
    bb_printf(&b, ",\"options_hash\":\"%s\"", J->hash);
    if (J->have_stats)
        bb_printf(&b,
                  ",\"grid\":[%d,%d,%d],\"voxel_size\":%.17g,\"origin\":[%.17g,%.17g,%.17g]"
                  ",\"backend\":\"%s\"",
                  s->n[0], s->n[1], s->n[2], s->h, s->origin[0], s->origin[1], s->origin[2],
                  hv_backend_name(s->backend));
    else
        bb_printf(&b, ",\"grid\":null");
    report_times(&b, J);
    if (J->have_mesh) {
        bb_printf(&b, ",\"mesh\":{\"output\":");
        bb_json_string(&b, J->mesh_path);
        bb_printf(&b, ",\"triangles\":%zu,\"adaptivity\":%.17g}", J->mesh_tris, J->o.adaptivity);
    } else {
        bb_printf(&b, ",\"mesh\":null");
    }
    report_defects(&b, J);
    if (J->have_stats)
        report_repair(&b, J);
    report_points(&b, J);
    bb_printf(&b, "}\n");
    if (b.s)
        fputs(b.s, stdout);
    fflush(stdout);
    bb_free(&b);
}

int batch_job_main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "heatvox batch --job: needs INPUT OUTPUT [options]\n");
        return HV_EXIT_USAGE;
    }
    job *J = calloc(1, sizeof *J);
    char **rest = malloc(sizeof(char *) * (size_t)(argc + 1));
    if (!J || !rest) {
        free(J);
        free(rest);
        fprintf(stderr, "heatvox batch --job: out of memory\n");
        return HV_EXIT_FAIL;
    }
    J->input = argv[0];
    J->output = argv[1];
    J->t0 = hv_now();
    batch_opts_default(&J->o);
    /* -q / -v are for the driver; the job prints only its report line. */
    int nrest = 0;
    for (int i = 2; i < argc; i++)
        if (strcmp(argv[i], "-q") && strcmp(argv[i], "-v"))
            rest[nrest++] = argv[i];
    J->stage = "options";
    int parsed = batch_opts_parse(nrest, rest, &J->o, J->err, sizeof J->err) == 0 &&
                 batch_opts_check(&J->o, J->err, sizeof J->err) == 0;
    free(rest);
    batch_opts_canonical(&J->o, J->canon, sizeof J->canon);
    batch_hash(J->canon, J->hash);
    if (parsed)
        job_run(J);
    report_line(J);
    const int ok = J->stage == NULL;
    hv_grid_destroy(&J->g);
    hv_vdb_writer_destroy(&J->w);
    hv_mesh_destroy(&J->m);
    free(J);
    return ok ? HV_EXIT_OK : HV_EXIT_FAIL;
}
