/*
 * The FFTW backend: an exact solve of (alpha*I - beta*Lap) u = f on a plain box
 * with Neumann walls. The cell-centred Neumann Laplacian is diagonalized by the
 * DCT-II (docs/METHOD.md, "Discretization"): per axis of N cells its
 * eigenvalues are -(4/h^2) sin^2(pi k / (2N)), k = 0..N-1. FFTW's REDFT10
 * (forward) and REDFT01 (inverse) are unnormalized, their product is
 * prod_d 2N_d times identity.
 *
 * Plans are made once at create on a buffer the state owns and reused by every
 * solve: only fftw_execute is thread-safe, so planning, plan destruction and
 * wisdom go through one process-wide mutex.
 */
#include "solve/backend.h"
#include "core/error.h"
#include "heatvox/ops.h"

#include <errno.h>
#include <fftw3.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct fftw_state {
    const hv_setup *s;
    int dim;
    int n[3]; /* n[2] == 1 in 2D */
    size_t count;
    int use_double;
    double *lam[3]; /* per axis: -(eigenvalue) = (4/h^2) sin^2(pi k/(2N)) >= 0 */
    double norm;    /* prod over transformed axes of 2N */
    double *bufd;   /* double transforms: in-place buffer, then the residual work */
    float *buff;    /* float transforms: in-place buffer */
    double *work;   /* float mode: A u for the residual */
    fftw_plan fwd, inv;
    fftwf_plan fwdf, invf;
} fftw_state;

static pthread_mutex_t planner_lock = PTHREAD_MUTEX_INITIALIZER;
static pthread_once_t threads_once = PTHREAD_ONCE_INIT;
static int threads_ok;

static void threads_init(void)
{
    threads_ok = fftw_init_threads() != 0 && fftwf_init_threads() != 0;
    fftw_make_planner_thread_safe();
    fftwf_make_planner_thread_safe();
}

/* ---- wisdom ------------------------------------------------------------ */

/* A wisdom file holds up to two s-expressions, "(fftw-3.x fftw_wisdom ...)" and
 * "(fftw-3.x fftwf_wisdom ...)", so that double and float solvers can share it.
 * Returns 1 if every section imported, 0 if some section was bad. */
static int wisdom_import_text(char *text)
{
    int ok = 1, sections = 0;
    char *p = text;
    for (;;) {
        while (*p && *p != '(') {
            if (*p != ' ' && *p != '\t' && *p != '\n' && *p != '\r')
                ok = 0;
            p++;
        }
        if (!*p)
            break;
        char *start = p;
        int depth = 0;
        for (; *p; p++) {
            if (*p == '(')
                depth++;
            else if (*p == ')' && --depth == 0)
                break;
        }
        if (!*p)
            return 0; /* unbalanced: truncated or not wisdom */
        char save = *++p;
        *p = '\0';
        sections++;
        const char *sp = strchr(start, ' ');
        if (sp && strncmp(sp + 1, "fftwf_wisdom", 12) == 0)
            ok &= fftwf_import_wisdom_from_string(start) != 0;
        else if (sp && strncmp(sp + 1, "fftw_wisdom", 11) == 0)
            ok &= fftw_import_wisdom_from_string(start) != 0;
        else
            ok = 0;
        *p = save;
    }
    return ok && sections > 0;
}

/* Called with planner_lock held. A missing file is the normal first run. */
static void wisdom_import(const char *path)
{
    FILE *fp = fopen(path, "rb");
    if (!fp) {
        if (errno != ENOENT)
            hv__log(HV_LOG_WARN, "%s: cannot read FFTW wisdom: %s", path, strerror(errno));
        return;
    }
    char *text = NULL;
    long size = -1;
    if (fseek(fp, 0, SEEK_END) == 0 && (size = ftell(fp)) >= 0 && fseek(fp, 0, SEEK_SET) == 0)
        text = malloc((size_t)size + 1);
    if (!text || fread(text, 1, (size_t)size, fp) != (size_t)size) {
        hv__log(HV_LOG_WARN, "%s: cannot read FFTW wisdom", path);
    } else {
        text[size] = '\0';
        if (strlen(text) != (size_t)size || !wisdom_import_text(text))
            hv__log(HV_LOG_WARN, "%s: FFTW wisdom is corrupt or from another FFTW; ignored", path);
    }
    free(text);
    fclose(fp);
}

