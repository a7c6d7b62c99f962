/*
 * Fast generalized winding number (Jacobson et al. 2013; Barill et al.,
 * "Fast winding numbers for soups and clouds", 2018): a bounding-volume
 * hierarchy over triangles whose far clusters are replaced by their dipole
 * term, (sum of vector areas) . (c - p) / (4 pi |c - p|^3); near leaves sum
 * exact solid angles (Van Oosterom & Strackee 1983).
 */
#include "winding.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define WN_LEAF 8
#define WN_BETA 2.5

static void face_info(const hv_wn_tree *W, uint32_t f, double c[3], double N[3], double *area)
{
    const uint32_t *t = W->T + 3 * (size_t)f;
    const double *a = W->V + 3 * (size_t)t[0], *b = W->V + 3 * (size_t)t[1],
                 *d = W->V + 3 * (size_t)t[2];
    double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]},
           v[3] = {d[0] - a[0], d[1] - a[1], d[2] - a[2]};
    N[0] = 0.5 * (u[1] * v[2] - u[2] * v[1]);
    N[1] = 0.5 * (u[2] * v[0] - u[0] * v[2]);
    N[2] = 0.5 * (u[0] * v[1] - u[1] * v[0]);
    *area = sqrt(N[0] * N[0] + N[1] * N[1] + N[2] * N[2]);
    for (int k = 0; k < 3; k++)
        c[k] = (a[k] + b[k] + d[k]) / 3.0;
}

/* Centroid, vector area and area of the face at each position of order[],
 * computed once and permuted along with it. */
typedef struct finfo {
    double c[3], N[3], a;
} finfo;

/* Fills node nd over order[first, first + count) and, unless it is a leaf,
 * partitions that range at the middle of its centroids' longest extent;
 * returns the split (0 for a leaf). */
static size_t make_node(hv_wn_tree *W, finfo *F, hv_wn_node *nd, size_t first, size_t count)
{
    memset(nd, 0, sizeof *nd);
    nd->first = first;
    nd->count = count;
    nd->left = nd->right = -1;
    double asum = 0, lo[3] = {INFINITY, INFINITY, INFINITY},
           hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t q = first; q < first + count; q++) {
        const finfo *f = &F[q];
        double s = W->sign[q];
        for (int k = 0; k < 3; k++) {
            nd->N[k] += s * f->N[k];
            nd->c[k] += f->a * f->c[k];
            lo[k] = f->c[k] < lo[k] ? f->c[k] : lo[k];
            hi[k] = f->c[k] > hi[k] ? f->c[k] : hi[k];
        }
        asum += f->a;
    }
    for (int k = 0; k < 3; k++)
        nd->c[k] = asum > 0 ? nd->c[k] / asum : 0.5 * (lo[k] + hi[k]);
    double r2 = 0;
    for (size_t q = first; q < first + count; q++)
        for (int v = 0; v < 3; v++) {
            const double *x = W->V + 3 * (size_t)W->T[3 * (size_t)W->order[q] + v];
            double d2 = (x[0] - nd->c[0]) * (x[0] - nd->c[0]) +
                        (x[1] - nd->c[1]) * (x[1] - nd->c[1]) +
                        (x[2] - nd->c[2]) * (x[2] - nd->c[2]);
            r2 = d2 > r2 ? d2 : r2;
        }
    nd->r = sqrt(r2);
    if (count <= WN_LEAF)
        return 0;
    int ax = 0;
    for (int k = 1; k < 3; k++)
        if (hi[k] - lo[k] > hi[ax] - lo[ax])
            ax = k;
    double mid = 0.5 * (lo[ax] + hi[ax]);
    size_t i = first, j = first + count;
    while (i < j) {
        if (F[i].c[ax] < mid) {
            i++;
        } else {
            j--;
            uint32_t t = W->order[i];
            W->order[i] = W->order[j];
            W->order[j] = t;
            signed char sg = W->sign[i];
            W->sign[i] = W->sign[j];
            W->sign[j] = sg;
            finfo ft = F[i];
            F[i] = F[j];
            F[j] = ft;
        }
    }
    if (i == first || i == first + count)
        i = first + count / 2;
    return i;
}

/* The subtree over [first, first + count) into nodes[*nn...], depth first;
 * returns its root's index. */
static int build(hv_wn_tree *W, finfo *F, hv_wn_node *nodes, int *nn, size_t first, size_t count)
{
    int id = (*nn)++;
    size_t i = make_node(W, F, &nodes[id], first, count);
    if (!i)
        return id;
    int l = build(W, F, nodes, nn, first, i - first);
    int r = build(W, F, nodes, nn, i, first + count - i);
    nodes[id].left = l;
    nodes[id].right = r;
    return id;
}

/* The whole tree: the root's two subtrees are built side by side into
 * arrays of their own, then laid out after the root, left then right, as
 * the serial build lays them out (the same tree, node for node). */
