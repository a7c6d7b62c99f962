/* heatvox devices: the OpenCL devices --backend opencl can use. */
#include "cli.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void usage(FILE *out)
{
    fprintf(out, "usage: heatvox devices [--json] [-q] [-v]\n"
                 "\n"
                 "Lists the OpenCL devices of every platform; '*' marks the one --backend opencl\n"
                 "uses. Choose another with HEATVOX_OPENCL_DEVICE=\"P:D\" (platform:device) or\n"
                 "part of a device name; by default the first GPU, else the first device.\n"
                 "Then says what --backend auto takes and why: the marked device where it is a\n"
                 "GPU and a grid is large enough, else the CPU backends.\n"
                 "\n"
                 "  --json   one JSON object per device and line, then one with auto,\n"
                 "           auto_min_cells and why\n"
                 "\n"
                 "exit codes: 0 devices listed, 1 no OpenCL platform or HEATVOX_OPENCL_DEVICE\n"
                 "names no device, 2 usage error\n");
}

static void json_string(const char *s)
{
    putchar('"');
    for (; *s; s++) {
        if (*s == '"' || *s == '\\')
            printf("\\%c", *s);
        else if ((unsigned char)*s < 0x20)
            printf("\\u%04x", (unsigned char)*s);
        else
            putchar(*s);
    }
    putchar('"');
}

/* Which device the auto backend takes, and why (hv_backend_resolve). */
static void print_auto(const hv_opencl_device *sel, int json)
{
    const size_t big = HV_AUTO_DEVICE_MIN_CELLS;
    const int dev_big = hv_backend_resolve(HV_BACKEND_AUTO, big, 0) == HV_BACKEND_OPENCL;
    const int dev_small = hv_backend_resolve(HV_BACKEND_AUTO, 1, 0) == HV_BACKEND_OPENCL;
    const char *env = getenv("HEATVOX_AUTO_OPENCL");
    char why[400];
    if (dev_small)
        snprintf(why, sizeof why, "HEATVOX_AUTO_OPENCL=1 lets it take any device, at any size");
    else if (dev_big)
        snprintf(why, sizeof why,
                 "'%s' is a GPU: auto takes it for grids of %zu cells or more, and below that "
                 "fftw for plain boxes and mg with solid cells",
                 sel->name, big);
    else if (env && !strcmp(env, "0"))
        snprintf(why, sizeof why, "HEATVOX_AUTO_OPENCL=0 keeps auto on the CPU");
    else
        snprintf(why, sizeof why,
                 "'%s' is not a GPU: the CPU multigrid is faster on the same cores, so auto "
                 "takes fftw for plain boxes and mg with solid cells (HEATVOX_AUTO_OPENCL=1 "
                 "takes the device)",
                 sel->name);
    if (json) {
        printf("{\"auto\":\"%s\",\"auto_min_cells\":%zu,\"why\":",
               dev_big || dev_small ? "opencl" : "cpu", dev_small ? (size_t)1 : big);
        json_string(why);
        printf("}\n");
    } else {
        printf("auto: %s\n  %s\n",
               dev_big || dev_small ? "opencl on the device marked *" : "the CPU", why);
    }
}

static void help(void) { usage(stdout); }

int cmd_devices(int argc, char **argv)
{
    int json = 0;
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "--json", .kind = CLI_FLAG, .dst = &json, .val = 1},
        {.names = NULL},
    };
    const char *stray = NULL;
    int rc = cli_parse("devices", argc, argv, opts, "argument", &stray, help);
    if (rc >= 0)
        return rc;
    if (stray)
        return cli_usage_error("devices", "unexpected argument '%s'", stray);
    int count = 0;
    hv_status st = hv_opencl_list_devices(NULL, 0, &count);
    if (st)
        return cli_fail("devices", "no OpenCL device", st);
    hv_opencl_device *d = calloc((size_t)count, sizeof *d);
    if (!d)
        return cli_fail("devices", "listing devices", HV_ERR_NOMEM);
    if ((st = hv_opencl_list_devices(d, count, &count))) {
        free(d);
        return cli_fail("devices", "no OpenCL device", st);
    }
    int selected = 0;
    hv_opencl_device sel;
    memset(&sel, 0, sizeof sel);
    if (!json)
        printf("%-5s %-36s %-30s %9s %5s\n", "P:D", "device", "platform", "memory", "fp64");
    for (int i = 0; i < count; i++) {
        selected |= d[i].selected;
        if (d[i].selected)
            sel = d[i];
        char pd[24];
        snprintf(pd, sizeof pd, "%d:%d", d[i].platform, d[i].device);
        if (json) {
            printf("{\"device\":\"%s\",\"name\":", pd);
            json_string(d[i].name);
            printf(",\"platform\":");
            json_string(d[i].platform_name);
            printf(",\"version\":");
            json_string(d[i].version);
            printf(",\"global_mem\":%llu,\"compute_units\":%d,\"fp64\":%s,\"gpu\":%s,\"selected\":%"
                   "s}\n",
                   (unsigned long long)d[i].global_mem, d[i].compute_units,
                   d[i].fp64 ? "true" : "false", d[i].gpu ? "true" : "false",
                   d[i].selected ? "true" : "false");
        } else {
            printf("%-5s %-36.36s %-30.30s %5.1f GiB %5s %s\n", pd, d[i].name, d[i].platform_name,
                   (double)d[i].global_mem / (1024.0 * 1024.0 * 1024.0), d[i].fp64 ? "yes" : "no",
                   d[i].selected ? "*" : "");
            cli_info("      %s, %d compute units, %s\n", d[i].version, d[i].compute_units,
                     d[i].gpu ? "GPU" : "not a GPU");
        }
    }
    free(d);
    if (!selected) {
        /* HEATVOX_OPENCL_DEVICE names none of them: say why */
        st = hv_opencl_probe(NULL);
        return cli_fail("devices", "choosing a device", st ? st : HV_ERR_INTERNAL);
    }
    print_auto(&sel, json);
    return HV_EXIT_OK;
}
