/* The memory a run may take (src/core/memory.c): the cgroup's limit read
 * from fake /proc/self/cgroup files and cgroup trees, v1 and v2, and the
 * address-space limit (ulimit -v) as the size checks see it, in a child. */
#include "core/error.h"
#include "core/memory.h"
#include "testlib.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

static char dir[256];

static void make_dir(void)
{
    snprintf(dir, sizeof dir, "/tmp/hv_memlimit_XXXXXX");
    ck_assert_ptr_nonnull(mkdtemp(dir));
}

static void remove_dir(void) { tl_rm_rf(dir); }

/* Writes text to dir/rel, making the folders on the way. */
static void put(const char *rel, const char *text)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", dir, rel);
    for (char *p = path + strlen(dir) + 1; (p = strchr(p, '/')); p++) {
        *p = '\0';
        mkdir(path, 0700);
        *p = '/';
    }
    FILE *f = fopen(path, "w");
    ck_assert_ptr_nonnull(f);
    fputs(text, f);
    fclose(f);
}

static size_t limit_of(void)
{
    char proc[512], sys[512];
    snprintf(proc, sizeof proc, "%s/cgroup", dir);
    snprintf(sys, sizeof sys, "%s/sys", dir);
    return hv__cgroup_memory_limit(proc, sys);
}

START_TEST(cgroup_v2_limit_should_be_the_least_of_the_group_and_those_above)
{
    put("cgroup", "0::/user.slice/job-7\n");
    put("sys/user.slice/job-7/memory.max", "max\n");
    put("sys/user.slice/memory.max", "6442450944\n");
    put("sys/memory.max", "8589934592\n");
    ck_assert_uint_eq(limit_of(), (size_t)6442450944u);
    put("sys/user.slice/job-7/memory.max", "1073741824\n");
    ck_assert_uint_eq(limit_of(), (size_t)1073741824u);
}
END_TEST

START_TEST(cgroup_v2_without_a_limit_should_give_none)
{
    put("cgroup", "0::/\n");
    ck_assert_uint_eq(limit_of(), SIZE_MAX); /* no memory.max at all */
    put("sys/memory.max", "max\n");
    ck_assert_uint_eq(limit_of(), SIZE_MAX);
    put("sys/memory.max", "12x\n"); /* not a number: not a limit */
    ck_assert_uint_eq(limit_of(), SIZE_MAX);
}
END_TEST

START_TEST(cgroup_v1_memory_line_should_be_read_and_others_ignored)
{
    /* the other controllers' lines and a v2 line without a limit around it */
    put("cgroup", "9:name=systemd:/\n5:cpu,cpuacct:/docker/abc\n4:blkio,memory:/docker/abc\n"
                  "0::/\n");
    put("sys/memory/docker/abc/memory.limit_in_bytes", "4294967296\n");
    put("sys/memory/memory.limit_in_bytes", "9223372036854771712\n"); /* v1's "none" */
    put("sys/cpu,cpuacct/docker/abc/memory.limit_in_bytes", "1\n");   /* not the memory line */
    ck_assert_uint_eq(limit_of(), (size_t)4294967296u);
}
END_TEST

START_TEST(cgroup_v1_in_a_container_should_read_the_mount_root)
{
    /* the path names the host's group; the container's mount shows only its
     * own group, at the root */
    put("cgroup", "4:memory:/process_api/bf079a\n");
    put("sys/memory/memory.limit_in_bytes", "2147483648\n");
    ck_assert_uint_eq(limit_of(), (size_t)2147483648u);
}
END_TEST

START_TEST(cgroup_files_absent_or_damaged_should_give_none)
{
    ck_assert_uint_eq(limit_of(), SIZE_MAX); /* no /proc file */
    put("cgroup", "garbage\n::\n4:memory\n0::relative\n\n");
    ck_assert_uint_eq(limit_of(), SIZE_MAX);
}
END_TEST

/* Virtual memory of this process, in bytes (0 where unknown). */
static size_t vm_size(void)
{
    FILE *f = fopen("/proc/self/status", "r");
    size_t kb = 0;
    char line[256];
    while (f && fgets(line, sizeof line, f))
        if (sscanf(line, "VmSize: %zu kB", &kb) == 1)
            break;
    if (f)
        fclose(f);
    return kb << 10;
}

START_TEST(address_space_limit_should_bound_the_size_checks)
{
    const size_t cap = (size_t)3 << 30;
    if (vm_size() + ((size_t)1 << 30) > cap)
        TL_SKIP("this build already maps %zu MB (a sanitizer's shadow): a %zu MB ulimit -v "
                "cannot be tried",
                vm_size() >> 20, cap >> 20);
    size_t before = hv__memory_limit(NULL);
    ck_assert_uint_gt(before, cap);
    int fd[2];
    ck_assert_int_eq(pipe(fd), 0);
    pid_t pid = fork();
    ck_assert_int_ge(pid, 0);
    if (pid == 0) { /* the child: the cap, the limit, and a grid past it */
        close(fd[0]);
        struct rlimit rl = {cap, cap};
        char out[512] = "setrlimit failed";
        if (!setrlimit(RLIMIT_AS, &rl)) {
            const char *what = "?";
            size_t got = hv__memory_limit(&what);
            const int n[3] = {1024, 1024, 1024}; /* 4.3 GB of floats */
            hv_status st = hv_check_dims(3, n, 1.0, sizeof(float));
            snprintf(out, sizeof out, "%zu %s %d %s", got, what, (int)st, hv_last_error());
        }
        ssize_t w = write(fd[1], out, strlen(out) + 1);
        _exit(w > 0 ? 0 : 1);
    }
    close(fd[1]);
    char got[512] = {0};
    ssize_t r = read(fd[0], got, sizeof got - 1);
    close(fd[0]);
    int status;
    waitpid(pid, &status, 0);
    ck_assert_msg(r > 0 && WIFEXITED(status) && WEXITSTATUS(status) == 0, "child: %s", got);
    size_t limit;
    char what[32];
    int st;
    ck_assert_msg(sscanf(got, "%zu %31s %d", &limit, what, &st) == 3, "child: %s", got);
    ck_assert_uint_eq(limit, cap);
    ck_assert_str_eq(what, "ulimit");
    ck_assert_int_eq(st, HV_ERR_NOMEM);
    ck_assert_msg(strstr(got, "grid 1024 x 1024 x 1024 needs 4.29 GB, more than the 3.22 GB of "
                              "address space ulimit -v allows"),
                  "%s", got);
    /* the parent, without the cap, takes the same grid */
    const int n[3] = {1024, 1024, 1024};
    ck_assert_int_eq(hv_check_dims(3, n, 1.0, sizeof(float)), HV_OK);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("memory_limit");
    TCase *tc = tcase_create("memory_limit");
    tcase_add_checked_fixture(tc, make_dir, remove_dir);
    tcase_add_test(tc, cgroup_v2_limit_should_be_the_least_of_the_group_and_those_above);
    tcase_add_test(tc, cgroup_v2_without_a_limit_should_give_none);
    tcase_add_test(tc, cgroup_v1_memory_line_should_be_read_and_others_ignored);
    tcase_add_test(tc, cgroup_v1_in_a_container_should_read_the_mount_root);
    tcase_add_test(tc, cgroup_files_absent_or_damaged_should_give_none);
    tcase_add_test(tc, address_space_limit_should_bound_the_size_checks);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
