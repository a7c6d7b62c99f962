/*
 * Curve repair, last step: which way each chain of segments runs (open chains
 * by their mutual coupling, then every loop by its nesting depth), for
 * hv__sdf2d_repair in sdf2d_repair.c. The nesting is found through a
 * bounding-volume hierarchy that gives the same depths as testing every pair
 * of loops (hv__sdf2d_all_pairs, for the tests).
 */
#include "core/error.h"
#include "sdf2d_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Most units per leaf of the nesting index. */
#define SDF2_BVH_LEAF 8

int hv__sdf2d_all_pairs = 0;

/*
 * Orientation of chains, after each chain was made consistent along itself.
 *
 * Open chains: the generalized winding number of an open chain has the
 * gradient of a pair of point vortices at its ends, so the coupling of two
 * chains c, d (the flux of one's winding-number gradient through the other)
 * depends on their end points only:
 *     J(c, d) = log( |e_c - e_d| |s_c - s_d| / (|s_c - e_d| |e_c - s_d|) ),
 * symmetric, positive for chains that continue each other head to tail or face
 * each other antiparallel (two sides of one shape), negative for the reverse.
 * Single chains, then groups of strongly coupled chains (J > 2), are reversed
 * while that raises the total coupling (a local search that always ends).
 *
 * Units (cycles, and groups of open chains): counter-clockwise (positive
 * shoelace sum) when a point of the unit lies inside an even number of other
 * units, clockwise when odd; "inside" is |generalized winding number| > 1/2,
 * which holds for loops with gaps too.
 */
typedef struct chain_end {
    double s[2], e[2];
} chain_end;

static double coupling(const chain_end *c, const chain_end *d, double eps)
{
    double a = fmax(hypot(c->e[0] - d->e[0], c->e[1] - d->e[1]), eps);
    double b = fmax(hypot(c->s[0] - d->s[0], c->s[1] - d->s[1]), eps);
    double x = fmax(hypot(c->s[0] - d->e[0], c->s[1] - d->e[1]), eps);
    double y = fmax(hypot(c->e[0] - d->s[0], c->e[1] - d->s[1]), eps);
    return log(a * b / (x * y));
}

static void reverse_end(chain_end *c)
{
    for (int a = 0; a < 2; a++) {
        double t = c->s[a];
        c->s[a] = c->e[a];
        c->e[a] = t;
    }
}

/* Generalized winding number at (x, y) of the segments ids[0..n) with
 * orientation sign `sgn` (+1 as stored, -1 reversed). */
static double winding(const double *P, const sdf2d_seg *S, const uint32_t *ids, size_t n,
                      double sgn, double x, double y)
{
    double w = 0;
    for (size_t k = 0; k < n; k++) {
        const double *p = P + 2 * S[ids[k]].a, *q = P + 2 * S[ids[k]].b;
        double ax = p[0] - x, ay = p[1] - y, bx = q[0] - x, by = q[1] - y;
        w += atan2(ax * by - ay * bx, ax * bx + ay * by);
    }
    return sgn * w / (2 * M_PI);
}

/*
 * Nesting of units through a bounding-volume hierarchy of their boxes: the
 * winding of unit v at the point of unit u is summed only where v's box, grown
 * as below, holds the point. The windings skipped are ones that cannot pass
 * |w| > 1/2, so the depths are those of testing every pair:
 *  - one chain (path or cycle): seen from outside its box it lies in an open
 *    half-plane, so its angles add up to the angle between its ends, below pi.
 *    Growing the box by 1e-3 of its size keeps |w| < 1/2 - 2e-4, far beyond
 *    the rounding of the sum;
 *  - a group of open chains: closed by gaps from each chain's end to the next
 *    one's start (total length G), it has winding 0 outside the box, so |w| is
 *    that of the gaps, at most G / (2 pi d) at distance d. Growing by G/3 as
 *    well keeps |w| < 3 / (2 pi) < 0.48.
 */
typedef struct bvh_node {
    double lo[2], hi[2];
    uint32_t first, count; /* leaf: items first .. first+count-1; 0 for inner nodes */
    uint32_t skip;         /* the node after this subtree */
} bvh_node;

