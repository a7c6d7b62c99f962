/*
 * Curve repair for the 2D signed heat method (see heatvox/curves.h): welds
 * points closer than the tolerance, splits segments at the points lying on
 * them (so that overlaps become duplicates and T-junctions shared points),
 * drops zero-length and duplicate segments, and makes each chain through
 * points of degree 2 run one way; which way whole chains run is decided in
 * sdf2d_orient.c.
 */
#include "core/error.h"
#include "sdf2d_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static int by_key(const void *a, const void *b)
{
    const uint64_t *x = a, *y = b;
    if (x[0] != y[0])
        return (x[0] > y[0]) - (x[0] < y[0]);
    return (x[1] > y[1]) - (x[1] < y[1]);
}

/* Points on a dense grid of square cells over their bounds, listed by cell (a
 * counting sort). */
typedef struct point_grid {
    double lo[2], side;
    int64_t n[2];
    uint32_t *start; /* n[0] * n[1] + 1 offsets into ids, x fastest */
    uint32_t *ids;
} point_grid;

static int64_t pg_index(const point_grid *g, double v, int a)
{
    return (int64_t)floor((v - g->lo[a]) / g->side);
}

static size_t pg_cell(const point_grid *g, const double *p)
{
    return (size_t)pg_index(g, p[0], 0) + (size_t)g->n[0] * (size_t)pg_index(g, p[1], 1);
}

static void pg_free(point_grid *g)
{
    free(g->start);
    free(g->ids);
    g->start = g->ids = NULL;
}

/* The points i with used[i] (all when used is NULL), in cells of side `side`
 * (> 0), or larger where that would make more than about 3 (2n + 4096) cells:
 * memory stays linear in the points. */
static hv_status pg_build(point_grid *g, const double *P, size_t np, const uint8_t *used,
                          double side)
{
    size_t n = 0;
    double hi[2] = {0, 0};
    g->lo[0] = g->lo[1] = 0;
    for (size_t i = 0; i < np; i++)
        if (!used || used[i]) {
            for (int a = 0; a < 2; a++) {
                g->lo[a] = n ? fmin(g->lo[a], P[2 * i + a]) : P[2 * i + a];
                hi[a] = n ? fmax(hi[a], P[2 * i + a]) : P[2 * i + a];
            }
            n++;
        }
    double W = hi[0] - g->lo[0], H = hi[1] - g->lo[1], cap = 2.0 * n + 4096;
    g->side = fmax(side, fmax(sqrt(W * H / cap), fmax(W, H) / cap));
    g->n[0] = (int64_t)floor(W / g->side) + 1;
    g->n[1] = (int64_t)floor(H / g->side) + 1;
    size_t cells = (size_t)g->n[0] * (size_t)g->n[1];
    g->start = calloc(cells + 1, sizeof *g->start);
    g->ids = malloc((n ? n : 1) * sizeof *g->ids);
    if (!g->start || !g->ids) {
        pg_free(g);
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    }
    for (size_t i = 0; i < np; i++)
        if (!used || used[i])
            g->start[pg_cell(g, P + 2 * i) + 1]++;
    for (size_t c = 0; c < cells; c++)
        g->start[c + 1] += g->start[c];
    for (size_t i = 0; i < np; i++)
        if (!used || used[i])
            g->ids[g->start[pg_cell(g, P + 2 * i)]++] = (uint32_t)i;
    for (size_t c = cells; c > 0; c--)
        g->start[c] = g->start[c - 1];
    g->start[0] = 0;
    return HV_OK;
}

/* Overlaps: splits every segment at the points that lie on it (within tol,
 * away from its ends), so that collinear overlaps become exact duplicates and
 * T-junctions become shared points. *S is replaced by a new array.
 *
 * The split points of a segment, and the order they are sorted from, are those
 * of a walk over buckets of side `cell` (>= tol): samples cell/2 apart along the
 * segment, the 3 x 3 buckets around each, the points of a bucket in the order
 * of a sort by bucket. The points themselves are found on a point_grid of
 * cells of about the mean segment length (at least 2 tol), since buckets of
 * side h hold thousands of points where many small curves share one; each
 * point found is then placed where that walk would first have met it. */
typedef struct tp {
    double t;
    uint32_t p;
    uint32_t step, around, rank; /* where the walk over buckets of side cell meets p */
} tp;

