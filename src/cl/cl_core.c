/* OpenCL devices, the shared context, the modules' programs and launch
 * helpers (cl_core.h). */
#include "cl_core.h"
#include "core/error.h"

#include <CL/cl_ext.h>
#include <ctype.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef CL_PLATFORM_NOT_FOUND_KHR
#define CL_PLATFORM_NOT_FOUND_KHR -1001
#endif

#define MAX_PLATFORMS 16
#define MAX_DEVICES 64

const char *hv__cl_strerror(cl_int e)
{
    switch (e) {
    case CL_SUCCESS: return "CL_SUCCESS";
    case CL_DEVICE_NOT_FOUND: return "CL_DEVICE_NOT_FOUND";
    case CL_DEVICE_NOT_AVAILABLE: return "CL_DEVICE_NOT_AVAILABLE";
    case CL_COMPILER_NOT_AVAILABLE: return "CL_COMPILER_NOT_AVAILABLE";
    case CL_MEM_OBJECT_ALLOCATION_FAILURE: return "CL_MEM_OBJECT_ALLOCATION_FAILURE";
    case CL_OUT_OF_RESOURCES: return "CL_OUT_OF_RESOURCES";
    case CL_OUT_OF_HOST_MEMORY: return "CL_OUT_OF_HOST_MEMORY";
    case CL_BUILD_PROGRAM_FAILURE: return "CL_BUILD_PROGRAM_FAILURE";
    case CL_INVALID_VALUE: return "CL_INVALID_VALUE";
    case CL_INVALID_DEVICE: return "CL_INVALID_DEVICE";
    case CL_INVALID_CONTEXT: return "CL_INVALID_CONTEXT";
    case CL_INVALID_COMMAND_QUEUE: return "CL_INVALID_COMMAND_QUEUE";
    case CL_INVALID_MEM_OBJECT: return "CL_INVALID_MEM_OBJECT";
    case CL_INVALID_BUILD_OPTIONS: return "CL_INVALID_BUILD_OPTIONS";
    case CL_INVALID_PROGRAM: return "CL_INVALID_PROGRAM";
    case CL_INVALID_PROGRAM_EXECUTABLE: return "CL_INVALID_PROGRAM_EXECUTABLE";
    case CL_INVALID_KERNEL_NAME: return "CL_INVALID_KERNEL_NAME";
    case CL_INVALID_KERNEL: return "CL_INVALID_KERNEL";
    case CL_INVALID_ARG_INDEX: return "CL_INVALID_ARG_INDEX";
    case CL_INVALID_ARG_VALUE: return "CL_INVALID_ARG_VALUE";
    case CL_INVALID_ARG_SIZE: return "CL_INVALID_ARG_SIZE";
    case CL_INVALID_KERNEL_ARGS: return "CL_INVALID_KERNEL_ARGS";
    case CL_INVALID_WORK_DIMENSION: return "CL_INVALID_WORK_DIMENSION";
    case CL_INVALID_WORK_GROUP_SIZE: return "CL_INVALID_WORK_GROUP_SIZE";
    case CL_INVALID_GLOBAL_WORK_SIZE: return "CL_INVALID_GLOBAL_WORK_SIZE";
    case CL_INVALID_BUFFER_SIZE: return "CL_INVALID_BUFFER_SIZE";
    case CL_INVALID_OPERATION: return "CL_INVALID_OPERATION";
    case CL_PLATFORM_NOT_FOUND_KHR: return "CL_PLATFORM_NOT_FOUND_KHR";
    }
    return "unknown OpenCL error";
}

/* ---------- devices ---------- */

typedef struct devlist {
    int n;
    cl_platform_id plat[MAX_DEVICES];
    cl_device_id dev[MAX_DEVICES];
    hv_opencl_device info[MAX_DEVICES];
} devlist;

/* A string property, truncated to size (the query itself fails on a short buffer). */
static void info_string(cl_platform_id p, cl_device_id d, cl_uint param, char *dst, size_t size)
{
    char buf[1024] = "";
    cl_int e = d ? clGetDeviceInfo(d, param, sizeof buf - 1, buf, NULL)
                 : clGetPlatformInfo(p, param, sizeof buf - 1, buf, NULL);
    if (e != CL_SUCCESS)
        buf[0] = 0;
    buf[sizeof buf - 1] = 0;
    snprintf(dst, size, "%s", buf);
}

