/* 2D signed distance from broken curves: circles, squares and an annulus drawn
 * with gaps, flipped segments, duplicates and the wrong winding, against their
 * analytic distances; the text and SVG readers. */
#include "heatvox/heatvox.h"
#include "sdf2d/sdf2d_internal.h"
#include "testlib.h"

#include <check.h>
#include <limits.h>
#include <math.h>
#include <sys/wait.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* ---- curve sets built in the test ---- */

typedef struct cset {
    double *pts;
    size_t np, cap;
    size_t *start;
    uint8_t *closed;
    size_t nl, capl;
} cset;

static void cs_line(cset *c, const double *xy, size_t count, int closed)
{
    if (c->np + count > c->cap) {
        c->cap = 2 * (c->np + count) + 64;
        c->pts = realloc(c->pts, 2 * c->cap * sizeof *c->pts);
    }
    if (c->nl + 2 > c->capl) {
        c->capl = 2 * c->nl + 16;
        c->start = realloc(c->start, c->capl * sizeof *c->start);
        c->closed = realloc(c->closed, c->capl);
    }
    c->start[c->nl] = c->np;
    c->closed[c->nl] = (uint8_t)closed;
    memcpy(c->pts + 2 * c->np, xy, 2 * count * sizeof *xy);
    c->np += count;
    c->nl++;
    c->start[c->nl] = c->np;
}

static hv_curves *cs_finish(cset *c)
{
    hv_curves *out = NULL;
    TL_ASSERT_OK(hv_curves_from_arrays(&out, c->pts, c->np, c->start, c->nl, c->closed));
    free(c->pts);
    free(c->start);
    free(c->closed);
    memset(c, 0, sizeof *c);
    return out;
}

/* A closed polygon given by its m vertices v (counter-clockwise), added as
 * separate pieces: segments inside a gap are left out, a fraction `flip` of the
 * segments is added reversed as 2-point polylines, the rest as runs. Gaps are
 * `ngaps` evenly spaced runs of `gap_segs` missing segments, the first at
 * gap_offset / ngaps of the way round. */
static void add_broken_polygon(cset *c, const double *v, int m, int ngaps, int gap_segs,
                               double gap_offset, double flip, uint64_t seed)
{
    double *run = malloc(2 * ((size_t)m + 1) * sizeof *run);
    size_t rn = 0;
    for (int s = 0; s < m; s++) {
        int in_gap = 0;
        for (int g = 0; g < ngaps; g++) {
            int g0 = (int)((g + gap_offset) * m / ngaps);
            in_gap |= s >= g0 && s < g0 + gap_segs;
        }
        int flipped = !in_gap && tl_rand(&seed) + 0.5 < flip;
        const double *a = v + 2 * s, *b = v + 2 * ((s + 1) % m);
        if (in_gap || flipped) {
            if (rn >= 2)
                cs_line(c, run, rn, 0);
            rn = 0;
            if (flipped) {
                double seg[4] = {b[0], b[1], a[0], a[1]};
                cs_line(c, seg, 2, 0);
            }
            continue;
        }
        if (rn == 0) {
            run[0] = a[0];
            run[1] = a[1];
            rn = 1;
        }
        run[2 * rn] = b[0];
        run[2 * rn + 1] = b[1];
        rn++;
    }
    if (rn >= 2)
        cs_line(c, run, rn, 0);
    free(run);
}

static double *circle_pts(double cx, double cy, double r, int m, int ccw)
{
    double *v = malloc(2 * (size_t)m * sizeof *v);
    for (int k = 0; k < m; k++) {
        double a = 2 * M_PI * k / m * (ccw ? 1 : -1);
        v[2 * k] = cx + r * cos(a);
        v[2 * k + 1] = cy + r * sin(a);
    }
    return v;
}

/* Square of half side a, centre (cx, cy), rotated by rot, each side split into
 * `per_side` segments, counter-clockwise. */
