/* Smoothed aggregation (agg_internal.h): the Galerkin coarse operators. */
#include "agg_internal.h"

/* A sparse accumulator over a level's unknowns, with the list of those touched. */
typedef struct spa {
    double *acc;
    int32_t *mark, gen;
    int32_t *idx;
    size_t nidx, cap;
} spa;

static int spa_init(spa *s, int32_t n)
{
    memset(s, 0, sizeof *s);
    s->acc = malloc(((size_t)n + 1) * sizeof *s->acc);
    s->mark = malloc(((size_t)n + 1) * sizeof *s->mark);
    s->idx = malloc(((size_t)n + 1) * sizeof *s->idx);
    s->cap = (size_t)n + 1;
    if (!s->acc || !s->mark || !s->idx)
        return -1;
    for (int32_t c = 0; c < n; c++)
        s->mark[c] = -1;
    return 0;
}

static void spa_free(spa *s)
{
    free(s->acc);
    free(s->mark);
    free(s->idx);
}

static void spa_start(spa *s)
{
    s->gen++;
    s->nidx = 0;
}

/* acc[c] += v (every column has room: idx holds n entries). Returns 0. */
static inline int spa_add(spa *s, int32_t c, double v)
{
    if (s->mark[c] != s->gen) {
        s->mark[c] = s->gen;
        s->acc[c] = v;
        s->idx[s->nidx++] = c;
    } else {
        s->acc[c] += v;
    }
    return 0;
}

/* Growing arrays of one thread's rows. */
typedef struct rows_out {
    int32_t *ci;
    float *v;
    size_t n, cap;
    int32_t *len;
} rows_out;

static int rows_push(rows_out *r, int32_t c, float v)
{
    if (r->n == r->cap) {
        size_t cap = r->cap ? 2 * r->cap : 4096;
        int32_t *ci = realloc(r->ci, cap * sizeof *ci);
        if (ci)
            r->ci = ci;
        float *vv = ci ? realloc(r->v, cap * sizeof *vv) : NULL;
        if (vv)
            r->v = vv;
        if (!ci || !vv)
            return -1;
        r->cap = cap;
    }
    r->ci[r->n] = c;
    r->v[r->n++] = v;
    return 0;
}

/* ---------- Galerkin on the coarse levels: sparse products ---------- */

/* One row of a product into a sparse accumulator (after spa_start), with
 * scratch of its own for each thread: zeroed memory, or a second sparse
 * accumulator (build_csr's `inner`). */
typedef int (*row_fn)(const void *ctx, void *scratch, int32_t row, spa *s);

/* out = the nrows rows that fn makes, over ncols columns; with `drop`,
 * entries off the diagonal below drop times the diagonal are left out. */