static void device_info(cl_platform_id p, cl_device_id d, hv_opencl_device *o)
{
    cl_ulong mem = 0;
    cl_uint cu = 0;
    cl_device_type type = 0;
    cl_device_fp_config fp = 0;
    char ext[8192] = "";
    info_string(p, d, CL_DEVICE_NAME, o->name, sizeof o->name);
    info_string(p, NULL, CL_PLATFORM_NAME, o->platform_name, sizeof o->platform_name);
    info_string(p, d, CL_DEVICE_VERSION, o->version, sizeof o->version);
    clGetDeviceInfo(d, CL_DEVICE_GLOBAL_MEM_SIZE, sizeof mem, &mem, NULL);
    clGetDeviceInfo(d, CL_DEVICE_MAX_COMPUTE_UNITS, sizeof cu, &cu, NULL);
    clGetDeviceInfo(d, CL_DEVICE_TYPE, sizeof type, &type, NULL);
    if (clGetDeviceInfo(d, CL_DEVICE_DOUBLE_FP_CONFIG, sizeof fp, &fp, NULL) != CL_SUCCESS)
        fp = 0;
    clGetDeviceInfo(d, CL_DEVICE_EXTENSIONS, sizeof ext - 1, ext, NULL);
    o->global_mem = mem;
    o->compute_units = (int)cu;
    o->gpu = (type & CL_DEVICE_TYPE_GPU) != 0;
    o->fp64 = fp != 0 || strstr(ext, "cl_khr_fp64") != NULL;
}

static hv_status enumerate(devlist *L)
{
    cl_platform_id p[MAX_PLATFORMS];
    cl_uint np = 0;
    L->n = 0;
    cl_int e = clGetPlatformIDs(MAX_PLATFORMS, p, &np);
    if (e == CL_PLATFORM_NOT_FOUND_KHR || (e == CL_SUCCESS && np == 0))
        return hv__error(HV_ERR_UNSUPPORTED,
                         "no OpenCL platform is installed (an ICD such as "
                         "Debian's pocl-opencl-icd or a GPU driver provides one)");
    if (e != CL_SUCCESS)
        return hv__error(HV_ERR_UNSUPPORTED, "OpenCL: clGetPlatformIDs failed: %s",
                         hv__cl_strerror(e));
    if (np > MAX_PLATFORMS)
        np = MAX_PLATFORMS;
    for (cl_uint pi = 0; pi < np; pi++) {
        cl_device_id d[MAX_DEVICES];
        cl_uint nd = 0;
        if (clGetDeviceIDs(p[pi], CL_DEVICE_TYPE_ALL, MAX_DEVICES, d, &nd) != CL_SUCCESS)
            continue;
        for (cl_uint di = 0; di < nd && di < MAX_DEVICES && L->n < MAX_DEVICES; di++) {
            hv_opencl_device *o = &L->info[L->n];
            memset(o, 0, sizeof *o);
            o->platform = (int)pi;
            o->device = (int)di;
            device_info(p[pi], d[di], o);
            L->plat[L->n] = p[pi];
            L->dev[L->n] = d[di];
            L->n++;
        }
    }
    if (L->n == 0)
        return hv__error(HV_ERR_UNSUPPORTED, "OpenCL platforms are installed but offer no device");
    return HV_OK;
}

/* Index into L of the device HEATVOX_OPENCL_DEVICE names (or the default). */
static hv_status choose(const devlist *L, int *index)
{
    const char *spec = getenv("HEATVOX_OPENCL_DEVICE");
    *index = -1;
    if (!spec || !*spec) {
        for (int i = 0; i < L->n && *index < 0; i++)
            if (L->info[i].gpu)
                *index = i;
        if (*index < 0)
            *index = 0;
        return HV_OK;
    }
    int P, D, used = 0;
    if (sscanf(spec, "%d:%d%n", &P, &D, &used) == 2 && spec[used] == '\0') {
        for (int i = 0; i < L->n; i++)
            if (L->info[i].platform == P && L->info[i].device == D)
                *index = i;
    } else {
        for (int i = 0; i < L->n && *index < 0; i++)
            if (strcasestr(L->info[i].name, spec))
                *index = i;
    }
    if (*index >= 0)
        return HV_OK;
    char list[600] = "";
    size_t len = 0;
    for (int i = 0; i < L->n && len < sizeof list - 1; i++) {
        int w = snprintf(list + len, sizeof list - len, "%s%d:%d '%s'", i ? ", " : "",
                         L->info[i].platform, L->info[i].device, L->info[i].name);
        if (w < 0)
            break;
        len += (size_t)w;
    }
    return hv__error(HV_ERR_INVALID_ARG,
                     "HEATVOX_OPENCL_DEVICE='%s' names no OpenCL device (give \"P:D\" or part of a "
                     "device name); devices: %s",
                     spec, list);
}

hv_status hv_opencl_list_devices(hv_opencl_device *out, int max, int *count)
{
    if (!count || max < 0 || (max > 0 && !out))
        return hv__error(HV_ERR_INVALID_ARG, "hv_opencl_list_devices: bad arguments");
    *count = 0;
    devlist *L = malloc(sizeof *L);
    if (!L)
        return hv__error(HV_ERR_NOMEM, "hv_opencl_list_devices: out of memory");
    hv_status st = enumerate(L);
    if (st == HV_OK) {
        int sel = -1;
        if (choose(L, &sel) != HV_OK)
            sel = -1;
        hv_clear_error();
        for (int i = 0; i < L->n && i < max; i++) {
            out[i] = L->info[i];
            out[i].selected = i == sel;
        }
        *count = L->n;
    }
    free(L);
    return st;
}

