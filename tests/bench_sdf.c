/*
 * Benchmark and accuracy report for hv_sdf_compute (not part of make check):
 *   make build/tests/bench_sdf && HEATVOX_TEST_DATA=../shared/meshes build/tests/bench_sdf [res]
 * or tools/bench/bench_sdf.sh. Prints one line per measurement:
 *   1. analytic shapes: band, whole-grid and far-field errors in voxels, for
 *      the default (exact magnitude) and the heat method's own phi;
 *   2. defects made from bunny_small and spot, per repair configuration (what
 *      each repair step buys), inside-IoU against ray parity on the clean mesh;
 *   3. real broken meshes against the winding number / ray parity;
 *   4. time per stage and peak memory for stanford-bunny.
 */
#include "sdf_testutil.h"

static const double C0[3] = {0.013, -0.021, 0.007};

static double sphere_sdf(const double p[3])
{
    double x = p[0] - C0[0], y = p[1] - C0[1], z = p[2] - C0[2];
    return sqrt(x * x + y * y + z * z) - 0.5;
}

static double torus_sdf(const double p[3])
{
    double x = p[0] - C0[0], y = p[1] - C0[1], z = p[2] - C0[2];
    double q = sqrt(x * x + y * y) - 0.55;
    return sqrt(q * q + z * z) - 0.2;
}

static void analytic(int res)
{
    hv_mesh *meshes[2] = {NULL, NULL};
    hv_mesh_make_sphere(&meshes[0], C0, 0.5, 5);
    hv_mesh_make_torus(&meshes[1], C0, 0.55, 0.2, 256, 96);
    double (*truth[2])(const double *) = {sphere_sdf, torus_sdf};
    for (int s = 0; s < 2; s++)
        for (int mode = 0; mode < 2; mode++) {
            hv_sdf_opts o;
            hv_sdf_opts_default(&o);
            o.res = res;
            o.use_bbox = 1;
            double b[6] = {-1, -1, -1, 1, 1, 1};
            memcpy(o.bbox, b, sizeof b);
            o.magnitude = mode ? HV_SDF_HEAT : HV_SDF_EXACT;
            hv_grid *g = NULL;
            hv_sdf_stats S;
            if (hv_sdf_compute(meshes[s], &o, &g, &S)) {
                printf("analytic: %s\n", hv_last_error());
                continue;
            }
            double band = 0, bmax = 0, all = 0, far = 0;
            size_t nb = 0, bad = 0;
            for (int k = 0; k < g->n[2]; k++)
                for (int j = 0; j < g->n[1]; j++)
                    for (int i = 0; i < g->n[0]; i++) {
                        double p[3];
                        hv_grid_cell_center(g, i, j, k, p);
                        double t = truth[s](p),
                               v = g->v[i + (size_t)g->n[0] * (j + (size_t)g->n[1] * k)];
                        double e = fabs(v - t) / g->h;
                        all = fmax(all, e);
                        if (fabs(t) < 3 * g->h)
                            band += e, bmax = fmax(bmax, e), nb++;
                        if (fabs(t) > 10 * g->h)
                            far = fmax(far, e);
                        bad += fabs(t) > g->h && (v < 0) != (t < 0);
                    }
            printf("analytic %-6s %3d^3 %-5s band(<3vox) mean %.4f max %.3f | grid max %.3f | "
                   "far(>10vox) max %.3f | "
                   "sign errors beyond 1 vox %zu | surface rms %.3f -> %.3f vox | %.2f s\n",
                   s ? "torus" : "sphere", res, mode ? "heat" : "exact", band / (double)nb, bmax,
                   all, far, bad, S.surface_rms_before, S.surface_rms_after, S.t_total);
            fflush(stdout);
            hv_grid_destroy(&g);
        }
    hv_mesh_destroy(&meshes[0]);
    hv_mesh_destroy(&meshes[1]);
}

static hv_sdf_opts fixed(const hv_mesh *m, int res, hv_grid **tg)
{
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = res;
    int n[3];
    double h, org[3];
    hv_sdf_grid_for_mesh(m, &o, n, &h, org);
    o.use_bbox = 1;
    o.voxel_size = h;
    for (int a = 0; a < 3; a++)
        o.bbox[a] = org[a], o.bbox[3 + a] = org[a] + n[a] * h;
    hv_grid_create(tg, 3, n, h, org);
    return o;
}

