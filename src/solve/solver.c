/*
 * The solver front end: validates problems, labels connected fluid regions,
 * projects Poisson right-hand sides onto the operator's range, converts float
 * arrays and dispatches to the backend chosen at run time.
 */
#include "backend.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

struct hv_solver {
    hv_setup setup;
    const hv_backend_ops *ops;
    void *state;
    hv_backend backend;
    uint8_t *solid;  /* owned copy of the mask */
    int32_t *region; /* owned region labels */
    double *fd, *ud; /* double buffers for the float interface */
};

hv_backend hv_backend_resolve(hv_backend b, size_t cells, int solid)
{
    if (b != HV_BACKEND_AUTO)
        return b;
    const hv_backend cpu = solid ? HV_BACKEND_MG : HV_BACKEND_FFTW;
    const char *env = getenv("HEATVOX_AUTO_OPENCL");
    const int mode = env && *env ? atoi(env) : -1; /* -1: GPUs on large grids */
    if (mode == 0)
        return cpu;
    const int device = hv__opencl_auto_device();
    if (mode > 0)
        return device >= 0 ? HV_BACKEND_OPENCL : cpu;
    return device == 1 && cells >= HV_AUTO_DEVICE_MIN_CELLS ? HV_BACKEND_OPENCL : cpu;
}

const char *hv_backend_name(hv_backend b)
{
    switch (b) {
    case HV_BACKEND_AUTO: return "auto";
    case HV_BACKEND_MG: return "mg";
    case HV_BACKEND_FFTW: return "fftw";
    case HV_BACKEND_OPENCL: return "opencl";
    case HV_BACKEND_PETSC: return "petsc";
    }
    return "unknown";
}

hv_status hv_backend_parse(const char *s, hv_backend *out)
{
    static const hv_backend all[] = {HV_BACKEND_AUTO, HV_BACKEND_MG, HV_BACKEND_FFTW,
                                     HV_BACKEND_OPENCL, HV_BACKEND_PETSC};
    for (size_t i = 0; s && i < sizeof all / sizeof all[0]; i++)
        if (!strcmp(s, hv_backend_name(all[i]))) {
            *out = all[i];
            return HV_OK;
        }
    return hv__error(HV_ERR_INVALID_ARG,
                     "unknown backend '%s' (expected auto, mg, fftw, opencl or petsc)",
                     s ? s : "(null)");
}

const char *hv_stop_reason_str(hv_stop_reason r)
{
    switch (r) {
    case HV_STOP_NONE: return "none";
    case HV_STOP_CONVERGED: return "converged";
    case HV_STOP_MAX_ITER: return "max-iterations";
    case HV_STOP_STAGNATED: return "stagnated";
    case HV_STOP_EXACT: return "exact";
    }
    return "unknown";
}

void hv_solver_opts_default(hv_solver_opts *o)
{
    memset(o, 0, sizeof *o);
    o->backend = HV_BACKEND_AUTO;
    o->smoother = HV_SMOOTH_AUTO;
    o->tol = 1e-6;
    o->max_iter = 50;
    o->pre_smooth = 2;
    o->post_smooth = 2;
    o->fftw_double = 1;
}

/* 6-connected (4 in 2D) flood fill of the fluid cells. */
/* Runs of fluid cells along x, row after row, and a union-find over them:
 * the connected fluid regions without a walk over single cells. */
typedef struct fluid_runs {
    size_t *start; /* first cell of run r */
    int32_t *len;  /* its cells */
    size_t *row;   /* runs of row j + n[1] k: row[j + n[1] k] .. row[... + 1] */
    int32_t *up;   /* union-find parent */
    size_t n;
} fluid_runs;

static int32_t run_root(int32_t *up, int32_t r)
{
    while (up[r] != r) {
        up[r] = up[up[r]];
        r = up[r];
    }
    return r;
}

static void run_union(int32_t *up, int32_t a, int32_t b)
{
    a = run_root(up, a);
    b = run_root(up, b);
    if (a != b)
        up[a > b ? a : b] = a < b ? a : b;
}

/* Unions the runs of rows ra and rb that share an x. */
static void join_rows(const fluid_runs *R, size_t sy, size_t ra, size_t rb)
{
    size_t p = R->row[ra], q = R->row[rb];
    while (p < R->row[ra + 1] && q < R->row[rb + 1]) {
        size_t p0 = R->start[p] % sy, p1 = p0 + (size_t)R->len[p];
        size_t q0 = R->start[q] % sy, q1 = q0 + (size_t)R->len[q];
        if (p0 < q1 && q0 < p1)
            run_union(R->up, (int32_t)p, (int32_t)q);
        if (p1 < q1)
            p++;
        else
            q++;
    }
}

