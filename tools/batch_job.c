/* heatvox batch: job options, the resume sidecar, and the job one worker runs;
 * also the text helpers the batch files share. */
#include "batch.h"
#include "cli.h"

#include <errno.h>
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

static const struct {
    const char *name;
    int nargs;
} job_options[] = {
    {"--res", 1},         {"--voxel-size", 1},  {"--pad", 1},       {"--bbox", 6},
    {"--round-to", 1},    {"--unsigned", 0},    {"--heat", 0},      {"--exact", 0},
    {"--t-scale", 1},     {"--far-levels", 1},  {"--no-repair", 0}, {"--backend", 1},
    {"--diffuse-tol", 1}, {"--poisson-tol", 1}, {"--threads", 1},   {"--band", 1},
    {"--dense", 0},       {"--format", 1},      {"--preview", 0},   {"--mesh-out-format", 1},
    {"--adaptivity", 1},
};

static const char *const mesh_exts[] = {NULL, "obj", "ply", "stl"};

void batch_opts_default(batch_opts *o)
{
    memset(o, 0, sizeof *o);
    hv_sdf_opts_default(&o->sdf);
    o->format = BATCH_VDB;
    o->band = 3.0;
}

int batch_opt_arity(const char *name)
{
    for (size_t i = 0; i < sizeof job_options / sizeof job_options[0]; i++)
        if (!strcmp(name, job_options[i].name))
            return job_options[i].nargs;
    return -1;
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

int batch_opts_parse(int argc, char **argv, batch_opts *o, char *err, size_t errsize)
{
    for (int i = 0; i < argc; i++) {
        const char *a = argv[i];
        int k = batch_opt_arity(a);
        if (k < 0)
            return bad(err, errsize, "unknown option '%s'", a);
        if (i + k >= argc)
            return bad(err, errsize, "%s needs %d value%s", a, k, k > 1 ? "s" : "");
        char **v = argv + i + 1;
        i += k;
        int iv = 0;
        double dv = 0;
        if (!strcmp(a, "--res")) {
            if (cli_parse_int(v[0], &iv) || iv < 2)
                return bad(err, errsize, "--res must be an integer >= 2, got '%s'", v[0]);
            o->sdf.res = iv;
            o->sdf.voxel_size = 0;
        } else if (!strcmp(a, "--voxel-size")) {
            if (cli_parse_double(v[0], &dv) || !(dv > 0))
                return bad(err, errsize, "--voxel-size must be positive, got '%s'", v[0]);
            o->sdf.voxel_size = dv;
        } else if (!strcmp(a, "--pad")) {
            if (cli_parse_int(v[0], &iv) || iv < 0)
                return bad(err, errsize, "--pad must be an integer >= 0, got '%s'", v[0]);
            o->sdf.pad = iv;
        } else if (!strcmp(a, "--bbox")) {
            for (int d = 0; d < 6; d++)
                if (cli_parse_double(v[d], &o->sdf.bbox[d]))
                    return bad(err, errsize, "--bbox value '%s' is not a number", v[d]);
            for (int d = 0; d < 3; d++)
                if (!(o->sdf.bbox[d] < o->sdf.bbox[d + 3]))
                    return bad(err, errsize, "--bbox: the %c range is empty", "xyz"[d]);
            o->sdf.use_bbox = 1;
        } else if (!strcmp(a, "--round-to")) {
            if (cli_parse_int(v[0], &iv) || iv < 1)
                return bad(err, errsize, "--round-to must be an integer >= 1, got '%s'", v[0]);
            o->sdf.round_to = iv;
        } else if (!strcmp(a, "--unsigned")) {
            o->sdf.unsigned_distance = 1;
        } else if (!strcmp(a, "--heat")) {
            o->sdf.magnitude = HV_SDF_HEAT;
        } else if (!strcmp(a, "--exact")) {
            o->sdf.magnitude = HV_SDF_EXACT;
        } else if (!strcmp(a, "--t-scale")) {
            if (cli_parse_double(v[0], &dv) || !(dv > 0))
                return bad(err, errsize, "--t-scale must be positive, got '%s'", v[0]);
            o->sdf.t_scale = dv;
        } else if (!strcmp(a, "--far-levels")) {
            if (cli_parse_int(v[0], &iv) || iv < -1)
                return bad(err, errsize, "--far-levels must be an integer >= -1, got '%s'", v[0]);
            o->sdf.far_levels = iv;
        } else if (!strcmp(a, "--no-repair")) {
            o->sdf.repair = 0;
        } else if (!strcmp(a, "--backend")) {
            char msg[160];
            if (cli_backend_value(v[0], CLI_BACKENDS_LOCAL, &o->sdf.backend, msg, sizeof msg))
                return bad(err, errsize, "%s", msg);
        } else if (!strcmp(a, "--diffuse-tol") || !strcmp(a, "--poisson-tol")) {
            if (cli_parse_double(v[0], &dv) || !(dv >= 1e-12) || dv >= 1)
                return bad(err, errsize, "%s must be in [1e-12, 1), got '%s'", a, v[0]);
            *(a[2] == 'd' ? &o->sdf.diffuse_tol : &o->sdf.poisson_tol) = dv;
        } else if (!strcmp(a, "--threads")) {
            if (cli_parse_threads(v[0], 0, &iv))
                return bad(err, errsize, "--threads must be an integer in [0, %d], got '%s'",
                           HV_MAX_THREADS, v[0]);
            o->sdf.threads = iv;
        } else if (!strcmp(a, "--band")) {
            if (cli_parse_double(v[0], &dv) || !(dv > 0))
                return bad(err, errsize, "--band must be positive (voxels), got '%s'", v[0]);
            o->band = dv;
        } else if (!strcmp(a, "--dense")) {
            o->dense = 1;
        } else if (!strcmp(a, "--format")) {
            if (!strcmp(v[0], "vdb"))
                o->format = BATCH_VDB;
            else if (!strcmp(v[0], "exr"))
                o->format = BATCH_EXR;
            else
                return bad(err, errsize, "--format must be vdb or exr, got '%s'", v[0]);
        } else if (!strcmp(a, "--preview")) {
            o->preview = 1;
        } else if (!strcmp(a, "--mesh-out-format")) {
            o->mesh_format = BATCH_MESH_NONE;
            for (int f = BATCH_MESH_OBJ; f <= BATCH_MESH_STL; f++)
                if (!strcmp(v[0], mesh_exts[f]))
                    o->mesh_format = f;
            if (o->mesh_format == BATCH_MESH_NONE)
                return bad(err, errsize, "--mesh-out-format must be obj, ply or stl, got '%s'",
                           v[0]);
        } else if (!strcmp(a, "--adaptivity")) {
            if (cli_parse_double(v[0], &dv) || dv < 0 || dv > 1)
                return bad(err, errsize, "--adaptivity must be in [0, 1], got '%s'", v[0]);
            o->adaptivity = dv;
        }
    }
    return 0;
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

/* A narrow-band .vdb alone is computed in tiles (heatvox sdf does the same). */
static int wants_tiles(const batch_opts *o)
{
    const unsigned orient = HV_SDF_REPAIR_ORIENT | HV_SDF_REPAIR_OUTWARD;
    return o->format == BATCH_VDB && !o->dense && !o->preview &&
           o->mesh_format == BATCH_MESH_NONE && !o->sdf.unsigned_distance &&
           o->sdf.magnitude == HV_SDF_EXACT && o->sdf.sign != HV_SDF_SIGN_HEAT &&
           (o->sdf.repair & orient) == orient;
}

static int write_volume(const char *output, const hv_grid *g, const hv_tiles *T,
                        const batch_opts *o, const char *input, const char *canon, char *err,
                        size_t errsize)
{
    hv_status st;
    if (o->format == BATCH_EXR) {
        st = hv_exr_write(output, g, "distance");
    } else {
        hv_vdb_writer *w = NULL;
        st = hv_vdb_writer_create(&w);
        if (!st)
            st = T ? hv_vdb_writer_add_levelset_tiles(w, T, "sdf", o->band)
                   : hv_vdb_writer_add_levelset(w, g, "sdf", o->band, o->dense);
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

int batch_job_main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "heatvox batch --job: needs INPUT OUTPUT [options]\n");
        return HV_EXIT_USAGE;
    }
    const char *input = argv[0], *output = argv[1];
    double t0 = hv_now();
    batch_opts o;
    batch_opts_default(&o);
    /* -q / -v are for the driver; the job prints only its report line. */
    char **rest = malloc(sizeof(char *) * (size_t)(argc + 1));
    int nrest = 0;
    for (int i = 2; i < argc; i++)
        if (strcmp(argv[i], "-q") && strcmp(argv[i], "-v"))
            rest[nrest++] = argv[i];
    char err[1024] = "", canon[1024], hash[17];
    const char *stage = "options";
    double t_read = 0, t_report = 0, t_write = 0, t_preview = 0, t_mesh = 0;
    char mesh_path[4200] = "";
    size_t mesh_tris = 0;
    int have_mesh = 0;
    hv_mesh *m = NULL;
    hv_grid *g = NULL;
    hv_tiles *T = NULL;
    hv_mesh_report rep;
    hv_sdf_stats stats;
    int have_rep = 0, have_stats = 0;
    memset(&stats, 0, sizeof stats);
    int parsed = batch_opts_parse(nrest, rest, &o, err, sizeof err) == 0 &&
                 batch_opts_check(&o, err, sizeof err) == 0;
    free(rest);
    batch_opts_canonical(&o, canon, sizeof canon);
    batch_hash(canon, hash);
    hv_status st = HV_OK;
    if (!parsed)
        goto report;
    stage = "read";
    double t = hv_now();
    st = hv_mesh_read(input, &m);
    t_read = hv_now() - t;
    if (st) {
        error_text(st, input, err, sizeof err);
        goto report;
    }
    t = hv_now();
    have_rep = hv_mesh_report_compute(m, &rep) == HV_OK;
    t_report = hv_now() - t;
    stage = "sdf";
    st = wants_tiles(&o) ? hv_sdf_compute_tiles(m, &o.sdf, o.band, &T, &stats)
                         : hv_sdf_compute(m, &o.sdf, &g, &stats);
    if (st) {
        error_text(st, input, err, sizeof err);
        goto report;
    }
    have_stats = 1;
    stage = "write";
    if (mkdir_parents(output) != 0) {
        snprintf(err, sizeof err, "%s: cannot create its directory: %s", output, strerror(errno));
        st = HV_ERR_IO;
        goto report;
    }
    t = hv_now();
    int wr = write_volume(output, g, T, &o, input, canon, err, sizeof err);
    hv_tiles_destroy(&T);
    t_write = hv_now() - t;
    if (wr)
        goto report;
    if (o.preview) {
        stage = "preview";
        char png[4200];
        batch_preview_path(output, png, sizeof png);
        t = hv_now();
        st = hv_png_write_preview(png, g, 0);
        t_preview = hv_now() - t;
        if (st) {
            error_text(st, png, err, sizeof err);
            goto report;
        }
    }
    if (o.mesh_format != BATCH_MESH_NONE) {
        stage = "mesh";
        batch_mesh_path(output, o.mesh_format, mesh_path, sizeof mesh_path);
        t = hv_now();
        hv_mesh *iso = NULL;
        st = hv_grid_to_mesh(g, 0.0, o.adaptivity, &iso);
        if (!st) {
            mesh_tris = iso->ntris;
            st = hv_mesh_write(iso, mesh_path);
        }
        hv_mesh_destroy(&iso);
        t_mesh = hv_now() - t;
        if (st) {
            error_text(st, mesh_path, err, sizeof err);
            goto report;
        }
        have_mesh = 1;
    }
    /* Last, so that an output whose preview or mesh failed is not taken as
     * up to date. */
    stage = "sidecar";
    if (write_sidecar(input, output, canon, hash, hv_now() - t0, err, sizeof err))
        goto report;
    stage = NULL;
report:;
    int ok = stage == NULL;
    batch_buf b = {0};
    bb_printf(&b, "{\"file\":");
    bb_json_string(&b, input);
    bb_printf(&b, ",\"output\":");
    bb_json_string(&b, output);
    bb_printf(&b, ",\"status\":\"%s\",\"error\":", ok ? "ok" : "failed");
    bb_json_string(&b, ok ? NULL : err);
    bb_printf(&b, ",\"stage\":");
    bb_json_string(&b, stage);
    bb_printf(&b, ",\"options\":");
    bb_json_string(&b, canon);
    bb_printf(&b, ",\"options_hash\":\"%s\"", hash);
    if (have_stats)
        bb_printf(&b,
                  ",\"grid\":[%d,%d,%d],\"voxel_size\":%.17g,\"origin\":[%.17g,%.17g,%.17g]"
                  ",\"backend\":\"%s\"",
                  stats.n[0], stats.n[1], stats.n[2], stats.h, stats.origin[0], stats.origin[1],
                  stats.origin[2], hv_backend_name(stats.backend));
    else
        bb_printf(&b, ",\"grid\":null");
    bb_printf(&b, ",\"seconds\":{\"read\":%.4f,\"report\":%.4f", t_read, t_report);
    if (have_stats)
        bb_printf(&b,
                  ",\"repair\":%.4f,\"splat\":%.4f,\"diffuse\":%.4f,\"normalize\":%.4f"
                  ",\"poisson\":%.4f,\"shift\":%.4f,\"redistance\":%.4f,\"sdf\":%.4f",
                  stats.t_repair, stats.t_splat, stats.t_diffuse, stats.t_normalize,
                  stats.t_poisson, stats.t_shift, stats.t_redistance, stats.t_total);
    bb_printf(&b, ",\"write\":%.4f,\"preview\":%.4f,\"mesh\":%.4f,\"total\":%.4f}", t_write,
              t_preview, t_mesh, hv_now() - t0);
    if (have_mesh) {
        bb_printf(&b, ",\"mesh\":{\"output\":");
        bb_json_string(&b, mesh_path);
        bb_printf(&b, ",\"triangles\":%zu,\"adaptivity\":%.17g}", mesh_tris, o.adaptivity);
    } else {
        bb_printf(&b, ",\"mesh\":null");
    }
    if (have_rep)
        bb_printf(&b,
                  ",\"defects\":{\"vertices\":%zu,\"triangles\":%zu,\"boundary_edges\":%zu"
                  ",\"nonmanifold_edges\":%zu,\"inconsistent_edges\":%zu,\"duplicate_faces\":%zu"
                  ",\"degenerate_faces\":%zu,\"nonfinite_vertices\":%zu,\"components\":%zu}",
                  rep.vertices, rep.triangles, rep.boundary_edges, rep.nonmanifold_edges,
                  rep.inconsistent_edges, rep.duplicate_faces, rep.degenerate_faces,
                  rep.nonfinite_vertices, rep.components);
    else
        bb_printf(&b, ",\"defects\":null");
    if (have_stats) {
        const hv_sdf_repair_report *r = &stats.repair;
        bb_printf(&b,
                  ",\"repair\":{\"vertices_welded\":%zu,\"degenerate_removed\":%zu"
                  ",\"duplicates_removed\":%zu,\"faces_flipped\":%zu,\"components_flipped\":%zu"
                  ",\"holes_filled\":%zu,\"holes_left_open\":%zu"
                  ",\"boundary_edges\":%zu,\"inconsistent_after\":%zu}"
                  ",\"solver\":{\"levels\":%d,\"diffuse_iterations\":%d,\"diffuse_relres\":%.3g"
                  ",\"poisson_iterations\":%d,\"poisson_relres\":%.3g,\"dead_faces\":%zu}",
                  r->vertices_welded, r->degenerate_removed, r->duplicates_removed,
                  r->faces_flipped, r->components_flipped, r->holes_filled, r->holes_left_open,
                  r->boundary_edges, r->inconsistent_after, stats.levels, stats.diffuse_iterations,
                  stats.diffuse_relres, stats.poisson_iterations, stats.poisson_relres,
                  stats.dead_faces);
        /* A narrow band in tiles: how many, and the voxels in its band. */
        if (stats.tiles)
            bb_printf(&b, ",\"tiles\":%zu,\"active_voxels\":%zu,\"sign\":\"%s\"", stats.tiles,
                      stats.active_voxels, cli_sign_name(stats.sign));
    }
    bb_printf(&b, "}\n");
    if (b.s)
        fputs(b.s, stdout);
    fflush(stdout);
    bb_free(&b);
    hv_grid_destroy(&g);
    hv_tiles_destroy(&T);
    hv_mesh_destroy(&m);
    return ok ? HV_EXIT_OK : HV_EXIT_FAIL;
}
