/*
 * Thin parts of a cloud without normals (hv_points_surface, step 0, after
 * the tree). Where a point's neighbourhood holds two sheets (its spread
 * above OR_CUT_SPREAD: the faces of a fin or an ear thinner than the
 * neighbourhood), the tree's sign is a guess. A ray from the point counts
 * the sheets it crosses on its way out of the cloud, one way and the other
 * along the coordinate axis nearest the point's direction: the way with an
 * even count leaves the solid, a vote for or against the point's sign. The
 * votes and the neighbour graph's couplings make a binary labelling (keep
 * or turn each point) whose least cost is a minimum cut (Dinic's maximum
 * flow) over the points within OR_CUT_HOPS edges of a vote; the points
 * beyond hold their signs.
 */
#include "sdf_internal.h"
#include "core/error.h"

#include <limits.h>
#include <math.h>

#include <stdlib.h>
#include <string.h>

#define OR_CUT_SPREAD 0.3 /* a point's spread above which it votes */
#define OR_CUT_HOPS 10    /* edges from a vote that the labelling reaches */
#define OR_CUT_VOTE 1.0   /* a vote's weight (an edge weighs at most 1) */
#define OR_CUT_EPS 1e-12  /* capacity left that counts as none */

/* ---- votes ---- */

typedef struct cut_rays {
    const pt_bins *B;  /* cells of side 2 rc */
    double rc, sheet;  /* the rays' radius; a sheet's half thickness */
    long lo[3], hi[3]; /* the cells the cloud spans */
} cut_rays;

typedef struct hits {
    double *t;
    size_t n, cap;
} hits;

static int hits_push(hits *H, double t)
{
    if (H->n == H->cap) {
        size_t c = H->cap ? 2 * H->cap : 256;
        double *p = realloc(H->t, c * sizeof *p);
        if (!p)
            return -1;
        H->t = p, H->cap = c;
    }
    H->t[H->n++] = t;
    return 0;
}

