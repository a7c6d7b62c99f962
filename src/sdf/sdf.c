/*
 * The signed heat method on a cell-centred grid (Feng & Crane 2024), with the
 * grid-specific choices described in docs/METHOD.md ("Discretization",
 * "Signed heat method"):
 *   - t tied to the grid, t = (t_scale h)^2, not to the mesh's edge lengths;
 *   - the normalized field lives on cell faces (MAC) and the Poisson operator
 *     is exactly div(grad), which keeps the zero set in place;
 *   - far from the surface the diffused field decays like e^{-r/sqrt(t)} below
 *     solver accuracy; faces where it has are either served by a longer
 *     diffusion (far levels, t x16 each) or left with X = 0, where phi is then
 *     harmonic and keeps the sign of its surroundings (maximum principle);
 *   - by default |phi| is replaced by the exact distance to the triangles and
 *     the heat method supplies only the sign, its robust part.
 */
#include "sdf_cl.h"
#include "sdf_internal.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* Peak bytes per cell, for hv_check_dims, measured on stanford-bunny (peak
 * RSS less the process's own 40 MB): the exact distance with the
 * winding-number sign or unsigned, 20 at 256^3 and 512^3 (output, distance,
 * nearest triangle, the raster's packed minimum, the sign); the heat method
 * on its grid about 80 more per heat-grid cell plus 12 per diffusion level
 * (98 per cell all told at 160^3 uncoarsened, 120 with --heat and its far
 * levels at 256^3). */
#define SDF_EXACT_BYTES 24
#define SDF_HEAT_BYTES 80
/* Rasterization radius of the exact distance, in voxels. */
#define SDF_EXACT_BAND 2.0
/* Narrow bands up to this many voxels are rasterized whole. */
#define SDF_RASTER_MAX 4.0

void hv_sdf_opts_default(hv_sdf_opts *o)
{
    memset(o, 0, sizeof *o);
    o->res = 128;
    o->pad = 4;
    o->round_to = 8;
    o->magnitude = HV_SDF_EXACT;
    o->t_scale = 1.0;
    o->far_levels = -1;
    o->local_shift = 1;
    o->max_hole = 0.5;
    o->near_sign = 1.0;
    o->repair = HV_SDF_REPAIR_ALL;
    o->backend = HV_BACKEND_AUTO;
    o->diffuse_tol = 0; /* auto, see resolve_auto */
    o->poisson_tol = 0;
    o->heat_coarsen = 0;
}

/* Tolerances. Where the heat method only decides the sign (exact magnitude,
 * signed), phi's value never reaches the output: what matters is where it
 * changes sign, and that moves by about the solve error over |grad phi| = 1,
 * far below a voxel at these tolerances. The diffused field is normalized, so
 * its relative error stays at the tolerance where it is above the noise
 * threshold (faces below SDF_NOISE_FACTOR times the error bound count as
 * decayed, X = 0), and the local shift's reach follows it too: on
 * bun_zipper_res4 at 64^3 (holes) inside-IoU beyond 1 voxel was 0.99949 at
 * 1e-10, 0.99946 at 1e-6, 0.99868 at 1e-5. 1e-6 (heat) and 1e-4 (Poisson)
 * let FFTW use single-precision transforms (relres ~6e-7 for the heat solves,
 * ~1e-5 for the Poisson solve) and multigrid stop after a few cycles. Where phi is the
 * output (HV_SDF_HEAT, unsigned), the tight tolerances stay. Every backend
 * gets the same tolerances. The heat grid: coarsening by 2 only on large
 * grids, where the solves would otherwise dominate; within a voxel of the
 * surface the sign then comes from pseudonormals where the mesh is clean
 * (on the bunny at 256^3, 73 of 13.6 M cells change sign against the full-
 * resolution heat method, all near its filled holes, where the winding
 * number sides with the coarse grid in 43 of them). */
#define SDF_SIGN_TOL 1e-6
#define SDF_SIGN_POISSON_TOL 1e-4
#define SDF_COARSEN_CELLS ((size_t)1 << 22)
static void resolve_auto(hv_sdf_opts *o)
{
    const int sign_only = o->magnitude == HV_SDF_EXACT && !o->unsigned_distance;
    if (o->diffuse_tol == 0)
        o->diffuse_tol = sign_only ? SDF_SIGN_TOL : 1e-10;
    if (o->poisson_tol == 0)
        o->poisson_tol = sign_only ? SDF_SIGN_POISSON_TOL : 1e-8;
}

int hv__sdf_heat_factor(const hv_sdf_opts *o, const int n[3])
{
    if (o->magnitude != HV_SDF_EXACT || o->unsigned_distance)
        return 1;
    if (o->heat_coarsen > 0)
        return o->heat_coarsen;
    return (size_t)n[0] * n[1] * n[2] > SDF_COARSEN_CELLS ? 2 : 1;
}

hv_status hv__sdf_check_opts(const hv_sdf_opts *o)
{
    if (!(o->voxel_size >= 0) || !isfinite(o->voxel_size))
        return hv__error(HV_ERR_INVALID_ARG, "sdf: voxel size must be positive and finite, got %g",
                         o->voxel_size);
    if (o->voxel_size == 0 && o->res <= 0)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: resolution must be positive, got %d", o->res);
    if (o->pad < 0)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: padding must be >= 0 cells, got %d", o->pad);
    if (!o->use_bbox && o->voxel_size == 0 && o->res <= 2 * o->pad)
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf: resolution %d leaves no cells inside a padding of %d on each side",
                         o->res, o->pad);
    if (o->round_to < 0 || o->round_to > 64)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: round_to must be in [0, 64], got %d",
                         o->round_to);
    if (!(o->t_scale > 0) || !isfinite(o->t_scale) || o->t_scale > 1e4)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: t scale must be in (0, 1e4], got %g",
                         o->t_scale);
    if (o->far_levels < -1 || o->far_levels > 8)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: far levels must be in [-1, 8], got %d",
                         o->far_levels);
    if (o->magnitude != HV_SDF_EXACT && o->magnitude != HV_SDF_HEAT)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: unknown magnitude mode %d", (int)o->magnitude);
    if (!(o->max_hole >= 0) || !isfinite(o->max_hole))
        return hv__error(HV_ERR_INVALID_ARG, "sdf: max hole size must be finite and >= 0, got %g",
                         o->max_hole);
    if (o->repair & ~(unsigned)(HV_SDF_REPAIR_ALL | HV_SDF_REPAIR_DOMED_CAPS))
        return hv__error(HV_ERR_INVALID_ARG, "sdf: unknown repair flags 0x%x", o->repair);
    if (!(o->diffuse_tol == 0 || (o->diffuse_tol >= 1e-12 && o->diffuse_tol < 1)) ||
        !(o->poisson_tol == 0 || (o->poisson_tol >= 1e-12 && o->poisson_tol < 1)))
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf: tolerances must be 0 (auto) or in [1e-12, 1), got %g and %g",
                         o->diffuse_tol, o->poisson_tol);
    if (o->heat_coarsen < 0 || o->heat_coarsen > 4)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: heat coarsening must be in [0, 4], got %d",
                         o->heat_coarsen);
    if (!(o->near_sign >= 0) || o->near_sign > 16)
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf: near-sign width must be in [0, 16] voxels, got %g", o->near_sign);
    if (o->sign != HV_SDF_SIGN_AUTO && o->sign != HV_SDF_SIGN_HEAT &&
        o->sign != HV_SDF_SIGN_WINDING)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: unknown sign source %d", (int)o->sign);
    if (o->orient != HV_ORIENT_AUTO && o->orient != HV_ORIENT_GIVEN &&
        o->orient != HV_ORIENT_RECOVER)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: unknown orientation source %d", (int)o->orient);
    if (o->sign == HV_SDF_SIGN_WINDING && o->magnitude == HV_SDF_EXACT && !o->unsigned_distance &&
        (o->repair & (HV_SDF_REPAIR_ORIENT | HV_SDF_REPAIR_OUTWARD)) !=
            (HV_SDF_REPAIR_ORIENT | HV_SDF_REPAIR_OUTWARD))
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf: the winding-number sign needs the repair's orientation steps "
                         "(a mesh as given may be oriented any way)");
    if (o->threads < 0 || o->threads > HV_MAX_THREADS)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: thread count must be in [0, %d], got %d",
                         HV_MAX_THREADS, o->threads);
    if (o->use_bbox) {
        for (int a = 0; a < 6; a++)
            if (!isfinite(o->bbox[a]))
                return hv__error(HV_ERR_INVALID_ARG,
                                 "sdf: bounding box coordinate %d is not finite", a);
        for (int a = 0; a < 3; a++)
            if (!(o->bbox[3 + a] > o->bbox[a]))
                return hv__error(HV_ERR_INVALID_ARG,
                                 "sdf: bounding box is empty along %c (%g to %g)", "xyz"[a],
                                 o -> bbox[a], o -> bbox[3 + a]);
    }
    return hv__sdf_morph_check(o);
}

