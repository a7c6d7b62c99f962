/* Smoothed aggregation (agg_internal.h): the CPU cycle's packing of built levels. */
#include "agg_internal.h"

static size_t bytes_saved(size_t before, size_t after)
{
    return before > after ? before - after : 0;
}

/* M's columns as 16-bit offsets from each row's smallest where every row
 * spans fewer than 65536 (mg_csr); returns the bytes saved. */
static size_t csr_pack(mg_csr *M)
{
    if (!M->rp || !M->ci)
        return 0;
    const size_t nnz = M->rp[M->n];
    int32_t *cb = malloc(((size_t)M->n + 1) * sizeof *cb);
    uint16_t *co = malloc((nnz + MG_CSR_PAD) * sizeof *co);
    if (!cb || !co) {
        free(cb);
        free(co);
        return 0;
    }
    int fits = 1; /* each thread's copy starts at 1 too */
#pragma omp parallel for schedule(static) reduction(&& : fits) if (M->n > AGG_PAR_MIN)
    for (int32_t r = 0; r < M->n; r++) {
        if (!fits)
            continue;
        int32_t lo = INT32_MAX, hi = INT32_MIN;
        for (size_t q = M->rp[r]; q < M->rp[r + 1]; q++) {
            lo = M->ci[q] < lo ? M->ci[q] : lo;
            hi = M->ci[q] > hi ? M->ci[q] : hi;
        }
        if (lo > hi)
            lo = hi = 0;
        if ((int64_t)hi - lo > UINT16_MAX) {
            fits = 0;
            continue;
        }
        cb[r] = lo;
        for (size_t q = M->rp[r]; q < M->rp[r + 1]; q++)
            co[q] = (uint16_t)(M->ci[q] - lo);
    }
    if (!fits) {
        free(cb);
        free(co);
        return 0;
    }
    memset(co + nnz, 0, MG_CSR_PAD * sizeof *co);
    free(M->ci);
    M->ci = NULL;
    M->cb = cb;
    M->co = co;
    return bytes_saved(nnz * sizeof(int32_t),
                       (nnz + MG_CSR_PAD) * sizeof(uint16_t) + (size_t)M->n * sizeof(int32_t));
}

#define CLS_MIN 32    /* rows that a row class needs to become a template */
#define CLS_MAX 65000 /* row classes at most (cls is 16-bit) */
#define CLS_RUN 8     /* consecutive rows of a class that it serves at least */
#define CLS_WIDTH 512 /* entries of a class at most */

/* Hash of row c's entries, columns relative to c. */
static uint64_t row_hash(const mg_csr *A, int32_t c)
{
    uint64_t h = 1469598103934665603ull ^ (uint64_t)(A->rp[c + 1] - A->rp[c]);
    for (size_t q = A->rp[c]; q < A->rp[c + 1]; q++) {
        uint32_t bits;
        memcpy(&bits, &A->v[q], sizeof bits);
        h = (h ^ (uint32_t)(A->ci[q] - c)) * 1099511628211ull;
        h = (h ^ bits) * 1099511628211ull;
    }
    return h ^ (h >> 29);
}

/* Rows a and b hold the same entries (bit for bit) at the same offsets. */
static int rows_equal(const mg_csr *A, int32_t a, int32_t b)
{
    size_t qa = A->rp[a], qb = A->rp[b], len = A->rp[a + 1] - qa;
    if (A->rp[b + 1] - qb != len)
        return 0;
    for (size_t e = 0; e < len; e++)
        if (A->ci[qa + e] - a != A->ci[qb + e] - b)
            return 0;
    return memcmp(A->v + qa, A->v + qb, len * sizeof *A->v) == 0;
}

/* The slot of row c's class in an open-addressing table of rows (rep, key;
 * mask + 1 slots), claimed for c where the class is new. */
static size_t class_slot(const mg_csr *A, int32_t c, int32_t *rep, uint64_t *key, size_t mask)
{
    const uint64_t h = row_hash(A, c);
    size_t s = (size_t)h & mask;
    while (rep[s] >= 0 && !(key[s] == h && rows_equal(A, rep[s], c)))
        s = (s + 1) & mask;
    if (rep[s] < 0) {
        rep[s] = c;
        key[s] = h;
    }
    return s;
}