static double *square_pts(double cx, double cy, double a, double rot, int per_side)
{
    int m = 4 * per_side;
    double *v = malloc(2 * (size_t)m * sizeof *v);
    const double cs[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
    for (int s = 0; s < 4; s++)
        for (int k = 0; k < per_side; k++) {
            double t = (double)k / per_side;
            const double *p = cs[s], *q = cs[(s + 1) % 4];
            double x = a * (p[0] + t * (q[0] - p[0])), y = a * (p[1] + t * (q[1] - p[1]));
            v[2 * (s * per_side + k)] = cx + x * cos(rot) - y * sin(rot);
            v[2 * (s * per_side + k) + 1] = cy + x * sin(rot) + y * cos(rot);
        }
    return v;
}

/* ---- truths and measures ---- */

typedef double (*truth_fn)(double x, double y, const double *prm);

static double circle_sdf(double x, double y, const double *p)
{
    return hypot(x - p[0], y - p[1]) - p[2];
}

static double square_sdf(double x, double y, const double *p)
{
    double dx = x - p[0], dy = y - p[1];
    double u = fabs(dx * cos(p[3]) + dy * sin(p[3])) - p[2];
    double v = fabs(-dx * sin(p[3]) + dy * cos(p[3])) - p[2];
    return hypot(fmax(u, 0), fmax(v, 0)) + fmin(fmax(u, v), 0);
}

static double annulus_sdf(double x, double y, const double *p)
{
    double r = hypot(x - p[0], y - p[1]);
    return fmax(r - p[2], p[3] - r);
}

typedef struct measure {
    double sign_agree; /* fraction of cells with |truth| > 1 px whose sign matches */
    double band_mean;  /* mean |phi - truth| over |truth| <= 3 px, in pixels */
    size_t wrong;
} measure;

static measure compare(const hv_grid *g, truth_fn f, const double *prm)
{
    measure m = {0, 0, 0};
    size_t nsign = 0, nband = 0;
    double sum = 0;
    for (int j = 0; j < g->n[1]; j++)
        for (int i = 0; i < g->n[0]; i++) {
            double x[3];
            hv_grid_cell_center(g, i, j, 0, x);
            double t = f(x[0], x[1], prm) / g->h, v = g->v[i + (size_t)g->n[0] * j] / g->h;
            if (fabs(t) > 1) {
                nsign++;
                if ((t < 0) != (v < 0))
                    m.wrong++;
            }
            if (fabs(t) <= 3) {
                nband++;
                sum += fabs(v - t);
            }
        }
    m.sign_agree = 1.0 - (double)m.wrong / (double)nsign;
    m.band_mean = sum / (double)nband;
    return m;
}

/* bbox [-64, 64]^2 at 128 cells: h = 1 pixel. */
static void opts_px(hv_sdf2d_opts *o)
{
    hv_sdf2d_opts_default(o);
    o->use_bbox = 1;
    o->bbox[0] = o->bbox[1] = -64;
    o->bbox[2] = o->bbox[3] = 64;
    o->res = 128;
}

static measure run_case(hv_curves *c, truth_fn f, const double *prm, const char *what,
                        hv_sdf2d_stats *stats_out)
{
    hv_sdf2d_opts o;
    opts_px(&o);
    hv_grid *g = NULL;
    hv_sdf2d_stats st;
    TL_ASSERT_OK(hv_curves_sdf(c, &o, &g, &st));
    ck_assert_int_eq(g->dim, 2);
    ck_assert_int_eq(g->n[0], 128);
    ck_assert_int_eq(g->n[1], 128);
    ck_assert(fabs(g->h - 1.0) < 1e-12);
    measure m = compare(g, f, prm);
    printf("%-44s sign %.6f (%zu wrong)  band mean |err| %.4f px  flipped %zu  chains %zu  "
           "cycles %zu  %.3f s\n",
           what, m.sign_agree, m.wrong, m.band_mean, st.segments_flipped, st.chains, st.cycles,
           st.t_total);
    if (stats_out)
        *stats_out = st;
    hv_grid_destroy(&g);
    return m;
}

static void expect_good(measure m, const char *what)
{
    ck_assert_msg(m.wrong == 0, "%s: %zu cells beyond 1 px have the wrong sign", what, m.wrong);
    ck_assert_msg(m.band_mean <= 0.1, "%s: mean |error| within 3 px is %.4f px", what, m.band_mean);
}

/* ---- tests ---- */

START_TEST(clean_circle_should_match_its_distance)
{
    double prm[3] = {3.3, -2.1, 40};
    double *v = circle_pts(prm[0], prm[1], prm[2], 240, 1);
    cset cs = {0};
    cs_line(&cs, v, 240, 1);
    hv_curves *c = cs_finish(&cs);
    measure m = run_case(c, circle_sdf, prm, "circle, clean", NULL);
    expect_good(m, "clean circle");
    ck_assert(m.band_mean < 0.02); /* polygon vs circle: sagitta 0.01 px */
    hv_curves_destroy(&c);
    free(v);
}
END_TEST

START_TEST(circle_drawn_clockwise_should_still_be_negative_inside)
{
    double prm[3] = {-5.5, 7.25, 33};
    double *v = circle_pts(prm[0], prm[1], prm[2], 200, 0);
    cset cs = {0};
    cs_line(&cs, v, 200, 1);
    hv_curves *c = cs_finish(&cs);
    hv_sdf2d_stats st;
    expect_good(run_case(c, circle_sdf, prm, "circle, clockwise", &st), "clockwise circle");
    ck_assert_int_eq(st.segments_flipped, 200);
    ck_assert_int_eq(st.cycles, 1);
    hv_curves_destroy(&c);
    free(v);
}
END_TEST

START_TEST(circle_with_gaps_and_flipped_segments_should_keep_sign_and_distance)
{
    double prm[3] = {3.3, -2.1, 40};
    double *v = circle_pts(prm[0], prm[1], prm[2], 240, 1);
    const double flips[] = {0.1, 0.3, 0.45};
    for (size_t f = 0; f < sizeof flips / sizeof flips[0]; f++) {
        cset cs = {0};
        /* 4 gaps of 3 segments (about 3 px each), a fraction of segments reversed */
        add_broken_polygon(&cs, v, 240, 4, 3, 0.0, flips[f], 17 + f);
        hv_curves *c = cs_finish(&cs);
        char what[96];
        snprintf(what, sizeof what, "circle, 4 gaps of 3 px, %.0f%% flipped", 100 * flips[f]);
        hv_sdf2d_stats st;
        measure m = run_case(c, circle_sdf, prm, what, &st);
        expect_good(m, what);
        ck_assert_int_gt(st.segments_flipped, 0);
        ck_assert_int_ge(st.chains, 4);
        hv_curves_destroy(&c);
    }
    free(v);
}
END_TEST

START_TEST(rotated_square_with_gaps_and_flips_should_keep_sign_and_distance)
{
    double prm[4] = {-4.2, 3.9, 30, 0.35};
    double *v = square_pts(prm[0], prm[1], prm[2], prm[3], 40);
    cset cs = {0};
    /* gaps at segments 16-17, 69-70, 122-123: none takes a corner away */
    add_broken_polygon(&cs, v, 160, 3, 2, 0.3, 0.3, 5);
    hv_curves *c = cs_finish(&cs);
    expect_good(run_case(c, square_sdf, prm, "square, 3 gaps, 30% flipped", NULL), "broken square");
    hv_curves_destroy(&c);
    free(v);
}
END_TEST

START_TEST(square_from_separate_sides_with_a_reversed_side_and_an_overlap)
{
    /* four sides as separate polylines, one reversed, and the bottom side drawn
     * a second time reversed (a duplicate that would cancel the first). */
    double prm[4] = {1.5, -2.5, 35, 0};
    double a = prm[2], x0 = prm[0] - a, x1 = prm[0] + a, y0 = prm[1] - a, y1 = prm[1] + a;
    cset cs = {0};
    double bottom[] = {x0, y0, prm[0], y0, x1, y0};
    double right_rev[] = {x1, y1, x1, y0}; /* reversed */
    double top[] = {x1, y1, x0, y1};
    double left[] = {x0, y1, x0, prm[1], x0, y0};
    double bottom_dup[] = {x1, y0, prm[0], y0, x0, y0};
    cs_line(&cs, bottom, 3, 0);
    cs_line(&cs, right_rev, 2, 0);
    cs_line(&cs, top, 2, 0);
    cs_line(&cs, left, 3, 0);
    cs_line(&cs, bottom_dup, 3, 0);
    hv_curves *c = cs_finish(&cs);
    hv_sdf2d_stats st;
    expect_good(run_case(c, square_sdf, prm, "square, sides apart, reversed + duplicate", &st),
                "square from sides");
    ck_assert_int_eq(st.duplicates_removed, 2);
    ck_assert_int_eq(st.cycles, 1);
    ck_assert_int_ge(st.points_welded, 4);
    hv_curves_destroy(&c);
}
END_TEST

START_TEST(overlapping_collinear_pieces_drawn_backwards_should_not_cancel)
{
    /* bottom side once as one segment, and again backwards in pieces that
     * overlap it only partly and end at other points */
    double prm[4] = {-3.5, 4.5, 30, 0};
    double a = prm[2], x0 = prm[0] - a, x1 = prm[0] + a, y0 = prm[1] - a, y1 = prm[1] + a;
    cset cs = {0};
    double loop[] = {x0, y0, x1, y0, x1, y1, x0, y1};
    cs_line(&cs, loop, 4, 1);
    double back[] = {x1 - 5, y0, x0 + 20, y0, x0 + 3, y0};
    cs_line(&cs, back, 3, 0);
    double right_back[] = {x1, y1 - 4, x1, y0 + 4}; /* inside the right side, backwards */
    cs_line(&cs, right_back, 2, 0);
    hv_curves *c = cs_finish(&cs);
    hv_sdf2d_stats st;
    expect_good(run_case(c, square_sdf, prm, "square, partial overlaps backwards", &st),
                "overlaps");
    ck_assert_int_ge(st.segments_split, 2);
    ck_assert_int_ge(st.duplicates_removed, 3);
    hv_curves_destroy(&c);
}
END_TEST

START_TEST(nested_circles_both_counter_clockwise_should_give_an_annulus)
{
    double prm[4] = {2.2, 1.1, 45, 20};
    double *outer = circle_pts(prm[0], prm[1], prm[2], 280, 1);
    double *inner = circle_pts(prm[0], prm[1], prm[3], 140, 1);
    cset cs = {0};
    cs_line(&cs, outer, 280, 1);
    cs_line(&cs, inner, 140, 1);
    hv_curves *c = cs_finish(&cs);
    hv_sdf2d_stats st;
    expect_good(run_case(c, annulus_sdf, prm, "annulus, both counter-clockwise", &st), "annulus");
    ck_assert_int_eq(st.cycles, 2);
    ck_assert_int_eq(st.segments_flipped, 140);
    hv_curves_destroy(&c);
    free(outer);
    free(inner);
}
END_TEST

static double two_circles_sdf(double x, double y, const double *p)
{
    return fmin(hypot(x - p[0], y - p[1]) - p[2], hypot(x - p[3], y - p[4]) - p[5]);
}

START_TEST(broken_shapes_side_by_side_and_nested_should_each_find_their_inside)
{
    /* two circles, both with gaps and flips, the second drawn clockwise */
    double prm[6] = {-30, 5, 24, 31, -6, 20};
    double *a = circle_pts(prm[0], prm[1], prm[2], 150, 1);
    double *b = circle_pts(prm[3], prm[4], prm[5], 130, 0);
    cset cs = {0};
    add_broken_polygon(&cs, a, 150, 3, 2, 0.1, 0.3, 41);
    add_broken_polygon(&cs, b, 130, 5, 2, 0.2, 0.3, 43);
    hv_curves *c = cs_finish(&cs);
    expect_good(run_case(c, two_circles_sdf, prm, "two broken circles, one clockwise", NULL),
                "two circles");
    hv_curves_destroy(&c);
    free(a);
    free(b);
    /* an annulus with both loops broken and flipped, both drawn counter-clockwise */
    double ann[4] = {2.2, 1.1, 45, 20};
    double *outer = circle_pts(ann[0], ann[1], ann[2], 280, 1);
    double *inner = circle_pts(ann[0], ann[1], ann[3], 140, 1);
    add_broken_polygon(&cs, outer, 280, 4, 3, 0.2, 0.35, 47);
    add_broken_polygon(&cs, inner, 140, 3, 2, 0.4, 0.35, 53);
    c = cs_finish(&cs);
    expect_good(run_case(c, annulus_sdf, ann, "annulus, both loops broken and flipped", NULL),
                "broken annulus");
    hv_curves_destroy(&c);
    free(outer);
    free(inner);
}
END_TEST

START_TEST(without_repair_a_duplicate_drawn_backwards_should_break_the_sign)
{
    /* The control for the repair: opposite duplicates cancel without it. */
    double prm[3] = {0, 0, 40};
    double *v = circle_pts(0, 0, 40, 240, 1), *w = circle_pts(0, 0, 40, 240, 0);
    cset cs = {0};
    cs_line(&cs, v, 120, 0); /* half the circle, drawn twice in opposite directions */
    double *back = malloc(2 * 121 * sizeof *back);
    for (int k = 0; k <= 120; k++) {
        back[2 * k] = v[2 * (120 - k)];
        back[2 * k + 1] = v[2 * (120 - k) + 1];
    }
    cs_line(&cs, back, 121, 0);
    double *rest = malloc(2 * 121 * sizeof *rest);
    for (int k = 0; k <= 120; k++) {
        rest[2 * k] = v[2 * ((120 + k) % 240)];
        rest[2 * k + 1] = v[2 * ((120 + k) % 240) + 1];
    }
    cs_line(&cs, rest, 121, 0);
    hv_curves *c = cs_finish(&cs);
    measure good = run_case(c, circle_sdf, prm, "circle, half drawn twice opposite", NULL);
    expect_good(good, "half drawn twice");
    hv_sdf2d_opts o;
    opts_px(&o);
    o.repair = 0;
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_curves_sdf(c, &o, &g, NULL));
    measure bad = compare(g, circle_sdf, prm);
    printf("%-44s sign %.6f (%zu wrong)\n", "  same without repair", bad.sign_agree, bad.wrong);
    ck_assert_int_gt(bad.wrong, 100);
    hv_grid_destroy(&g);
    hv_curves_destroy(&c);
    free(v);
    free(w);
    free(back);
    free(rest);
}
END_TEST