static int cmp_double(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* The sheets along a ray: its hits' distances sorted, a new sheet where
 * two are more than a sheet's thickness apart. */
static long sheets(hits *H, double gap)
{
    if (!H->n)
        return 0;
    qsort(H->t, H->n, sizeof *H->t, cmp_double);
    long s = 1;
    for (size_t k = 1; k < H->n; k++)
        s += H->t[k] - H->t[k - 1] > gap;
    return s;
}

/* The points within rc of the line through x along axis a, off x's own
 * sheet (farther than `sheet` from its plane, normal v), by their side:
 * the distances along a into plus and minus. */
static int ray_hits(const cut_rays *C, const float *x, const double *v, int a, hits *plus,
                    hits *minus)
{
    const pt_bins *B = C->B;
    const int b = (a + 1) % 3, c = (a + 2) % 3;
    long q[3], r[3];
    for (int k = 0; k < 3; k++) {
        q[k] = (long)floor((x[k] - C->rc) / B->c); /* sx is from B->lo */
        r[k] = (long)floor((x[k] + C->rc) / B->c);
    }
    for (long j = q[b]; j <= r[b]; j++)
        for (long k = q[c]; k <= r[c]; k++)
            for (long i = C->lo[a]; i <= C->hi[a]; i++) {
                long cell[3];
                cell[a] = i, cell[b] = j, cell[c] = k;
                uint32_t s, len;
                if (!hv__bins_find(B, hv__cell_key(cell[0], cell[1], cell[2]), &s, &len))
                    continue;
                for (uint32_t m = s; m < s + len; m++) {
                    const float *y = B->sx + 3 * (size_t)m;
                    const double d[3] = {y[0] - x[0], y[1] - x[1], y[2] - x[2]};
                    if (d[b] * d[b] + d[c] * d[c] >= C->rc * C->rc ||
                        fabs(d[0] * v[0] + d[1] * v[1] + d[2] * v[2]) <= C->sheet)
                        continue;
                    if (hits_push(d[a] > 0 ? plus : minus, fabs(d[a])))
                        return -1;
                }
            }
    return 0;
}

/* The vote of the point at x with direction v: +1 when v leaves the solid
 * (an even count of sheets ahead and an odd one behind), -1 the other way,
 * 0 when the counts do not tell. */
static int ray_vote(const cut_rays *C, const float *x, const double *v, hits *plus, hits *minus,
                    int *failed)
{
    int a = 0;
    for (int k = 1; k < 3; k++)
        a = fabs(v[k]) > fabs(v[a]) ? k : a;
    plus->n = minus->n = 0;
    if (ray_hits(C, x, v, a, plus, minus)) {
        *failed = 1;
        return 0;
    }
    const long np = sheets(plus, C->sheet), nm = sheets(minus, C->sheet);
    if ((np & 1) == (nm & 1))
        return 0;
    const int ahead_even = v[a] > 0 ? !(np & 1) : !(nm & 1);
    return ahead_even ? 1 : -1;
}

/* Each place's vote into vote (0 where its spread is low); how many. */
static hv_status cut_votes(const pt_bins *near, size_t n, const float *spread, const double *D,
                           const cut_rays *C, signed char *vote, size_t *nvote)
{
    int failed = 0;
    size_t votes = 0;
#pragma omp parallel reduction(| : failed) reduction(+ : votes)
    {
        hits plus = {NULL, 0, 0}, minus = {NULL, 0, 0};
#pragma omp for schedule(dynamic, 256)
        for (size_t u = 0; u < n; u++) {
            vote[u] = 0;
            if (failed || !(spread[near->order[u]] > OR_CUT_SPREAD))
                continue;
            vote[u] = (signed char)ray_vote(C, near->sx + 3 * u, D + 3 * u, &plus, &minus, &failed);
            votes += vote[u] != 0;
        }
        free(plus.t), free(minus.t);
    }
    *nvote = votes;
    return failed ? hv__error(HV_ERR_NOMEM, "points: out of memory for the rays") : HV_OK;
}

/* ---- the labelling: places within OR_CUT_HOPS of a vote ---- */

/* The places within OR_CUT_HOPS edges of a vote, breadth first, into sub
 * (their number into *m) and their local numbers into loc (UINT32_MAX
 * for the others). */
static void cut_region(const or_graph *G, size_t n, const signed char *vote, uint32_t *sub,
                       size_t *m, uint32_t *loc)
{
    size_t k = 0;
    for (size_t u = 0; u < n; u++) {
        loc[u] = vote[u] ? (uint32_t)k : UINT32_MAX;
        if (vote[u])
            sub[k++] = (uint32_t)u;
    }
    size_t from = 0;
    for (int hop = 0; hop < OR_CUT_HOPS; hop++) {
        const size_t to = k;
        for (size_t q = from; q < to; q++)
            for (uint32_t e = G->off[sub[q]]; e < G->off[sub[q] + 1]; e++) {
                const uint32_t j = G->adj[e];
                if (loc[j] == UINT32_MAX) {
                    loc[j] = (uint32_t)k;
                    sub[k++] = j;
                }
            }
        from = to;
    }
    *m = k;
}

/* How strongly places i and j hold their signs together: |d_i . d_j|
 * where the two lie on one sheet (each off the other's plane by little),
 * 0 where the directions disagree in sign; -1 when the directions
 * disagree. */
static double coupling(const pt_bins *B, const double *D, uint32_t i, uint32_t j)
{
    const double *a = D + 3 * (size_t)i, *b = D + 3 * (size_t)j;
    const float *x = B->sx + 3 * (size_t)i, *y = B->sx + 3 * (size_t)j;
    const double u[3] = {y[0] - x[0], y[1] - x[1], y[2] - x[2]};
    const double len = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    const double ab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    if (!(ab > 0))
        return 0;
    if (!(len > 0))
        return ab;
    const double oa = fabs(u[0] * a[0] + u[1] * a[1] + u[2] * a[2]) / len;
    const double ob = fabs(u[0] * b[0] + u[1] * b[1] + u[2] * b[2]) / len;
    return ab * (1 - fmax(oa, ob));
}

/* A flow network in arrays: node x's arcs from off[x] to off[x + 1], each
 * with its head, capacity left and reverse arc. */
typedef struct net {
    uint32_t *off, *head, *rev;
    double *cap;
    uint32_t *cur; /* fill cursors, then Dinic's current arcs */
    int32_t *level;
    uint32_t *queue, *path;
    size_t nodes;
} net;

/* An arc a to b of capacity c and its reverse, of capacity back. */
static void net_pair(net *F, uint32_t a, uint32_t b, double c, double back)
{
    const uint32_t fa = F->cur[a]++, fb = F->cur[b]++;
    F->head[fa] = b, F->cap[fa] = c, F->rev[fa] = fb;
    F->head[fb] = a, F->cap[fb] = back, F->rev[fb] = fa;
}

/* The arcs of the labelling (source: keep, sink: turn): an edge's coupling
 * both ways between places of the region, to the source where the other
 * end lies beyond it; OR_CUT_VOTE from the source to a place voting to
 * keep, to the sink from one voting to turn. count: the arcs' counts per
 * node into F->cur, else the arcs themselves. */
static void cut_arcs(net *F, const pt_bins *B, const or_graph *G, const double *D,
                     const signed char *vote, const uint32_t *sub, size_t m, const uint32_t *loc,
                     int count)
{
    const uint32_t src = (uint32_t)m, snk = (uint32_t)m + 1;
    for (size_t x = 0; x < m; x++) {
        const uint32_t u = sub[x];
        for (uint32_t e = G->off[u]; e < G->off[u + 1]; e++) {
            const uint32_t j = G->adj[e];
            const double w = coupling(B, D, u, j);
            if (!(w > 0))
                continue;
            const uint32_t y = loc[j] == UINT32_MAX ? src : loc[j];
            if (y < x) /* the lists hold each edge both ways: one pair for both */
                continue;
            if (count)
                F->cur[x]++, F->cur[y]++;
            else if (y == src)
                net_pair(F, src, (uint32_t)x, w, 0);
            else
                net_pair(F, (uint32_t)x, y, w, w);
        }
        if (vote[u]) {
            const uint32_t a = vote[u] > 0 ? src : (uint32_t)x, b = vote[u] > 0 ? (uint32_t)x : snk;
            if (count)
                F->cur[a]++, F->cur[b]++;
            else
                net_pair(F, a, b, OR_CUT_VOTE, 0);
        }
    }
}

static void net_free(net *F)
{
    free(F->off), free(F->head), free(F->rev), free(F->cap), free(F->cur), free(F->level);
    free(F->queue), free(F->path);
}

static hv_status net_build(net *F, const pt_bins *B, const or_graph *G, const double *D,
                           const signed char *vote, const uint32_t *sub, size_t m,
                           const uint32_t *loc)
{
    memset(F, 0, sizeof *F);
    F->nodes = m + 2;
    F->off = calloc(F->nodes + 1, sizeof *F->off);
    F->cur = calloc(F->nodes, sizeof *F->cur);
    F->level = malloc(F->nodes * sizeof *F->level);
    F->queue = malloc(F->nodes * sizeof *F->queue);
    F->path = malloc(F->nodes * sizeof *F->path);
    if (!F->off || !F->cur || !F->level || !F->queue || !F->path)
        return hv__error(HV_ERR_NOMEM, "points: out of memory for the thin parts' labelling");
    cut_arcs(F, B, G, D, vote, sub, m, loc, 1);
    for (size_t x = 0; x < F->nodes; x++)
        F->off[x + 1] = F->off[x] + F->cur[x];
    const size_t arcs = F->off[F->nodes];
    F->head = malloc(arcs * sizeof *F->head);
    F->rev = malloc(arcs * sizeof *F->rev);
    F->cap = malloc(arcs * sizeof *F->cap);
    if (!F->head || !F->rev || !F->cap)
        return hv__error(HV_ERR_NOMEM, "points: out of memory for the thin parts' labelling");
    memcpy(F->cur, F->off, F->nodes * sizeof *F->cur);
    cut_arcs(F, B, G, D, vote, sub, m, loc, 0);
    return HV_OK;
}

/* Levels from s by arcs with capacity left, up to t's (the nodes beyond
 * lie on no shortest path); whether t is reached. */
static int net_levels(net *F, uint32_t s, uint32_t t)
{
    for (size_t x = 0; x < F->nodes; x++)
        F->level[x] = -1;
    size_t qh = 0, qt = 0;
    F->level[s] = 0;
    F->queue[qt++] = s;
    while (qh < qt) {
        const uint32_t x = F->queue[qh++];
        if (F->level[t] >= 0 && F->level[x] >= F->level[t])
            break;
        for (uint32_t e = F->off[x]; e < F->off[x + 1]; e++)
            if (F->cap[e] > OR_CUT_EPS && F->level[F->head[e]] < 0) {
                F->level[F->head[e]] = F->level[x] + 1;
                F->queue[qt++] = F->head[e];
            }
    }
    return F->level[t] >= 0;
}

/* One blocking flow of Dinic's: paths s to t along rising levels, found
 * by a walk that keeps its arcs in F->path and each node's next arc to try
 * in F->cur. */
static void net_block(net *F, uint32_t s, uint32_t t)
{
    memcpy(F->cur, F->off, F->nodes * sizeof *F->cur);
    size_t len = 0;
    uint32_t x = s;
    for (;;) {
        if (x == t) {
            double c = INFINITY;
            for (size_t k = 0; k < len; k++)
                c = fmin(c, F->cap[F->path[k]]);
            size_t first = len;
            for (size_t k = 0; k < len; k++) {
                F->cap[F->path[k]] -= c;
                F->cap[F->rev[F->path[k]]] += c;
                if (first == len && F->cap[F->path[k]] <= OR_CUT_EPS)
                    first = k;
            }
            len = first;
            x = len ? F->head[F->path[len - 1]] : s;
            continue;
        }
        uint32_t e = F->cur[x];
        while (e < F->off[x + 1] &&
               !(F->cap[e] > OR_CUT_EPS && F->level[F->head[e]] == F->level[x] + 1))
            e++;
        F->cur[x] = e;
        if (e < F->off[x + 1]) {
            F->path[len++] = e;
            x = F->head[e];
            continue;
        }
        if (x == s)
            return;
        F->level[x] = -1; /* a dead end */
        len--;
        x = len ? F->head[F->path[len - 1]] : s;
        F->cur[x]++;
    }
}

/* The rays' cells (side 2 rc) and the span of the cloud's. */
static hv_status rays_init(cut_rays *C, pt_bins *RB, const hv_points *P, const double lo[3],
                           const pt_thin *T)
{
    size_t cells;
    hv_status st = hv__bins_build(RB, P->xyz, P->count, lo, 2 * T->rc, &cells);
    *C = (cut_rays){.B = RB, .rc = T->rc, .sheet = T->sheet};
    for (int a = 0; a < 3; a++)
        C->lo[a] = LONG_MAX, C->hi[a] = LONG_MIN;
    for (size_t i = 0; i < P->count && !st; i++) {
        long q[3];
        hv__cell_of(RB, P->xyz + 3 * i, q);
        for (int a = 0; a < 3; a++) {
            C->lo[a] = q[a] < C->lo[a] ? q[a] : C->lo[a];
            C->hi[a] = q[a] > C->hi[a] ? q[a] : C->hi[a];
        }
    }
    return st;
}

/* The least-cost labelling of the region sub[0..m): its maximum flow, then
 * the places the source no longer reaches turned. */
static hv_status cut_label(const pt_bins *near, const or_graph *G, const signed char *vote,
                           const uint32_t *sub, size_t m, const uint32_t *loc, double *D,
                           hv_points_report *R)
{
    net F;
    hv_status st = net_build(&F, near, G, D, vote, sub, m, loc);
    if (!st) {
        const uint32_t src = (uint32_t)m, snk = (uint32_t)m + 1;
        while (net_levels(&F, src, snk))
            net_block(&F, src, snk);
        for (size_t x = 0; x < m; x++)
            if (F.level[x] < 0) { /* the last levels: those the source reaches */
                double *d = D + 3 * (size_t)sub[x];
                d[0] = -d[0], d[1] = -d[1], d[2] = -d[2];
                R->orient_thin_turned++;
            }
    }
    net_free(&F);
    return st;
}

hv_status hv__points_cut(const pt_bins *near, const or_graph *G, const hv_points *P,
                         const pt_thin *T, double *D, hv_points_report *R)
{
    const size_t n = P->count;
    pt_bins RB;
    cut_rays C;
    signed char *vote = malloc(n);
    uint32_t *sub = malloc(n * sizeof *sub), *loc = malloc(n * sizeof *loc);
    hv_status st = vote && sub && loc
                       ? rays_init(&C, &RB, P, near->lo, T)
                       : hv__error(HV_ERR_NOMEM, "points: out of memory for the thin parts");
    if (!st)
        st = cut_votes(near, n, T->spread, D, &C, vote, &R->orient_thin_votes);
    if (!st && R->orient_thin_votes) {
        size_t m;
        cut_region(G, n, vote, sub, &m, loc);
        st = cut_label(near, G, vote, sub, m, loc, D, R);
    }
    for (size_t u = 0; !st && T->held && u < n; u++)
        T->held[near->order[u]] = T->spread[near->order[u]] > OR_CUT_SPREAD;
    if (vote && sub && loc)
        hv__bins_free(&RB);
    free(vote), free(sub), free(loc);
    return st;
}
