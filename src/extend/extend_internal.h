/* Private: the extender and the pieces of the extension off a level set that
 * its files share: the pipeline (extend_vhm.c), the per-cell passes
 * (extend_eval.c), the levels' boxes, solvers and box solves
 * (extend_levels.c), the band solve (extend_band.c) and the OpenCL path
 * (extend_cl.c). Helpers called per cell from more than one file are static
 * inline here so that they stay inlined where they run. */
#ifndef HV_HEAT_EXTEND_INTERNAL_H
#define HV_HEAT_EXTEND_INTERNAL_H

#include "heatvox/heat.h"

#include <math.h>
#include <stddef.h>
#include <stdint.h>

#define MAX_LEVELS 8
/* Fields per hv_extend_many call (each takes up to 4 right-hand sides). */
#define MAX_FIELDS_PER_CALL 64
#define LEVEL_FACTOR 16.0
/* A level's solve covers the cells it must answer for plus BOX_MARGIN sqrt(t)
 * on every side: Neumann walls there reflect e^{-2 BOX_MARGIN} (6e-6) of what
 * reaches them. */
#define BOX_MARGIN 6.0
/* Ratios are trusted where the diffused weight is RELIABLE times the solve's
 * pointwise error bound (relres * ||rhs||_2; the heat operator's inverse has
 * norm <= 1). */
#define RELIABLE 1e3
/* |grad phi| must lie in this range for phi to be taken as a distance. */
/* Diffusion times up to BAND_MAX_T_SCALE h^2 are solved on the band in one
 * process (extend_band.c; longer ones by the box solve, which needs fewer
 * sweeps through a V-cycle), and with Jacobi-preconditioned CG on a DMDA
 * (extend_dmda.c). */
#define BAND_MAX_T_SCALE 8.0
#define GRAD_MIN 0.5
#define GRAD_MAX 1.5

/* Closest points past the box of a distributed extender (pending 3): a
 * cell whose closest point's interpolation stencil needs cells beyond a face
 * of its box that another rank owns reads them from their owners. The
 * stencil's corners are keys (global cell indices) of an open-addressing
 * table; slot s holds key[s] - 1 (0: empty), the level set there (phi[s]),
 * whether a closest point that passed its check reads it (read[s]), and
 * after level 0 the solutions there (sol[s * nsol + r]). */
typedef struct hv_extend_remote {
    int go[3], gn[3];  /* the box's first cell in the whole grid; the grid's size */
    uint8_t cut[3][2]; /* 1: the box's low / high face on axis a borders another rank */
    /* Where the box's level 0 is the one process's, on such a face: a point
     * p (box index space) with lo[a] <= p[a] <= hi[a] reads the box. */
    int lo[3], hi[3];
    size_t *key; /* cap slots */
    float *phi, *sol;
    uint8_t *read;
    size_t cap, used;
    size_t cells; /* the cells of pending 3 that passed the check */
} hv_extend_remote;

/* A distributed extension (extend_dmda.c): the extender works on one rank's
 * box with its ghost layer, and these make its decisions over all ranks and
 * solve its levels on the whole grid. */
typedef struct hv_extend_dist {
    void *user;
    /* The sum of v over the ranks, and the largest v (collective). */
    size_t (*sum)(void *user, size_t v);
    double (*max)(void *user, double v);
    /* 1: level 0 takes the band solve on this rank's box, whose ghost layer
     * holds everything the band solve of its own cells depends on. */
    int band0;
    /* Level l's solves of every right-hand side (the weights and the fields'
     * values on the box's cells) over all ranks; the solutions into e->sol on
     * every cell of the box, *thr as hv__extend_solve_level's (collective). */
    hv_status (*solve)(void *user, hv_extender *e, int l, int nrhs, int nfields,
                       const hv_extend_field *f, double *thr, hv_extend_stats *S);
    /* This rank's own cells in the box, inclusive: only they count as left
     * for a next level (the ghost layer's are other ranks'). */
    int own_lo[3], own_hi[3];
    /* NULL, or the closest points past the box: stage 0 (after the first
     * pass, before the band is built) fetches phi at their stencils from
     * the owners, checks them as hv__extend_classify checks the others
     * (hv__extend_remote_check), and marks the stencils of those that pass
     * in the owners' need (may be NULL); stage 1 (after level 0's solve)
     * fetches the solutions there into rem->sol (collective). */
    hv_extend_remote *rem;
    hv_status (*remote)(void *user, hv_extender *e, const float *phi, uint8_t *need, int stage);
} hv_extend_dist;

