/* The benchmarks' process runner (bench_ref.h): a benchmark that measures a
 * whole command runs it as its own process, so that its time and peak
 * resident memory are those a user sees; and the extension benchmarks'
 * test fields. */
#include "bench_ref.h"

#include <fcntl.h>
#include <math.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

int bench_run_exe(const char *exe, char **argv, const char *out, double *seconds, double *rss_mb,
                  int *code)
{
    double t0 = hv_now();
    pid_t pid = fork();
    if (pid < 0)
        return -1;
    if (pid == 0) {
        int fd = out ? open(out, O_WRONLY | O_CREAT | O_TRUNC, 0644) : -1;
        if (out && (fd < 0 || dup2(fd, STDOUT_FILENO) < 0))
            _exit(126);
        execv(exe, argv);
        _exit(127);
    }
    int status;
    struct rusage ru;
    if (wait4(pid, &status, 0, &ru) != pid)
        return -1;
    *seconds = hv_now() - t0;
    *rss_mb = ru.ru_maxrss / 1024.0;
    *code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return 0;
}

int bench_run_self(char **argv, double *seconds, double *rss_mb)
{
    int code;
    if (bench_run_exe("/proc/self/exe", argv, NULL, seconds, rss_mb, &code) || code)
        return -1;
    return 0;
}

void bench_field_at(const double p[3], double v[3])
{
    v[0] = -p[1] + 0.3;
    v[1] = p[0] + 0.2;
    v[2] = 0.5 + 0.2 * p[2] + 0.3 * sin(3 * p[0]);
}

double bench_scalar_at(const double p[3]) { return 2 + sin(3 * p[0]) * cos(2 * p[1]) + 0.5 * p[2]; }