static hv_status find_runs(const int n[3], const uint8_t *solid, fluid_runs *R)
{
    const size_t sy = (size_t)n[0], rows = (size_t)n[1] * n[2];
    size_t cap = rows + 16;
    memset(R, 0, sizeof *R);
    R->row = malloc((rows + 1) * sizeof *R->row);
    R->start = malloc(cap * sizeof *R->start);
    R->len = malloc(cap * sizeof *R->len);
    if (!R->row || !R->start || !R->len)
        return HV_ERR_NOMEM;
    for (size_t w = 0; w < rows; w++) {
        R->row[w] = R->n;
        const uint8_t *m = solid + w * sy;
        for (size_t i = 0; i < sy;) {
            if (m[i]) {
                i++;
                continue;
            }
            size_t i0 = i;
            while (i < sy && !m[i])
                i++;
            if (R->n == cap) {
                cap *= 2;
                size_t *st = realloc(R->start, cap * sizeof *st);
                if (st)
                    R->start = st;
                int32_t *ln = st ? realloc(R->len, cap * sizeof *ln) : NULL;
                if (ln)
                    R->len = ln;
                if (!st || !ln)
                    return HV_ERR_NOMEM;
            }
            R->start[R->n] = w * sy + i0;
            R->len[R->n++] = (int32_t)(i - i0);
        }
    }
    R->row[rows] = R->n;
    if (R->n >= (size_t)INT32_MAX || !(R->up = malloc((R->n ? R->n : 1) * sizeof *R->up)))
        return HV_ERR_NOMEM;
    return HV_OK;
}

static void runs_free(fluid_runs *R)
{
    free(R->start);
    free(R->len);
    free(R->row);
    free(R->up);
}

int hv__label_regions(const int n[3], const uint8_t *solid, int32_t *region)
{
    const size_t sy = (size_t)n[0], ny = (size_t)n[1], count = sy * ny * (size_t)n[2];
    fluid_runs R = {0};
    if (find_runs(n, solid, &R)) {
        runs_free(&R);
        return -1;
    }
    for (size_t r = 0; r < R.n; r++)
        R.up[r] = (int32_t)r;
    for (size_t k = 0; k < (size_t)n[2]; k++)
        for (size_t j = 0; j < ny; j++) {
            size_t w = j + ny * k;
            if (j > 0)
                join_rows(&R, sy, w, w - 1);
            if (k > 0)
                join_rows(&R, sy, w, w - ny);
        }
    /* Parents precede their children, so in one ascending pass every run
     * comes to point at its root, the component's first run (which holds its
     * first cell): regions are numbered as the roots come. */
    int nr = 0;
    for (size_t r = 0; r < R.n; r++) {
        int32_t p = R.up[r];
        R.up[r] = p == (int32_t)r ? -(++nr) : R.up[p];
    }
    for (size_t c = 0; c < count; c++)
        region[c] = -1;
    for (size_t r = 0; r < R.n; r++) {
        int32_t lab = -R.up[r] - 1;
        for (int32_t q = 0; q < R.len[r]; q++)
            region[R.start[r] + (size_t)q] = lab;
    }
    runs_free(&R);
    return nr;
}

static hv_status label_regions(hv_solver *sv)
{
    int nr = -1;
    sv->region = malloc(sv->setup.count * sizeof(int32_t));
    if (!sv->region || (nr = hv__label_regions(sv->setup.p.n, sv->solid, sv->region)) < 0)
        return hv__error(HV_ERR_NOMEM, "solver: out of memory labelling fluid regions");
    sv->setup.nregion = nr;
    sv->setup.region = sv->region;
    return HV_OK;
}

static const hv_backend_ops *backend_ops(hv_backend b)
{
    switch (b) {
    case HV_BACKEND_MG: return &hv__backend_mg_ops;
    case HV_BACKEND_FFTW: return &hv__backend_fftw_ops;
    case HV_BACKEND_OPENCL: return &hv__backend_opencl_ops;
    case HV_BACKEND_PETSC: return &hv__backend_petsc_ops;
    default: return NULL;
    }
}