struct hv_extender {
    int dim, n[3];
    double h;
    size_t count;
    uint8_t *solid; /* owned copy or NULL */
    hv_extend_opts o;
    hv_solver *sv[MAX_LEVELS]; /* level l: t * 16^l, built on first use */
    int blo[MAX_LEVELS][3];    /* the box level l's solver was built for */
    int bn[MAX_LEVELS][3];
    double *fd, *ud; /* one right-hand side and solution (double) */
    float *w;        /* weights */
    /* Solutions of the current level, interleaved: right-hand side r of cell c
     * at c * nsol + r (a closest point's 8 corners then cost a few cache lines
     * for all fields). */
    float *sol;
    int nsol, capsol;
    float *bf, *bu0, *bu1;          /* band solve: right-hand sides and iterates, compact */
    size_t bcap;                    /* floats each of them holds */
    uint8_t *bneed, *bg0, *bg1;     /* band solve: cells read, growing buffers */
    uint8_t *pending;               /* per cell: 0 done, 1 read at the closest point, 2 at itself,
                                    3 at a closest point past the box (hv_extend_remote) */
    struct hv_extend_cl *cl;        /* backend opencl: the device path's state (extend_cl.h) */
    int resolved;                   /* o.backend resolved (AUTO: OPENCL on a GPU) */
    int auto_backend;               /* o.backend was AUTO (a device path may fall back) */
    struct hv_extend_sparse *sp;    /* hv_extend_tiles: maps and marks kept between calls
                                    (extend_tiles.c) */
    struct hv_extend_tiles_cl *tcl; /* hv_extend_tiles on the device: its maps and buffers
                                       (extend_tiles_cl.c), on cl's context */
    const hv_extend_dist *dist;     /* NULL, or the distributed extension's hooks */
};

/* ---- right-hand sides ----------------------------------------------------- */

/* Right-hand side r of the layout: 0 = weights; then per field, for a scalar
 * w f, for a vector w |v| followed by w v_c per component. rhs_part finds
 * which (field -1 for the weights; part 0 = |v|, c + 1 = component c). */
typedef struct {
    int field, part;
} rhs_part;

static inline rhs_part rhs_locate(int r, int nfields, const hv_extend_field *f)
{
    rhs_part p = {-1, 0};
    for (int i = 0, base = 1; i < nfields && r > 0; i++) {
        int k = f[i].ncomp == 1 ? 1 : f[i].ncomp + 1;
        if (r < base + k) {
            p.field = i;
            p.part = r - base;
            break;
        }
        base += k;
    }
    return p;
}

/* Right-hand side p at cell c. */
static inline double rhs_value(const hv_extender *e, const hv_extend_field *f, rhs_part p, size_t c)
{
    const double w = e->w[c];
    if (!(w > 0))
        return 0;
    if (p.field < 0)
        return w;
    const hv_extend_field *F = &f[p.field];
    if (F->ncomp == 1)
        return w * F->in[0][c];
    if (p.part > 0)
        return w * F->in[p.part - 1][c];
    double m = 0;
    for (int q = 0; q < F->ncomp; q++)
        m += (double)F->in[q][c] * F->in[q][c];
    return w * sqrt(m);
}

/* ---- boxes of cells --------------------------------------------------------- */

typedef struct {
    int lo[3], hi[3]; /* inclusive; lo > hi when empty */
} ibox;