static double iou(const hv_mesh *m, const hv_sdf_opts *o, const uint8_t *truth, double *secs)
{
    hv_grid *g = NULL;
    hv_sdf_stats S;
    if (hv_sdf_compute(m, o, &g, &S)) {
        printf("  error: %s\n", hv_last_error());
        return -1;
    }
    double r = tu_iou(g, truth);
    if (secs)
        *secs = S.t_total;
    hv_grid_destroy(&g);
    return r;
}

static void defects(int res)
{
    const char *names[2] = {"bunny_small.obj", "spot.obj"};
    static const unsigned configs[] = {
        0, HV_SDF_REPAIR_WELD | HV_SDF_REPAIR_DEGENERATE | HV_SDF_REPAIR_DUPLICATES, 0x0f, 0x1f,
        HV_SDF_REPAIR_ALL};
    static const char *cname[] = {"none", "weld+dedup", "+orient", "+outward", "+fill(all)"};
    for (int f = 0; f < 2; f++) {
        hv_mesh *clean = tu_load_shared(names[f]);
        if (!clean)
            continue;
        hv_grid *tg = NULL;
        hv_sdf_opts o = fixed(clean, res, &tg);
        uint8_t *truth = malloc(hv_grid_count(tg));
        tu_ray_parity(clean, tg, truth);
        const char *vn[] = {"clean",    "holes3%", "holes5%", "flip30",
                            "fliphalf", "soup",    "dup10",   "all"};
        for (int v = 0; v < 8; v++) {
            hv_mesh *d = NULL;
            hv_mesh_clone(clean, &d);
            if (v == 1 || v == 7)
                hv_mesh_defect_holes(d, 5, 0.03, 11);
            if (v == 2)
                hv_mesh_defect_holes(d, 5, 0.05, 11);
            if (v == 3 || v == 7)
                hv_mesh_defect_flip(d, 0.3, 12);
            if (v == 4 || v == 7)
                hv_mesh_defect_flip_half(d, 0);
            if (v == 6 || v == 7)
                hv_mesh_defect_duplicate(d, 0.1, 13);
            if (v == 5 || v == 7)
                hv_mesh_defect_soup(d, 0, 14);
            printf("defects %-16s %3d^3 %-9s IoU by repair:", names[f], res, vn[v]);
            double secs = 0;
            for (size_t c = 0; c < sizeof configs / sizeof configs[0]; c++) {
                o.repair = configs[c];
                printf(" %s %.5f", cname[c], iou(d, &o, truth, &secs));
                fflush(stdout);
            }
            /* The winding number of the defective mesh, for comparison. */
            uint8_t *wn = malloc(hv_grid_count(tg));
            tu_winding(d, tg, wn);
            size_t I = 0, U = 0;
            for (size_t c = 0; c < hv_grid_count(tg); c++)
                I += wn[c] && truth[c], U += wn[c] || truth[c];
            printf(" | winding number %.5f | %.2f s\n", U ? (double)I / U : 1.0, secs);
            free(wn);
            hv_mesh_destroy(&d);
        }
        free(truth);
        hv_grid_destroy(&tg);
        hv_mesh_destroy(&clean);
    }
}