/* Mesh bounds grown by what the morphology may add to the shape. */
static void grow_bounds(const hv_sdf_opts *o, double lo[3], double hi[3])
{
    const double g = hv__sdf_morph_growth(o);
    for (int a = 0; a < 3; a++) {
        lo[a] -= g;
        hi[a] += g;
    }
}

/* Bounds of the vertices used by triangles; checks indices and finiteness. */
static hv_status used_bounds(const hv_mesh *m, double lo[3], double hi[3])
{
    if (!m || m->ntris == 0 || m->nverts == 0 || !m->tris || !m->verts)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: the mesh is empty (%zu vertices, %zu triangles)",
                         m ? m->nverts : 0, m ? m->ntris : 0);
    for (int a = 0; a < 3; a++)
        lo[a] = INFINITY, hi[a] = -INFINITY;
    for (size_t i = 0; i < 3 * m->ntris; i++) {
        uint32_t v = m->tris[i];
        if (v >= m->nverts)
            return hv__error(HV_ERR_INVALID_ARG, "sdf: triangle %zu uses vertex %u of %zu", i / 3,
                             v, m->nverts);
        const double *x = m->verts + 3 * (size_t)v;
        for (int a = 0; a < 3; a++) {
            if (!isfinite(x[a]))
                return hv__nonfinite_vertex_error(m, "sdf", v, x[a]);
            lo[a] = x[a] < lo[a] ? x[a] : lo[a];
            hi[a] = x[a] > hi[a] ? x[a] : hi[a];
        }
    }
    return HV_OK;
}