/* Called with planner_lock held. Failing to save wisdom only costs planning
 * time next run, so it is a warning, not an error. */
static void wisdom_export(const char *path)
{
    char tmp[4096];
    if (hv_tmp_name(path, tmp, sizeof tmp) != HV_OK) {
        hv__log(HV_LOG_WARN, "%s: cannot save FFTW wisdom: %s", path, hv_last_error());
        return;
    }
    char *wd = fftw_export_wisdom_to_string();
    char *wf = fftwf_export_wisdom_to_string();
    FILE *fp = fopen(tmp, "wb");
    int ok = fp && wd && wf && fputs(wd, fp) >= 0 && fputs(wf, fp) >= 0;
    if (fp && fclose(fp) != 0)
        ok = 0;
    free(wd);
    free(wf);
    if (!ok) {
        hv__log(HV_LOG_WARN, "%s: cannot write FFTW wisdom to %s", path, tmp);
        hv_tmp_discard(tmp);
        return;
    }
    if (hv_tmp_commit(tmp, path) != HV_OK)
        hv__log(HV_LOG_WARN, "%s: cannot save FFTW wisdom: %s", path, hv_last_error());
}

/* ---- create / destroy --------------------------------------------------- */

static void fftw_destroy(void *state)
{
    fftw_state *st = state;
    if (!st)
        return;
    pthread_mutex_lock(&planner_lock);
    if (st->fwd)
        fftw_destroy_plan(st->fwd);
    if (st->inv)
        fftw_destroy_plan(st->inv);
    if (st->fwdf)
        fftwf_destroy_plan(st->fwdf);
    if (st->invf)
        fftwf_destroy_plan(st->invf);
    pthread_mutex_unlock(&planner_lock);
    fftw_free(st->bufd);
    fftwf_free(st->buff);
    hv_free(st->work);
    for (int a = 0; a < 3; a++)
        hv_free(st->lam[a]);
    free(st);
}

/* Builds the forward and inverse plans; called with planner_lock held. */
static hv_status make_plans(fftw_state *st, unsigned flags)
{
    fftw_iodim64 dims[3];
    fftw_r2r_kind kf[3], ki[3];
    int rank = 0;
    /* FFTW is row-major: its first dimension is our slowest axis (z). Axes of one
     * cell are left out: their transform is the identity up to the factor 2
     * that the normalization would undo. */
    for (int a = 2; a >= 0; a--) {
        if (st->n[a] == 1)
            continue;
        ptrdiff_t stride = 1;
        for (int b = 0; b < a; b++)
            stride *= st->n[b];
        dims[rank].n = st->n[a];
        dims[rank].is = dims[rank].os = stride;
        kf[rank] = FFTW_REDFT10;
        ki[rank] = FFTW_REDFT01;
        rank++;
    }
    fftw_plan_with_nthreads(hv_get_threads());
    fftwf_plan_with_nthreads(hv_get_threads());
    if (st->use_double) {
        st->fwd = fftw_plan_guru64_r2r(rank, dims, 0, NULL, st->bufd, st->bufd, kf, flags);
        st->inv = fftw_plan_guru64_r2r(rank, dims, 0, NULL, st->bufd, st->bufd, ki, flags);
        if (!st->fwd || !st->inv)
            return hv__error(HV_ERR_BACKEND, "FFTW could not plan a %d x %d x %d DCT (double)",
                             st->n[0], st->n[1], st->n[2]);
    } else {
        fftwf_iodim64 dimsf[3];
        for (int r = 0; r < rank; r++) {
            dimsf[r].n = dims[r].n;
            dimsf[r].is = dims[r].is;
            dimsf[r].os = dims[r].os;
        }
        st->fwdf = fftwf_plan_guru64_r2r(rank, dimsf, 0, NULL, st->buff, st->buff, kf, flags);
        st->invf = fftwf_plan_guru64_r2r(rank, dimsf, 0, NULL, st->buff, st->buff, ki, flags);
        if (!st->fwdf || !st->invf)
            return hv__error(HV_ERR_BACKEND, "FFTW could not plan a %d x %d x %d DCT (float)",
                             st->n[0], st->n[1], st->n[2]);
    }
    return HV_OK;
}