static void real(int res)
{
    const char *names[] = {
        "stanford-bunny.obj",  "knot.obj",   "chair.obj",        "armadillo_bad.obj",
        "bun_zipper_res4.ply", "rocker.obj", "polygon-bear.obj", "cow.obj"};
    for (size_t f = 0; f < sizeof names / sizeof names[0]; f++) {
        hv_mesh *m = tu_load_shared(names[f]);
        if (!m)
            continue;
        hv_grid *tg = NULL;
        hv_sdf_opts o = fixed(m, res, &tg);
        uint8_t *wn = malloc(hv_grid_count(tg)), *par = malloc(hv_grid_count(tg));
        tu_winding(m, tg, wn);
        tu_ray_parity(m, tg, par);
        hv_grid *g = NULL;
        hv_sdf_stats S;
        if (hv_sdf_compute(m, &o, &g, &S)) {
            printf("real %s: %s\n", names[f], hv_last_error());
            continue;
        }
        size_t I = 0, U = 0;
        for (size_t c = 0; c < hv_grid_count(g); c++) {
            if (fabs(g->v[c]) <= g->h)
                continue;
            I += g->v[c] < 0 && wn[c], U += g->v[c] < 0 || wn[c];
        }
        /* Winding numbers of the mesh after orientation repair (no caps), and
         * after the full repair (caps included). */
        double iou_or = -1, iou_full = -1;
        hv_mesh *rm = NULL;
        uint8_t *w2 = malloc(hv_grid_count(tg));
        if (!hv_sdf_repair(m, HV_SDF_REPAIR_ALL & ~HV_SDF_REPAIR_FILL_HOLES, o.max_hole, &rm,
                           NULL)) {
            tu_winding(rm, tg, w2);
            iou_or = tu_iou(g, w2);
            hv_mesh_destroy(&rm);
        }
        if (!hv_sdf_repair(m, HV_SDF_REPAIR_ALL, o.max_hole, &rm, NULL)) {
            tu_winding(rm, tg, w2);
            iou_full = tu_iou(g, w2);
            hv_mesh_destroy(&rm);
        }
        free(w2);
        printf("real %-20s IoU vs winding after orientation repair %.5f, vs the closed solid "
               "(flat caps) %.5f\n",
               names[f], iou_or, iou_full);
        printf("real %-20s %dx%dx%d IoU vs winding %.5f (beyond 1 vox %.5f) vs parity %.5f | holes "
               "%zu/%zu filled, "
               "%zu faces flipped | %.2f s\n",
               names[f], g->n[0], g->n[1], g->n[2], tu_iou(g, wn), U ? (double)I / U : 1,
               tu_iou(g, par), S.repair.holes_filled,
               S.repair.holes_filled + S.repair.holes_left_open, S.repair.faces_flipped, S.t_total);
        fflush(stdout);
        hv_grid_destroy(&g);
        free(wn), free(par);
        hv_grid_destroy(&tg);
        hv_mesh_destroy(&m);
    }
}

static void timing(int res)
{
    hv_mesh *m = tu_load_shared("stanford-bunny.obj");
    if (!m)
        return;
    for (int b = 0; b < 2; b++) {
        hv_sdf_opts o;
        hv_sdf_opts_default(&o);
        o.res = res;
        o.backend = b ? HV_BACKEND_FFTW : HV_BACKEND_MG;
        hv_grid *g = NULL;
        hv_sdf_stats S;
        if (hv_sdf_compute(m, &o, &g, &S)) {
            printf("timing %s: %s\n", hv_backend_name(o.backend), hv_last_error());
            continue;
        }
        printf("timing stanford-bunny %dx%dx%d %s threads %d: repair %.2f splat %.2f diffuse %.2f "
               "normalize %.2f "
               "poisson %.2f shift %.2f redistance %.2f total %.2f s | iterations %d/%d | peak RSS "
               "%.0f MB\n",
               S.n[0], S.n[1], S.n[2], hv_backend_name(S.backend), hv_get_threads(), S.t_repair,
               S.t_splat, S.t_diffuse, S.t_normalize, S.t_poisson, S.t_shift, S.t_redistance,
               S.t_total, S.diffuse_iterations, S.poisson_iterations, hv_peak_rss() / 1e6);
        fflush(stdout);
        hv_grid_destroy(&g);
    }
    hv_mesh_destroy(&m);
}

int main(int argc, char **argv)
{
    int res = argc > 1 ? atoi(argv[1]) : 128;
    const char *what = argc > 2 ? argv[2] : "all";
    if (!strcmp(what, "all") || !strcmp(what, "timing"))
        timing(res);
    if (!strcmp(what, "all") || !strcmp(what, "analytic"))
        analytic(res);
    if (!strcmp(what, "all") || !strcmp(what, "real"))
        real(res);
    if (!strcmp(what, "all") || !strcmp(what, "defects"))
        defects(res);
    return 0;
}