hv_status hv_opencl_probe(hv_opencl_device *out)
{
    devlist *L = malloc(sizeof *L);
    if (!L)
        return hv__error(HV_ERR_NOMEM, "hv_opencl_probe: out of memory");
    int sel = -1;
    hv_status st = enumerate(L);
    if (st == HV_OK)
        st = choose(L, &sel);
    if (st == HV_OK && out) {
        *out = L->info[sel];
        out->selected = 1;
    }
    free(L);
    return st;
}

/* ---------- the shared context and programs ---------- */

/* A module's program on one context (hv__cl_program). */
typedef struct modprog {
    struct modprog *next;
    const hv_cl_module *m;
    cl_program prog;
} modprog;

struct hv_cl_shared {
    hv_cl_shared *next;
    int refs;
    cl_device_id dev;
    int fp64;
    cl_context ctx;
    int adopted;   /* ctx is a caller's (retained), not one heatvox made */
    modprog *mods; /* modules' programs, built on first use */
};

static pthread_mutex_t shared_lock = PTHREAD_MUTEX_INITIALIZER;
static hv_cl_shared *shared_list;

static hv_status build_program(cl_context ctx, cl_device_id dev, const char *devname,
                               const char *const *sources, int nsrc, const char *options,
                               cl_program *prog)
{
    cl_int e;
    *prog = clCreateProgramWithSource(ctx, (cl_uint)nsrc, (const char **)sources, NULL, &e);
    if (e != CL_SUCCESS)
        return hv__error(HV_ERR_BACKEND, "OpenCL: clCreateProgramWithSource failed: %s",
                         hv__cl_strerror(e));
    e = clBuildProgram(*prog, 1, &dev, options, NULL, NULL);
    if (e == CL_SUCCESS)
        return HV_OK;
    /* The first lines of the log name the first error; keep those. */
    char log[640] = "";
    size_t got = 0;
    clGetProgramBuildInfo(*prog, dev, CL_PROGRAM_BUILD_LOG, 0, NULL, &got);
    char *full = got ? malloc(got + 1) : NULL;
    if (full &&
        clGetProgramBuildInfo(*prog, dev, CL_PROGRAM_BUILD_LOG, got, full, NULL) == CL_SUCCESS) {
        full[got] = 0;
        const char *s = full;
        while (*s && isspace((unsigned char)*s))
            s++;
        snprintf(log, sizeof log, "%s", s);
        if (strlen(s) >= sizeof log)
            memcpy(log + sizeof log - 5, "...", 4);
    }
    free(full);
    clReleaseProgram(*prog);
    *prog = NULL;
    return hv__error(HV_ERR_BACKEND, "OpenCL kernels failed to build on '%s' (%s): %s", devname,
                     hv__cl_strerror(e), *log ? log : "(no build log)");
}

/* The options of every program on a context: the solver's and the modules'
 * kernels see the same HV_WG, HV_RED_BLOCK and precision. */
static void build_options(int fp64, char *opts, size_t size)
{
    snprintf(opts, size, "-cl-std=CL1.2 -DHV_WG=%d -DHV_RED_BLOCK=%d%s", HV_CL_WG, HV_CL_RED_BLOCK,
             fp64 ? " -DHV_FP64=1" : "");
}

/* The shared state of (context, device, precision): heatvox's own context on
 * the device (ctx NULL), or the caller's ctx, retained. */
static hv_status shared_get(cl_platform_id plat, cl_device_id dev, int fp64, const char *devname,
                            cl_context ctx, hv_cl_shared **out)
{
    for (hv_cl_shared *s = shared_list; s; s = s->next)
        if (s->dev == dev && s->fp64 == fp64 && (ctx ? s->ctx == ctx : !s->adopted)) {
            s->refs++;
            *out = s;
            return HV_OK;
        }
    hv_cl_shared *s = calloc(1, sizeof *s);
    if (!s)
        return hv__error(HV_ERR_NOMEM, "OpenCL: out of memory");
    cl_int e = CL_SUCCESS;
    if (ctx) {
        e = clRetainContext(ctx);
        s->ctx = ctx;
        s->adopted = 1;
    } else {
        cl_context_properties props[] = {CL_CONTEXT_PLATFORM, (cl_context_properties)plat, 0};
        s->ctx = clCreateContext(props, 1, &dev, NULL, NULL, &e);
    }
    if (e != CL_SUCCESS) {
        free(s);
        return hv__error(HV_ERR_BACKEND, "OpenCL: cannot %s a context on '%s': %s",
                         ctx ? "retain" : "create", devname, hv__cl_strerror(e));
    }
    s->dev = dev;
    s->fp64 = fp64;
    s->refs = 1;
    s->next = shared_list;
    shared_list = s;
    *out = s;
    return HV_OK;
}

static void shared_put(hv_cl_shared *s)
{
    pthread_mutex_lock(&shared_lock);
    if (--s->refs == 0) {
        for (hv_cl_shared **pp = &shared_list; *pp; pp = &(*pp)->next)
            if (*pp == s) {
                *pp = s->next;
                break;
            }
        while (s->mods) {
            modprog *mp = s->mods;
            s->mods = mp->next;
            clReleaseProgram(mp->prog);
            free(mp);
        }
        clReleaseContext(s->ctx);
        free(s);
    }
    pthread_mutex_unlock(&shared_lock);
}

