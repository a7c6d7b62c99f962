/* OpenEXR files through the OpenEXR Core C API (layout in heatvox/image.h). */
#include "heatvox/image.h"
#include "heatvox/io.h"
#include "core/error.h"

/* The quoted includes inside openexr.h resolve next to it, so no -I is needed. */
#include <OpenEXR/openexr.h>
#include <zlib.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* The Core library reports through a callback whose default prints to stderr;
 * ours keeps the last message for this thread so the error names it. */
static _Thread_local char exr_msg[512];

static void on_exr_error(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    (void)ctxt;
    (void)code;
    snprintf(exr_msg, sizeof exr_msg, "%s", msg ? msg : "");
}

static const char *exr_reason(exr_result_t rv)
{
    return exr_msg[0] ? exr_msg : exr_get_default_error_message(rv);
}

static exr_context_initializer_t exr_init(void)
{
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = on_exr_error;
    /* A damaged offset table must fail, not be patched up from the chunk data. */
    init.flags = EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION;
    exr_msg[0] = '\0';
    return init;
}

static hv_status verify_written(const char *tmp, const char *path, const hv_grid *g,
                                const char *channel);

/* Reading: the most float bytes one file byte can decode to (ZIP's deflate
 * tops out near 1032:1; PIZ's Huffman-coded runs near 4096:1 are the limit
 * taken), and the grid size always allowed. */
#define EXR_MAX_RATIO 4096.0
#define EXR_SMALL_GRID (64.0 * 1024 * 1024)

static void part_name(char *buf, size_t size, int k) { snprintf(buf, size, "slice_%04d", k); }

/* ---- writing ---- */

/* OpenEXR's reader takes a chunk whose stored size equals its raw size as
 * stored raw, whatever the part's compression. OpenEXR 3.1's Core ZIP encoder
 * keeps a deflated chunk whose size happens to equal the raw size (it falls
 * back to raw only when the deflated chunk is larger: upstream #2306), and every
 * reader then decodes that chunk as garbage. This wrapper around whichever
 * compressor the library chose stores such a chunk raw, which every version
 * reads back right. */
typedef struct {
    exr_result_t (*compress)(exr_encode_pipeline_t *enc);
} exr_guard;

static exr_result_t compress_guarded(exr_encode_pipeline_t *enc)
{
    const exr_guard *gd = enc->encoding_user_data;
    exr_result_t rv = gd->compress(enc);
    if (rv != EXR_ERR_SUCCESS || enc->compressed_bytes < enc->packed_bytes)
        return rv;
    if (!enc->compressed_buffer || enc->compressed_alloc_size < enc->packed_bytes)
        return EXR_ERR_OUT_OF_MEMORY;
    memcpy(enc->compressed_buffer, enc->packed_buffer, enc->packed_bytes);
    enc->compressed_bytes = enc->packed_bytes;
    return EXR_ERR_SUCCESS;
}