hv_status hv_solver_create(hv_solver **out, const hv_problem *p, const hv_solver_opts *opts)
{
    if (!out || !p)
        return hv__error(HV_ERR_INVALID_ARG, "hv_solver_create: NULL argument");
    *out = NULL;
    hv_status st = hv_check_dims(p->dim, p->n, p->h, 40);
    if (st)
        return st;
    if (!(p->alpha >= 0) || !isfinite(p->alpha))
        return hv__error(HV_ERR_INVALID_ARG, "solver: alpha must be finite and >= 0, got %g",
                         p->alpha);
    if (!(p->beta > 0) || !isfinite(p->beta))
        return hv__error(HV_ERR_INVALID_ARG, "solver: beta must be finite and > 0, got %g",
                         p->beta);
    hv_solver_opts o;
    if (opts)
        o = *opts;
    else
        hv_solver_opts_default(&o);
    if (!(o.tol >= 1e-12) || !(o.tol < 1))
        return hv__error(HV_ERR_INVALID_ARG, "solver: tolerance must be in [1e-12, 1), got %g",
                         o.tol);
    if (o.max_iter <= 0 || o.pre_smooth < 0 || o.post_smooth < 0 ||
        o.pre_smooth + o.post_smooth == 0)
        return hv__error(
            HV_ERR_INVALID_ARG,
            "solver: max_iter must be positive and smoothing steps non-negative (not both zero)");

    if (o.cycles_per_iteration < 0 || o.cycles_per_iteration > 8)
        return hv__error(HV_ERR_INVALID_ARG,
                         "solver: cycles_per_iteration must be 0 (auto) to 8, got %d",
                         o.cycles_per_iteration);

    hv_solver *sv = calloc(1, sizeof *sv);
    if (!sv)
        return hv__error(HV_ERR_NOMEM, "solver: out of memory");
    hv_setup *s = &sv->setup;
    s->p = *p;
    if (p->dim == 2)
        s->p.n[2] = 1;
    s->count = (size_t)s->p.n[0] * s->p.n[1] * s->p.n[2];
    s->nregion = 1;
    s->p.solid = NULL;
    if (p->solid) {
        size_t nsolid = 0;
        for (size_t c = 0; c < s->count; c++)
            nsolid += p->solid[c] != 0;
        if (nsolid == s->count) {
            free(sv);
            return hv__error(HV_ERR_INVALID_ARG, "solver: every cell of the mask is solid");
        }
        if (nsolid) { /* an all-fluid mask is a plain box */
            sv->solid = malloc(s->count);
            if (!sv->solid) {
                hv_solver_destroy(&sv);
                return hv__error(HV_ERR_NOMEM, "solver: out of memory copying the mask");
            }
            for (size_t c = 0; c < s->count; c++)
                sv->solid[c] = p->solid[c] != 0;
            s->p.solid = sv->solid;
            if ((st = label_regions(sv))) {
                hv_solver_destroy(&sv);
                return st;
            }
        }
    }
    hv_backend b = hv_backend_resolve(o.backend, s->count, s->p.solid != NULL);
    if (b == HV_BACKEND_FFTW && s->p.solid) {
        hv_solver_destroy(&sv);
        return hv__error(
            HV_ERR_UNSUPPORTED,
            "the FFTW backend solves plain boxes only; this grid has solid cells (use mg)");
    }
    if (o.smoother == HV_SMOOTH_AUTO)
        o.smoother = b == HV_BACKEND_OPENCL ? HV_SMOOTH_CHEBYSHEV : HV_SMOOTH_RBGS;
    s->o = o;
    sv->backend = b;
    sv->ops = backend_ops(b);
    if (!sv->ops) {
        hv_solver_destroy(&sv);
        return hv__error(HV_ERR_INVALID_ARG, "solver: unknown backend %d", (int)b);
    }
    if ((st = sv->ops->create(&sv->state, s))) {
        sv->state = NULL;
        hv_solver_destroy(&sv);
        return st;
    }
    *out = sv;
    return HV_OK;
}

static hv_status solve_prepared(hv_solver *sv, double *f, double *u, hv_solve_info *info)
{
    const hv_setup *s = &sv->setup;
    hv_solve_info local;
    if (!info)
        info = &local;
    memset(info, 0, sizeof *info);
    info->backend = sv->backend;
    if (s->p.solid)
        for (size_t c = 0; c < s->count; c++)
            if (s->p.solid[c])
                f[c] = 0;
    if (s->p.alpha == 0)
        hv__project_mean(s, f);
    double t0 = hv_now();
    hv_status st = sv->ops->solve(sv->state, f, u, info);
    info->seconds = hv_now() - t0;
    info->backend = sv->backend;
    return st;
}