static inline void box_empty(ibox *b)
{
    for (int a = 0; a < 3; a++) {
        b->lo[a] = 1 << 30;
        b->hi[a] = -(1 << 30);
    }
}

static inline void box_add(ibox *b, int i, int j, int k)
{
    const int p[3] = {i, j, k};
    for (int a = 0; a < 3; a++) {
        if (p[a] < b->lo[a])
            b->lo[a] = p[a];
        if (p[a] > b->hi[a])
            b->hi[a] = p[a];
    }
}

static inline void box_union(ibox *b, const ibox *o)
{
    for (int a = 0; a < 3; a++) {
        if (o->lo[a] < b->lo[a])
            b->lo[a] = o->lo[a];
        if (o->hi[a] > b->hi[a])
            b->hi[a] = o->hi[a];
    }
}

/* A difference of phi along one axis at a cell of value pc between vm and vp,
 * over two cells (the central difference's scale): the central difference,
 * or with upwind != 0, where |phi| grows across the cell along the axis, the
 * one-sided difference towards the neighbour of smaller |phi|, doubled.
 * Where a narrow-band level set is clamped, a cell next to the clamp has a
 * neighbour that holds the background rather than a distance, and its
 * central gradient is too short; the side towards the surface still
 * measures the distance. A clamped cell (|phi| equal to a neighbour's) and
 * a ridge (|phi| above both) keep the central difference. */
static inline double phi_diff2(double pc, double vm, double vp, int upwind)
{
    const double a = fabs(pc), am = fabs(vm), ap = fabs(vp);
    if (upwind && am < a && a < ap)
        return 2 * (pc - vm);
    if (upwind && ap < a && a < am)
        return 2 * (vp - pc);
    return vp - vm;
}

/* The closest point p (index space) of an interior cell (i,j,k) of a 3D grid
 * of spacing h from its phi pc and its six neighbours' (x-, x+, y-, y+, z-,
 * z+): central differences, upwind where they are too short or long; 0 when
 * |grad phi| stays outside [GRAD_MIN, GRAD_MAX]. The dense and the tiled
 * evaluations both take it, so that they read the same points bit for bit. */
static inline int hv__ext_closest_point(double pc, const double nb[6], double h, int i, int j,
                                        int k, double p[3])
{
    double gx = 0, gy = 0, gz = 0, gn = 0;
    for (int up = 0; up < 2; up++) { /* central, then upwind (phi_diff2) */
        gx = phi_diff2(pc, nb[0], nb[1], up);
        gy = phi_diff2(pc, nb[2], nb[3], up);
        gz = phi_diff2(pc, nb[4], nb[5], up);
        gn = sqrt(gx * gx + gy * gy + gz * gz) * (0.5 / h);
        if (gn >= GRAD_MIN && gn <= GRAD_MAX)
            break;
    }
    if (!(gn >= GRAD_MIN && gn <= GRAD_MAX))
        return 0;
    const double sc = pc * 0.5 / (gn * h * h);
    p[0] = i - sc * gx;
    p[1] = j - sc * gy;
    p[2] = k - sc * gz;
    return 1;
}

/* The trilinear stencil of point p on a grid of nn cells: its base corner f
 * (clamped so that f + 1 is in the grid) and the 8 weights, corner q at
 * f + (q & 1, q >> 1 & 1, q >> 2); 0 when p lies more than half a cell
 * outside. */
static inline int hv__ext_trilinear(const double p[3], const int nn[3], int f[3], double w[8])
{
    double fr[3];
    for (int a = 0; a < 3; a++) {
        if (p[a] < -0.5 || p[a] > nn[a] - 0.5)
            return 0;
        double q = p[a] < 0 ? 0 : p[a]; /* comparisons: fmin/fmax are libm calls here */
        if (q > nn[a] - 1)
            q = nn[a] - 1;
        f[a] = (int)q;
        if (f[a] > nn[a] - 2)
            f[a] = nn[a] - 2;
        fr[a] = q - f[a];
    }
    const double wx[2] = {1 - fr[0], fr[0]}, wy[2] = {1 - fr[1], fr[1]}, wz[2] = {1 - fr[2], fr[2]};
    for (int q = 0; q < 8; q++)
        w[q] = wx[q & 1] * wy[(q >> 1) & 1] * wz[q >> 2];
    return 1;
}

