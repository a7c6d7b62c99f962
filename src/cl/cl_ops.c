/* Grid operations on an OpenCL device (cl_ops.h) and their kernels' module. */
#include "cl_ops.h"
#include "core/error.h"

#include <stdlib.h>
#include <string.h>

/* kernels/, embedded by the Makefile */
extern const char hv__kernel_reduce[], hv__kernel_faces[], hv__kernel_pointwise[];

static const char *const ops_sources[] = {hv__kernel_reduce, hv__kernel_faces, hv__kernel_pointwise,
                                          NULL};
enum {
    HV_K_RED_DOT_F,
    HV_K_RED_FINISH,
    HV_K_RED_CHUNK_F,
    HV_K_RED_REGION,
    HV_K_REGION_SUB_F,
    HV_K_FACE_GRADIENT,
    HV_K_FACE_DIVERGENCE,
    HV_K_FACE_NORMALIZE,
    HV_K_PW_RATIO,
    HV_K_PW_AXPY,
    HV_K_SCAN_BLOCK_U,
    HV_K_SCAN_ADD_U,
    HV_K_RED_CHUNK_D, /* fp64 only from here */
    HV_K_REGION_SUB_D,
    HV_K_RED_DOT_D
};
static const char *const ops_kernels[] = {
    "red_dot_f",    "red_finish",    "red_chunk_f",     "red_region",
    "region_sub_f", "face_gradient", "face_divergence", "face_normalize",
    "pw_ratio",     "pw_axpy",       "scan_block_u",    "scan_add_u",
    "red_chunk_d",  "region_sub_d",  "red_dot_d",       NULL};
const hv_cl_module hv__cl_ops_module = {"grid operation", ops_sources, ops_kernels, 0,
                                        HV_K_RED_CHUNK_D};
#define OPS (&hv__cl_ops_module)

hv_status hv__cl_ops_open(hv_cl *cl) { return hv__cl_module_open(cl, OPS); }

/* Cells per chunk: what one work-group of a block reduction takes. */
#define CHUNK (HV_CL_WG * HV_CL_RED_BLOCK)

void hv__cl_regions_destroy(hv_cl_regions *R)
{
    hv__cl_free(&R->region);
    hv__cl_free(&R->perm);
    hv__cl_free(&R->cb);
    hv__cl_free(&R->rc);
    hv__cl_free(&R->rinv);
    hv__cl_free(&R->part);
    hv__cl_free(&R->sum);
}

hv_status hv__cl_regions_create(hv_cl *cl, hv_cl_regions *R, size_t count, const int32_t *region,
                                int nregion)
{
    memset(R, 0, sizeof *R);
    if (!region)
        nregion = 1;
    if (nregion <= 0 || count == 0 || count > UINT32_MAX)
        return hv__error(HV_ERR_INVALID_ARG, "OpenCL regions: %d regions over %zu cells", nregion,
                         count);
    R->count = count;
    R->nregion = nregion;
    size_t *cells = calloc((size_t)nregion + 1, sizeof *cells);
    uint32_t *rc = malloc(((size_t)nregion + 1) * sizeof *rc);
    uint32_t *perm = region ? malloc(count * sizeof *perm) : NULL;
    double *rinv = malloc((size_t)nregion * sizeof *rinv);
    float *rinvf = malloc((size_t)nregion * sizeof *rinvf);
    uint32_t *cb = NULL;
    hv_status st = HV_OK;
    if (!cells || !rc || (region && !perm) || !rinv || !rinvf) {
        st = hv__error(HV_ERR_NOMEM, "OpenCL regions: out of memory");
        goto done;
    }
    /* counting sort of the labelled cells by region */
    if (region) {
        for (size_t c = 0; c < count; c++)
            if (region[c] >= 0 && region[c] < nregion)
                cells[region[c] + 1]++;
    } else {
        cells[1] = count;
    }
    for (int r = 0; r < nregion; r++)
        cells[r + 1] += cells[r];
    if (region) {
        size_t *pos = malloc((size_t)nregion * sizeof *pos);
        if (!pos) {
            st = hv__error(HV_ERR_NOMEM, "OpenCL regions: out of memory");
            goto done;
        }
        memcpy(pos, cells, (size_t)nregion * sizeof *pos);
        for (size_t c = 0; c < count; c++)
            if (region[c] >= 0 && region[c] < nregion)
                perm[pos[region[c]]++] = (uint32_t)c;
        free(pos);
    }
    /* chunks: each region's run cut into pieces of at most CHUNK */
    R->nchunk = 0;
    for (int r = 0; r < nregion; r++) {
        size_t len = cells[r + 1] - cells[r];
        R->nchunk += len ? (len + CHUNK - 1) / CHUNK : 1;
    }
    cb = malloc((R->nchunk + 1) * sizeof *cb);
    if (!cb) {
        st = hv__error(HV_ERR_NOMEM, "OpenCL regions: out of memory");
        goto done;
    }
    size_t k = 0;
    for (int r = 0; r < nregion; r++) {
        size_t len = cells[r + 1] - cells[r], nch = len ? (len + CHUNK - 1) / CHUNK : 1;
        rc[r] = (uint32_t)k;
        for (size_t q = 0; q < nch; q++)
            cb[k++] = (uint32_t)(cells[r] + q * CHUNK);
        rinv[r] = len ? 1.0 / (double)len : 0.0;
        rinvf[r] = (float)rinv[r];
    }
    rc[nregion] = (uint32_t)k;
    cb[k] = (uint32_t)cells[nregion];
    if ((region && ((st = hv__cl_alloc(cl, count * sizeof(int32_t), region, &R->region)) ||
                    (st = hv__cl_alloc(cl, cells[nregion] * sizeof(uint32_t), perm, &R->perm)))) ||
        (st = hv__cl_alloc(cl, (R->nchunk + 1) * sizeof(uint32_t), cb, &R->cb)) ||
        (st = hv__cl_alloc(cl, ((size_t)nregion + 1) * sizeof(uint32_t), rc, &R->rc)) ||
        (st = hv__cl_alloc(cl, (size_t)nregion * cl->acc, cl->fp64 ? (void *)rinv : (void *)rinvf,
                           &R->rinv)) ||
        (st = hv__cl_alloc(cl, R->nchunk * cl->acc, NULL, &R->part)) ||
        (st = hv__cl_alloc(cl, (size_t)nregion * cl->acc, NULL, &R->sum)))
        hv__cl_regions_destroy(R);
done:
    free(cells);
    free(rc);
    free(perm);
    free(rinv);
    free(rinvf);
    free(cb);
    return st;
}

