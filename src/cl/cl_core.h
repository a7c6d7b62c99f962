/*
 * Private: the OpenCL device, context, programs and kernel launches: a
 * runtime that knows no kernel. Every owner of kernels describes them as a
 * module (hv_cl_module below): the device grid operations (cl_ops.c), the
 * solver backend (src/solve/cl/) and the heat methods' device paths
 * (src/sdf/sdf_cl.c, distance_cl.c, extend_cl.c). Kernels come from
 * kernels/<name>.cl, embedded into the library at build time
 * (build/gen/kernels.c); kernels/common.cl heads every program.
 *
 * One context per process and device, shared by reference count; a module's
 * program is built on that context when first asked for and kept with it. Every hv_cl handle has its own in-order queue and kernel
 * objects, so handles may be used from different threads (one thread per
 * handle).
 *
 * Launch helpers never return errors: the first failure since the last check
 * is kept in the handle and hv__cl_check() turns it into HV_ERR_BACKEND naming
 * the call, so that a sequence of enqueues reads straight.
 */
#ifndef HV_CL_CL_CORE_H
#define HV_CL_CL_CORE_H

#include "heatvox/opencl.h"

#include <CL/cl.h>

/* kernels/common.cl, embedded by the Makefile: the head of every program. */
extern const char hv__kernel_common[];

/* Work-group size of every kernel but the single-group ones (x-major), and
 * the elements a work-item takes in a reduction (HV_WG, HV_RED_BLOCK in
 * kernels/common.cl). */
#define HV_CL_WG 64
#define HV_CL_RED_BLOCK 16

typedef struct hv_cl_shared hv_cl_shared;
typedef struct hv_cl_module hv_cl_module;

/* Modules whose kernels one handle can hold at once. */
#define HV_CL_MODULES 8

typedef struct hv_cl {
    hv_cl_shared *sh;
    cl_context ctx;
    cl_device_id dev;
    cl_command_queue q;
    int fp64;      /* double kernels built (HV_FP64): acc_t is double */
    size_t acc;    /* sizeof(acc_t) on the device: 8 or 4 */
    size_t max_wg; /* device work-group limit */
    hv_opencl_device info;
    cl_mem part; /* acc_t partial sums of hv__cl_dot_f */
    size_t part_cap;
    cl_int err; /* first failure since the last hv__cl_check */
    char err_where[96];
    struct {
        const hv_cl_module *m;
        cl_kernel *k;     /* one per kernel of m (NULL: not built on this handle) */
    } mod[HV_CL_MODULES]; /* modules' kernels made on this handle (hv__cl_module_open) */
    int nmod;
    int profile; /* events kept for hv_opencl_profile_take (cl_profile.c) */
    int nev;
    cl_event *ev;
    const char **evname;
    size_t *evbytes; /* bytes a transfer event moved between host and device */
} hv_cl;

/* Events a profiling handle holds before it reads them. */
#define HV_CL_PROFILE_EVENTS 4096

/* Opens the device chosen by HEATVOX_OPENCL_DEVICE (hv_opencl_probe), with
 * its context (shared per process) and a queue of the handle's own; no
 * kernel is built until a module is opened. HV_ERR_UNSUPPORTED without an
 * OpenCL platform or device, HV_ERR_INVALID_ARG for a bad device choice.
 * HEATVOX_OPENCL_FP64=0 builds without double precision even where the device
 * has it (tests use it to exercise the float-only path). */
hv_status hv__cl_open(hv_cl **out);
/* The next hv__cl_open on this thread opens on the caller's context, device
 * and in-order queue (retained by the handle) instead of heatvox's own, and
 * forgets them; NULLs forget them without an open. */
void hv__cl_adopt(cl_context ctx, cl_device_id dev, cl_command_queue q);
void hv__cl_close(hv_cl **cl);

/* Profiling (cl_profile.c), on with HEATVOX_OPENCL_PROFILE=1: a command
 * enqueued with the event of hv__cl_profile_event(cl, name) (NULL when off)
 * and then hv__cl_profile_done(cl, its status) adds its device time to name;
 * hv__cl_profile_flush reads the handle's events. */
int hv__cl_profiling(void);
cl_event *hv__cl_profile_event(hv_cl *cl, const char *name);
void hv__cl_profile_done(hv_cl *cl, cl_int e);
/* The same for a transfer of `bytes` between host and device. */
void hv__cl_profile_moved(hv_cl *cl, cl_int e, size_t bytes);
/* Adds bytes under name without an event (a buffer made from host memory). */
void hv__cl_profile_count(hv_cl *cl, const char *name, size_t bytes);
void hv__cl_profile_flush(hv_cl *cl);

/* Builds a program from sources on cl's device; HV_ERR_BACKEND with the
 * (truncated) build log when it fails. The caller releases *prog. */
hv_status hv__cl_build(hv_cl *cl, const char *const *sources, int nsrc, const char *options,
                       cl_program *prog);

const char *hv__cl_strerror(cl_int e);