static hv_status build_csr(mg_csr *out, int32_t nrows, int32_t ncols, row_fn fn, const void *ctx,
                           size_t scratch_bytes, int32_t inner, double drop)
{
    memset(out, 0, sizeof *out);
    int nthr = 1;
#ifdef _OPENMP
    nthr = nrows > 256 ? omp_get_max_threads() : 1;
#endif
    rows_out *outs = calloc((size_t)nthr, sizeof *outs);
    int32_t *len = malloc(((size_t)nrows + 1) * sizeof *len);
    int failed = !outs || !len;
#pragma omp parallel num_threads(nthr) if (nthr > 1)
    {
        int t = 0;
#ifdef _OPENMP
        t = omp_get_thread_num();
#endif
        spa cs = {0}, in = {0};
        void *scratch = scratch_bytes ? calloc(1, scratch_bytes) : inner > 0 ? (void *)&in : NULL;
        int bad = failed || spa_init(&cs, ncols) || (scratch_bytes && !scratch) ||
                  (inner > 0 && spa_init(&in, inner));
        int32_t r0 = (int32_t)((int64_t)nrows * t / nthr),
                r1 = (int32_t)((int64_t)nrows * (t + 1) / nthr);
        for (int32_t r = r0; r < r1 && !bad; r++) {
            spa_start(&cs);
            if (fn(ctx, scratch, r, &cs)) {
                bad = 1;
                break;
            }
            double diag = r < ncols && cs.mark[r] == cs.gen ? fabs(cs.acc[r]) : 0.0;
            int32_t n = 0;
            for (size_t q = 0; q < cs.nidx && !bad; q++) {
                int32_t c = cs.idx[q];
                double v = cs.acc[c];
                if (c != r && (v == 0 || (drop > 0 && !(fabs(v) > drop * diag))))
                    continue;
                bad = rows_push(&outs[t], c, (float)v) != 0;
                n++;
            }
            len[r] = n;
        }
        spa_free(&cs);
        spa_free(&in);
        if (scratch_bytes)
            free(scratch);
        if (bad) {
#pragma omp atomic write
            failed = 1;
        }
    }
    size_t nnz = 0;
    for (int t = 0; !failed && t < nthr; t++)
        nnz += outs[t].n;
    if (!failed) {
        out->n = nrows;
        out->rp = malloc(((size_t)nrows + 1) * sizeof *out->rp);
        out->ci = malloc((nnz ? nnz : 1) * sizeof *out->ci);
        out->v = malloc((nnz ? nnz : 1) * sizeof *out->v);
        failed = !out->rp || !out->ci || !out->v;
    }
    if (!failed) {
        out->rp[0] = 0;
        for (int32_t r = 0; r < nrows; r++)
            out->rp[r + 1] = out->rp[r] + (size_t)len[r];
        size_t at = 0;
        for (int t = 0; t < nthr; t++) {
            memcpy(out->ci + at, outs[t].ci, outs[t].n * sizeof *out->ci);
            memcpy(out->v + at, outs[t].v, outs[t].n * sizeof *out->v);
            at += outs[t].n;
        }
    }
    for (int t = 0; outs && t < nthr; t++) {
        free(outs[t].ci);
        free(outs[t].v);
    }
    free(outs);
    free(len);
    if (failed)
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for a coarse level's products");
    return HV_OK;
}

void hv__agg_csr_free(mg_csr *m)
{
    free(m->rp);
    free(m->ci);
    free(m->v);
    free(m->cb);
    free(m->co);
    memset(m, 0, sizeof *m);
}

/* P = (I - wp D^-1 A) P0 of a coarse level, row by row. */
typedef struct p_ctx {
    const mg_alevel *L;
    const int32_t *agg;
    const float *dinv;
    double wp;
} p_ctx;

static int p_row(const void *ctx, void *scratch, int32_t c, spa *s)
{
    (void)scratch;
    const p_ctx *x = ctx;
    if (x->agg[c] < 0)
        return 0;
    if (spa_add(s, x->agg[c], 1.0))
        return -1;
    double f = -x->wp * x->dinv[c];
    int32_t bc[ROW_MAX];
    float bv[ROW_MAX];
    const int32_t *col;
    const float *val;
    int k = hv__agg_level_row(x->L, c, bc, bv, &col, &val);
    for (int q = 0; q < k; q++)
        if (x->agg[col[q]] >= 0 && spa_add(s, x->agg[col[q]], f * val[q]))
            return -1;
    return 0;
}

/* The first row of each of ncls classes (cls over n rows, -1 none); NULL
 * out of memory. */
static int32_t *class_firsts(const int32_t *cls, int32_t n, int32_t ncls)
{
    int32_t *first = malloc(((size_t)ncls + 1) * sizeof *first);
    for (int32_t k = 0; first && k < ncls; k++)
        first[k] = -1;
    for (int32_t r = 0; first && r < n; r++)
        if (cls[r] >= 0 && first[cls[r]] < 0)
            first[cls[r]] = r;
    return first;
}

/* A row of a class of level 2: n entries at block offsets off (3 each). */
typedef struct agg_crow {
    int n;
    int8_t *off;
    double *val;
} agg_crow;

/* Row I of R A P: the row (R A)(I,:) in the inner accumulator, then times P.
 * No product is stored between the two. With classes (level 2), rows of a
 * class are copied from its row. */
typedef struct rap_ctx {
    const mg_csr *R, *P;
    const mg_alevel *L, *C;
    const int32_t *cls;   /* per unknown of level 2: its class, -1 none (or NULL) */
    const int32_t *bid;   /* per block of level 2: its one unknown */
    const agg_crow *rows; /* the classes' rows (NULL while they are made) */
} rap_ctx;

