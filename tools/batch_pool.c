/* heatvox batch: the pool of worker processes. Each job runs in its own
 * process (`heatvox batch --job ...`, exec'd from /proc/self/exe) whose stdout
 * (the report line) and stderr are read through pipes; a worker that crashes or
 * is killed costs only its job, and its temporaries are removed. SIGINT, SIGTERM
 * and SIGHUP stop the workers.
 *
 * A worker killed by SIGKILL while other workers ran was most likely taken by
 * the kernel's OOM killer for the memory of all of them together (each job
 * checks its own needs against the whole limit, not against what the others
 * use): its job runs again, once, after the others, alone and on every core. */
#include "batch.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

typedef struct worker {
    pid_t pid;
    int fd[2]; /* stdout, stderr pipes; -1 once closed */
    batch_buf buf[2];
    batch_job *job;
    double t0;
} worker;

static volatile sig_atomic_t stop_signal;
static volatile pid_t worker_pids[BATCH_MAX_WORKERS];

static void on_stop(int sig)
{
    stop_signal = sig;
    for (int i = 0; i < BATCH_MAX_WORKERS; i++)
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

static int start_worker(worker *w, int slot, batch_job *j, const char *exe, int gargc, char **gargv,
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
    char *dir = slash ? batch_xprintf("%.*s", (int)(slash - target), target) : batch_xstrdup(".");
    const char *base = slash ? slash + 1 : target;
    char *prefix = batch_xprintf(".%s.tmp-%ld-", base, (long)pid);
    DIR *d = opendir(*dir ? dir : "/");
    struct dirent *e;
    while (d && (e = readdir(d)))
        if (!strncmp(e->d_name, prefix, strlen(prefix))) {
            char *p = batch_xprintf("%s/%s", dir, e->d_name);
            unlink(p);
            free(p);
        }
    if (d)
        closedir(d);
    free(prefix);
    free(dir);
}

static void remove_job_temps(const batch_job *j, pid_t pid)
{
    char path[4200];
    remove_worker_temps(j->output, pid);
    batch_sidecar_path(j->output, path, sizeof path);
    remove_worker_temps(path, pid);
    batch_preview_path(j->output, path, sizeof path);
    remove_worker_temps(path, pid);
    if (j->opts.mesh_format != BATCH_MESH_NONE) {
        batch_mesh_path(j->output, j->opts.mesh_format, path, sizeof path);
        remove_worker_temps(path, pid);
    }
}

/* The value of "key":"..." in a JSON line written by the job (unescaped). */
static char *json_field(const char *line, const char *key)
{
    char *pat = batch_xprintf("\"%s\":\"", key);
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
    return b.s ? b.s : batch_xstrdup("");
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
    return batch_xprintf("%.*s", nl ? (int)(nl - best) : (int)strlen(best), best);
}
/* Whether the job of w, whose worker died with status while `others` workers
 * ran, is to run again alone; if so its temporaries are removed and a line
 * says why. */
static int run_again(batch_progress *p, worker *w, int status, int others)
{
    batch_job *j = w->job;
    if (!WIFSIGNALED(status) || WTERMSIG(status) != SIGKILL || others == 0 || j->again ||
        stop_signal)
        return 0;
    remove_job_temps(j, w->pid);
    bb_free(&w->buf[0]);
    bb_free(&w->buf[1]);
    j->again = 1;
    j->state = 0;
    batch_bar_clear(p);
    fprintf(stderr,
            "heatvox batch: %s: its worker was killed (SIGKILL) while %d other%s ran, most "
            "likely for memory; it runs again alone after them\n",
            j->input, others, others == 1 ? "" : "s");
    return 1;
}

static void reap(batch_progress *p, worker *w, int status)
{
    batch_job *j = w->job;
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
        batch_report_line(p, line);
        batch_finish(p, j, ok, 0, err, seconds);
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
        char *err = batch_xprintf("%s: %s%s%s", j->input, why, *tail ? ": " : "", tail);
        batch_report_simple(p, j, "failed", err, "worker");
        batch_finish(p, j, 0, 0, err, seconds);
        free(err);
    }
    free(line);
    bb_free(&w->buf[0]);
    bb_free(&w->buf[1]);
}

int batch_ncpus(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n > 0 ? (int)n : 1;
}

/* Starts job j in the first free slot of ws (the caller knows there is one);
 * returns 1, or 0 with the job reported failed when no worker could start. */
static int launch(batch_progress *p, worker *ws, batch_job *j, const char *exe, int gargc,
                  char **gargv, int threads)
{
    int slot = 0;
    while (ws[slot].pid > 0)
        slot++;
    if (start_worker(&ws[slot], slot, j, exe, gargc, gargv, threads) != 0) {
        char *err = batch_xprintf("%s: cannot start a worker: %s", j->input, strerror(errno));
        batch_report_simple(p, j, "failed", err, "worker");
        batch_finish(p, j, 0, 0, err, 0);
        free(err);
        return 0;
    }
    p->current = j->input;
    return 1;
}

/* Runs every job with at most nworkers at once; returns the stop signal (0 when
 * all finished). */
int batch_pool_run(batch_joblist *l, batch_progress *p, const char *exe, int nworkers, int gargc,
                   char **gargv)
{
    worker *ws = calloc((size_t)nworkers, sizeof *ws);
    struct pollfd *pf = calloc(2 * (size_t)nworkers, sizeof *pf);
    int *pw = calloc(2 * (size_t)nworkers, sizeof *pw);
    int threads = batch_ncpus() / nworkers;
    if (threads < 1)
        threads = 1;
    size_t next = 0, again = 0;
    int active = 0;
    set_handlers(on_stop);
    for (;;) {
        /* Dispatch; the jobs to run again, alone, once every other is done. */
        while (!stop_signal && next >= l->n && active == 0 && again < l->n) {
            batch_job *j = &l->v[again++];
            if (j->again && j->state == 0)
                active += launch(p, ws, j, exe, gargc, gargv, batch_ncpus());
        }
        while (!stop_signal && next < l->n && active < nworkers) {
            batch_job *j = &l->v[next++];
            if (j->error) {
                batch_report_simple(p, j, "failed", j->error, "plan");
                batch_finish(p, j, 0, 0, j->error, 0);
                continue;
            }
            if (j->skip) {
                batch_report_simple(p, j, "skipped", NULL, NULL);
                batch_finish(p, j, 1, 1, NULL, 0);
                continue;
            }
            active += launch(p, ws, j, exe, gargc, gargv, threads);
        }
        if (active == 0 && ((next >= l->n && again >= l->n) || stop_signal))
            break;
        batch_bar_draw(p, 0);
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
            if (!run_again(p, w, status, active - 1))
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
            batch_report_simple(p, w->job, "interrupted", "interrupted", "worker");
            w->pid = 0;
        }
    }
    free(ws);
    free(pf);
    free(pw);
    return sig;
}