static hv_status write_part(exr_context_t ctx, int part, const float *slice, int nx, int ny,
                            float *buf, const char *tmp, const char *path)
{
    int lpc = 1;
    exr_result_t rv = exr_get_scanlines_per_chunk(ctx, part, &lpc);
    if (rv != EXR_ERR_SUCCESS || lpc < 1)
        return hv__error(HV_ERR_BACKEND, "%s: OpenEXR: lines per chunk: %s", path, exr_reason(rv));
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    exr_guard guard = {NULL};
    int started = 0;
    hv_status st = HV_OK;
    for (int y = 0; y < ny && st == HV_OK; y += lpc) {
        exr_chunk_info_t ci;
        rv = exr_write_scanline_chunk_info(ctx, part, y, &ci);
        if (rv == EXR_ERR_SUCCESS)
            rv = started ? exr_encoding_update(ctx, part, &ci, &enc)
                         : exr_encoding_initialize(ctx, part, &ci, &enc);
        if (rv != EXR_ERR_SUCCESS) {
            st = hv__error(HV_ERR_IO, "%s: writing part %d, line %d: %s", path, part, y,
                           exr_reason(rv));
            break;
        }
        /* Image row y shows grid row ny-1-y (second axis up). */
        for (int r = 0; r < ci.height; r++)
            memcpy(buf + (size_t)r * nx, slice + (size_t)(ny - 1 - (y + r)) * nx,
                   sizeof(float) * (size_t)nx);
        exr_coding_channel_info_t *c = &enc.channels[0];
        c->encode_from_ptr = (const uint8_t *)buf;
        c->user_pixel_stride = (int32_t)sizeof(float);
        c->user_line_stride = (int32_t)(sizeof(float) * (size_t)nx);
        c->user_data_type = EXR_PIXEL_FLOAT;
        c->user_bytes_per_element = (int16_t)sizeof(float);
        if (!started) {
            rv = exr_encoding_choose_default_routines(ctx, part, &enc);
            started = 1;
            if (rv == EXR_ERR_SUCCESS && enc.compress_fn) {
                guard.compress = enc.compress_fn;
                enc.encoding_user_data = &guard;
                enc.compress_fn = compress_guarded;
            }
        }
        if (rv == EXR_ERR_SUCCESS)
            rv = exr_encoding_run(ctx, part, &enc);
        if (rv != EXR_ERR_SUCCESS)
            st = hv__error(HV_ERR_IO, "%s (writing %s): part %d, line %d: %s", path, tmp, part, y,
                           exr_reason(rv));
    }
    if (started)
        exr_encoding_destroy(ctx, &enc);
    return st;
}

hv_status hv_exr_write(const char *path, const hv_grid *g, const char *channel)
{
    if (!path || !g || !g->v)
        return hv__error(HV_ERR_INVALID_ARG, "hv_exr_write: path or grid is NULL");
    if (!channel)
        channel = "Y";
    size_t clen = strlen(channel);
    if (clen < 1 || clen > 31)
        return hv__error(HV_ERR_INVALID_ARG, "%s: EXR channel name '%s' must be 1 to 31 characters",
                         path, channel);
    int nx = g->n[0], ny = g->n[1], nparts = g->dim == 3 ? g->n[2] : 1;
    char tmp[4096];
    hv_status st = hv_tmp_name(path, tmp, sizeof tmp);
    if (st)
        return st;
    float *buf = malloc(sizeof(float) * (size_t)nx * 64);
    if (!buf) {
        hv_tmp_discard(tmp);
        return hv__error(HV_ERR_NOMEM, "%s: no memory for an EXR line buffer", path);
    }
    exr_context_initializer_t init = exr_init();
    exr_context_t ctx = NULL;
    exr_result_t rv = exr_start_write(&ctx, tmp, EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv != EXR_ERR_SUCCESS) {
        st = hv__error(HV_ERR_IO, "%s: cannot create %s: %s", path, tmp, exr_reason(rv));
        goto done;
    }
    exr_attr_v3d_t org = {{{g->origin[0], g->origin[1], g->origin[2]}}};
    exr_attr_v3i_t dims = {{{g->n[0], g->n[1], g->n[2]}}};
    for (int k = 0; k < nparts; k++) {
        char name[32];
        part_name(name, sizeof name, k);
        int part = -1;
        rv = exr_add_part(ctx, g->dim == 3 ? name : "heatvox", EXR_STORAGE_SCANLINE, &part);
        if (rv == EXR_ERR_SUCCESS)
            rv = exr_initialize_required_attr_simple(ctx, part, nx, ny, EXR_COMPRESSION_ZIP);
        if (rv == EXR_ERR_SUCCESS)
            rv =
                exr_add_channel(ctx, part, channel, EXR_PIXEL_FLOAT, EXR_PERCEPTUALLY_LINEAR, 1, 1);
        if (rv == EXR_ERR_SUCCESS)
            rv = exr_attr_set_double(ctx, part, "heatvox:voxelSize", g->h);
        if (rv == EXR_ERR_SUCCESS)
            rv = exr_attr_set_v3d(ctx, part, "heatvox:origin", &org);
        if (rv == EXR_ERR_SUCCESS)
            rv = exr_attr_set_v3i(ctx, part, "heatvox:dims", &dims);
        if (rv == EXR_ERR_SUCCESS)
            rv = exr_attr_set_int(ctx, part, "heatvox:sliceIndex", k);
        if (rv != EXR_ERR_SUCCESS) {
            st = hv__error(HV_ERR_BACKEND, "%s: OpenEXR header of part %d: %s", path, k,
                           exr_reason(rv));
            goto done;
        }
    }
    rv = exr_write_header(ctx);
    if (rv != EXR_ERR_SUCCESS) {
        st = hv__error(HV_ERR_IO, "%s: writing the EXR header: %s", path, exr_reason(rv));
        goto done;
    }
    for (int k = 0; k < nparts && st == HV_OK; k++) {
        st = hv__progress((double)k / nparts, "exr");
        if (st == HV_OK)
            st = write_part(ctx, k, g->v + (size_t)k * nx * ny, nx, ny, buf, tmp, path);
    }
done:
    free(buf);
    if (ctx) {
        rv = exr_finish(&ctx);
        if (st == HV_OK && rv != EXR_ERR_SUCCESS)
            st = hv__error(HV_ERR_IO, "%s: finishing %s: %s", path, tmp, exr_reason(rv));
    }
    if (st == HV_OK)
        st = verify_written(tmp, path, g, channel);
    if (st != HV_OK) {
        hv_tmp_discard(tmp);
        return st;
    }
    return hv_tmp_commit(tmp, path);
}