/* A without the rows that a class serves (cls[r] != 0): their ranges empty. */
static int csr_drop_rows(mg_csr *A, const uint16_t *cls)
{
    size_t kept = 0;
    for (int32_t r = 0; r < A->n; r++)
        kept += cls[r] ? 0 : A->rp[r + 1] - A->rp[r];
    int32_t *ci = malloc((kept ? kept : 1) * sizeof *ci);
    float *v = malloc((kept ? kept : 1) * sizeof *v);
    if (!ci || !v) {
        free(ci);
        free(v);
        return -1;
    }
    size_t at = 0, from = A->rp[0];
    for (int32_t r = 0; r < A->n; r++) {
        const size_t b = from, e = A->rp[r + 1];
        from = e;
        A->rp[r] = at;
        if (cls[r])
            continue;
        memcpy(ci + at, A->ci + b, (e - b) * sizeof *ci);
        memcpy(v + at, A->v + b, (e - b) * sizeof *v);
        at += e - b;
    }
    A->rp[A->n] = at;
    free(A->ci);
    free(A->v);
    A->ci = ci;
    A->v = v;
    return 0;
}

/* Emits the open group of class k (fill rows, padded with its last row). */
static void group_emit(mg_alevel *L, int32_t *open, int *fill, int k)
{
    int32_t *g = L->grow + (size_t)MG_GROUP * L->ngrp;
    for (int i = 0; i < MG_GROUP; i++)
        g[i] = open[(size_t)MG_GROUP * k + (i < fill[k] ? i : fill[k] - 1)];
    L->gcls[L->ngrp++] = k;
    fill[k] = 0;
}

/* The rows of classes in runs along x shorter than CLS_RUN (a stencil over
 * a few lanes costs more than their sparse rows) into groups of MG_GROUP rows
 * of one class (mg_alevel's grow), marked MG_CLS_GROUP in cls: the rows
 * beside walls across x, each of its own class but for its neighbours along
 * y and z. -1 where memory is short. */
static int class_groups(mg_alevel *L, uint16_t *cls, int ncls)
{
    size_t nshort = 0;
    for (int32_t c = 0; c < L->n;) {
        int32_t e = c + 1;
        while (e < L->n && cls[e] == cls[c])
            e++;
        nshort += cls[c] > 1 && e - c < CLS_RUN ? (size_t)(e - c) : 0;
        c = e;
    }
    const size_t maxg = nshort / MG_GROUP + (size_t)ncls;
    int32_t *open = malloc((size_t)ncls * MG_GROUP * sizeof *open);
    int *fill = calloc((size_t)ncls, sizeof *fill);
    L->grow = malloc((maxg ? maxg : 1) * MG_GROUP * sizeof *L->grow);
    L->gcls = malloc((maxg ? maxg : 1) * sizeof *L->gcls);
    L->ngrp = 0;
    if (!open || !fill || !L->grow || !L->gcls) {
        free(open);
        free(fill);
        return -1;
    }
    for (int32_t c = 0; c < L->n;) {
        int32_t e = c + 1;
        while (e < L->n && cls[e] == cls[c])
            e++;
        for (int32_t r = c; cls[c] > 1 && e - c < CLS_RUN && r < e; r++) {
            const int k = cls[r] - 2;
            open[(size_t)MG_GROUP * k + fill[k]++] = r;
            if (fill[k] == MG_GROUP)
                group_emit(L, open, fill, k);
        }
        if (cls[c] > 1 && e - c < CLS_RUN)
            for (int32_t r = c; r < e; r++)
                cls[r] = MG_CLS_GROUP;
        c = e;
    }
    for (int k = 0; k < ncls; k++)
        if (fill[k])
            group_emit(L, open, fill, k);
    free(open);
    free(fill);
    return 0;
}

/* Row classes of a level with a template (mg_alevel's cls): the stored rows
 * grouped by their entries relative to the row, each group of CLS_MIN rows
 * or more a template of its own. Returns the bytes saved (0 where it finds
 * none or memory is short). */
