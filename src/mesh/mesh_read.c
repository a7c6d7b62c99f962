/* hv_mesh_read: loads the file, picks the reader by extension or content (the
 * formats assimp reads by extension, handing it the path), and the number
 * scanning the text readers share. */
#include "mesh_internal.h"

#include <errno.h>
#include <locale.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

/* ---- numbers ---- */

static locale_t c_locale;
static pthread_once_t c_locale_once = PTHREAD_ONCE_INIT;
static void c_locale_init(void) { c_locale = newlocale(LC_ALL_MASK, "C", (locale_t)0); }

int hv__mesh_parse_double(const char *s, const char **end, double *out)
{
    /* strtod would skip leading white space, newlines included */
    if (mesh_is_delim(*s))
        return -1;
    pthread_once(&c_locale_once, c_locale_init);
    char *e;
    double v = c_locale ? strtod_l(s, &e, c_locale) : strtod(s, &e);
    if (e == s)
        return -1;
    *out = v;
    *end = e;
    return 0;
}

int hv__mesh_parse_i64(const char *s, const char **end, int64_t *out)
{
    int neg = 0;
    const char *p = s;
    if (*p == '+' || *p == '-')
        neg = *p++ == '-';
    if (*p < '0' || *p > '9')
        return -1;
    uint64_t v = 0;
    while (*p >= '0' && *p <= '9') {
        unsigned d = (unsigned)(*p++ - '0');
        if (v > (UINT64_C(9223372036854775807) - d) / 10)
            return -1;
        v = v * 10 + d;
    }
    *out = neg ? -(int64_t)v : (int64_t)v;
    *end = p;
    return 0;
}

const char *hv__mesh_token_preview(const char *s, const char *end)
{
    static _Thread_local char buf[64];
    size_t n = 0;
    while (s < end && !mesh_is_delim(*s) && n < 24) {
        unsigned char c = (unsigned char)*s++;
        buf[n++] = c >= 32 && c < 127 ? (char)c : '?';
    }
    if (s < end && !mesh_is_delim(*s)) {
        memcpy(buf + n, "...", 3);
        n += 3;
    }
    buf[n] = '\0';
    return buf;
}

/* ---- files ---- */

/* Pipes (FIFOs, such as a shell's <(...)) are read up to this many bytes. */
#define MESH_MAX_PIPE_BYTES ((size_t)1 << 30)

static const char *file_kind(mode_t m)
{
    return S_ISDIR(m)    ? "a directory"
           : S_ISCHR(m)  ? "a character device"
           : S_ISBLK(m)  ? "a block device"
           : S_ISSOCK(m) ? "a socket"
                         : "not a regular file";
}

/* Regular files are read whole; FIFOs up to MESH_MAX_PIPE_BYTES; anything else
 * (directories, devices such as /dev/zero, sockets) is refused before it is
 * opened, and checked again on the open descriptor. */