static hv_status fftw_create(void **state, const hv_setup *s)
{
    if (!state || !s)
        return hv__error(HV_ERR_INVALID_ARG, "fftw backend: NULL %s", state ? "setup" : "state");
    *state = NULL;
    const hv_problem *p = &s->p;
    if (p->solid)
        return hv__error(HV_ERR_UNSUPPORTED,
                         "the FFTW backend solves plain boxes only; this problem has solid cells "
                         "(use the multigrid backend)");
    hv_status rc = hv_check_dims(p->dim, p->n, p->h, s->o.fftw_double ? 8 : 12);
    if (rc)
        return rc;
    if (!(p->alpha >= 0) || !(p->beta > 0) || !isfinite(p->alpha) || !isfinite(p->beta))
        return hv__error(HV_ERR_INVALID_ARG,
                         "fftw backend: need alpha >= 0 and beta > 0, got alpha = %g, beta = %g",
                         p->alpha, p->beta);

    fftw_state *st = calloc(1, sizeof *st);
    if (!st)
        return hv__error(HV_ERR_NOMEM, "fftw backend: no memory for the state");
    st->s = s;
    st->dim = p->dim;
    st->n[0] = p->n[0];
    st->n[1] = p->n[1];
    st->n[2] = p->dim == 3 ? p->n[2] : 1;
    st->count = (size_t)st->n[0] * st->n[1] * st->n[2];
    st->use_double = s->o.fftw_double != 0;
    st->norm = 1.0;
    const double c = 4.0 / (p->h * p->h);
    for (int a = 0; a < 3; a++) {
        int na = st->n[a];
        st->lam[a] = hv_malloc((size_t)na * sizeof(double));
        if (!st->lam[a]) {
            fftw_destroy(st);
            return hv__error(HV_ERR_NOMEM, "fftw backend: no memory for eigenvalues");
        }
        for (int k = 0; k < na; k++) {
            double sn = sin(M_PI * k / (2.0 * na));
            st->lam[a][k] = c * sn * sn;
        }
        if (na > 1)
            st->norm *= 2.0 * na;
    }
    if (st->use_double) {
        st->bufd = fftw_alloc_real(st->count);
    } else {
        st->buff = fftwf_alloc_real(st->count);
        st->work = hv_malloc(st->count * sizeof(double));
    }
    if (st->use_double ? !st->bufd : (!st->buff || !st->work)) {
        fftw_destroy(st);
        return hv__error(HV_ERR_NOMEM, "fftw backend: no memory for a %zu-cell buffer", st->count);
    }

    pthread_once(&threads_once, threads_init);
    if (!threads_ok) {
        fftw_destroy(st);
        return hv__error(HV_ERR_BACKEND, "FFTW threads could not be initialized");
    }
    unsigned flags = s->o.fftw_measure ? FFTW_MEASURE : FFTW_ESTIMATE;
    pthread_mutex_lock(&planner_lock);
    if (s->o.wisdom_file && *s->o.wisdom_file)
        wisdom_import(s->o.wisdom_file);
    rc = make_plans(st, flags);
    if (rc == HV_OK && s->o.wisdom_file && *s->o.wisdom_file)
        wisdom_export(s->o.wisdom_file);
    pthread_mutex_unlock(&planner_lock);
    if (rc) {
        fftw_destroy(st);
        return rc;
    }
    *state = st;
    return HV_OK;
}

/* ---- solve --------------------------------------------------------------- */

/* Divides every DCT coefficient by its eigenvalue of A and by the transform
 * normalization. For Poisson (alpha = 0) the constant mode, the null space, has
 * eigenvalue 0 and is set to zero: the solution is the mean-free one. */
