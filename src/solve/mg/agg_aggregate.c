/* Smoothed aggregation (agg_internal.h): the aggregates of a level. */
#include "agg_internal.h"

/* Block coordinates of unknown c of level l. */
static void unknown_xyz(const mg_agg *g, int l, int32_t c, int xyz[3])
{
    if (l == 0) {
        const mg_level *L = g->fine;
        xyz[0] = (int)(c % L->n[0]);
        xyz[1] = (int)((c / L->n[0]) % L->n[1]);
        xyz[2] = (int)(c / L->sz);
        return;
    }
    for (int b = 0; b < 3; b++)
        xyz[b] = g->lv[l].xyz[3 * (size_t)c + b];
}

static int strong(float aij, float dii_inv, float djj_inv)
{
    double q = (double)aij * aij * dii_inv * djj_inv;
    return q > AGG_STRONG * AGG_STRONG;
}

/* The parts of one block (unknowns u[0..m) of level l) that couplings within
 * it connect: lab[q] = part of u[q]; returns the number of parts. */
static int block_parts(const agg_op *o, const int32_t *u, int m, int *lab)
{
    int parts = 0, stack[64];
    for (int q = 0; q < m; q++)
        lab[q] = -1;
    for (int q0 = 0; q0 < m; q0++) {
        if (lab[q0] >= 0)
            continue;
        int top = 0;
        stack[top++] = q0;
        lab[q0] = parts;
        while (top) {
            int q = stack[--top];
            int32_t bc[ROW_MAX];
            float bv[ROW_MAX];
            const int32_t *col;
            const float *val;
            int k = hv__agg_op_row(o, u[q], bc, bv, &col, &val);
            for (int e = 0; e < k; e++)
                for (int p = 0; p < m; p++)
                    if (u[p] == col[e] && lab[p] < 0 && p != q &&
                        strong(val[e], o->dinv[u[q]], o->dinv[col[e]])) {
                        lab[p] = parts;
                        if (top < 64)
                            stack[top++] = p;
                    }
        }
        parts++;
    }
    return parts;
}

/* Whether the 8 unknowns of a 3D block of the fine level (u in ascending
 * order: x fastest) are one part, every face between them open and strong
 * (binary levels only, where op_row reads the faces): block_parts' answer
 * without its search, for the blocks of open space. */
static int block_whole(const agg_op *o, const int32_t *u)
{
    for (int q = 0; q < 8; q++)
        for (int b = 0; b < 3; b++) {
            int hi = !(q >> b & 1), p = q ^ (1 << b);
            if (!(o->faces[u[q]] & (1u << (2 * b + hi))) ||
                !strong((float)-o->F->c[b], o->dinv[u[q]], o->dinv[u[p]]))
                return 0;
        }
    return 1;
}

/* The cells of the fine level's block (bx, by, bz) that have a row, in
 * ascending order (x fastest); returns how many. */
static int fine_block_cells(const mg_level *F, const float *dinv, int bx, int by, int bz,
                            int32_t u[8])
{
    int m = 0;
    for (int k = 2 * bz; k < 2 * bz + 2 && k < F->n[2]; k++)
        for (int j = 2 * by; j < 2 * by + 2 && j < F->n[1]; j++)
            for (int i = 2 * bx; i < 2 * bx + 2 && i < F->n[0]; i++) {
                int32_t c = (int32_t)((size_t)i + F->sy * j + F->sz * k);
                if (dinv[c] > 0)
                    u[m++] = c;
            }
    return m;
}

/* hv__agg_aggregate for the fine level, whose blocks are read off the grid:
 * in parallel over the blocks, the same aggregates, numbers and member lists
 * (the first part of block b is aggregate b, the others follow all blocks in
 * block order). */