START_TEST(heat_magnitude_should_approximate_the_distance)
{
    double prm[3] = {3.3, -2.1, 40};
    double *v = circle_pts(prm[0], prm[1], prm[2], 240, 1);
    cset cs = {0};
    cs_line(&cs, v, 240, 1);
    hv_curves *c = cs_finish(&cs);
    hv_sdf2d_opts o;
    opts_px(&o);
    o.heat_magnitude = 1;
    hv_grid *g = NULL;
    hv_sdf2d_stats st;
    TL_ASSERT_OK(hv_curves_sdf(c, &o, &g, &st));
    measure m = compare(g, circle_sdf, prm);
    printf("%-44s sign %.6f (%zu wrong)  band mean |err| %.4f px  levels %d\n",
           "circle, heat magnitude", m.sign_agree, m.wrong, m.band_mean, st.levels);
    ck_assert_int_eq(m.wrong, 0);
    ck_assert(m.band_mean < 0.5);
    ck_assert_int_gt(st.levels, 1);
    hv_grid_destroy(&g);
    hv_curves_destroy(&c);
    free(v);
}
END_TEST

START_TEST(grid_should_follow_res_and_pad_around_the_curves)
{
    double v[8] = {0, 0, 10, 0, 10, 5, 0, 5};
    size_t start[2] = {0, 4};
    uint8_t closed = 1;
    hv_curves *c = NULL;
    TL_ASSERT_OK(hv_curves_from_arrays(&c, v, 4, start, 1, &closed));
    hv_sdf2d_opts o;
    hv_sdf2d_opts_default(&o);
    o.res = 64;
    o.pad = 4;
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_curves_sdf(c, &o, &g, NULL));
    ck_assert_int_eq(g->n[0], 64);
    ck_assert(fabs(g->h - 10.0 / 56) < 1e-12);
    ck_assert_int_eq(g->n[1], 28 + 8);
    ck_assert(g->v[g->n[0] / 2 + (size_t)g->n[0] * (g->n[1] / 2)] < -2.0f); /* centre inside */
    ck_assert(g->v[0] > 0);
    hv_grid_destroy(&g);
    o.res = 8; /* no room inside the padding */
    ck_assert_int_eq(hv_curves_sdf(c, &o, &g, NULL), HV_ERR_INVALID_ARG);
    hv_curves_destroy(&c);
}
END_TEST