static int rap_row(const void *ctx, void *scratch, int32_t I, spa *s)
{
    const rap_ctx *m = ctx;
    spa *ra = scratch;
    int32_t bc[ROW_MAX];
    float bv[ROW_MAX];
    const int32_t *col;
    const float *val;
    spa_start(ra);
    for (size_t q = m->R->rp[I]; q < m->R->rp[I + 1]; q++) {
        int32_t c = m->R->ci[q];
        double r = m->R->v[q];
        int k = hv__agg_level_row(m->L, c, bc, bv, &col, &val);
        for (int p = 0; p < k; p++)
            spa_add(ra, col[p], r * val[p]);
    }
    for (size_t q = 0; q < ra->nidx; q++) {
        int32_t e = ra->idx[q];
        double x = ra->acc[e];
        for (size_t p = m->P->rp[e]; p < m->P->rp[e + 1]; p++)
            spa_add(s, m->P->ci[p], x * m->P->v[p]);
    }
    return 0;
}

static int rap_row_classed(const void *ctx, void *scratch, int32_t I, spa *s)
{
    const rap_ctx *m = ctx;
    if (!m->rows || m->cls[I] < 0)
        return rap_row(ctx, scratch, I, s);
    const agg_crow *K = &m->rows[m->cls[I]];
    const int32_t *p = m->C->xyz + 3 * (size_t)I;
    const int *e = m->C->ext;
    for (int q = 0; q < K->n; q++) {
        const int8_t *d = K->off + 3 * q;
        size_t B =
            (size_t)(p[0] + d[0]) + e[0] * ((size_t)(p[1] + d[1]) + e[1] * (size_t)(p[2] + d[2]));
        spa_add(s, m->bid[B], K->val[q]);
    }
    return 0;
}

/* Each class's row from its first unknown by rap_row, as block offsets.
 * Returns 0, or -1 out of memory. */
static int rap_class_rows(const rap_ctx *m, int32_t ncls, agg_crow *rows)
{
    const mg_alevel *C = m->C;
    int32_t *first = class_firsts(m->cls, C->n, ncls);
    int failed = !first;
#pragma omp parallel if (ncls > 16 && !failed)
    {
        spa cs = {0}, in = {0};
        int bad = failed || spa_init(&cs, C->n) || spa_init(&in, m->L->n);
#pragma omp for schedule(dynamic, 4)
        for (int32_t k = 0; k < ncls; k++) {
            if (bad)
                continue;
            int32_t I = first[k];
            if (I < 0)
                continue; /* a class of blocks without an unknown: no row uses it */
            const int32_t *p = C->xyz + 3 * (size_t)I;
            spa_start(&cs);
            rap_row(m, &in, I, &cs);
            rows[k].n = (int)cs.nidx;
            rows[k].off = malloc(3 * (cs.nidx ? cs.nidx : 1));
            rows[k].val = malloc((cs.nidx ? cs.nidx : 1) * sizeof *rows[k].val);
            if (!rows[k].off || !rows[k].val) {
                bad = 1;
                continue;
            }
            for (size_t q = 0; q < cs.nidx; q++) {
                const int32_t *r = C->xyz + 3 * (size_t)cs.idx[q];
                for (int a = 0; a < 3; a++)
                    rows[k].off[3 * q + a] = (int8_t)(r[a] - p[a]);
                rows[k].val[q] = cs.acc[cs.idx[q]];
            }
        }
        spa_free(&cs);
        spa_free(&in);
        if (bad) {
#pragma omp atomic write
            failed = 1;
        }
    }
    free(first);
    return failed ? -1 : 0;
}

/* Classes of level l + 1's rows (3D, l >= 1): m->cls, m->bid and m->rows
 * set where they apply; *ncls_out for the caller to free them. Returns the
 * rows that copy their class's row. */
