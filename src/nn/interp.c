/* Bilinear feature-map resampling with PyTorch's index arithmetic (see gen3d/nn_interp.h). */
#include "gen3d/nn_interp.h"

#include <stdlib.h>

/* One axis: left tap, right tap and the right tap's weight, for every output index. */
static void axis_taps(int in, int out, int align_corners, int *i0, int *i1, float *l1)
{
    float scale;
    if (align_corners) scale = out > 1 ? (float)(in - 1) / (float)(out - 1) : 0.0f;
    else scale = (float)in / (float)out;
    for (int d = 0; d < out; d++) {
        float src = align_corners ? scale * (float)d : scale * ((float)d + 0.5f) - 0.5f;
        if (src < 0.0f) src = 0.0f;
        int f = (int)src;
        if (f > in - 1) f = in - 1;
        i0[d] = f;
        i1[d] = f < in - 1 ? f + 1 : f;
        l1[d] = src - (float)f;
    }
}

g3d_status g3d_nn_resize_bilinear(const float *x, int c, int h, int w, int ho, int wo, int align_corners,
                                  float *y)
{
    if (c <= 0 || h <= 0 || w <= 0 || ho <= 0 || wo <= 0)
        return G3D_ERR(G3D_ERR_ARG, "bilinear resize: bad sizes %dx%dx%d -> %dx%d", c, h, w, ho, wo);
    int *iy = malloc(sizeof(int) * 2 * ((size_t)ho + wo));
    float *ly = malloc(sizeof(float) * ((size_t)ho + wo));
    if (!iy || !ly) {
        free(iy);
        free(ly);
        return G3D_ERR(G3D_ERR_NOMEM, "bilinear resize: out of memory");
    }
    int *iy1 = iy + ho, *ix0 = iy1 + ho, *ix1 = ix0 + wo;
    float *lx = ly + ho;
    axis_taps(h, ho, align_corners, iy, iy1, ly);
    axis_taps(w, wo, align_corners, ix0, ix1, lx);
    size_t in_plane = (size_t)h * w, out_plane = (size_t)ho * wo;
#pragma omp parallel for collapse(2) schedule(static)
    for (int ch = 0; ch < c; ch++) {
        for (int oy = 0; oy < ho; oy++) {
            const float *r0 = x + ch * in_plane + (size_t)iy[oy] * w;
            const float *r1 = x + ch * in_plane + (size_t)iy1[oy] * w;
            float b = ly[oy], a = 1.0f - b;
            float *dst = y + ch * out_plane + (size_t)oy * wo;
            for (int ox = 0; ox < wo; ox++) {
                float q = lx[ox], p = 1.0f - q;
                dst[ox] = a * (p * r0[ix0[ox]] + q * r0[ix1[ox]]) + b * (p * r1[ix0[ox]] + q * r1[ix1[ox]]);
            }
        }
    }
    free(iy);
    free(ly);
    return G3D_OK;
}