/* ---------- modules: the kernels of one owner ----------
 * An owner of kernels describes them once, as a const hv_cl_module of static
 * storage, and launches them through a handle by their index in the
 * description. Its program is kernels/common.cl followed by the module's
 * sources, built with the options every program shares (-DHV_WG,
 * -DHV_RED_BLOCK, -DHV_FP64 on fp64 handles): once per context, when first
 * asked for, and kept until the context goes, so that repeated calls do not
 * rebuild it (and PoCL's program cache keeps it across processes). The
 * description is the cache key: one object per module, never a temporary.
 * tests/check_kernels.sh reads every description from the code and compiles
 * its program offline. */
struct hv_cl_module {
    const char *name;           /* for messages: "extend" */
    const char *const *sources; /* NULL-terminated, after kernels/common.cl */
    const char *const *kernels; /* kernel names, NULL-terminated: the module's launch indices */
    int fp64;                   /* 1: its kernels are built only with HV_FP64 (fp64 handles) */
    int first_fp64;             /* > 0: kernels from this index on exist only with HV_FP64
                                 * (left NULL on other handles); 0: none such */
};

/* The program of module m on cl's context, built on first use (HV_ERR_BACKEND
 * with the build log when it fails). Owned by the context: do not release. */
hv_status hv__cl_program(hv_cl *cl, const hv_cl_module *m, cl_program *prog);
/* Makes m's kernels on cl (once per handle; later calls return at once), so
 * that they can be launched with hv__cl_args / hv__cl_run. Call it
 * where errors can be reported: a launch of a module not opened opens it
 * itself, but a failure there reaches hv__cl_check without the build log.
 * HV_ERR_UNSUPPORTED for an fp64 module on a handle without fp64. */
hv_status hv__cl_module_open(hv_cl *cl, const hv_cl_module *m);
/* HV_OK, or HV_ERR_BACKEND for the first failure recorded since the last check. */
hv_status hv__cl_check(hv_cl *cl);
/* Waits for the queue, then hv__cl_check. */
hv_status hv__cl_finish(hv_cl *cl);
/* Records e (when not CL_SUCCESS and nothing is recorded yet); returns e != 0. */
int hv__cl_fail(hv_cl *cl, cl_int e, const char *where);

/* Buffers: bytes (at least 1), initialized from init when not NULL. */
hv_status hv__cl_alloc(hv_cl *cl, size_t bytes, const void *init, cl_mem *out);
void hv__cl_free(cl_mem *m);
void hv__cl_write(hv_cl *cl, cl_mem m, size_t offset, size_t bytes, const void *src);
/* Blocking read: a host synchronization. */
void hv__cl_read(hv_cl *cl, cl_mem m, size_t offset, size_t bytes, void *dst);
void hv__cl_zero(hv_cl *cl, cl_mem m, size_t bytes);
/* bytes (a multiple of size) of m set to the pattern of size bytes (1, 2, 4 ...). */
void hv__cl_fill(hv_cl *cl, cl_mem m, size_t bytes, const void *pattern, size_t size);
void hv__cl_copy(hv_cl *cl, cl_mem src, cl_mem dst, size_t bytes);
/* HV_OK when m is a buffer on cl's context of at least count floats, else
 * HV_ERR_INVALID_ARG with a message "<who>: <what> ..." saying which. */
hv_status hv__cl_check_floats(const hv_cl *cl, cl_mem m, size_t count, const char *who,
                              const char *what);
/* The same from byte src_off of src to byte dst_off of dst. */
void hv__cl_copy_at(hv_cl *cl, cl_mem src, size_t src_off, cl_mem dst, size_t dst_off,
                    size_t bytes);

/* Sets the arguments of kernel k (an index into m->kernels) of module m from
 * a format: m cl_mem (may be NULL), i int, l size_t as ulong, f float (pass a
 * double), a acc_t (pass a double), I int4 (const cl_int *), F float4 (const
 * cl_float *), A acc4_t (const double *). A module not opened on cl is opened
 * here (a failure reaches hv__cl_check without the build log). */
void hv__cl_args(hv_cl *cl, const hv_cl_module *m, int k, const char *fmt, ...);
/* Enqueues kernel k of module m on a 1D or 2D range. */
void hv__cl_run(hv_cl *cl, const hv_cl_module *m, int k, int dims, const size_t *global,
                const size_t *local);

/* Ranges: 2D over (nx, rows) with work-groups of HV_CL_WG x 1 items, and 1D
 * over n items. */
void hv__cl_range2(size_t nx, size_t rows, size_t g[2], size_t l[2]);
void hv__cl_range1(size_t n, size_t g[1], size_t l[1]);
/* want (a power of two) halved until kernel k of module m accepts
 * work-groups that large. */
size_t hv__cl_group_limit(hv_cl *cl, const hv_cl_module *m, int k, size_t want);
/* Range of a block reduction over n elements; returns the number of groups. */
size_t hv__cl_range_red(size_t n, size_t g[1], size_t l[1]);

/* Reads n acc_t values from S as doubles (a host synchronization). */
void hv__cl_read_acc(hv_cl *cl, cl_mem S, int first, int n, double *out);

#endif
