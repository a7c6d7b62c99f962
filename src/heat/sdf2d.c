/*
 * The signed heat method for 2D curves on a cell-centred grid (Feng & Crane
 * 2024), the 2D sibling of sdf.c with the same grid choices (docs/METHOD.md,
 * "Discretization", "Signed heat method"):
 * segment normals splatted bilinearly onto cell centres, one backward-Euler
 * diffusion per level (t = (t_scale h)^2, x16 per level until the field reaches
 * across the block), the diffused vectors averaged and normalized on cell faces
 * (MAC), div X, the Neumann Poisson solve whose Laplacian is exactly div(grad),
 * and a shift that puts the length-weighted mean of phi on the curves to zero.
 * By default |phi| is then replaced by the exact distance to the segments.
 *
 * Curve repair (see heatvox/curves.h) plays the part of the mesh repair:
 * without it, two copies of a segment drawn in opposite directions cancel,
 * and a flipped piece turns the sign around it.
 */
#include "heatvox/curves.h"
#include "core/error.h"
#include "heat/sdf2d_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Faces whose diffused vector is below this many times the solver's error
 * bound count as decayed (as in sdf.c). */
#define SDF2_NOISE_FACTOR 4.0
/* Rasterization radius of the exact distance, in cells. */
#define SDF2_BAND 2.0
#define SDF2_MAX_LEVELS 9
/* Most units per leaf of the nesting index. */
#define SDF2_BVH_LEAF 8

int hv_sdf2d_all_pairs = 0;

void hv_sdf2d_opts_default(hv_sdf2d_opts *o)
{
    memset(o, 0, sizeof *o);
    o->res = 256;
    o->pad = 8;
    o->t_scale = 1.0;
    o->repair = 1;
    o->weld_tol = 1e-3;
    o->backend = HV_BACKEND_AUTO;
    o->tol = 1e-10;
}

static hv_status check_opts(const hv_sdf2d_opts *o)
{
    if (!(o->voxel_size >= 0) || !isfinite(o->voxel_size))
        return hv_error(HV_ERR_INVALID_ARG, "sdf2d: voxel size must be positive and finite, got %g",
                        o->voxel_size);
    if (o->voxel_size == 0 && !o->use_bbox && o->res <= 2 * o->pad)
        return hv_error(HV_ERR_INVALID_ARG,
                        "sdf2d: resolution %d leaves no cells inside a padding of %d on each side",
                        o->res, o->pad);
    if (o->voxel_size == 0 && o->res < 2)
        return hv_error(HV_ERR_INVALID_ARG, "sdf2d: resolution must be at least 2, got %d", o->res);
    if (o->pad < 0)
        return hv_error(HV_ERR_INVALID_ARG, "sdf2d: padding must be >= 0 cells, got %d", o->pad);
    if (!(o->t_scale > 0) || !(o->t_scale <= 1e4))
        return hv_error(HV_ERR_INVALID_ARG, "sdf2d: t scale must be in (0, 1e4], got %g",
                        o->t_scale);
    if (!(o->weld_tol >= 0) || !(o->weld_tol < 1))
        return hv_error(HV_ERR_INVALID_ARG, "sdf2d: weld tolerance must be in [0, 1), got %g",
                        o->weld_tol);
    if (!(o->tol >= 1e-12 && o->tol < 1))
        return hv_error(HV_ERR_INVALID_ARG, "sdf2d: tolerance must be in [1e-12, 1), got %g",
                        o->tol);
    if (o->use_bbox)
        for (int a = 0; a < 2; a++)
            if (!isfinite(o->bbox[a]) || !isfinite(o->bbox[a + 2]) ||
                !(o->bbox[a + 2] > o->bbox[a]))
                return hv_error(HV_ERR_INVALID_ARG, "sdf2d: bounding box is empty along %c",
                                "xy"[a]);
    return HV_OK;
}

/* ---- segments and repair ---- */

typedef struct seg2 {
    uint32_t a, b;
} seg2;

static uint32_t uf_find(uint32_t *p, uint32_t x)
{
    while (p[x] != x) {
        p[x] = p[p[x]];
        x = p[x];
    }
    return x;
}

static int by_key(const void *a, const void *b)
{
    const uint64_t *x = a, *y = b;
    return (x[0] > y[0]) - (x[0] < y[0]) ? (x[0] > y[0]) - (x[0] < y[0])
                                         : (x[1] > y[1]) - (x[1] < y[1]);
}

static int by_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

static double seg_len(const double *P, seg2 s)
{
    return hypot(P[2 * s.b] - P[2 * s.a], P[2 * s.b + 1] - P[2 * s.a + 1]);
}

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
static double winding(const double *P, const seg2 *S, const uint32_t *ids, size_t n, double sgn,
                      double x, double y)
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
static double unit_winding(const double *P, const seg2 *S, const uint32_t *ustart,
                           const uint32_t *useg, const uint8_t *segturn, uint32_t v, double x,
                           double y)
{
    double w = 0;
    for (uint32_t k = ustart[v]; k < ustart[v + 1]; k++)
        w += winding(P, S, &useg[k], 1, segturn[useg[k]] ? -1 : 1, x, y);
    return w;
}

