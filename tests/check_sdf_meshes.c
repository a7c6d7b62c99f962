/*
 * hv_sdf_compute on the shared meshes ($HEATVOX_TEST_DATA, default ../shared/meshes; skipped when
 * absent), scored by inside-IoU of {phi < 0} against a truth computed
 * independently of the library (tests/sdf_testutil.h):
 *   - defects made from the clean closed meshes bunny_small and spot (5
 *     holes of radius 3% of the diagonal, 30% random flips, the +x half
 *     flipped, unwelded soup, 10% of faces duplicated, half of them reversed,
 *     and all at once): the
 *     truth is ray parity along grid rows on the CLEAN mesh (exact for a
 *     closed mesh);
 *   - real broken meshes: the generalized winding number (> 1/2) of the raw
 *     mesh for meshes with holes, ray parity for armadillo_bad (closed, faces
 *     flipped at random, where the winding number fails).
 * Grids are 64 cells along the longest axis to keep the run short.
 */
#include "sdf_testutil.h"

#include <check.h>

#define RES 64

/* The block hv_sdf_compute would use for m, fixed as a bbox so that variants
 * of m (with fewer faces, other bounds) land on the same cells. */
static hv_sdf_opts fixed_grid(const hv_mesh *m, hv_grid **truth_grid)
{
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = RES;
    int n[3];
    double h, org[3];
    ck_assert_int_eq(hv_sdf_grid_for_mesh(m, &o, n, &h, org), HV_OK);
    o.use_bbox = 1;
    o.voxel_size = h;
    for (int a = 0; a < 3; a++) {
        o.bbox[a] = org[a];
        o.bbox[3 + a] = org[a] + n[a] * h;
    }
    ck_assert_int_eq(hv_grid_create(truth_grid, 3, n, h, org), HV_OK);
    return o;
}

static double iou_of(const hv_mesh *m, const hv_sdf_opts *o, const uint8_t *truth,
                     const hv_grid *tg, const char *label, hv_sdf_stats *stats)
{
    hv_grid *g = NULL;
    hv_sdf_stats S;
    hv_status st = hv_sdf_compute(m, o, &g, &S);
    ck_assert_msg(st == HV_OK, "%s: %s: %s", label, hv_status_str(st), hv_last_error());
    ck_assert_int_eq(g->n[0], tg->n[0]);
    ck_assert_int_eq(g->n[1], tg->n[1]);
    ck_assert_int_eq(g->n[2], tg->n[2]);
    double iou = tu_iou(g, truth);
    /* The same beyond one voxel of our surface, where sub-voxel closure
     * choices at holes do not count. */
    size_t I = 0, U = 0;
    for (size_t c = 0; c < hv_grid_count(g); c++) {
        if (fabs(g->v[c]) <= g->h)
            continue;
        int a = g->v[c] < 0, b = truth[c] != 0;
        I += a && b;
        U += a || b;
    }
    printf("  %-28s IoU %.5f (beyond 1 voxel %.5f)  %dx%dx%d  %zu -> %zu triangles, %zu holes "
           "filled, %zu faces flipped, %.2f s\n",
           label, iou, U ? (double)I / U : 1.0, g->n[0], g->n[1], g->n[2], S.repair.triangles_in,
           S.repair.triangles_out, S.repair.holes_filled, S.repair.faces_flipped, S.t_total);
    if (stats)
        *stats = S;
    hv_grid_destroy(&g);
    return iou;
}

enum { D_HOLES = 1, D_FLIP = 2, D_HALF = 4, D_SOUP = 8, D_DUP = 16 };

static hv_mesh *with_defects(const hv_mesh *clean, int which)
{
    hv_mesh *d = NULL;
    ck_assert_int_eq(hv_mesh_clone(clean, &d), HV_OK);
    if (which & D_HOLES)
        ck_assert_int_eq(hv_mesh_defect_holes(d, 5, 0.03, 11), HV_OK);
    if (which & D_FLIP)
        ck_assert_int_eq(hv_mesh_defect_flip(d, 0.3, 12), HV_OK);
    if (which & D_HALF)
        ck_assert_int_eq(hv_mesh_defect_flip_half(d, 0), HV_OK);
    if (which & D_DUP)
        ck_assert_int_eq(hv_mesh_defect_duplicate(d, 0.1, 13), HV_OK);
    if (which & D_SOUP)
        ck_assert_int_eq(hv_mesh_defect_soup(d, 0, 14), HV_OK);
    return d;
}