/* ---- nesting through the spatial index ---- */

static void add_loop(cset *c, const double *v, int m, int ccw)
{
    double *w = malloc(2 * (size_t)m * sizeof *w);
    for (int k = 0; k < m; k++) {
        int s = ccw ? k : m - 1 - k;
        w[2 * k] = v[2 * s];
        w[2 * k + 1] = v[2 * s + 1];
    }
    cs_line(c, w, (size_t)m, 1);
    free(w);
}

/* n hexagons of radius 1 on a lattice of pitch 3, every other one clockwise;
 * the clockwise segments counted in *cw. */
static hv_curves *hexagon_lattice(int n, size_t *cw)
{
    int side = (int)ceil(sqrt(n));
    cset cs = {0};
    *cw = 0;
    for (int k = 0; k < n; k++) {
        double *v = circle_pts(3.0 * (k % side), 3.0 * (k / side), 1.0, 6, 1);
        add_loop(&cs, v, 6, k % 2 == 0);
        *cw += k % 2 ? 6 : 0;
        free(v);
    }
    return cs_finish(&cs);
}

/* Runs c with the index and with every pair tested; the grids must be equal
 * bit for bit, and so must the repair's counts. */
static void expect_index_agrees(hv_curves *c, const hv_sdf2d_opts *o, const char *what,
                                hv_sdf2d_stats *out)
{
    hv_grid *g = NULL, *ref = NULL;
    hv_sdf2d_stats st, rs;
    TL_ASSERT_OK(hv_curves_sdf(c, o, &g, &st));
    hv__sdf2d_all_pairs = 1;
    hv_status s = hv_curves_sdf(c, o, &ref, &rs);
    hv__sdf2d_all_pairs = 0;
    TL_ASSERT_OK(s);
    printf("%-44s nesting tests %zu (all pairs %zu), flipped %zu, chains %zu, cycles %zu\n", what,
           st.nesting_tests, rs.nesting_tests, st.segments_flipped, st.chains, st.cycles);
    ck_assert_int_eq(g->n[0], ref->n[0]);
    ck_assert_int_eq(g->n[1], ref->n[1]);
    ck_assert_msg(memcmp(g->v, ref->v, hv_grid_count(g) * sizeof *g->v) == 0,
                  "%s: the index changed the result", what);
    ck_assert_int_eq(st.segments_flipped, rs.segments_flipped);
    ck_assert_int_eq(st.segments_out, rs.segments_out);
    ck_assert_int_eq(st.chains, rs.chains);
    ck_assert_int_eq(st.cycles, rs.cycles);
    ck_assert(st.nesting_tests <= rs.nesting_tests);
    if (out)
        *out = st;
    hv_grid_destroy(&g);
    hv_grid_destroy(&ref);
}

START_TEST(nesting_tests_should_grow_linearly_with_disjoint_loops)
{
    /* Every pair is N (N - 1) tests; the index should try none of them, since
     * no hexagon's box holds another's point. */
    const int n = 20000;
    size_t cw;
    hv_curves *c = hexagon_lattice(n, &cw);
    hv_sdf2d_opts o;
    hv_sdf2d_opts_default(&o);
    o.res = 64;
    hv_grid *g = NULL;
    hv_sdf2d_stats st;
    TL_ASSERT_OK(hv_curves_sdf(c, &o, &g, &st));
    printf("%-44s nesting tests %zu for %d loops, flipped %zu, repair %.3f s\n",
           "lattice of hexagons", st.nesting_tests, n, st.segments_flipped, st.t_repair);
    ck_assert_int_eq(st.cycles, n);
    ck_assert_msg(st.nesting_tests < 50 * (size_t)n, "%zu nesting tests for %d loops",
                  st.nesting_tests, n);
    ck_assert_int_eq(st.segments_flipped, cw); /* all counter-clockwise: depth 0 */
    hv_grid_destroy(&g);
    hv_curves_destroy(&c);
    /* the count is that of every pair without the index */
    c = hexagon_lattice(300, &cw);
    hv_sdf2d_stats all;
    expect_index_agrees(c, &o, "lattice of 300 hexagons", &st);
    hv__sdf2d_all_pairs = 1;
    TL_ASSERT_OK(hv_curves_sdf(c, &o, &g, &all));
    hv__sdf2d_all_pairs = 0;
    ck_assert_int_eq(all.nesting_tests, 300 * 299);
    ck_assert_int_eq(st.nesting_tests, 0);
    hv_grid_destroy(&g);
    hv_curves_destroy(&c);
}
END_TEST

/* Four nests of 5 concentric circles at (+-30, +-30), radii 25 - 6k, drawn
 * in random directions. */
static const double nest_r[5] = {25, 19, 13, 7, 2.5};

static double nests_sdf(double x, double y, const double *p)
{
    (void)p;
    double d = INFINITY;
    int depth = 0;
    for (int q = 0; q < 4; q++)
        for (int k = 0; k < 5; k++) {
            double r = hypot(x - (q & 1 ? 30 : -30), y - (q & 2 ? 30 : -30));
            depth += r < nest_r[k];
            d = fmin(d, fabs(r - nest_r[k]));
        }
    return depth % 2 ? -d : d;
}

static void add_nests(cset *cs, uint64_t *seed)
{
    for (int q = 0; q < 4; q++)
        for (int k = 0; k < 5; k++) {
            int m = 24 + 40 * (4 - k);
            double *v = circle_pts(q & 1 ? 30 : -30, q & 2 ? 30 : -30, nest_r[k], m, 1);
            add_loop(cs, v, m, tl_rand(seed) < 0);
            free(v);
        }
}

