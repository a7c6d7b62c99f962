/* heatvox sdf2d: 2D signed distance from (broken) curves to EXR and PNG. */
#include "cli.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>

static void help(void)
{
    printf("usage: heatvox sdf2d CURVES -o OUT.exr [--png FILE] [--res N] [options]\n"
           "\n"
           "Signed distance (negative inside) of 2D curves with the signed heat method on\n"
           "a 2D grid; gaps, flipped segments, duplicates and overlaps are tolerated.\n"
           "CURVES is an SVG file (path, polygon, polyline; M L H V Z C S Q T, absolute\n"
           "and relative) or heatvox's text format: 'M x y', 'L x y', 'Z' lines, or\n"
           "one polyline per line as x0 y0 x1 y1 ... ('#' comments). SVG's y axis is\n"
           "flipped so drawings keep their look with y up.\n"
           "\n"
           "  -o FILE          output EXR: one FLOAT channel (--channel, default\n"
           "                   \"distance\"), row 0 at the top (y up); voxel size and\n"
           "                   origin in the heatvox:* attributes\n"
           "  --png FILE       preview: blue inside, red outside, black zero contour\n"
           "  --range R        preview colour range (default: max |distance|)\n"
           "  --res N          cells along the longest axis of the padded box (default 256)\n"
           "  --voxel-size H   voxel size instead of --res\n"
           "  --pad N          cells around the curves' bounds (default 8)\n"
           "  --bbox X0 Y0 X1 Y1   block bounds instead of --pad\n"
           "  --heat           |distance| from the heat method (default: exact distance to\n"
           "                   the segments, with the heat method's sign)\n"
           "  --t-scale S      diffusion time (S h)^2 (default 1)\n"
           "  --sign S         auto (default: the winding number of the repaired curves\n"
           "                   where they stay open or the block cuts them, so that the\n"
           "                   answer does not depend on the block; the heat method\n"
           "                   otherwise), heat, or winding\n"
           "  --no-repair      no welding, duplicate removal or orientation repair\n"
           "  --backend B      auto, mg, fftw, opencl\n"
           "  -q / -v          no summary / more detail\n"
           "\n"
           "The summary (grid, repair counts, seconds) goes to stdout.\n"
           "exit: 0 written, 1 failure (unreadable curves, I/O), 2 usage error\n");
}

int cmd_sdf2d(int argc, char **argv)
{
    const char *in = NULL, *out = NULL, *png = NULL, *channel = "distance";
    double range = 0;
    hv_sdf2d_opts o;
    hv_sdf2d_opts_default(&o);
    hv_sdf_sign sign = (hv_sdf_sign)o.sign;
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "CURVES", .kind = CLI_WORDS, .files = ".svg .txt"},
        {.names = "-o", .kind = CLI_STR, .dst = &out, .files = ".exr"},
        {.names = "--png", .kind = CLI_STR, .dst = &png, .files = ".png"},
        {.names = "--channel", .kind = CLI_STR, .dst = &channel},
        CLI_ROW_RES(&o.res, 2, NULL),
        CLI_ROW_PAD(&o.pad),
        CLI_ROW_VOXEL_SIZE(&o.voxel_size, NULL),
        CLI_ROW_T_SCALE(&o.t_scale),
        {.names = "--range",
         .kind = CLI_DOUBLE,
         .dst = &range,
         .max = INFINITY,
         .flags = CLI_ABOVE,
         .needs = "a positive number"},
        {.names = "--bbox",
         .kind = CLI_DOUBLES,
         .dst = o.bbox,
         .val = 4,
         .needs = "4 finite numbers (X0 Y0 X1 Y1)",
         .given = &o.use_bbox},
        {.names = "--heat", .kind = CLI_FLAG, .dst = &o.heat_magnitude, .val = 1},
        CLI_ROW_SIGN(&sign),
        CLI_ROW_NO_REPAIR(&o.repair),
        CLI_ROW_BACKEND(&o.backend, CLI_BACKENDS_LOCAL),
        {.names = NULL},
    };
    int prc = cli_parse("sdf2d", argc, argv, opts, "curves file", &in, help);
    if (prc >= 0)
        return prc;
    o.sign = (int)sign;
    if (o.use_bbox && !(o.bbox[2] > o.bbox[0] && o.bbox[3] > o.bbox[1]))
        return cli_usage_error("sdf2d", "--bbox is empty");
    if (!in)
        return cli_usage_error("sdf2d", "no curves file given");
    if (!out && !png)
        return cli_usage_error("sdf2d", "no output: give -o OUT.exr and/or --png FILE");
    if (cli_check_ext("sdf2d", "-o", out, ".exr") || cli_check_ext("sdf2d", "--png", png, ".png"))
        return HV_EXIT_USAGE;
    const char *outs[] = {out, png};
    if (cli_check_outputs("sdf2d", outs, 2, &in, 1))
        return HV_EXIT_FAIL;
    hv_curves *c = NULL;
    hv_status st = hv_curves_read(in, &c);
    if (st)
        return cli_fail("sdf2d", in, st);
    hv_grid *g = NULL;
    hv_sdf2d_stats S;
    st = hv_curves_sdf(c, &o, &g, &S);
    hv_curves_destroy(&c);
    if (st)
        return cli_fail("sdf2d", in, st);
    double t0 = hv_now();
    cli_outputs co = {0};
    const char *t_out = out ? cli_stage("sdf2d", &co, out) : NULL;
    const char *t_png = png && (!out || t_out) ? cli_stage("sdf2d", &co, png) : NULL;
    if ((out && !t_out) || (png && !t_png)) {
        cli_discard(&co);
        hv_grid_destroy(&g);
        return HV_EXIT_FAIL;
    }
    const char *failed = NULL;
    if (out && (st = hv_exr_write(t_out, g, channel)) != HV_OK)
        failed = out;
    if (!failed && png && (st = hv_png_write(t_png, g, range)) != HV_OK)
        failed = png;
    hv_grid_destroy(&g);
    if (failed) {
        cli_discard(&co);
        return cli_fail("sdf2d", failed, st);
    }
    if (cli_commit("sdf2d", &co))
        return HV_EXIT_FAIL;
    double t_write = hv_now() - t0;
    if (cli_verbose >= 0) {
        printf("%s: %d x %d cells, h %g, origin (%g, %g)\n", in, S.n[0], S.n[1], S.h, S.origin[0],
               S.origin[1]);
        printf("  segments %zu in, %zu used (%zu points welded, %zu zero-length, %zu "
               "duplicates dropped; %zu reversed; %zu chains, %zu closed)\n",
               S.segments_in, S.segments_out, S.points_welded, S.zero_length_removed,
               S.duplicates_removed, S.segments_flipped, S.chains, S.cycles);
        if (S.sign == 2)
            printf("  sign from the winding number (%zu open ends, %zu evaluations); %.3f s (+ "
                   "%.3f s writing)\n",
                   S.open_ends, S.winding_evals, S.t_total, t_write);
        else
            printf("  %d diffusion level%s on %s, %zu decayed faces; %.3f s (+ %.3f s writing)\n",
                   S.levels, S.levels == 1 ? "" : "s", hv_backend_name(S.backend), S.dead_faces,
                   S.t_total, t_write);
        if (out)
            printf("  wrote %s\n", out);
        if (png)
            printf("  wrote %s\n", png);
    }
    return HV_EXIT_OK;
}
