/* PNG previews with a diverging colour map (heatvox/image.h), through libpng. */
#include "heatvox/image.h"
#include "heatvox/io.h"
#include "core/error.h"

#include <errno.h>
#include <math.h>
#include <png.h>
#include <setjmp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- colour map ---- */

static double auto_range(const hv_grid *const *gs, int count)
{
    double m = 0;
    for (int s = 0; s < count; s++) {
        size_t n = hv_grid_count(gs[s]);
        for (size_t i = 0; i < n; i++) {
            double a = fabs((double)gs[s]->v[i]);
            if (isfinite(a) && a > m)
                m = a;
        }
    }
    return m > 0 ? m : 1.0;
}

static void shade(double v, double range, uint8_t *px)
{
    if (!isfinite(v)) {
        px[0] = px[1] = px[2] = HV_PNG_GREY;
        return;
    }
    double t = v / range;
    t = t < -1 ? -1 : t > 1 ? 1 : t;
    static const double blue[3] = {HV_PNG_BLUE_R, HV_PNG_BLUE_G, HV_PNG_BLUE_B};
    static const double red[3] = {HV_PNG_RED_R, HV_PNG_RED_G, HV_PNG_RED_B};
    const double *end = t < 0 ? blue : red;
    double a = fabs(t);
    for (int c = 0; c < 3; c++)
        px[c] = (uint8_t)lround(255.0 + (end[c] - 255.0) * a);
}

/* True when cell a lies on the zero contour against its neighbour b. */
static int on_contour(float a, float b)
{
    if (!isfinite(a) || !isfinite(b) || (a < 0) == (b < 0))
        return 0;
    return fabsf(a) <= fabsf(b);
}

/* Writes the map of g into an image of width `stride` pixels, with g's row
 * j = 0 at image row `bottom` and higher j above it. */
static void colormap_into(const hv_grid *g, double range, uint8_t *rgb, int stride, int bottom)
{
    int nx = g->n[0], ny = g->n[1];
    for (int j = 0; j < ny; j++) {
        const float *row = g->v + (size_t)j * nx;
        uint8_t *px = rgb + 3 * ((size_t)(bottom - j) * stride);
        for (int i = 0; i < nx; i++, px += 3) {
            float v = row[i];
            int black =
                (i > 0 && on_contour(v, row[i - 1])) || (i + 1 < nx && on_contour(v, row[i + 1])) ||
                (j > 0 && on_contour(v, row[i - nx])) || (j + 1 < ny && on_contour(v, row[i + nx]));
            if (black)
                px[0] = px[1] = px[2] = 0;
            else
                shade(v, range, px);
        }
    }
}

static hv_status check_2d(const hv_grid *g, const char *what)
{
    if (!g || !g->v)
        return hv__error(HV_ERR_INVALID_ARG, "%s: grid is NULL", what);
    if (g->dim != 2)
        return hv__error(HV_ERR_INVALID_ARG, "%s: a preview image needs a 2D grid (slice it first)",
                         what);
    return HV_OK;
}

hv_status hv_image_colormap(const hv_grid *g, double range, uint8_t *rgb)
{
    hv_status st = check_2d(g, "hv_image_colormap");
    if (st)
        return st;
    if (!rgb)
        return hv__error(HV_ERR_INVALID_ARG, "hv_image_colormap: rgb is NULL");
    if (!(range > 0) || !isfinite(range))
        range = auto_range(&g, 1);
    colormap_into(g, range, rgb, g->n[0], g->n[1] - 1);
    return HV_OK;
}

/* ---- libpng ---- */

struct png_err {
    jmp_buf jmp;
    char msg[256];
};

static void on_png_error(png_structp png, png_const_charp msg)
{
    struct png_err *e = png_get_error_ptr(png);
    snprintf(e->msg, sizeof e->msg, "%s", msg);
    longjmp(e->jmp, 1);
}

static void on_png_warning(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg;
}