static size_t rap_classes(const mg_agg *g, int l, rap_ctx *m, int32_t **cls_out, int32_t **bid_out,
                          agg_crow **rows_out, int32_t *ncls_out)
{
    const mg_alevel *C = &g->lv[l + 1];
    const size_t nb = (size_t)C->ext[0] * C->ext[1] * C->ext[2];
    int32_t *bid = malloc((nb ? nb : 1) * sizeof *bid),
            *bcls = malloc((nb ? nb : 1) * sizeof *bcls);
    int32_t *cls = malloc(((size_t)C->n + 1) * sizeof *cls), ncls = -1;
    uint64_t *ca = malloc((nb ? nb : 1) * sizeof *ca), *cb = malloc((nb ? nb : 1) * sizeof *cb);
    uint64_t *fp = malloc(2 * (nb ? nb : 1) * sizeof *fp);
    agg_crow *rows = NULL;
    /* A row of level l + 1 reads P's columns (a row's reach out of its
     * block), A's rows (a reach more) and those rows' P (their rows, a third):
     * that many blocks of level l, half as many of level l + 1. */
    int reach = 0;
    if (bid && bcls && cls && ca && cb && fp &&
        hv__agg_level_codes(g, l, bid, ca, cb, &reach) == 0 &&
        (3 * reach + 1) / 2 <= AGG_CLASS_RADIUS &&
        hv__agg_fingerprints(C->ext, (3 * reach + 1) / 2, ca, cb, fp) == 0)
        ncls = hv__agg_classes(nb, fp, NULL, bcls, AGG_CLASS_MAX);
    if (ncls > 0 && (rows = calloc((size_t)ncls, sizeof *rows))) {
        for (int32_t I = 0; I < C->n; I++)
            cls[I] = -1;
        for (size_t B = 0; B < nb; B++)
            if (bcls[B] >= 0 && bid[B] >= 0)
                cls[bid[B]] = bcls[B];
        m->cls = cls;
        m->bid = bid;
        if (rap_class_rows(m, ncls, rows) == 0)
            m->rows = rows;
    }
    size_t copies = 0;
    for (int32_t I = 0; m->rows && I < C->n; I++)
        copies += cls[I] >= 0;
    free(bcls);
    free(ca);
    free(cb);
    free(fp);
    *cls_out = cls;
    *bid_out = bid;
    *rows_out = rows;
    *ncls_out = rows ? ncls : 0;
    return m->rows ? copies - (size_t)ncls : 0;
}

static void rap_classes_free(int32_t *cls, int32_t *bid, agg_crow *rows, int32_t ncls)
{
    for (int32_t k = 0; k < ncls; k++) {
        free(rows[k].off);
        free(rows[k].val);
    }
    free(rows);
    free(cls);
    free(bid);
}

/* T = M^T for M with ncols columns. */
static hv_status csr_transpose(const mg_csr *M, int32_t ncols, mg_csr *T)
{
    size_t nnz = M->rp[M->n];
    T->n = ncols;
    T->rp = calloc((size_t)ncols + 1, sizeof *T->rp);
    T->ci = malloc((nnz ? nnz : 1) * sizeof *T->ci);
    T->v = malloc((nnz ? nnz : 1) * sizeof *T->v);
    size_t *fill = malloc(((size_t)ncols + 1) * sizeof *fill);
    if (!T->rp || !T->ci || !T->v || !fill) {
        free(fill);
        hv__agg_csr_free(T);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for a coarse level's products");
    }
    for (size_t q = 0; q < nnz; q++)
        T->rp[M->ci[q] + 1]++;
    for (int32_t c = 0; c < ncols; c++)
        T->rp[c + 1] += T->rp[c];
    memcpy(fill, T->rp, ((size_t)ncols + 1) * sizeof *fill);
    for (int32_t r = 0; r < M->n; r++)
        for (size_t q = M->rp[r]; q < M->rp[r + 1]; q++) {
            size_t at = fill[M->ci[q]]++;
            T->ci[at] = r;
            T->v[at] = M->v[q];
        }
    free(fill);
    return HV_OK;
}

/* Each row of P without its entries below AGG_TRUNCATE times its largest,
 * the rest scaled to the row's old sum: P still maps the constant to the
 * constant (the Neumann null space the coarse levels must keep), P^T A P is
 * still a Galerkin product (symmetric, semi-definite), and the products below
 * it stay sparse (smoothing widens every level's stencil). */
static void p_truncate(mg_csr *P)
{
    size_t at = 0, start = 0;
    for (int32_t r = 0; r < P->n; r++) {
        size_t end = P->rp[r + 1], first = at;
        double big = 0, sum = 0, kept = 0;
        for (size_t q = start; q < end; q++) {
            big = fmax(big, fabs(P->v[q]));
            sum += P->v[q];
        }
        for (size_t q = start; q < end; q++)
            if (fabs(P->v[q]) >= AGG_TRUNCATE * big) {
                P->ci[at] = P->ci[q];
                P->v[at++] = P->v[q];
                kept += P->v[q];
            }
        for (size_t q = first; q < at && kept != 0; q++)
            P->v[q] = (float)(P->v[q] * (sum / kept));
        start = end;
        P->rp[r + 1] = at;
    }
}