/* uturn[u] = 1 where unit u runs against its nesting (see orient_chains). */
static hv_status nesting_turns(const double *P, const seg2 *S, uint32_t nu,
                               const uint32_t *ustart, const uint32_t *useg,
                               const uint8_t *segturn, const double *upt, const double *uarea,
                               const double *utot, const double *ugap, uint8_t *uturn,
                               size_t *tests)
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
        return hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
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
            double t = hi[a] > lo[a] ? (0.5 * (box[4 * v + a] + box[4 * v + 2 + a]) - lo[a]) /
                                           (hi[a] - lo[a])
                                     : 0;
            q[a] = (uint32_t)(fmin(fmax(t, 0), 1) * 65535.0);
        }
        key[n++] = (uint64_t)(spread16(q[0]) | spread16(q[1]) << 1) << 32 | v;
    }
    qsort(key, n, sizeof *key, by_u64);
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
            if (!hv_sdf2d_all_pairs &&
                (x < b->lo[0] || x > b->hi[0] || y < b->lo[1] || y > b->hi[1])) {
                k = b->skip;
                continue;
            }
            for (uint32_t j = b->first; j < b->first + b->count; j++) {
                uint32_t v = ids[j];
                const double *vb = box + 4 * v;
                if (v == u || (!hv_sdf2d_all_pairs &&
                               (x < vb[0] || x > vb[2] || y < vb[1] || y > vb[3])))
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

static hv_status orient_chains(const double *P, seg2 *S, const uint32_t *deg, uint32_t nc,
                               const uint32_t *mstart, const uint32_t *members, double tol,
                               uint8_t *turn, hv_sdf2d_stats *st)
{
    hv_status status = HV_OK;
    uint8_t *is_cycle = calloc(nc, 1);
    uint32_t *open = malloc(nc * sizeof *open), *unit = malloc(nc * sizeof *unit);
    chain_end *ce = malloc(nc * sizeof *ce);
    double *acc = NULL, *G = NULL;
    uint32_t *gpar = NULL, *gid = NULL;
    uint8_t *segturn = NULL;
    if (!is_cycle || !open || !unit || !ce) {
        status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
        goto out;
    }
    uint32_t m = 0;
    for (uint32_t c = 0; c < nc; c++) {
        int cyc = 1;
        ce[c].s[0] = ce[c].s[1] = ce[c].e[0] = ce[c].e[1] = NAN;
        for (uint32_t k = mstart[c]; k < mstart[c + 1]; k++) {
            seg2 s = S[members[k]];
            int da = deg[s.a + 1] - deg[s.a] == 2, db = deg[s.b + 1] - deg[s.b] == 2;
            cyc &= da && db;
            if (!da && isnan(ce[c].s[0]))
                memcpy(ce[c].s, P + 2 * s.a, sizeof ce[c].s);
            if (!db && isnan(ce[c].e[0]))
                memcpy(ce[c].e, P + 2 * s.b, sizeof ce[c].e);
        }
        is_cycle[c] = (uint8_t)(cyc && mstart[c + 1] - mstart[c] >= 3);
        st->cycles += is_cycle[c];
        if (!is_cycle[c] && !isnan(ce[c].s[0]) && !isnan(ce[c].e[0]))
            open[m++] = c;
    }
    /* Single-chain local search on the coupling energy. */
    double eps = fmax(tol, 1e-12);
    acc = calloc(m ? m : 1, sizeof *acc);
    if (!acc) {
        status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
        goto out;
    }
    for (uint32_t i = 0; i < m; i++)
        for (uint32_t j = i + 1; j < m; j++) {
            double J = coupling(&ce[open[i]], &ce[open[j]], eps);
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
                acc[j] -= 2 * coupling(&ce[open[worst]], &ce[open[j]], eps);
        acc[worst] = -acc[worst];
        reverse_end(&ce[open[worst]]);
        turn[open[worst]] ^= 1;
    }
    /* Groups of strongly coupled chains, then the same search over groups. */
    gpar = malloc((m ? m : 1) * sizeof *gpar);
    gid = malloc((m ? m : 1) * sizeof *gid);
    if (!gpar || !gid) {
        status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
        goto out;
    }
    for (uint32_t i = 0; i < m; i++)
        gpar[i] = i;
    for (uint32_t i = 0; i < m; i++)
        for (uint32_t j = i + 1; j < m; j++)
            if (coupling(&ce[open[i]], &ce[open[j]], eps) > 2) {
                uint32_t a = uf_find(gpar, i), b = uf_find(gpar, j);
                if (a != b)
                    gpar[a > b ? a : b] = a < b ? a : b;
            }
    uint32_t ng = 0;
    for (uint32_t i = 0; i < m; i++)
        gid[i] = uf_find(gpar, i) == i ? ng++ : UINT32_MAX;
    for (uint32_t i = 0; i < m; i++)
        gid[i] = gid[uf_find(gpar, i)];
    if (ng > 1 && ng <= 4096) {
        G = calloc((size_t)ng * ng, sizeof *G);
        if (!G) {
            status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
            goto out;
        }
        for (uint32_t i = 0; i < m; i++)
            for (uint32_t j = i + 1; j < m; j++)
                if (gid[i] != gid[j]) {
                    double J = coupling(&ce[open[i]], &ce[open[j]], eps);
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
                    turn[open[i]] ^= 1;
                    reverse_end(&ce[open[i]]);
                }
        }
    }
    /* Units: each cycle, each group of open chains, each other chain alone. */
    uint32_t nu = 0;
    for (uint32_t c = 0; c < nc; c++)
        unit[c] = UINT32_MAX;
    for (uint32_t i = 0; i < m; i++)
        unit[open[i]] = gid[i];
    nu = ng;
    for (uint32_t c = 0; c < nc; c++)
        if (unit[c] == UINT32_MAX)
            unit[c] = nu++;
    /* Per unit: its segments (sorted by unit), shoelace sum, a point on it. */
    uint32_t *ustart = calloc((size_t)nu + 1, sizeof *ustart);
    uint32_t *useg = malloc((mstart[nc] ? mstart[nc] : 1) * sizeof *useg);
    double *upt = malloc(2 * (nu ? nu : 1) * sizeof *upt);
    double *ulen = calloc(nu ? nu : 1, sizeof *ulen), *uarea = calloc(nu ? nu : 1, sizeof *uarea);
    double *utot = calloc(nu ? nu : 1, sizeof *utot);
    uint8_t *uturn = calloc(nu ? nu : 1, 1);
    double *ugap = NULL;
    uint32_t *ufirst = NULL, *ulast = NULL;
    if (!ustart || !useg || !upt || !ulen || !uarea || !utot || !uturn) {
        status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
        goto units_out;
    }
    for (uint32_t c = 0; c < nc; c++)
        ustart[unit[c] + 1] += mstart[c + 1] - mstart[c];
    for (uint32_t u = 0; u < nu; u++)
        ustart[u + 1] += ustart[u];
    {
        uint32_t *fill = calloc(nu ? nu : 1, sizeof *fill);
        if (!fill) {
            status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
            goto units_out;
        }
        for (uint32_t c = 0; c < nc; c++)
            for (uint32_t k = mstart[c]; k < mstart[c + 1]; k++)
                useg[ustart[unit[c]] + fill[unit[c]]++] = members[k];
        free(fill);
    }
    /* S is not yet reversed by turn: signs carry it. */
    {
        size_t nseg = mstart[nc];
        segturn = calloc(nseg ? nseg : 1, 1);
        if (!segturn) {
            status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
            goto units_out;
        }
        for (uint32_t c = 0; c < nc; c++)
            for (uint32_t k = mstart[c]; k < mstart[c + 1]; k++)
                segturn[members[k]] = turn[c];
    }
    for (uint32_t u = 0; u < nu; u++) {
        /* shoelace about a point of the unit, so that open pieces do not
         * depend on where the origin is */
        const double *o = P + 2 * S[useg[ustart[u]]].a;
        for (uint32_t k = ustart[u]; k < ustart[u + 1]; k++) {
            uint32_t id = useg[k];
            const double *p = P + 2 * S[id].a, *q = P + 2 * S[id].b;
            double sg = segturn[id] ? -1 : 1;
            uarea[u] += sg * ((p[0] - o[0]) * (q[1] - o[1]) - (q[0] - o[0]) * (p[1] - o[1]));
            double L = hypot(q[0] - p[0], q[1] - p[1]);
            utot[u] += L;
            if (L > ulen[u]) {
                ulen[u] = L;
                upt[2 * u] = 0.5 * (p[0] + q[0]);
                upt[2 * u + 1] = 0.5 * (p[1] + q[1]);
            }
        }
    }
    /* Gaps closing each group of open chains, end of one to start of the next
     * (ce follows the turns); ugap < 0 marks units of a single chain. */
    ugap = malloc((nu ? nu : 1) * sizeof *ugap);
    ufirst = malloc((nu ? nu : 1) * sizeof *ufirst);
    ulast = malloc((nu ? nu : 1) * sizeof *ulast);
    if (!ugap || !ufirst || !ulast) {
        status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
        goto units_out;
    }
    for (uint32_t u = 0; u < nu; u++) {
        ugap[u] = -1;
        ufirst[u] = UINT32_MAX;
    }
    for (uint32_t i = 0; i < m; i++) {
        uint32_t c = open[i], u = unit[c];
        if (ufirst[u] == UINT32_MAX) {
            ufirst[u] = c;
        } else {
            const double *e = ce[ulast[u]].e;
            ugap[u] = fmax(ugap[u], 0) + hypot(ce[c].s[0] - e[0], ce[c].s[1] - e[1]);
        }
        ulast[u] = c;
    }
    for (uint32_t u = 0; u < nu; u++)
        if (ugap[u] >= 0) {
            const double *e = ce[ulast[u]].e, *s0 = ce[ufirst[u]].s;
            ugap[u] += hypot(s0[0] - e[0], s0[1] - e[1]);
        }
    status = nesting_turns(P, S, nu, ustart, useg, segturn, upt, uarea, utot, ugap, uturn,
                           &st->nesting_tests);
    if (status != HV_OK)
        goto units_out;
    for (uint32_t c = 0; c < nc; c++)
        turn[c] ^= uturn[unit[c]];
units_out:
    free(ugap);
    free(ufirst);
    free(ulast);
    free(segturn);
    free(ustart);
    free(useg);
    free(utot);
    free(upt);
    free(ulen);
    free(uarea);
    free(uturn);
out:
    free(is_cycle);
    free(open);
    free(unit);
    free(ce);
    free(acc);
    free(G);
    free(gpar);
    free(gid);
    return status;
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
        return hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
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
static hv_status walk_ranks(const double *P, size_t np, const uint8_t *used, size_t nu,
                            double cell, uint32_t **rank)
{
    uint64_t *keys = malloc(2 * (nu ? nu : 1) * sizeof *keys);
    *rank = malloc((np ? np : 1) * sizeof **rank);
    if (!keys || !*rank) {
        free(keys);
        free(*rank);
        *rank = NULL;
        return hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    }
    size_t n = 0;
    for (size_t i = 0; i < np; i++)
        if (used[i]) {
            keys[2 * n] = bucket_key((int64_t)floor(P[2 * i] / cell), (int64_t)floor(P[2 * i + 1] / cell));
            keys[2 * n + 1] = i;
            n++;
        }
    qsort(keys, n, 2 * sizeof *keys, by_u64);
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
        int64_t bx = (int64_t)floor((a[0] + t * dx) / cell), by = (int64_t)floor((a[1] + t * dy) / cell);
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
                            const double *P, seg2 s, double L, double tol, double cell,
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
                        return hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
                    *hits = more;
                }
                (*hits)[*nh] = (tp){along, p, 0, 0, 0};
                *nh += (size_t)walk_meets(P, a, dx, dy, (int)ceil(L / (0.5 * cell)), cell, p,
                                          &(*hits)[*nh]);
            }
        }
    return HV_OK;
}