/* The trilinear (bilinear in 2D) stencil of p on a grid of nn cells, p
 * clamped to the grid: along each of the dim axes its base corner f, its
 * step d to the next corner (0 on an axis of one cell) and the fraction fr;
 * the axes past dim get 0. The walls' stencil of both evaluations. */
static inline void hv__ext_clamped(int dim, const int nn[3], const double p[3], int f[3], int d[3],
                                   double fr[3])
{
    for (int a = 0; a < 3; a++) {
        f[a] = d[a] = 0;
        fr[a] = 0;
    }
    for (int a = 0; a < dim; a++) {
        double q = p[a];
        if (q < 0)
            q = 0;
        if (q > nn[a] - 1)
            q = nn[a] - 1;
        int fl = (int)floor(q);
        if (fl > nn[a] - 2)
            fl = nn[a] - 2;
        if (fl < 0)
            fl = 0;
        f[a] = fl;
        d[a] = nn[a] > 1;
        fr[a] = nn[a] > 1 ? q - fl : 0;
    }
}

/* The residual f - A u along one x-run of a band solve (extend_band.c, and
 * its waves, extend_wave.c): len cells of R fields side by side in v and f,
 * the run's neighbours along y and z in nb[4] and along x at v[-R] and
 * v[len R], diagonal d and coupling s. Adds each field's squared residuals,
 * its largest |residual| and its squared right-hand side into acc[r],
 * acc[R + r] (a maximum) and acc[2 R + r]. */
static inline void hv__band_run_residual(const float *v, const float *f, const float *const nb[4],
                                         size_t len, int R, double d, double s, double *acc)
{
    for (size_t x = 0, y = 0; x < len; x++)
        for (int r = 0; r < R; r++, y++) {
            double sum =
                (double)nb[0][y] + nb[1][y] + nb[2][y] + nb[3][y] + v[(ptrdiff_t)y - R] + v[y + R];
            double res = f[y] - (d * (double)v[y] - s * sum);
            acc[r] += res * res;
            if (fabs(res) > acc[R + r])
                acc[R + r] = fabs(res);
            acc[2 * R + r] += (double)f[y] * f[y];
        }
}

/* ---- the per-cell passes (extend_eval.c) ------------------------------------ */

/* The first pass over the grid: the weights e->w (a smooth bump of
 * |phi| / (band h) on fluid cells), phi and the fields where they are read
 * (the weighted cells) checked for NaN/Inf, and the output cells classified in
 * e->pending: 0 = background, 1 = read at the closest point, 2 = read at the
 * cell. *wbox boxes the weighted cells, *rbox the cells read at themselves.
 * need (NULL: none) receives the band solve's cells: the weights and the
 * closest points' stencils. Counts the weighted cells (*nsrc) and the output
 * cells (*npend). HV_ERR_NUMERIC for a non-finite phi or field value where it
 * is read; nothing is written to the outputs (they may alias the inputs). */
hv_status hv__extend_classify(hv_extender *e, const float *phi, int nfields,
                              const hv_extend_field *f, uint8_t *need, size_t *nsrc, size_t *npend,
                              ibox *wbox, ibox *rbox);

/* The background on the output cells that no level will write (pending 0). */
void hv__extend_fill_background(const hv_extender *e, int nfields, const hv_extend_field *f);

/* Distributed (e->dist->rem): the table of the corners that this rank's
 * cells of pending 3 read, rebuilt (HV_ERR_NOMEM when it cannot grow). */
hv_status hv__extend_remote_collect(hv_extender *e, const float *phi);