/* Level l+1's operator P^T A P from a coarse level l by sparse products (row
 * by row of P^T, (P^T A) then P: nothing of the size of A P is held). */
hv_status hv__agg_galerkin_csr(mg_agg *g, int l, double wp)
{
    mg_alevel *L = &g->lv[l], *C = &g->lv[l + 1];
    mg_csr P = {0}, R = {0};
    p_ctx pc = {L, L->agg, L->dinv, wp};
    hv_status st = build_csr(&P, L->n, C->n, p_row, &pc, 0, 0, 0);
    rap_ctx rap = {&R, &P, L, C, NULL, NULL, NULL};
    if (!st) {
        p_truncate(&P);
        st = csr_transpose(&P, C->n, &R);
    }
    int32_t *cls = NULL, *bid = NULL, ncls = 0;
    agg_crow *rows = NULL;
    /* Level 2 only: deeper rows reach 3 blocks, their neighbourhoods 11^3
     * blocks, and those repeat too rarely to pay for the fingerprints. */
    if (!st && l == 1 && g->dim == 3 && hv__agg_classes_on())
        g->class_copies += rap_classes(g, l, &rap, &cls, &bid, &rows, &ncls);
    if (!st)
        st = build_csr(&C->A, C->n, C->n, rap_row_classed, &rap, 0, L->n, 1e-9);
    rap_classes_free(cls, bid, rows, ncls);
    if (st) {
        hv__agg_csr_free(&P);
        hv__agg_csr_free(&R);
        return st;
    }
    if (L->tn) {
        /* A level that is mostly template rows applies P and P^T from its
         * stencil as the fine level does: cheaper than the two matrices. */
        hv__agg_csr_free(&P);
        hv__agg_csr_free(&R);
        return HV_OK;
    }
    L->P = P; /* kept for the transfers */
    L->R = R;
    g->bytes += (P.rp[P.n] + R.rp[R.n]) * (sizeof(int32_t) + sizeof(float)) +
                ((size_t)P.n + R.n + 2) * sizeof(size_t);
    return HV_OK;
}

/* ---------- Galerkin from the fine level ---------- */

/* A small open-addressing accumulator over fine cells: the supports of one
 * coarse column's products on the fine level lie in an 8^3 box of cells. */
#define HASH_BITS 11
#define HASH_SIZE (1 << HASH_BITS)

typedef struct hacc {
    int32_t key[HASH_SIZE]; /* cell + 1; 0: empty */
    double val[HASH_SIZE];
    int32_t used[HASH_SIZE]; /* slots in insertion order */
    int n;
} hacc;

static inline int hacc_slot(hacc *h, int32_t c)
{
    uint32_t s = ((uint32_t)c * 2654435761u) >> (32 - HASH_BITS);
    for (;;) {
        if (h->key[s] == c + 1)
            return (int)s;
        if (h->key[s] == 0) {
            if (h->n >= HASH_SIZE / 2)
                return -1;
            h->key[s] = c + 1;
            h->val[s] = 0;
            h->used[h->n++] = (int32_t)s;
            return (int)s;
        }
        s = (s + 1) & (HASH_SIZE - 1);
    }
}

static void hacc_clear(hacc *h)
{
    for (int q = 0; q < h->n; q++)
        h->key[h->used[q]] = 0;
    h->n = 0;
}

typedef struct g0_scratch {
    hacc v, w;
    double t[HASH_SIZE];
} g0_scratch;

/* A coarse row copied from a template: the row of a block whose neighbourhood
 * is plain fluid, as offsets to the neighbouring blocks. */
typedef struct g0_template {
    int n;
    int off[125][3];
    double val[125];
} g0_template;

/* Rows of level 1 that share their neighbourhood: classes of rows whose 5^3
 * blocks of fine cells read the same (open faces, fluid, in the grid) and
 * hold one aggregate each, so that g0_row does the same arithmetic in the
 * same order for each of them and gives the same entries at the same block
 * offsets, bit for bit. One row of each class of two or more is computed;
 * the others are copied from it. */
#define G0_WIN 125 /* blocks of a neighbourhood */

typedef struct g0_class {
    int n;
    int8_t off[G0_WIN][3];
    double val[G0_WIN];
} g0_class;