/* ---- reading ---- */

/* Files written by OpenEXR 3.1's Core ZIP encoder (heatvox before its guard,
 * and other programs) can hold a deflated chunk flagged as raw: stored size
 * equal to the raw size (see compress_guarded). Raw float data that also forms
 * a whole zlib stream, with its Adler-32, inflating to exactly the chunk's raw
 * size does not happen by chance, so such a chunk is inflated and its ZIP
 * predictor undone here; the rows land in dst. Only parts of one FLOAT channel
 * (heatvox's own layout) are recovered. Returns 1 when the chunk was
 * recovered, 0 when it is to be decoded as usual. */
static int recover_misflagged(exr_context_t ctx, int part, const exr_chunk_info_t *ci, float *dst,
                              int nx, const char *path)
{
    exr_compression_t comp;
    const exr_attr_chlist_t *chl = NULL;
    if (ci->packed_size != ci->unpacked_size || ci->packed_size < 16 ||
        exr_get_compression(ctx, part, &comp) != EXR_ERR_SUCCESS ||
        (comp != EXR_COMPRESSION_ZIP && comp != EXR_COMPRESSION_ZIPS) ||
        exr_get_channels(ctx, part, &chl) != EXR_ERR_SUCCESS || !chl || chl->num_channels != 1 ||
        chl->entries[0].pixel_type != EXR_PIXEL_FLOAT || ci->width != nx ||
        ci->unpacked_size != (uint64_t)ci->width * ci->height * sizeof(float))
        return 0;
    size_t n = (size_t)ci->packed_size;
    unsigned char *z = malloc(n), *t = malloc(n);
    int ok = z && t && exr_read_chunk(ctx, part, ci, z) == EXR_ERR_SUCCESS && (z[0] & 0x0f) == 8;
    uLongf out = (uLongf)n;
    ok = ok && uncompress(t, &out, z, (uLong)n) == Z_OK && out == n;
    if (ok) {
        for (size_t i = 1; i < n; i++)
            t[i] = (unsigned char)(t[i - 1] + t[i] - 128);
        size_t half = (n + 1) / 2;
        for (size_t i = 0; i < n; i++)
            z[i] = t[(i & 1) ? half + i / 2 : i / 2];
        for (size_t k = 0; k < n / 4; k++) {
            uint32_t b = (uint32_t)z[4 * k] | (uint32_t)z[4 * k + 1] << 8 |
                         (uint32_t)z[4 * k + 2] << 16 | (uint32_t)z[4 * k + 3] << 24;
            memcpy(dst + k, &b, sizeof b);
        }
        hv__log(HV_LOG_WARN,
                "%s: part %d, lines %d..%d: a deflated chunk flagged as raw (OpenEXR 3.1's ZIP "
                "encoder) was inflated",
                path, part, ci->start_y, ci->start_y + ci->height - 1);
    }
    free(z);
    free(t);
    return ok;
}