static hv_status split_overlaps(const double *P, size_t np, seg2 **Sp, size_t *ns, double tol,
                                double cell, size_t *nsplit)
{
    seg2 *S = *Sp;
    uint8_t *used = calloc(np ? np : 1, 1);
    uint32_t *rank = NULL; /* made at the first split point */
    point_grid g = {{0, 0}, 0, {0, 0}, NULL, NULL};
    seg2 *out = NULL;
    tp *hits = NULL;
    size_t nu = 0, nout = 0, capout = 0, caphits = 0;
    hv_status status = HV_OK;
    if (!used)
        return hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    for (size_t k = 0; k < *ns; k++)
        used[S[k].a] = used[S[k].b] = 1;
    for (size_t i = 0; i < np; i++)
        nu += used[i];
    double total = 0;
    for (size_t k = 0; k < *ns; k++)
        total += seg_len(P, S[k]);
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
            seg2 *no = realloc(out, capout * sizeof *out);
            if (!no) {
                status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
                goto done;
            }
            out = no;
        }
        if (nh > 1)
            qsort(hits, nh, sizeof *hits, by_t);
        uint32_t prev = S[k].a;
        for (size_t e = 0; e < nh; e++) {
            out[nout++] = (seg2){prev, hits[e].p};
            prev = hits[e].p;
        }
        out[nout++] = (seg2){prev, S[k].b};
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
                uint32_t ra = uf_find(par, i), rb = uf_find(par, j);
                if (ra != rb) {
                    par[ra > rb ? ra : rb] = ra < rb ? ra : rb;
                    (*welded)++;
                }
            }
        }
}

