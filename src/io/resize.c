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

g3d_status g3d_image_resize(const g3d_image *src, int dw, int dh, g3d_resize_mode mode, g3d_image *dst)
{
    G3D_TRY(g3d_image_create(dst, dw, dh, src->c));
    g3d_status rc = g3d_resize_buffer(src->data, src->w, src->h, src->c, dst->data, dw, dh, mode);
    if (rc != G3D_OK) g3d_image_free(dst);
    return rc;
}

/* PIL's resampling coefficients for one axis (Resample.c precompute_coeffs with the bilinear
 * filter), turned into its 22-bit fixed-point integers. */
#define PIL_BITS 22
static g3d_status pil_taps(int in, int out, int *ksize_out, int **bounds_out, int **kk_out)
{
    double scale = (double)in / out, fscale = scale < 1.0 ? 1.0 : scale, support = fscale;
    int ksize = (int)ceil(support) * 2 + 1;
    int *bounds = malloc(sizeof(int) * 2 * (size_t)out), *kk = malloc(sizeof(int) * (size_t)ksize * out);
    double *k = malloc(sizeof(double) * (size_t)ksize);
    if (!bounds || !kk || !k) {
        free(bounds); free(kk); free(k);
        return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    for (int o = 0; o < out; o++) {
        double center = (o + 0.5) * scale, ww = 0.0, ss = 1.0 / fscale;
        int xmin = (int)(center - support + 0.5), xmax = (int)(center + support + 0.5);
        if (xmin < 0) xmin = 0;
        if (xmax > in) xmax = in;
        xmax -= xmin;
        for (int x = 0; x < xmax; x++) {
            double t = fabs((x + xmin - center + 0.5) * ss);
            k[x] = t < 1.0 ? 1.0 - t : 0.0;
            ww += k[x];
        }
        for (int x = 0; x < ksize; x++) {
            double v = x < xmax && ww != 0.0 ? k[x] / ww : 0.0;
            kk[(size_t)o * ksize + x] = v < 0 ? (int)(-0.5 + v * (1 << PIL_BITS)) : (int)(0.5 + v * (1 << PIL_BITS));
        }
        bounds[2 * o] = xmin;
        bounds[2 * o + 1] = xmax;
    }
    free(k);
    *ksize_out = ksize;
    *bounds_out = bounds;
    *kk_out = kk;
    return G3D_OK;
}

static uint8_t pil_clip8(int v)
{
    v >>= PIL_BITS;
    return (uint8_t)(v < 0 ? 0 : v > 255 ? 255 : v);
}

g3d_status g3d_resize_u8_pil_bilinear(const uint8_t *src, int sw, int sh, int c, uint8_t *dst, int dw, int dh)
{
    if (sw < 1 || sh < 1 || dw < 1 || dh < 1 || c < 1 || sw > G3D_MAX_IMAGE_SIDE || sh > G3D_MAX_IMAGE_SIDE ||
        dw > G3D_MAX_IMAGE_SIDE || dh > G3D_MAX_IMAGE_SIDE)
        return G3D_ERR(G3D_ERR_ARG, "cannot resize %dx%d to %dx%d", sw, sh, dw, dh);
    int kx, ky, *bx = NULL, *wx = NULL, *by = NULL, *wy = NULL;
    g3d_status rc = pil_taps(sw, dw, &kx, &bx, &wx);
    if (rc == G3D_OK) rc = pil_taps(sh, dh, &ky, &by, &wy);
    /* PIL resizes the rows first (only those the column pass reads), through a uint8 picture. */
    int y0 = by ? by[0] : 0, y1 = by ? by[2 * dh - 2] + by[2 * dh - 1] : 0;
    uint8_t *tmp = rc == G3D_OK ? malloc((size_t)dw * (y1 - y0) * c) : NULL;
    if (rc == G3D_OK && !tmp) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) {
#pragma omp parallel for schedule(static)
        for (int y = y0; y < y1; y++)
            for (int o = 0; o < dw; o++)
                for (int ch = 0; ch < c; ch++) {
                    int acc = 1 << (PIL_BITS - 1);
                    const int *k = wx + (size_t)o * kx;
                    for (int x = 0; x < bx[2 * o + 1]; x++) acc += src[((size_t)y * sw + bx[2 * o] + x) * c + ch] * k[x];
                    tmp[((size_t)(y - y0) * dw + o) * c + ch] = pil_clip8(acc);
                }
#pragma omp parallel for schedule(static)
        for (int o = 0; o < dh; o++)
            for (int x = 0; x < dw * c; x++) {
                int acc = 1 << (PIL_BITS - 1);
                const int *k = wy + (size_t)o * ky;
                for (int y = 0; y < by[2 * o + 1]; y++) acc += tmp[(size_t)(by[2 * o] - y0 + y) * dw * c + x] * k[y];
                dst[(size_t)o * dw * c + x] = pil_clip8(acc);
            }
    }
    free(tmp); free(bx); free(wx); free(by); free(wy);
    return rc;
}
