/* Moving pixels without arithmetic: padding and nearest-neighbour upsampling. */
#include "nn/nn_int.h"

#include <string.h>

/* Source index of padded coordinate i for a side of n pixels. */
static int src_index(g3d_nn_padmode m, int i, int n)
{
    if (i >= 0 && i < n) return i;
    switch (m) {
    case G3D_PAD_REFLECT: return i < 0 ? -i : 2 * (n - 1) - i;
    case G3D_PAD_SYMMETRIC: return i < 0 ? -i - 1 : 2 * n - 1 - i;
    case G3D_PAD_REPLICATE: return i < 0 ? 0 : n - 1;
    default: return -1;
    }
}

g3d_status g3d_nn_pad2d(const float *x, int c, int h, int w, int top, int bottom, int left, int right,
                        g3d_nn_padmode mode, float *y)
{
    if (top < 0 || bottom < 0 || left < 0 || right < 0 || c < 0 || h <= 0 || w <= 0)
        return G3D_ERR(G3D_ERR_ARG, "pad2d: bad sizes (%d channels, %dx%d, pads %d %d %d %d)", c, w, h, top, bottom,
                       left, right);
    int lim = mode == G3D_PAD_REFLECT ? 1 : 0;
    if ((mode == G3D_PAD_REFLECT || mode == G3D_PAD_SYMMETRIC) &&
        (top > h - lim || bottom > h - lim || left > w - lim || right > w - lim))
        return G3D_ERR(G3D_ERR_ARG, "pad2d: %s padding (%d %d %d %d) too large for %dx%d",
                       mode == G3D_PAD_REFLECT ? "reflect" : "symmetric", top, bottom, left, right, w, h);
    const int ho = h + top + bottom, wo = w + left + right;
#pragma omp parallel for schedule(static) if ((size_t)c * ho * wo > (1 << 16))
    for (int ch = 0; ch < c; ch++)
        for (int oy = 0; oy < ho; oy++) {
            float *d = y + ((size_t)ch * ho + oy) * wo;
            int iy = src_index(mode, oy - top, h);
            if (iy < 0) {
                memset(d, 0, sizeof(float) * wo);
                continue;
            }
            const float *s = x + ((size_t)ch * h + iy) * w;
            for (int ox = 0; ox < left; ox++) {
                int ix = src_index(mode, ox - left, w);
                d[ox] = ix < 0 ? 0.0f : s[ix];
            }
            memcpy(d + left, s, sizeof(float) * w);
            for (int ox = left + w; ox < wo; ox++) {
                int ix = src_index(mode, ox - left, w);
                d[ox] = ix < 0 ? 0.0f : s[ix];
            }
        }
    return G3D_OK;
}

void g3d_nn_upsample2x(const float *x, int c, int h, int w, float *y)
{
#pragma omp parallel for schedule(static) if ((size_t)c * h * w > (1 << 14))
    for (int ch = 0; ch < c; ch++)
        for (int iy = 0; iy < h; iy++) {
            const float *s = x + ((size_t)ch * h + iy) * w;
            float *d = y + ((size_t)ch * 2 * h + 2 * iy) * 2 * w;
            for (int ix = 0; ix < w; ix++) d[2 * ix] = d[2 * ix + 1] = s[ix];
            memcpy(d + 2 * w, d, sizeof(float) * 2 * w);
        }
}