START_TEST(loops_inside_loops_should_alternate_sides_with_depth)
{
    uint64_t seed = 99;
    cset cs = {0};
    add_nests(&cs, &seed);
    hv_curves *c = cs_finish(&cs);
    hv_sdf2d_stats st;
    measure m = run_case(c, nests_sdf, NULL, "four nests of 5 loops, random directions", &st);
    ck_assert_int_eq(m.wrong, 0);
    ck_assert(m.band_mean < 0.1);
    ck_assert_int_eq(st.cycles, 20);
    /* each point lies in the boxes of its own nest only */
    ck_assert_int_le(st.nesting_tests, 4 * 5 * 4);
    hv_sdf2d_opts o;
    opts_px(&o);
    expect_index_agrees(c, &o, "four nests against all pairs", NULL);
    hv_curves_destroy(&c);
}
END_TEST

START_TEST(index_should_agree_with_all_pairs_on_awkward_loops)
{
    hv_sdf2d_opts o;
    opts_px(&o);
    uint64_t seed = 7;
    cset cs = {0};
    /* identical boxes: a diamond crossing a skewed square, a square with the
     * circle inscribed in it (touching at four points), a square twice and a
     * square once more reversed */
    double diamond[] = {-40, 30, -30, 40, -40, 50, -50, 40};
    double skew[] = {-30, 45, -45, 50, -50, 35, -35, 30};
    cs_line(&cs, diamond, 4, 1);
    cs_line(&cs, skew, 4, 1);
    double sq[] = {0, 30, 20, 30, 20, 50, 0, 50};
    double *circ = circle_pts(10, 40, 10, 32, 0);
    cs_line(&cs, sq, 4, 1);
    cs_line(&cs, circ, 32, 1);
    double dup[] = {30, 30, 50, 30, 50, 50, 30, 50};
    add_loop(&cs, dup, 4, 0);
    add_loop(&cs, dup, 4, 0);
    add_loop(&cs, dup, 4, 1);
    /* loops sharing edges: a 3 x 3 block of squares, each drawn whole */
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double x = -55 + 10 * i, y = -55 + 10 * j;
            double s[] = {x, y, x + 10, y, x + 10, y + 10, x, y + 10};
            add_loop(&cs, s, 4, tl_rand(&seed) < 0);
        }
    /* overlapping circles */
    for (int k = 0; k < 6; k++) {
        double *v = circle_pts(10 + 4 * k, -40 + 3 * k, 8, 20 + k, 1);
        add_loop(&cs, v, 20 + k, tl_rand(&seed) < 0);
        free(v);
    }
    hv_curves *c = cs_finish(&cs);
    expect_index_agrees(c, &o, "identical boxes, duplicates, shared edges", NULL);
    hv_curves_destroy(&c);

    /* broken loops (groups of open chains) nested, with small loops inside,
     * just outside and between them */
    double *outer = circle_pts(-20, 0, 40, 200, 1), *inner = circle_pts(-20, 0, 20, 120, 0);
    add_broken_polygon(&cs, outer, 200, 5, 2, 0.1, 0.3, 3);
    add_broken_polygon(&cs, inner, 120, 3, 2, 0.2, 0.3, 4);
    for (int k = 0; k < 300; k++) {
        double x = -62 + 124 * (tl_rand(&seed) + 0.5), y = -62 + 124 * (tl_rand(&seed) + 0.5);
        double *v = circle_pts(x, y, 1.2, 5, 1);
        add_loop(&cs, v, 5, tl_rand(&seed) < 0);
        free(v);
    }
    c = cs_finish(&cs);
    hv_sdf2d_stats st;
    expect_index_agrees(c, &o, "broken nested loops among 300 small ones", &st);
    ck_assert_int_ge(st.chains, 300 + 8);
    hv_curves_destroy(&c);
    free(outer);
    free(inner);
    free(circ);
}
END_TEST

START_TEST(squares_with_t_junctions_and_overlaps_should_split_each_edge_once)
{
    /* Axis-aligned squares share x and y values by the thousand (a sweep over
     * x meets every pair of a column); every 7th has a small square standing on
     * its right side (a T-junction), every 11th a piece of its bottom drawn
     * backwards. Each such edge splits once and each extra piece duplicates a
     * part of it. */
    const int n = 3000, side = 55;
    cset cs = {0};
    size_t nt = 0, no = 0;
    for (int k = 0; k < n; k++) {
        double x = 3.0 * (k % side), y = 3.0 * (k / side);
        double sq[] = {x, y, x + 2, y, x + 2, y + 2, x, y + 2};
        add_loop(&cs, sq, 4, k % 3 != 0);
        if (k % 7 == 0) {
            double t[] = {x + 2, y + 1, x + 2.8, y + 1, x + 2.8, y + 1.8, x + 2, y + 1.8};
            add_loop(&cs, t, 4, k % 2);
            nt++;
        }
        if (k % 11 == 0) {
            double piece[] = {x + 1.5, y, x + 0.25, y};
            cs_line(&cs, piece, 2, 0);
            no++;
        }
    }
    hv_curves *c = cs_finish(&cs);
    hv_sdf2d_opts o;
    hv_sdf2d_opts_default(&o);
    o.voxel_size = 0.25; /* 4 cells across the gaps */
    hv_sdf2d_stats st;
    expect_index_agrees(c, &o, "3000 squares, T-junctions, overlaps", &st);
    ck_assert_int_eq(st.points_welded, 0);
    ck_assert_int_eq(st.segments_split, nt + no);
    ck_assert_int_eq(st.duplicates_removed, nt + no);
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_curves_sdf(c, &o, &g, NULL));
    for (int k = 0; k < n; k++) {
        if (k % 7 == 0 || k % 11 == 0)
            continue;
        double x = 3.0 * (k % side) + 1, y = 3.0 * (k / side) + 1;
        int i = (int)floor((x - g->origin[0]) / g->h), j = (int)floor((y - g->origin[1]) / g->h);
        ck_assert_msg(g->v[i + (size_t)g->n[0] * j] < 0, "square %d: centre outside", k);
    }
    hv_grid_destroy(&g);
    hv_curves_destroy(&c);
}
END_TEST

/* ---- readers ---- */