static void scale_d(const fftw_state *st, double alpha, double beta, double *buf)
{
    const ptrdiff_t nx = st->n[0], ny = st->n[1], nz = st->n[2];
    const double *lx = st->lam[0], *ly = st->lam[1], *lz = st->lam[2];
    const double norm = st->norm;
#pragma omp parallel for collapse(2) schedule(static)
    for (ptrdiff_t k = 0; k < nz; k++)
        for (ptrdiff_t j = 0; j < ny; j++) {
            const double lyz = ly[j] + lz[k];
            double *row = buf + (k * ny + j) * nx;
            for (ptrdiff_t i = 0; i < nx; i++) {
                const double d = norm * (alpha + beta * (lx[i] + lyz));
                row[i] = d > 0.0 ? row[i] / d : 0.0;
            }
        }
}

static void scale_f(const fftw_state *st, double alpha, double beta, float *buf)
{
    const ptrdiff_t nx = st->n[0], ny = st->n[1], nz = st->n[2];
    const double *lx = st->lam[0], *ly = st->lam[1], *lz = st->lam[2];
    const double norm = st->norm;
#pragma omp parallel for collapse(2) schedule(static)
    for (ptrdiff_t k = 0; k < nz; k++)
        for (ptrdiff_t j = 0; j < ny; j++) {
            const double lyz = ly[j] + lz[k];
            float *row = buf + (k * ny + j) * nx;
            for (ptrdiff_t i = 0; i < nx; i++) {
                const double d = norm * (alpha + beta * (lx[i] + lyz));
                row[i] = d > 0.0 ? (float)(row[i] / d) : 0.0f;
            }
        }
}

static hv_status fftw_solve(void *state, const double *f, double *u, hv_solve_info *info)
{
    fftw_state *st = state;
    if (!st || !f || !u || !info)
        return hv__error(HV_ERR_INVALID_ARG, "fftw backend: NULL argument to solve");
    const hv_problem *p = &st->s->p;
    const double alpha = p->alpha, beta = p->beta;
    const ptrdiff_t count = (ptrdiff_t)st->count;

    if (st->use_double) {
        double *b = st->bufd;
#pragma omp parallel for schedule(static)
        for (ptrdiff_t i = 0; i < count; i++)
            b[i] = f[i];
        fftw_execute(st->fwd);
        scale_d(st, alpha, beta, b);
        fftw_execute(st->inv);
#pragma omp parallel for schedule(static)
        for (ptrdiff_t i = 0; i < count; i++)
            u[i] = b[i];
    } else {
        float *b = st->buff;
#pragma omp parallel for schedule(static)
        for (ptrdiff_t i = 0; i < count; i++)
            b[i] = (float)f[i];
        fftwf_execute(st->fwdf);
        scale_f(st, alpha, beta, b);
        fftwf_execute(st->invf);
#pragma omp parallel for schedule(static)
        for (ptrdiff_t i = 0; i < count; i++)
            u[i] = b[i];
    }

    /* The zeroed constant mode leaves a float-rounding mean; remove it in double. */
    if (alpha == 0.0) {
        double sum = 0.0;
#pragma omp parallel for reduction(+ : sum) schedule(static)
        for (ptrdiff_t i = 0; i < count; i++)
            sum += u[i];
        const double mean = sum / (double)count;
#pragma omp parallel for schedule(static)
        for (ptrdiff_t i = 0; i < count; i++)
            u[i] -= mean;
    }

    /* The true residual in double, so that info says what this solve achieved. */
    double *au = st->use_double ? st->bufd : st->work;
    hv_status rc = hv_apply_helmholtz_d(st->dim, st->n, p->h, NULL, alpha, beta, u, au);
    if (rc)
        return rc;
    double rr = 0.0, ff = 0.0;
#pragma omp parallel for reduction(+ : rr, ff) schedule(static)
    for (ptrdiff_t i = 0; i < count; i++) {
        const double r = f[i] - au[i];
        rr += r * r;
        ff += f[i] * f[i];
    }
    const double relres = ff > 0.0 ? sqrt(rr / ff) : sqrt(rr);

    info->reason = HV_STOP_EXACT;
    info->iterations = 1;
    info->nhistory = 0;
    hv_info_push(info, 1.0);
    hv_info_push(info, relres);
    return HV_OK;
}

const hv_backend_ops hv__backend_fftw_ops = {
    .name = "fftw",
    .create = fftw_create,
    .solve = fftw_solve,
    .solve_many = NULL,
    .destroy = fftw_destroy,
};