static int levels_for(const hv_sdf_opts *oin, const int n[3])
{
    hv_sdf_opts ro = *oin, *o = &ro;
    resolve_auto(o);
    if (o->far_levels >= 0)
        return 1 + o->far_levels;
    if (o->magnitude == HV_SDF_EXACT && !o->unsigned_distance)
        return 1;
    /* The field stays above the solver's error bound for roughly
     * r < sqrt(t) ln(1/tol) / 2 (measured margin); add levels until that
     * covers the block's diagonal. */
    double diag = sqrt((double)n[0] * n[0] + (double)n[1] * n[1] + (double)n[2] * n[2]);
    double reach = o->t_scale * 0.5 * log(1.0 / o->diffuse_tol);
    int L = 1;
    while (reach < diag && L < 9) {
        reach *= 4;
        L++;
    }
    return L;
}

/* The block for mesh bounds lo, hi: cell counts, voxel size, origin. */
hv_status hv__sdf_grid_place(const hv_sdf_opts *opts, const double lo[3], const double hi[3],
                             int n[3], double *h, double origin[3])
{
    if (opts->use_bbox) {
        const double *b = opts->bbox;
        double L = fmax(b[3] - b[0], fmax(b[4] - b[1], b[5] - b[2]));
        *h = opts->voxel_size > 0 ? opts->voxel_size : L / opts->res;
        for (int a = 0; a < 3; a++) {
            double c = ceil((b[3 + a] - b[a]) / *h - 1e-9);
            if (!(c < 1e9))
                return hv__error(HV_ERR_INVALID_ARG, "sdf: voxel size %g gives %g cells along %c",
                                 *h, c, "xyz"[a]);
            n[a] = c < 1 ? 1 : (int)c;
            origin[a] = b[a];
        }
    } else {
        double L = fmax(hi[0] - lo[0], fmax(hi[1] - lo[1], hi[2] - lo[2]));
        if (opts->voxel_size > 0)
            *h = opts->voxel_size;
        else if (L > 0)
            *h = L / (opts->res - 2 * opts->pad);
        else
            return hv__error(
                HV_ERR_INVALID_ARG,
                "sdf: the mesh has no extent (all vertices at one point); give a voxel size");
        int longest = (hi[0] - lo[0] == L) ? 0 : (hi[1] - lo[1] == L) ? 1 : 2;
        for (int a = 0; a < 3; a++) {
            double c = ceil((hi[a] - lo[a]) / *h - 1e-9) + 2.0 * opts->pad;
            if (!(c < 1e9))
                return hv__error(HV_ERR_INVALID_ARG, "sdf: voxel size %g gives %g cells along %c",
                                 *h, c, "xyz"[a]);
            n[a] = c < 1 ? 1 : (int)c;
            /* Extra padding for multigrid; the longest axis keeps --res exactly. */
            int r = opts->round_to > 1 ? opts->round_to : 1;
            if (r > 1 && !(opts->voxel_size == 0 && a == longest) && n[a] % r)
                n[a] += r - n[a] % r;
            origin[a] = 0.5 * (lo[a] + hi[a]) - 0.5 * n[a] * *h;
        }
    }
    return HV_OK;
}