static hv_status read_part(exr_context_t ctx, int part, const exr_attr_box2i_t *dw,
                           const char *channel, float *rows, int nx, const char *path,
                           const char *pname)
{
    int lpc = 1;
    exr_result_t rv = exr_get_scanlines_per_chunk(ctx, part, &lpc);
    if (rv != EXR_ERR_SUCCESS || lpc < 1)
        return hv__error(HV_ERR_PARSE, "%s: part %d (%s): lines per chunk: %s", path, part, pname,
                         exr_reason(rv));
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    int started = 0;
    hv_status st = HV_OK;
    for (int y = dw->min.y; y <= dw->max.y && st == HV_OK; y += lpc) {
        exr_chunk_info_t ci;
        rv = exr_read_scanline_chunk_info(ctx, part, y, &ci);
        if (rv == EXR_ERR_SUCCESS &&
            recover_misflagged(ctx, part, &ci, rows + (size_t)(ci.start_y - dw->min.y) * nx, nx,
                               path))
            continue;
        if (rv == EXR_ERR_SUCCESS)
            rv = started ? exr_decoding_update(ctx, part, &ci, &dec)
                         : exr_decoding_initialize(ctx, part, &ci, &dec);
        if (rv != EXR_ERR_SUCCESS) {
            st = hv__error(HV_ERR_PARSE, "%s: part %d (%s), line %d: %s", path, part, pname, y,
                           exr_reason(rv));
            break;
        }
        int found = 0;
        for (int c = 0; c < dec.channel_count; c++) {
            exr_coding_channel_info_t *ch = &dec.channels[c];
            if (!found && !strcmp(ch->channel_name, channel)) {
                found = 1;
                ch->decode_to_ptr = (uint8_t *)(rows + (size_t)(ci.start_y - dw->min.y) * nx);
                ch->user_pixel_stride = (int32_t)sizeof(float);
                ch->user_line_stride = (int32_t)(sizeof(float) * (size_t)nx);
                ch->user_data_type = EXR_PIXEL_FLOAT;
                ch->user_bytes_per_element = (int16_t)sizeof(float);
            } else {
                ch->decode_to_ptr = NULL;
            }
        }
        if (!found) {
            st = hv__error(HV_ERR_PARSE, "%s: part %d (%s): channel '%s' missing from a chunk",
                           path, part, pname, channel);
            break;
        }
        if (!started) {
            rv = exr_decoding_choose_default_routines(ctx, part, &dec);
            started = 1;
        }
        if (rv == EXR_ERR_SUCCESS)
            rv = exr_decoding_run(ctx, part, &dec);
        if (rv != EXR_ERR_SUCCESS)
            st = hv__error(HV_ERR_PARSE, "%s: part %d (%s), lines %d..%d: %s", path, part, pname,
                           ci.start_y, ci.start_y + ci.height - 1, exr_reason(rv));
    }
    if (started)
        exr_decoding_destroy(ctx, &dec);
    return st;
}

/* Picks the channel to read from part 0 and checks it has full resolution. */
static hv_status choose_channel(exr_context_t ctx, const char *want, const char *path, char *out,
                                size_t outsize)
{
    const exr_attr_chlist_t *chl = NULL;
    exr_result_t rv = exr_get_channels(ctx, 0, &chl);
    if (rv != EXR_ERR_SUCCESS || !chl || chl->num_channels < 1)
        return hv__error(HV_ERR_PARSE, "%s: no channels: %s", path,
                         rv != EXR_ERR_SUCCESS ? exr_reason(rv) : "empty channel list");
    const exr_attr_chlist_entry_t *pick = NULL;
    const char *name = want ? want : chl->num_channels == 1 ? chl->entries[0].name.str : "Y";
    for (int c = 0; c < chl->num_channels; c++)
        if (!strcmp(chl->entries[c].name.str, name))
            pick = &chl->entries[c];
    if (!pick) {
        char list[256] = "";
        for (int c = 0; c < chl->num_channels; c++) {
            size_t l = strlen(list);
            snprintf(list + l, sizeof list - l, "%s%s", c ? ", " : "", chl->entries[c].name.str);
        }
        return hv__error(HV_ERR_PARSE, "%s: no channel '%s' (channels: %s)%s", path, name, list,
                         want ? "" : "; name one");
    }
    if (pick->x_sampling != 1 || pick->y_sampling != 1)
        return hv__error(HV_ERR_UNSUPPORTED, "%s: channel '%s' is subsampled (%d x %d)", path, name,
                         pick->x_sampling, pick->y_sampling);
    snprintf(out, outsize, "%s", name);
    return HV_OK;
}