static uint32_t spread16(uint32_t x)
{
    x &= 0xffff;
    x = (x | x << 8) & 0x00ff00ff;
    x = (x | x << 4) & 0x0f0f0f0f;
    x = (x | x << 2) & 0x33333333;
    return (x | x << 1) & 0x55555555;
}

/* Median split of items lo .. hi-1 (in Morton order), nodes in preorder. */
static void bvh_build(bvh_node *nd, uint32_t *nn, const double *box, const uint32_t *ids,
                      uint32_t lo, uint32_t hi)
{
    uint32_t i = (*nn)++;
    if (hi - lo <= SDF2_BVH_LEAF) {
        nd[i].first = lo;
        nd[i].count = hi - lo;
        nd[i].lo[0] = nd[i].lo[1] = INFINITY;
        nd[i].hi[0] = nd[i].hi[1] = -INFINITY;
        for (uint32_t k = lo; k < hi; k++)
            for (int a = 0; a < 2; a++) {
                nd[i].lo[a] = fmin(nd[i].lo[a], box[4 * ids[k] + a]);
                nd[i].hi[a] = fmax(nd[i].hi[a], box[4 * ids[k] + 2 + a]);
            }
    } else {
        uint32_t mid = lo + (hi - lo) / 2;
        bvh_build(nd, nn, box, ids, lo, mid);
        uint32_t r = *nn;
        bvh_build(nd, nn, box, ids, mid, hi);
        nd[i].first = nd[i].count = 0;
        for (int a = 0; a < 2; a++) {
            nd[i].lo[a] = fmin(nd[i + 1].lo[a], nd[r].lo[a]);
            nd[i].hi[a] = fmax(nd[i + 1].hi[a], nd[r].hi[a]);
        }
    }
    nd[i].skip = *nn;
}

/* Winding of unit v, as oriented by segturn, at (x, y). */
static double unit_winding(const double *P, const sdf2d_seg *S, const uint32_t *ustart,
                           const uint32_t *useg, const uint8_t *segturn, uint32_t v, double x,
                           double y)
{
    double w = 0;
    for (uint32_t k = ustart[v]; k < ustart[v + 1]; k++)
        w += winding(P, S, &useg[k], 1, segturn[useg[k]] ? -1 : 1, x, y);
    return w;
}

