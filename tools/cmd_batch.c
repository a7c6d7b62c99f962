/* heatvox batch: signed distance volumes for many meshes with a pool of worker
 * processes. Each mesh runs in its own process (`heatvox batch --job ...`,
 * exec'd from /proc/self/exe), so a crash, a hang killed by the user or a bad
 * file costs only that file, and no process forks after OpenVDB or OpenCL has
 * started threads (docs/METHOD.md, "Testing notes"). */
#include "batch.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <poll.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#define MAX_WORKERS 256
#define MAX_DEPTH 64

static void help(void)
{
    printf(
        "usage: heatvox batch INPUT... -o OUTDIR [-j N] [--report FILE] [--dry-run] [--force]\n"
        "                     [-q|-v] [job options]\n"
        "\n"
        "Computes a signed distance volume for every mesh, each in its own worker process.\n"
        "\n"
        "INPUT is a mesh file (.obj .ply .stl .off), a directory (searched recursively for\n"
        "those extensions, hidden entries skipped; the output keeps the sub-directory), or\n"
        "a manifest (.txt or .list): one mesh path per line, relative to the manifest's\n"
        "directory, optionally followed by job options for that mesh alone (they come\n"
        "after the global ones, so they win); '#' starts a comment; quote paths with\n"
        "spaces (\"...\" or '...'). Outputs are OUTDIR/<name>.vdb (or .exr); when two inputs\n"
        "would write the same name, later ones get _2, _3, ...\n"
        "\n"
        "  -o DIR          output directory (created when missing)\n"
        "  -j N            worker processes (default: the number of CPUs); each worker runs\n"
        "                  with CPUs/N threads unless --threads is given\n"
        "  --report FILE   JSON lines, one per input, written as inputs finish: file,\n"
        "                  output, status (ok, failed, skipped, interrupted), error, stage,\n"
        "                  grid, voxel_size, seconds per stage, defects (mesh report before\n"
        "                  repair), repair and solver counts, options and options_hash\n"
        "  --dry-run       list what would run or be skipped; compute nothing\n"
        "  --force         recompute outputs that are up to date\n"
        "  -q / -v         quiet (failures and the summary only) / one line per file\n"
        "\n"
        "job options (global, or per manifest line):\n"
        "  --res N            cells along the longest axis (default 128)\n"
        "  --voxel-size H     voxel size instead of --res\n"
        "  --pad N            cells between the mesh bounds and the block (default 4)\n"
        "  --bbox X0 Y0 Z0 X1 Y1 Z1   block bounds instead of --pad\n"
        "  --round-to N       round cell counts up to a multiple of N (default 8)\n"
        "  --unsigned         unsigned distance\n"
        "  --heat | --exact   magnitude from the heat method, or exact distance with the\n"
        "                     heat method's sign (default)\n"
        "  --t-scale S        diffusion time (S h)^2 (default 1)\n"
        "  --far-levels N     extra diffusion levels (-1 automatic)\n"
        "  --no-repair        no mesh repair before the heat method\n"
        "  --backend B        auto, mg, fftw, opencl\n"
        "  --diffuse-tol T, --poisson-tol T   solver tolerances\n"
        "  --threads N        threads per worker\n"
        "  --format vdb|exr   output format (default vdb: a level set grid \"sdf\", file\n"
        "                     metadata \"source\" and \"heatvox_options\"; exr: the\n"
        "                     multi-part layout of heatvox/image.h, channel \"distance\")\n"
        "  --band N           VDB narrow band half width in voxels (default 3)\n"
        "  --dense            VDB: every voxel active\n"
        "  --preview          also write OUTDIR/<name>.png: middle x, y, z slices\n"
        "\n"
        "Resume: an output is skipped when it exists, is not older than its input, and\n"
        "its sidecar <output>.heatvox.json records the same input and options hash (the\n"
        "options above except --threads); --force recomputes. Outputs, previews and\n"
        "sidecars are written to temporary names and renamed when complete; Ctrl-C stops\n"
        "the workers and removes their temporaries. The report is appended line by line\n"
        "as files finish.\n"
        "\n"
        "Progress: a bar with rate and ETA when stderr is a terminal, else one line per\n"
        "file on stderr. The summary goes to stdout.\n"
        "\n"
        "exit: 0 every input written or up to date, 1 some input failed (each named on\n"
        "stderr with its error), 2 usage error; killed by the signal on Ctrl-C\n"
        "\n"
        "Workers run `heatvox batch --job INPUT OUTPUT [job options]`, which computes one\n"
        "output and prints its report line on stdout (exit 0 ok, 1 failed).\n");
}