static void region_sums(hv_cl *cl, hv_cl_regions *R, cl_mem v, int mean, int chunk)
{
    size_t l = HV_CL_WG, g = R->nchunk * HV_CL_WG;
    hv__cl_args(cl, OPS, chunk, "mmmm", v, R->perm, R->cb, R->part);
    hv__cl_run(cl, OPS, chunk, 1, &g, &l);
    size_t gr = (size_t)R->nregion * HV_CL_WG;
    hv__cl_args(cl, OPS, HV_K_RED_REGION, "mmmm", R->part, R->rc, mean ? R->rinv : NULL, R->sum);
    hv__cl_run(cl, OPS, HV_K_RED_REGION, 1, &gr, &l);
}

void hv__cl_region_sums(hv_cl *cl, hv_cl_regions *R, cl_mem v, int mean)
{
    region_sums(cl, R, v, mean, HV_K_RED_CHUNK_F);
}

void hv__cl_project(hv_cl *cl, hv_cl_regions *R, cl_mem v)
{
    region_sums(cl, R, v, 1, HV_K_RED_CHUNK_F);
    size_t g[1], l[1];
    hv__cl_range1(R->count, g, l);
    hv__cl_args(cl, OPS, HV_K_REGION_SUB_F, "mmml", v, R->region, R->sum, R->count);
    hv__cl_run(cl, OPS, HV_K_REGION_SUB_F, 1, g, l);
}

void hv__cl_project_d(hv_cl *cl, hv_cl_regions *R, cl_mem v)
{
    region_sums(cl, R, v, 1, HV_K_RED_CHUNK_D);
    size_t g[1], l[1];
    hv__cl_range1(R->count, g, l);
    hv__cl_args(cl, OPS, HV_K_REGION_SUB_D, "mmml", v, R->region, R->sum, R->count);
    hv__cl_run(cl, OPS, HV_K_REGION_SUB_D, 1, g, l);
}

static void face_range(int a, const int n[3], size_t g[2], size_t l[2])
{
    size_t m[3] = {(size_t)n[0] + (a == 0), (size_t)n[1] + (a == 1), (size_t)n[2] + (a == 2)};
    hv__cl_range2(m[0], m[1] * m[2], g, l);
}

static void dims4(int dim, const int n[3], cl_int N[4])
{
    N[0] = n[0];
    N[1] = n[1];
    N[2] = dim == 3 ? n[2] : 1;
    N[3] = dim;
}

void hv__cl_face_gradient(hv_cl *cl, int dim, const int n[3], double h, cl_mem solid, cl_mem u,
                          cl_mem const g[3])
{
    cl_int N[4];
    dims4(dim, n, N);
    for (int a = 0; a < dim; a++) {
        size_t gs[2], ls[2];
        face_range(a, N, gs, ls);
        hv__cl_args(cl, OPS, HV_K_FACE_GRADIENT, "Iifmmm", N, a, (double)(float)(1.0 / h), solid, u,
                    g[a]);
        hv__cl_run(cl, OPS, HV_K_FACE_GRADIENT, 2, gs, ls);
    }
}

void hv__cl_face_divergence(hv_cl *cl, int dim, const int n[3], double h, cl_mem solid,
                            cl_mem const F[3], cl_mem out)
{
    cl_int N[4];
    dims4(dim, n, N);
    size_t g[2], l[2];
    hv__cl_range2((size_t)N[0], (size_t)N[1] * N[2], g, l);
    hv__cl_args(cl, OPS, HV_K_FACE_DIVERGENCE, "Iammmmm", N, 1.0 / h, solid, F[0], F[1],
                dim == 3 ? F[2] : NULL, out);
    hv__cl_run(cl, OPS, HV_K_FACE_DIVERGENCE, 2, g, l);
}