/* uturn[u] = 1 where unit u runs against its nesting (see orient_chains). */
static hv_status nesting_turns(const double *P, const sdf2d_seg *S, uint32_t nu,
                               const uint32_t *ustart, const uint32_t *useg, const uint8_t *segturn,
                               const double *upt, const double *uarea, const double *utot,
                               const double *ugap, uint8_t *uturn, size_t *tests)
{
    uint32_t nv = 0; /* units that can hold others: two segments or more */
    for (uint32_t v = 0; v < nu; v++)
        nv += ustart[v + 1] - ustart[v] >= 2;
    double *box = malloc(4 * (nu ? nu : 1) * sizeof *box);
    uint64_t *key = malloc((nv ? nv : 1) * sizeof *key);
    uint32_t *ids = malloc((nv ? nv : 1) * sizeof *ids);
    bvh_node *nd = malloc((2 * (size_t)nv / (SDF2_BVH_LEAF / 2) + 2) * sizeof *nd);
    if (!box || !key || !ids || !nd) {
        free(box);
        free(key);
        free(ids);
        free(nd);
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    }
    double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
    for (uint32_t v = 0; v < nu; v++) {
        if (ustart[v + 1] - ustart[v] < 2)
            continue;
        double *b = box + 4 * v;
        b[0] = b[1] = INFINITY;
        b[2] = b[3] = -INFINITY;
        for (uint32_t k = ustart[v]; k < ustart[v + 1]; k++)
            for (int a = 0; a < 2; a++) {
                double p = P[2 * S[useg[k]].a + a], q = P[2 * S[useg[k]].b + a];
                b[a] = fmin(b[a], fmin(p, q));
                b[2 + a] = fmax(b[2 + a], fmax(p, q));
            }
        double grow = 1e-3 * fmax(b[2] - b[0], b[3] - b[1]);
        if (ugap[v] >= 0)
            grow = fmax(grow, ugap[v] / 3);
        for (int a = 0; a < 2; a++) {
            b[a] -= grow;
            b[2 + a] += grow;
            lo[a] = fmin(lo[a], 0.5 * (b[a] + b[2 + a]));
            hi[a] = fmax(hi[a], 0.5 * (b[a] + b[2 + a]));
        }
    }
    /* Morton order of the box centres (ties by unit), then a median split. */
    uint32_t n = 0;
    for (uint32_t v = 0; v < nu; v++) {
        if (ustart[v + 1] - ustart[v] < 2)
            continue;
        uint32_t q[2];
        for (int a = 0; a < 2; a++) {
            double t = hi[a] > lo[a]
                           ? (0.5 * (box[4 * v + a] + box[4 * v + 2 + a]) - lo[a]) / (hi[a] - lo[a])
                           : 0;
            q[a] = (uint32_t)(fmin(fmax(t, 0), 1) * 65535.0);
        }
        key[n++] = (uint64_t)(spread16(q[0]) | spread16(q[1]) << 1) << 32 | v;
    }
    qsort(key, n, sizeof *key, sdf2d_by_u64);
    for (uint32_t k = 0; k < n; k++)
        ids[k] = (uint32_t)key[k];
    uint32_t nn = 0;
    if (n)
        bvh_build(nd, &nn, box, ids, 0, n);
    size_t count = 0;
    for (uint32_t u = 0; u < nu; u++) {
        /* a straight or nearly straight unit has no side to prefer */
        if (!(fabs(uarea[u]) > 1e-6 * utot[u] * utot[u]))
            continue;
        double x = upt[2 * u], y = upt[2 * u + 1];
        int depth = 0;
        for (uint32_t k = 0; k < nn;) {
            const bvh_node *b = &nd[k];
            if (!hv__sdf2d_all_pairs &&
                (x < b->lo[0] || x > b->hi[0] || y < b->lo[1] || y > b->hi[1])) {
                k = b->skip;
                continue;
            }
            for (uint32_t j = b->first; j < b->first + b->count; j++) {
                uint32_t v = ids[j];
                const double *vb = box + 4 * v;
                if (v == u ||
                    (!hv__sdf2d_all_pairs && (x < vb[0] || x > vb[2] || y < vb[1] || y > vb[3])))
                    continue;
                depth += fabs(unit_winding(P, S, ustart, useg, segturn, v, x, y)) > 0.5;
                count++;
            }
            k = b->count ? b->skip : k + 1;
        }
        uturn[u] = (uint8_t)((uarea[u] > 0) != (depth % 2 == 0));
    }
    *tests += count;
    free(box);
    free(key);
    free(ids);
    free(nd);
    return HV_OK;
}

/* The chains being oriented, and what the open ones among them tell. */
typedef struct chains {
    const double *P;
    const sdf2d_seg *S;
    uint32_t nc;
    const uint32_t *mstart, *members;
    uint8_t *turn;  /* turn[c] ^= 1 reverses chain c */
    chain_end *ce;  /* the ends of each chain, following its turns */
    uint32_t *open; /* the open chains with both ends, open[0..m) */
    uint32_t m;
    double eps;    /* the least distance the coupling sees */
    uint32_t *gid; /* group of each open chain, ng groups */
    uint32_t ng;
} chains;

/* The ends of every chain, the cycles counted; the open chains listed. */
static void find_open_chains(chains *C, const uint32_t *deg, uint8_t *is_cycle, hv_sdf2d_stats *st)
{
    const uint32_t *mstart = C->mstart;
    chain_end *ce = C->ce;
    uint32_t m = 0;
    for (uint32_t c = 0; c < C->nc; c++) {
        int cyc = 1;
        ce[c].s[0] = ce[c].s[1] = ce[c].e[0] = ce[c].e[1] = NAN;
        for (uint32_t k = mstart[c]; k < mstart[c + 1]; k++) {
            sdf2d_seg s = C->S[C->members[k]];
            int da = deg[s.a + 1] - deg[s.a] == 2, db = deg[s.b + 1] - deg[s.b] == 2;
            cyc &= da && db;
            if (!da && isnan(ce[c].s[0]))
                memcpy(ce[c].s, C->P + 2 * s.a, sizeof ce[c].s);
            if (!db && isnan(ce[c].e[0]))
                memcpy(ce[c].e, C->P + 2 * s.b, sizeof ce[c].e);
        }
        is_cycle[c] = (uint8_t)(cyc && mstart[c + 1] - mstart[c] >= 3);
        st->cycles += is_cycle[c];
        if (!is_cycle[c] && !isnan(ce[c].s[0]) && !isnan(ce[c].e[0]))
            C->open[m++] = c;
    }
    C->m = m;
}