static void defects_on(const char *name)
{
    hv_mesh *clean = tu_load_shared(name);
    if (!clean)
        return;
    hv_grid *tg = NULL;
    hv_sdf_opts o = fixed_grid(clean, &tg);
    uint8_t *truth = malloc(hv_grid_count(tg));
    tu_ray_parity(clean, tg, truth);
    char label[64];
    snprintf(label, sizeof label, "%s clean", name);
    ck_assert_double_ge(iou_of(clean, &o, truth, tg, label, NULL), 0.999);
    static const struct {
        const char *name;
        int which;
    } v[] = {
        {"holes", D_HOLES},        {"30% flipped", D_FLIP},
        {"half flipped", D_HALF},  {"soup", D_SOUP},
        {"10% duplicated", D_DUP}, {"all at once", D_HOLES | D_FLIP | D_HALF | D_SOUP | D_DUP}};
    for (size_t i = 0; i < sizeof v / sizeof v[0]; i++) {
        hv_mesh *d = with_defects(clean, v[i].which);
        snprintf(label, sizeof label, "%s %s", name, v[i].name);
        double iou = iou_of(d, &o, truth, tg, label, NULL);
        ck_assert_msg(iou >= 0.99, "%s: inside-IoU %.5f < 0.99", label, iou);
        hv_mesh_destroy(&d);
    }
    free(truth);
    hv_grid_destroy(&tg);
    hv_mesh_destroy(&clean);
}

START_TEST(bunny_small_defects_should_keep_iou_099) { defects_on("bunny_small.obj"); }
END_TEST

START_TEST(spot_defects_should_keep_iou_099) { defects_on("spot.obj"); }
END_TEST

/* What repair buys: a coherently flipped half turns half the solid inside
 * out for the plain heat method (docs/METHOD.md, "Signed heat method");
 * orientation repair fixes it. */
START_TEST(repair_should_be_what_fixes_a_coherently_flipped_half)
{
    hv_mesh *clean = tu_load_shared("spot.obj");
    if (!clean)
        return;
    hv_grid *tg = NULL;
    hv_sdf_opts o = fixed_grid(clean, &tg);
    uint8_t *truth = malloc(hv_grid_count(tg));
    tu_ray_parity(clean, tg, truth);
    hv_mesh *d = with_defects(clean, D_HALF | D_DUP);
    double with = iou_of(d, &o, truth, tg, "half flipped, repaired", NULL);
    o.repair = 0;
    double without = iou_of(d, &o, truth, tg, "half flipped, no repair", NULL);
    ck_assert_double_ge(with, 0.99);
    ck_assert_double_lt(without, 0.5);
    free(truth);
    hv_grid_destroy(&tg);
    hv_mesh_destroy(&d);
    hv_mesh_destroy(&clean);
}
END_TEST

/* Truth for a real mesh: ray parity (closed meshes with scrambled
 * orientation), the winding number of the mesh as given, or (holey meshes)
 * the closed solid: the mesh with its orientation repaired and every hole
 * closed by a flat cap, inside where its winding number is above 1/2. */
enum { TRUTH_WINDING, TRUTH_PARITY, TRUTH_CLOSED };

