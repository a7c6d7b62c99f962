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

hv_status hv__agg_aggregate(mg_agg *g, int l)
{
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
    /* Parts of each block. Under the fine level, the first takes the block's
     * own index (a block without live unknowns leaves an empty one) and the
     * others come after all blocks: in open space level 1 is then a grid whose
     * neighbours are at fixed offsets (its template rows). Deeper, every
     * block's parts are numbered in turn, so that a row's columns stay within
     * a few planes of blocks of it (hv__mg_agg_pack). */
    const int grid = l == 0;
    size_t cap = nblk + 16, next = grid ? nblk : 0;
    C->xyz = malloc(3 * cap * sizeof *C->xyz);
    hv_status st = HV_OK;
    if (!C->xyz) {
        st = hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates of level %d", l);
        goto done;
    }
    for (size_t b = 0; b < nblk; b++) {
        const int32_t *u = order + start[b];
        int m = (int)(start[b + 1] - start[b]), lab[64];
        const int32_t bxyz[3] = {(int32_t)(b % bx), (int32_t)((b / bx) % by),
                                 (int32_t)(b / ((size_t)bx * by))};
        if (grid)
            memcpy(C->xyz + 3 * b, bxyz, sizeof bxyz);
        for (int q0 = 0; q0 < m; q0 += 64) {
            int mm = m - q0 < 64 ? m - q0 : 64;
            int whole = mm == 8 && o.faces && g->dim == 3 && block_whole(&o, u + q0);
            if (whole)
                memset(lab, 0, 8 * sizeof lab[0]);
            int parts = whole ? 1 : block_parts(&o, u + q0, mm, lab);
            for (int p = 0; p < parts; p++) {
                size_t id = b;
                if (!grid || p > 0 || q0 > 0) {
                    id = next++;
                    if (id >= cap) {
                        cap *= 2;
                        int32_t *x2 = realloc(C->xyz, 3 * cap * sizeof *x2);
                        if (!x2) {
                            st = hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates");
                            goto done;
                        }
                        C->xyz = x2;
                    }
                    memcpy(C->xyz + 3 * id, bxyz, sizeof bxyz);
                }
                for (int q = 0; q < mm; q++)
                    if (lab[q] == p)
                        L->agg[u[q0 + q]] = (int32_t)id;
            }
        }
    }
    if (next >= (size_t)INT32_MAX) {
        st = hv__error(HV_ERR_UNSUPPORTED, "multigrid: level %d has too many aggregates", l + 1);
        goto done;
    }
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