static int by_t(const void *a, const void *b)
{
    double x = ((const tp *)a)->t, y = ((const tp *)b)->t;
    return (x > y) - (x < y);
}

static uint64_t bucket_key(int64_t bx, int64_t by)
{
    return ((uint64_t)(bx + (1ll << 31)) << 32) | (uint64_t)(by + (1ll << 31));
}

/* rank[p]: the place of point p in the walk's buckets, sorted by bucket. */
static hv_status walk_ranks(const double *P, size_t np, const uint8_t *used, size_t nu, double cell,
                            uint32_t **rank)
{
    uint64_t *keys = malloc(2 * (nu ? nu : 1) * sizeof *keys);
    *rank = malloc((np ? np : 1) * sizeof **rank);
    if (!keys || !*rank) {
        free(keys);
        free(*rank);
        *rank = NULL;
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    }
    size_t n = 0;
    for (size_t i = 0; i < np; i++)
        if (used[i]) {
            keys[2 * n] =
                bucket_key((int64_t)floor(P[2 * i] / cell), (int64_t)floor(P[2 * i + 1] / cell));
            keys[2 * n + 1] = i;
            n++;
        }
    qsort(keys, n, 2 * sizeof *keys, sdf2d_by_u64);
    for (size_t q = 0; q < n; q++)
        (*rank)[keys[2 * q + 1]] = (uint32_t)q;
    free(keys);
    return HV_OK;
}

/* The first step of the walk along a -> b whose 3 x 3 buckets hold point p, and
 * which of the nine; 0 when none does (the walk misses p). */
static int walk_meets(const double *P, const double *a, double dx, double dy, int steps,
                      double cell, uint32_t p, tp *h)
{
    int64_t px = (int64_t)floor(P[2 * p] / cell), py = (int64_t)floor(P[2 * p + 1] / cell);
    for (int m = 0; m <= steps; m++) {
        double t = steps ? (double)m / steps : 0;
        int64_t bx = (int64_t)floor((a[0] + t * dx) / cell),
                by = (int64_t)floor((a[1] + t * dy) / cell);
        if (px - bx >= -1 && px - bx <= 1 && py - by >= -1 && py - by <= 1) {
            h->step = (uint32_t)m;
            h->around = (uint32_t)(3 * (px - bx + 1) + (py - by + 1));
            return 1;
        }
    }
    return 0;
}

static int walk_before(const tp *x, const tp *y)
{
    if (x->step != y->step)
        return x->step < y->step;
    if (x->around != y->around)
        return x->around < y->around;
    return x->rank < y->rank;
}

/* The points of grid cells x0..x1 by y0..y1 that lie on segment s (length L)
 * and that the walk meets, appended to *hits once each. */
static hv_status cells_hits(const point_grid *g, int64_t x0, int64_t x1, int64_t y0, int64_t y1,
                            const double *P, sdf2d_seg s, double L, double tol, double cell,
                            tp **hits, size_t *nh, size_t *cap)
{
    const double *a = P + 2 * s.a;
    double dx = P[2 * s.b] - a[0], dy = P[2 * s.b + 1] - a[1];
    x0 = x0 < 0 ? 0 : x0;
    y0 = y0 < 0 ? 0 : y0;
    x1 = x1 >= g->n[0] ? g->n[0] - 1 : x1;
    y1 = y1 >= g->n[1] ? g->n[1] - 1 : y1;
    for (int64_t cy = y0; cy <= y1; cy++)
        for (int64_t cx = x0; cx <= x1; cx++) {
            size_t c = (size_t)cx + (size_t)g->n[0] * (size_t)cy;
            for (uint32_t q = g->start[c]; q < g->start[c + 1]; q++) {
                uint32_t p = g->ids[q];
                if (p == s.a || p == s.b)
                    continue;
                double px = P[2 * p] - a[0], py = P[2 * p + 1] - a[1];
                double along = (px * dx + py * dy) / L;
                double off = fabs(px * dy - py * dx) / L;
                if (off > tol || along <= tol || along >= L - tol)
                    continue;
                int seen = 0;
                for (size_t e = 0; e < *nh && !seen; e++)
                    seen = (*hits)[e].p == p;
                if (seen)
                    continue;
                if (*nh == *cap) {
                    *cap = *cap ? 2 * *cap : 16;
                    tp *more = realloc(*hits, *cap * sizeof **hits);
                    if (!more)
                        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
                    *hits = more;
                }
                (*hits)[*nh] = (tp){along, p, 0, 0, 0};
                *nh += (size_t)walk_meets(P, a, dx, dy, (int)ceil(L / (0.5 * cell)), cell, p,
                                          &(*hits)[*nh]);
            }
        }
    return HV_OK;
}

