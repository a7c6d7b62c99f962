/* NumPy .npy files (format 1.0 to write; 1.0, 2.0 and 3.0 to read), as
 * specified in numpy/lib/format.py: magic "\x93NUMPY", version, header length
 * (2 bytes in 1.0, 4 in 2.0/3.0, little-endian), a Python dict literal padded
 * with spaces and ended by '\n' so that the data starts at a multiple of 64. */
#include "heatvox/io.h"
#include "core/error.h"

#include <ctype.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define NPY_MAGIC "\x93NUMPY"
#define NPY_MAGIC_LEN 6
#define NPY_MAX_HEADER (1u << 20)

static int host_is_little_endian(void)
{
    const uint16_t one = 1;
    uint8_t b;
    memcpy(&b, &one, 1);
    return b == 1;
}

static void swap4(void *p)
{
    uint8_t *b = p, t;
    t = b[0], b[0] = b[3], b[3] = t;
    t = b[1], b[1] = b[2], b[2] = t;
}

static void swap8(void *p)
{
    uint8_t *b = p, t;
    for (int i = 0; i < 4; i++)
        t = b[i], b[i] = b[7 - i], b[7 - i] = t;
}

hv_status hv_write_npy(const char *path, const hv_grid *g)
{
    if (!path || !*path)
        return hv__error(HV_ERR_INVALID_ARG, "hv_write_npy: output path is empty");
    if (!g || !g->v)
        return hv__error(HV_ERR_INVALID_ARG, "%s: hv_write_npy: grid is NULL", path);
    if (g->dim != 2 && g->dim != 3)
        return hv__error(HV_ERR_INVALID_ARG, "%s: grid dimension must be 2 or 3", path);

    char dict[256];
    if (g->dim == 3)
        snprintf(dict, sizeof dict,
                 "{'descr': '<f4', 'fortran_order': False, 'shape': (%d, %d, %d), }", g->n[2],
                 g->n[1], g->n[0]);
    else
        snprintf(dict, sizeof dict, "{'descr': '<f4', 'fortran_order': False, 'shape': (%d, %d), }",
                 g->n[1], g->n[0]);
    /* magic(6) + version(2) + length(2) + dict + padding + '\n' = multiple of 64 */
    size_t dlen = strlen(dict);
    size_t total = (NPY_MAGIC_LEN + 4 + dlen + 1 + 63) / 64 * 64;
    size_t hlen = total - NPY_MAGIC_LEN - 4;
    uint8_t head[320];
    memcpy(head, NPY_MAGIC, NPY_MAGIC_LEN);
    head[6] = 1;
    head[7] = 0;
    head[8] = (uint8_t)(hlen & 0xff);
    head[9] = (uint8_t)(hlen >> 8);
    memcpy(head + 10, dict, dlen);
    memset(head + 10 + dlen, ' ', hlen - dlen - 1);
    head[total - 1] = '\n';

    char tmp[4096];
    hv_status st;
    FILE *f = hv__tmp_open(path, tmp, sizeof tmp, &st);
    if (!f)
        return st;
    int ok = fwrite(head, 1, total, f) == total;
    size_t count = hv_grid_count(g);
    if (host_is_little_endian()) {
        ok = ok && fwrite(g->v, sizeof(float), count, f) == count;
    } else {
        float buf[1024];
        for (size_t i = 0; ok && i < count; i += 1024) {
            size_t m = count - i < 1024 ? count - i : 1024;
            memcpy(buf, g->v + i, m * sizeof(float));
            for (size_t j = 0; j < m; j++)
                swap4(&buf[j]);
            ok = fwrite(buf, sizeof(float), m, f) == m;
        }
    }
    int e = errno;
    if (fclose(f) != 0 && ok) {
        ok = 0;
        e = errno;
    }
    if (!ok) {
        hv_tmp_discard(tmp);
        return hv__error(HV_ERR_IO, "%s: writing failed: %s", path, strerror(e));
    }
    return hv_tmp_commit(tmp, path);
}