static hv_status aggregate_fine(mg_agg *g)
{
    mg_alevel *L = &g->lv[0], *C = &g->lv[1];
    agg_op o = level_op(g, 0);
    const mg_level *F = g->fine;
    const int bx = (F->n[0] + 1) / 2, by = (F->n[1] + 1) / 2, bz = (F->n[2] + 1) / 2;
    const size_t nblk = (size_t)bx * by * bz;
    uint8_t *parts = malloc(nblk);
    size_t *extra = malloc((nblk + 1) * sizeof *extra);
    L->agg = malloc((size_t)L->n * sizeof *L->agg);
    if (!parts || !extra || !L->agg) {
        free(parts);
        free(extra);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates of level 0");
    }
#pragma omp parallel for schedule(static) if (L->n > AGG_PAR_MIN)
    for (int32_t c = 0; c < L->n; c++)
        L->agg[c] = -1;
        /* Each block's parts; L->agg holds a cell's part within its block for now. */
#pragma omp parallel for schedule(static) if (nblk > AGG_PAR_MIN)
    for (size_t b = 0; b < nblk; b++) {
        int32_t u[8];
        int lab[8];
        int m = fine_block_cells(F, o.dinv, (int)(b % bx), (int)(b / bx % by),
                                 (int)(b / ((size_t)bx * by)), u);
        int whole = m == 8 && o.faces && g->dim == 3 && block_whole(&o, u);
        if (whole)
            memset(lab, 0, sizeof lab);
        parts[b] = (uint8_t)(whole ? 1 : m ? block_parts(&o, u, m, lab) : 0);
        for (int q = 0; q < m; q++)
            L->agg[u[q]] = lab[q];
    }
    extra[0] = 0;
    for (size_t b = 0; b < nblk; b++)
        extra[b + 1] = extra[b] + (parts[b] > 1 ? parts[b] - 1u : 0u);
    hv_status st = HV_OK;
    if (nblk + extra[nblk] >= (size_t)INT32_MAX) {
        st = hv__error(HV_ERR_UNSUPPORTED, "multigrid: level 1 has too many aggregates");
        goto done;
    }
    C->n = (int32_t)(nblk + extra[nblk]);
    C->xyz = malloc(3 * ((size_t)C->n + 1) * sizeof *C->xyz);
    L->mrp = calloc((size_t)C->n + 1, sizeof *L->mrp);
    if (!C->xyz || !L->mrp) {
        st = hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates of level 0");
        goto done;
    }
    /* Numbers, coordinates and member counts (mrp[I + 1] for now). */
#pragma omp parallel for schedule(static) if (nblk > AGG_PAR_MIN)
    for (size_t b = 0; b < nblk; b++) {
        int32_t u[8],
            xyz[3] = {(int32_t)(b % bx), (int32_t)(b / bx % by), (int32_t)(b / ((size_t)bx * by))};
        int m = fine_block_cells(F, o.dinv, xyz[0], xyz[1], xyz[2], u);
        memcpy(C->xyz + 3 * b, xyz, sizeof xyz);
        for (int p = 1; p < parts[b]; p++)
            memcpy(C->xyz + 3 * (nblk + extra[b] + p - 1), xyz, sizeof xyz);
        for (int q = 0; q < m; q++) {
            int p = L->agg[u[q]];
            size_t id = p == 0 ? b : nblk + extra[b] + (size_t)p - 1;
            L->agg[u[q]] = (int32_t)id;
            L->mrp[id + 1]++;
        }
    }
    L->nagg = 0;
    for (int32_t I = 0; I < C->n; I++) {
        L->nagg += L->mrp[I + 1] > 0;
        L->mrp[I + 1] += L->mrp[I];
    }
    L->live = (int32_t)L->mrp[C->n];
    if (!(L->mem = malloc((L->live ? (size_t)L->live : 1) * sizeof *L->mem))) {
        st = hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates of level 0");
        goto done;
    }
    /* Members in ascending order: every aggregate lies in one block. */
#pragma omp parallel for schedule(static) if (nblk > AGG_PAR_MIN)
    for (size_t b = 0; b < nblk; b++) {
        int32_t u[8];
        int m = fine_block_cells(F, o.dinv, (int)(b % bx), (int)(b / bx % by),
                                 (int)(b / ((size_t)bx * by)), u);
        size_t at[8];
        for (int p = 0; p < parts[b]; p++)
            at[p] = L->mrp[p == 0 ? b : nblk + extra[b] + (size_t)p - 1];
        for (int q = 0; q < m; q++) {
            size_t id = (size_t)L->agg[u[q]];
            int p = id == b ? 0 : (int)(id - nblk - extra[b]) + 1;
            L->mem[at[p]++] = u[q];
        }
    }
    C->ext[0] = bx;
    C->ext[1] = by;
    C->ext[2] = bz;
done:
    free(parts);
    free(extra);
    return st;
}