static hv_status split_overlaps(const double *P, size_t np, sdf2d_seg **Sp, size_t *ns, double tol,
                                double cell, size_t *nsplit)
{
    sdf2d_seg *S = *Sp;
    uint8_t *used = calloc(np ? np : 1, 1);
    uint32_t *rank = NULL; /* made at the first split point */
    point_grid g = {{0, 0}, 0, {0, 0}, NULL, NULL};
    sdf2d_seg *out = NULL;
    tp *hits = NULL;
    size_t nu = 0, nout = 0, capout = 0, caphits = 0;
    hv_status status = HV_OK;
    if (!used)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    for (size_t k = 0; k < *ns; k++)
        used[S[k].a] = used[S[k].b] = 1;
    for (size_t i = 0; i < np; i++)
        nu += used[i];
    double total = 0;
    for (size_t k = 0; k < *ns; k++)
        total += sdf2d_seg_len(P, S[k]);
    /* side >= 2 tol: a point within tol of a segment lies within 0.56 side of
     * a sample side/2 apart, so in the 3 x 3 cells around it */
    double side = fmax(2 * tol, fmin(cell, total / (double)(*ns ? *ns : 1)));
    if ((status = pg_build(&g, P, np, used, side)) != HV_OK)
        goto done;
    for (size_t k = 0; k < *ns; k++) {
        const double *a = P + 2 * S[k].a, *b = P + 2 * S[k].b;
        double dx = b[0] - a[0], dy = b[1] - a[1], L = hypot(dx, dy);
        size_t nh = 0;
        /* the cells of the segment's box (grown by 2 tol) when they are few,
         * else 3 x 3 cells around samples g.side/2 apart */
        int64_t x0 = pg_index(&g, fmin(a[0], b[0]) - 2 * tol, 0);
        int64_t x1 = pg_index(&g, fmax(a[0], b[0]) + 2 * tol, 0);
        int64_t y0 = pg_index(&g, fmin(a[1], b[1]) - 2 * tol, 1);
        int64_t y1 = pg_index(&g, fmax(a[1], b[1]) + 2 * tol, 1);
        if ((x1 - x0 + 1) * (y1 - y0 + 1) <= 16) {
            status = cells_hits(&g, x0, x1, y0, y1, P, S[k], L, tol, cell, &hits, &nh, &caphits);
        } else {
            int steps = (int)ceil(L / (0.5 * g.side));
            int64_t pbx = 0, pby = 0;
            for (int m = 0; m <= steps && status == HV_OK; m++) {
                double t = steps ? (double)m / steps : 0;
                int64_t bx = pg_index(&g, a[0] + t * dx, 0), by = pg_index(&g, a[1] + t * dy, 1);
                if (m > 0 && bx == pbx && by == pby)
                    continue;
                pbx = bx;
                pby = by;
                status = cells_hits(&g, bx - 1, bx + 1, by - 1, by + 1, P, S[k], L, tol, cell,
                                    &hits, &nh, &caphits);
            }
        }
        if (status != HV_OK)
            goto done;
        if (nh && !rank && (status = walk_ranks(P, np, used, nu, cell, &rank)) != HV_OK)
            goto done;
        /* the order the walk over buckets of side cell met them in */
        for (size_t e = 0; e < nh; e++)
            hits[e].rank = rank[hits[e].p];
        for (size_t e = 1; e < nh; e++)
            for (size_t f = e; f > 0 && walk_before(&hits[f], &hits[f - 1]); f--) {
                tp x = hits[f];
                hits[f] = hits[f - 1];
                hits[f - 1] = x;
            }
        if (nout + nh + 1 > capout) {
            capout = 2 * (nout + nh + 1) + *ns;
            sdf2d_seg *no = realloc(out, capout * sizeof *out);
            if (!no) {
                status = hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
                goto done;
            }
            out = no;
        }
        if (nh > 1)
            qsort(hits, nh, sizeof *hits, by_t);
        uint32_t prev = S[k].a;
        for (size_t e = 0; e < nh; e++) {
            out[nout++] = (sdf2d_seg){prev, hits[e].p};
            prev = hits[e].p;
        }
        out[nout++] = (sdf2d_seg){prev, S[k].b};
        *nsplit += nh > 0;
    }
    free(S);
    *Sp = out;
    *ns = nout;
    out = NULL;
done:
    pg_free(&g);
    free(used);
    free(rank);
    free(hits);
    free(out);
    return status;
}