START_TEST(text_format_should_read_commands_and_number_lines)
{
    const char *txt = "# a square and a line\n"
                      "M 0 0\nL 1 0\nL 1,1\nL 0 1\nZ\n"
                      "\n"
                      "  2 2   3 3 4 2.5e0  # an open polyline\n";
    hv_curves *c = NULL;
    TL_ASSERT_OK(hv_curves_parse(txt, strlen(txt), 0, "t.txt", &c));
    ck_assert_int_eq(c->nlines, 2);
    ck_assert_int_eq(c->npoints, 7);
    ck_assert_int_eq(c->closed[0], 1);
    ck_assert_int_eq(c->closed[1], 0);
    ck_assert_int_eq(hv_curves_segments(c), 6);
    ck_assert(c->pts[2 * 6] == 4 && c->pts[2 * 6 + 1] == 2.5);
    hv_curves_destroy(&c);
    const char *bad[] = {"M 0 0\nL 1\n", "L 1 1\n",        "M 0 0\nL 1 1 foo\n",
                         "1 2 3\n",      "M 0 0\nQ 1 1\n", "# nothing\n"};
    const char *where[] = {"line 2", "line 1", "line 2", "line 1", "line 2", "no curve"};
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        ck_assert_int_eq(hv_curves_parse(bad[k], strlen(bad[k]), 0, "bad.txt", &c), HV_ERR_PARSE);
        ck_assert_msg(strstr(hv_last_error(), "bad.txt") && strstr(hv_last_error(), where[k]),
                      "case %zu: '%s'", k, hv_last_error());
        ck_assert_ptr_null(c);
    }
}
END_TEST

START_TEST(svg_paths_should_read_absolute_relative_and_implicit_commands)
{
    const char *svg = "<?xml version=\"1.0\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\">\n"
                      "<!-- <path d=\"M 99 99 L 98 98\"/> is a comment -->\n"
                      "<path id='a' d=\"M10,20 h 5 v5 H10 z\"/>\n"
                      "<path d='m 0 0 10-5 l.5.5 V 0' fill=\"none\"/>\n"
                      "<polygon points=\"0,0 4,0 4,4\"/>\n"
                      "<path d=\"M0 0 Q 5 5 10 0 T 20 0\"/>\n"
                      "</svg>\n";
    hv_curves *c = NULL;
    TL_ASSERT_OK(hv_curves_parse(svg, strlen(svg), 1, "t.svg", &c));
    ck_assert_int_eq(c->nlines, 4);
    /* path 1: (10,20) (15,20) (15,25) (10,25), closed; y negated */
    ck_assert_int_eq(c->start[1] - c->start[0], 4);
    ck_assert_int_eq(c->closed[0], 1);
    const double p1[8] = {10, -20, 15, -20, 15, -25, 10, -25};
    for (int k = 0; k < 8; k++)
        ck_assert(c->pts[k] == p1[k]);
    /* path 2: m 0 0, implicit relative line-to 10 -5, l .5 .5, V 0 */
    const double *q = c->pts + 2 * c->start[1];
    ck_assert_int_eq(c->start[2] - c->start[1], 4);
    ck_assert(q[2] == 10 && q[3] == 5 && q[4] == 10.5 && q[5] == 4.5 && q[6] == 10.5 && q[7] == 0);
    ck_assert_int_eq(c->closed[1], 0);
    /* polygon: closed triangle */
    ck_assert_int_eq(c->start[3] - c->start[2], 3);
    ck_assert_int_eq(c->closed[2], 1);
    /* quadratics: 16 segments each, ending at (20, 0), the smooth one mirrored */
    ck_assert_int_eq(c->start[4] - c->start[3], 33);
    const double *e = c->pts + 2 * (c->npoints - 1);
    ck_assert(fabs(e[0] - 20) < 1e-12 && fabs(e[1]) < 1e-12);
    const double *mid = c->pts + 2 * (c->start[3] + 24);                /* t = 1/2 of the T curve */
    ck_assert(fabs(mid[0] - 15) < 1e-12 && fabs(mid[1] - 2.5) < 1e-12); /* below: -(-2.5) */
    hv_curves_destroy(&c);

    const char *arc = "<svg><path d=\"M 0 0 A 5 5 0 0 1 10 0\"/></svg>";
    ck_assert_int_eq(hv_curves_parse(arc, strlen(arc), 1, "arc.svg", &c), HV_ERR_UNSUPPORTED);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "arc.svg: byte 20"));
    const char *badnum = "<svg><path d=\"M 0 0 L 1\"/></svg>";
    ck_assert_int_eq(hv_curves_parse(badnum, strlen(badnum), 1, "n.svg", &c), HV_ERR_PARSE);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "n.svg: byte"));
    const char *empty = "<svg><rect width=\"3\" height=\"4\"/></svg>";
    ck_assert_int_eq(hv_curves_parse(empty, strlen(empty), 1, "e.svg", &c), HV_ERR_PARSE);
}
END_TEST

START_TEST(svg_circle_file_should_give_a_circle_distance)
{
    /* A circle of radius 40 as an SVG path of line segments with a gap, read
     * from a file: y is flipped, so the centre (10, 5) lands at (10, -5). */
    char dir[] = "/tmp/hv_check_sdf2d_XXXXXX";
    ck_assert_ptr_nonnull(mkdtemp(dir));
    char path[128];
    snprintf(path, sizeof path, "%s/c.svg", dir);
    FILE *f = fopen(path, "w");
    fprintf(f, "<svg xmlns=\"http://www.w3.org/2000/svg\"><path d=\"M %.9f %.9f", 10 + 40.0, 5.0);
    for (int k = 1; k < 236; k++)
        fprintf(f, " L %.9f %.9f", 10 + 40 * cos(2 * M_PI * k / 240),
                5 + 40 * sin(2 * M_PI * k / 240));
    fprintf(f, "\"/></svg>\n");
    fclose(f);
    hv_curves *c = NULL;
    TL_ASSERT_OK(hv_curves_read(path, &c));
    double prm[3] = {10, -5, 40};
    expect_good(run_case(c, circle_sdf, prm, "circle from an SVG file, one gap", NULL),
                "SVG circle");
    hv_curves_destroy(&c);
    unlink(path);
    rmdir(dir);
    ck_assert_int_eq(hv_curves_read(path, &c), HV_ERR_IO);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), path));
}
END_TEST

/* The command: $HEATVOX_BIN, else ../heatvox next to this test's directory. */
static const char *heatvox_bin(void)
{
    static char bin[PATH_MAX];
    const char *env = getenv("HEATVOX_BIN");
    if (env && *env) {
        snprintf(bin, sizeof bin, "%s", env);
    } else {
        char self[PATH_MAX];
        ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
        ck_assert_int_gt(n, 0);
        self[n] = '\0';
        *strrchr(self, '/') = '\0';
        snprintf(bin, sizeof bin, "%.4000s/../heatvox", self);
    }
    ck_assert_msg(access(bin, X_OK) == 0, "heatvox binary %s not found (set HEATVOX_BIN)", bin);
    return bin;
}

static int run_cmd(const char *fmt, const char *a, const char *b, const char *c)
{
    char cmd[8192];
    snprintf(cmd, sizeof cmd, fmt, heatvox_bin(), a, b, c);
    int st = system(cmd);
    return WIFEXITED(st) ? WEXITSTATUS(st) : 128;
}

