/* heatvox batch: the job list, and the inputs found for it: mesh files,
 * directories searched recursively, and manifests of mesh paths with per-line
 * options. */
#include "batch.h"

#include <dirent.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#define MAX_DEPTH 64

batch_job *batch_jobs_add(batch_joblist *l, const char *input, const char *stem)
{
    if (l->n == l->cap) {
        l->cap = l->cap ? 2 * l->cap : 64;
        batch_job *v = realloc(l->v, l->cap * sizeof *v);
        if (!v) {
            fprintf(stderr, "heatvox batch: out of memory\n");
            exit(HV_EXIT_FAIL);
        }
        l->v = v;
    }
    batch_job *j = &l->v[l->n++];
    memset(j, 0, sizeof *j);
    j->input = batch_xstrdup(input);
    j->stem = batch_xstrdup(stem);
    return j;
}

void batch_jobs_free(batch_joblist *l)
{
    for (size_t i = 0; i < l->n; i++) {
        batch_job *j = &l->v[i];
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

/* Oriented point clouds by extension (hv_points_file); meshes are those
 * hv_mesh_format_by_extension names. */
static const char *const points_exts[] = {"xyz", "pts", "xyzn", NULL};
static const char *const manifest_exts[] = {"txt", "list", NULL};

/* "dir/name.ext" -> "name" */
static char *stem_of(const char *path)
{
    const char *slash = strrchr(path, '/');
    const char *base = slash ? slash + 1 : path;
    const char *dot = strrchr(base, '.');
    size_t len = dot && dot != base ? (size_t)(dot - base) : strlen(base);
    return batch_xprintf("%.*s", (int)len, base);
}

static int by_name(const struct dirent **a, const struct dirent **b)
{
    return strcmp((*a)->d_name, (*b)->d_name);
}

static void walk(batch_joblist *l, const char *dir, const char *rel, const char *outdir, int depth)
{
    struct dirent **names = NULL;
    int n = scandir(dir, &names, NULL, by_name);
    if (n < 0) {
        batch_job *j = batch_jobs_add(l, dir, dir);
        j->error = batch_xprintf("%s: cannot read the directory: %s", dir, strerror(errno));
        return;
    }
    for (int i = 0; i < n; i++) {
        const char *name = names[i]->d_name;
        if (name[0] != '.') {
            char *path = batch_xprintf("%s/%s", dir, name);
            char *sub = batch_xprintf("%s%s%s", rel, *rel ? "/" : "", name);
            struct stat sb;
            if (stat(path, &sb) == 0 && S_ISDIR(sb.st_mode)) {
                if (depth < MAX_DEPTH)
                    walk(l, path, sub, outdir, depth + 1);
            } else if (hv_mesh_format_by_extension(name) || has_ext(name, points_exts)) {
                char *stem = stem_of(name);
                char *out = batch_xprintf("%s/%s%s%s", outdir, rel, *rel ? "/" : "", stem);
                batch_jobs_add(l, path, out);
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

static void read_manifest(batch_joblist *l, const char *path, const char *outdir)
{
    FILE *f = fopen(path, "r");
    if (!f) {
        batch_job *j = batch_jobs_add(l, path, path);
        j->error = batch_xprintf("%s: cannot open the manifest: %s", path, strerror(errno));
        return;
    }
    const char *slash = strrchr(path, '/');
    char *dir = slash ? batch_xprintf("%.*s", (int)(slash - path), path) : batch_xstrdup(".");
    char *line = NULL;
    size_t cap = 0;
    int lineno = 0;
    while (getline(&line, &cap, f) > 0) {
        lineno++;
        char **toks = NULL;
        int n = 0;
        char err[256];
        if (split_line(line, &toks, &n, err, sizeof err)) {
            char *where = batch_xprintf("%s:%d", path, lineno);
            batch_job *j = batch_jobs_add(l, where, where);
            j->error = batch_xprintf("%s: %s", where, err);
            free(where);
            continue;
        }
        if (n == 0) {
            free(toks);
            continue;
        }
        char *mesh = toks[0][0] == '/' || !strcmp(dir, ".") ? batch_xstrdup(toks[0])
                                                            : batch_xprintf("%s/%s", dir, toks[0]);
        char *stem = stem_of(mesh);
        char *out = batch_xprintf("%s/%s", outdir, stem);
        batch_job *j = batch_jobs_add(l, mesh, out);
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

void batch_inputs_find(batch_joblist *l, const char *const *inputs, int ninputs, const char *outdir)
{
    for (int i = 0; i < ninputs; i++) {
        char *in = batch_xstrdup(inputs[i]);
        for (size_t n = strlen(in); n > 1 && in[n - 1] == '/'; n--)
            in[n - 1] = '\0';
        struct stat sb;
        if (stat(in, &sb) == 0 && S_ISDIR(sb.st_mode))
            walk(l, in, "", outdir, 0);
        else if (has_ext(in, manifest_exts))
            read_manifest(l, in, outdir);
        else {
            char *stem = stem_of(in);
            char *out = batch_xprintf("%s/%s", outdir, stem);
            batch_jobs_add(l, in, out);
            free(stem);
            free(out);
        }
        free(in);
    }
}