static hv_status png_write_file(FILE *f, const uint8_t *rgb, int width, int height,
                                struct png_err *err)
{
    png_structp png =
        png_create_write_struct(PNG_LIBPNG_VER_STRING, err, on_png_error, on_png_warning);
    if (!png) {
        snprintf(err->msg, sizeof err->msg, "libpng could not start");
        return HV_ERR_BACKEND;
    }
    png_infop info = png_create_info_struct(png);
    if (!info || setjmp(err->jmp)) {
        png_destroy_write_struct(&png, &info);
        if (!err->msg[0])
            snprintf(err->msg, sizeof err->msg, "libpng could not start");
        return HV_ERR_IO;
    }
    png_init_io(png, f);
    png_set_IHDR(png, info, (png_uint_32)width, (png_uint_32)height, 8, PNG_COLOR_TYPE_RGB,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    for (int y = 0; y < height; y++)
        png_write_row(png, rgb + 3 * (size_t)y * width);
    png_write_end(png, NULL);
    png_destroy_write_struct(&png, &info);
    return HV_OK;
}

hv_status hv_png_write_rgb(const char *path, const uint8_t *rgb, int width, int height)
{
    if (!path || !rgb)
        return hv__error(HV_ERR_INVALID_ARG, "hv_png_write_rgb: path or pixels NULL");
    if (width < 1 || height < 1 || width > 1000000 || height > 1000000)
        return hv__error(HV_ERR_INVALID_ARG, "%s: PNG size %d x %d is out of range", path, width,
                         height);
    char tmp[4096];
    hv_status st;
    FILE *f = hv__tmp_open(path, tmp, sizeof tmp, &st);
    if (!f)
        return st;
    struct png_err err;
    err.msg[0] = '\0';
    st = png_write_file(f, rgb, width, height, &err);
    int closed = fclose(f);
    if (st == HV_OK && closed != 0) {
        st = HV_ERR_IO;
        snprintf(err.msg, sizeof err.msg, "%s", strerror(errno));
    }
    if (st != HV_OK) {
        hv_tmp_discard(tmp);
        return hv__error(st, "%s: writing PNG: %s", path, err.msg);
    }
    return hv_tmp_commit(tmp, path);
}

hv_status hv_png_write_slices(const char *path, const hv_grid *const *slices, int count,
                              double range)
{
    if (!slices || count < 1)
        return hv__error(HV_ERR_INVALID_ARG, "%s: no slices to draw", path ? path : "PNG");
    int width = 0, height = 0;
    for (int s = 0; s < count; s++) {
        hv_status st = check_2d(slices[s], path ? path : "PNG");
        if (st)
            return st;
        width += slices[s]->n[0] + (s ? HV_PNG_GAP : 0);
        if (slices[s]->n[1] > height)
            height = slices[s]->n[1];
    }
    if (!(range > 0) || !isfinite(range))
        range = auto_range(slices, count);
    uint8_t *rgb = malloc(3 * (size_t)width * height);
    if (!rgb)
        return hv__error(HV_ERR_NOMEM, "%s: no memory for a %d x %d image", path, width, height);
    memset(rgb, 255, 3 * (size_t)width * height);
    int x0 = 0;
    for (int s = 0; s < count; s++) {
        colormap_into(slices[s], range, rgb + 3 * (size_t)x0, width, height - 1);
        x0 += slices[s]->n[0] + HV_PNG_GAP;
    }
    hv_status st = hv_png_write_rgb(path, rgb, width, height);
    free(rgb);
    return st;
}

hv_status hv_png_write(const char *path, const hv_grid *g, double range)
{
    return hv_png_write_slices(path, &g, 1, range);
}

hv_status hv_png_write_preview(const char *path, const hv_grid *g, double range)
{
    if (!g || !g->v || g->dim != 3)
        return hv__error(HV_ERR_INVALID_ARG, "%s: the three-slice preview needs a 3D grid",
                         path ? path : "PNG");
    hv_grid *s[3] = {NULL, NULL, NULL};
    hv_status st = HV_OK;
    for (int a = 0; a < 3 && st == HV_OK; a++)
        st = hv_grid_slice(g, a, g->n[a] / 2, &s[a]);
    if (st == HV_OK)
        st = hv_png_write_slices(path, (const hv_grid *const *)s, 3, range);
    for (int a = 0; a < 3; a++)
        hv_grid_destroy(&s[a]);
    return st;
}

/* ---- reading (tests, tools) ---- */

hv_status hv_png_read_rgb(const char *path, uint8_t **rgb, int *width, int *height)
{
    if (!path || !rgb || !width || !height)
        return hv__error(HV_ERR_INVALID_ARG, "hv_png_read_rgb: NULL argument");
    *rgb = NULL;
    *width = *height = 0;
    FILE *f = fopen(path, "rb");
    if (!f)
        return hv__error(HV_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    struct png_err err;
    err.msg[0] = '\0';
    png_structp png =
        png_create_read_struct(PNG_LIBPNG_VER_STRING, &err, on_png_error, on_png_warning);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    uint8_t *volatile pix = NULL;
    png_bytep *volatile rows = NULL;
    if (!png || !info) {
        png_destroy_read_struct(&png, &info, NULL);
        fclose(f);
        return hv__error(HV_ERR_BACKEND, "%s: libpng could not start", path);
    }
    if (setjmp(err.jmp)) {
        png_destroy_read_struct(&png, &info, NULL);
        fclose(f);
        free(pix);
        free(rows);
        return hv__error(HV_ERR_PARSE, "%s: not a readable PNG: %s", path, err.msg);
    }
    png_init_io(png, f);
    png_read_info(png, info);
    png_set_expand(png);
    png_set_strip_16(png);
    png_set_strip_alpha(png);
    png_set_gray_to_rgb(png);
    png_set_interlace_handling(png);
    png_read_update_info(png, info);
    png_uint_32 w = png_get_image_width(png, info), h = png_get_image_height(png, info);
    if (png_get_rowbytes(png, info) != 3 * (size_t)w)
        png_error(png, "unexpected row size after conversion to RGB");
    pix = malloc(3 * (size_t)w * h);
    rows = malloc(sizeof(png_bytep) * h);
    if (!pix || !rows)
        png_error(png, "out of memory");
    for (png_uint_32 y = 0; y < h; y++)
        rows[y] = pix + 3 * (size_t)y * w;
    png_read_image(png, rows);
    png_read_end(png, NULL);
    png_destroy_read_struct(&png, &info, NULL);
    fclose(f);
    free(rows);
    *rgb = pix;
    *width = (int)w;
    *height = (int)h;
    return HV_OK;
}
