/*
 * Smoothed aggregation (agg_internal.h): rows that repeat, found before they
 * are computed. A row of level 1 depends only on the fine cells of the 5^3
 * blocks around its block, a row of a deeper level l + 1 only on the rows of
 * level l in the 7^3 blocks of level l + 1 around its own. Each block gets a code of what
 * it holds, each neighbourhood a fingerprint of its codes (two independent
 * 64-bit hashes, taken along x, then y, then z), and rows whose
 * neighbourhoods have the same fingerprint form a class: the Galerkin
 * products do the same arithmetic in the same order for each of them, so one
 * row of a class is computed and the others copy it (docs/METHOD.md, "Coarse
 * levels that keep the walls").
 */
#include "agg_internal.h"

int hv__agg_classes_on(void)
{
    const char *e = getenv("HV_AGG_NOCLASS");
    return !(e && *e && *e != '0');
}

static const uint64_t seed[2] = {0x9E3779B97F4A7C15ull, 0xD1B54A32D192ED03ull},
                      mult[2] = {0xBF58476D1CE4E5B9ull, 0x94D049BB133111EBull};

static inline uint64_t mix(uint64_t h, uint64_t k, uint64_t v)
{
    h = (h ^ v) * k;
    return h ^ (h >> 29);
}

void hv__agg_fine_codes(const mg_agg *g, uint64_t *code)
{
    const mg_level *F = g->fine;
    const mg_alevel *L = &g->lv[0];
    const int *e = g->lv[1].ext;
    const size_t nb = (size_t)e[0] * e[1] * e[2];
#pragma omp parallel for schedule(static) if (nb > AGG_PAR_MIN)
    for (size_t b = 0; b < nb; b++) {
        int bx = (int)(b % e[0]), by = (int)((b / e[0]) % e[1]),
            bz = (int)(b / ((size_t)e[0] * e[1]));
        uint64_t v = 0;
        for (int q = 0; q < 8 && v != AGG_SPLIT; q++) {
            int i = 2 * bx + (q & 1), j = 2 * by + ((q >> 1) & 1), k = 2 * bz + (q >> 2);
            uint64_t byte = 0x80;
            if (i < F->n[0] && j < F->n[1] && k < F->n[2]) {
                size_t c = (size_t)i + F->sy * j + F->sz * k;
                byte = g->faces[c] | (F->a[c] != 0.0f ? 0x40u : 0u);
                if (L->agg[c] >= 0 && (size_t)L->agg[c] != b)
                    v = AGG_SPLIT;
            }
            if (v != AGG_SPLIT)
                v |= byte << (8 * q);
        }
        code[b] = v;
    }
}

/* The two codes of unknown c of a coarse level (its block's only one): its row as
 * offsets to its block and values, and its diagonal's inverse. */
static void unknown_code(const mg_alevel *L, int32_t c, uint64_t h[2], int *reach)
{
    int32_t bc[ROW_MAX];
    float bv[ROW_MAX];
    const int32_t *col;
    const float *val;
    int k = hv__agg_level_row(L, c, bc, bv, &col, &val);
    const int32_t *p = L->xyz + 3 * (size_t)c;
    uint32_t d;
    memcpy(&d, &L->dinv[c], sizeof d);
    for (int chain = 0; chain < 2; chain++)
        h[chain] = mix(seed[chain], mult[chain], ((uint64_t)(uint32_t)k << 32) | d);
    for (int q = 0; q < k; q++) {
        const int32_t *r = L->xyz + 3 * (size_t)col[q];
        for (int a = 0; a < 3; a++)
            *reach = abs(r[a] - p[a]) > *reach ? abs(r[a] - p[a]) : *reach;
        uint64_t off = (uint64_t)(uint8_t)(r[0] - p[0]) | (uint64_t)(uint8_t)(r[1] - p[1]) << 8 |
                       (uint64_t)(uint8_t)(r[2] - p[2]) << 16;
        uint32_t v;
        memcpy(&v, &val[q], sizeof v);
        for (int chain = 0; chain < 2; chain++)
            h[chain] = mix(h[chain], mult[chain], off << 32 | v);
    }
}