hv_status hv_sdf_grid_for_mesh(const hv_mesh *m, const hv_sdf_opts *opts, int n[3], double *h,
                               double origin[3])
{
    hv_sdf_opts def;
    if (!opts) {
        hv_sdf_opts_default(&def);
        opts = &def;
    }
    if (!n || !h || !origin)
        return hv__error(HV_ERR_INVALID_ARG, "hv_sdf_grid_for_mesh: NULL output");
    hv_status st = hv__sdf_check_opts(opts);
    double lo[3], hi[3];
    if (st || (st = used_bounds(m, lo, hi)))
        return st;
    grow_bounds(opts, lo, hi);
    if ((st = hv__sdf_grid_place(opts, lo, hi, n, h, origin)))
        return st;
    /* The heat method runs unless the sign is the winding number's or the
     * distance is exact and unsigned; AUTO may run it. */
    const int exact = opts->magnitude == HV_SDF_EXACT;
    const int heat = !(exact && (opts->unsigned_distance || opts->sign == HV_SDF_SIGN_WINDING));
    size_t per = exact ? SDF_EXACT_BYTES : 0;
    if (heat) {
        const int f = hv__sdf_heat_factor(opts, n);
        int nh[3];
        for (int a = 0; a < 3; a++)
            nh[a] = (n[a] + f - 1) / f;
        per += (SDF_HEAT_BYTES + 12 * (size_t)levels_for(opts, nh) + (size_t)f * f * f - 1) /
               ((size_t)f * f * f);
    }
    return hv_check_dims(3, n, *h, per);
}

typedef struct sdf_work {
    hv_mesh *repaired;
    hv_quad q;
    float *dist;
    uint32_t *tri;
    hv_grid *g;  /* the output grid */
    hv_grid *gh; /* the heat method's grid when it is not g */
} sdf_work;

static void work_free(sdf_work *w)
{
    hv_mesh_destroy(&w->repaired);
    hv__quad_free(&w->q);
    hv_free(w->dist);
    hv_free(w->tri);
    hv_grid_destroy(&w->g);
    hv_grid_destroy(&w->gh);
}

static hv_status stage(double f, const char *name) { return hv__progress(f, name); }

/* HV_SDF_SIGN_AUTO: the heat method's sign depends on where the block ends
 * when the repaired mesh is still open (its inside runs out of a wide opening
 * to the nearest walls) or when the block cuts the mesh (the heat method sees
 * only the part inside); the winding number of the repaired mesh is the same
 * in any block. It needs the repair's orientation. lo, hi: the input mesh's
 * bounds (repair moves no vertex). */
static int wants_winding(const hv_sdf_opts *o, const hv_sdf_repair_report *r, const double lo[3],
                         const double hi[3], const int n[3], double h, const double origin[3])
{
    if (o->sign != HV_SDF_SIGN_AUTO)
        return o->sign == HV_SDF_SIGN_WINDING;
    const unsigned orient = HV_SDF_REPAIR_ORIENT | HV_SDF_REPAIR_OUTWARD;
    if ((o->repair & orient) != orient)
        return 0;
    if (r->boundary_edges > 0)
        return 1;
    for (int a = 0; a < 3; a++)
        if (lo[a] < origin[a] || hi[a] > origin[a] + n[a] * h)
            return 1;
    return 0;
}

/* What a run does, decided once the mesh is repaired: the output grid, where
 * the sign comes from, and the heat method's grid and levels. */
typedef struct sdf_plan {
    int unsig, exact;
    int sign_only; /* the heat method (if it runs) only decides the sign */
    int wn_sign;   /* the winding number decides it instead */
    int need_heat; /* stages 2-6 run */
    int n[3];
    double h, origin[3];
    int f, nh[3], nlev; /* the heat grid: f times coarser, nh cells, nlev levels */
    double hh;
} sdf_plan;

/* 1. Repair (unsigned distance: only the steps that do not orient). *M is the
 * mesh the later stages use. */
static hv_status sdf_repair(const hv_mesh *m, const hv_sdf_opts *o, int unsig, sdf_work *w,
                            const hv_mesh **M, hv_sdf_stats *S)
{
    hv_status st;
    double tt = hv_now();
    *M = m;
    if ((st = stage(0.0, "repair")))
        return st;
    if (o->repair) {
        unsigned flags = unsig ? (o->repair & (HV_SDF_REPAIR_WELD | HV_SDF_REPAIR_DEGENERATE |
                                               HV_SDF_REPAIR_DUPLICATES))
                               : o->repair;
        if ((st = hv_sdf_repair(m, flags, o->max_hole, &w->repaired, &S->repair)))
            return st;
        *M = w->repaired;
    } else {
        S->repair.vertices_in = S->repair.vertices_out = m->nverts;
        S->repair.triangles_in = S->repair.triangles_out = m->ntris;
    }
    S->t_repair = hv_now() - tt;
    return HV_OK;
}