START_TEST(sdf2d_command_should_write_the_library_result_as_exr_and_png)
{
    char dir[] = "/tmp/hv_check_sdf2d_cli_XXXXXX";
    ck_assert_ptr_nonnull(mkdtemp(dir));
    char in[128], exr[128], png[128];
    snprintf(in, sizeof in, "%s/sq.txt", dir);
    snprintf(exr, sizeof exr, "%s/sq.exr", dir);
    snprintf(png, sizeof png, "%s/sq.png", dir);
    FILE *f = fopen(in, "w");
    /* a square with a gap in its left side and the top drawn backwards */
    fputs("M -10 -10\nL 10 -10\nL 10 10\n-10 10 10 10\nM -10 10\nL -10 2\n", f);
    fclose(f);
    ck_assert_int_eq(run_cmd("'%s' sdf2d '%s' -o '%s' --png '%s' --res 64 -q", in, exr, png), 0);
    hv_grid *g = NULL, *ref = NULL;
    TL_ASSERT_OK(hv_exr_read(exr, "distance", &g));
    hv_curves *c = NULL;
    TL_ASSERT_OK(hv_curves_read(in, &c));
    hv_sdf2d_opts o;
    hv_sdf2d_opts_default(&o);
    o.res = 64;
    TL_ASSERT_OK(hv_curves_sdf(c, &o, &ref, NULL));
    ck_assert_int_eq(g->n[0], ref->n[0]);
    ck_assert_int_eq(g->n[1], ref->n[1]);
    ck_assert(fabs(g->h - ref->h) < 1e-12 && fabs(g->origin[0] - ref->origin[0]) < 1e-12);
    for (size_t i = 0; i < hv_grid_count(g); i++)
        ck_assert_msg(fabsf(g->v[i] - ref->v[i]) <= 1e-5f * (1 + fabsf(ref->v[i])),
                      "cell %zu: %g vs %g", i, g->v[i], ref->v[i]);
    /* the centre is inside */
    ck_assert(g->v[g->n[0] / 2 + (size_t)g->n[0] * (g->n[1] / 2)] < -5);
    uint8_t *rgb = NULL;
    int w, h;
    TL_ASSERT_OK(hv_png_read_rgb(png, &rgb, &w, &h));
    ck_assert_int_eq(w, g->n[0]);
    ck_assert_int_eq(h, g->n[1]);
    free(rgb);
    hv_grid_destroy(&g);
    hv_grid_destroy(&ref);
    hv_curves_destroy(&c);
    /* failures: unreadable input 1, usage 2 */
    ck_assert_int_eq(run_cmd("'%s' sdf2d '%s/none.txt' -o '%s' 2>/dev/null %s", dir, exr, ""), 1);
    ck_assert_int_eq(run_cmd("'%s' sdf2d '%s' --res x -o '%s' 2>/dev/null %s", in, exr, ""), 2);
    unlink(in);
    unlink(exr);
    unlink(png);
    rmdir(dir);
}
END_TEST

/* ---- a sign that does not depend on the block ---- */

/* Generalized winding number of polyline xy[0..m) at (x, y), brute force. */
static double direct_winding(const double *xy, int m, double x, double y)
{
    double w = 0;
    for (int k = 0; k + 1 < m; k++) {
        double ax = xy[2 * k] - x, ay = xy[2 * k + 1] - y, bx = xy[2 * k + 2] - x,
               by = xy[2 * k + 3] - y;
        w += atan2(ax * by - ay * bx, ax * bx + ay * by);
    }
    return w / (2 * M_PI);
}

static float at2(const hv_grid *g, int i, int j) { return g->v[i + (size_t)g->n[0] * j]; }

/* An open polyline (an arc of 300 degrees, a U) at pads 2, 8 and 40 on one
 * lattice: the same inside, none on the outer layer, and the inside of the
 * winding number (the heat method's inside leaked out of the opening). A
 * window through it equals the full run's values. */
static void check_open_curve(const char *what, const double *xy, int m)
{
    size_t st[2] = {0, (size_t)m};
    hv_curves *c = NULL;
    TL_ASSERT_OK(hv_curves_from_arrays(&c, xy, (size_t)m, st, 1, NULL));
    const int pads[3] = {2, 8, 40};
    hv_grid *g[3];
    hv_sdf2d_stats S;
    for (int q = 0; q < 3; q++) {
        hv_sdf2d_opts o;
        hv_sdf2d_opts_default(&o);
        o.voxel_size = 0.02;
        o.pad = pads[q];
        TL_ASSERT_OK(hv_curves_sdf(c, &o, &g[q], &S));
        ck_assert_int_eq(S.sign, 2);
        ck_assert_uint_eq(S.open_ends, 2);
    }
    for (int q = 0; q < 3; q++) {
        const hv_grid *a = g[0], *b = g[q];
        int off[2];
        for (int d = 0; d < 2; d++)
            off[d] = (int)lround((a->origin[d] - b->origin[d]) / a->h);
        size_t I = 0, U = 0, outer = 0, WI = 0, WU = 0;
        for (int j = 0; j < a->n[1]; j++)
            for (int i = 0; i < a->n[0]; i++) {
                int x = at2(a, i, j) < 0, y = at2(b, i + off[0], j + off[1]) < 0;
                I += x && y;
                U += x || y;
            }
        for (int j = 0; j < b->n[1]; j++)
            for (int i = 0; i < b->n[0]; i++) {
                int in = at2(b, i, j) < 0;
                if (i == 0 || j == 0 || i == b->n[0] - 1 || j == b->n[1] - 1)
                    outer += in;
                double px = b->origin[0] + (i + 0.5) * b->h, py = b->origin[1] + (j + 0.5) * b->h;
                int w = direct_winding(xy, m, px, py) > 0.5;
                WI += w && in;
                WU += w || in;
            }
        double iou = (double)I / (double)U, wiou = (double)WI / (double)WU;
        printf("%-44s pad %2d: IoU %.5f against pad 2, %zu inside on the outer layer, %.5f "
               "against the winding number\n",
               what, pads[q], iou, outer, wiou);
        ck_assert_msg(iou >= 0.995 && outer == 0 && wiou >= 0.98, "%s, pad %d", what, pads[q]);
    }
    /* A window through the curve: the full run's signs, and its values bit for
     * bit within 2 cells of the curve (beyond, the distance is passed on from
     * the segments in the block, as the 3D path does outside its band). */
    hv_sdf2d_opts o;
    hv_sdf2d_opts_default(&o);
    o.voxel_size = 0.02;
    o.use_bbox = 1;
    const hv_grid *f = g[1];
    int i0 = f->n[0] / 3, j0 = f->n[1] / 4;
    o.bbox[0] = f->origin[0] + i0 * f->h;
    o.bbox[1] = f->origin[1] + j0 * f->h;
    o.bbox[2] = f->origin[0] + (f->n[0] - 2) * f->h;
    o.bbox[3] = f->origin[1] + (3 * f->n[1] / 4) * f->h;
    hv_grid *w = NULL;
    TL_ASSERT_OK(hv_curves_sdf(c, &o, &w, &S));
    ck_assert_int_eq(S.sign, 2);
    size_t diff = 0, sdiff = 0, band = 0;
    for (int j = 0; j < w->n[1]; j++)
        for (int i = 0; i < w->n[0]; i++) {
            float a = at2(w, i, j), b = at2(f, i + i0, j + j0);
            sdiff += (a < 0) != (b < 0);
            if (fabsf(b) <= 2 * f->h) {
                band++;
                diff += a != b;
            }
        }
    ck_assert_msg(sdiff == 0 && diff == 0 && band > 100,
                  "%s: %zu signs and %zu of %zu band values of the window differ from the full run",
                  what, sdiff, diff, band);
    /* On request, the heat method: its inside reaches the walls. */
    hv_sdf2d_opts_default(&o);
    o.voxel_size = 0.02;
    o.pad = 8;
    o.sign = 1;
    hv_grid *hg = NULL;
    TL_ASSERT_OK(hv_curves_sdf(c, &o, &hg, &S));
    ck_assert_int_eq(S.sign, 1);
    size_t outer = 0;
    for (int j = 0; j < hg->n[1]; j++)
        for (int i = 0; i < hg->n[0]; i++)
            if (i == 0 || j == 0 || i == hg->n[0] - 1 || j == hg->n[1] - 1)
                outer += at2(hg, i, j) < 0;
    ck_assert_uint_gt(outer, 0);
    hv_grid_destroy(&hg);
    hv_grid_destroy(&w);
    for (int q = 0; q < 3; q++)
        hv_grid_destroy(&g[q]);
    hv_curves_destroy(&c);
}

