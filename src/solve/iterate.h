/*
 * Private: the outer iterations of the multigrid backends, written once for
 * the CPU (mg/mg_backend.c) and the OpenCL device (cl/cl_backend.c): the stationary defect
 * correction and preconditioned CG, with their stopping rules (converged,
 * max iterations, stagnated) and the residual history (docs/METHOD.md,
 * "Multigrid"). The driver sequences the steps and decides; a backend does
 * the arithmetic on its own fine-level vectors (x, f, r, p, z, q in double).
 *
 * The steps are whole passes, not vector primitives: each hands back the
 * scalars that the driver needs once per iteration, so that a device backend
 * synchronizes once per iteration (its CG coefficients stay on the device)
 * and the CPU backend keeps its fused passes (x and the next residual in one
 * pass; the CG update and ||r|| in one pass).
 */
#ifndef HV_SOLVE_ITERATE_H
#define HV_SOLVE_ITERATE_H

#include "backend.h"

typedef struct hv_iter_ops {
    /* Starts the divergence messages: "" or, e.g., "OpenCL ". */
    const char *prefix;
    /* r = f - A x; *norm = ||r|| over the fluid cells. */
    hv_status (*residual)(void *ctx, double *norm);
    /* Stationary: outer iteration `it` (0 first) adds to x the correction
     * its V-cycles find for the residual of the last step (rel: that
     * residual relative to ||f||), then r = f - A x and *norm = ||r||.
     * Counts its cycles in info. */
    hv_status (*correct)(void *ctx, int it, double rel, hv_solve_info *info, double *norm);
    /* PCG: z = M r, p = z, rz = r.z. Counts its cycles in info. */
    hv_status (*pcg_start)(void *ctx, hv_solve_info *info);
    /* PCG: q = A p and *pq = p.q; when pq > 0, x += a p and r -= a q with
     * a = rz / pq, and *norm = ||r|| (when pq <= 0 the driver stops and
     * ignores *norm). */
    hv_status (*pcg_step)(void *ctx, double *pq, double *norm);
    /* PCG: z = M r, p = z + (r.z / rz) p, then rz = r.z. Counts its cycles. */
    hv_status (*pcg_next)(void *ctx, hv_solve_info *info);
    /* PCG: x made mean-free per region for Poisson (alpha = 0), else nothing. */
    void (*project)(void *ctx);
} hv_iter_ops;

/* Defect correction x += M (f - A x) until the relative residual
 * ||f - A x|| / fn is at most o->tol, o->max_iter iterations have run, or it
 * has not fallen below 0.95 of its value three iterations earlier
 * (stagnated). fn = ||f|| > 0. Uses ops->residual (once, first) and
 * ops->correct. Fills info's reason, iterations and history; HV_ERR_NUMERIC
 * when the residual is not finite. With slow > 0, it also stops (setting
 * *slowed) after a correction whose V-cycles reduced the residual by less
 * than that factor each: the caller goes on with PCG. */
hv_status hv__iterate_stationary(const hv_iter_ops *ops, void *ctx, const hv_solver_opts *o,
                                 double fn, double slow, hv_solve_info *info, int *slowed);

/* Preconditioned CG to the same tolerance; stagnated after 50 iterations
 * without a 10% gain or when p.q <= 0. Ends with x projected (ops->project)
 * and info->relres the true residual of x (not pushed to the history). */
hv_status hv__iterate_pcg(const hv_iter_ops *ops, void *ctx, const hv_solver_opts *o, double fn,
                          hv_solve_info *info);

/* info += rest, a solve that went on from where info's ended (rest's
 * history[0] is info's last residual and is left out). */
void hv__info_append(hv_solve_info *info, const hv_solve_info *rest);

/* Asked after a probe's iterations (info so far): *changed = 1 when it
 * changed what the backend's cycles run. */
typedef hv_status (*hv_iter_decide)(void *user, const hv_solve_info *info, int *changed);

/* hv__iterate_pcg that asks decide(user, ...) after `probe` iterations
 * (neither converged nor stagnated): when it changed the preconditioner, PCG
 * starts again from where it got, for the iterations left of o->max_iter;
 * else it goes on unchanged (the same iterates as hv__iterate_pcg). A decide
 * that fails fails the solve. */
hv_status hv__iterate_pcg_probed(const hv_iter_ops *ops, void *ctx, const hv_solver_opts *o,
                                 double fn, int probe, hv_iter_decide decide, void *user,
                                 hv_solve_info *info);

#endif
