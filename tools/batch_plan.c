/* heatvox batch: the plan: each job's options and output name (later inputs
 * that would overwrite an earlier output get _2, _3, ...), inputs that cannot
 * run, outputs already up to date, and the dry run that lists them. */
#include "batch.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* Parses the options of every job, names its output and decides skips. */
void batch_plan(batch_joblist *l, int gargc, char **gargv, int force)
{
    for (size_t i = 0; i < l->n; i++) {
        batch_job *j = &l->v[i];
        batch_opts_default(&j->opts);
        char err[512];
        if (!j->error && (batch_opts_parse(gargc, gargv, &j->opts, err, sizeof err) ||
                          batch_opts_parse(j->nargs, j->args, &j->opts, err, sizeof err) ||
                          batch_opts_check(&j->opts, err, sizeof err)))
            j->error = batch_xprintf("%s: %s", j->input, err);
        char canon[1024];
        batch_opts_canonical(&j->opts, canon, sizeof canon);
        batch_hash(canon, j->hash);
    }
    /* Names: later inputs that would overwrite an earlier output get _2, _3, ... */
    for (size_t i = 0; i < l->n; i++) {
        batch_job *j = &l->v[i];
        const char *ext = batch_ext(j->opts.format);
        j->output = batch_xprintf("%s%s", j->stem, ext);
        for (int k = 2;; k++) {
            int clash = 0;
            for (size_t p = 0; p < i && !clash; p++)
                clash = !strcmp(l->v[p].output, j->output);
            if (!clash)
                break;
            free(j->output);
            j->output = batch_xprintf("%s_%d%s", j->stem, k, ext);
        }
    }
    for (size_t i = 0; i < l->n; i++) {
        batch_job *j = &l->v[i];
        struct stat sb;
        if (!j->error && stat(j->input, &sb) != 0)
            j->error = batch_xprintf("%s: cannot open: %s", j->input, strerror(errno));
        else if (!j->error && !S_ISREG(sb.st_mode))
            j->error = batch_xprintf("%s: not a regular file", j->input);
        if (!j->error && j->opts.mesh_format != BATCH_MESH_NONE) {
            /* A mesh output has an input's extension: never let it replace one
             * (e.g. -o the input directory with --mesh-out-format obj). */
            char mesh[4200];
            struct stat sm, si;
            batch_mesh_path(j->output, j->opts.mesh_format, mesh, sizeof mesh);
            for (size_t k = 0; k < l->n && !j->error; k++)
                if (stat(mesh, &sm) == 0 && stat(l->v[k].input, &si) == 0 &&
                    sm.st_dev == si.st_dev && sm.st_ino == si.st_ino)
                    j->error = batch_xprintf("%s: its mesh output %s would replace the input %s",
                                             j->input, mesh, l->v[k].input);
        }
        if (!j->error && !force && batch_up_to_date(j->input, j->output, &j->opts, j->hash))
            j->skip = 1;
    }
}

int batch_plan_print(const batch_joblist *l)
{
    size_t nrun = 0, nskip = 0, nfail = 0;
    for (size_t i = 0; i < l->n; i++) {
        const batch_job *j = &l->v[i];
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
    printf("heatvox batch: dry run: %zu to run, %zu up to date, %zu failing\n", nrun, nskip, nfail);
    return nfail ? HV_EXIT_FAIL : HV_EXIT_OK;
}
