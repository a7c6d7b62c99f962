/* How much memory a run may take, for the checks made before it allocates:
 * the least of the machine's physical memory, the process's address-space
 * limit (ulimit -v) and the memory limit of its cgroup. A container, a
 * systemd unit with MemoryMax or a batch scheduler's job sees the machine's
 * memory through sysconf, and is killed, not refused, when it asks for more
 * than its cgroup allows. */
#include "error.h"
#include "memory.h"

#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <unistd.h>

/* Limits at or above this are "none" (cgroup v1 writes 2^63 rounded down to
 * a page for no limit). */
#define NO_LIMIT ((uint64_t)1 << 60)

/* The number in file, or NO_LIMIT when it says "max", is absent or is not a
 * number. */
static uint64_t read_limit(const char *file)
{
    FILE *f = fopen(file, "r");
    if (!f)
        return NO_LIMIT;
    char line[64] = {0};
    uint64_t v = NO_LIMIT;
    if (fgets(line, sizeof line, f) && line[0] >= '0' && line[0] <= '9') {
        char *end;
        unsigned long long x = strtoull(line, &end, 10);
        if (*end == '\n' || *end == '\0')
            v = x;
    }
    fclose(f);
    return v < NO_LIMIT ? v : NO_LIMIT;
}

/* The least limit named file in dir and in each folder above it, up to and
 * including root (dir lies under root). */
static uint64_t limit_up_to(const char *root, const char *rel, const char *file)
{
    char dir[4096];
    if (snprintf(dir, sizeof dir, "%s%s", root, rel) >= (int)sizeof dir)
        return NO_LIMIT;
    const size_t stop = strlen(root);
    uint64_t least = NO_LIMIT;
    for (;;) {
        char path[4200];
        snprintf(path, sizeof path, "%s/%s", dir, file);
        uint64_t v = read_limit(path);
        least = v < least ? v : least;
        char *slash = strrchr(dir, '/');
        if (strlen(dir) <= stop || !slash || (size_t)(slash - dir) < stop)
            break;
        *slash = '\0';
    }
    return least;
}

/* Whether the comma-separated controller list names "memory". */
static int names_memory(const char *list, size_t len)
{
    for (const char *p = list; p < list + len;) {
        const char *comma = memchr(p, ',', (size_t)(list + len - p));
        size_t n = comma ? (size_t)(comma - p) : (size_t)(list + len - p);
        if (n == 6 && !memcmp(p, "memory", 6))
            return 1;
        p += n + 1;
    }
    return 0;
}

size_t hv__cgroup_memory_limit(const char *proc_cgroup, const char *sys_root)
{
    FILE *f = fopen(proc_cgroup, "r");
    if (!f)
        return SIZE_MAX;
    char line[4096];
    uint64_t least = NO_LIMIT;
    while (fgets(line, sizeof line, f)) {
        line[strcspn(line, "\n")] = '\0';
        /* hierarchy-ID:controller-list:cgroup-path */
        char *c1 = strchr(line, ':'), *c2 = c1 ? strchr(c1 + 1, ':') : NULL;
        if (!c2 || c2[1] != '/')
            continue;
        const char *rel = strcmp(c2 + 1, "/") ? c2 + 1 : "";
        char root[4096];
        uint64_t v = NO_LIMIT;
        if (c2 == c1 + 1 && c1 == line + 1 && line[0] == '0') { /* v2: "0::/path" */
            v = limit_up_to(sys_root, rel, "memory.max");
        } else if (names_memory(c1 + 1, (size_t)(c2 - c1 - 1))) { /* v1 */
            snprintf(root, sizeof root, "%s/memory", sys_root);
            /* inside a container the mount's root is the container's own
             * group, whatever path the line names: the walk up reads it too */
            v = limit_up_to(root, rel, "memory.limit_in_bytes");
        }
        least = v < least ? v : least;
    }
    fclose(f);
    return least < NO_LIMIT && least <= SIZE_MAX ? (size_t)least : SIZE_MAX;
}

/* The machine's memory and the cgroup's limit, read once: grids are checked
 * on every hv_grid_create, and the files cost some 30 us a read. */
static size_t machine_bytes, cgroup_bytes;
static pthread_once_t read_once = PTHREAD_ONCE_INIT;

static void read_limits(void)
{
    long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    machine_bytes = pages > 0 && page > 0 ? (size_t)pages * (size_t)page : SIZE_MAX;
    cgroup_bytes = hv__cgroup_memory_limit("/proc/self/cgroup", "/sys/fs/cgroup");
}

size_t hv__memory_limit(const char **what)
{
    pthread_once(&read_once, read_limits);
    size_t least = machine_bytes;
    const char *why = "machine";
    if (cgroup_bytes < least) {
        least = cgroup_bytes;
        why = "cgroup";
    }
    struct rlimit rl; /* a call of its own: setrlimit may lower it at any time */
    if (!getrlimit(RLIMIT_AS, &rl) && rl.rlim_cur != RLIM_INFINITY && rl.rlim_cur < least) {
        least = (size_t)rl.rlim_cur;
        why = "ulimit";
    }
    if (what)
        *what = why;
    return least;
}

const char *hv__memory_limit_text(char *buf, size_t size)
{
    const char *what;
    const double gb = hv__memory_limit(&what) / 1e9;
    if (!strcmp(what, "cgroup"))
        snprintf(buf, size, "the %.3g GB its cgroup allows", gb);
    else if (!strcmp(what, "ulimit"))
        snprintf(buf, size, "the %.3g GB of address space ulimit -v allows", gb);
    else
        snprintf(buf, size, "this machine's %.3g GB", gb);
    return buf;
}