hv_status hv__mesh_read_file(const char *path, char **out, size_t *len)
{
    *out = NULL;
    *len = 0;
    struct stat sb;
    if (stat(path, &sb) != 0)
        return hv__error(HV_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    if (!S_ISREG(sb.st_mode) && !S_ISFIFO(sb.st_mode))
        return hv__error(HV_ERR_IO, "%s: is %s; meshes are read from regular files or pipes", path,
                         file_kind(sb.st_mode));
    FILE *f = fopen(path, "rb");
    if (!f)
        return hv__error(HV_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    if (fstat(fileno(f), &sb) != 0) {
        int e = errno;
        fclose(f);
        return hv__error(HV_ERR_IO, "%s: cannot stat: %s", path, strerror(e));
    }
    int regular = S_ISREG(sb.st_mode);
    if (!regular && !S_ISFIFO(sb.st_mode)) {
        fclose(f);
        return hv__error(HV_ERR_IO, "%s: is %s; meshes are read from regular files or pipes", path,
                         file_kind(sb.st_mode));
    }
    if (regular && (uint64_t)sb.st_size >= SIZE_MAX / 2) {
        fclose(f);
        return hv__error(HV_ERR_NOMEM, "%s: file too large", path);
    }
    /* A regular file's size sizes the buffer (it may still grow while read); a
     * pipe's buffer grows up to the bound. */
    size_t cap = regular ? (size_t)sb.st_size + 1 : 1 << 16, n = 0;
    const size_t limit = MESH_MAX_PIPE_BYTES;
    char *buf = malloc(cap);
    if (!buf) {
        fclose(f);
        return hv__error(HV_ERR_NOMEM, "%s: out of memory for %zu bytes", path, cap);
    }
    for (;;) {
        if (!regular && n > limit) {
            free(buf);
            fclose(f);
            return hv__error(HV_ERR_IO, "%s: more than %zu MiB from a pipe; save it to a file",
                             path, limit >> 20);
        }
        if (n + 1 >= cap) {
            char *q = cap < SIZE_MAX / 4 ? realloc(buf, cap * 2) : NULL;
            if (!q) {
                free(buf);
                fclose(f);
                return hv__error(HV_ERR_NOMEM, "%s: out of memory reading the file", path);
            }
            buf = q;
            cap *= 2;
        }
        size_t want = cap - 1 - n;
        if (!regular && want > limit + 1 - n)
            want = limit + 1 - n; /* one byte past the bound tells that there is more */
        size_t got = fread(buf + n, 1, want, f);
        n += got;
        if (got == 0)
            break;
    }
    if (ferror(f)) {
        int e = errno;
        free(buf);
        fclose(f);
        return hv__error(HV_ERR_IO, "%s: read error after %zu bytes: %s", path, n, strerror(e));
    }
    fclose(f);
    buf[n] = '\0';
    *out = buf;
    *len = n;
    return HV_OK;
}

/* A regular file read through assimp, which opens it itself (and the files
 * it refers to): refused here, as hv__mesh_read_file would refuse it, when it
 * cannot be opened or is empty. */
static hv_status check_regular_file(const char *path, const struct stat *sb)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return hv__error(HV_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    fclose(f);
    if (sb->st_size == 0)
        return hv__error(HV_ERR_PARSE, "%s: empty file", path);
    return HV_OK;
}

static hv_status read_through_assimp(const char *path, hv_mesh **out)
{
    struct stat sb;
    if (stat(path, &sb) != 0)
        return hv__error(HV_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    if (S_ISREG(sb.st_mode)) {
        hv_status st = check_regular_file(path, &sb);
        return st ? st : hv__mesh_read_assimp(path, NULL, 0, (uint64_t)sb.st_size, out);
    }
    char *buf;
    size_t len;
    hv_status st = hv__mesh_read_file(path, &buf, &len);
    if (st)
        return st;
    st = len ? hv__mesh_read_assimp(path, buf, len, len, out)
             : hv__error(HV_ERR_PARSE, "%s: empty file", path);
    free(buf);
    return st;
}

typedef enum { FMT_UNKNOWN, FMT_OBJ, FMT_PLY, FMT_STL, FMT_OFF } mesh_format;

static mesh_format format_by_extension(const char *path)
{
    const char *slash = strrchr(path, '/');
    const char *dot = strrchr(slash ? slash + 1 : path, '.');
    if (!dot)
        return FMT_UNKNOWN;
    if (!strcasecmp(dot, ".obj"))
        return FMT_OBJ;
    if (!strcasecmp(dot, ".ply"))
        return FMT_PLY;
    if (!strcasecmp(dot, ".stl"))
        return FMT_STL;
    if (!strcasecmp(dot, ".off"))
        return FMT_OFF;
    return FMT_UNKNOWN;
}

const char *hv_mesh_format_by_extension(const char *path)
{
    if (!path)
        return NULL;
    static const char *const names[] = {NULL, "OBJ", "PLY", "STL", "OFF"};
    mesh_format f = format_by_extension(path);
    return f != FMT_UNKNOWN ? names[f] : hv__mesh_assimp_format(path);
}

static int starts_with_word(const char *s, const char *word)
{
    size_t n = strlen(word);
    return strncmp(s, word, n) == 0 && mesh_is_delim(s[n]);
}

static mesh_format format_by_content(const char *buf, size_t len)
{
    if (len >= 84) {
        uint32_t n = (uint32_t)(unsigned char)buf[80] | (uint32_t)(unsigned char)buf[81] << 8 |
                     (uint32_t)(unsigned char)buf[82] << 16 |
                     (uint32_t)(unsigned char)buf[83] << 24;
        if (n > 0 && (uint64_t)len == 84 + 50 * (uint64_t)n)
            return FMT_STL;
    }
    const char *p = buf;
    if (len >= 3 && (unsigned char)p[0] == 0xEF && (unsigned char)p[1] == 0xBB &&
        (unsigned char)p[2] == 0xBF)
        p += 3;
    if (!strncmp(p, "ply", 3) && (p[3] == '\n' || p[3] == '\r'))
        return FMT_PLY;
    /* white space and # comment lines before an OFF keyword or "solid" */
    for (;;) {
        while (mesh_is_space(*p))
            p++;
        if (*p != '#')
            break;
        const char *nl = memchr(p, '\n', (size_t)(buf + len - p));
        if (!nl)
            return FMT_UNKNOWN;
        p = nl + 1;
    }
    static const char *const off_words[] = {"OFF",   "COFF",   "NOFF",   "CNOFF",
                                            "STOFF", "STCOFF", "STNOFF", "STCNOFF"};
    for (size_t i = 0; i < sizeof off_words / sizeof off_words[0]; i++) {
        size_t n = strlen(off_words[i]);
        if (!strncmp(p, off_words[i], n) && (mesh_is_delim(p[n]) || (p[n] >= '0' && p[n] <= '9')))
            return FMT_OFF;
    }
    if (starts_with_word(p, "solid"))
        return FMT_STL;
    /* OBJ: a vertex or face record at the start of a line in the first 64 KiB */
    size_t scan = len < 65536 ? len : 65536;
    for (const char *q = buf; q < buf + scan;) {
        while (q < buf + scan && mesh_is_hspace(*q))
            q++;
        if (starts_with_word(q, "v") || starts_with_word(q, "f"))
            return FMT_OBJ;
        const char *nl = memchr(q, '\n', (size_t)(buf + scan - q));
        if (!nl)
            break;
        q = nl + 1;
    }
    return FMT_UNKNOWN;
}

hv_status hv_mesh_read(const char *path, hv_mesh **out)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_read: out is NULL");
    *out = NULL;
    if (!path || !*path)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_read: empty path");
    if (hv__mesh_assimp_format(path))
        return read_through_assimp(path, out);
    char *buf;
    size_t len;
    hv_status st = hv__mesh_read_file(path, &buf, &len);
    if (st)
        return st;
    if (len == 0) {
        free(buf);
        return hv__error(HV_ERR_PARSE, "%s: empty file", path);
    }
    mesh_format fmt = format_by_extension(path);
    if (fmt == FMT_UNKNOWN)
        fmt = format_by_content(buf, len);
    switch (fmt) {
    case FMT_OBJ: st = hv__mesh_read_obj(path, buf, len, out); break;
    case FMT_PLY: st = hv__mesh_read_ply(path, buf, len, out); break;
    case FMT_STL: st = hv__mesh_read_stl(path, buf, len, out); break;
    case FMT_OFF: st = hv__mesh_read_off(path, buf, len, out); break;
    default:
        if (len >= 2 && (((unsigned char)buf[0] == 0xFE && (unsigned char)buf[1] == 0xFF) ||
                         ((unsigned char)buf[0] == 0xFF && (unsigned char)buf[1] == 0xFE)))
            st = hv__error(HV_ERR_PARSE,
                           "%s: UTF-16 text (byte order mark); save it as UTF-8 or "
                           "ASCII",
                           path);
        else
            st = hv__error(HV_ERR_PARSE,
                           "%s: not a mesh format heatvox reads (OBJ, PLY, STL, OFF by extension "
                           "or content; glTF, GLB, FBX, 3MF, DAE, X by extension)",
                           path);
    }
    free(buf);
    return st;
}
