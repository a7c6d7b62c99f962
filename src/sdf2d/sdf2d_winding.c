/*
 * The 2D sibling of sign_winding.c: the sign of a 2D distance field from the
 * generalized winding number of the repaired curves (inside above 1/2), for
 * open curves and blocks that cut the curves, where the heat method's sign
 * depends on where the block ends (docs/METHOD.md, "Sign from the winding
 * number").
 *
 * The winding number of a segment a -> b at p is the angle it subtends over
 * 2 pi. A tree over the segments replaces far clusters by their dipole term:
 * seen from far away a segment subtends about N . (c - p) / |c - p|^2, N the
 * right-hand normal times its length, so a cluster subtends its summed N
 * dotted with (c - p) / |c - p|^2, c its length-weighted centre. Squares of
 * 8, 4, 2 cells anchored to the lattice take one sign where no cell of them is
 * near the curves and their corners agree; the remaining cells are evaluated
 * at their centres.
 */
#include "core/error.h"
#include "sdf2d_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define W2_LEAF 8
#define W2_BETA 1.0
#define W2_FLAT 0.25
#define W2_TOP 8
#define W2_MARGIN 0.1
#define W2_NEAR 1.0
#define W2_NEAR_REL 0.5

typedef struct w2_node {
    double c[2], N[2], r;
    int left, right; /* children, -1 for a leaf */
    uint32_t first, count;
} w2_node;

typedef struct w2_tree {
    const double *P;
    const sdf2d_seg *S;
    uint32_t *order;
    w2_node *nodes;
    int nnodes;
} w2_tree;

static int w2_build(w2_tree *T, uint32_t first, uint32_t count)
{
    int id = T->nnodes++;
    w2_node *nd = &T->nodes[id];
    memset(nd, 0, sizeof *nd);
    nd->first = first;
    nd->count = count;
    nd->left = nd->right = -1;
    double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY}, L = 0;
    for (uint32_t q = first; q < first + count; q++) {
        const sdf2d_seg s = T->S[T->order[q]];
        const double *a = T->P + 2 * s.a, *b = T->P + 2 * s.b;
        double l = hypot(b[0] - a[0], b[1] - a[1]);
        nd->N[0] += b[1] - a[1];
        nd->N[1] -= b[0] - a[0];
        for (int k = 0; k < 2; k++) {
            nd->c[k] += l * 0.5 * (a[k] + b[k]);
            double m = 0.5 * (a[k] + b[k]);
            lo[k] = m < lo[k] ? m : lo[k];
            hi[k] = m > hi[k] ? m : hi[k];
        }
        L += l;
    }
    for (int k = 0; k < 2; k++)
        nd->c[k] = L > 0 ? nd->c[k] / L : 0.5 * (lo[k] + hi[k]);
    double r2 = 0;
    for (uint32_t q = first; q < first + count; q++) {
        const sdf2d_seg s = T->S[T->order[q]];
        for (int e = 0; e < 2; e++) {
            const double *x = T->P + 2 * (e ? s.b : s.a);
            double d2 =
                (x[0] - nd->c[0]) * (x[0] - nd->c[0]) + (x[1] - nd->c[1]) * (x[1] - nd->c[1]);
            r2 = d2 > r2 ? d2 : r2;
        }
    }
    nd->r = sqrt(r2);
    if (count <= W2_LEAF)
        return id;
    int ax = hi[1] - lo[1] > hi[0] - lo[0];
    double mid = 0.5 * (lo[ax] + hi[ax]);
    uint32_t i = first, j = first + count;
    while (i < j) {
        const sdf2d_seg s = T->S[T->order[i]];
        if (0.5 * (T->P[2 * s.a + ax] + T->P[2 * s.b + ax]) < mid) {
            i++;
        } else {
            j--;
            uint32_t t = T->order[i];
            T->order[i] = T->order[j];
            T->order[j] = t;
        }
    }
    if (i == first || i == first + count)
        i = first + count / 2;
    int l = w2_build(T, first, i - first);
    int r = w2_build(T, i, first + count - i);
    T->nodes[id].left = l;
    T->nodes[id].right = r;
    return id;
}