/* Per block of level l: its one unknown (-1 none, -2 more than one). */
static int32_t *block_unknowns(const mg_alevel *L)
{
    const int *e = L->ext;
    const size_t nb = (size_t)e[0] * e[1] * e[2];
    int32_t *u = malloc((nb ? nb : 1) * sizeof *u);
    if (!u)
        return NULL;
    for (size_t b = 0; b < nb; b++)
        u[b] = -1;
    for (int32_t c = 0; c < L->n; c++) {
        const int32_t *p = L->xyz + 3 * (size_t)c;
        size_t b = (size_t)p[0] + e[0] * ((size_t)p[1] + e[1] * (size_t)p[2]);
        u[b] = u[b] == -1 ? c : -2;
    }
    return u;
}

int hv__agg_level_codes(const mg_agg *g, int l, int32_t *bid, uint64_t *ca, uint64_t *cb,
                        int *reach)
{
    int far = 0;
    const mg_alevel *L = &g->lv[l], *C = &g->lv[l + 1];
    const int *e1 = L->ext, *e2 = C->ext;
    const size_t nb2 = (size_t)e2[0] * e2[1] * e2[2];
    int32_t *u1 = block_unknowns(L), *u2 = block_unknowns(C);
    if (!u1 || !u2) {
        free(u1);
        free(u2);
        return -1;
    }
#pragma omp parallel for schedule(static) reduction(max : far) if (nb2 > AGG_PAR_MIN / 8)
    for (size_t B = 0; B < nb2; B++) {
        int x = (int)(B % e2[0]), y = (int)((B / e2[0]) % e2[1]),
            z = (int)(B / ((size_t)e2[0] * e2[1]));
        uint64_t h[2] = {seed[0], seed[1]};
        int split = u2[B] == -2;
        for (int q = 0; q < 8 && !split; q++) {
            int i = 2 * x + (q & 1), j = 2 * y + ((q >> 1) & 1), k = 2 * z + (q >> 2);
            uint64_t v[2] = {AGG_OUTSIDE, AGG_OUTSIDE};
            if (i < e1[0] && j < e1[1] && k < e1[2]) {
                int32_t c = u1[(size_t)i + e1[0] * ((size_t)j + e1[1] * (size_t)k)];
                split |= c == -2;
                if (c < 0 || L->agg[c] < 0)
                    v[0] = v[1] = 1; /* no unknown, or one without a row */
                else
                    unknown_code(L, c, v, &far);
            }
            for (int chain = 0; chain < 2; chain++)
                h[chain] = mix(h[chain], mult[chain], v[chain]);
        }
        /* A code of its own for split blocks: no hash stands for it. */
        ca[B] = split ? AGG_SPLIT : h[0] == AGG_SPLIT ? h[0] - 1 : h[0];
        cb[B] = split ? AGG_SPLIT : h[1];
        bid[B] = split ? -1 : u2[B];
    }
    free(u1);
    free(u2);
    *reach = far;
    return 0;
}

/* One pass along axis a: dst[b] = the hash of src over b - r .. b + r, out
 * for the blocks outside. */
static void window_pass(const int e[3], int a, int r, const uint64_t *src, uint64_t out, int chain,
                        uint64_t *dst)
{
    const size_t nb = (size_t)e[0] * e[1] * e[2];
    const size_t stride = a == 0 ? 1 : a == 1 ? (size_t)e[0] : (size_t)e[0] * e[1];
#pragma omp parallel for schedule(static) if (nb > AGG_PAR_MIN)
    for (size_t b = 0; b < nb; b++) {
        int x = (int)(b / stride % (size_t)e[a]);
        uint64_t h = seed[chain];
        for (int d = -r; d <= r; d++)
            h = mix(h, mult[chain],
                    x + d >= 0 && x + d < e[a] ? src[b + (ptrdiff_t)d * (ptrdiff_t)stride] : out);
        dst[b] = h;
    }
}

/* flag[b] = some flag over b - r .. b + r along each axis in turn (in f1
 * after the three passes; f0 holds the flags on entry). */
