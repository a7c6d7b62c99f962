/*
 * The sign of a distance field from the generalized winding number of the
 * repaired mesh (inside where it exceeds 1/2; Jacobson et al. 2013), for the
 * cases where the heat method's sign depends on where the block ends: a mesh
 * that stays open after repair (its inside leaks out of a wide opening to the
 * nearest walls) and a block that cuts the mesh (the heat method sees only the
 * part inside). The winding number is a function of position alone, so the
 * sign is the same in any block on the same lattice (docs/METHOD.md, "Sign
 * from the winding number").
 *
 * Evaluated hierarchically on the block's lattice, as in fast sweeping of
 * octrees: cubes of 8, 4, 2 cells anchored to the lattice (not the block, so
 * two blocks on one lattice decide alike) take one sign when no surface is
 * near them and the winding number at their eight corners lies on one side of
 * 1/2 by a margin; the other cubes split, down to single cells. Those take
 * the pseudonormal of a clean nearest feature within dlim of them (exact
 * there, as in the heat-method path) or the winding number at their centres.
 * Only cells near broken parts of the surface or near the winding number's
 * own 1/2 crossings (across openings) pay an evaluation.
 */
#include "sdf_internal.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Clusters beyond WS_BETA radii count as dipoles (hv__wn_eval: 2.5), which is
 * coarse (errors up to about 0.1) but enough wherever the winding number is
 * clearly 0 or 1: most evaluations. Where a value comes out within WS_FLAT of
 * 1/2 it is evaluated again with the dipoles twice as far, whose errors are
 * about a quarter, until it is clear of 1/2 by about twice the error or the
 * dipoles start beyond 32 radii (open space across openings, where the
 * winding number is flat around 1/2: inside an open tube near its ends).
 * knot at 64^3: 0.34 s against 0.79 s starting from 2 radii, same signs. */
#define WS_BETA 1.0
#define WS_FLAT 0.25
/* Cube edge of the first level, in cells. */
#define WS_TOP 8
/* A cube takes one sign only when the winding number at its corners is this
 * far from 1/2 ... */
#define WS_MARGIN 0.1
/* ... and no cell of it is nearer the surface than max(WS_NEAR, WS_NEAR_REL
 * times its edge) voxels: beyond sqrt(3)/2 voxels no surface crosses a
 * cell, and larger cubes keep more room from rims, near which the winding
 * number varies fastest. */
#define WS_NEAR 1.0
#define WS_NEAR_REL 0.5