void hv__cl_close(hv_cl **pcl)
{
    if (!pcl || !*pcl)
        return;
    hv_cl *cl = *pcl;
    hv__cl_profile_flush(cl);
    free(cl->ev);
    free(cl->evname);
    free(cl->evbytes);
    hv__cl_free(&cl->part);
    for (int i = 0; i < cl->nmod; i++) {
        for (int k = 0; cl->mod[i].m->kernels[k]; k++)
            if (cl->mod[i].k[k])
                clReleaseKernel(cl->mod[i].k[k]);
        free(cl->mod[i].k);
    }
    if (cl->q)
        clReleaseCommandQueue(cl->q);
    if (cl->sh)
        shared_put(cl->sh);
    free(cl);
    *pcl = NULL;
}

static hv_status open_finish(hv_cl *cl, hv_cl **out);

/* A context, device and queue of the caller's that the next hv__cl_open on
 * this thread takes (hv__cl_adopt), instead of heatvox's own. */
static _Thread_local struct {
    cl_context ctx;
    cl_device_id dev;
    cl_command_queue q;
} adopt;

void hv__cl_adopt(cl_context ctx, cl_device_id dev, cl_command_queue q)
{
    adopt.ctx = ctx;
    adopt.dev = dev;
    adopt.q = q;
}

/* The queue must be an in-order queue of dev on ctx: heatvox's commands
 * depend on the order they are enqueued in. */
static hv_status check_adopted(cl_context ctx, cl_device_id dev, cl_command_queue q)
{
    cl_context qc = NULL;
    cl_device_id qd = NULL;
    cl_command_queue_properties props = 0;
    cl_int e = clGetCommandQueueInfo(q, CL_QUEUE_CONTEXT, sizeof qc, &qc, NULL);
    if (e == CL_SUCCESS)
        e = clGetCommandQueueInfo(q, CL_QUEUE_DEVICE, sizeof qd, &qd, NULL);
    if (e == CL_SUCCESS)
        e = clGetCommandQueueInfo(q, CL_QUEUE_PROPERTIES, sizeof props, &props, NULL);
    if (e != CL_SUCCESS)
        return hv__error(HV_ERR_INVALID_ARG, "OpenCL: the command queue cannot be queried: %s",
                         hv__cl_strerror(e));
    if (qc != ctx || qd != dev)
        return hv__error(HV_ERR_INVALID_ARG,
                         "OpenCL: the command queue belongs to another %s than the one given",
                         qc != ctx ? "context" : "device");
    if (props & CL_QUEUE_OUT_OF_ORDER_EXEC_MODE_ENABLE)
        return hv__error(HV_ERR_INVALID_ARG,
                         "OpenCL: the command queue runs out of order; heatvox needs an in-order "
                         "queue");
    return HV_OK;
}

/* hv__cl_open on the adopted context, device and queue. */
static hv_status open_adopted(hv_cl *cl, hv_cl **out)
{
    cl_context ctx = adopt.ctx;
    cl_device_id dev = adopt.dev;
    cl_command_queue q = adopt.q;
    hv__cl_adopt(NULL, NULL, NULL);
    cl_platform_id plat = NULL;
    hv_status st = check_adopted(ctx, dev, q);
    if (!st && clGetDeviceInfo(dev, CL_DEVICE_PLATFORM, sizeof plat, &plat, NULL) != CL_SUCCESS)
        st = hv__error(HV_ERR_INVALID_ARG, "OpenCL: the device cannot be queried");
    if (st) {
        free(cl);
        return st;
    }
    device_info(plat, dev, &cl->info);
    cl->info.platform = cl->info.device = -1;
    cl->info.selected = 1;
    const char *no64 = getenv("HEATVOX_OPENCL_FP64");
    cl->fp64 = cl->info.fp64 && !(no64 && !strcmp(no64, "0"));
    cl->dev = dev;
    pthread_mutex_lock(&shared_lock);
    st = shared_get(plat, dev, cl->fp64, cl->info.name, ctx, &cl->sh);
    pthread_mutex_unlock(&shared_lock);
    if (st) {
        free(cl);
        return st;
    }
    cl->ctx = ctx;
    cl_int e = clRetainCommandQueue(q);
    if (e != CL_SUCCESS) {
        hv__cl_close(&cl);
        return hv__error(HV_ERR_BACKEND, "OpenCL: cannot retain the command queue: %s",
                         hv__cl_strerror(e));
    }
    cl->q = q;
    cl_command_queue_properties props = 0;
    clGetCommandQueueInfo(q, CL_QUEUE_PROPERTIES, sizeof props, &props, NULL);
    cl->profile = (props & CL_QUEUE_PROFILING_ENABLE) != 0;
    return open_finish(cl, out);
}