/* Joins point i with the points j > i within tol in the 3 x 3 cells around
 * cell (cx, cy). */
static void weld_near(const double *P, const point_grid *g, int64_t cx, int64_t cy, uint32_t i,
                      double tol, uint32_t *par, size_t *welded)
{
    const double *p = P + 2 * i;
    for (int64_t y = cy - 1; y <= cy + 1; y++)
        for (int64_t x = cx - 1; x <= cx + 1; x++) {
            if (x < 0 || x >= g->n[0] || y < 0 || y >= g->n[1])
                continue;
            size_t c = (size_t)(x + g->n[0] * y);
            for (uint32_t f = g->start[c]; f < g->start[c + 1]; f++) {
                uint32_t j = g->ids[f];
                const double *q = P + 2 * j;
                if (j <= i || fabs(q[0] - p[0]) > tol || fabs(q[1] - p[1]) > tol ||
                    hypot(q[0] - p[0], q[1] - p[1]) > tol)
                    continue;
                uint32_t ra = sdf2d_uf_find(par, i), rb = sdf2d_uf_find(par, j);
                if (ra != rb) {
                    par[ra > rb ? ra : rb] = ra < rb ? ra : rb;
                    (*welded)++;
                }
            }
        }
}

/* 1. Weld: points within tol, pairs found on a grid of cells >= 2 tol. The
 * roots (the lowest index of each cluster) and the count do not depend on
 * the order the pairs are met in. */
static hv_status weld_points(const double *P, size_t np, double tol, uint32_t *par, size_t *welded)
{
    point_grid g = {{0, 0}, 0, {0, 0}, NULL, NULL};
    hv_status status = pg_build(&g, P, np, NULL, 2 * tol);
    if (status != HV_OK)
        return status;
    for (int64_t cy = 0; cy < g.n[1]; cy++)
        for (int64_t cx = 0; cx < g.n[0]; cx++) {
            size_t c = (size_t)(cx + g.n[0] * cy);
            for (uint32_t e = g.start[c]; e < g.start[c + 1]; e++)
                weld_near(P, &g, cx, cy, g.ids[e], tol, par, welded);
        }
    pg_free(&g);
    return HV_OK;
}

/* The segments S[0..ns) between welded points, compacted in place without
 * those of zero length; returns their number. */
static size_t weld_segments(const double *P, sdf2d_seg *S, size_t ns, uint32_t *par,
                            hv_sdf2d_stats *st)
{
    size_t n = 0;
    for (size_t k = 0; k < ns; k++) {
        sdf2d_seg s = {sdf2d_uf_find(par, S[k].a), sdf2d_uf_find(par, S[k].b)};
        if (s.a == s.b || sdf2d_seg_len(P, s) == 0) {
            st->zero_length_removed++;
            continue;
        }
        S[n++] = s;
    }
    return n;
}

/* 2. Duplicates (either direction): keep the first. */
static hv_status drop_duplicates(sdf2d_seg *S, size_t *np, hv_sdf2d_stats *st)
{
    const size_t n = *np;
    uint64_t *key = malloc(n * 2 * sizeof *key);
    if (!key && n)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    for (size_t k = 0; k < n; k++) {
        uint32_t lo = S[k].a < S[k].b ? S[k].a : S[k].b, hi = S[k].a ^ S[k].b ^ lo;
        key[2 * k] = ((uint64_t)lo << 32) | hi;
        key[2 * k + 1] = k;
    }
    if (n > 1)
        qsort(key, n, 2 * sizeof *key, by_key);
    uint8_t *drop = calloc(n ? n : 1, 1);
    if (!drop) {
        free(key);
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    }
    for (size_t k = 1; k < n; k++)
        if (key[2 * k] == key[2 * k - 2])
            drop[key[2 * k + 1]] = 1;
    free(key);
    size_t m = 0;
    for (size_t k = 0; k < n; k++) {
        if (drop[k])
            st->duplicates_removed++;
        else
            S[m++] = S[k];
    }
    free(drop);
    *np = m;
    return HV_OK;
}