static double w2_eval(const w2_tree *T, double x, double y, double beta)
{
    int stack[128], top = 0;
    double w = 0;
    stack[top++] = 0;
    while (top) {
        const w2_node *nd = &T->nodes[stack[--top]];
        double dx = nd->c[0] - x, dy = nd->c[1] - y, d2 = dx * dx + dy * dy;
        if (d2 > beta * beta * nd->r * nd->r) {
            w += (nd->N[0] * dx + nd->N[1] * dy) / d2;
            continue;
        }
        if (nd->left < 0 || top > 120) {
            for (uint32_t q = nd->first; q < nd->first + nd->count; q++) {
                const sdf2d_seg s = T->S[T->order[q]];
                const double *p = T->P + 2 * s.a, *r = T->P + 2 * s.b;
                double ax = p[0] - x, ay = p[1] - y, bx = r[0] - x, by = r[1] - y;
                w += atan2(ax * by - ay * bx, ax * bx + ay * by);
            }
            continue;
        }
        stack[top++] = nd->left;
        stack[top++] = nd->right;
    }
    return w / (2 * M_PI);
}

/* Winding number at a point. Where it comes out near 1/2 it is evaluated again
 * with clusters taken as dipoles only twice as far away, whose error is about
 * a quarter, until the value is clear of 1/2 by twice that error (or the
 * dipoles start beyond 32 radii, errors near 1e-4). */
static double w2_at(const w2_tree *T, double x, double y, size_t *evals)
{
    double beta = W2_BETA, flat = W2_FLAT;
    double w = w2_eval(T, x, y, beta);
    ++*evals;
    while (fabs(w - 0.5) < flat && beta < 32) {
        beta *= 2;
        flat /= 4;
        w = w2_eval(T, x, y, beta);
        ++*evals;
    }
    return w;
}