hv_status hv__cl_open(hv_cl **out)
{
    *out = NULL;
    hv_cl *cl = calloc(1, sizeof *cl);
    if (cl && adopt.ctx)
        return open_adopted(cl, out);
    devlist *L = malloc(sizeof *L);
    if (!cl || !L) {
        free(cl);
        free(L);
        return hv__error(HV_ERR_NOMEM, "OpenCL: out of memory");
    }
    pthread_mutex_lock(&shared_lock);
    int sel = -1;
    hv_status st = enumerate(L);
    if (st == HV_OK)
        st = choose(L, &sel);
    if (st == HV_OK) {
        const char *no64 = getenv("HEATVOX_OPENCL_FP64");
        cl->info = L->info[sel];
        cl->info.selected = 1;
        cl->fp64 = cl->info.fp64 && !(no64 && !strcmp(no64, "0"));
        cl->dev = L->dev[sel];
        st = shared_get(L->plat[sel], cl->dev, cl->fp64, cl->info.name, NULL, &cl->sh);
    }
    pthread_mutex_unlock(&shared_lock);
    free(L);
    if (st) {
        free(cl);
        return st;
    }
    cl->ctx = cl->sh->ctx;
    cl_int e;
    cl->profile = hv__cl_profiling();
    cl->q = clCreateCommandQueue(cl->ctx, cl->dev, cl->profile ? CL_QUEUE_PROFILING_ENABLE : 0, &e);
    if (e != CL_SUCCESS) {
        hv__cl_close(&cl);
        return hv__error(HV_ERR_BACKEND, "OpenCL: cannot create a command queue: %s",
                         hv__cl_strerror(e));
    }
    return open_finish(cl, out);
}

/* The end of opening a handle on its context and queue: profiling and the
 * device's limits. Closes cl on failure. */
static hv_status open_finish(hv_cl *cl, hv_cl **out)
{
    cl->acc = cl->fp64 ? sizeof(cl_double) : sizeof(cl_float);
    if (cl->profile) {
        cl->ev = malloc(HV_CL_PROFILE_EVENTS * sizeof *cl->ev);
        cl->evname = malloc(HV_CL_PROFILE_EVENTS * sizeof *cl->evname);
        cl->evbytes = malloc(HV_CL_PROFILE_EVENTS * sizeof *cl->evbytes);
        if (!cl->ev || !cl->evname || !cl->evbytes) {
            hv__cl_close(&cl);
            return hv__error(HV_ERR_NOMEM, "OpenCL: out of memory");
        }
    }
    size_t wg = 0;
    clGetDeviceInfo(cl->dev, CL_DEVICE_MAX_WORK_GROUP_SIZE, sizeof wg, &wg, NULL);
    cl->max_wg = wg;
    if (wg < HV_CL_WG) {
        hv__cl_close(&cl);
        return hv__error(HV_ERR_UNSUPPORTED,
                         "OpenCL device '%s' allows work-groups of %zu items; "
                         "heatvox needs %d",
                         cl->info.name, wg, HV_CL_WG);
    }
    *out = cl;
    return HV_OK;
}

hv_status hv__cl_build(hv_cl *cl, const char *const *sources, int nsrc, const char *options,
                       cl_program *prog)
{
    return build_program(cl->ctx, cl->dev, cl->info.name, sources, nsrc, options, prog);
}

/* ---------- modules' programs and kernels ---------- */

hv_status hv__cl_program(hv_cl *cl, const hv_cl_module *m, cl_program *prog)
{
    *prog = NULL;
    hv_status st = HV_OK;
    pthread_mutex_lock(&shared_lock);
    modprog *mp = cl->sh->mods;
    while (mp && mp->m != m)
        mp = mp->next;
    if (!mp) {
        int nsrc = 0;
        while (m->sources[nsrc])
            nsrc++;
        const char **src = malloc(((size_t)nsrc + 1) * sizeof *src);
        if (!src || !(mp = calloc(1, sizeof *mp))) {
            free(src);
            pthread_mutex_unlock(&shared_lock);
            return hv__error(HV_ERR_NOMEM, "OpenCL: out of memory");
        }
        src[0] = hv__kernel_common;
        for (int i = 0; i < nsrc; i++)
            src[i + 1] = m->sources[i];
        char opts[128];
        build_options(cl->sh->fp64, opts, sizeof opts);
        st = build_program(cl->ctx, cl->dev, cl->info.name, src, nsrc + 1, opts, &mp->prog);
        free(src);
        if (st) {
            free(mp);
            mp = NULL;
        } else {
            mp->m = m;
            mp->next = cl->sh->mods;
            cl->sh->mods = mp;
        }
    }
    if (mp)
        *prog = mp->prog;
    pthread_mutex_unlock(&shared_lock);
    return st;
}

/* m's kernels on cl, NULL when not opened there. */
static cl_kernel *module_kernels(const hv_cl *cl, const hv_cl_module *m)
{
    for (int i = 0; i < cl->nmod; i++)
        if (cl->mod[i].m == m)
            return cl->mod[i].k;
    return NULL;
}