static hv_status build_tree(hv_wn_tree *W, finfo *F, size_t nfaces)
{
    W->nnodes = 1;
    size_t i = make_node(W, F, &W->nodes[0], 0, nfaces);
    if (!i)
        return HV_OK;
    const size_t nl = i, nr = nfaces - i;
    hv_wn_node *L = malloc((2 * nl + 1) * sizeof *L), *R = malloc((2 * nr + 1) * sizeof *R);
    if (!L || !R) {
        free(L);
        free(R);
        W->nnodes = 1;
        W->nodes[0].left = build(W, F, W->nodes, &W->nnodes, 0, nl);
        W->nodes[0].right = build(W, F, W->nodes, &W->nnodes, i, nr);
        return HV_OK;
    }
    int cl = 0, cr = 0;
#pragma omp parallel sections num_threads(2)
    {
#pragma omp section
        build(W, F, L, &cl, 0, nl);
#pragma omp section
        build(W, F, R, &cr, i, nr);
    }
    for (int k = 0; k < cl; k++) {
        W->nodes[1 + k] = L[k];
        if (L[k].left >= 0) {
            W->nodes[1 + k].left += 1;
            W->nodes[1 + k].right += 1;
        }
    }
    for (int k = 0; k < cr; k++) {
        W->nodes[1 + cl + k] = R[k];
        if (R[k].left >= 0) {
            W->nodes[1 + cl + k].left += 1 + cl;
            W->nodes[1 + cl + k].right += 1 + cl;
        }
    }
    W->nodes[0].left = 1;
    W->nodes[0].right = 1 + cl;
    W->nnodes = 1 + cl + cr;
    free(L);
    free(R);
    return HV_OK;
}

hv_status hv__wn_build(hv_wn_tree *W, const double *V, const uint32_t *T, const uint32_t *faces,
                       size_t nfaces, const uint8_t *flip)
{
    memset(W, 0, sizeof *W);
    W->V = V;
    W->T = T;
    W->order = malloc((nfaces ? nfaces : 1) * sizeof *W->order);
    W->sign = malloc(nfaces ? nfaces : 1);
    W->nodes = malloc((2 * nfaces + 1) * sizeof *W->nodes);
    finfo *F = malloc((nfaces ? nfaces : 1) * sizeof *F);
    if (!W->order || !W->sign || !W->nodes || !F) {
        free(F);
        hv__wn_free(W);
        return hv__error(HV_ERR_NOMEM, "winding number: out of memory for %zu faces", nfaces);
    }
    for (size_t q = 0; q < nfaces; q++) {
        W->order[q] = faces[q];
        W->sign[q] = (signed char)(flip && flip[faces[q]] ? -1 : 1);
        face_info(W, faces[q], F[q].c, F[q].N, &F[q].a);
    }
    if (nfaces)
        build_tree(W, F, nfaces);
    free(F);
    return HV_OK;
}

void hv__wn_free(hv_wn_tree *W)
{
    free(W->order);
    free(W->sign);
    free(W->nodes);
    memset(W, 0, sizeof *W);
}

static double solid_angle(const double p[3], const double *a, const double *b, const double *c)
{
    double A[3], B[3], C[3];
    for (int d = 0; d < 3; d++) {
        A[d] = a[d] - p[d];
        B[d] = b[d] - p[d];
        C[d] = c[d] - p[d];
    }
    double la = sqrt(A[0] * A[0] + A[1] * A[1] + A[2] * A[2]);
    double lb = sqrt(B[0] * B[0] + B[1] * B[1] + B[2] * B[2]);
    double lc = sqrt(C[0] * C[0] + C[1] * C[1] + C[2] * C[2]);
    double det = A[0] * (B[1] * C[2] - B[2] * C[1]) - A[1] * (B[0] * C[2] - B[2] * C[0]) +
                 A[2] * (B[0] * C[1] - B[1] * C[0]);
    double den = la * lb * lc + (A[0] * B[0] + A[1] * B[1] + A[2] * B[2]) * lc +
                 (A[0] * C[0] + A[1] * C[1] + A[2] * C[2]) * lb +
                 (B[0] * C[0] + B[1] * C[1] + B[2] * C[2]) * la;
    return 2.0 * atan2(det, den);
}

double hv__wn_eval(const hv_wn_tree *W, const double p[3], uint32_t skip)
{
    return hv__wn_eval_beta(W, p, skip, WN_BETA);
}

double hv__wn_eval_beta(const hv_wn_tree *W, const double p[3], uint32_t skip, double beta)
{
    if (!W->nnodes)
        return 0;
    int stack[128], top = 0;
    double w = 0;
    stack[top++] = 0;
    while (top) {
        const hv_wn_node *nd = &W->nodes[stack[--top]];
        double d[3] = {nd->c[0] - p[0], nd->c[1] - p[1], nd->c[2] - p[2]};
        double dist = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        if (dist > beta * nd->r) {
            w += (nd->N[0] * d[0] + nd->N[1] * d[1] + nd->N[2] * d[2]) / (dist * dist * dist);
            continue;
        }
        if (nd->left < 0 || top > 120) {
            for (size_t q = nd->first; q < nd->first + nd->count; q++) {
                uint32_t f = W->order[q];
                if (f == skip)
                    continue;
                const uint32_t *t = W->T + 3 * (size_t)f;
                w += W->sign[q] * solid_angle(p, W->V + 3 * (size_t)t[0], W->V + 3 * (size_t)t[1],
                                              W->V + 3 * (size_t)t[2]);
            }
            continue;
        }
        stack[top++] = nd->left;
        stack[top++] = nd->right;
    }
    return w / (4 * M_PI);
}