static void window_or(const int e[3], int r, uint8_t *f0, uint8_t *f1)
{
    const size_t nb = (size_t)e[0] * e[1] * e[2];
    for (int a = 0; a < 3; a++) {
        const uint8_t *src = a % 2 ? f1 : f0;
        uint8_t *dst = a % 2 ? f0 : f1;
        const size_t stride = a == 0 ? 1 : a == 1 ? (size_t)e[0] : (size_t)e[0] * e[1];
#pragma omp parallel for schedule(static) if (nb > AGG_PAR_MIN)
        for (size_t b = 0; b < nb; b++) {
            int x = (int)(b / stride % (size_t)e[a]), any = 0;
            for (int d = -r; d <= r; d++)
                any |= x + d >= 0 && x + d < e[a] && src[b + (ptrdiff_t)d * (ptrdiff_t)stride];
            dst[b] = (uint8_t)any;
        }
    }
}

int hv__agg_fingerprints(const int e[3], int r, const uint64_t *ca, const uint64_t *cb,
                         uint64_t *fp)
{
    const size_t nb = (size_t)e[0] * e[1] * e[2];
    uint64_t *w0 = malloc(nb * sizeof *w0), *w1 = malloc(nb * sizeof *w1);
    if (!w0 || !w1) {
        free(w0);
        free(w1);
        return -1;
    }
    uint64_t *wk[2] = {w0, w1};
    for (int chain = 0; chain < 2; chain++) {
        uint64_t out = AGG_OUTSIDE;
        const uint64_t *src = chain ? cb : ca;
        for (int a = 0; a < 3; a++) {
            uint64_t *dst = wk[a % 2];
            window_pass(e, a, r, src, out, chain, dst);
            /* A block outside reads as the hash of blocks outside. */
            uint64_t h = seed[chain];
            for (int d = -r; d <= r; d++)
                h = mix(h, mult[chain], out);
            out = h;
            src = dst;
        }
        /* After three passes the hashes are in w0. */
#pragma omp parallel for schedule(static) if (nb > AGG_PAR_MIN)
        for (size_t b = 0; b < nb; b++)
            fp[2 * b + chain] = w0[b];
    }
    uint8_t *f0 = (uint8_t *)w0, *f1 = (uint8_t *)w1;
#pragma omp parallel for schedule(static) if (nb > AGG_PAR_MIN)
    for (size_t b = 0; b < nb; b++)
        f0[b] = ca[b] == AGG_SPLIT;
    window_or(e, r, f0, f1);
    for (size_t b = 0; b < nb; b++)
        if (f1[b] || (!fp[2 * b] && !fp[2 * b + 1]))
            fp[2 * b] = fp[2 * b + 1] = 0;
    free(w0);
    free(w1);
    return 0;
}

int32_t hv__agg_classes(size_t nb, const uint64_t *fp, const uint8_t *skip, int32_t *cls,
                        int32_t max)
{
    size_t tsize = 1;
    while (tsize < 2 * nb)
        tsize *= 2;
    int32_t *slot = malloc(tsize * sizeof *slot), *count = calloc(nb ? nb : 1, sizeof *count);
    int32_t ncls = -1;
    if (!slot || !count)
        goto done;
    for (size_t q = 0; q < tsize; q++)
        slot[q] = -1;
    /* Classes named by their first block; cls[b] the first block for now. */
    for (size_t b = 0; b < nb; b++) {
        const uint64_t *h = fp + 2 * b;
        cls[b] = -1;
        if ((skip && skip[b]) || (!h[0] && !h[1]))
            continue;
        size_t s = h[0] & (tsize - 1);
        while (slot[s] >= 0 &&
               (fp[2 * (size_t)slot[s]] != h[0] || fp[2 * (size_t)slot[s] + 1] != h[1]))
            s = (s + 1) & (tsize - 1);
        if (slot[s] < 0)
            slot[s] = (int32_t)b;
        else
            cls[b] = slot[s];
    }
    /* Classes of two blocks or more, numbered; the first block joins its class. */
    for (size_t b = 0; b < nb; b++)
        if (cls[b] >= 0)
            count[cls[b]]++;
    ncls = 0;
    for (size_t b = 0; b < nb; b++)
        count[b] = count[b] > 0 && ncls < max ? ncls++ : -1;
    for (size_t b = 0; b < nb; b++)
        cls[b] = count[b] >= 0 ? count[b] : cls[b] >= 0 ? count[cls[b]] : -1;
done:
    free(slot);
    free(count);
    return ncls;
}
