/* heatvox slice: one 2D slice of a volume, as EXR data or a PNG preview. */
#include "cli.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>

static void help(void)
{
    printf("usage: heatvox slice VOLUME [--grid NAME] [--axis x|y|z] [--index K]\n"
           "                    -o OUT.exr|OUT.png [--range R]\n"
           "\n"
           "Cuts the plane at index K (default: the middle) across the axis (default z)\n"
           "out of a volume and writes it as a one-channel float EXR or a PNG preview\n"
           "(blue inside, red outside, black zero contour), chosen by the extension.\n"
           "The slice keeps the other two axes in order: a z slice shows x to the right\n"
           "and y up, a y slice x and z, an x slice y and z.\n"
           "\n"
           "VOLUME is an OpenVDB file (.vdb: a float or double grid, read densely over\n"
           "the block heatvox wrote, else over its active voxels) or a heatvox EXR volume\n"
           "(one part per z slice, as written by heatvox batch --format exr).\n"
           "\n"
           "  --grid NAME   the grid or EXR channel to read (default: the only one, or\n"
           "                \"distance\"/\"Y\")\n"
           "  --range R     PNG colour range (default: max |value| of the slice)\n"
           "\n"
           "exit: 0 written, 1 failure (unreadable volume, index out of range, I/O),\n"
           "2 usage error\n");
}

static int ends_with(const char *s, const char *ext)
{
    size_t n = strlen(s), e = strlen(ext);
    return n > e && !strcasecmp(s + n - e, ext);
}

/* The grid to slice in a VDB file: the named one, else the only float grid,
 * else "sdf" (heatvox's level sets). */
static hv_status read_vdb(const char *path, const char *grid, hv_grid **out)
{
    char pick[256];
    if (!grid) {
        size_t count = 0;
        hv_vdb_grid_info info[64];
        hv_status st = hv_vdb_list(path, info, 64, &count);
        if (st)
            return st;
        int nfloat = 0;
        snprintf(pick, sizeof pick, "sdf");
        for (size_t i = 0; i < count && i < 64; i++)
            if (!strcmp(info[i].value_type, "float") || !strcmp(info[i].value_type, "double")) {
                if (!nfloat++)
                    snprintf(pick, sizeof pick, "%s", info[i].name);
            }
        if (nfloat > 1)
            snprintf(pick, sizeof pick, "sdf");
        grid = pick;
    }
    return hv_vdb_read_float(path, grid, NULL, out, NULL);
}

static hv_status read_volume(const char *path, const char *grid, hv_grid **out)
{
    if (ends_with(path, ".vdb"))
        return read_vdb(path, grid, out);
    if (!grid) {
        /* heatvox writes volumes with a "distance" channel; other files name theirs */
        hv_status st = hv_exr_read(path, "distance", out);
        if (st == HV_OK)
            return st;
        return hv_exr_read(path, NULL, out);
    }
    return hv_exr_read(path, grid, out);
}

/* --axis x|y|z: 0, 1 or 2. */
static int take_axis(const char *cmd, const char *opt, char **v, int nv, void *dst)
{
    if (nv < 1 || strlen(v[0]) != 1 || !strchr("xyz", v[0][0]))
        return -cli_usage_error(cmd, "%s needs x, y or z%s%s%s", opt, nv ? ", got '" : "",
                                nv ? v[0] : "", nv ? "'" : "");
    *(int *)dst = v[0][0] - 'x';
    return 1;
}

int cmd_slice(int argc, char **argv)
{
    const char *in = NULL, *out = NULL, *grid = NULL;
    int axis = 2, index = -1;
    double range = 0;
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "VOLUME", .kind = CLI_WORDS, .files = ".vdb .exr"},
        CLI_ROW_OUTPUT(&out, ".exr .png"),
        {.names = "--grid", .kind = CLI_STR, .dst = &grid},
        {.names = "--axis",
         .kind = CLI_FN,
         .dst = &axis,
         .val = 1,
         .fn = take_axis,
         .choices = "x|y|z"},
        {.names = "--index",
         .kind = CLI_INT,
         .dst = &index,
         .max = INT_MAX,
         .needs = "an integer >= 0"},
        {.names = "--range",
         .kind = CLI_DOUBLE,
         .dst = &range,
         .max = INFINITY,
         .flags = CLI_ABOVE,
         .needs = "a positive number"},
        {.names = NULL},
    };
    int prc = cli_parse("slice", argc, argv, opts, "input", &in, help);
    if (prc >= 0)
        return prc;
    if (!in)
        return cli_usage_error("slice", "no volume given");
    if (!out)
        return cli_usage_error("slice", "no output (-o OUT.exr or OUT.png)");
    int png = ends_with(out, ".png");
    if (!png && !ends_with(out, ".exr"))
        return cli_usage_error("slice", "output '%s' must end in .exr or .png", out);
    if (cli_check_outputs("slice", &out, 1, &in, 1))
        return HV_EXIT_FAIL;
    hv_grid *g = NULL;
    hv_status st = read_volume(in, grid, &g);
    if (st)
        return cli_fail("slice", in, st);
    if (g->dim == 2 && axis != 2) {
        fprintf(stderr, "heatvox slice: %s: a 2D image has only z slices\n", in);
        hv_grid_destroy(&g);
        return HV_EXIT_FAIL;
    }
    if (index < 0)
        index = g->n[axis] / 2;
    hv_grid *s = NULL;
    st = hv_grid_slice(g, axis, index, &s);
    hv_grid_destroy(&g);
    if (st)
        return cli_fail("slice", in, st);
    st = png ? hv_png_write(out, s, range) : hv_exr_write(out, s, "distance");
    if (st) {
        hv_grid_destroy(&s);
        return cli_fail("slice", out, st);
    }
    if (cli_verbose >= 0)
        printf("%s: %c = %d slice, %d x %d -> %s\n", in, "xyz"[axis], index, s -> n[0], s -> n[1],
               out);
    hv_grid_destroy(&s);
    return HV_EXIT_OK;
}