static inline long floordiv(long a, long b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

typedef struct ws_level {
    int s;        /* cube edge in cells */
    long r0[3];   /* lattice index of the first cube along each axis */
    int nr[3];    /* cubes along each axis covering the block */
    uint8_t *act; /* per cube: 1 to be decided at this level */
    float *w;     /* (nr + 1)^3 corner values, NAN where not needed */
} ws_level;

double hv__wn_sure(const hv_wn_tree *W, const double p[3], size_t *evals)
{
    double beta = WS_BETA, flat = WS_FLAT;
    double w = hv__wn_eval_beta(W, p, UINT32_MAX, beta);
    ++*evals;
    while (fabs(w - 0.5) < flat && beta < 32) {
        beta *= 2;
        flat /= 4;
        w = hv__wn_eval_beta(W, p, UINT32_MAX, beta);
        ++*evals;
    }
    return w;
}

/* The same at the lattice point with global index G. */
static double wn_at(const hv_wn_tree *W, const hv_grid *g, const long base[3], const long G[3],
                    size_t *evals)
{
    double p[3];
    for (int a = 0; a < 3; a++)
        p[a] = g->origin[a] + ((double)(G[a] - base[a]) + 0.5) * g->h;
    return hv__wn_sure(W, p, evals);
}

/* Global lattice index of cell 0: blocks on one lattice differ by whole
 * cells. */
static void lattice_base(const hv_grid *g, long base[3])
{
    for (int a = 0; a < 3; a++) {
        double q = g->origin[a] / g->h;
        /* Beyond 2^40 cells from the origin the block anchors its own cubes. */
        base[a] = fabs(q) < 0x1p40 ? lround(q) : 0;
    }
}

/* The levels of cubes, WS_TOP cells down to 2, covering the block; *nlev
 * counts those made. 0 when out of memory (the levels made are in L). */
static int levels_create(ws_level L[4], const long base[3], const int n[3], int *nlev)
{
    for (int s = WS_TOP; s >= 2; s /= 2, (*nlev)++) {
        ws_level *lv = &L[*nlev];
        lv->s = s;
        size_t nc = 1, nw = 1;
        for (int a = 0; a < 3; a++) {
            lv->r0[a] = floordiv(base[a], s);
            lv->nr[a] = (int)(floordiv(base[a] + n[a] - 1, s) - lv->r0[a] + 1);
            nc *= (size_t)lv->nr[a];
            nw *= (size_t)lv->nr[a] + 1;
        }
        lv->act = hv_calloc(nc, 1);
        lv->w = hv_malloc(nw * sizeof(float));
        if (!lv->act || !lv->w)
            return 0;
    }
    return 1;
}

/* The winding number at the corners of the level's active cubes, NAN at the
 * other corners. Returns the evaluations. */
static size_t level_corners(ws_level *lv, const hv_wn_tree *W, const hv_grid *g, const long base[3])
{
    const int s = lv->s;
    const int nr0 = lv->nr[0], nr1 = lv->nr[1], nr2 = lv->nr[2];
    const int nw0 = nr0 + 1, nw1 = nr1 + 1, nw2 = nr2 + 1;
    size_t evals = 0;
#pragma omp parallel for collapse(2) schedule(dynamic, 4) reduction(+ : evals)
    for (int cz = 0; cz < nw2; cz++)
        for (int cy = 0; cy < nw1; cy++)
            for (int cx = 0; cx < nw0; cx++) {
                int need = 0;
                for (int q = 0; q < 8 && !need; q++) {
                    int rx = cx - (q & 1), ry = cy - (q >> 1 & 1), rz = cz - (q >> 2 & 1);
                    if (rx >= 0 && ry >= 0 && rz >= 0 && rx < nr0 && ry < nr1 && rz < nr2)
                        need = lv->act[rx + (size_t)nr0 * (ry + (size_t)nr1 * rz)];
                }
                float v = NAN;
                if (need) {
                    long G[3] = {(lv->r0[0] + cx) * s, (lv->r0[1] + cy) * s, (lv->r0[2] + cz) * s};
                    v = (float)wn_at(W, g, base, G, &evals);
                }
                lv->w[cx + (size_t)nw0 * (cy + (size_t)nw1 * cz)] = v;
            }
    return evals;
}

/* The side all eight corners of cube (rx, ry, rz) lie on, clear of 1/2 by
 * WS_MARGIN: -1 inside, +1 outside, 0 when they do not agree. */
static int corner_side(const ws_level *lv, int rx, int ry, int rz)
{
    const int nw0 = lv->nr[0] + 1, nw1 = lv->nr[1] + 1;
    int side = 0;
    for (int q = 0; q < 8; q++) {
        float v = lv->w[(rx + (q & 1)) +
                        (size_t)nw0 * ((ry + (q >> 1 & 1)) + (size_t)nw1 * (rz + (q >> 2 & 1)))];
        int sd = v > 0.5 + WS_MARGIN ? -1 : v < 0.5 - WS_MARGIN ? 1 : 0;
        if (!sd || (side && sd != side))
            return 0;
        side = sd;
    }
    return side;
}

/* Whether a cell of the box lo..hi (exclusive) is nearer the surface than
 * dnear. */
static int any_near(const float *dist, const int n[3], const int lo[3], const int hi[3],
                    float dnear)
{
    const size_t sy = (size_t)n[0], sz = (size_t)n[0] * n[1];
    for (int k = lo[2]; k < hi[2]; k++)
        for (int j = lo[1]; j < hi[1]; j++)
            for (int i = lo[0]; i < hi[0]; i++)
                if (dist[i + sy * j + sz * k] < dnear)
                    return 1;
    return 0;
}

/* The 8 children of cube r of lv at the next level, to be decided there. */
static void mark_children(const ws_level *lv, ws_level *next, const int r[3])
{
    for (int q = 0; q < 8; q++) {
        long cr[3];
        int ok = 1;
        for (int a = 0; a < 3; a++) {
            cr[a] = (lv->r0[a] + r[a]) * 2 + (q >> a & 1) - next->r0[a];
            ok &= cr[a] >= 0 && cr[a] < next->nr[a];
        }
        if (ok)
            next->act[cr[0] + (size_t)next->nr[0] * (cr[1] + (size_t)next->nr[1] * cr[2])] = 1;
    }
}

/* Each active cube of the level takes one sign into sg where its corners
 * agree and no cell of it is near the surface; else its children at the next
 * level (NULL: none) are to be decided. */
static void level_decide(const ws_level *lv, ws_level *next, const hv_grid *g, const long base[3],
                         const float *dist, int8_t *sg)
{
    const int *n = g->n;
    const size_t sy = (size_t)n[0], sz = (size_t)n[0] * n[1];
    const int s = lv->s;
    const int nr0 = lv->nr[0], nr1 = lv->nr[1], nr2 = lv->nr[2];
    const float dnear = (float)(fmax(WS_NEAR, WS_NEAR_REL * s) * g->h);
#pragma omp parallel for collapse(2) schedule(dynamic, 4)
    for (int rz = 0; rz < nr2; rz++)
        for (int ry = 0; ry < nr1; ry++)
            for (int rx = 0; rx < nr0; rx++) {
                if (!lv->act[rx + (size_t)nr0 * (ry + (size_t)nr1 * rz)])
                    continue;
                int lo[3], hi[3];
                const int r[3] = {rx, ry, rz};
                for (int a = 0; a < 3; a++) {
                    long c0 = (lv->r0[a] + r[a]) * s - base[a];
                    lo[a] = c0 < 0 ? 0 : (int)c0;
                    hi[a] = c0 + s > n[a] ? n[a] : (int)(c0 + s);
                }
                int side = corner_side(lv, rx, ry, rz);
                if (side && any_near(dist, n, lo, hi, dnear))
                    side = 0;
                if (side) {
                    for (int k = lo[2]; k < hi[2]; k++)
                        for (int j = lo[1]; j < hi[1]; j++)
                            memset(sg + lo[0] + sy * j + sz * k, side, (size_t)(hi[0] - lo[0]));
                    continue;
                }
                if (next)
                    mark_children(lv, next, r);
            }
}

/* Cells left undecided: within dlim of a clean feature whose faces bound a
 * solid, its pseudonormal (exact there, and no evaluation); elsewhere the
 * winding number at the centre. *used counts the first; returns the
 * evaluations. */
static size_t sign_cells(const hv_mesh *m, const hv_grid *g, const float *dist, const uint32_t *tri,
                         hv_pseudo *ps, double dlim, int8_t *sg, size_t *used)
{
    const int *n = g->n;
    const size_t sy = (size_t)n[0], sz = (size_t)n[0] * n[1];
    size_t evals = 0, nused = 0;
    const float dl = (float)dlim;
#pragma omp parallel for collapse(2) schedule(dynamic, 4) reduction(+ : evals, nused)
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++) {
            int8_t *row = sg + sy * j + sz * k;
            for (int i = 0; i < n[0]; i++) {
                if (row[i])
                    continue;
                const size_t c = (size_t)i + sy * j + sz * k;
                double p[3];
                hv_grid_cell_center(g, i, j, k, p);
                if (tri && dist[c] < dl && tri[c] != UINT32_MAX) {
                    int s = hv__pseudo_sign(ps, m, tri[c], p, 0);
                    if (s) {
                        row[i] = (int8_t)s;
                        nused++;
                        continue;
                    }
                }
                row[i] = hv__wn_sure(&ps->W, p, &evals) > 0.5 ? -1 : 1;
            }
        }
    *used = nused;
    return evals;
}