hv_status hv__cl_module_open(hv_cl *cl, const hv_cl_module *m)
{
    if (module_kernels(cl, m))
        return HV_OK;
    if (m->fp64 && !cl->fp64)
        return hv__error(HV_ERR_UNSUPPORTED,
                         "OpenCL: the %s kernels need fp64, which '%s' lacks "
                         "(or HEATVOX_OPENCL_FP64=0)",
                         m->name, cl->info.name);
    if (cl->nmod == HV_CL_MODULES)
        return hv__error(HV_ERR_BACKEND, "OpenCL: more than %d kernel modules on one handle",
                         HV_CL_MODULES);
    cl_program prog;
    hv_status st = hv__cl_program(cl, m, &prog);
    if (st)
        return st;
    int nk = 0;
    while (m->kernels[nk])
        nk++;
    cl_kernel *k = calloc((size_t)nk + 1, sizeof *k);
    if (!k)
        return hv__error(HV_ERR_NOMEM, "OpenCL: out of memory");
    for (int i = 0; i < nk; i++) {
        if (m->first_fp64 > 0 && i >= m->first_fp64 && !cl->fp64)
            continue;
        cl_int e;
        k[i] = clCreateKernel(prog, m->kernels[i], &e);
        if (e != CL_SUCCESS) {
            for (int j = 0; j < i; j++)
                if (k[j])
                    clReleaseKernel(k[j]);
            free(k);
            return hv__error(HV_ERR_BACKEND, "OpenCL: kernel '%s' of the %s kernels is missing: %s",
                             m->kernels[i], m->name, hv__cl_strerror(e));
        }
    }
    cl->mod[cl->nmod].m = m;
    cl->mod[cl->nmod].k = k;
    cl->nmod++;
    return HV_OK;
}

/* Kernel k of module m on cl, opening the module on first use; NULL (the
 * failure recorded in cl) when it cannot be had: the module does not build,
 * or the kernel exists only with fp64 and cl has none. */
static cl_kernel module_kernel(hv_cl *cl, const hv_cl_module *m, int k)
{
    cl_kernel *ks = module_kernels(cl, m);
    if (!ks && cl->err == CL_SUCCESS && hv__cl_module_open(cl, m) == HV_OK)
        ks = module_kernels(cl, m);
    char where[96];
    if (!ks) {
        snprintf(where, sizeof where, "building the %s kernels", m->name);
        hv__cl_fail(cl, CL_BUILD_PROGRAM_FAILURE, where);
        return NULL;
    }
    if (!ks[k]) {
        snprintf(where, sizeof where, "kernel %s (fp64 only)", m->kernels[k]);
        hv__cl_fail(cl, CL_INVALID_KERNEL, where);
    }
    return ks[k];
}

/* ---------- errors, buffers, launches ---------- */

int hv__cl_fail(hv_cl *cl, cl_int e, const char *where)
{
    if (e == CL_SUCCESS)
        return 0;
    if (cl->err == CL_SUCCESS) {
        cl->err = e;
        snprintf(cl->err_where, sizeof cl->err_where, "%s", where);
    }
    return 1;
}

hv_status hv__cl_check(hv_cl *cl)
{
    if (cl->err == CL_SUCCESS)
        return HV_OK;
    cl_int e = cl->err;
    cl->err = CL_SUCCESS;
    hv_status st = (e == CL_MEM_OBJECT_ALLOCATION_FAILURE || e == CL_OUT_OF_HOST_MEMORY)
                       ? HV_ERR_NOMEM
                       : HV_ERR_BACKEND;
    return hv__error(st, "OpenCL: %s failed on '%s': %s", cl->err_where, cl->info.name,
                     hv__cl_strerror(e));
}

hv_status hv__cl_finish(hv_cl *cl)
{
    hv__cl_fail(cl, clFinish(cl->q), "clFinish");
    hv__cl_profile_flush(cl);
    return hv__cl_check(cl);
}

hv_status hv__cl_alloc(hv_cl *cl, size_t bytes, const void *init, cl_mem *out)
{
    cl_int e;
    if (bytes == 0) /* OpenCL has no empty buffers */
        init = NULL;
    *out = clCreateBuffer(cl->ctx, CL_MEM_READ_WRITE | (init ? CL_MEM_COPY_HOST_PTR : 0),
                          bytes ? bytes : 1, (void *)init, &e);
    if (e == CL_SUCCESS) {
        if (init)
            hv__cl_profile_count(cl, "write", bytes);
        return HV_OK;
    }
    *out = NULL;
    if (e == CL_INVALID_BUFFER_SIZE || e == CL_MEM_OBJECT_ALLOCATION_FAILURE ||
        e == CL_OUT_OF_RESOURCES || e == CL_OUT_OF_HOST_MEMORY)
        return hv__error(HV_ERR_NOMEM, "OpenCL: cannot allocate %zu bytes on '%s': %s", bytes,
                         cl->info.name, hv__cl_strerror(e));
    return hv__error(HV_ERR_BACKEND, "OpenCL: clCreateBuffer(%zu bytes) failed: %s", bytes,
                     hv__cl_strerror(e));
}

void hv__cl_free(cl_mem *m)
{
    if (m && *m) {
        clReleaseMemObject(*m);
        *m = NULL;
    }
}

