/* heatvox bench sdf2d: `heatvox sdf2d` on a generated SVG of many small closed
 * paths, with the repair against --no-repair on the same file in the same run.
 * Each run is a child process, so that its peak memory is its own. */
#include "../cli.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

static int usage(FILE *out)
{
    fprintf(out,
            "usage: heatvox bench sdf2d --n N [--res R] [--repeat K] [--dir DIR] [--keep]\n"
            "Writes an SVG of N closed paths to DIR (default $TMPDIR, else /tmp): hexagons\n"
            "of radius 1.5 on a lattice of pitch 4, turned at random and about half of them\n"
            "clockwise, every 8th holding a second hexagon and every 64th a third (N counts\n"
            "them all), then runs `heatvox sdf2d FILE -o FILE.exr --res R` (default 256) with\n"
            "the repair and with --no-repair (best of K runs each, default 1), and prints\n"
            "one JSON line: bench, n, svg_mb, res, backend, seconds (wall time of the\n"
            "command), peak_rss_mb (of that process), ref \"no-repair\", ref_seconds,\n"
            "ref_peak_rss_mb, ratio = seconds / ref_seconds. The files are removed unless\n"
            "--keep.\n");
    return out == stdout ? HV_EXIT_OK : HV_EXIT_USAGE;
}