/* Once rem->phi holds phi at every corner: a cell of pending 3 whose closest
 * point fails the check of hv__extend_classify (|phi| there above half the
 * band) is read at itself (pending 2, need[c] set when need is not NULL);
 * the corners of the others are marked in rem->read. */
void hv__extend_remote_check(hv_extender *e, const float *phi, uint8_t *need);

/* Counts of one level's evaluation pass. */
typedef struct {
    size_t left, cp, ratio, weak;
} hv_extend_counts;

/* Reads the current level's solutions (e->sol) for every pending cell: at its
 * closest point, or at the cell where the closest point has no weight (or
 * phi is not a distance there), writing the outputs where the weight is above
 * thr (or, on the last level, anywhere: the background where it is 0).
 * trusted (NULL: every cell) marks the cells the level's solve answers for.
 * *rbox receives the box of the cells left for the next level. */
void hv__extend_eval_level(hv_extender *e, const float *phi, int nfields, const hv_extend_field *f,
                           double thr, int last, const uint8_t *trusted, ibox *rbox,
                           hv_extend_counts *n);

/* ---- the levels (extend_levels.c) ------------------------------------------- */

/* The box of level l as the level loop of hv_extend_many forms it: the box of
 * the cells with a weight (wlo..whi, inclusive) grown by 2 (the closest
 * points' stencils), joined with the box of the cells read at themselves
 * (rlo..rhi; lo > hi when empty), grown by BOX_MARGIN sqrt(t_l) voxels and
 * then to a size the solvers like, within the grid: corner lo, size bn. */
void hv__extend_level_box(const hv_extender *e, const int wlo[3], const int whi[3],
                          const int rlo[3], const int rhi[3], int l, int lo[3], int bn[3]);

/* The solver of diffusion level l (t_scale h^2 16^l) on the box [lo, lo + bn)
 * (Neumann walls at its faces), for `backend`: *sv is kept while the box keeps
 * its size and, with solid cells, its place (blo, bnk: the box it was made
 * for), and rebuilt otherwise. Shared by the host and device paths. */
hv_status hv__extend_level_solver(int dim, const int n[3], double h, const uint8_t *solid,
                                  const hv_extend_opts *o, hv_backend backend, int l,
                                  const int lo[3], const int bn[3], hv_solver **sv, int blo[3],
                                  int bnk[3]);

/* Solves every right-hand side (nrhs = e->nsol) for level l on the box
 * [lo, lo + bn) and stores the solutions in e->sol, 0 outside the box; *thr
 * is the level's trust bound for the weight. */
hv_status hv__extend_solve_level(hv_extender *e, int l, const int lo[3], const int bn[3], int nrhs,
                                 int nfields, const hv_extend_field *f, double *thr,
                                 hv_extend_stats *S);

/* ---- the band solve (extend_band.c) ----------------------------------------- */

/* The first level's cells near what is read, for the Chebyshev band solve;
 * built by hv__extend_band_build, on the stack of hv_extend_many. */
typedef struct hv_extend_band hv_extend_band;
typedef struct xrun xrun; /* x-runs of band cells and their segments (extend_band.c) */
typedef struct bseg bseg;

struct hv_extend_band {
    xrun *runs;
    size_t nruns, cells;
    uint8_t *need; /* the cells read (before growing): trusted at level 0 */
    size_t *roff;  /* compact cell of run q's left ghost; its cells follow */
    bseg *segs;
    size_t nsegs;
    size_t *kstart;  /* segments of plane k: kstart[k] .. kstart[k + 1] - 1 */
    size_t zero;     /* compact cell of the zero block (nx cells) */
    size_t ncompact; /* compact cells in all */
    int R;           /* right-hand sides, side by side */
    float *f, *u0, *u1;
    float *sol; /* after the sweeps: the solutions (u0 or u1) */
    int iters;
    double s; /* diffusion time in units of h^2 */
};

/* Whether hv_extend_many may solve the first level on a band: short times,
 * no obstacles, CPU backends only (an explicit fftw or opencl backend gets its
 * own solver), box_only off. */