/* Finds the value following 'key': in the header dict; NULL if absent. */
static const char *dict_value(const char *hdr, const char *key)
{
    char pat[64];
    const char *quotes = "'\"";
    for (int q = 0; q < 2; q++) {
        snprintf(pat, sizeof pat, "%c%s%c", quotes[q], key, quotes[q]);
        const char *p = strstr(hdr, pat);
        if (!p)
            continue;
        p += strlen(pat);
        while (isspace((unsigned char)*p))
            p++;
        if (*p != ':')
            return NULL;
        p++;
        while (isspace((unsigned char)*p))
            p++;
        return p;
    }
    return NULL;
}

/* Opens path for reading when it is a regular file: the data's size is
 * checked against the file's, and only a regular file has one (a pipe or a
 * device such as /dev/zero is refused before opening). */
static hv_status open_regular(const char *path, FILE **fp)
{
    struct stat sb;
    if (stat(path, &sb) != 0)
        return hv__error(HV_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    if (!S_ISREG(sb.st_mode))
        return hv__error(HV_ERR_IO, "%s: is %s; .npy arrays are read from regular files", path,
                         S_ISDIR(sb.st_mode)    ? "a directory"
                         : S_ISCHR(sb.st_mode)  ? "a character device"
                         : S_ISFIFO(sb.st_mode) ? "a pipe"
                                                : "not a regular file");
    FILE *f = fopen(path, "rb");
    if (!f)
        return hv__error(HV_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    if (fstat(fileno(f), &sb) != 0 || !S_ISREG(sb.st_mode)) {
        fclose(f);
        return hv__error(HV_ERR_IO, "%s: not a regular file", path);
    }
    *fp = f;
    return HV_OK;
}

/* The magic, the version and the header dict, read into *hdr (malloc'ed,
 * NUL-terminated: the caller frees it, also on failure); *data_off, where
 * the data starts. */
static hv_status read_header(FILE *f, const char *path, char **hdr, size_t *data_off)
{
    uint8_t pre[12];
    if (fread(pre, 1, 10, f) != 10 || memcmp(pre, NPY_MAGIC, NPY_MAGIC_LEN) != 0)
        return hv__error(HV_ERR_PARSE, "%s: not a NumPy .npy file (no \\x93NUMPY magic at byte 0)",
                         path);
    int major = pre[6], minor = pre[7];
    size_t hlen;
    if (major == 1) {
        hlen = (size_t)pre[8] | (size_t)pre[9] << 8;
        *data_off = 10 + hlen;
    } else if (major == 2 || major == 3) {
        if (fread(pre + 10, 1, 2, f) != 2)
            return hv__error(HV_ERR_PARSE, "%s: truncated .npy header (byte 10)", path);
        hlen = (size_t)pre[8] | (size_t)pre[9] << 8 | (size_t)pre[10] << 16 | (size_t)pre[11] << 24;
        *data_off = 12 + hlen;
    } else {
        return hv__error(HV_ERR_UNSUPPORTED, "%s: .npy format version %d.%d is not supported", path,
                         major, minor);
    }
    if (hlen == 0 || hlen > NPY_MAX_HEADER)
        return hv__error(HV_ERR_PARSE, "%s: .npy header length %zu is out of range", path, hlen);
    char *h = *hdr = malloc(hlen + 1);
    if (!h)
        return hv__error(HV_ERR_NOMEM, "%s: no memory for the .npy header", path);
    if (fread(h, 1, hlen, f) != hlen)
        return hv__error(HV_ERR_PARSE,
                         "%s: truncated .npy header (expected %zu bytes after byte %zu)", path,
                         hlen, *data_off - hlen);
    h[hlen] = '\0';
    if (memchr(h, '\0', hlen))
        return hv__error(HV_ERR_PARSE, "%s: .npy header contains a NUL byte", path);
    return HV_OK;
}

/* 'descr': little-endian float32 or float64 only. */
static hv_status parse_descr(const char *path, const char *descr, size_t *itemsize)
{
    if (!strncmp(descr, "'<f4'", 5) || !strncmp(descr, "\"<f4\"", 5)) {
        *itemsize = 4;
        return HV_OK;
    }
    if (!strncmp(descr, "'<f8'", 5) || !strncmp(descr, "\"<f8\"", 5)) {
        *itemsize = 8;
        return HV_OK;
    }
    int len = 0;
    while (descr[len] && descr[len] != ',' && descr[len] != '}' && len < 40)
        len++;
    return hv__error(HV_ERR_UNSUPPORTED,
                     "%s: .npy dtype %.*s is not supported (need little-endian float32 '<f4' or "
                     "float64 '<f8')",
                     path, len, descr);
}

static hv_status parse_fortran_order(const char *path, const char *fortran)
{
    if (!strncmp(fortran, "True", 4))
        return hv__error(HV_ERR_UNSUPPORTED,
                         "%s: .npy array is in Fortran order; save it in C order "
                         "(numpy.ascontiguousarray)",
                         path);
    if (strncmp(fortran, "False", 5))
        return hv__error(HV_ERR_PARSE, "%s: .npy header: bad fortran_order value", path);
    return HV_OK;
}

/* 'shape': a tuple of up to 4 entries (a fourth only to refuse it). */
static hv_status parse_shape(const char *path, const char *shape, long dims[4], int *ndims)
{
    if (*shape != '(')
        return hv__error(HV_ERR_PARSE, "%s: .npy header: shape is not a tuple", path);
    int nd = 0;
    const char *p = shape + 1;
    for (;;) {
        while (isspace((unsigned char)*p))
            p++;
        if (*p == ')')
            break;
        if (!isdigit((unsigned char)*p))
            return hv__error(HV_ERR_PARSE, "%s: .npy header: bad shape near \"%.20s\"", path, p);
        char *end;
        errno = 0;
        long v = strtol(p, &end, 10);
        if (errno || v > 0x7fffffffL)
            return hv__error(HV_ERR_INVALID_ARG, "%s: .npy shape entry is too large", path);
        if (nd == 4)
            return hv__error(HV_ERR_UNSUPPORTED, "%s: .npy array has more than 3 dimensions", path);
        dims[nd++] = v;
        p = end;
        while (isspace((unsigned char)*p))
            p++;
        if (*p == ',')
            p++;
        else if (*p != ')')
            return hv__error(HV_ERR_PARSE, "%s: .npy header: bad shape near \"%.20s\"", path, p);
    }
    *ndims = nd;
    return HV_OK;
}

/* The header dict: item size and grid dimensions (x fastest). */
static hv_status parse_dict(const char *path, const char *hdr, size_t *itemsize, int *nd, int n[3])
{
    const char *descr = dict_value(hdr, "descr");
    const char *fortran = dict_value(hdr, "fortran_order");
    const char *shape = dict_value(hdr, "shape");
    if (!descr || !fortran || !shape)
        return hv__error(HV_ERR_PARSE, "%s: .npy header lacks '%s': %s", path,
                         !descr     ? "descr"
                         : !fortran ? "fortran_order"
                                    : "shape",
                         hdr);
    long dims[4];
    hv_status st;
    if ((st = parse_descr(path, descr, itemsize)) || (st = parse_fortran_order(path, fortran)) ||
        (st = parse_shape(path, shape, dims, nd)))
        return st;
    if (*nd != 2 && *nd != 3)
        return hv__error(HV_ERR_UNSUPPORTED,
                         "%s: .npy array has %d dimension%s; heatvox grids need 2 (ny, nx) or 3 "
                         "(nz, ny, nx)",
                         path, *nd, *nd == 1 ? "" : "s");
    n[0] = (int)dims[*nd - 1];
    n[1] = (int)dims[*nd - 2];
    n[2] = *nd == 3 ? (int)dims[0] : 1;
    st = hv_check_dims(*nd, n, 1.0, *itemsize);
    if (st) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", hv_last_error());
        return hv__error(st, "%s: %s", path, msg);
    }
    return HV_OK;
}

/* The file holds exactly need bytes from data_off on; leaves f there. */
static hv_status check_data_size(FILE *f, const char *path, size_t data_off, size_t need)
{
    if (fseek(f, 0, SEEK_END) != 0)
        return hv__error(HV_ERR_IO, "%s: cannot seek: %s", path, strerror(errno));
    long fsize = ftell(f);
    if (fsize < 0 || fseek(f, (long)data_off, SEEK_SET) != 0)
        return hv__error(HV_ERR_IO, "%s: cannot seek: %s", path, strerror(errno));
    if ((size_t)fsize < data_off + need)
        return hv__error(HV_ERR_PARSE,
                         "%s: truncated .npy data: shape needs %zu bytes from byte %zu, the file "
                         "has %zu",
                         path, need, data_off,
                         (size_t)fsize > data_off ? (size_t)fsize - data_off : 0);
    if ((size_t)fsize > data_off + need)
        return hv__error(HV_ERR_PARSE,
                         "%s: .npy file has %zu bytes after the data that the shape describes "
                         "(data from byte %zu, %zu bytes)",
                         path, (size_t)fsize - data_off - need, data_off, need);
    return HV_OK;
}

/* The count values into g->v, float64 narrowed to float32. */
static hv_status read_data(FILE *f, const char *path, size_t itemsize, size_t count, hv_grid *g)
{
    int little = host_is_little_endian();
    if (itemsize == 4) {
        if (fread(g->v, 4, count, f) != count)
            return hv__error(HV_ERR_IO, "%s: read error in the data", path);
        if (!little)
            for (size_t i = 0; i < count; i++)
                swap4(&g->v[i]);
        return HV_OK;
    }
    enum { CHUNK = 4096 };
    double *dbuf = malloc(CHUNK * sizeof(double));
    if (!dbuf)
        return hv__error(HV_ERR_NOMEM, "%s: no memory for a read buffer", path);
    for (size_t i = 0; i < count; i += CHUNK) {
        size_t m = count - i < CHUNK ? count - i : CHUNK;
        if (fread(dbuf, 8, m, f) != m) {
            free(dbuf);
            return hv__error(HV_ERR_IO, "%s: read error in the data", path);
        }
        for (size_t j = 0; j < m; j++) {
            if (!little)
                swap8(&dbuf[j]);
            g->v[i + j] = (float)dbuf[j];
        }
    }
    free(dbuf);
    return HV_OK;
}

hv_status hv_read_npy(const char *path, hv_grid **out)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_read_npy: out is NULL");
    *out = NULL;
    if (!path || !*path)
        return hv__error(HV_ERR_INVALID_ARG, "hv_read_npy: input path is empty");
    FILE *f = NULL;
    hv_status st = open_regular(path, &f);
    if (st)
        return st;
    char *hdr = NULL;
    hv_grid *g = NULL;
    size_t data_off = 0, itemsize = 0;
    int nd = 0, n[3] = {0, 0, 0};
    if ((st = read_header(f, path, &hdr, &data_off)) ||
        (st = parse_dict(path, hdr, &itemsize, &nd, n)))
        goto done;
    size_t count = (size_t)n[0] * (size_t)n[1] * (size_t)n[2];
    if ((st = check_data_size(f, path, data_off, count * itemsize)) ||
        (st = hv_grid_create(&g, nd, n, 1.0, NULL)) ||
        (st = read_data(f, path, itemsize, count, g)))
        goto done;
    *out = g;
    g = NULL;
done:
    free(hdr);
    hv_grid_destroy(&g);
    fclose(f);
    return st;
}
