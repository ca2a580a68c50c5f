/* Separable resampling. Each mode builds, per axis, a table of taps (source index, weight)
 * for every output coordinate; one routine then applies the two tables. */
#include "gen3d/resize.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct axis_taps {
    int ntaps;      /* taps per output coordinate (fixed per axis) */
    int *index;     /* (out, ntaps) source indices, already clamped */
    double *weight; /* (out, ntaps) */
} axis_taps;

static void taps_free(axis_taps *t)
{
    free(t->index);
    free(t->weight);
}

static int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

/* Keys cubic weights, evaluated in float exactly as OpenCV does for its coefficient table. */
static void cubic_weights(float x, float A, double w[4])
{
    float c0 = ((A * (x + 1) - 5 * A) * (x + 1) + 8 * A) * (x + 1) - 4 * A;
    float c1 = ((A + 2) * x - (A + 3)) * x * x + 1;
    float c2 = ((A + 2) * (1 - x) - (A + 3)) * (1 - x) * (1 - x) + 1;
    w[0] = c0;
    w[1] = c1;
    w[2] = c2;
    w[3] = 1.f - c0 - c1 - c2;
}

static g3d_status build_taps(int in, int out, g3d_resize_mode mode, axis_taps *t)
{
    double scale = (double)in / out;
    memset(t, 0, sizeof *t);
    if (mode == G3D_RESIZE_AREA && out > in) mode = G3D_RESIZE_BILINEAR;
    if (mode == G3D_RESIZE_AREA) t->ntaps = (int)ceil(scale) + 2;
    else if (mode == G3D_RESIZE_CUBIC_OPENCV || mode == G3D_RESIZE_CUBIC_HALF) t->ntaps = 4;
    else if (mode == G3D_RESIZE_NEAREST) t->ntaps = 1;
    else if (mode == G3D_RESIZE_BILINEAR_AA) t->ntaps = (int)ceil(2.0 * fmax(scale, 1.0)) + 2;
    else t->ntaps = 2;
    t->index = calloc((size_t)out * t->ntaps, sizeof(int));
    t->weight = calloc((size_t)out * t->ntaps, sizeof(double));
    if (!t->index || !t->weight) { taps_free(t); return G3D_ERR(G3D_ERR_NOMEM, "resize: out of memory"); }

    for (int o = 0; o < out; o++) {
        int *ix = t->index + (size_t)o * t->ntaps;
        double *w = t->weight + (size_t)o * t->ntaps;
        switch (mode) {
        case G3D_RESIZE_BILINEAR:
        case G3D_RESIZE_BILINEAR_AC: {
            double s = mode == G3D_RESIZE_BILINEAR_AC ? (out > 1 ? o * (double)(in - 1) / (out - 1) : 0.0)
                                                      : fmax((o + 0.5) * scale - 0.5, 0.0);
            int i0 = (int)floor(s);
            if (i0 > in - 1) i0 = in - 1;
            double l = s - i0;
            ix[0] = i0;
            ix[1] = i0 + 1 < in ? i0 + 1 : in - 1;
            w[0] = 1.0 - l;
            w[1] = l;
            break;
        }
        case G3D_RESIZE_CUBIC_OPENCV:
        case G3D_RESIZE_CUBIC_HALF: {
            /* OpenCV computes the source position in double and rounds it to float. */
            float f = (float)((o + 0.5) * scale - 0.5);
            int s = (int)floorf(f);
            f -= (float)s;
            cubic_weights(f, mode == G3D_RESIZE_CUBIC_OPENCV ? -0.75f : -0.5f, w);
            for (int k = 0; k < 4; k++) ix[k] = clampi(s - 1 + k, 0, in - 1);
            break;
        }
        case G3D_RESIZE_AREA: {
            /* Output pixel o covers [o*scale, (o+1)*scale) of the input; weights are the
             * covered fraction of each input pixel, normalised by the cell size. */
            double a = o * scale, b = (o + 1) * scale;
            int first = (int)floor(a), k = 0;
            for (int i = first; i < b && k < t->ntaps; i++, k++) {
                double lo = fmax(a, i), hi = fmin(b, i + 1.0);
                ix[k] = clampi(i, 0, in - 1);
                w[k] = (hi - lo) / scale;
            }
            break;
        }
        case G3D_RESIZE_BILINEAR_AA: {
            /* PyTorch evaluates the window in the tensor's precision (float); the first and
             * last taps are truncated towards zero exactly as it does. */
            float sc = (float)in / (float)out, support = sc >= 1.0f ? sc : 1.0f;
            float inv = sc >= 1.0f ? 1.0f / sc : 1.0f, centre = sc * ((float)o + 0.5f);
            int lo = (int)(centre - support + 0.5f), hi = (int)(centre + support + 0.5f);
            lo = lo < 0 ? 0 : lo;
            hi = hi > in ? in : hi;
            double total = 0;
            for (int k = 0; k < t->ntaps; k++) {
                float d = fabsf(((float)(lo + k) - centre + 0.5f) * inv);
                ix[k] = lo + k < hi ? lo + k : lo;
                w[k] = lo + k < hi && d < 1.0f ? 1.0f - d : 0.0;
                total += w[k];
            }
            for (int k = 0; k < t->ntaps && total > 0; k++) w[k] /= total;
            break;
        }
        case G3D_RESIZE_NEAREST:
            ix[0] = clampi((int)floor((o + 0.5) * scale), 0, in - 1);
            w[0] = 1.0;
            break;
        default:
            taps_free(t);
            return G3D_ERR(G3D_ERR_ARG, "resize: unknown mode %d", (int)mode);
        }
    }
    return G3D_OK;
}

