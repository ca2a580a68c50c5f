/* Bilinear resizing of feature maps [c, h, w] (PyTorch's F.interpolate(mode="bilinear"),
 * without antialiasing), the resampler of the DPT head and of MoGe's ConvStacks.
 *
 * The whole map is one parallel loop over (channel, band of output rows). Per band, each
 * source row that an output row needs is interpolated along x once into a line buffer (an
 * upsampling by two reuses every such row for two output rows), and an output row is a
 * vectorised blend of two line buffers. Every output value is the same two blends whatever
 * the band or thread it falls in. Per-plane calls of the general image resizer (double
 * precision, one parallel loop per plane and pass) had cost the DPT head's resizes as much
 * time as its 1x1 convolutions. */
#include "nn/nn_int.h"

#include <math.h>
#include <stdlib.h>

#define BAND 16 /* output rows per task */

/* Per output coordinate: the two source indices and the weight of the second. */
static void axis_taps(int in, int out, int align_corners, int *i0, int *i1, float *l)
{
    const double scale = (double)in / out;
    for (int o = 0; o < out; o++) {
        double s = align_corners ? (out > 1 ? o * (double)(in - 1) / (out - 1) : 0.0) : fmax((o + 0.5) * scale - 0.5, 0.0);
        int a = (int)s;
        if (a > in - 1) a = in - 1;
        i0[o] = a;
        i1[o] = a + 1 < in ? a + 1 : in - 1;
        l[o] = (float)(s - a);
    }
}

/* Cloned per instruction set (as the activations are): the blends vectorise, the horizontal
 * pass with gathers. */
#define CLONES __attribute__((target_clones("avx512f", "avx2", "default")))

CLONES static void hrow(const float *restrict s, int ow, const int *x0, const int *x1, const float *lx, float *restrict d)
{
    for (int x = 0; x < ow; x++) d[x] = (1.0f - lx[x]) * s[x0[x]] + lx[x] * s[x1[x]];
}

CLONES static void blend(const float *restrict p, const float *restrict q, float a, float b, int n, float *restrict d)
{
    for (int i = 0; i < n; i++) d[i] = a * p[i] + b * q[i];
}

g3d_status g3d_nn_resize_bilinear(const float *x, int c, int h, int w, float *y, int oh, int ow, int align_corners)
{
    if (c < 0 || h <= 0 || w <= 0 || oh <= 0 || ow <= 0)
        return G3D_ERR(G3D_ERR_ARG, "bilinear resize: bad sizes (%d channels, %dx%d -> %dx%d)", c, w, h, ow, oh);
    int *ix = malloc(sizeof(int) * 2 * ((size_t)ow + oh));
    float *lw = malloc(sizeof(float) * ((size_t)ow + oh));
    if (!ix || !lw) {
        free(ix), free(lw);
        return G3D_ERR(G3D_ERR_NOMEM, "bilinear resize: out of memory");
    }
    int *x0 = ix, *x1 = ix + ow, *y0 = ix + 2 * ow, *y1 = y0 + oh;
    float *lx = lw, *ly = lw + ow;
    axis_taps(w, ow, align_corners, x0, x1, lx);
    axis_taps(h, oh, align_corners, y0, y1, ly);
    const int nband = (oh + BAND - 1) / BAND;
    const long ntask = (long)c * nband;
    int failed = 0;
#pragma omp parallel if ((size_t)c * oh * ow > (1 << 15))
    {
        float *buf = malloc(sizeof(float) * 2 * (size_t)ow);
        if (!buf) {
#pragma omp atomic write
            failed = 1;
        }
#pragma omp for schedule(static)
        for (long t = 0; t < ntask; t++) {
            if (!buf) continue;
            const int ch = (int)(t / nband), r0 = (int)(t % nband) * BAND, r1 = r0 + BAND < oh ? r0 + BAND : oh;
            const float *src = x + (size_t)ch * h * w;
            float *slot[2] = {buf, buf + ow};
            int tag[2] = {-1, -1}; /* source row held in each line buffer */
            for (int oy = r0; oy < r1; oy++) {
                const float *row[2];
                const int need[2] = {y0[oy], y1[oy]};
                for (int k = 0; k < 2; k++) {
                    int s = tag[0] == need[k] ? 0 : tag[1] == need[k] ? 1 : -1;
                    if (s < 0) {
                        /* refill the buffer the other needed row does not occupy */
                        s = k ? (row[0] == slot[0] ? 1 : 0) : (tag[0] == need[1] ? 1 : 0);
                        hrow(src + (size_t)need[k] * w, ow, x0, x1, lx, slot[s]);
                        tag[s] = need[k];
                    }
                    row[k] = slot[s];
                }
                blend(row[0], row[1], 1.0f - ly[oy], ly[oy], ow, y + ((size_t)ch * oh + oy) * ow);
            }
        }
        free(buf);
    }
    free(ix), free(lw);
    if (failed) return G3D_ERR(G3D_ERR_NOMEM, "bilinear resize: out of memory");
    return G3D_OK;
}

/* ---- reference ------------------------------------------------------------------------------ */
static void ref_coord(int o, int in, int out, int align_corners, int *a, int *b, double *l)
{
    double s = align_corners ? (out > 1 ? o * (double)(in - 1) / (out - 1) : 0.0) : fmax((o + 0.5) * in / out - 0.5, 0.0);
    *a = (int)floor(s);
    if (*a > in - 1) *a = in - 1;
    *b = *a + 1 < in ? *a + 1 : in - 1;
    *l = s - *a;
}

void nn_ref_resize_bilinear(const float *x, int c, int h, int w, float *y, int oh, int ow, int align_corners)
{
    for (int ch = 0; ch < c; ch++)
        for (int oy = 0; oy < oh; oy++)
            for (int ox = 0; ox < ow; ox++) {
                int ya, yb, xa, xb;
                double ly, lx;
                ref_coord(oy, h, oh, align_corners, &ya, &yb, &ly);
                ref_coord(ox, w, ow, align_corners, &xa, &xb, &lx);
                const float *s = x + (size_t)ch * h * w;
                double top = (1 - lx) * s[ya * w + xa] + lx * s[ya * w + xb];
                double bot = (1 - lx) * s[yb * w + xa] + lx * s[yb * w + xb];
                y[((size_t)ch * oh + oy) * ow + ox] = (float)((1 - ly) * top + ly * bot);
            }
}