void hv__cl_write(hv_cl *cl, cl_mem m, size_t offset, size_t bytes, const void *src)
{
    if (!bytes)
        return;
    cl_int e = clEnqueueWriteBuffer(cl->q, m, CL_TRUE, offset, bytes, src, 0, NULL,
                                    hv__cl_profile_event(cl, "write"));
    hv__cl_profile_moved(cl, e, bytes);
    hv__cl_fail(cl, e, "clEnqueueWriteBuffer");
}

void hv__cl_read(hv_cl *cl, cl_mem m, size_t offset, size_t bytes, void *dst)
{
    if (!bytes)
        return;
    cl_int e = clEnqueueReadBuffer(cl->q, m, CL_TRUE, offset, bytes, dst, 0, NULL,
                                   hv__cl_profile_event(cl, "read"));
    hv__cl_profile_moved(cl, e, bytes);
    hv__cl_fail(cl, e, "clEnqueueReadBuffer");
}

void hv__cl_zero(hv_cl *cl, cl_mem m, size_t bytes)
{
    const cl_uchar zero = 0;
    if (!bytes)
        return;
    cl_int e = clEnqueueFillBuffer(cl->q, m, &zero, 1, 0, bytes, 0, NULL,
                                   hv__cl_profile_event(cl, "fill"));
    hv__cl_profile_done(cl, e);
    hv__cl_fail(cl, e, "clEnqueueFillBuffer");
}

void hv__cl_fill(hv_cl *cl, cl_mem m, size_t bytes, const void *pattern, size_t size)
{
    if (!bytes)
        return;
    cl_int e = clEnqueueFillBuffer(cl->q, m, pattern, size, 0, bytes, 0, NULL,
                                   hv__cl_profile_event(cl, "fill"));
    hv__cl_profile_done(cl, e);
    hv__cl_fail(cl, e, "clEnqueueFillBuffer");
}

void hv__cl_copy(hv_cl *cl, cl_mem src, cl_mem dst, size_t bytes)
{
    if (!bytes)
        return;
    cl_int e = clEnqueueCopyBuffer(cl->q, src, dst, 0, 0, bytes, 0, NULL,
                                   hv__cl_profile_event(cl, "copy"));
    hv__cl_profile_done(cl, e);
    hv__cl_fail(cl, e, "clEnqueueCopyBuffer");
}

hv_status hv__cl_check_floats(const hv_cl *cl, cl_mem m, size_t count, const char *who,
                              const char *what)
{
    size_t bytes = 0;
    cl_context c = NULL;
    if (!m || clGetMemObjectInfo(m, CL_MEM_SIZE, sizeof bytes, &bytes, NULL) != CL_SUCCESS ||
        clGetMemObjectInfo(m, CL_MEM_CONTEXT, sizeof c, &c, NULL) != CL_SUCCESS)
        return hv__error(HV_ERR_INVALID_ARG, "%s: %s is no OpenCL buffer", who, what);
    if (c != cl->ctx)
        return hv__error(HV_ERR_INVALID_ARG, "%s: %s lives on another context than heatvox's", who,
                         what);
    if (bytes < count * sizeof(float))
        return hv__error(HV_ERR_INVALID_ARG, "%s: %s holds %zu bytes; %zu cells of float need %zu",
                         who, what, bytes, count, count * sizeof(float));
    return HV_OK;
}

void hv__cl_copy_at(hv_cl *cl, cl_mem src, size_t src_off, cl_mem dst, size_t dst_off, size_t bytes)
{
    if (!bytes)
        return;
    cl_int e = clEnqueueCopyBuffer(cl->q, src, dst, src_off, dst_off, bytes, 0, NULL,
                                   hv__cl_profile_event(cl, "copy"));
    hv__cl_profile_done(cl, e);
    hv__cl_fail(cl, e, "clEnqueueCopyBuffer");
}