g3d_status g3d_resize_buffer(const float *src, int sw, int sh, int c, float *dst, int dw, int dh, g3d_resize_mode mode)
{
    axis_taps tx, ty;
    if (sw < 1 || sh < 1 || dw < 1 || dh < 1 || c < 1 || sw > G3D_MAX_IMAGE_SIDE || sh > G3D_MAX_IMAGE_SIDE ||
        dw > G3D_MAX_IMAGE_SIDE || dh > G3D_MAX_IMAGE_SIDE)
        return G3D_ERR(G3D_ERR_ARG, "resize: bad sizes %dx%d -> %dx%d", sw, sh, dw, dh);
    G3D_TRY(build_taps(sw, dw, mode, &tx));
    if (build_taps(sh, dh, mode, &ty) != G3D_OK) { taps_free(&tx); return G3D_ERR_NOMEM; }
    /* Horizontal pass into a (sh, dw, c) double buffer, then the vertical pass. */
    double *tmp = malloc(sizeof(double) * (size_t)sh * dw * c);
    if (!tmp) { taps_free(&tx); taps_free(&ty); return G3D_ERR(G3D_ERR_NOMEM, "resize: out of memory"); }
#pragma omp parallel for schedule(static)
    for (int y = 0; y < sh; y++) {
        const float *row = src + (size_t)y * sw * c;
        for (int x = 0; x < dw; x++)
            for (int ch = 0; ch < c; ch++) {
                double s = 0;
                for (int k = 0; k < tx.ntaps; k++)
                    s += tx.weight[(size_t)x * tx.ntaps + k] * row[(size_t)tx.index[(size_t)x * tx.ntaps + k] * c + ch];
                tmp[((size_t)y * dw + x) * c + ch] = s;
            }
    }
#pragma omp parallel for schedule(static)
    for (int y = 0; y < dh; y++)
        for (int x = 0; x < dw; x++)
            for (int ch = 0; ch < c; ch++) {
                double s = 0;
                for (int k = 0; k < ty.ntaps; k++)
                    s += ty.weight[(size_t)y * ty.ntaps + k] * tmp[((size_t)ty.index[(size_t)y * ty.ntaps + k] * dw + x) * c + ch];
                dst[((size_t)y * dw + x) * c + ch] = (float)s;
            }
    free(tmp);
    taps_free(&tx);
    taps_free(&ty);
    return G3D_OK;
}

void g3d_fit_size(int w, int h, int max_side, int *ow, int *oh)
{
    double s = (double)max_side / (w > h ? w : h);
    *ow = (int)lround(w * s);
    *oh = (int)lround(h * s);
    if (*ow < 1) *ow = 1;
    if (*oh < 1) *oh = 1;
}

g3d_status g3d_image_resize(const g3d_image *src, int dw, int dh, g3d_resize_mode mode, g3d_image *dst)
{
    G3D_TRY(g3d_image_create(dst, dw, dh, src->c));
    g3d_status rc = g3d_resize_buffer(src->data, src->w, src->h, src->c, dst->data, dw, dh, mode);
    if (rc != G3D_OK) g3d_image_free(dst);
    return rc;
}

/* ---- PIL's 8-bit resampling (Resample.c) ----------------------------------------------- */
#define PIL_PREC 22 /* fractional bits of PIL's fixed-point coefficients (32 - 8 - 2) */

static double pil_bilinear(double x)
{
    x = fabs(x);
    return x < 1.0 ? 1.0 - x : 0.0;
}

static double pil_bicubic(double x)
{
    const double a = -0.5;
    x = fabs(x);
    if (x < 1.0) return ((a + 2.0) * x - (a + 3.0)) * x * x + 1;
    if (x < 2.0) return (((x - 5) * x + 8) * x - 4) * a;
    return 0.0;
}

/* One axis's taps as PIL precomputes them (the filter widened by the shrink factor): per output
 * coordinate the first source index, the tap count and ksize fixed-point weights. */