typedef struct g0_ctx {
    agg_op o;
    const mg_alevel *L, *C;
    double wp;
    const uint8_t *plain;    /* per level-1 unknown: a plain neighbourhood (or NULL) */
    const g0_template *tmpl; /* NULL until made */
    const int32_t *cls;      /* per level-1 unknown: its class, -1 none (or NULL) */
    const g0_class *rows;    /* the classes' rows (NULL while they are made) */
} g0_ctx;

/* Row J of A_c = P^T A (P e_J): v = P e_J on the members of J and their
 * neighbours, w = A v, then w - wp A D^-1 w summed per aggregate
 * (P^T = P0^T (I - wp A D^-1)). */
static int g0_row(const void *ctx, void *scratch, int32_t J, spa *cs)
{
    const g0_ctx *x = ctx;
    const agg_op *o = &x->o;
    const mg_alevel *L = x->L;
    if (x->tmpl && x->plain[J])
        return 0; /* the template's row: level 1 takes it from there */
    g0_scratch *S = scratch;
    int32_t bc[ROW_MAX];
    float bv[ROW_MAX];
    const int32_t *col;
    const float *val;
    hacc_clear(&S->v);
    hacc_clear(&S->w);
    for (size_t q = L->mrp[J]; q < L->mrp[J + 1]; q++) {
        int k = hv__agg_op_row(o, L->mem[q], bc, bv, &col, &val);
        for (int e = 0; e < k; e++)
            if (L->agg[col[e]] >= 0 && hacc_slot(&S->v, col[e]) < 0)
                return -1;
    }
    /* P(c, J) = [agg c = J] - wp dinv_c sum over row c of a_cx [agg x = J],
     * and w = A v = sum over c of P(c, J) times row c (A is symmetric). */
    for (int q = 0; q < S->v.n; q++) {
        int32_t c = S->v.key[S->v.used[q]] - 1;
        int k = hv__agg_op_row(o, c, bc, bv, &col, &val);
        double sum = 0;
        for (int e = 0; e < k; e++)
            if (L->agg[col[e]] == J)
                sum += val[e];
        double pc = (L->agg[c] == J) - x->wp * o->dinv[c] * sum;
        if (pc == 0)
            continue;
        for (int e = 0; e < k; e++) {
            int h = hacc_slot(&S->w, col[e]);
            if (h < 0)
                return -1;
            S->w.val[h] += val[e] * pc;
        }
    }
    int nw = S->w.n;
    for (int q = 0; q < nw; q++) {
        int h = S->w.used[q];
        S->t[q] = x->wp * o->dinv[S->w.key[h] - 1] * S->w.val[h];
    }
    for (int q = 0; q < nw; q++) {
        if (S->t[q] == 0)
            continue;
        int k = hv__agg_op_row(o, S->w.key[S->w.used[q]] - 1, bc, bv, &col, &val);
        for (int e = 0; e < k; e++) {
            int h = hacc_slot(&S->w, col[e]);
            if (h < 0)
                return -1;
            S->w.val[h] -= val[e] * S->t[q];
        }
    }
    for (int q = 0; q < S->w.n; q++) {
        int h = S->w.used[q];
        int32_t I = L->agg[S->w.key[h] - 1];
        if (I >= 0 && spa_add(cs, I, S->w.val[h]))
            return -1;
    }
    return 0;
}

/* A level-1 row from its class: the class's entries at J's block offsets. */
static int g0_class_row(const g0_ctx *x, int32_t J, spa *cs)
{
    const g0_class *K = &x->rows[x->cls[J]];
    const int32_t *p = x->C->xyz + 3 * (size_t)J;
    const int *e = x->C->ext;
    for (int q = 0; q < K->n; q++) {
        int32_t I =
            (p[0] + K->off[q][0]) + e[0] * ((p[1] + K->off[q][1]) + e[1] * (p[2] + K->off[q][2]));
        spa_add(cs, I, K->val[q]);
    }
    return 0;
}

static int g0_row_classed(const void *ctx, void *scratch, int32_t J, spa *cs)
{
    const g0_ctx *x = ctx;
    if (x->cls && x->rows && x->cls[J] >= 0)
        return g0_class_row(x, J, cs);
    return g0_row(ctx, scratch, J, cs);
}

/* cls[J] for the rows of level 1 that are not plain: the class of J's
 * neighbourhood of 5^3 blocks, -1 for a row alone in its class. Returns the
 * number of classes, or -1 out of memory. */
