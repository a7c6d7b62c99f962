#include "heatvox/core.h"
#include "error.h"

#include <dirent.h>
#include <errno.h>
#include <signal.h>
#include <stdlib.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* A fixed table of pending temporaries, so that a signal handler can unlink them
 * without allocating or locking. */
#define HV_TMP_SLOTS 64
#define HV_TMP_LEN 4096
static char tmp_names[HV_TMP_SLOTS][HV_TMP_LEN];
static atomic_int tmp_used[HV_TMP_SLOTS];
static atomic_uint tmp_counter;

static void tmp_register(const char *name)
{
    for (int i = 0; i < HV_TMP_SLOTS; i++) {
        int expect = 0;
        if (atomic_compare_exchange_strong(&tmp_used[i], &expect, 2)) {
            snprintf(tmp_names[i], HV_TMP_LEN, "%s", name);
            atomic_store(&tmp_used[i], 1);
            return;
        }
    }
}

/* Whether name is a temporary this process has staged and not yet committed. */
static int tmp_is_ours(const char *name)
{
    for (int i = 0; i < HV_TMP_SLOTS; i++)
        if (atomic_load(&tmp_used[i]) == 1 && strcmp(tmp_names[i], name) == 0)
            return 1;
    return 0;
}

static void tmp_unregister(const char *name)
{
    for (int i = 0; i < HV_TMP_SLOTS; i++)
        if (atomic_load(&tmp_used[i]) == 1 && strcmp(tmp_names[i], name) == 0) {
            atomic_store(&tmp_used[i], 0);
            return;
        }
}

/* The pid in a temporary's name "<dots><base>.tmp-<pid>-...", or 0 where the
 * name is no temporary of base. One leading dot is the rule; two are the name
 * of a temporary of a temporary, which a killed writer can leave. */
static long stale_pid(const char *n, const char *base, size_t blen)
{
    for (int dots = 1; dots <= 2; dots++) {
        if (n[dots - 1] != '.')
            return 0;
        const char *p = n + dots;
        if (strncmp(p, base, blen) != 0 || strncmp(p + blen, ".tmp-", 5) != 0)
            continue;
        char *end = NULL;
        long pid = strtol(p + blen + 5, &end, 10);
        return pid > 0 && end && *end == '-' ? pid : 0;
    }
    return 0;
}

/* A process killed by SIGKILL (or a crash, or a power cut) leaves its
 * "<dir>/.<base>.tmp-<pid>-<n>" behind. The next write of the same name removes
 * those whose process is gone; a live pid's temporaries are left alone. */
static void remove_stale(const char *dir, const char *base)
{
    DIR *d = opendir(*dir ? dir : ".");
    if (!d)
        return;
    size_t blen = strlen(base);
    struct dirent *e;
    while ((e = readdir(d))) {
        const char *n = e->d_name;
        long pid = stale_pid(n, base, blen);
        if (pid <= 0 || pid == (long)getpid())
            continue;
        if (kill((pid_t)pid, 0) == 0 || errno != ESRCH)
            continue;
        char path[HV_TMP_LEN];
        if (snprintf(path, sizeof path, "%s%s", dir, n) < (int)sizeof path)
            unlink(path);
    }
    closedir(d);
}

hv_status hv_tmp_name(const char *target, char *tmp, size_t tmpsize)
{
    if (!target || !*target)
        return hv__error(HV_ERR_INVALID_ARG, "output path is empty");
    const char *slash = strrchr(target, '/');
    int dirlen = slash ? (int)(slash - target + 1) : 0;
    const char *base = slash ? slash + 1 : target;
    if (!*base)
        return hv__error(HV_ERR_INVALID_ARG, "output path '%s' names a directory", target);
    /* A writer handed a temporary that a caller has staged (the command stages
     * every output, then the writer stages its own) writes straight into it:
     * one temporary per output, whose name the next write of that output knows. */
    if (tmp_is_ours(target)) {
        if (strlen(target) >= tmpsize)
            return hv__error(HV_ERR_INVALID_ARG, "output path '%s' is too long", target);
        memcpy(tmp, target, strlen(target) + 1);
        return HV_OK;
    }
    /* Renaming onto a device or FIFO would replace it (as root, /dev/null). */
    struct stat sb;
    if (stat(target, &sb) == 0 && !S_ISREG(sb.st_mode))
        return hv__error(HV_ERR_IO, "%s: exists and is not a regular file; it is not replaced",
                         target);
    char dir[HV_TMP_LEN];
    if (dirlen >= (int)sizeof dir)
        return hv__error(HV_ERR_INVALID_ARG, "output path '%s' is too long", target);
    memcpy(dir, target, (size_t)dirlen);
    dir[dirlen] = '\0';
    remove_stale(dir, base);
    int n = snprintf(tmp, tmpsize, "%.*s.%s.tmp-%ld-%u", dirlen, target, base, (long)getpid(),
                     atomic_fetch_add(&tmp_counter, 1u));
    if (n < 0 || (size_t)n >= tmpsize || n >= HV_TMP_LEN)
        return hv__error(HV_ERR_INVALID_ARG, "output path '%s' is too long", target);
    tmp_register(tmp);
    return HV_OK;
}

hv_status hv_tmp_commit(const char *tmp, const char *target)
{
    if (strcmp(tmp, target) == 0)
        return HV_OK; /* written into the caller's temporary; the caller commits it */
    if (rename(tmp, target) != 0) {
        int e = errno;
        unlink(tmp);
        tmp_unregister(tmp);
        return hv__error(HV_ERR_IO, "%s: cannot rename the finished output into place: %s", target,
                         strerror(e));
    }
    tmp_unregister(tmp);
    return HV_OK;
}

void hv_tmp_discard(const char *tmp)
{
    unlink(tmp);
    tmp_unregister(tmp);
}

void hv_tmp_cleanup_all(void)
{
    for (int i = 0; i < HV_TMP_SLOTS; i++)
        if (atomic_load(&tmp_used[i]) == 1)
            unlink(tmp_names[i]);
}

FILE *hv__tmp_open(const char *path, char *tmp, size_t tmpsize, hv_status *st)
{
    if ((*st = hv_tmp_name(path, tmp, tmpsize)))
        return NULL;
    FILE *f = fopen(tmp, "wb");
    if (!f) {
        int e = errno;
        hv_tmp_discard(tmp);
        *st = hv__error(HV_ERR_IO, "%s: cannot create the output file: %s", path, strerror(e));
    }
    return f;
}