static inline long floordiv(long a, long b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

hv_status hv__sdf2d_winding_sign(const double *P, const sdf2d_seg *S, size_t ns, const int n[2],
                                 double h, const double org[2], const double *dist, int8_t *sg,
                                 size_t *evals_out)
{
    w2_tree T = {P, S, NULL, NULL, 0};
    T.order = malloc((ns ? ns : 1) * sizeof *T.order);
    T.nodes = malloc((2 * ns + 1) * sizeof *T.nodes);
    uint8_t *act[3] = {NULL, NULL, NULL};
    float *wc[3] = {NULL, NULL, NULL};
    hv_status st = HV_OK;
    size_t evals = 0;
    if (!T.order || !T.nodes) {
        st = hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the winding-number sign");
        goto out;
    }
    for (size_t k = 0; k < ns; k++)
        T.order[k] = (uint32_t)k;
    w2_build(&T, 0, (uint32_t)ns);
    long base[2];
    for (int a = 0; a < 2; a++) {
        double q = org[a] / h;
        base[a] = fabs(q) < 0x1p40 ? lround(q) : 0;
    }
    memset(sg, 0, (size_t)n[0] * n[1]);
    long r0[3][2];
    int nr[3][2];
    int nlev = 0;
    for (int s = W2_TOP; s >= 2; s /= 2, nlev++) {
        size_t nc = 1, nw = 1;
        for (int a = 0; a < 2; a++) {
            r0[nlev][a] = floordiv(base[a], s);
            nr[nlev][a] = (int)(floordiv(base[a] + n[a] - 1, s) - r0[nlev][a] + 1);
            nc *= (size_t)nr[nlev][a];
            nw *= (size_t)nr[nlev][a] + 1;
        }
        act[nlev] = calloc(nc, 1);
        wc[nlev] = malloc(nw * sizeof(float));
        if (!act[nlev] || !wc[nlev]) {
            st = hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the winding-number sign");
            goto out;
        }
        if (nlev == 0)
            memset(act[0], 1, nc);
    }
    for (int l = 0, s = W2_TOP; l < nlev; l++, s /= 2) {
        const int n0 = nr[l][0], n1 = nr[l][1], w0 = n0 + 1;
        for (int cy = 0; cy <= n1; cy++)
            for (int cx = 0; cx <= n0; cx++) {
                int need = 0;
                for (int q = 0; q < 4 && !need; q++) {
                    int rx = cx - (q & 1), ry = cy - (q >> 1);
                    if (rx >= 0 && ry >= 0 && rx < n0 && ry < n1)
                        need = act[l][rx + (size_t)n0 * ry];
                }
                float v = NAN;
                if (need) {
                    double x = org[0] + ((double)((r0[l][0] + cx) * s - base[0]) + 0.5) * h,
                           y = org[1] + ((double)((r0[l][1] + cy) * s - base[1]) + 0.5) * h;
                    v = (float)w2_at(&T, x, y, &evals);
                }
                wc[l][cx + (size_t)w0 * cy] = v;
            }
        const double dnear = fmax(W2_NEAR, W2_NEAR_REL * s) * h;
        for (int ry = 0; ry < n1; ry++)
            for (int rx = 0; rx < n0; rx++) {
                if (!act[l][rx + (size_t)n0 * ry])
                    continue;
                int lo[2], hi[2];
                const int r[2] = {rx, ry};
                for (int a = 0; a < 2; a++) {
                    long c0 = (r0[l][a] + r[a]) * s - base[a];
                    lo[a] = c0 < 0 ? 0 : (int)c0;
                    hi[a] = c0 + s > n[a] ? n[a] : (int)(c0 + s);
                }
                int side = 0;
                for (int q = 0; q < 4; q++) {
                    float v = wc[l][(rx + (q & 1)) + (size_t)w0 * (ry + (q >> 1))];
                    int sd = v > 0.5 + W2_MARGIN ? -1 : v < 0.5 - W2_MARGIN ? 1 : 0;
                    if (!sd || (side && sd != side)) {
                        side = 0;
                        break;
                    }
                    side = sd;
                }
                for (int j = lo[1]; j < hi[1] && side; j++)
                    for (int i = lo[0]; i < hi[0]; i++)
                        if (dist[i + (size_t)n[0] * j] < dnear) {
                            side = 0;
                            break;
                        }
                if (side) {
                    for (int j = lo[1]; j < hi[1]; j++)
                        memset(sg + lo[0] + (size_t)n[0] * j, side, (size_t)(hi[0] - lo[0]));
                } else if (l + 1 < nlev) {
                    for (int q = 0; q < 4; q++) {
                        long cx = (r0[l][0] + rx) * 2 + (q & 1) - r0[l + 1][0],
                             cy = (r0[l][1] + ry) * 2 + (q >> 1) - r0[l + 1][1];
                        if (cx >= 0 && cy >= 0 && cx < nr[l + 1][0] && cy < nr[l + 1][1])
                            act[l + 1][cx + (size_t)nr[l + 1][0] * cy] = 1;
                    }
                }
            }
    }
    for (int j = 0; j < n[1]; j++)
        for (int i = 0; i < n[0]; i++) {
            int8_t *c = sg + i + (size_t)n[0] * j;
            if (*c)
                continue;
            double x = org[0] + (i + 0.5) * h, y = org[1] + (j + 0.5) * h;
            *c = w2_at(&T, x, y, &evals) > 0.5 ? -1 : 1;
        }
out:
    for (int l = 0; l < 3; l++) {
        free(act[l]);
        free(wc[l]);
    }
    free(T.order);
    free(T.nodes);
    if (evals_out)
        *evals_out = evals;
    return st;
}