static int32_t row_classes(const mg_agg *g, const uint8_t *plain, int32_t *cls)
{
    const mg_alevel *C = &g->lv[1];
    const size_t nb = (size_t)C->ext[0] * C->ext[1] * C->ext[2];
    uint64_t *code = malloc(nb * sizeof *code), *fp = malloc(2 * nb * sizeof *fp);
    int32_t ncls = -1;
    if (code && fp) {
        hv__agg_fine_codes(g, code);
        if (hv__agg_fingerprints(C->ext, 2, code, code, fp) == 0)
            ncls = hv__agg_classes(nb, fp, plain, cls, AGG_CLASS_MAX);
    }
    for (size_t J = nb; ncls >= 0 && J < (size_t)C->n; J++)
        cls[J] = -1;
    free(code);
    free(fp);
    return ncls;
}

/* The rows of the classes: each class's first row by g0_row, as offsets to
 * its block. Returns 0, or -1 where g0_row failed. */
static int class_rows(const g0_ctx *x, int32_t ncls, g0_class *rows)
{
    const mg_alevel *C = x->C;
    int32_t *first = class_firsts(x->cls, C->n, ncls);
    int failed = !first;
#pragma omp parallel if (ncls > 64 && !failed)
    {
        spa cs = {0};
        g0_scratch *S = malloc(sizeof *S);
        int bad = failed || !S || spa_init(&cs, C->n);
        if (S)
            memset(S, 0, sizeof *S);
#pragma omp for schedule(dynamic, 16)
        for (int32_t k = 0; k < ncls; k++) {
            if (bad)
                continue;
            int32_t J = first[k];
            if (J < 0)
                continue;
            const int32_t *p = C->xyz + 3 * (size_t)J;
            spa_start(&cs);
            if (g0_row(x, S, J, &cs) || cs.nidx > G0_WIN) {
                bad = 1;
                continue;
            }
            rows[k].n = (int)cs.nidx;
            for (size_t q = 0; q < cs.nidx; q++) {
                const int32_t *r = C->xyz + 3 * (size_t)cs.idx[q];
                for (int a = 0; a < 3; a++)
                    rows[k].off[q][a] = (int8_t)(r[a] - p[a]);
                rows[k].val[q] = cs.acc[cs.idx[q]];
            }
        }
        spa_free(&cs);
        free(S);
        if (bad) {
#pragma omp atomic write
            failed = 1;
        }
    }
    free(first);
    return failed ? -1 : 0;
}

/* Blocks of level 1 whose 5^3 neighbourhood of blocks is whole and all fluid
 * (3D binary fine levels): their rows are all the same, up to the columns.
 * plain[J] per level-1 unknown (NULL when there are none). */
static hv_status plain_blocks(const mg_agg *g, uint8_t **plain_out)
{
    const mg_level *F = g->fine;
    const mg_alevel *C = &g->lv[1];
    *plain_out = NULL;
    if (g->dim != 3 || !F->binary)
        return HV_OK;
    int e[3] = {C->ext[0], C->ext[1], C->ext[2]};
    size_t nb = (size_t)e[0] * e[1] * e[2];
    uint8_t *full = malloc(nb), *tmp = malloc(nb), *plain = malloc((size_t)C->n + 1);
    if (!full || !tmp || !plain) {
        free(full);
        free(tmp);
        free(plain);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for the coarse operator");
    }
    /* full: the block's 8 cells are in the grid and fluid with every face open. */
#pragma omp parallel for schedule(static) if (nb > AGG_PAR_MIN)
    for (size_t b = 0; b < nb; b++) {
        int bx = (int)(b % e[0]), by = (int)((b / e[0]) % e[1]),
            bz = (int)(b / ((size_t)e[0] * e[1]));
        int ok = 2 * bx + 1 < F->n[0] && 2 * by + 1 < F->n[1] && 2 * bz + 1 < F->n[2];
        for (int q = 0; ok && q < 8; q++) {
            size_t c = (size_t)(2 * bx + (q & 1)) + F->sy * (size_t)(2 * by + ((q >> 1) & 1)) +
                       F->sz * (size_t)(2 * bz + (q >> 2));
            ok = F->a[c] != 0.0f && g->faces[c] == 0x3f;
        }
        full[b] = (uint8_t)ok;
    }
    /* An AND over a window of 5 blocks along each axis, out of range counting as 0. */
    size_t stride[3] = {1, (size_t)e[0], (size_t)e[0] * e[1]};
    for (int a = 0; a < 3; a++) {
        uint8_t *src = a % 2 ? tmp : full, *dst = a % 2 ? full : tmp;
#pragma omp parallel for schedule(static) if (nb > AGG_PAR_MIN)
        for (size_t b = 0; b < nb; b++) {
            int x = (int)(b / stride[a] % e[a]), ok = x >= 2 && x + 2 < e[a];
            for (int d = -2; ok && d <= 2; d++)
                ok = src[b + (ptrdiff_t)d * (ptrdiff_t)stride[a]];
            dst[b] = (uint8_t)ok;
        }
    }
    /* After three passes the result is in tmp. */
    for (int32_t I = 0; I < C->n; I++) {
        const int32_t *p = C->xyz + 3 * (size_t)I;
        plain[I] = tmp[(size_t)p[0] + e[0] * ((size_t)p[1] + e[1] * (size_t)p[2])];
    }
    free(full);
    free(tmp);
    *plain_out = plain;
    return HV_OK;
}