hv_status hv_exr_read(const char *path, const char *channel, hv_grid **out)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_exr_read: out is NULL");
    *out = NULL;
    if (!path)
        return hv__error(HV_ERR_INVALID_ARG, "hv_exr_read: path is NULL");
    struct stat sb;
    if (stat(path, &sb) != 0)
        return hv__error(HV_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    if (!S_ISREG(sb.st_mode))
        return hv__error(HV_ERR_IO, "%s: not a regular file", path);
    exr_context_initializer_t init = exr_init();
    exr_context_t ctx = NULL;
    exr_result_t rv = exr_start_read(&ctx, path, &init);
    if (rv != EXR_ERR_SUCCESS) {
        hv_status st =
            hv__error(HV_ERR_PARSE, "%s: not a readable EXR file: %s", path, exr_reason(rv));
        if (ctx)
            exr_finish(&ctx);
        return st;
    }
    hv_grid *g = NULL;
    float *rows = NULL;
    hv_status st = HV_OK;
    int nparts = 0;
    exr_attr_box2i_t dw0;
    char chan[64];
    rv = exr_get_count(ctx, &nparts);
    if (rv != EXR_ERR_SUCCESS || nparts < 1) {
        st = hv__error(HV_ERR_PARSE, "%s: no image parts", path);
        goto done;
    }
    for (int p = 0; p < nparts; p++) {
        exr_storage_t storage;
        exr_attr_box2i_t dw;
        rv = exr_get_storage(ctx, p, &storage);
        if (rv == EXR_ERR_SUCCESS)
            rv = exr_get_data_window(ctx, p, &dw);
        if (rv != EXR_ERR_SUCCESS) {
            st = hv__error(HV_ERR_PARSE, "%s: part %d: %s", path, p, exr_reason(rv));
            goto done;
        }
        if (storage != EXR_STORAGE_SCANLINE) {
            st = hv__error(HV_ERR_UNSUPPORTED, "%s: part %d is %s; only scanline images are read",
                           path, p, storage == EXR_STORAGE_TILED ? "tiled" : "deep");
            goto done;
        }
        if (p == 0)
            dw0 = dw;
        else if (memcmp(&dw, &dw0, sizeof dw) != 0) {
            st = hv__error(HV_ERR_PARSE,
                           "%s: part %d has data window (%d,%d)-(%d,%d), part 0 (%d,%d)-(%d,%d); "
                           "parts of one volume must match",
                           path, p, dw.min.x, dw.min.y, dw.max.x, dw.max.y, dw0.min.x, dw0.min.y,
                           dw0.max.x, dw0.max.y);
            goto done;
        }
    }
    if ((st = choose_channel(ctx, channel, path, chan, sizeof chan)) != HV_OK)
        goto done;
    const char *name0 = NULL;
    exr_get_name(ctx, 0, &name0);
    int dim = nparts > 1 || (name0 && !strcmp(name0, "slice_0000")) ? 3 : 2;
    int n[3] = {dw0.max.x - dw0.min.x + 1, dw0.max.y - dw0.min.y + 1, nparts};
    double h = 1.0;
    exr_attr_v3d_t org = {{{0, 0, 0}}};
    if (exr_attr_get_double(ctx, 0, "heatvox:voxelSize", &h) != EXR_ERR_SUCCESS || !(h > 0) ||
        !isfinite(h))
        h = 1.0;
    if (exr_attr_get_v3d(ctx, 0, "heatvox:origin", &org) != EXR_ERR_SUCCESS ||
        !isfinite(org.x + org.y + org.z))
        org.x = org.y = org.z = 0;
    exr_msg[0] = '\0';
    double origin[3] = {org.x, org.y, org.z};
    /* The header's data window sets the allocation, so a few hundred bytes
     * could ask for gigabytes before a chunk is read: no lossless EXR codec
     * packs floats tighter than EXR_MAX_RATIO to one, so a larger grid than
     * that from this file is a damaged header. */
    double want = 4.0 * n[0] * (double)n[1] * nparts;
    if (n[0] < 1 || n[1] < 1 || want > EXR_MAX_RATIO * (double)sb.st_size + EXR_SMALL_GRID) {
        st = hv__error(HV_ERR_PARSE,
                       "%s: data window %d x %d in %d part(s) needs %.3g bytes, more than a file "
                       "of %lld bytes can hold",
                       path, n[0], n[1], nparts, want, (long long)sb.st_size);
        goto done;
    }
    if ((st = hv_grid_create(&g, dim, n, h, origin)) != HV_OK)
        goto done;
    size_t plane = (size_t)n[0] * n[1];
    rows = malloc(sizeof(float) * plane);
    if (!rows) {
        st = hv__error(HV_ERR_NOMEM, "%s: no memory for a %d x %d image", path, n[0], n[1]);
        goto done;
    }
    for (int p = 0; p < nparts && st == HV_OK; p++) {
        const char *pname = NULL;
        if (exr_get_name(ctx, p, &pname) != EXR_ERR_SUCCESS || !pname)
            pname = "unnamed";
        const exr_attr_chlist_t *chl = NULL;
        int has = 0;
        if (exr_get_channels(ctx, p, &chl) == EXR_ERR_SUCCESS && chl)
            for (int c = 0; c < chl->num_channels; c++)
                has |= !strcmp(chl->entries[c].name.str, chan) && chl->entries[c].x_sampling == 1 &&
                       chl->entries[c].y_sampling == 1;
        if (!has) {
            st = hv__error(HV_ERR_PARSE, "%s: part %d (%s) has no full-resolution channel '%s'",
                           path, p, pname, chan);
            break;
        }
        st = read_part(ctx, p, &dw0, chan, rows, n[0], path, pname);
        if (st == HV_OK) {
            float *dst = g->v + plane * (size_t)p;
            for (int y = 0; y < n[1]; y++)
                memcpy(dst + (size_t)(n[1] - 1 - y) * n[0], rows + (size_t)y * n[0],
                       sizeof(float) * (size_t)n[0]);
        }
    }
done:
    free(rows);
    exr_finish(&ctx);
    if (st != HV_OK) {
        hv_grid_destroy(&g);
        return st;
    }
    *out = g;
    return HV_OK;
}