/* Placement: the output grid, the sign's source, the heat grid and levels,
 * and the backend (AUTO on a GPU runs stages 2-6 on the device, as an
 * explicit opencl does). lo, hi: the mesh's bounds. */
static hv_status sdf_place(const hv_mesh *M, hv_sdf_opts *o, const double lo[3], const double hi[3],
                           sdf_work *w, sdf_plan *P, hv_sdf_stats *S)
{
    hv_status st;
    if ((st = hv_sdf_grid_for_mesh(M, o, P->n, &P->h, P->origin)) ||
        (st = hv_grid_create(&w->g, 3, P->n, P->h, P->origin)))
        return st;
    memcpy(S->n, P->n, sizeof S->n);
    S->h = P->h;
    memcpy(S->origin, P->origin, sizeof S->origin);
    /* With the exact magnitude (signed) only the heat method's sign is used,
     * and it may run on a grid f times coarser. Where that sign would depend
     * on the block, the winding number of the repaired mesh decides instead
     * (sign_winding.c). */
    P->sign_only = P->exact && !P->unsig;
    P->wn_sign = P->sign_only && wants_winding(o, &S->repair, lo, hi, P->n, P->h, P->origin);
    S->sign = !P->sign_only ? HV_SDF_SIGN_AUTO
              : P->wn_sign  ? HV_SDF_SIGN_WINDING
                            : HV_SDF_SIGN_HEAT;
    P->need_heat = !(P->unsig && P->exact) && !P->wn_sign;
    P->f = hv__sdf_heat_factor(o, P->n);
    S->heat_coarsen = P->need_heat ? P->f : 0;
    P->hh = P->f * P->h;
    for (int a = 0; a < 3; a++)
        P->nh[a] = (P->n[a] + P->f - 1) / P->f;
    if (P->need_heat && P->sign_only && P->f > 1 &&
        (st = hv_grid_create(&w->gh, 3, P->nh, P->hh, P->origin)))
        return st;
    const hv_grid *gh = w->gh ? w->gh : w->g;
    /* The backend, chosen here once for every solve of the pipeline: on a
     * device, the whole heat method runs there (sdf_cl.c). */
    if (P->need_heat)
        o->backend = hv_backend_resolve(o->backend, hv_grid_count(gh), 0);
    P->nlev = P->need_heat ? levels_for(o, P->nh) : 0;
    S->levels = P->nlev;
    S->t = (o->t_scale * P->hh) * (o->t_scale * P->hh);
    return HV_OK;
}

/* The surface quadrature at the heat grid's spacing (src/geom/surface.c),
 * which the heat method splats; for the heat method a mesh with no part in
 * the block is an error (the exact distance and the winding number are
 * defined in any block). */
static hv_status sdf_surface(const hv_mesh *M, const sdf_plan *P, sdf_work *w, hv_sdf_stats *S)
{
    hv_status st;
    if ((st = stage(0.05, "splat")))
        return st;
    double tt = hv_now(), blo[3], bhi[3];
    for (int a = 0; a < 3; a++) {
        blo[a] = P->origin[a];
        bhi[a] = P->origin[a] + P->n[a] * P->h;
    }
    if ((st = hv__quad_build(M, P->hh, blo, bhi, &w->q)))
        return st;
    S->surface_samples = w->q.count;
    if (w->q.count == 0)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: no part of the mesh lies inside the grid block");
    S->t_splat = hv_now() - tt;
    return HV_OK;
}

/* 7a. The exact distance to the triangles (src/geom/exact.c), and the nearest
 * triangle of each cell where a pseudonormal or the winding number needs it. */
static hv_status sdf_band_distance(const hv_mesh *M, const hv_sdf_opts *o, const sdf_plan *P,
                                   sdf_work *w, hv_sdf_stats *S)
{
    const size_t count = hv_grid_count(w->g);
    if (!(w->dist = hv_malloc(count * sizeof(float))))
        return hv__error(HV_ERR_NOMEM, "sdf: out of memory for the exact distance (%zu cells)",
                         count);
    const int want_tri = !P->unsig && o->near_sign > 0;
    if (want_tri && !(w->tri = hv_malloc(count * sizeof *w->tri)))
        return hv__error(HV_ERR_NOMEM, "sdf: out of memory for nearest triangles (%zu cells)",
                         count);
    /* A narrow band needs exact values within band_only voxels only;
     * farther cells get (band_only + 1) h. */
    const double cap = o->band_only > 0 ? o->band_only * P->h : INFINITY;
    /* A narrow band up to SDF_RASTER_MAX voxels is rasterized whole
     * (exact, no dilation): at 3 voxels on the bunny at 256^3 that took
     * 1.07 CPU s against 1.96 for a 2-voxel raster plus dilation, which
     * pays a descent for most cells. */
    const double raster = o->band_only > 0 && o->band_only <= SDF_RASTER_MAX
                              ? fmax(SDF_EXACT_BAND, o->band_only)
                              : SDF_EXACT_BAND;
    return hv__exact_distance(M, w->g, raster, cap, w->dist, w->tri, &S->band_cells);
}