hv_status hv__winding_sign(const hv_mesh *m, const hv_grid *g, const float *dist,
                           const uint32_t *tri, hv_pseudo *ps, double dlim, float *out,
                           size_t *evals_out, size_t *ps_used)
{
    long base[3];
    lattice_base(g, base);
    hv_status st = HV_OK;
    /* Sign marker: 0 undecided, else +1 outside / -1 inside. */
    int8_t *sg = hv_calloc(hv_grid_count(g), 1);
    ws_level L[4];
    memset(L, 0, sizeof L);
    size_t evals = 0;
    int nlev = 0;
    if (!sg || !levels_create(L, base, g->n, &nlev)) {
        st = hv__error(HV_ERR_NOMEM, "sdf: out of memory for the winding-number sign");
        goto out;
    }
    /* Every cube of the first level is to be decided. */
    memset(L[0].act, 1, (size_t)L[0].nr[0] * L[0].nr[1] * L[0].nr[2]);
    for (int l = 0; l < nlev; l++) {
        evals += level_corners(&L[l], &ps->W, g, base);
        level_decide(&L[l], l + 1 < nlev ? &L[l + 1] : NULL, g, base, dist, sg);
    }
    size_t used = 0;
    evals += sign_cells(m, g, dist, tri, ps, dlim, sg, &used);
    if (ps_used)
        *ps_used = used;
    /* The sign as a value below any distance the pseudonormal test looks at. */
    const float tiny = (float)(1e-6 * g->h);
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < hv_grid_count(g); c++)
        out[c] = sg[c] < 0 ? -tiny : tiny;
out:
    for (int l = 0; l < 4; l++) {
        hv_free(L[l].act);
        hv_free(L[l].w);
    }
    hv_free(sg);
    if (evals_out)
        *evals_out = evals;
    return st;
}
