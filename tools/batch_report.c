/* heatvox batch: progress and report: the bar (rate, ETA) when stderr is a
 * terminal, else a line per finished input; the JSON lines of --report as
 * inputs finish; the summary on stdout. */
#include "batch.h"

#include <stdio.h>
#include <string.h>
#include <unistd.h>

void batch_progress_start(batch_progress *p, const batch_joblist *l)
{
    memset(p, 0, sizeof *p);
    p->total = l->n;
    p->t0 = hv_now();
    p->tty = isatty(2) && cli_verbose >= 0;
    for (size_t i = 0; i < l->n; i++)
        p->to_run += !l->v[i].error && !l->v[i].skip;
}

void batch_bar_clear(batch_progress *p)
{
    if (p->bar_shown) {
        fputs("\r\033[K", stderr);
        p->bar_shown = 0;
    }
}

/* Redraws the bar, at most ten times a second unless forced. */
void batch_bar_draw(batch_progress *p, int force)
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

void batch_report_line(batch_progress *p, const char *line)
{
    if (p->report && line) {
        fputs(line, p->report);
        fputc('\n', p->report);
        fflush(p->report);
    }
}

void batch_report_simple(batch_progress *p, const batch_job *j, const char *status,
                         const char *error, const char *stage)
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
    batch_report_line(p, b.s);
    bb_free(&b);
}

/* One finished input: counts, a line on stderr, the report. */
void batch_finish(batch_progress *p, batch_job *j, int ok, int skipped, const char *error,
                  double seconds)
{
    p->done++;
    j->state = 2;
    if (skipped)
        p->skipped++;
    else if (ok)
        p->ok++;
    else
        p->failed++;
    batch_bar_clear(p);
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
    batch_bar_draw(p, 1);
}

void batch_report_summary(const batch_progress *p, int sig)
{
    double secs = hv_now() - p->t0;
    printf("heatvox batch: %zu input%s: %zu written, %zu up to date, %zu failed%s in %.1f s\n",
           p->total, p->total == 1 ? "" : "s", p->ok, p->skipped, p->failed,
           sig ? ", interrupted" : "", secs);
    fflush(stdout);
}