/* Welds, drops zero-length and duplicate segments, orients chains. S and ns are
 * updated in place. */
static hv_status repair(const double *P, size_t np, seg2 **Sp, size_t *ns, double tol, double h,
                        hv_sdf2d_stats *st)
{
    seg2 *S = *Sp;
    hv_status status = HV_OK;
    uint32_t *par = malloc(np * sizeof *par);
    if (!par)
        return hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
    for (uint32_t i = 0; i < np; i++)
        par[i] = i;
    /* 1. Weld: points within tol, pairs found on a grid of cells >= 2 tol. The
     * roots (the lowest index of each cluster) and the count do not depend on
     * the order the pairs are met in. */
    if (tol > 0) {
        point_grid g = {{0, 0}, 0, {0, 0}, NULL, NULL};
        if ((status = pg_build(&g, P, np, NULL, 2 * tol)) != HV_OK)
            goto out;
        for (int64_t cy = 0; cy < g.n[1]; cy++)
            for (int64_t cx = 0; cx < g.n[0]; cx++) {
                size_t c = (size_t)(cx + g.n[0] * cy);
                for (uint32_t e = g.start[c]; e < g.start[c + 1]; e++)
                    weld_near(P, &g, cx, cy, g.ids[e], tol, par, &st->points_welded);
            }
        pg_free(&g);
    }
    size_t n = 0;
    for (size_t k = 0; k < *ns; k++) {
        seg2 s = {uf_find(par, S[k].a), uf_find(par, S[k].b)};
        if (s.a == s.b || seg_len(P, s) == 0) {
            st->zero_length_removed++;
            continue;
        }
        S[n++] = s;
    }
    /* 1b. Overlaps: split at points lying on other segments. */
    if (tol > 0 && n > 0) {
        if ((status = split_overlaps(P, np, Sp, &n, tol, h, &st->segments_split)) != HV_OK)
            goto out;
        S = *Sp;
    }
    /* 2. Duplicates (either direction): keep the first. */
    uint64_t *key = malloc(n * 2 * sizeof *key);
    if (!key && n) {
        status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
        goto out;
    }
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
        status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
        goto out;
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
    n = m;
    *ns = n;
    if (n == 0)
        goto out;

    /* 3. Chains through points of degree 2; consistent direction by a walk. */
    {
        uint32_t *deg = calloc(np + 1, sizeof *deg), *inc = malloc(2 * n * sizeof *inc);
        uint32_t *comp = malloc(n * sizeof *comp), *queue = malloc(n * sizeof *queue);
        uint8_t *flip = calloc(n, 1);
        double *vote = NULL;
        uint32_t *members = NULL, *mstart = NULL;
        if (!deg || !inc || !comp || !queue || !flip) {
            status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
            goto chains_out;
        }
        for (size_t k = 0; k < n; k++) {
            deg[S[k].a + 1]++;
            deg[S[k].b + 1]++;
        }
        for (size_t v = 0; v < np; v++)
            deg[v + 1] += deg[v]; /* deg is now the CSR offset array */
        {
            uint32_t *fill = calloc(np, sizeof *fill);
            if (!fill) {
                status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
                goto chains_out;
            }
            for (uint32_t k = 0; k < n; k++) {
                inc[deg[S[k].a] + fill[S[k].a]++] = k;
                inc[deg[S[k].b] + fill[S[k].b]++] = k;
            }
            free(fill);
        }
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
        st->chains = nc;
        /* Vote: keep the direction most of the length had. */
        vote = calloc(2 * (size_t)nc, sizeof *vote);
        mstart = calloc((size_t)nc + 1, sizeof *mstart);
        members = malloc(n * sizeof *members);
        if (!vote || !mstart || !members) {
            status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
            goto chains_out;
        }
        for (size_t k = 0; k < n; k++) {
            vote[2 * comp[k] + flip[k]] += seg_len(P, S[k]);
            mstart[comp[k] + 1]++;
        }
        for (uint32_t c = 0; c < nc; c++)
            mstart[c + 1] += mstart[c];
        {
            uint32_t *fill = calloc(nc, sizeof *fill);
            if (!fill) {
                status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
                goto chains_out;
            }
            for (uint32_t k = 0; k < n; k++)
                members[mstart[comp[k]] + fill[comp[k]]++] = k;
            free(fill);
        }
        for (size_t k = 0; k < n; k++)
            if (vote[2 * comp[k] + 1] > vote[2 * comp[k]])
                flip[k] ^= 1;
        for (size_t k = 0; k < n; k++)
            if (flip[k]) {
                uint32_t t = S[k].a;
                S[k].a = S[k].b;
                S[k].b = t;
            }
        /* 4. Orientation of whole chains (open ones by their mutual coupling,
         * then every loop by nesting). */
        uint8_t *turn = calloc(nc, 1);
        if (!turn) {
            status = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the repair");
            goto chains_out;
        }
        if ((status = orient_chains(P, S, deg, nc, mstart, members, tol, turn, st)) != HV_OK) {
            free(turn);
            goto chains_out;
        }
        for (size_t k = 0; k < n; k++) {
            flip[k] ^= turn[comp[k]];
            if (turn[comp[k]]) {
                uint32_t t = S[k].a;
                S[k].a = S[k].b;
                S[k].b = t;
            }
        }
        free(turn);
        /* flip[k] now says whether segment k runs against its input direction */
        for (size_t k = 0; k < n; k++)
            st->segments_flipped += flip[k];
    chains_out:
        free(deg);
        free(inc);
        free(comp);
        free(queue);
        free(flip);
        free(vote);
        free(members);
        free(mstart);
    }
out:
    free(par);
    return status;
}