void hv__cl_face_normalize(hv_cl *cl, int dim, const int n[3], cl_mem solid, cl_mem const v[3],
                           cl_mem const out[3], double eps)
{
    cl_int N[4];
    dims4(dim, n, N);
    for (int a = 0; a < dim; a++) {
        size_t g[2], l[2];
        face_range(a, N, g, l);
        hv__cl_args(cl, OPS, HV_K_FACE_NORMALIZE, "Iimmmmmf", N, a, solid, v[0], v[1],
                    dim == 3 ? v[2] : NULL, out[a], eps);
        hv__cl_run(cl, OPS, HV_K_FACE_NORMALIZE, 2, g, l);
    }
}

void hv__cl_ratio(hv_cl *cl, size_t n, cl_mem a, cl_mem b, cl_mem out, double eps)
{
    size_t g[1], l[1];
    hv__cl_range1(n, g, l);
    hv__cl_args(cl, OPS, HV_K_PW_RATIO, "mmmfl", a, b, out, eps, n);
    hv__cl_run(cl, OPS, HV_K_PW_RATIO, 1, g, l);
}

void hv__cl_axpy(hv_cl *cl, size_t n, double alpha, cl_mem x, cl_mem y)
{
    size_t g[1], l[1];
    hv__cl_range1(n, g, l);
    hv__cl_args(cl, OPS, HV_K_PW_AXPY, "fmml", alpha, x, y, n);
    hv__cl_run(cl, OPS, HV_K_PW_AXPY, 1, g, l);
}

/* ---------- prefix sums ---------- */

hv_status hv__cl_scan_u32(hv_cl *cl, cl_mem in, cl_mem out, size_t n)
{
    const size_t ng = (n + CHUNK - 1) / CHUNK;
    cl_mem sums = NULL, ssum = NULL;
    hv_status st = hv__cl_alloc(cl, (ng ? ng : 1) * sizeof(cl_uint), NULL, &sums);
    if (st)
        return st;
    size_t g[1] = {ng * HV_CL_WG}, l[1] = {HV_CL_WG};
    hv__cl_args(cl, OPS, HV_K_SCAN_BLOCK_U, "lmmm", n, in, out, sums);
    hv__cl_run(cl, OPS, HV_K_SCAN_BLOCK_U, 1, g, l);
    if (ng > 1 && !(st = hv__cl_alloc(cl, ng * sizeof(cl_uint), NULL, &ssum)) &&
        !(st = hv__cl_scan_u32(cl, sums, ssum, ng))) {
        hv__cl_range1(n, g, l);
        hv__cl_args(cl, OPS, HV_K_SCAN_ADD_U, "lmm", n, out, ssum);
        hv__cl_run(cl, OPS, HV_K_SCAN_ADD_U, 1, g, l);
    }
    /* Released with commands queued: OpenCL frees them once those ran. */
    hv__cl_free(&sums);
    hv__cl_free(&ssum);
    return st ? st : hv__cl_check(cl);
}

/* ---------- reductions ---------- */

void hv__cl_finish_sum(hv_cl *cl, cl_mem part, size_t nparts, cl_mem S, int slot)
{
    size_t l = hv__cl_group_limit(cl, OPS, HV_K_RED_FINISH, 256);
    hv__cl_args(cl, OPS, HV_K_RED_FINISH, "mlmi", part, nparts, S, slot);
    hv__cl_run(cl, OPS, HV_K_RED_FINISH, 1, &l, &l);
}

void hv__cl_dot_f(hv_cl *cl, cl_mem a, cl_mem b, size_t n, cl_mem S, int slot)
{
    size_t g[1], l[1];
    size_t groups = hv__cl_range_red(n, g, l);
    if (groups > cl->part_cap) {
        hv__cl_free(&cl->part);
        cl->part_cap = 0;
        if (hv__cl_alloc(cl, groups * cl->acc, NULL, &cl->part) != HV_OK) {
            hv__cl_fail(cl, CL_MEM_OBJECT_ALLOCATION_FAILURE, "partial sums of a reduction");
            return;
        }
        cl->part_cap = groups;
    }
    hv__cl_args(cl, OPS, HV_K_RED_DOT_F, "mmlm", a, b, n, cl->part);
    hv__cl_run(cl, OPS, HV_K_RED_DOT_F, 1, g, l);
    hv__cl_finish_sum(cl, cl->part, groups, S, slot);
}

void hv__cl_dot_parts_d(hv_cl *cl, cl_mem a, cl_mem b, size_t n, cl_mem part)
{
    size_t g[1], l[1];
    hv__cl_range_red(n, g, l);
    hv__cl_args(cl, OPS, HV_K_RED_DOT_D, "mmlm", a, b, n, part);
    hv__cl_run(cl, OPS, HV_K_RED_DOT_D, 1, g, l);
}