/* 7b. The output: the exact distance with its sign. The sign is the winding
 * number's (sign_winding.c, pseudonormals included) or the heat method's phi
 * (interpolated from a coarser heat grid gh), which within near_sign voxels
 * the clean nearest feature's pseudonormal overrules. */
static hv_status sdf_sign_output(const hv_mesh *M, const hv_sdf_opts *o, const sdf_plan *P,
                                 const hv_grid *gh, sdf_work *w, hv_sdf_stats *S)
{
    hv_status st = HV_OK;
    const size_t count = hv_grid_count(w->g);
    const int *n = P->n;
    float *res = w->g->v;
    const float *dist = w->dist;
    const float far = (float)((o->band_only + 1) * P->h);
    if (P->unsig) {
#pragma omp parallel for schedule(static)
        for (size_t c = 0; c < count; c++)
            res[c] = isinf(dist[c]) ? far : dist[c];
        return HV_OK;
    }
    const uint32_t *tri = w->tri;
    hv_pseudo ps;
    const int have_ps = o->near_sign > 0 || P->wn_sign;
    if (have_ps && (st = hv__pseudo_build(M, &ps)))
        return st;
    const float dlim = (float)(o->near_sign * P->h), hlim = (float)(1.5 * o->near_sign * P->h);
    size_t changed = 0, used = 0;
    if ((st = stage(0.95, "sign"))) {
        if (have_ps)
            hv__pseudo_free(&ps);
        return st;
    }
    if (P->wn_sign) {
        double ts = hv_now();
        st = hv__winding_sign(M, w->g, dist, tri, &ps, o->near_sign * P->h, res, &S->winding_evals,
                              &used);
        S->t_sign = hv_now() - ts;
    } else if (gh != w->g) {
        st = hv__sdf_upsample(gh, gh->v, w->g, res);
    }
    if (st) {
        if (have_ps)
            hv__pseudo_free(&ps);
        return st;
    }
    const int use_ps = o->near_sign > 0 && !P->wn_sign;
#pragma omp parallel for collapse(2) schedule(dynamic, 16) reduction(+ : changed, used)
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                size_t c = (size_t)i + (size_t)n[0] * ((size_t)j + (size_t)n[1] * k);
                float d = dist[c], sg = res[c];
                if (use_ps && d < dlim && fabsf(sg) < hlim && tri[c] != UINT32_MAX) {
                    double p[3];
                    hv_grid_cell_center(w->g, i, j, k, p);
                    int s = hv__pseudo_sign(&ps, M, tri[c], p, sg < 0 ? -1 : 1);
                    if (s) {
                        used++;
                        if ((s < 0) != (sg < 0)) {
                            sg = (float)s;
                            changed++;
                        }
                    }
                }
                d = isinf(d) ? far : d;
                res[c] = sg < 0 ? -d : d;
            }
    S->near_sign_cells = used;
    S->near_sign_changed = changed;
    if (have_ps)
        hv__pseudo_free(&ps);
    return HV_OK;
}

/* What both entry points start with: the options (defaults for NULL),
 * checked, zeroed stats and work, and the mesh's bounds (checked). */
static hv_status sdf_begin(const hv_mesh *m, const hv_sdf_opts *opts, hv_sdf_opts *o,
                           hv_sdf_stats *S, sdf_work *w, double lo[3], double hi[3])
{
    if (opts)
        *o = *opts;
    else
        hv_sdf_opts_default(o);
    memset(S, 0, sizeof *S);
    memset(w, 0, sizeof *w);
    hv_status st = hv__sdf_check_opts(o);
    return st ? st : used_bounds(m, lo, hi);
}