/* ---- grid ---- */

static hv_status place_grid(const double *P, size_t np, const hv_sdf2d_opts *o, int n[2],
                            double *h, double origin[2])
{
    double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
    for (size_t i = 0; i < np; i++)
        for (int a = 0; a < 2; a++) {
            double v = P[2 * i + a];
            if (!isfinite(v))
                return hv_error(HV_ERR_NUMERIC, "sdf2d: point %zu has a non-finite coordinate", i);
            lo[a] = fmin(lo[a], v);
            hi[a] = fmax(hi[a], v);
        }
    if (o->use_bbox) {
        const double *b = o->bbox;
        double L = fmax(b[2] - b[0], b[3] - b[1]);
        *h = o->voxel_size > 0 ? o->voxel_size : L / o->res;
        for (int a = 0; a < 2; a++) {
            double c = ceil((b[a + 2] - b[a]) / *h - 1e-9);
            if (!(c < 1e8))
                return hv_error(HV_ERR_INVALID_ARG, "sdf2d: %g cells along %c", c, "xy"[a]);
            n[a] = c < 1 ? 1 : (int)c;
            origin[a] = b[a];
        }
    } else {
        double L = fmax(hi[0] - lo[0], hi[1] - lo[1]);
        if (o->voxel_size > 0)
            *h = o->voxel_size;
        else if (L > 0)
            *h = L / (o->res - 2 * o->pad);
        else
            return hv_error(HV_ERR_INVALID_ARG,
                            "sdf2d: the curves have no extent (one point); give a voxel size");
        for (int a = 0; a < 2; a++) {
            double c = ceil((hi[a] - lo[a]) / *h - 1e-9) + 2.0 * o->pad;
            if (!(c < 1e8))
                return hv_error(HV_ERR_INVALID_ARG, "sdf2d: %g cells along %c", c, "xy"[a]);
            n[a] = c < 1 ? 1 : (int)c;
            origin[a] = 0.5 * (lo[a] + hi[a]) - 0.5 * n[a] * *h;
        }
    }
    int n3[3] = {n[0], n[1], 1};
    return hv_check_dims(2, n3, *h, 8 * sizeof(double) * 3);
}