/* A library can write garbage without reporting an error (see compress_guarded):
 * every file is decoded in full before it takes its name, and anything but the
 * exact values given is an error. */
static hv_status verify_written(const char *tmp, const char *path, const hv_grid *g,
                                const char *channel)
{
    hv_grid *back = NULL;
    if (hv_exr_read(tmp, channel, &back) != HV_OK) {
        char why[512];
        snprintf(why, sizeof why, "%s", hv_last_error());
        return hv__error(HV_ERR_IO, "%s: the EXR file just written does not decode (%s); not kept",
                         path, why);
    }
    hv_status st = HV_OK;
    size_t n = hv_grid_count(g);
    if (back->dim != g->dim || back->n[0] != g->n[0] || back->n[1] != g->n[1] ||
        (g->dim == 3 && back->n[2] != g->n[2]) || hv_grid_count(back) != n) {
        st = hv__error(HV_ERR_IO,
                       "%s: the EXR file just written decodes to another shape; not kept", path);
    } else if (memcmp(back->v, g->v, sizeof(float) * n) != 0) {
        size_t i = 0, bad = 0;
        for (size_t k = 0; k < n; k++)
            if (memcmp(&back->v[k], &g->v[k], sizeof(float)) != 0) {
                if (!bad)
                    i = k;
                bad++;
            }
        st = hv__error(HV_ERR_IO,
                       "%s: the EXR file just written decodes to other values in %zu of %zu voxels "
                       "(first at index %zu: %g instead of %g); not kept",
                       path, bad, n, i, (double)back->v[i], (double)g->v[i]);
    }
    hv_grid_destroy(&back);
    return st;
}