hv_status hv_sdf_compute(const hv_mesh *m, const hv_sdf_opts *opts, hv_grid **out,
                         hv_sdf_stats *stats)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_sdf_compute: out is NULL");
    *out = NULL;
    hv_sdf_opts o;
    hv_sdf_stats S;
    sdf_work w;
    sdf_plan P;
    memset(&P, 0, sizeof P);
    double lo[3], hi[3];
    hv_status st = sdf_begin(m, opts, &o, &S, &w, lo, hi);
    if (st)
        return st;
    resolve_auto(&o);
    if (o.threads > 0)
        hv_set_threads(o.threads);
    P.unsig = o.unsigned_distance != 0;
    P.exact = o.magnitude == HV_SDF_EXACT;
    const double t0 = hv_now();
    const hv_mesh *M = m;
    if ((st = sdf_repair(m, &o, P.unsig, &w, &M, &S)) ||
        (st = sdf_place(M, &o, lo, hi, &w, &P, &S)) ||
        (P.need_heat && (st = sdf_surface(M, &P, &w, &S))))
        goto done;
    /* A band reaches as far as the morphology moves the surface. */
    if (o.band_only > 0)
        o.band_only += hv__sdf_morph_reach(&o) / P.h;
    /* 2-6. The signed heat method (sdf_heat.c), where it decides the sign or
     * gives the distance; phi on gh. */
    hv_grid *gh = w.gh ? w.gh : w.g;
    if (P.need_heat && (st = hv__sdf_heat(&w.q, gh, P.nlev, P.unsig, &o, &S)))
        goto done;
    /* 7. The exact magnitude and its sign. */
    if (P.exact) {
        if ((st = stage(0.85, "redistance")))
            goto done;
        hv__progress_span(0.85, 0.95);
        double tt = hv_now();
        if ((st = sdf_band_distance(M, &o, &P, &w, &S)) ||
            (st = sdf_sign_output(M, &o, &P, gh, &w, &S)))
            goto done;
        S.t_redistance = hv_now() - tt;
    }
    if (hv__sdf_morph_on(&o) && (st = hv__sdf_morph_grid(w.g, &o)))
        goto done;
    if ((st = stage(1.0, "done")))
        goto done;
    S.t_total = hv_now() - t0;
    *out = w.g;
    w.g = NULL;
done:
    work_free(&w);
    if (stats)
        *stats = S;
    return st;
}

/* The sink between the tiles and the caller's: the offset and shell moved
 * onto each batch (the producer's own arrays, writable), the active voxels
 * counted after them. */
typedef struct {
    const hv_tiles_sink *to;
    const hv_sdf_opts *o;
    double band;
    size_t active;
    int ended; /* end was passed on */
} morph_sink;

static hv_status morph_begin(void *user, const hv_tiles *block, size_t max_tiles)
{
    const morph_sink *ms = user;
    return ms->to->begin(ms->to->user, block, max_tiles);
}

static hv_status morph_put(void *user, const hv_tiles *batch)
{
    morph_sink *ms = user;
    if (hv__sdf_morph_on(ms->o))
        hv__sdf_morph_tiles((hv_tiles *)batch, ms->o, ms->band);
    ms->active += batch->active;
    return ms->to->put(ms->to->user, batch);
}

static hv_status morph_end(void *user, int ok)
{
    morph_sink *ms = user;
    ms->ended = 1;
    return ms->to->end(ms->to->user, ok);
}

const char *hv_sdf_tiles_refusal(const hv_sdf_opts *o, int levelset)
{
    const unsigned orient = HV_SDF_REPAIR_ORIENT | HV_SDF_REPAIR_OUTWARD;
    const int sign = o && !o->unsigned_distance;
    if (!o)
        return "no options";
    if (o->magnitude != HV_SDF_EXACT)
        return "a narrow band of tiles has the exact distance only (the heat method's own values "
               "need the dense grid)";
    if (sign && o->sign == HV_SDF_SIGN_HEAT)
        return "a narrow band of tiles takes its sign from the winding number (the heat method's "
               "sign needs the dense grid)";
    if (sign && (o->repair & orient) != orient)
        return "a narrow band of tiles takes its sign from the winding number, which needs the "
               "repair's orientation steps";
    if (o->close > 0 || o->open > 0)
        return "closing and opening need the dense grid (they redistance between their two moves)";
    if (!sign && levelset)
        return "an unsigned distance is no level set: it is written as a dense grid";
    return NULL;
}

/* hv_sdf_stream_tiles's checks of its options. */
static hv_status tiles_check(const hv_sdf_opts *o, double band)
{
    if (!(band > 0) || band > 64)
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf: band half width must be in (0, 64] voxels, got %g", band);
    const char *why = hv_sdf_tiles_refusal(o, 0);
    return why ? hv__error(HV_ERR_INVALID_ARG, "sdf: %s", why) : HV_OK;
}