/* The chains through points of degree 2 of the n segments: deg the CSR
 * offsets of each point's incident segments inc, comp the chain of each
 * segment and flip whether it runs against its chain, the chains' members
 * (mstart, CSR) and the length voting for each direction. */
typedef struct seg_chains {
    uint32_t *deg, *inc, *comp, *queue;
    uint8_t *flip;
    double *vote;
    uint32_t *members, *mstart;
    uint32_t nc;
} seg_chains;

static void seg_chains_free(seg_chains *K)
{
    free(K->deg);
    free(K->inc);
    free(K->comp);
    free(K->queue);
    free(K->flip);
    free(K->vote);
    free(K->members);
    free(K->mstart);
}

/* deg and inc: the segments incident to each point. */
static hv_status link_points(const sdf2d_seg *S, size_t n, size_t np, seg_chains *K)
{
    uint32_t *deg = K->deg;
    for (size_t k = 0; k < n; k++) {
        deg[S[k].a + 1]++;
        deg[S[k].b + 1]++;
    }
    for (size_t v = 0; v < np; v++)
        deg[v + 1] += deg[v]; /* deg is now the CSR offset array */
    uint32_t *fill = calloc(np, sizeof *fill);
    if (!fill)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    for (uint32_t k = 0; k < n; k++) {
        K->inc[deg[S[k].a] + fill[S[k].a]++] = k;
        K->inc[deg[S[k].b] + fill[S[k].b]++] = k;
    }
    free(fill);
    return HV_OK;
}

/* comp and flip: a walk through points of degree 2 from each unvisited
 * segment, orienting each segment met after the one it was reached from. */
static void walk_chains(const sdf2d_seg *S, size_t n, seg_chains *K)
{
    const uint32_t *deg = K->deg, *inc = K->inc;
    uint32_t *comp = K->comp, *queue = K->queue;
    uint8_t *flip = K->flip;
    for (size_t k = 0; k < n; k++)
        comp[k] = UINT32_MAX;
    uint32_t nc = 0;
    for (uint32_t seed = 0; seed < n; seed++) {
        if (comp[seed] != UINT32_MAX)
            continue;
        size_t head = 0, tail = 0;
        comp[seed] = nc;
        queue[tail++] = seed;
        while (head < tail) {
            uint32_t s = queue[head++];
            uint32_t ends[2] = {S[s].a, S[s].b};
            for (int e = 0; e < 2; e++) {
                uint32_t v = ends[e];
                if (deg[v + 1] - deg[v] != 2)
                    continue;
                uint32_t t = inc[deg[v]] == s ? inc[deg[v] + 1] : inc[deg[v]];
                if (comp[t] != UINT32_MAX)
                    continue;
                /* exactly one of the two (as oriented) must end at v */
                int s_ends = (S[s].b == v) ^ flip[s];
                int t_ends_raw = S[t].b == v;
                flip[t] = (uint8_t)(1 ^ s_ends ^ t_ends_raw);
                comp[t] = nc;
                queue[tail++] = t;
            }
        }
        nc++;
    }
    K->nc = nc;
}

/* Vote: each chain keeps the direction most of its length had, and S is
 * turned so; the chains' members listed. */