/* Single-chain local search on the coupling energy. */
static hv_status flip_chains(chains *C)
{
    const uint32_t m = C->m, *open = C->open;
    chain_end *ce = C->ce;
    double *acc = calloc(m ? m : 1, sizeof *acc);
    if (!acc)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    for (uint32_t i = 0; i < m; i++)
        for (uint32_t j = i + 1; j < m; j++) {
            double J = coupling(&ce[open[i]], &ce[open[j]], C->eps);
            acc[i] += J;
            acc[j] += J;
        }
    for (size_t iter = 0; iter < 10 * (size_t)m + 10; iter++) {
        uint32_t worst = UINT32_MAX;
        double low = -1e-9;
        for (uint32_t i = 0; i < m; i++)
            if (acc[i] < low) {
                low = acc[i];
                worst = i;
            }
        if (worst == UINT32_MAX)
            break;
        for (uint32_t j = 0; j < m; j++)
            if (j != worst)
                acc[j] -= 2 * coupling(&ce[open[worst]], &ce[open[j]], C->eps);
        acc[worst] = -acc[worst];
        reverse_end(&ce[open[worst]]);
        C->turn[open[worst]] ^= 1;
    }
    free(acc);
    return HV_OK;
}

/* Groups of strongly coupled open chains (J > 2, transitively): C->gid. */
static hv_status group_chains(chains *C)
{
    const uint32_t m = C->m, *open = C->open;
    uint32_t *gpar = malloc((m ? m : 1) * sizeof *gpar);
    C->gid = malloc((m ? m : 1) * sizeof *C->gid);
    if (!gpar || !C->gid) {
        free(gpar);
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    }
    for (uint32_t i = 0; i < m; i++)
        gpar[i] = i;
    for (uint32_t i = 0; i < m; i++)
        for (uint32_t j = i + 1; j < m; j++)
            if (coupling(&C->ce[open[i]], &C->ce[open[j]], C->eps) > 2) {
                uint32_t a = sdf2d_uf_find(gpar, i), b = sdf2d_uf_find(gpar, j);
                if (a != b)
                    gpar[a > b ? a : b] = a < b ? a : b;
            }
    uint32_t ng = 0, *gid = C->gid;
    for (uint32_t i = 0; i < m; i++)
        gid[i] = sdf2d_uf_find(gpar, i) == i ? ng++ : UINT32_MAX;
    for (uint32_t i = 0; i < m; i++)
        gid[i] = gid[sdf2d_uf_find(gpar, i)];
    C->ng = ng;
    free(gpar);
    return HV_OK;
}

/* The local search of flip_chains over whole groups (up to 4096 of them). */
static hv_status flip_groups(chains *C)
{
    const uint32_t m = C->m, ng = C->ng, *open = C->open, *gid = C->gid;
    if (!(ng > 1 && ng <= 4096))
        return HV_OK;
    double *G = calloc((size_t)ng * ng, sizeof *G);
    if (!G)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    for (uint32_t i = 0; i < m; i++)
        for (uint32_t j = i + 1; j < m; j++)
            if (gid[i] != gid[j]) {
                double J = coupling(&C->ce[open[i]], &C->ce[open[j]], C->eps);
                G[(size_t)gid[i] * ng + gid[j]] += J;
                G[(size_t)gid[j] * ng + gid[i]] += J;
            }
    for (size_t iter = 0; iter < 10 * (size_t)ng; iter++) {
        uint32_t worst = UINT32_MAX;
        double low = -1e-9;
        for (uint32_t g = 0; g < ng; g++) {
            double a = 0;
            for (uint32_t h = 0; h < ng; h++)
                a += G[(size_t)g * ng + h];
            if (a < low) {
                low = a;
                worst = g;
            }
        }
        if (worst == UINT32_MAX)
            break;
        for (uint32_t h = 0; h < ng; h++) {
            G[(size_t)worst * ng + h] = -G[(size_t)worst * ng + h];
            G[(size_t)h * ng + worst] = -G[(size_t)h * ng + worst];
        }
        for (uint32_t i = 0; i < m; i++)
            if (gid[i] == worst) {
                C->turn[open[i]] ^= 1;
                reverse_end(&C->ce[open[i]]);
            }
    }
    free(G);
    return HV_OK;
}