/* The band's tiles on the device where the backend says so: opencl always,
 * auto where it would take the device for a solve on the block (a GPU, a
 * large block; HEATVOX_AUTO_OPENCL). An auto run whose device fails before
 * the sink was begun (no fp64, too little memory) falls back to the host. */
static hv_status band_tiles(const hv_mesh *M, const hv_sdf_opts *o, const int n[3], double h,
                            const double origin[3], double band, const hv_tiles_sink *via,
                            hv_sdf_stats *S)
{
    const int unsig = o->unsigned_distance != 0;
    const size_t cells = (size_t)n[0] * n[1] * n[2];
    const int device = o->backend == HV_BACKEND_OPENCL ||
                       (o->backend == HV_BACKEND_AUTO &&
                        hv_backend_resolve(HV_BACKEND_AUTO, cells, 0) == HV_BACKEND_OPENCL);
    if (device) {
        hv_status st = hv__sdf_tiles_cl(M, n, h, origin, band, unsig, o->near_sign, via, S);
        const morph_sink *ms = via->user;
        if (o->backend == HV_BACKEND_OPENCL || ms->ended ||
            (st != HV_ERR_UNSUPPORTED && st != HV_ERR_NOMEM && st != HV_ERR_BACKEND))
            return st;
        hv_clear_error();
    }
    return hv__sdf_tiles(M, n, h, origin, band, unsig, o->near_sign, via, S);
}

/* hv_sdf_stream_tiles once its options are checked: the repair, the
 * placement and the tiles through ms. */
static hv_status stream_run(const hv_mesh *m, hv_sdf_opts *o, double band, morph_sink *ms,
                            sdf_work *w, double lo[3], double hi[3], hv_sdf_stats *S)
{
    const double t0 = hv_now();
    const hv_mesh *M = m;
    const int unsig = o->unsigned_distance != 0;
    int n[3];
    double h, origin[3];
    hv_status st;
    grow_bounds(o, lo, hi);
    if ((st = sdf_repair(m, o, unsig, w, &M, S)) ||
        (st = hv__sdf_grid_place(o, lo, hi, n, &h, origin)))
        return st;
    memcpy(S->n, n, sizeof S->n);
    S->h = h;
    memcpy(S->origin, origin, sizeof S->origin);
    S->sign = unsig ? HV_SDF_SIGN_AUTO : HV_SDF_SIGN_WINDING;
    S->backend = HV_BACKEND_AUTO;
    if ((st = stage(0.1, "tiles")))
        return st;
    const double tt = hv_now();
    const hv_tiles_sink via = {ms, morph_begin, morph_put, morph_end};
    if ((st = band_tiles(M, o, n, h, origin, band + hv__sdf_morph_reach(o) / h, &via, S)))
        return st;
    S->active_voxels = ms->active;
    S->t_redistance = hv_now() - tt;
    /* The sink has taken the band: a cancel now would undo nothing. */
    (void)stage(1.0, "done");
    hv_clear_error();
    S->t_total = hv_now() - t0;
    return HV_OK;
}

hv_status hv_sdf_stream_tiles(const hv_mesh *m, const hv_sdf_opts *opts, double band,
                              const hv_tiles_sink *sink, hv_sdf_stats *stats)
{
    if (!sink || !sink->begin || !sink->put || !sink->end)
        return hv__error(HV_ERR_INVALID_ARG, "hv_sdf_stream_tiles: the sink is incomplete");
    hv_sdf_opts o;
    hv_sdf_stats S;
    sdf_work w;
    double lo[3], hi[3];
    morph_sink ms = {.to = sink, .o = &o, .band = band};
    hv_status st = sdf_begin(m, opts, &o, &S, &w, lo, hi);
    if (!st && !(st = tiles_check(&o, band))) {
        if (o.threads > 0)
            hv_set_threads(o.threads);
        st = stream_run(m, &o, band, &ms, &w, lo, hi, &S);
        work_free(&w);
    }
    /* The sink hears once of every run, also of one that failed before it
     * began. */
    if (!ms.ended)
        sink->end(sink->user, 0);
    if (stats)
        *stats = S;
    return st;
}

hv_status hv_sdf_compute_tiles(const hv_mesh *m, const hv_sdf_opts *opts, double band,
                               hv_tiles **out, hv_sdf_stats *stats)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_sdf_compute_tiles: out is NULL");
    *out = NULL;
    hv__tiles_collect c = {NULL};
    const hv_tiles_sink sink = hv__tiles_collector(&c);
    hv_status st = hv_sdf_stream_tiles(m, opts, band, &sink, stats);
    if (st)
        hv_tiles_destroy(&c.T);
    *out = c.T;
    return st;
}