/* Bilinear weights of world point (x, y) on the cell centres (clamped). */
static void bilinear(const int n[2], double h, const double org[2], double x, double y,
                     size_t idx[4], double w[4])
{
    double u = (x - org[0]) / h - 0.5, v = (y - org[1]) / h - 0.5;
    int i = (int)floor(u), j = (int)floor(v);
    double fu = u - i, fv = v - j;
    if (i < 0) {
        i = 0;
        fu = 0;
    } else if (i >= n[0] - 1) {
        i = n[0] > 1 ? n[0] - 2 : 0;
        fu = n[0] > 1 ? 1 : 0;
    }
    if (j < 0) {
        j = 0;
        fv = 0;
    } else if (j >= n[1] - 1) {
        j = n[1] > 1 ? n[1] - 2 : 0;
        fv = n[1] > 1 ? 1 : 0;
    }
    int i1 = n[0] > 1 ? i + 1 : i, j1 = n[1] > 1 ? j + 1 : j;
    idx[0] = (size_t)i + (size_t)n[0] * j;
    idx[1] = (size_t)i1 + (size_t)n[0] * j;
    idx[2] = (size_t)i + (size_t)n[0] * j1;
    idx[3] = (size_t)i1 + (size_t)n[0] * j1;
    w[0] = (1 - fu) * (1 - fv);
    w[1] = fu * (1 - fv);
    w[2] = (1 - fu) * fv;
    w[3] = fu * fv;
}

static double point_seg_d2(double x, double y, const double *p, const double *q)
{
    double dx = q[0] - p[0], dy = q[1] - p[1];
    double L2 = dx * dx + dy * dy;
    double t = L2 > 0 ? ((x - p[0]) * dx + (y - p[1]) * dy) / L2 : 0;
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    double ex = p[0] + t * dx - x, ey = p[1] + t * dy - y;
    return ex * ex + ey * ey;
}

/* Exact distance to the segments: rasterized within SDF2_BAND cells of each
 * segment, then nearest-segment candidates passed on by sweeps in the four
 * diagonal directions (twice). */
static hv_status exact_distance(const double *P, const seg2 *S, size_t ns, const int n[2],
                                double h, const double org[2], double *dist)
{
    size_t count = (size_t)n[0] * n[1];
    uint32_t *near = malloc(count * sizeof *near);
    if (!near)
        return hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the exact distance");
    for (size_t c = 0; c < count; c++) {
        dist[c] = INFINITY;
        near[c] = UINT32_MAX;
    }
    for (size_t k = 0; k < ns; k++) {
        const double *p = P + 2 * S[k].a, *q = P + 2 * S[k].b;
        int i0 = (int)floor((fmin(p[0], q[0]) - org[0]) / h - 0.5 - SDF2_BAND);
        int i1 = (int)ceil((fmax(p[0], q[0]) - org[0]) / h - 0.5 + SDF2_BAND);
        int j0 = (int)floor((fmin(p[1], q[1]) - org[1]) / h - 0.5 - SDF2_BAND);
        int j1 = (int)ceil((fmax(p[1], q[1]) - org[1]) / h - 0.5 + SDF2_BAND);
        i0 = i0 < 0 ? 0 : i0;
        j0 = j0 < 0 ? 0 : j0;
        i1 = i1 > n[0] - 1 ? n[0] - 1 : i1;
        j1 = j1 > n[1] - 1 ? n[1] - 1 : j1;
        for (int j = j0; j <= j1; j++)
            for (int i = i0; i <= i1; i++) {
                double x = org[0] + (i + 0.5) * h, y = org[1] + (j + 0.5) * h;
                double d2 = point_seg_d2(x, y, p, q);
                size_t c = (size_t)i + (size_t)n[0] * j;
                if (d2 < dist[c]) {
                    dist[c] = d2;
                    near[c] = (uint32_t)k;
                }
            }
    }
    for (int pass = 0; pass < 2; pass++)
        for (int dir = 0; dir < 4; dir++) {
            int di = dir & 1 ? -1 : 1, dj = dir & 2 ? -1 : 1;
            for (int jj = 0; jj < n[1]; jj++) {
                int j = dj > 0 ? jj : n[1] - 1 - jj;
                for (int ii = 0; ii < n[0]; ii++) {
                    int i = di > 0 ? ii : n[0] - 1 - ii;
                    size_t c = (size_t)i + (size_t)n[0] * j;
                    int nbi[3] = {i - di, i, i - di}, nbj[3] = {j, j - dj, j - dj};
                    for (int b = 0; b < 3; b++) {
                        if (nbi[b] < 0 || nbi[b] >= n[0] || nbj[b] < 0 || nbj[b] >= n[1])
                            continue;
                        uint32_t s = near[(size_t)nbi[b] + (size_t)n[0] * nbj[b]];
                        if (s == UINT32_MAX || s == near[c])
                            continue;
                        double x = org[0] + (i + 0.5) * h, y = org[1] + (j + 0.5) * h;
                        double d2 = point_seg_d2(x, y, P + 2 * S[s].a, P + 2 * S[s].b);
                        if (d2 < dist[c]) {
                            dist[c] = d2;
                            near[c] = s;
                        }
                    }
                }
            }
        }
    for (size_t c = 0; c < count; c++)
        dist[c] = sqrt(dist[c]);
    free(near);
    return HV_OK;
}

static hv_status solver_create(hv_solver **s, const hv_problem *p, const hv_solver_opts *so)
{
    hv_status st = hv_solver_create(s, p, so);
    if (st == HV_ERR_UNSUPPORTED && so->backend == HV_BACKEND_AUTO) {
        hv_solver_opts mg = *so;
        mg.backend = HV_BACKEND_MG;
        st = hv_solver_create(s, p, &mg);
    }
    return st;
}