/* The units of the nesting test, each with its segments (useg, by unit),
 * shoelace sum, total length and a point on its longest segment. */
typedef struct units {
    uint32_t nu;
    uint32_t *unit; /* unit of each chain */
    uint32_t *ustart, *useg;
    uint8_t *segturn; /* 1 where a segment runs against S (S is not yet turned) */
    double *upt, *ulen, *uarea, *utot;
    double *ugap; /* the gaps closing a group of open chains; < 0 for one chain */
    uint32_t *ufirst, *ulast;
    uint8_t *uturn;
} units;

static void units_free(units *U)
{
    free(U->ugap);
    free(U->ufirst);
    free(U->ulast);
    free(U->segturn);
    free(U->ustart);
    free(U->useg);
    free(U->utot);
    free(U->upt);
    free(U->ulen);
    free(U->uarea);
    free(U->uturn);
}

/* Units: each cycle, each group of open chains, each other chain alone. */
static void assign_units(const chains *C, units *U)
{
    for (uint32_t c = 0; c < C->nc; c++)
        U->unit[c] = UINT32_MAX;
    for (uint32_t i = 0; i < C->m; i++)
        U->unit[C->open[i]] = C->gid[i];
    uint32_t nu = C->ng;
    for (uint32_t c = 0; c < C->nc; c++)
        if (U->unit[c] == UINT32_MAX)
            U->unit[c] = nu++;
    U->nu = nu;
}

/* The segments of each unit (sorted by unit), and which way each runs. */
static hv_status unit_segments(const chains *C, units *U)
{
    const uint32_t nc = C->nc, nu = U->nu, *mstart = C->mstart, *members = C->members;
    const uint32_t *unit = U->unit;
    U->ustart = calloc((size_t)nu + 1, sizeof *U->ustart);
    U->useg = malloc((mstart[nc] ? mstart[nc] : 1) * sizeof *U->useg);
    U->upt = malloc(2 * (nu ? nu : 1) * sizeof *U->upt);
    U->ulen = calloc(nu ? nu : 1, sizeof *U->ulen);
    U->uarea = calloc(nu ? nu : 1, sizeof *U->uarea);
    U->utot = calloc(nu ? nu : 1, sizeof *U->utot);
    U->uturn = calloc(nu ? nu : 1, 1);
    if (!U->ustart || !U->useg || !U->upt || !U->ulen || !U->uarea || !U->utot || !U->uturn)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    uint32_t *ustart = U->ustart;
    for (uint32_t c = 0; c < nc; c++)
        ustart[unit[c] + 1] += mstart[c + 1] - mstart[c];
    for (uint32_t u = 0; u < nu; u++)
        ustart[u + 1] += ustart[u];
    uint32_t *fill = calloc(nu ? nu : 1, sizeof *fill);
    if (!fill)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    for (uint32_t c = 0; c < nc; c++)
        for (uint32_t k = mstart[c]; k < mstart[c + 1]; k++)
            U->useg[ustart[unit[c]] + fill[unit[c]]++] = members[k];
    free(fill);
    /* S is not yet reversed by turn: signs carry it. */
    size_t nseg = mstart[nc];
    U->segturn = calloc(nseg ? nseg : 1, 1);
    if (!U->segturn)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    for (uint32_t c = 0; c < nc; c++)
        for (uint32_t k = mstart[c]; k < mstart[c + 1]; k++)
            U->segturn[members[k]] = C->turn[c];
    return HV_OK;
}