static hv_status vote_directions(const double *P, sdf2d_seg *S, size_t n, seg_chains *K)
{
    const uint32_t nc = K->nc, *comp = K->comp;
    uint8_t *flip = K->flip;
    K->vote = calloc(2 * (size_t)nc, sizeof *K->vote);
    K->mstart = calloc((size_t)nc + 1, sizeof *K->mstart);
    K->members = malloc(n * sizeof *K->members);
    if (!K->vote || !K->mstart || !K->members)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    double *vote = K->vote;
    uint32_t *mstart = K->mstart;
    for (size_t k = 0; k < n; k++) {
        vote[2 * comp[k] + flip[k]] += sdf2d_seg_len(P, S[k]);
        mstart[comp[k] + 1]++;
    }
    for (uint32_t c = 0; c < nc; c++)
        mstart[c + 1] += mstart[c];
    uint32_t *fill = calloc(nc, sizeof *fill);
    if (!fill)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    for (uint32_t k = 0; k < n; k++)
        K->members[mstart[comp[k]] + fill[comp[k]]++] = k;
    free(fill);
    for (size_t k = 0; k < n; k++)
        if (vote[2 * comp[k] + 1] > vote[2 * comp[k]])
            flip[k] ^= 1;
    for (size_t k = 0; k < n; k++)
        if (flip[k]) {
            uint32_t t = S[k].a;
            S[k].a = S[k].b;
            S[k].b = t;
        }
    return HV_OK;
}

/* 4. Orientation of whole chains (open ones by their mutual coupling, then
 * every loop by nesting): S turned, flip updated. */
static hv_status turn_chains(const double *P, sdf2d_seg *S, size_t n, double tol, seg_chains *K,
                             hv_sdf2d_stats *st)
{
    uint8_t *turn = calloc(K->nc, 1);
    if (!turn)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    hv_status status =
        hv__sdf2d_orient_chains(P, S, K->deg, K->nc, K->mstart, K->members, tol, turn, st);
    if (status != HV_OK) {
        free(turn);
        return status;
    }
    for (size_t k = 0; k < n; k++) {
        K->flip[k] ^= turn[K->comp[k]];
        if (turn[K->comp[k]]) {
            uint32_t t = S[k].a;
            S[k].a = S[k].b;
            S[k].b = t;
        }
    }
    free(turn);
    return HV_OK;
}

/* 3. Chains through points of degree 2; consistent direction by a walk,
 * then by a vote of their length, then whole chains turned. */
static hv_status orient_segments(const double *P, size_t np, sdf2d_seg *S, size_t n, double tol,
                                 hv_sdf2d_stats *st)
{
    hv_status status = HV_OK;
    seg_chains K;
    memset(&K, 0, sizeof K);
    K.deg = calloc(np + 1, sizeof *K.deg);
    K.inc = malloc(2 * n * sizeof *K.inc);
    K.comp = malloc(n * sizeof *K.comp);
    K.queue = malloc(n * sizeof *K.queue);
    K.flip = calloc(n, 1);
    if (!K.deg || !K.inc || !K.comp || !K.queue || !K.flip) {
        status = hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
        goto out;
    }
    if ((status = link_points(S, n, np, &K)) != HV_OK)
        goto out;
    walk_chains(S, n, &K);
    st->chains = K.nc;
    if ((status = vote_directions(P, S, n, &K)) != HV_OK ||
        (status = turn_chains(P, S, n, tol, &K, st)) != HV_OK)
        goto out;
    /* flip[k] now says whether segment k runs against its input direction */
    for (size_t k = 0; k < n; k++)
        st->segments_flipped += K.flip[k];
out:
    seg_chains_free(&K);
    return status;
}

/* Welds, drops zero-length and duplicate segments, orients chains (see
 * sdf2d_internal.h). */
hv_status hv__sdf2d_repair(const double *P, size_t np, sdf2d_seg **Sp, size_t *ns, double tol,
                           double h, hv_sdf2d_stats *st)
{
    hv_status status = HV_OK;
    uint32_t *par = malloc(np * sizeof *par);
    if (!par)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    for (uint32_t i = 0; i < np; i++)
        par[i] = i;
    if (tol > 0 && (status = weld_points(P, np, tol, par, &st->points_welded)) != HV_OK)
        goto out;
    size_t n = weld_segments(P, *Sp, *ns, par, st);
    /* 1b. Overlaps: split at points lying on other segments. */
    if (tol > 0 && n > 0 &&
        (status = split_overlaps(P, np, Sp, &n, tol, h, &st->segments_split)) != HV_OK)
        goto out;
    if ((status = drop_duplicates(*Sp, &n, st)) != HV_OK)
        goto out;
    *ns = n;
    if (n > 0)
        status = orient_segments(P, np, *Sp, n, tol, st);
out:
    free(par);
    return status;
}
