/*
 * The OpenCL backend's device-resident entries: solves whose fields stay in
 * device buffers (solve_cl.h, for the heat methods' device paths) and the
 * public ones on the caller's context (heatvox/opencl.h). They take the front
 * end's solver (solver.c) and hand its backend state to cl_backend.c.
 */
#include "cl_backend.h"
#include "solve_cl.h"
#include "core/error.h"
#include "heatvox/opencl.h"

#include <string.h>

/* Devices without fp64: through the host front end. */
static hv_status solve_cl_via_host(hv_solver *sv, void *o, cl_mem f, cl_mem u, hv_solve_info *info)
{
    hv_cl *cl = hv__clsolve_cl(o);
    const hv_setup *s = hv__clsolve_setup(o);
    const size_t n = s->count;
    float *hf = hv_malloc(n * sizeof *hf), *hu = hv_malloc(n * sizeof *hu);
    hv_status st;
    if (!hf || !hu) {
        st = hv__error(HV_ERR_NOMEM, "OpenCL backend: out of memory for %zu-cell vectors", n);
        goto out;
    }
    hv__cl_read(cl, f, 0, n * sizeof *hf, hf);
    if (s->o.nonzero_guess)
        hv__cl_read(cl, u, 0, n * sizeof *hu, hu);
    if ((st = hv__cl_check(cl)) || (st = hv_solver_solve(sv, hf, hu, info)))
        goto out;
    hv__cl_write(cl, u, 0, n * sizeof *hu, hu);
    st = hv__cl_finish(cl);
out:
    hv_free(hf);
    hv_free(hu);
    return st;
}

/* The checks shared by the entries: *o is the solver's backend state. */
static hv_status device_entry(const char *who, hv_solver *sv, cl_mem f, cl_mem u,
                              hv_solve_info *info, void **o)
{
    memset(info, 0, sizeof *info);
    info->backend = HV_BACKEND_OPENCL;
    if (!sv || !f || !u)
        return hv__error(HV_ERR_INVALID_ARG, "%s: NULL argument", who);
    if (hv__solver_ops(sv) != &hv__backend_opencl_ops)
        return hv__error(HV_ERR_UNSUPPORTED, "%s: the solver runs on the %s backend, not opencl",
                         who, hv_backend_name(hv_solver_backend(sv)));
    *o = hv__solver_state(sv);
    return HV_OK;
}

hv_status hv__cl_solver_solve(hv_solver *sv, cl_mem f, cl_mem u, hv_solve_info *info)
{
    hv_solve_info local;
    if (!info)
        info = &local;
    void *o = NULL;
    hv_status st = device_entry("hv__cl_solver_solve", sv, f, u, info, &o);
    if (st)
        return st;
    if (!hv__clsolve_takes_floats(o))
        return solve_cl_via_host(sv, o, f, u, info);
    return hv__clsolve_floats(o, f, u, info);
}

hv_status hv__cl_solver_solve_d(hv_solver *sv, cl_mem f, cl_mem u, hv_solve_info *info)
{
    hv_solve_info local;
    if (!info)
        info = &local;
    void *o = NULL;
    hv_status st = device_entry("hv__cl_solver_solve_d", sv, f, u, info, &o);
    if (st)
        return st;
    return hv__clsolve_doubles(o, f, u, info);
}

/* ---------- the public device entry (heatvox/opencl.h) ---------- */

hv_status hv_opencl_solver_create(hv_solver **out, const hv_problem *p, const hv_solver_opts *opts,
                                  cl_context ctx, cl_device_id dev, cl_command_queue queue)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_opencl_solver_create: out is NULL");
    *out = NULL;
    if (!ctx || !dev || !queue)
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_opencl_solver_create: the context, device and queue are required");
    hv_solver_opts o;
    if (opts)
        o = *opts;
    else
        hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_OPENCL;
    hv__cl_adopt(ctx, dev, queue);
    hv_status st = hv_solver_create(out, p, &o);
    hv__cl_adopt(NULL, NULL, NULL);
    return st;
}

hv_status hv_opencl_solve(hv_solver *sv, cl_mem f, cl_mem u, hv_solve_info *info)
{
    hv_solve_info local;
    void *o = NULL;
    hv_status st = device_entry("hv_opencl_solve", sv, f, u, info ? info : &local, &o);
    if (st)
        return st;
    hv_cl *cl = hv__clsolve_cl(o);
    const size_t n = hv__clsolve_setup(o)->count;
    if ((st = hv__cl_check_floats(cl, f, n, "hv_opencl_solve", "f")) ||
        (st = hv__cl_check_floats(cl, u, n, "hv_opencl_solve", "u")))
        return st;
    return hv__cl_solver_solve(sv, f, u, info);
}

hv_status hv_opencl_solver_queue(hv_solver *sv, cl_context *ctx, cl_device_id *dev,
                                 cl_command_queue *queue)
{
    if (!sv)
        return hv__error(HV_ERR_INVALID_ARG, "hv_opencl_solver_queue: sv is NULL");
    if (hv__solver_ops(sv) != &hv__backend_opencl_ops)
        return hv__error(HV_ERR_UNSUPPORTED,
                         "hv_opencl_solver_queue: the solver runs on the %s backend, not opencl",
                         hv_backend_name(hv_solver_backend(sv)));
    const hv_cl *cl = hv__clsolve_cl(hv__solver_state(sv));
    if (ctx)
        *ctx = cl->ctx;
    if (dev)
        *dev = cl->dev;
    if (queue)
        *queue = cl->q;
    return HV_OK;
}
