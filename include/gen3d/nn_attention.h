/* gen3d/nn_attention.h - multi-head scaled dot-product attention (included by gen3d/nn.h).
 *
 *   out_h = softmax(scale * q_h k_h^T + bias_h + mask) v_h      for every head h
 *
 * Self- and cross-attention alike: q, k and v are separate pointers with their own row
 * strides, so a packed qkv projection ([n, 3*D], q/k/v at column offsets 0, D, 2D) and three
 * separate projections work the same way. Head h occupies columns h*hd .. h*hd+hd-1 of q and k
 * and h*hdv .. of v and out (PyTorch's view(n, heads, hd)).
 *
 * The scores are never stored whole: queries go in blocks of 64, keys in blocks, and the
 * softmax is carried along the keys online (running maximum and sum), so scratch memory is a
 * few tiles per thread whatever the token count. Threads take (head, query block) pairs (every
 * head of a few blocks at once for key sets of at most 240); each walks the keys in a fixed
 * order, so the result does not depend on the thread count.
 */
#ifndef G3D_NN_ATTENTION_H
#define G3D_NN_ATTENTION_H

#include "gen3d/base.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Additive score bias, supplied by the model a tile at a time: add bias(batch, head, q0+i, k0+j)
 * to s[i*qs + j*ks] for 0 <= i < nq, 0 <= j < nk (the scores are already multiplied by scale;
 * batch is the problem's index in a batched call, else 0). Called concurrently from several
 * threads: it may only read ctx. */
typedef void (*g3d_nn_bias_fn)(void *ctx, int batch, int head, int q0, int nq, int k0, int nk, float *s, long qs,
                               long ks);

typedef struct g3d_nn_attn {
    int nq, nk;           /* query and key/value token counts */
    int heads, hd, hdv;   /* head count, q/k channels per head, v channels per head (0 = hd) */
    const float *q, *k, *v;
    long ldq, ldk, ldv;   /* row strides in floats (0 = heads*hd, heads*hd, heads*hdv) */
    float *out;           /* [nq, heads*hdv] at row stride ldo (0 = heads*hdv); no overlap with q/k/v */
    long ldo;
    float scale;          /* usually hd^-0.5 */
    int causal;           /* query i sees keys j <= i + nk - nq (CLIP text, a decoder with a cache) */
    g3d_nn_bias_fn bias;  /* NULL: none */
    void *bias_ctx;
    /* a batch of independent problems of the same shape in one call (windowed attention: one
     * problem per window): problem b reads q + b*bsq, k + b*bsk, v + b*bsv and writes out + b*bso */
    int batch;            /* 0 = 1 */
    long bsq, bsk, bsv, bso;
} g3d_nn_attn;

/* Runs the attention described by a. G3D_ERR_ARG for inconsistent sizes, G3D_ERR_NOMEM if
 * the per-thread tiles cannot be allocated. A query row that sees no key gets zeros. */
g3d_status g3d_nn_attend(const g3d_nn_attn *a);

/* Self-attention over a packed projection: qkv [n, 3*heads*hd] holds q, k, v of each token one
 * after the other (PyTorch's reshape(n, 3, heads, hd)); out [n, heads*hd]. */
g3d_status g3d_nn_attention(const float *qkv, int n, int heads, int hd, float scale, float *out);

/* ---- ready-made biases ------------------------------------------------------------------ */

/* A stored bias matrix per head, the same for every problem of a batch: bias(b, h, i, j) =
 * b[h*head_stride + i*ld + j] (head_stride 0 shares one matrix between heads). TinyViT's
 * attention_biases gathered through its index table fit here (heads x N x N for a window of N
 * tokens). */
typedef struct g3d_nn_bias_dense {
    const float *b;
    long head_stride, ld;
} g3d_nn_bias_dense;
void g3d_nn_bias_dense_fn(void *ctx, int batch, int head, int q0, int nq, int k0, int nk, float *s, long qs, long ks);

/* SAM's decomposed relative positions: queries and keys on grids qh x qw and kh x kw (token
 * index y*width + x); with t = batch*heads + head, bias(t, q, k) = rh[(t*kh + ky)*nq + q] +
 * rw[(t*kw + kx)*nq + q] and (ky, kx) the key's grid position (tables key-major: the attention
 * adds them a key at a time across 64 queries). Fill them with g3d_nn_relpos_tables, once per
 * problem of a batch (at rh + b*heads*kh*nq, rw + b*heads*kw*nq). g3d_nn_attend recognises
 * this function as a.bias and adds the terms inside its score kernel instead of calling it. */
typedef struct g3d_nn_bias_relpos {
    const float *rh, *rw;
    int nq, kh, kw, heads;
} g3d_nn_bias_relpos;
void g3d_nn_bias_relpos_fn(void *ctx, int batch, int head, int q0, int nq, int k0, int nk, float *s, long qs, long ks);

/* SAM's add_decomposed_rel_pos tables from the unscaled queries q (head h at column h*hd, row
 * stride ldq) on a square-cell grid qh x qw attending to kh x kw (equal sizes, as in SAM's
 * image encoder): rh [heads, kh, qh*qw], rw [heads, kw, qh*qw], with rel_h [2*kh-1, hd] and
 * rel_w [2*kw-1, hd] the checkpoint's rel_pos_h / rel_pos_w. G3D_ERR_UNSUPPORTED when the
 * sizes differ (the official code would interpolate the tables). */
g3d_status g3d_nn_relpos_tables(const float *q, long ldq, int heads, int hd, int qh, int qw, int kh, int kw,
                                const float *rel_h, const float *rel_w, float *rh, float *rw);

#ifdef __cplusplus
}
#endif
#endif /* G3D_NN_ATTENTION_H */