hv_status hv__agg_galerkin0(mg_agg *g, double wp)
{
    mg_alevel *C = &g->lv[1];
    g0_ctx x = {level_op(g, 0), &g->lv[0], C, wp, NULL, NULL, NULL, NULL};
    uint8_t *plain;
    hv_status st = plain_blocks(g, &plain);
    if (st)
        return st;
    g0_template *T = NULL;
    int32_t J0 = -1;
    for (int32_t J = 0; plain && J < C->n && J0 < 0; J++)
        if (plain[J])
            J0 = J;
    if (J0 >= 0) {
        /* The template: one plain row, computed. */
        spa cs = {0};
        g0_scratch *S = calloc(1, sizeof *S);
        T = calloc(1, sizeof *T);
        if (!S || !T || spa_init(&cs, C->n) || (spa_start(&cs), g0_row(&x, S, J0, &cs)) ||
            cs.nidx > 125) {
            free(T);
            T = NULL;
        } else {
            const int32_t *p0 = C->xyz + 3 * (size_t)J0;
            for (size_t q = 0; q < cs.nidx; q++) {
                const int32_t *p = C->xyz + 3 * (size_t)cs.idx[q];
                for (int a = 0; a < 3; a++)
                    T->off[T->n][a] = p[a] - p0[a];
                T->val[T->n++] = cs.acc[cs.idx[q]];
            }
        }
        spa_free(&cs);
        free(S);
    }
    x.plain = plain;
    x.tmpl = T;
    /* The other rows by class where they repeat (3D binary levels). */
    int32_t *cls = NULL, ncls = 0;
    g0_class *rows = NULL;
    if (hv__agg_classes_on() && g->dim == 3 && g->fine->binary &&
        (cls = malloc(((size_t)C->n + 1) * sizeof *cls)) &&
        (ncls = row_classes(g, plain, cls)) > 0 && (rows = malloc((size_t)ncls * sizeof *rows))) {
        x.cls = cls;
        if (class_rows(&x, ncls, rows) == 0) {
            x.rows = rows;
            for (int32_t J = 0; J < C->n; J++)
                g->class_copies += cls[J] >= 0;
            g->class_copies -= (size_t)ncls;
        }
    }
    st = build_csr(&C->A, C->n, C->n, g0_row_classed, &x, sizeof(g0_scratch), 0, 1e-9);
    free(cls);
    free(rows);
    if (!st && T) {
        /* Level 1 keeps the template for its plain rows (as build_csr keeps
         * them: tiny entries off the diagonal left out). */
        double diag = 0;
        for (int e = 0; e < T->n; e++)
            if (!T->off[e][0] && !T->off[e][1] && !T->off[e][2])
                diag = fabs(T->val[e]);
        for (int e = 0; e < T->n; e++) {
            const int *d = T->off[e];
            int self = !d[0] && !d[1] && !d[2];
            if (!self && !(fabs(T->val[e]) > 1e-9 * diag))
                continue;
            C->toff[C->tn] = d[0] + C->ext[0] * (d[1] + C->ext[1] * d[2]);
            C->tval[C->tn++] = (float)T->val[e];
        }
        C->plain = plain;
        plain = NULL;
    }
    free(T);
    free(plain);
    return st;
}