static size_t row_classes(mg_alevel *L)
{
    const mg_csr *A = &L->A;
    if (!A->ci)
        return 0;
    const uint8_t *plain = L->plain;
    size_t nstored = 0, slots = 64;
    for (int32_t c = 0; c < L->n; c++)
        nstored += !(plain && plain[c]) && A->rp[c + 1] > A->rp[c];
    while (slots < 2 * nstored)
        slots *= 2;
    int32_t *rep = malloc(slots * sizeof *rep), *slot_of = malloc((size_t)L->n * sizeof *slot_of);
    int32_t *cnt = calloc(slots, sizeof *cnt);
    uint64_t *key = malloc(slots * sizeof *key);
    uint16_t *cls = calloc((size_t)L->n, sizeof *cls);
    size_t saved = 0;
    if (!rep || !slot_of || !cnt || !key || !cls)
        goto done;
    for (size_t s = 0; s < slots; s++)
        rep[s] = -1;
    for (int32_t c = 0; c < L->n; c++) {
        size_t len = A->rp[c + 1] - A->rp[c];
        slot_of[c] = -1;
        if ((plain && plain[c]) || len == 0 || len > CLS_WIDTH)
            continue;
        slot_of[c] = (int32_t)class_slot(A, c, rep, key, slots - 1);
        cnt[slot_of[c]]++;
    }
    /* cnt becomes each slot's class (-1: none), in the order of the table */
    int ncls = 0;
    for (size_t s = 0; s < slots; s++)
        cnt[s] = cnt[s] >= CLS_MIN && ncls < CLS_MAX ? ncls++ : -1;
    if (!ncls)
        goto done;
    L->cn = malloc((size_t)ncls * sizeof *L->cn);
    L->cw = 1;
    for (size_t s = 0; s < slots; s++)
        if (cnt[s] >= 0 && A->rp[rep[s] + 1] - A->rp[rep[s]] > (size_t)L->cw)
            L->cw = (int)(A->rp[rep[s] + 1] - A->rp[rep[s]]);
    L->coff = malloc((size_t)ncls * L->cw * sizeof *L->coff);
    L->cval = malloc((size_t)ncls * L->cw * sizeof *L->cval);
    if (!L->cn || !L->coff || !L->cval)
        goto fail;
    for (size_t s = 0; s < slots; s++) {
        if (cnt[s] < 0)
            continue;
        const int k = cnt[s];
        const int32_t r = rep[s];
        L->cn[k] = (int)(A->rp[r + 1] - A->rp[r]);
        for (int e = 0; e < L->cn[k]; e++) {
            L->coff[(size_t)k * L->cw + e] = A->ci[A->rp[r] + e] - r;
            L->cval[(size_t)k * L->cw + e] = A->v[A->rp[r] + e];
        }
    }
    size_t before = A->rp[L->n];
    for (int32_t c = 0; c < L->n; c++)
        cls[c] = plain && plain[c]                         ? 1
                 : slot_of[c] >= 0 && cnt[slot_of[c]] >= 0 ? 2 + cnt[slot_of[c]]
                                                           : 0;
    if (class_groups(L, cls, ncls) || csr_drop_rows(&L->A, cls))
        goto fail;
    L->cls = cls;
    L->ncls = ncls;
    cls = NULL;
    saved = bytes_saved((before - L->A.rp[L->n]) * (sizeof(int32_t) + sizeof(float)),
                        (size_t)L->n * sizeof *L->cls +
                            (size_t)ncls *
                                ((size_t)L->cw * (sizeof(int32_t) + sizeof(float)) + sizeof(int)) +
                            (size_t)L->ngrp * (MG_GROUP + 1) * sizeof(int32_t));
    goto done;
fail:
    free(L->cn);
    free(L->coff);
    free(L->cval);
    free(L->grow);
    free(L->gcls);
    L->cn = NULL;
    L->coff = NULL;
    L->cval = NULL;
    L->grow = NULL;
    L->gcls = NULL;
    L->ngrp = 0;
done:
    free(rep);
    free(slot_of);
    free(cnt);
    free(key);
    free(cls);
    return saved;
}

void hv__mg_agg_pack(mg_agg *g)
{
    for (int l = 1; l < g->nlev; l++) {
        mg_alevel *L = &g->lv[l];
        size_t saved = row_classes(L);
        saved += csr_pack(&L->A) + csr_pack(&L->P) + csr_pack(&L->R);
        g->bytes -= saved < g->bytes ? saved : 0;
    }
}