int hv__extend_band_allowed(const hv_extender *e);

/* Builds the band from b->need for the diffusion time s h^2: grown by
 * BOX_MARGIN sqrt(s) voxels, cut into x-runs and segments, laid out compactly
 * for R right-hand sides. Returns 0 (and frees nothing) when the band is not
 * worth it (more than half of box_cells), 1 when built, -1 when out of
 * memory. */
int hv__extend_band_build(hv_extender *e, hv_extend_band *b, size_t box_cells, int R, double s);

/* The Chebyshev sweeps of a band solve for the diffusion time s h^2. */
int hv__extend_band_iters(const hv_extender *e, double s);

/* Whether a band solve may serve diffusion level l (t_scale 16^l h^2). */
int hv__extend_band_level_allowed(const hv_extender *e, int l);

/* The last level hv_extend_many and hv_extend_tiles run when the output is a
 * band of ob voxels (ob > 0): the first whose reach sqrt(t_l) covers the
 * output band beyond the weights, within max_levels. */
int hv__extend_last_level(const hv_extender *e, double ob);
void hv__extend_band_free(hv_extend_band *b);

/* Level 0 on the band: every right-hand side at once; solutions stored in
 * e->sol on the band's cells; *thr as hv__extend_solve_level's. */
hv_status hv__extend_band_solve(hv_extender *e, hv_extend_band *b, int nfields,
                                const hv_extend_field *f, double *thr, hv_extend_stats *S);

/* ---- narrow bands as tiles (extend_tiles.c, extend_wave.c) ------------------- */

void hv__extend_sparse_destroy(struct hv_extend_sparse **sp);

/* HV_OK when e takes tiles (3D, no solid cells), else HV_ERR_INVALID_ARG. */
hv_status hv__extend_tiles_check(const hv_extender *e);

/* e->o.backend resolved once (AUTO: opencl on a GPU, e->auto_backend set). */
void hv__extend_resolve_backend(hv_extender *e);

/* A set of cells as x-runs per row, on the planes k0 <= k < k1: the runs of
 * row (j, k) are x[2 q] <= x < x[2 q + 1] for first[r] <= q < first[r + 1],
 * r = j + ny (k - k0), sorted and apart. */
typedef struct hv_xrows {
    int k0, k1;
    size_t *first;
    int32_t *x;
    size_t nruns;
} hv_xrows;

/* The run of row (j, k) holding x, or -1. */
static inline long hv__xrows_find(const hv_xrows *s, int ny, int j, int k, int x)
{
    if (k < s->k0 || k >= s->k1)
        return -1;
    const size_t r = (size_t)j + (size_t)ny * (k - s->k0);
    for (size_t q = s->first[r]; q < s->first[r + 1]; q++) {
        if (x < s->x[2 * q])
            return -1;
        if (x < s->x[2 * q + 1])
            return (long)q;
    }
    return -1;
}

/* The right-hand sides of cells x0 <= x < x1 of row (j, k), R per cell. */
typedef void (*hv_extend_rhs_fn)(const void *ctx, int j, int k, int x0, int x1, float *dst);

/* The band solve (hv__extend_band_solve's sweeps: the same coefficients and
 * arithmetic, so the same values) of R right-hand sides for the diffusion time
 * s h^2 on the cells of dom, as a wave through its planes: sweep t of plane k
 * runs once sweep t - 1 of planes k - 1 .. k + 1 is done, so only the planes
 * the wave is crossing are held (about the sweep count), whatever the band's
 * size. sol receives the solutions at the cells of need (a subset of dom), R
 * per cell in need's order; *thr as hv__extend_band_solve's. S: solves,
 * relres, solve work in work_bytes (the larger). */
hv_status hv__extend_wave_solve(const hv_extender *e, const hv_xrows *dom, const hv_xrows *need,
                                double s, int R, hv_extend_rhs_fn rhs, const void *ctx, float *sol,
                                double *thr, hv_extend_stats *S);

#endif