START_TEST(open_curves_should_not_depend_on_the_block)
{
    double arc[2 * 101];
    for (int k = 0; k <= 100; k++) {
        double a = (120 + 3.0 * k) * M_PI / 180;
        arc[2 * k] = cos(a), arc[2 * k + 1] = sin(a);
    }
    check_open_curve("arc of 300 degrees", arc, 101);
    const double u[8] = {-1, 1, -1, -1, 1, -1, 1, 1};
    check_open_curve("U", u, 4);
}
END_TEST

START_TEST(sign_options_should_be_checked)
{
    const double u[8] = {-1, 1, -1, -1, 1, -1, 1, 1};
    size_t st[2] = {0, 4};
    hv_curves *c = NULL;
    TL_ASSERT_OK(hv_curves_from_arrays(&c, u, 4, st, 1, NULL));
    hv_sdf2d_opts o;
    hv_sdf2d_opts_default(&o);
    o.res = 32;
    hv_grid *g = NULL;
    o.sign = 3;
    ck_assert_int_eq(hv_curves_sdf(c, &o, &g, NULL), HV_ERR_INVALID_ARG);
    o.sign = 2;
    o.repair = 0;
    ck_assert_int_eq(hv_curves_sdf(c, &o, &g, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "orientation"));
    ck_assert_ptr_null(g);
    hv_curves_destroy(&c);
    char dir[] = "/tmp/hv_check_sdf2d_sign_XXXXXX";
    ck_assert_ptr_nonnull(mkdtemp(dir));
    char in[128], exr[128];
    snprintf(in, sizeof in, "%s/u.txt", dir);
    snprintf(exr, sizeof exr, "%s/u.exr", dir);
    FILE *f = fopen(in, "w");
    fputs("M -1 1\nL -1 -1\nL 1 -1\nL 1 1\n", f);
    fclose(f);
    ck_assert_int_eq(run_cmd("'%s' sdf2d '%s' -o '%s' --sign sideways 2>/dev/null%s", in, exr, ""),
                     2);
    ck_assert_int_eq(
        run_cmd("'%s' sdf2d '%s' -o '%s' --sign winding --no-repair 2>/dev/null%s", in, exr, ""),
        1);
    ck_assert_int_eq(
        run_cmd("'%s' sdf2d '%s' -o '%s' --res 32 | grep -q 'sign from the winding number%s'", in,
                exr, ""),
        0);
    unlink(in);
    unlink(exr);
    rmdir(dir);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("sdf2d");
    TCase *tc = tcase_create("broken curves");
    tcase_set_timeout(tc, 60);
    tcase_add_test(tc, clean_circle_should_match_its_distance);
    tcase_add_test(tc, circle_drawn_clockwise_should_still_be_negative_inside);
    tcase_add_test(tc, circle_with_gaps_and_flipped_segments_should_keep_sign_and_distance);
    tcase_add_test(tc, rotated_square_with_gaps_and_flips_should_keep_sign_and_distance);
    tcase_add_test(tc, square_from_separate_sides_with_a_reversed_side_and_an_overlap);
    tcase_add_test(tc, overlapping_collinear_pieces_drawn_backwards_should_not_cancel);
    tcase_add_test(tc, nested_circles_both_counter_clockwise_should_give_an_annulus);
    tcase_add_test(tc, broken_shapes_side_by_side_and_nested_should_each_find_their_inside);
    tcase_add_test(tc, without_repair_a_duplicate_drawn_backwards_should_break_the_sign);
    tcase_add_test(tc, heat_magnitude_should_approximate_the_distance);
    tcase_add_test(tc, open_curves_should_not_depend_on_the_block);
    tcase_add_test(tc, sign_options_should_be_checked);
    tcase_add_test(tc, grid_should_follow_res_and_pad_around_the_curves);
    suite_add_tcase(s, tc);
    tc = tcase_create("nesting index");
    tcase_set_timeout(tc, 60);
    tcase_add_test(tc, nesting_tests_should_grow_linearly_with_disjoint_loops);
    tcase_add_test(tc, loops_inside_loops_should_alternate_sides_with_depth);
    tcase_add_test(tc, index_should_agree_with_all_pairs_on_awkward_loops);
    tcase_add_test(tc, squares_with_t_junctions_and_overlaps_should_split_each_edge_once);
    suite_add_tcase(s, tc);
    tc = tcase_create("readers");
    tcase_add_test(tc, text_format_should_read_commands_and_number_lines);
    tcase_add_test(tc, svg_paths_should_read_absolute_relative_and_implicit_commands);
    tcase_add_test(tc, svg_circle_file_should_give_a_circle_distance);
    suite_add_tcase(s, tc);
    tc = tcase_create("command");
    tcase_set_timeout(tc, 60);
    tcase_add_test(tc, sdf2d_command_should_write_the_library_result_as_exr_and_png);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