/* Per unit: the shoelace sum, the length, the middle of the longest segment. */
static void unit_shapes(const chains *C, units *U)
{
    const double *P = C->P;
    const sdf2d_seg *S = C->S;
    for (uint32_t u = 0; u < U->nu; u++) {
        /* shoelace about a point of the unit, so that open pieces do not
         * depend on where the origin is */
        const double *o = P + 2 * S[U->useg[U->ustart[u]]].a;
        for (uint32_t k = U->ustart[u]; k < U->ustart[u + 1]; k++) {
            uint32_t id = U->useg[k];
            const double *p = P + 2 * S[id].a, *q = P + 2 * S[id].b;
            double sg = U->segturn[id] ? -1 : 1;
            U->uarea[u] += sg * ((p[0] - o[0]) * (q[1] - o[1]) - (q[0] - o[0]) * (p[1] - o[1]));
            double L = hypot(q[0] - p[0], q[1] - p[1]);
            U->utot[u] += L;
            if (L > U->ulen[u]) {
                U->ulen[u] = L;
                U->upt[2 * u] = 0.5 * (p[0] + q[0]);
                U->upt[2 * u + 1] = 0.5 * (p[1] + q[1]);
            }
        }
    }
}

/* Gaps closing each group of open chains, end of one to start of the next
 * (ce follows the turns); ugap < 0 marks units of a single chain. */
static hv_status unit_gaps(const chains *C, units *U)
{
    const uint32_t nu = U->nu;
    const chain_end *ce = C->ce;
    U->ugap = malloc((nu ? nu : 1) * sizeof *U->ugap);
    U->ufirst = malloc((nu ? nu : 1) * sizeof *U->ufirst);
    U->ulast = malloc((nu ? nu : 1) * sizeof *U->ulast);
    if (!U->ugap || !U->ufirst || !U->ulast)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    double *ugap = U->ugap;
    for (uint32_t u = 0; u < nu; u++) {
        ugap[u] = -1;
        U->ufirst[u] = UINT32_MAX;
    }
    for (uint32_t i = 0; i < C->m; i++) {
        uint32_t c = C->open[i], u = U->unit[c];
        if (U->ufirst[u] == UINT32_MAX) {
            U->ufirst[u] = c;
        } else {
            const double *e = ce[U->ulast[u]].e;
            ugap[u] = fmax(ugap[u], 0) + hypot(ce[c].s[0] - e[0], ce[c].s[1] - e[1]);
        }
        U->ulast[u] = c;
    }
    for (uint32_t u = 0; u < nu; u++)
        if (ugap[u] >= 0) {
            const double *e = ce[U->ulast[u]].e, *s0 = ce[U->ufirst[u]].s;
            ugap[u] += hypot(s0[0] - e[0], s0[1] - e[1]);
        }
    return HV_OK;
}

/* Every unit turned to agree with its nesting depth (see the top). */
static hv_status orient_units(const chains *C, uint32_t *unit, hv_sdf2d_stats *st)
{
    units U;
    memset(&U, 0, sizeof U);
    U.unit = unit;
    assign_units(C, &U);
    hv_status status = unit_segments(C, &U);
    if (status == HV_OK) {
        unit_shapes(C, &U);
        status = unit_gaps(C, &U);
    }
    if (status == HV_OK)
        status = nesting_turns(C->P, C->S, U.nu, U.ustart, U.useg, U.segturn, U.upt, U.uarea,
                               U.utot, U.ugap, U.uturn, &st->nesting_tests);
    if (status == HV_OK)
        for (uint32_t c = 0; c < C->nc; c++)
            C->turn[c] ^= U.uturn[unit[c]];
    units_free(&U);
    return status;
}

hv_status hv__sdf2d_orient_chains(const double *P, sdf2d_seg *S, const uint32_t *deg, uint32_t nc,
                                  const uint32_t *mstart, const uint32_t *members, double tol,
                                  uint8_t *turn, hv_sdf2d_stats *st)
{
    hv_status status = HV_OK;
    chains C = {P, S, nc, mstart, members, turn, NULL, NULL, 0, fmax(tol, 1e-12), NULL, 0};
    uint8_t *is_cycle = calloc(nc, 1);
    C.open = malloc(nc * sizeof *C.open);
    uint32_t *unit = malloc(nc * sizeof *unit);
    C.ce = malloc(nc * sizeof *C.ce);
    if (!is_cycle || !C.open || !unit || !C.ce) {
        status = hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
        goto out;
    }
    find_open_chains(&C, deg, is_cycle, st);
    if ((status = flip_chains(&C)) || (status = group_chains(&C)) || (status = flip_groups(&C)))
        goto out;
    status = orient_units(&C, unit, st);
out:
    free(is_cycle);
    free(C.open);
    free(unit);
    free(C.ce);
    free(C.gid);
    return status;
}