hv_status hv__agg_aggregate(mg_agg *g, int l)
{
    if (l == 0)
        return aggregate_fine(g);
    mg_alevel *L = &g->lv[l], *C = &g->lv[l + 1];
    agg_op o = level_op(g, l);
    int bx = (L->ext[0] + 1) / 2, by = (L->ext[1] + 1) / 2, bz = (L->ext[2] + 1) / 2;
    size_t nblk = (size_t)bx * by * bz;
    size_t *start = calloc(nblk + 1, sizeof *start);
    int32_t *order = malloc((size_t)L->n * sizeof *order);
    L->agg = malloc((size_t)L->n * sizeof *L->agg);
    if (!start || !order || !L->agg) {
        free(start);
        free(order);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates of level %d", l);
    }
    /* Counting sort of the live unknowns by block. */
    for (int32_t c = 0; c < L->n; c++) {
        L->agg[c] = -1;
        if (!(o.dinv[c] > 0))
            continue;
        int x[3];
        unknown_xyz(g, l, c, x);
        start[(size_t)x[0] / 2 + bx * ((size_t)x[1] / 2 + by * ((size_t)x[2] / 2)) + 1]++;
    }
    for (size_t b = 0; b < nblk; b++)
        start[b + 1] += start[b];
    size_t live = start[nblk];
    size_t *fill = malloc(nblk * sizeof *fill);
    if (!fill) {
        free(start);
        free(order);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates of level %d", l);
    }
    memcpy(fill, start, nblk * sizeof *fill);
    for (int32_t c = 0; c < L->n; c++) {
        if (!(o.dinv[c] > 0))
            continue;
        int x[3];
        unknown_xyz(g, l, c, x);
        order[fill[(size_t)x[0] / 2 + bx * ((size_t)x[1] / 2 + by * ((size_t)x[2] / 2))]++] = c;
    }
    free(fill);
    /* Parts of each block, in chunks of at most 64 unknowns, in parallel:
     * lab[q] the part of order[q] within its block, nparts[b] the block's
     * count. */
    int *lab = malloc((live ? live : 1) * sizeof *lab);
    size_t *first = malloc((nblk + 1) * sizeof *first);
    hv_status st = HV_OK;
    if (!lab || !first) {
        free(lab);
        free(first);
        st = hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates of level %d", l);
        goto done;
    }
#pragma omp parallel for schedule(dynamic, 256) if (nblk > AGG_PAR_MIN / 8)
    for (size_t b = 0; b < nblk; b++) {
        int m = (int)(start[b + 1] - start[b]), parts = 0;
        for (int q0 = 0; q0 < m; q0 += 64) {
            int mm = m - q0 < 64 ? m - q0 : 64, *lb = lab + start[b] + q0;
            int np = block_parts(&o, order + start[b] + q0, mm, lb);
            for (int q = 0; q < mm; q++)
                lb[q] += parts;
            parts += np;
        }
        first[b + 1] = (size_t)parts;
    }
    /* Every block's parts are numbered in turn, so that a row's columns stay
     * within a few planes of blocks of it (hv__mg_agg_pack). */
    first[0] = 0;
    for (size_t b = 0; b < nblk; b++)
        first[b + 1] += first[b];
    size_t next = first[nblk];
    C->xyz = next < (size_t)INT32_MAX ? malloc(3 * (next ? next : 1) * sizeof *C->xyz) : NULL;
    if (next >= (size_t)INT32_MAX) {
        st = hv__error(HV_ERR_UNSUPPORTED, "multigrid: level %d has too many aggregates", l + 1);
    } else if (!C->xyz) {
        st = hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates of level %d", l);
    } else {
#pragma omp parallel for schedule(static) if (nblk > AGG_PAR_MIN / 8)
        for (size_t b = 0; b < nblk; b++) {
            const int32_t bxyz[3] = {(int32_t)(b % bx), (int32_t)((b / bx) % by),
                                     (int32_t)(b / ((size_t)bx * by))};
            for (size_t id = first[b]; id < first[b + 1]; id++)
                memcpy(C->xyz + 3 * id, bxyz, sizeof bxyz);
            for (size_t q = start[b]; q < start[b + 1]; q++)
                L->agg[order[q]] = (int32_t)(first[b] + (size_t)lab[q]);
        }
    }
    free(lab);
    free(first);
    if (st)
        goto done;
    C->n = (int32_t)next;
    /* Members grouped by aggregate. */
    L->mrp = calloc((size_t)C->n + 1, sizeof *L->mrp);
    L->mem = malloc((live ? live : 1) * sizeof *L->mem);
    if (!L->mrp || !L->mem) {
        st = hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates of level %d", l);
        goto done;
    }
    for (int32_t c = 0; c < L->n; c++)
        if (L->agg[c] >= 0)
            L->mrp[L->agg[c] + 1]++;
    L->nagg = 0;
    for (int32_t I = 0; I < C->n; I++) {
        L->nagg += L->mrp[I + 1] > 0;
        L->mrp[I + 1] += L->mrp[I];
    }
    L->live = (int32_t)live;
    for (size_t q = 0; q < live; q++) {
        int32_t c = order[q];
        L->mem[L->mrp[L->agg[c]]++] = c;
    }
    for (int32_t I = C->n; I > 0; I--)
        L->mrp[I] = L->mrp[I - 1];
    L->mrp[0] = 0;
    C->ext[0] = bx;
    C->ext[1] = by;
    C->ext[2] = bz;
done:
    free(start);
    free(order);
    return st;
}
