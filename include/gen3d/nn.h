/* gen3d/nn.h - CPU neural-network operators on flat float32 buffers.
 *
 * Layouts follow PyTorch so checkpoint tensors are used as stored:
 *   token matrices  [N, C] row-major (one row per token),
 *   feature maps    [C, H, W] (batch 1, channels first),
 *   Linear weights  [out, in], Conv2d weights [C_out, C_in, kH, kW],
 *   ConvTranspose2d weights [C_in, C_out, kH, kW].
 * The caller owns every buffer; outputs never alias inputs unless a function says so.
 * Matrix products go through OpenBLAS (cblas_sgemm); element-wise loops use OpenMP with
 * static schedules, so results are deterministic for a fixed thread count.
 */
#ifndef G3D_NN_H
#define G3D_NN_H

#include "gen3d/base.h"

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* y[n, out] = x[n, in] * w[out, in]^T + b[out] (b may be NULL). */
void g3d_nn_linear(const float *x, int n, int in, const float *w, const float *b, int out, float *y);

/* Output size of a convolution along one axis: (size + 2*pad - k) / stride + 1. */
int g3d_nn_conv_out(int size, int k, int stride, int pad);

/* 2-D convolution, zero padding, no dilation, no groups.
 * x [cin, h, w], w [cout, cin, k, k], b [cout] or NULL -> y [cout, ho, wo] with
 * ho = g3d_nn_conv_out(h, k, stride, pad), likewise wo.
 * Works through bands of output rows with a scratch of at most ~8 MB (at least one row),
 * allocated inside; G3D_ERR_NOMEM on failure.
 * 1x1 stride-1 unpadded convolutions skip the scratch buffer. */
g3d_status g3d_nn_conv2d(const float *x, int cin, int h, int w, const float *wt, const float *b, int cout, int k,
                         int stride, int pad, float *y);

/* Transposed convolution whose kernel equals its stride (no overlap, no padding), as the DPT
 * reassemble layers use: x [cin, h, w], w [cin, cout, k, k], b [cout] or NULL ->
 * y [cout, h*k, w*k]. G3D_ERR_NOMEM if the cout*k*k*h*w scratch cannot be allocated. */
g3d_status g3d_nn_conv_transpose2d(const float *x, int cin, int h, int w, const float *wt, const float *b,
                                   int cout, int k, float *y);

/* Row-wise LayerNorm of x [n, c] into y (may equal x): (x - mean) / sqrt(var + eps) * g + b. */
void g3d_nn_layernorm(const float *x, int n, int c, const float *g, const float *b, float eps, float *y);

/* In place: exact GELU x * 0.5 * (1 + erf(x / sqrt 2)). */
void g3d_nn_gelu(float *x, size_t n);

/* In place: max(x, 0). */
void g3d_nn_relu(float *x, size_t n);

/* y[i] += x[i]. */
void g3d_nn_add(float *y, const float *x, size_t n);

/* Multi-head self-attention core. qkv [n, 3*heads*hd] holds for each token q, k, v one after
 * the other, each split into heads of hd channels (PyTorch's reshape(n, 3, heads, hd)).
 * out [n, heads*hd] = concat over heads of softmax(q k^T * scale) v.
 * Needs an n*n scratch per head evaluation, allocated inside; G3D_ERR_NOMEM on failure. */
g3d_status g3d_nn_attention(const float *qkv, int n, int heads, int hd, float scale, float *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_NN_H */