static void real_mesh(const char *name, int truth_kind, double min_iou, double min_iou_beyond_1)
{
    hv_mesh *m = tu_load_shared(name);
    if (!m)
        return;
    hv_grid *tg = NULL;
    hv_sdf_opts o = fixed_grid(m, &tg);
    uint8_t *truth = malloc(hv_grid_count(tg)), *wn = malloc(hv_grid_count(tg));
    tu_winding(m, tg, wn);
    if (truth_kind == TRUTH_PARITY) {
        tu_ray_parity(m, tg, truth);
    } else if (truth_kind == TRUTH_CLOSED) {
        hv_mesh *closed = NULL;
        ck_assert_int_eq(hv_sdf_repair(m, HV_SDF_REPAIR_ALL, o.max_hole, &closed, NULL), HV_OK);
        tu_winding(closed, tg, truth);
        hv_mesh_destroy(&closed);
    } else {
        memcpy(truth, wn, hv_grid_count(tg));
    }
    hv_grid *g = NULL;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_OK);
    double iou = tu_iou(g, truth), iou_wn = tu_iou(g, wn);
    /* Beyond a voxel from the surface, against the winding number of the mesh
     * as given (independent of heatvox's repair). */
    size_t I = 0, U = 0;
    for (size_t c = 0; c < hv_grid_count(g); c++) {
        if (fabs(g->v[c]) <= g->h)
            continue;
        I += g->v[c] < 0 && wn[c];
        U += g->v[c] < 0 || wn[c];
    }
    double beyond = U ? (double)I / U : 1.0;
    static const char *kinds[] = {"the winding number", "ray parity", "the closed solid"};
    printf("  %-28s IoU %.5f against %s; against the raw winding number %.5f, beyond 1 voxel "
           "%.5f\n",
           name, iou, kinds[truth_kind], iou_wn, beyond);
    ck_assert_msg(iou >= min_iou, "%s: inside-IoU %.5f < %.3f", name, iou, min_iou);
    if (truth_kind != TRUTH_PARITY)
        ck_assert_msg(beyond >= min_iou_beyond_1, "%s: inside-IoU beyond 1 voxel %.5f < %.3f", name,
                      beyond, min_iou_beyond_1);
    hv_grid_destroy(&g);
    free(truth);
    free(wn);
    hv_grid_destroy(&tg);
    hv_mesh_destroy(&m);
}

START_TEST(stanford_bunny_should_match_its_winding_number)
{
    real_mesh("stanford-bunny.obj", TRUTH_WINDING, 0.98, 0.999);
}
END_TEST

START_TEST(bun_zipper_res4_should_match_its_winding_number)
{
    real_mesh("bun_zipper_res4.ply", TRUTH_WINDING, 0.98, 0.99);
}
END_TEST

START_TEST(armadillo_bad_should_match_its_ray_parity)
{
    real_mesh("armadillo_bad.obj", TRUTH_PARITY, 0.98, 0);
}
END_TEST

/* Knot and chair: hundreds of holes about as wide as the tube or plate
 * around them (knot: ~400 loops; chair: open strut ends and 1-2 voxel plates
 * at 64^3). The winding number of the open mesh is no solid there: at an open
 * tube end its 1/2 level retracts into the tube, and across a hole it sags,
 * so near the rims it and any closure disagree by a voxel or two (raw IoU
 * 0.93-0.97). The intended solid is the closed mesh (flat caps); beyond one
 * voxel from the surface the result must also agree with the raw winding
 * number. */
START_TEST(knot_should_match_its_closed_solid) { real_mesh("knot.obj", TRUTH_CLOSED, 0.98, 0.995); }
END_TEST

START_TEST(chair_should_match_its_closed_solid)
{
    real_mesh("chair.obj", TRUTH_CLOSED, 0.98, 0.995);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("sdf_meshes");
    TCase *tc = tcase_create("defects");
    tcase_set_timeout(tc, 600);
    tcase_add_test(tc, bunny_small_defects_should_keep_iou_099);
    tcase_add_test(tc, spot_defects_should_keep_iou_099);
    tcase_add_test(tc, repair_should_be_what_fixes_a_coherently_flipped_half);
    suite_add_tcase(s, tc);
    tc = tcase_create("real");
    tcase_set_timeout(tc, 600);
    tcase_add_test(tc, stanford_bunny_should_match_its_winding_number);
    tcase_add_test(tc, bun_zipper_res4_should_match_its_winding_number);
    tcase_add_test(tc, armadillo_bad_should_match_its_ray_parity);
    tcase_add_test(tc, knot_should_match_its_closed_solid);
    tcase_add_test(tc, chair_should_match_its_closed_solid);
    suite_add_tcase(s, tc);
    SRunner *sr = srunner_create(s);
    /* No fork, whatever CK_FORK says: the library links PoCL and OpenVDB/TBB,
     * whose worker threads do not survive fork: a forked test hangs
     * (docs/METHOD.md, "Testing notes"). */
    srunner_set_fork_status(sr, CK_NOFORK);
    srunner_run_all(sr, CK_NORMAL);
    int failed = srunner_ntests_failed(sr);
    srunner_free(sr);
    return failed ? EXIT_FAILURE : EXIT_SUCCESS;
}