/* ---- the method ---- */

hv_status hv_curves_sdf(const hv_curves *c, const hv_sdf2d_opts *opts, hv_grid **out,
                        hv_sdf2d_stats *stats)
{
    if (!out)
        return hv_error(HV_ERR_INVALID_ARG, "hv_curves_sdf: out is NULL");
    *out = NULL;
    if (!c || !c->pts || !c->start || c->nlines == 0)
        return hv_error(HV_ERR_INVALID_ARG, "hv_curves_sdf: no curves");
    hv_sdf2d_opts o;
    if (opts)
        o = *opts;
    else
        hv_sdf2d_opts_default(&o);
    hv_status st = check_opts(&o);
    if (st)
        return st;
    if (c->npoints >= UINT32_MAX)
        return hv_error(HV_ERR_INVALID_ARG, "sdf2d: too many points (%zu)", c->npoints);
    hv_sdf2d_stats S;
    memset(&S, 0, sizeof S);
    double t0 = hv_now(), tt = t0;

    int n[2] = {0, 0};
    double h = 0, org[2] = {0, 0};
    if ((st = place_grid(c->pts, c->npoints, &o, n, &h, org)))
        return st;
    S.n[0] = n[0];
    S.n[1] = n[1];
    S.h = h;
    S.origin[0] = org[0];
    S.origin[1] = org[1];
    const size_t count = (size_t)n[0] * n[1];
    const double *P = c->pts;

    size_t ns = 0, nsamp = 0;
    seg2 *Sg = malloc((hv_curves_segments(c) + 1) * sizeof *Sg);
    double *Y = NULL, *Ylev = NULL, *rhs = NULL, *phi = NULL, *samp = NULL;
    hv_solver *solver = NULL;
    hv_grid *g = NULL;
    if (!Sg) {
        st = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the segments");
        goto done;
    }
    for (size_t k = 0; k < c->nlines; k++) {
        size_t a = c->start[k], b = c->start[k + 1];
        if (b > c->npoints || b < a + 2) {
            st = hv_error(HV_ERR_INVALID_ARG, "sdf2d: polyline %zu has a bad point range", k);
            goto done;
        }
        for (size_t i = a; i + 1 < b; i++)
            Sg[ns++] = (seg2){(uint32_t)i, (uint32_t)(i + 1)};
        if (c->closed[k] && b - a > 2)
            Sg[ns++] = (seg2){(uint32_t)(b - 1), (uint32_t)a};
    }
    S.segments_in = ns;

    /* 1. Repair. */
    if ((st = hv_progress(0.0, "repair")))
        goto done;
    if (o.repair && (st = repair(P, c->npoints, &Sg, &ns, o.weld_tol * h, h, &S)))
        goto done;
    S.segments_out = ns;
    S.t_repair = hv_now() - tt;
    if (ns == 0) {
        st = hv_error(HV_ERR_INVALID_ARG, "sdf2d: no segment of non-zero length");
        goto done;
    }

    /* 2. Splat length-weighted normals (right-hand side of each segment). */
    if ((st = hv_progress(0.05, "splat")))
        goto done;
    tt = hv_now();
    size_t cap = 0;
    for (size_t k = 0; k < ns; k++)
        cap += (size_t)ceil(seg_len(P, Sg[k]) / (0.5 * h)) + 1;
    samp = malloc(3 * cap * sizeof *samp); /* x, y, length */
    Y = calloc(2 * count, sizeof *Y);
    if (!samp || !Y) {
        st = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the surface field");
        goto done;
    }
    double f2 = 0;
    for (size_t k = 0; k < ns; k++) {
        const double *p = P + 2 * Sg[k].a, *q = P + 2 * Sg[k].b;
        double L = seg_len(P, Sg[k]);
        int pieces = (int)ceil(L / (0.5 * h));
        pieces = pieces < 1 ? 1 : pieces;
        double nx = (q[1] - p[1]) / L, ny = -(q[0] - p[0]) / L, w = L / pieces;
        for (int m = 0; m < pieces; m++) {
            double t = (m + 0.5) / pieces;
            double x = p[0] + t * (q[0] - p[0]), y = p[1] + t * (q[1] - p[1]);
            size_t idx[4];
            double wt[4];
            bilinear(n, h, org, x, y, idx, wt);
            for (int b = 0; b < 4; b++) {
                Y[idx[b]] += wt[b] * w * nx / (h * h);
                Y[count + idx[b]] += wt[b] * w * ny / (h * h);
            }
            samp[3 * nsamp] = x;
            samp[3 * nsamp + 1] = y;
            samp[3 * nsamp + 2] = w;
            nsamp++;
        }
    }
    for (size_t i = 0; i < 2 * count; i++)
        f2 += Y[i] * Y[i];
    S.t_splat = hv_now() - tt;

    /* 3. Diffuse: levels t, 16t, ... until the field reaches across the block. */
    tt = hv_now();
    double diag = hypot(n[0], n[1]);
    double reach = o.t_scale * 0.5 * log(1.0 / o.tol);
    int nlev = 1;
    while (reach < diag && nlev < SDF2_MAX_LEVELS) {
        reach *= 4;
        nlev++;
    }
    S.levels = nlev;
    Ylev = malloc((size_t)nlev * 2 * count * sizeof *Ylev);
    if (!Ylev) {
        st = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for %d diffused fields", 2 * nlev);
        goto done;
    }
    double tau[SDF2_MAX_LEVELS];
    hv_solver_opts so;
    hv_solver_opts_default(&so);
    so.backend = o.backend;
    so.tol = o.tol;
    so.max_iter = 200;
    for (int k = 0; k < nlev; k++) {
        if ((st = hv_progress(0.1 + 0.5 * k / nlev, "diffuse")))
            goto done;
        double t = (o.t_scale * h) * (o.t_scale * h) * pow(16.0, k);
        hv_problem pb = {2, {n[0], n[1], 1}, h, NULL, 1.0, t};
        if ((st = solver_create(&solver, &pb, &so)))
            goto done;
        double relres = 0;
        for (int b = 0; b < 2; b++) {
            hv_solve_info info;
            if ((st = hv_solver_solve_d(solver, Y + b * count, Ylev + ((size_t)k * 2 + b) * count,
                                        &info)))
                goto done;
            relres = fmax(relres, info.relres);
            S.backend = info.backend;
        }
        hv_solver_destroy(&solver);
        tau[k] = SDF2_NOISE_FACTOR * fmax(relres, 1e-15) * sqrt(f2);
    }
    S.t_diffuse = hv_now() - tt;

    /* 4. Normalize on faces, rhs = -div X. */
    if ((st = hv_progress(0.6, "normalize")))
        goto done;
    tt = hv_now();
    rhs = calloc(count, sizeof *rhs);
    phi = calloc(count, sizeof *phi);
    if (!rhs || !phi) {
        st = hv_error(HV_ERR_NOMEM, "sdf2d: out of memory for the divergence");
        goto done;
    }
    const size_t step[2] = {1, (size_t)n[0]};
    for (int a = 0; a < 2; a++)
        for (int j = a == 1 ? 1 : 0; j < n[1]; j++)
            for (int i = a == 0 ? 1 : 0; i < n[0]; i++) {
                /* the interior face between cells lo and hi along axis a */
                size_t hi = (size_t)i + step[1] * j, lo = hi - step[a];
                double flux = 0;
                int dead = 1;
                for (int k = 0; k < nlev && dead; k++) {
                    const double *Yx = Ylev + (size_t)k * 2 * count, *Yy = Yx + count;
                    double vx = 0.5 * (Yx[lo] + Yx[hi]), vy = 0.5 * (Yy[lo] + Yy[hi]);
                    double len = hypot(vx, vy);
                    if (len > tau[k]) {
                        flux = (a == 0 ? vx : vy) / len;
                        dead = 0;
                    }
                }
                S.dead_faces += (size_t)dead;
                rhs[hi] += flux / h; /* -div: the face adds -flux/h to hi's div */
                rhs[lo] -= flux / h;
            }
    free(Ylev);
    Ylev = NULL;
    S.t_normalize = hv_now() - tt;

    /* 5. Poisson: -Lap phi = -div X, Neumann walls, mean-free. */
    if ((st = hv_progress(0.65, "poisson")))
        goto done;
    tt = hv_now();
    {
        hv_problem pb = {2, {n[0], n[1], 1}, h, NULL, 0.0, 1.0};
        if ((st = solver_create(&solver, &pb, &so)))
            goto done;
        hv_solve_info info;
        if ((st = hv_solver_solve_d(solver, rhs, phi, &info)))
            goto done;
        hv_solver_destroy(&solver);
    }
    /* 6. Shift: the length-weighted mean of phi on the curves goes to zero. */
    {
        double num = 0, den = 0;
        for (size_t s = 0; s < nsamp; s++) {
            size_t idx[4];
            double wt[4], v = 0;
            bilinear(n, h, org, samp[3 * s], samp[3 * s + 1], idx, wt);
            for (int b = 0; b < 4; b++)
                v += wt[b] * phi[idx[b]];
            num += samp[3 * s + 2] * v;
            den += samp[3 * s + 2];
        }
        double shift = den > 0 ? num / den : 0;
        for (size_t i = 0; i < count; i++)
            phi[i] -= shift;
    }
    S.t_poisson = hv_now() - tt;

    /* 7. Output, with the exact distance unless asked for the heat magnitude. */
    double org3[3] = {org[0], org[1], 0};
    int n3[3] = {n[0], n[1], 1};
    if ((st = hv_grid_create(&g, 2, n3, h, org3)))
        goto done;
    if (!o.heat_magnitude) {
        if ((st = hv_progress(0.85, "distance")))
            goto done;
        tt = hv_now();
        if ((st = exact_distance(P, Sg, ns, n, h, org, rhs)))
            goto done;
        for (size_t i = 0; i < count; i++)
            g->v[i] = (float)(phi[i] < 0 ? -rhs[i] : rhs[i]);
        S.t_distance = hv_now() - tt;
    } else {
        for (size_t i = 0; i < count; i++)
            g->v[i] = (float)phi[i];
    }
    if ((st = hv_progress(1.0, "done")))
        goto done;
    S.t_total = hv_now() - t0;
    *out = g;
    g = NULL;
done:
    hv_solver_destroy(&solver);
    hv_grid_destroy(&g);
    free(Sg);
    free(Y);
    free(Ylev);
    free(rhs);
    free(phi);
    free(samp);
    if (stats)
        *stats = S;
    return st;
}