/* splitmix64: a hash of the cell number, so that the file is the same every run */
static uint64_t mix(uint64_t x)
{
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5bbull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

static void hexagon(FILE *f, double cx, double cy, double r, uint64_t h)
{
    double rot = (double)(h >> 11) / (double)(1ull << 53), dir = h & 1 ? -1 : 1;
    double px = cx + r * cos(rot), py = cy + r * sin(rot);
    fprintf(f, "<path d=\"M%.4f %.4f", px, py);
    for (int k = 1; k < 6; k++) {
        double a = rot + dir * k * M_PI / 3;
        double x = cx + r * cos(a), y = cy + r * sin(a);
        fprintf(f, "l%.4f %.4f", x - px, y - py);
        px = x;
        py = y;
    }
    fputs("z\"/>\n", f);
}

static int write_svg(const char *path, long n)
{
    FILE *f = fopen(path, "w");
    if (!f)
        return -1;
    long cells = 0;
    for (long k = 0, paths = 0; paths < n; k++, cells++)
        paths += 1 + (k % 8 == 0) + (k % 64 == 0);
    long side = (long)ceil(sqrt((double)cells));
    fputs("<svg xmlns=\"http://www.w3.org/2000/svg\">\n", f);
    for (long k = 0, paths = 0; paths < n; k++) {
        double cx = 4.0 * (k % side), cy = 4.0 * (k / side);
        double r[3] = {1.5, 0.9, 0.4};
        for (int d = 0; d < 3 && paths < n; d++) {
            if ((d == 1 && k % 8) || (d == 2 && k % 64))
                break;
            hexagon(f, cx, cy, r[d], mix(3 * (uint64_t)k + d));
            paths++;
        }
    }
    fputs("</svg>\n", f);
    return fclose(f) ? -1 : 0;
}

/* Runs this executable's sdf2d on svg; stdout is read back for the backend. */
static int run_sdf2d(const char *svg, const char *exr, int res, int repair, double *seconds,
                     double *rss_mb, char *backend, size_t bsize)
{
    char rs[32];
    snprintf(rs, sizeof rs, "%d", res);
    char *argv[] = {"heatvox",   "sdf2d", (char *)svg, "-o",
                    (char *)exr, "--res", rs,          repair ? NULL : "--no-repair",
                    NULL};
    int fd[2];
    if (pipe(fd))
        return -1;
    double t0 = hv_now();
    pid_t pid = fork();
    if (pid < 0)
        return -1;
    if (pid == 0) {
        dup2(fd[1], 1);
        close(fd[0]);
        close(fd[1]);
        execv("/proc/self/exe", argv);
        _exit(127);
    }
    close(fd[1]);
    FILE *out = fdopen(fd[0], "r");
    char line[1024];
    while (out && fgets(line, sizeof line, out)) {
        const char *on = strstr(line, " diffusion level");
        if (on && (on = strstr(on, " on "))) {
            snprintf(backend, bsize, "%s", on + 4);
            backend[strcspn(backend, ",\n")] = '\0';
        }
    }
    if (out)
        fclose(out);
    else
        close(fd[0]);
    int status;
    struct rusage ru;
    if (wait4(pid, &status, 0, &ru) != pid || !WIFEXITED(status) || WEXITSTATUS(status))
        return -1;
    *seconds = hv_now() - t0;
    *rss_mb = ru.ru_maxrss / 1024.0;
    return 0;
}

static void help(void) { usage(stdout); }

int cmd_bench_sdf2d(int argc, char **argv)
{
    int n = 0, res = 256, repeat = 1, keep = 0;
    const char *dir = getenv("TMPDIR");
    dir = dir && *dir ? dir : "/tmp";
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "--keep", .kind = CLI_FLAG, .dst = &keep, .val = 1},
        {.names = "--n",
         .kind = CLI_INT,
         .dst = &n,
         .min = 1,
         .max = INT_MAX,
         .needs = "an integer >= 1"},
        CLI_ROW_RES(&res, 32, NULL),
        CLI_ROW_REPEAT(&repeat),
        {.names = "--dir", .kind = CLI_STR, .dst = &dir, .files = CLI_FILES_DIR},
        {.names = NULL},
    };
    const char *stray = NULL;
    int prc = cli_parse("bench sdf2d", argc, argv, opts, "argument", &stray, help);
    if (prc >= 0)
        return prc;
    if (stray)
        return cli_usage_error("bench sdf2d", "unexpected argument '%s'", stray);
    if (!n)
        return cli_usage_error("bench sdf2d", "--n is required");
    char svg[4096], exr[4200];
    snprintf(svg, sizeof svg, "%s/heatvox-bench-sdf2d-%d-%ld.svg", dir, n, (long)getpid());
    snprintf(exr, sizeof exr, "%s.exr", svg);
    if (write_svg(svg, n)) {
        unlink(svg);
        return cli_fail("bench sdf2d", svg, HV_ERR_IO);
    }
    struct stat sb;
    double svg_mb = stat(svg, &sb) ? 0 : sb.st_size / 1048576.0;
    double best[2] = {1e30, 1e30}, rss[2] = {0, 0};
    char backend[64] = "?";
    int failed = 0;
    for (int r = 0; r < repeat && !failed; r++)
        for (int repair = 1; repair >= 0 && !failed; repair--) {
            double t, m;
            if (run_sdf2d(svg, exr, res, repair, &t, &m, backend, sizeof backend)) {
                failed = 1;
                break;
            }
            best[!repair] = t < best[!repair] ? t : best[!repair];
            rss[!repair] = m > rss[!repair] ? m : rss[!repair];
        }
    if (!keep) {
        unlink(svg);
        unlink(exr);
    }
    if (failed) {
        fprintf(stderr, "heatvox bench sdf2d: heatvox sdf2d failed on %s\n", svg);
        return HV_EXIT_FAIL;
    }
    printf("{\"bench\":\"sdf2d\",\"n\":%d,\"svg_mb\":%.1f,\"res\":%d,\"backend\":\"%s\","
           "\"seconds\":%.3f,\"peak_rss_mb\":%.1f,\"ref\":\"no-repair\",\"ref_seconds\":%.3f,"
           "\"ref_peak_rss_mb\":%.1f,\"ratio\":%.3f}\n",
           n, svg_mb, res, backend, best[0], rss[0], best[1], rss[1], best[0] / best[1]);
    fflush(stdout);
    return HV_EXIT_OK;
}