/* Sets the arguments of kernel kk (named name, for messages). */
static void set_args(hv_cl *cl, cl_kernel kk, const char *name, const char *fmt, va_list ap)
{
    if (!kk) {
        hv__cl_fail(cl, CL_INVALID_KERNEL, name);
        return;
    }
    for (cl_uint i = 0; fmt[i]; i++) {
        cl_int e = CL_INVALID_VALUE;
        switch (fmt[i]) {
        case 'm': {
            cl_mem m = va_arg(ap, cl_mem);
            e = clSetKernelArg(kk, i, sizeof m, &m);
            break;
        }
        case 'i': {
            cl_int v = va_arg(ap, int);
            e = clSetKernelArg(kk, i, sizeof v, &v);
            break;
        }
        case 'l': {
            cl_ulong v = va_arg(ap, size_t);
            e = clSetKernelArg(kk, i, sizeof v, &v);
            break;
        }
        case 'f': {
            cl_float v = (cl_float)va_arg(ap, double);
            e = clSetKernelArg(kk, i, sizeof v, &v);
            break;
        }
        case 'a': {
            double v = va_arg(ap, double);
            cl_float f = (cl_float)v;
            e = cl->fp64 ? clSetKernelArg(kk, i, sizeof v, &v)
                         : clSetKernelArg(kk, i, sizeof f, &f);
            break;
        }
        case 'I': {
            const cl_int *v = va_arg(ap, const cl_int *);
            cl_int4 x = {{v[0], v[1], v[2], v[3]}};
            e = clSetKernelArg(kk, i, sizeof x, &x);
            break;
        }
        case 'F': {
            const cl_float *v = va_arg(ap, const cl_float *);
            cl_float4 x = {{v[0], v[1], v[2], v[3]}};
            e = clSetKernelArg(kk, i, sizeof x, &x);
            break;
        }
        case 'A': {
            const double *v = va_arg(ap, const double *);
            cl_double4 d = {{v[0], v[1], v[2], v[3]}};
            cl_float4 f = {{(cl_float)v[0], (cl_float)v[1], (cl_float)v[2], (cl_float)v[3]}};
            e = cl->fp64 ? clSetKernelArg(kk, i, sizeof d, &d)
                         : clSetKernelArg(kk, i, sizeof f, &f);
            break;
        }
        }
        if (e != CL_SUCCESS) {
            char where[96];
            snprintf(where, sizeof where, "argument %u of kernel %s", i, name);
            hv__cl_fail(cl, e, where);
            break;
        }
    }
}

/* Enqueues kernel kk (named name) on a 1D or 2D range. */
static void enqueue(hv_cl *cl, cl_kernel kk, const char *name, int dims, const size_t *global,
                    const size_t *local)
{
    for (int d = 0; d < dims; d++)
        if (global[d] == 0)
            return;
    if (!kk) {
        hv__cl_fail(cl, CL_INVALID_KERNEL, name);
        return;
    }
    cl_int e = clEnqueueNDRangeKernel(cl->q, kk, (cl_uint)dims, NULL, global, local, 0, NULL,
                                      hv__cl_profile_event(cl, name));
    hv__cl_profile_done(cl, e);
    if (e != CL_SUCCESS) {
        char where[96];
        snprintf(where, sizeof where, "kernel %s", name);
        hv__cl_fail(cl, e, where);
    }
}

void hv__cl_args(hv_cl *cl, const hv_cl_module *m, int k, const char *fmt, ...)
{
    cl_kernel kk = module_kernel(cl, m, k);
    if (!kk)
        return;
    va_list ap;
    va_start(ap, fmt);
    set_args(cl, kk, m->kernels[k], fmt, ap);
    va_end(ap);
}

void hv__cl_run(hv_cl *cl, const hv_cl_module *m, int k, int dims, const size_t *global,
                const size_t *local)
{
    for (int d = 0; d < dims; d++)
        if (global[d] == 0)
            return;
    cl_kernel kk = module_kernel(cl, m, k);
    if (kk)
        enqueue(cl, kk, m->kernels[k], dims, global, local);
}

size_t hv__cl_group_limit(hv_cl *cl, const hv_cl_module *m, int k, size_t want)
{
    size_t kwg = 0;
    cl_kernel kk = module_kernel(cl, m, k);
    if (!kk || clGetKernelWorkGroupInfo(kk, cl->dev, CL_KERNEL_WORK_GROUP_SIZE, sizeof kwg, &kwg,
                                        NULL) != CL_SUCCESS)
        kwg = cl->max_wg;
    while (want > 1 && want > kwg)
        want >>= 1;
    return want;
}

static size_t round_up(size_t n, size_t m) { return (n + m - 1) / m * m; }

void hv__cl_range2(size_t nx, size_t rows, size_t g[2], size_t l[2])
{
    /* One work-group shape for every level: PoCL compiles a kernel once per
     * local size, and idle items on narrow (coarse) levels cost little. */
    l[0] = HV_CL_WG;
    l[1] = 1;
    g[0] = round_up(nx, HV_CL_WG);
    g[1] = rows;
}

void hv__cl_range1(size_t n, size_t g[1], size_t l[1])
{
    l[0] = HV_CL_WG;
    g[0] = round_up(n, HV_CL_WG);
}

size_t hv__cl_range_red(size_t n, size_t g[1], size_t l[1])
{
    size_t per = (size_t)HV_CL_WG * HV_CL_RED_BLOCK, groups = (n + per - 1) / per;
    if (groups == 0)
        groups = 1;
    l[0] = HV_CL_WG;
    g[0] = groups * HV_CL_WG;
    return groups;
}

void hv__cl_read_acc(hv_cl *cl, cl_mem S, int first, int n, double *out)
{
    if (cl->fp64) {
        hv__cl_read(cl, S, (size_t)first * sizeof(double), (size_t)n * sizeof(double), out);
        return;
    }
    float tmp[64];
    for (int done = 0; done < n; done += 64) {
        int m = n - done < 64 ? n - done : 64;
        hv__cl_read(cl, S, (size_t)(first + done) * sizeof(float), (size_t)m * sizeof(float), tmp);
        for (int i = 0; i < m; i++)
            out[done + i] = cl->err ? 0.0 : tmp[i];
    }
}