/* ---- jobs ---- */

typedef struct job {
    char *input;
    char *stem;    /* output path without extension */
    char *output;
    char **args;   /* per-line options, owned */
    int nargs;
    batch_opts opts;
    char hash[17];
    char *error;   /* planning error: the job fails without running */
    int skip;
    int state;     /* 0 pending, 1 running, 2 done */
} job;

typedef struct joblist {
    job *v;
    size_t n, cap;
} joblist;

static char *xstrdup(const char *s)
{
    char *d = strdup(s);
    if (!d) {
        fprintf(stderr, "heatvox batch: out of memory\n");
        exit(HV_EXIT_FAIL);
    }
    return d;
}

static char *xprintf(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
static char *xprintf(const char *fmt, ...)
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

static job *add_job(joblist *l, const char *input, const char *stem)
{
    if (l->n == l->cap) {
        l->cap = l->cap ? 2 * l->cap : 64;
        job *v = realloc(l->v, l->cap * sizeof *v);
        if (!v) {
            fprintf(stderr, "heatvox batch: out of memory\n");
            exit(HV_EXIT_FAIL);
        }
        l->v = v;
    }
    job *j = &l->v[l->n++];
    memset(j, 0, sizeof *j);
    j->input = xstrdup(input);
    j->stem = xstrdup(stem);
    return j;
}

static void free_jobs(joblist *l)
{
    for (size_t i = 0; i < l->n; i++) {
        job *j = &l->v[i];
        free(j->input);
        free(j->stem);
        free(j->output);
        free(j->error);
        for (int a = 0; a < j->nargs; a++)
            free(j->args[a]);
        free(j->args);
    }
    free(l->v);
}

static int has_ext(const char *path, const char *const *exts)
{
    const char *slash = strrchr(path, '/');
    const char *dot = strrchr(path, '.');
    if (!dot || (slash && dot < slash))
        return 0;
    for (; *exts; exts++)
        if (!strcasecmp(dot + 1, *exts))
            return 1;
    return 0;
}

static const char *const mesh_exts[] = {"obj", "ply", "stl", "off", NULL};
static const char *const manifest_exts[] = {"txt", "list", NULL};

/* "dir/name.ext" -> "name" */
static char *stem_of(const char *path)
{
    const char *slash = strrchr(path, '/');
    const char *base = slash ? slash + 1 : path;
    const char *dot = strrchr(base, '.');
    size_t len = dot && dot != base ? (size_t)(dot - base) : strlen(base);
    return xprintf("%.*s", (int)len, base);
}

static int by_name(const struct dirent **a, const struct dirent **b)
{
    return strcmp((*a)->d_name, (*b)->d_name);
}

static void walk(joblist *l, const char *dir, const char *rel, const char *outdir, int depth)
{
    struct dirent **names = NULL;
    int n = scandir(dir, &names, NULL, by_name);
    if (n < 0) {
        job *j = add_job(l, dir, dir);
        j->error = xprintf("%s: cannot read the directory: %s", dir, strerror(errno));
        return;
    }
    for (int i = 0; i < n; i++) {
        const char *name = names[i]->d_name;
        if (name[0] != '.') {
            char *path = xprintf("%s/%s", dir, name);
            char *sub = xprintf("%s%s%s", rel, *rel ? "/" : "", name);
            struct stat sb;
            if (stat(path, &sb) == 0 && S_ISDIR(sb.st_mode)) {
                if (depth < MAX_DEPTH)
                    walk(l, path, sub, outdir, depth + 1);
            } else if (has_ext(name, mesh_exts)) {
                char *stem = stem_of(name);
                char *out = xprintf("%s/%s%s%s", outdir, rel, *rel ? "/" : "", stem);
                add_job(l, path, out);
                free(stem);
                free(out);
            }
            free(path);
            free(sub);
        }
        free(names[i]);
    }
    free(names);
}

/* Splits a manifest line into tokens: whitespace-separated, "..." (with \" and
 * \\) and '...' quoting, '#' at the start of a token ends the line. */
static int split_line(const char *line, char ***out, int *nout, char *err, size_t errsize)
{
    char **toks = NULL;
    int n = 0;
    const char *p = line;
    size_t cap = strlen(line) + 1;
    for (;;) {
        while (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n')
            p++;
        if (!*p || *p == '#')
            break;
        char *tok = malloc(cap);
        size_t k = 0;
        while (*p && *p != ' ' && *p != '\t' && *p != '\r' && *p != '\n') {
            if (*p == '"' || *p == '\'') {
                char q = *p++;
                while (*p && *p != q) {
                    if (q == '"' && *p == '\\' && (p[1] == '"' || p[1] == '\\'))
                        p++;
                    tok[k++] = *p++;
                }
                if (*p != q) {
                    free(tok);
                    for (int i = 0; i < n; i++)
                        free(toks[i]);
                    free(toks);
                    snprintf(err, errsize, "unterminated %c quote", q);
                    return -1;
                }
                p++;
            } else {
                tok[k++] = *p++;
            }
        }
        tok[k] = '\0';
        toks = realloc(toks, sizeof(char *) * (size_t)(n + 1));
        toks[n++] = tok;
    }
    *out = toks;
    *nout = n;
    return 0;
}

static void read_manifest(joblist *l, const char *path, const char *outdir)
{
    FILE *f = fopen(path, "r");
    if (!f) {
        job *j = add_job(l, path, path);
        j->error = xprintf("%s: cannot open the manifest: %s", path, strerror(errno));
        return;
    }
    const char *slash = strrchr(path, '/');
    char *dir = slash ? xprintf("%.*s", (int)(slash - path), path) : xstrdup(".");
    char *line = NULL;
    size_t cap = 0;
    int lineno = 0;
    while (getline(&line, &cap, f) > 0) {
        lineno++;
        char **toks = NULL;
        int n = 0;
        char err[256];
        if (split_line(line, &toks, &n, err, sizeof err)) {
            char *where = xprintf("%s:%d", path, lineno);
            job *j = add_job(l, where, where);
            j->error = xprintf("%s: %s", where, err);
            free(where);
            continue;
        }
        if (n == 0) {
            free(toks);
            continue;
        }
        char *mesh = toks[0][0] == '/' || !strcmp(dir, ".") ? xstrdup(toks[0])
                                                             : xprintf("%s/%s", dir, toks[0]);
        char *stem = stem_of(mesh);
        char *out = xprintf("%s/%s", outdir, stem);
        job *j = add_job(l, mesh, out);
        j->nargs = n - 1;
        j->args = malloc(sizeof(char *) * (size_t)(n > 1 ? n - 1 : 1));
        for (int i = 1; i < n; i++)
            j->args[i - 1] = toks[i];
        free(toks[0]);
        free(toks);
        free(mesh);
        free(stem);
        free(out);
    }
    free(line);
    free(dir);
    fclose(f);
}

/* Parses the options of every job, names its output and decides skips. */
static void plan(joblist *l, int gargc, char **gargv, int force)
{
    for (size_t i = 0; i < l->n; i++) {
        job *j = &l->v[i];
        batch_opts_default(&j->opts);
        char err[512];
        if (!j->error && (batch_opts_parse(gargc, gargv, &j->opts, err, sizeof err) ||
                          batch_opts_parse(j->nargs, j->args, &j->opts, err, sizeof err)))
            j->error = xprintf("%s: %s", j->input, err);
        char canon[1024];
        batch_opts_canonical(&j->opts, canon, sizeof canon);
        batch_hash(canon, j->hash);
    }
    /* Names: later inputs that would overwrite an earlier output get _2, _3, ... */
    for (size_t i = 0; i < l->n; i++) {
        job *j = &l->v[i];
        const char *ext = batch_ext(j->opts.format);
        j->output = xprintf("%s%s", j->stem, ext);
        for (int k = 2;; k++) {
            int clash = 0;
            for (size_t p = 0; p < i && !clash; p++)
                clash = !strcmp(l->v[p].output, j->output);
            if (!clash)
                break;
            free(j->output);
            j->output = xprintf("%s_%d%s", j->stem, k, ext);
        }
    }
    for (size_t i = 0; i < l->n; i++) {
        job *j = &l->v[i];
        struct stat sb;
        if (!j->error && stat(j->input, &sb) != 0)
            j->error = xprintf("%s: cannot open: %s", j->input, strerror(errno));
        else if (!j->error && !S_ISREG(sb.st_mode))
            j->error = xprintf("%s: not a regular file", j->input);
        if (!j->error && !force && batch_up_to_date(j->input, j->output, &j->opts, j->hash))
            j->skip = 1;
    }
}

/* ---- workers ---- */

typedef struct worker {
    pid_t pid;
    int fd[2];         /* stdout, stderr pipes; -1 once closed */
    batch_buf buf[2];
    job *job;
    double t0;
} worker;

static volatile sig_atomic_t stop_signal;
static volatile pid_t worker_pids[MAX_WORKERS];

static void on_stop(int sig)
{
    stop_signal = sig;
    for (int i = 0; i < MAX_WORKERS; i++)
        if (worker_pids[i] > 0)
            kill(worker_pids[i], SIGTERM);
}

static const int stop_signals[] = {SIGINT, SIGTERM, SIGHUP};

static void set_handlers(void (*fn)(int))
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = fn;
    sigemptyset(&sa.sa_mask);
    for (size_t i = 0; i < sizeof stop_signals / sizeof stop_signals[0]; i++)
        sigaction(stop_signals[i], &sa, NULL);
}

static int start_worker(worker *w, int slot, job *j, const char *exe, int gargc, char **gargv,
                        int threads)
{
    int out[2], errp[2];
    if (pipe2(out, O_CLOEXEC) != 0)
        return -1;
    if (pipe2(errp, O_CLOEXEC) != 0) {
        close(out[0]);
        close(out[1]);
        return -1;
    }
    int has_threads = 0;
    for (int i = 0; i < gargc; i++)
        has_threads |= !strcmp(gargv[i], "--threads");
    for (int i = 0; i < j->nargs; i++)
        has_threads |= !strcmp(j->args[i], "--threads");
    char tbuf[16];
    snprintf(tbuf, sizeof tbuf, "%d", threads);
    int argc = 0;
    char **argv = malloc(sizeof(char *) * (size_t)(8 + gargc + j->nargs));
    argv[argc++] = "heatvox";
    argv[argc++] = "batch";
    argv[argc++] = "--job";
    argv[argc++] = j->input;
    argv[argc++] = j->output;
    for (int i = 0; i < gargc; i++)
        argv[argc++] = gargv[i];
    for (int i = 0; i < j->nargs; i++)
        argv[argc++] = j->args[i];
    if (!has_threads) {
        argv[argc++] = "--threads";
        argv[argc++] = tbuf;
    }
    argv[argc] = NULL;

    sigset_t all, old;
    sigfillset(&all);
    sigprocmask(SIG_BLOCK, &all, &old);
    pid_t parent = getpid();
    pid_t pid = fork();
    if (pid == 0) {
        set_handlers(SIG_DFL);
        sigprocmask(SIG_SETMASK, &old, NULL);
        /* A worker must not outlive the driver. */
        prctl(PR_SET_PDEATHSIG, SIGTERM);
        if (getppid() != parent)
            _exit(127);
        dup2(out[1], 1);
        dup2(errp[1], 2);
        execv(exe, argv);
        dprintf(2, "cannot run %s: %s\n", exe, strerror(errno));
        _exit(127);
    }
    int fork_errno = errno;
    if (pid > 0)
        worker_pids[slot] = pid;
    sigprocmask(SIG_SETMASK, &old, NULL);
    free(argv);
    close(out[1]);
    close(errp[1]);
    if (pid < 0) {
        close(out[0]);
        close(errp[0]);
        errno = fork_errno;
        return -1;
    }
    memset(w, 0, sizeof *w);
    w->pid = pid;
    w->fd[0] = out[0];
    w->fd[1] = errp[0];
    w->job = j;
    w->t0 = hv_now();
    j->state = 1;
    return 0;
}

/* Removes temporaries a killed worker left beside target: ".<base>.tmp-<pid>-*"
 * (the naming of hv_tmp_name). */
static void remove_worker_temps(const char *target, pid_t pid)
{
    const char *slash = strrchr(target, '/');
    char *dir = slash ? xprintf("%.*s", (int)(slash - target), target) : xstrdup(".");
    const char *base = slash ? slash + 1 : target;
    char *prefix = xprintf(".%s.tmp-%ld-", base, (long)pid);
    DIR *d = opendir(*dir ? dir : "/");
    struct dirent *e;
    while (d && (e = readdir(d)))
        if (!strncmp(e->d_name, prefix, strlen(prefix))) {
            char *p = xprintf("%s/%s", dir, e->d_name);
            unlink(p);
            free(p);
        }
    if (d)
        closedir(d);
    free(prefix);
    free(dir);
}

static void remove_job_temps(const job *j, pid_t pid)
{
    char path[4200];
    remove_worker_temps(j->output, pid);
    batch_sidecar_path(j->output, path, sizeof path);
    remove_worker_temps(path, pid);
    batch_preview_path(j->output, path, sizeof path);
    remove_worker_temps(path, pid);
}

/* The value of "key":"..." in a JSON line written by the job (unescaped). */
static char *json_field(const char *line, const char *key)
{
    char *pat = xprintf("\"%s\":\"", key);
    const char *p = line ? strstr(line, pat) : NULL;
    free(pat);
    if (!p)
        return NULL;
    p = strchr(p, ':') + 2;
    batch_buf b = {0};
    for (; *p && *p != '"'; p++) {
        if (*p == '\\' && p[1]) {
            p++;
            if (*p == 'n')
                bb_printf(&b, "\n");
            else if (*p == 'u' && strlen(p) >= 5) {
                bb_printf(&b, "?");
                p += 4;
            } else
                bb_printf(&b, "%c", *p);
        } else
            bb_printf(&b, "%c", *p);
    }
    return b.s ? b.s : xstrdup("");
}

/* The last line of text starting with '{'. */
static char *last_json_line(const batch_buf *b)
{
    if (!b->s)
        return NULL;
    char *best = NULL;
    for (char *p = b->s; p && *p;) {
        char *nl = strchr(p, '\n');
        if (*p == '{')
            best = p;
        p = nl ? nl + 1 : NULL;
    }
    if (!best)
        return NULL;
    char *nl = strchr(best, '\n');
    return xprintf("%.*s", nl ? (int)(nl - best) : (int)strlen(best), best);
}

/* ---- progress and report ---- */

typedef struct progress {
    size_t total, done, ok, failed, skipped, to_run, ran;
    double t0, drawn;
    int tty, bar_shown;
    const char *current;
    FILE *report;
} progress;

static void clear_bar(progress *p)
{
    if (p->bar_shown) {
        fputs("\r\033[K", stderr);
        p->bar_shown = 0;
    }
}

/* Redraws the bar, at most ten times a second unless forced. */
static void draw_bar(progress *p, int force)
{
    double now = hv_now();
    if (!p->tty || (!force && now - p->drawn < 0.1))
        return;
    p->drawn = now;
    double el = now - p->t0;
    double rate = el > 0 ? p->ran / el : 0;
    size_t left = p->to_run > p->ran ? p->to_run - p->ran : 0;
    char eta[32] = "--:--";
    if (rate > 0 && p->ran > 0) {
        long s = (long)(left / rate + 0.5);
        snprintf(eta, sizeof eta, "%ld:%02ld", s / 60, s % 60);
    }
    const int width = 24;
    int fill = p->total ? (int)((double)p->done / p->total * width) : width;
    char bar[32];
    for (int i = 0; i < width; i++)
        bar[i] = i < fill ? '#' : '.';
    bar[width] = '\0';
    const char *cur = p->current ? strrchr(p->current, '/') : NULL;
    cur = cur ? cur + 1 : p->current ? p->current : "";
    fprintf(stderr, "\r\033[K[%s] %zu/%zu", bar, p->done, p->total);
    if (p->failed)
        fprintf(stderr, " (%zu failed)", p->failed);
    fprintf(stderr, "  %.2f files/s  ETA %s  %.30s", rate, eta, cur);
    fflush(stderr);
    p->bar_shown = 1;
}

static void report_line(progress *p, const char *line)
{
    if (p->report && line) {
        fputs(line, p->report);
        fputc('\n', p->report);
        fflush(p->report);
    }
}

static void simple_report(progress *p, const job *j, const char *status, const char *error,
                          const char *stage)
{
    batch_buf b = {0};
    bb_printf(&b, "{\"file\":");
    bb_json_string(&b, j->input);
    bb_printf(&b, ",\"output\":");
    bb_json_string(&b, j->output);
    bb_printf(&b, ",\"status\":\"%s\",\"error\":", status);
    bb_json_string(&b, error);
    bb_printf(&b, ",\"stage\":");
    bb_json_string(&b, stage);
    bb_printf(&b, ",\"options_hash\":\"%s\"}", j->hash);
    report_line(p, b.s);
    bb_free(&b);
}

/* One finished input: counts, a line on stderr, the report. */
static void finish(progress *p, job *j, int ok, int skipped, const char *error, double seconds)
{
    p->done++;
    j->state = 2;
    if (skipped)
        p->skipped++;
    else if (ok)
        p->ok++;
    else
        p->failed++;
    clear_bar(p);
    if (!ok && !skipped)
        fprintf(stderr, "heatvox batch: [%zu/%zu] FAILED %s\n", p->done, p->total,
                error ? error : j->input);
    else if (cli_verbose >= 1 || (!p->tty && cli_verbose >= 0)) {
        if (skipped)
            fprintf(stderr, "heatvox batch: [%zu/%zu] up to date %s -> %s\n", p->done, p->total,
                    j->input, j->output);
        else
            fprintf(stderr, "heatvox batch: [%zu/%zu] ok %s -> %s (%.2f s)\n", p->done, p->total,
                    j->input, j->output, seconds);
    }
    draw_bar(p, 1);
}

static void reap(progress *p, worker *w, int status)
{
    job *j = w->job;
    double seconds = hv_now() - w->t0;
    char *line = last_json_line(&w->buf[0]);
    p->ran++;
    int exited_ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
    if (!WIFEXITED(status) || WEXITSTATUS(status) > 1)
        remove_job_temps(j, w->pid);
    if (line && (WIFEXITED(status) && WEXITSTATUS(status) <= 1)) {
        char *st = json_field(line, "status");
        int ok = exited_ok && st && !strcmp(st, "ok");
        char *err = ok ? NULL : json_field(line, "error");
        report_line(p, line);
        finish(p, j, ok, 0, err, seconds);
        free(st);
        free(err);
    } else {
        /* No report from the worker: it crashed or could not start. */
        char why[128];
        if (WIFSIGNALED(status))
            snprintf(why, sizeof why, "worker killed by signal %d (%s)", WTERMSIG(status),
                     strsignal(WTERMSIG(status)));
        else
            snprintf(why, sizeof why, "worker exited with status %d", WEXITSTATUS(status));
        const char *tail = "";
        if (w->buf[1].s) {
            size_t len = w->buf[1].len;
            while (len && (w->buf[1].s[len - 1] == '\n' || w->buf[1].s[len - 1] == '\r'))
                w->buf[1].s[--len] = '\0';
            tail = len > 300 ? w->buf[1].s + len - 300 : w->buf[1].s;
        }
        char *err = xprintf("%s: %s%s%s", j->input, why, *tail ? ": " : "", tail);
        simple_report(p, j, "failed", err, "worker");
        finish(p, j, 0, 0, err, seconds);
        free(err);
    }
    free(line);
    bb_free(&w->buf[0]);
    bb_free(&w->buf[1]);
}

static int ncpus(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n > 0 ? (int)n : 1;
}

/* Runs every job with at most nworkers at once; returns the stop signal (0 when
 * all finished). */
static int run_pool(joblist *l, progress *p, const char *exe, int nworkers, int gargc,
                    char **gargv)
{
    worker *ws = calloc((size_t)nworkers, sizeof *ws);
    struct pollfd *pf = calloc(2 * (size_t)nworkers, sizeof *pf);
    int *pw = calloc(2 * (size_t)nworkers, sizeof *pw);
    int threads = ncpus() / nworkers;
    if (threads < 1)
        threads = 1;
    size_t next = 0;
    int active = 0;
    set_handlers(on_stop);
    for (;;) {
        /* Dispatch. */
        while (!stop_signal && next < l->n && active < nworkers) {
            job *j = &l->v[next++];
            if (j->error) {
                simple_report(p, j, "failed", j->error, "plan");
                finish(p, j, 0, 0, j->error, 0);
                continue;
            }
            if (j->skip) {
                simple_report(p, j, "skipped", NULL, NULL);
                finish(p, j, 1, 1, NULL, 0);
                continue;
            }
            int slot = 0;
            while (ws[slot].pid > 0)
                slot++;
            if (start_worker(&ws[slot], slot, j, exe, gargc, gargv, threads) != 0) {
                char *err = xprintf("%s: cannot start a worker: %s", j->input, strerror(errno));
                simple_report(p, j, "failed", err, "worker");
                finish(p, j, 0, 0, err, 0);
                free(err);
                continue;
            }
            p->current = j->input;
            active++;
        }
        if (active == 0 && (next >= l->n || stop_signal))
            break;
        draw_bar(p, 0);
        int nf = 0;
        for (int s = 0; s < nworkers; s++)
            for (int k = 0; k < 2; k++)
                if (ws[s].pid > 0 && ws[s].fd[k] >= 0) {
                    pf[nf].fd = ws[s].fd[k];
                    pf[nf].events = POLLIN;
                    pw[nf++] = 2 * s + k;
                }
        int r = poll(pf, (nfds_t)nf, 250);
        if (r < 0 && errno != EINTR)
            break;
        for (int f = 0; r > 0 && f < nf; f++) {
            if (!(pf[f].revents & (POLLIN | POLLHUP | POLLERR)))
                continue;
            worker *w = &ws[pw[f] / 2];
            int k = pw[f] % 2;
            char chunk[4096];
            ssize_t got = read(w->fd[k], chunk, sizeof chunk);
            if (got > 0)
                bb_printf(&w->buf[k], "%.*s", (int)got, chunk);
            else if (got == 0 || errno != EINTR) {
                close(w->fd[k]);
                w->fd[k] = -1;
            }
        }
        for (int s = 0; s < nworkers; s++) {
            worker *w = &ws[s];
            if (w->pid <= 0 || w->fd[0] >= 0 || w->fd[1] >= 0)
                continue;
            int status = 0;
            if (waitpid(w->pid, &status, 0) < 0 && errno == EINTR)
                continue;
            worker_pids[s] = 0;
            reap(p, w, status);
            w->pid = 0;
            active--;
        }
        if (stop_signal)
            break;
    }
    int sig = stop_signal;
    if (sig && active > 0) {
        /* Workers got SIGTERM in the handler; give them a moment, then kill. */
        double t0 = hv_now();
        for (int s = 0; s < nworkers; s++) {
            worker *w = &ws[s];
            if (w->pid <= 0)
                continue;
            int status;
            while (waitpid(w->pid, &status, WNOHANG) == 0) {
                if (hv_now() - t0 > 5) {
                    kill(w->pid, SIGKILL);
                    waitpid(w->pid, &status, 0);
                    break;
                }
                usleep(20000);
            }
            worker_pids[s] = 0;
            remove_job_temps(w->job, w->pid);
            for (int k = 0; k < 2; k++)
                if (w->fd[k] >= 0)
                    close(w->fd[k]);
            bb_free(&w->buf[0]);
            bb_free(&w->buf[1]);
            simple_report(p, w->job, "interrupted", "interrupted", "worker");
            w->pid = 0;
        }
    }
    free(ws);
    free(pf);
    free(pw);
    return sig;
}

/* ---- command ---- */

int cmd_batch(int argc, char **argv)
{
    if (argc >= 2 && !strcmp(argv[1], "--job"))
        return batch_job_main(argc - 2, argv + 2);
    const char *outdir = NULL, *report = NULL;
    int nworkers = ncpus(), dry = 0, force = 0;
    char **inputs = malloc(sizeof(char *) * (size_t)argc);
    char **gargv = malloc(sizeof(char *) * (size_t)argc);
    int ninputs = 0, gargc = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            help();
            free(inputs);
            free(gargv);
            return HV_EXIT_OK;
        }
        int k;
        if (!strcmp(a, "-q") || !strcmp(a, "-v"))
            continue;
        if (!strcmp(a, "-o") || !strcmp(a, "-j") || !strcmp(a, "--report")) {
            if (i + 1 >= argc) {
                free(inputs);
                free(gargv);
                return cli_usage_error("batch", "%s needs a value", a);
            }
            const char *v = argv[++i];
            if (a[1] == 'o')
                outdir = v;
            else if (a[1] == '-')
                report = v;
            else if (cli_parse_int(v, &nworkers) || nworkers < 1 || nworkers > MAX_WORKERS) {
                free(inputs);
                free(gargv);
                return cli_usage_error("batch", "-j must be 1..%d, got '%s'", MAX_WORKERS, v);
            }
        } else if (!strcmp(a, "--dry-run")) {
            dry = 1;
        } else if (!strcmp(a, "--force")) {
            force = 1;
        } else if ((k = batch_opt_arity(a)) >= 0) {
            if (i + k >= argc) {
                free(inputs);
                free(gargv);
                return cli_usage_error("batch", "%s needs %d value%s", a, k, k > 1 ? "s" : "");
            }
            for (int t = 0; t <= k; t++)
                gargv[gargc++] = argv[i + t];
            i += k;
        } else if (a[0] == '-' && a[1]) {
            free(inputs);
            free(gargv);
            return cli_usage_error("batch", "unknown option '%s'", a);
        } else {
            inputs[ninputs++] = argv[i];
        }
    }
    int rc = HV_EXIT_OK;
    if (!ninputs || !outdir) {
        rc = cli_usage_error("batch", ninputs ? "no output directory (-o DIR)" : "no input given");
        free(inputs);
        free(gargv);
        return rc;
    }
    batch_opts check;
    batch_opts_default(&check);
    char err[512];
    if (batch_opts_parse(gargc, gargv, &check, err, sizeof err)) {
        free(inputs);
        free(gargv);
        return cli_usage_error("batch", "%s", err);
    }
    char exe[PATH_MAX];
    ssize_t el = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (el <= 0) {
        fprintf(stderr, "heatvox batch: cannot find my own executable: %s\n", strerror(errno));
        free(inputs);
        free(gargv);
        return HV_EXIT_FAIL;
    }
    exe[el] = '\0';

    /* Strip trailing slashes from OUTDIR so output names stay clean. */
    char *od = xstrdup(outdir);
    for (size_t n = strlen(od); n > 1 && od[n - 1] == '/'; n--)
        od[n - 1] = '\0';
    joblist l = {0};
    for (int i = 0; i < ninputs; i++) {
        char *in = xstrdup(inputs[i]);
        for (size_t n = strlen(in); n > 1 && in[n - 1] == '/'; n--)
            in[n - 1] = '\0';
        struct stat sb;
        if (stat(in, &sb) == 0 && S_ISDIR(sb.st_mode))
            walk(&l, in, "", od, 0);
        else if (has_ext(in, manifest_exts))
            read_manifest(&l, in, od);
        else {
            char *stem = stem_of(in);
            char *out = xprintf("%s/%s", od, stem);
            add_job(&l, in, out);
            free(stem);
            free(out);
        }
        free(in);
    }
    plan(&l, gargc, gargv, force);

    if (dry) {
        size_t nrun = 0, nskip = 0, nfail = 0;
        for (size_t i = 0; i < l.n; i++) {
            job *j = &l.v[i];
            if (j->error) {
                printf("fail %s\n", j->error);
                nfail++;
            } else if (j->skip) {
                printf("skip %s -> %s (up to date)\n", j->input, j->output);
                nskip++;
            } else {
                printf("run  %s -> %s\n", j->input, j->output);
                nrun++;
            }
        }
        printf("heatvox batch: dry run: %zu to run, %zu up to date, %zu failing\n", nrun, nskip,
               nfail);
        rc = nfail ? HV_EXIT_FAIL : HV_EXIT_OK;
        goto done;
    }

    progress p;
    memset(&p, 0, sizeof p);
    p.total = l.n;
    p.t0 = hv_now();
    p.tty = isatty(2) && cli_verbose >= 0;
    for (size_t i = 0; i < l.n; i++)
        p.to_run += !l.v[i].error && !l.v[i].skip;
    if (batch_mkdirs(od) != 0) {
        fprintf(stderr, "heatvox batch: %s: cannot create the output directory: %s\n", od,
                strerror(errno));
        rc = HV_EXIT_FAIL;
        goto done;
    }
    if (report) {
        p.report = fopen(report, "we");
        if (!p.report) {
            fprintf(stderr, "heatvox batch: %s: cannot write the report: %s\n", report,
                    strerror(errno));
            rc = HV_EXIT_FAIL;
            goto done;
        }
    }
    int sig = run_pool(&l, &p, exe, nworkers, gargc, gargv);
    clear_bar(&p);
    if (p.report)
        fclose(p.report);
    double secs = hv_now() - p.t0;
    printf("heatvox batch: %zu input%s: %zu written, %zu up to date, %zu failed%s in %.1f s\n",
           l.n, l.n == 1 ? "" : "s", p.ok, p.skipped, p.failed,
           sig ? ", interrupted" : "", secs);
    fflush(stdout);
    if (sig) {
        hv_tmp_cleanup_all();
        free_jobs(&l);
        free(od);
        free(inputs);
        free(gargv);
        signal(sig, SIG_DFL);
        raise(sig);
        return 128 + sig;
    }
    rc = p.failed ? HV_EXIT_FAIL : HV_EXIT_OK;
done:
    free_jobs(&l);
    free(od);
    free(inputs);
    free(gargv);
    return rc;
}
