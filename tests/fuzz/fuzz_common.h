/* Shared by the libFuzzer targets: the readers take paths, so each input is
 * written to a per-process file on tmpfs (/dev/shm, else $TMPDIR, else /tmp)
 * named with the extension the reader dispatches on, and removed after the
 * call. A target defines FUZZ_EXT and calls fz_file() from
 * LLVMFuzzerTestOneInput. */
#ifndef HV_FUZZ_COMMON_H
#define HV_FUZZ_COMMON_H

#include "heatvox/heatvox.h"

#include <fcntl.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static inline const char *fz_dir(void)
{
    struct stat sb;
    if (stat("/dev/shm", &sb) == 0 && S_ISDIR(sb.st_mode) && access("/dev/shm", W_OK) == 0)
        return "/dev/shm";
    const char *t = getenv("TMPDIR");
    return t && *t ? t : "/tmp";
}

/* Writes data to this process's input file, named with ext (a string of
 * static storage), and returns its path (static storage), or NULL when the
 * file cannot be written (the input is skipped). */
static inline const char *fz_file(const uint8_t *data, size_t size, const char *ext)
{
    static char path[512];
    static const char *named_for;
    if (!path[0] || ext != named_for)
        snprintf(path, sizeof path, "%s/hvfz-%ld%s", fz_dir(), (long)getpid(), ext);
    named_for = ext;
    int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, 0600);
    if (fd < 0)
        return NULL;
    size_t done = 0;
    while (done < size) {
        ssize_t w = write(fd, data + done, size - done);
        if (w <= 0) {
            close(fd);
            unlink(path);
            return NULL;
        }
        done += (size_t)w;
    }
    close(fd);
    return path;
}

static inline void fz_done(const char *path)
{
    if (path)
        unlink(path);
}

#endif