static hv_status ensure_buffers(hv_solver *sv)
{
    if (sv->fd)
        return HV_OK;
    sv->fd = hv_malloc(sv->setup.count * sizeof(double));
    sv->ud = hv_malloc(sv->setup.count * sizeof(double));
    if (!sv->fd || !sv->ud)
        return hv__error(HV_ERR_NOMEM, "solver: out of memory for %zu-cell buffers",
                         sv->setup.count);
    return HV_OK;
}

hv_status hv_solver_solve_d(hv_solver *sv, const double *f, double *u, hv_solve_info *info)
{
    if (!sv || !f || !u)
        return hv__error(HV_ERR_INVALID_ARG, "hv_solver_solve_d: NULL argument");
    hv_status st = hv_check_finite_d(f, sv->setup.count, "the right-hand side");
    if (st || (st = ensure_buffers(sv)))
        return st;
    memcpy(sv->fd, f, sv->setup.count * sizeof(double));
    return solve_prepared(sv, sv->fd, u, info);
}

hv_status hv_solver_solve(hv_solver *sv, const float *f, float *u, hv_solve_info *info)
{
    if (!sv || !f || !u)
        return hv__error(HV_ERR_INVALID_ARG, "hv_solver_solve: NULL argument");
    size_t n = sv->setup.count;
    hv_status st = hv_check_finite(f, n, "the right-hand side");
    if (st)
        return st;
    if (sv->ops->solve_f) {
        hv_solve_info local, *in = info ? info : &local;
        memset(in, 0, sizeof *in);
        double t0 = hv_now();
        st = sv->ops->solve_f(sv->state, f, u, in);
        in->seconds = hv_now() - t0;
        in->backend = sv->backend;
        if (st != HV_ERR_UNSUPPORTED)
            return st;
    }
    if ((st = ensure_buffers(sv)))
        return st;
    /* Without a guess every backend sets u itself (clearing it here would be
     * one more pass over a double array). */
    int guess = sv->setup.o.nonzero_guess;
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < n; c++) {
        sv->fd[c] = f[c];
        if (guess)
            sv->ud[c] = u[c];
    }
    st = solve_prepared(sv, sv->fd, sv->ud, info);
    if (st)
        return st;
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < n; c++)
        u[c] = (float)sv->ud[c];
    return HV_OK;
}

hv_status hv_solver_solve_many(hv_solver *sv, int k, const float *const *f, float *const *u,
                               hv_solve_info *info)
{
    if (!sv || k < 0 || (k > 0 && (!f || !u)))
        return hv__error(HV_ERR_INVALID_ARG, "hv_solver_solve_many: bad arguments");
    for (int i = 0; i < k; i++) {
        hv_status st = hv_solver_solve(sv, f[i], u[i], info ? &info[i] : NULL);
        if (st)
            return st;
    }
    return HV_OK;
}

hv_status hv_solver_get_stats(const hv_solver *sv, hv_solver_stats *st)
{
    if (!sv || !st)
        return hv__error(HV_ERR_INVALID_ARG, "hv_solver_get_stats: NULL argument");
    memset(st, 0, sizeof *st);
    st->levels = 1;
    memcpy(st->n[0], sv->setup.p.n, sizeof st->n[0]);
    st->plain[0] = sv->setup.p.solid == NULL;
    if (sv->ops->stats)
        sv->ops->stats(sv->state, st);
    return HV_OK;
}

hv_backend hv_solver_backend(const hv_solver *sv) { return sv->backend; }

const hv_backend_ops *hv__solver_ops(const hv_solver *sv) { return sv->ops; }

void *hv__solver_state(hv_solver *sv) { return sv->state; }

const hv_problem *hv_solver_problem(const hv_solver *sv) { return &sv->setup.p; }

void hv_solver_destroy(hv_solver **s)
{
    if (!s || !*s)
        return;
    hv_solver *sv = *s;
    if (sv->ops && sv->state)
        sv->ops->destroy(sv->state);
    free(sv->solid);
    free(sv->region);
    hv_free(sv->fd);
    hv_free(sv->ud);
    free(sv);
    *s = NULL;
}