static g3d_status pil_taps(int in, int out, double (*filter)(double), double filter_support, int **first, int **count,
                           int **k, int *ksize)
{
    double scale = (double)in / out, fs = scale < 1.0 ? 1.0 : scale, support = filter_support * fs;
    *ksize = (int)ceil(support) * 2 + 1;
    *first = malloc(sizeof(int) * (size_t)out);
    *count = malloc(sizeof(int) * (size_t)out);
    *k = malloc(sizeof(int) * (size_t)out * *ksize);
    double *w = malloc(sizeof(double) * (size_t)*ksize);
    if (!*first || !*count || !*k || !w) {
        free(*first); free(*count); free(*k); free(w);
        *first = *count = *k = NULL;
        return G3D_ERR(G3D_ERR_NOMEM, "resize: out of memory");
    }
    for (int o = 0; o < out; o++) {
        double centre = (o + 0.5) * scale, total = 0;
        int lo = (int)(centre - support + 0.5), hi = (int)(centre + support + 0.5);
        lo = lo < 0 ? 0 : lo;
        hi = hi > in ? in : hi;
        for (int x = 0; x < hi - lo; x++) total += w[x] = filter((x + lo - centre + 0.5) / fs);
        for (int x = 0; x < *ksize; x++) {
            double v = x < hi - lo && total != 0.0 ? w[x] / total : 0.0;
            (*k)[(size_t)o * *ksize + x] = (int)(v < 0 ? -0.5 + v * (1 << PIL_PREC) : 0.5 + v * (1 << PIL_PREC));
        }
        (*first)[o] = lo;
        (*count)[o] = hi - lo;
    }
    free(w);
    return G3D_OK;
}

static uint8_t pil_clip8(int v)
{
    if (v >= (1 << PIL_PREC << 8)) return 255;
    return v <= 0 ? 0 : (uint8_t)(v >> PIL_PREC);
}

/* PIL resamples the rows first (only those the column pass reads) through an 8-bit picture, and
 * skips a pass whose size does not change. */
static g3d_status pil_resample_u8(const uint8_t *src, int sw, int sh, int c, uint8_t *dst, int dw, int dh,
                                  double (*filter)(double), double support)
{
    if (sw < 1 || sh < 1 || dw < 1 || dh < 1 || c < 1 || sw > G3D_MAX_IMAGE_SIDE || sh > G3D_MAX_IMAGE_SIDE ||
        dw > G3D_MAX_IMAGE_SIDE || dh > G3D_MAX_IMAGE_SIDE)
        return G3D_ERR(G3D_ERR_ARG, "resize: bad sizes %dx%d -> %dx%d", sw, sh, dw, dh);
    int *fx = NULL, *nx = NULL, *kx = NULL, *fy = NULL, *ny = NULL, *ky = NULL, ksx = 0, ksy = 0;
    g3d_status rc = G3D_OK;
    if (dw != sw) rc = pil_taps(sw, dw, filter, support, &fx, &nx, &kx, &ksx);
    if (rc == G3D_OK && dh != sh) rc = pil_taps(sh, dh, filter, support, &fy, &ny, &ky, &ksy);
    int y0 = fy ? fy[0] : 0, y1 = fy ? fy[dh - 1] + ny[dh - 1] : sh;
    uint8_t *mid = rc == G3D_OK ? malloc((size_t)(y1 - y0) * dw * c) : NULL;
    if (rc == G3D_OK && !mid) rc = G3D_ERR(G3D_ERR_NOMEM, "resize: out of memory");
    if (rc == G3D_OK) {
        if (!fx) memcpy(mid, src + (size_t)y0 * sw * c, (size_t)(y1 - y0) * sw * c);
        else {
#pragma omp parallel for schedule(static)
            for (int y = y0; y < y1; y++)
                for (int x = 0; x < dw; x++)
                    for (int ch = 0; ch < c; ch++) {
                        int s = 1 << (PIL_PREC - 1);
                        for (int t = 0; t < nx[x]; t++)
                            s += src[((size_t)y * sw + fx[x] + t) * c + ch] * kx[(size_t)x * ksx + t];
                        mid[((size_t)(y - y0) * dw + x) * c + ch] = pil_clip8(s);
                    }
        }
        if (!fy) memcpy(dst, mid, (size_t)sh * dw * c);
        else {
#pragma omp parallel for schedule(static)
            for (int y = 0; y < dh; y++)
                for (int x = 0; x < dw * c; x++) {
                    int s = 1 << (PIL_PREC - 1);
                    for (int t = 0; t < ny[y]; t++) s += mid[(size_t)(fy[y] - y0 + t) * dw * c + x] * ky[(size_t)y * ksy + t];
                    dst[(size_t)y * dw * c + x] = pil_clip8(s);
                }
        }
    }
    free(fx); free(nx); free(kx); free(fy); free(ny); free(ky);
    free(mid);
    return rc;
}

g3d_status g3d_resize_u8_pil_bilinear(const uint8_t *src, int sw, int sh, int c, uint8_t *dst, int dw, int dh)
{
    return pil_resample_u8(src, sw, sh, c, dst, dw, dh, pil_bilinear, 1.0);
}

g3d_status g3d_resize_u8_pil_bicubic(const uint8_t *src, int sw, int sh, int c, uint8_t *dst, int dw, int dh)
{
    return pil_resample_u8(src, sw, sh, c, dst, dw, dh, pil_bicubic, 2.0);
}
