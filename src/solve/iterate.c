/*
 * The outer iterations shared by the multigrid backends (iterate.h): the
 * stationary defect correction and preconditioned CG, their stopping rules
 * and residual histories. The arithmetic is the backends' (hv_iter_ops).
 */
#include "iterate.h"
#include "core/error.h"

#include <math.h>

/* The residual has not fallen below 0.95 of its value three iterations ago. */
static int stagnated(const hv_solve_info *info)
{
    int n = info->nhistory;
    return n >= 5 && info->history[n - 1] > 0.95 * info->history[n - 4];
}

/* Whether the last correction's cycles each reduced the residual by less
 * than `slow` (which the caller then hands to PCG). */
static int too_slow(double slow, double before, double after, int cycles)
{
    return slow > 0 && before > 0 && cycles > 0 && pow(after / before, 1.0 / cycles) > slow;
}

hv_status hv__iterate_stationary(const hv_iter_ops *ops, void *ctx, const hv_solver_opts *o,
                                 double fn, double slow, hv_solve_info *info, int *slowed)
{
    double norm;
    hv_status st = ops->residual(ctx, &norm);
    if (st)
        return st;
    double rel = norm / fn;
    hv_info_push(info, rel);
    for (int it = 0; it < o->max_iter; it++) {
        if (rel <= o->tol)
            break;
        const double before = rel;
        const int cycles = info->cycles;
        if ((st = ops->correct(ctx, it, rel, info, &norm)))
            return st;
        rel = norm / fn;
        info->iterations = it + 1;
        hv_info_push(info, rel);
        if (!isfinite(rel))
            return hv__error(HV_ERR_NUMERIC, "%smultigrid diverged (residual %g)", ops->prefix,
                             rel);
        if (rel > o->tol && too_slow(slow, before, rel, info->cycles - cycles)) {
            *slowed = 1;
            info->reason = HV_STOP_STAGNATED;
            return HV_OK;
        }
        if (stagnated(info) && rel > o->tol) {
            info->reason = HV_STOP_STAGNATED;
            return HV_OK;
        }
    }
    info->reason = rel <= o->tol ? HV_STOP_CONVERGED : HV_STOP_MAX_ITER;
    return HV_OK;
}

/* The PCG loop of hv__iterate_pcg. With decide, after `probe` iterations
 * decide may change the preconditioner (*changed): the loop then ends there
 * (x as it got, its true residual in info->relres) for the caller to start
 * again; else it goes on as if never asked. */
static hv_status pcg_loop(const hv_iter_ops *ops, void *ctx, const hv_solver_opts *o, double fn,
                          hv_solve_info *info, int probe, hv_iter_decide decide, void *user,
                          int *changed)
{
    double norm, pq;
    hv_status st = ops->residual(ctx, &norm);
    if (st)
        return st;
    double rel = norm / fn;
    hv_info_push(info, rel);
    if (rel <= o->tol) {
        info->reason = HV_STOP_CONVERGED;
        return HV_OK;
    }
    if ((st = ops->pcg_start(ctx, info)))
        return st;
    double best = rel;
    int since_best = 0;
    for (int it = 0; it < o->max_iter; it++) {
        if ((st = ops->pcg_step(ctx, &pq, &norm)))
            return st;
        if (!(pq > 0)) {
            info->reason = HV_STOP_STAGNATED;
            return HV_OK;
        }
        rel = norm / fn;
        info->iterations = it + 1;
        hv_info_push(info, rel);
        if (!isfinite(rel))
            return hv__error(HV_ERR_NUMERIC, "%spreconditioned CG diverged (residual %g)",
                             ops->prefix, rel);
        if (rel <= o->tol)
            break;
        /* the symmetric cycle keeps CG converging: 50 iterations without a
         * 10% gain is a stall */
        if (rel < 0.9 * best) {
            best = rel;
            since_best = 0;
        } else if (++since_best >= 50) {
            info->reason = HV_STOP_STAGNATED;
            break;
        }
        if (decide && it + 1 == probe && it + 1 < o->max_iter) {
            if ((st = decide(user, info, changed)))
                return st;
            if (*changed)
                break;
        }
        if ((st = ops->pcg_next(ctx, info)))
            return st;
    }
    ops->project(ctx);
    /* Report the true residual of the returned iterate. */
    if ((st = ops->residual(ctx, &norm)))
        return st;
    rel = norm / fn;
    info->relres = rel;
    if (info->reason != HV_STOP_STAGNATED)
        info->reason = rel <= o->tol * 1.0001 ? HV_STOP_CONVERGED : HV_STOP_MAX_ITER;
    return HV_OK;
}

hv_status hv__iterate_pcg(const hv_iter_ops *ops, void *ctx, const hv_solver_opts *o, double fn,
                          hv_solve_info *info)
{
    return pcg_loop(ops, ctx, o, fn, info, 0, NULL, NULL, NULL);
}

void hv__info_append(hv_solve_info *info, const hv_solve_info *rest)
{
    info->reason = rest->reason;
    info->relres = rest->relres;
    info->iterations += rest->iterations;
    info->cycles += rest->cycles;
    for (int i = 1; i < rest->nhistory; i++)
        hv_info_push(info, rest->history[i]);
}

hv_status hv__iterate_pcg_probed(const hv_iter_ops *ops, void *ctx, const hv_solver_opts *o,
                                 double fn, int probe, hv_iter_decide decide, void *user,
                                 hv_solve_info *info)
{
    int changed = 0;
    hv_status st = pcg_loop(ops, ctx, o, fn, info, probe, decide, user, &changed);
    if (st || !changed || info->reason == HV_STOP_CONVERGED)
        return st;
    hv_solver_opts ro = *o;
    ro.max_iter -= info->iterations;
    hv_solve_info rest = {0};
    if ((st = pcg_loop(ops, ctx, &ro, fn, &rest, 0, NULL, NULL, NULL)))
        return st;
    hv__info_append(info, &rest);
    return HV_OK;
}
