/* The pre-norm transformer block CLIP's text and image towers share (OpenAI / OpenCLIP and
 * Hugging Face names), used by clip_text.c and clip.c only. */
#ifndef G3D_CLIP_INT_H
#define G3D_CLIP_INT_H

#include "gen3d/ckpt.h"
#include "gen3d/image.h"
#include "gen3d/nn.h"

typedef struct g3d_clip_block {
    float *ln1w, *ln1b, *ln2w, *ln2b;
    g3d_nn_lin qkv, out, fc1, fc2;
} g3d_clip_block;

typedef struct g3d_clip_block_shape {
    int width, heads;
    g3d_act act;
    float eps;
    int causal; /* 1: the text tower's causal mask */
} g3d_clip_block_shape;

/* Work buffers for n tokens: T, A [n, width], QKV [n, 3 width], H [n, mlp]. */
typedef struct g3d_clip_scratch {
    float *T, *A, *QKV, *H;
} g3d_clip_scratch;

/* The tensor <prefix><printf name>, or NULL. */
const g3d_tensor_info *g3d_clip_findf(const g3d_ckpt *ck, const char *prefix, const char *fmt, ...);
/* Reads <prefix><printf name> of shape [d0] (d1 = 0) or [d0, d1] as float32 (malloc'd). */
g3d_status g3d_clip_readf(const g3d_ckpt *ck, const char *prefix, float **dst, int64_t d0, int64_t d1, const char *fmt, ...);

/* A Linear layer [out, in] from `parts` weights stacked along out (1, or 3 for separate q, k,
 * v) named prefix + w[p] / prefix + b[p]; 16-bit weights stay 16-bit in the packed panels. */
g3d_status g3d_clip_lin(const g3d_ckpt *ck, const char *prefix, g3d_nn_lin *L, int out, int in, int parts,
                        const char *const *w, const char *const *b);
/* An RGB or grey image with values in [0, 1] to 8 bits, resized to rw x rh with PIL's bicubic,
 * its centre size x size crop (torchvision's offsets) normalised with CLIP's mean and std
 * into out[3, size, size]. */
g3d_status g3d_clip_pixels(const g3d_image *img, int rw, int rh, int size, float *out);

/* Loads the block whose tensors start with `base` (e.g. "visual.transformer.resblocks.3." or
 * "vision_model.encoder.layers.3."); hf picks Hugging Face's names (separate q, k, v). */
g3d_status g3d_clip_block_load(const g3d_ckpt *ck, int hf, const char *base, int D, int M, g3d_clip_block *b);
void g3d_clip_block_free(g3d_clip_block *b);
/* X [n, width] in place: X += attn(ln1 X); X += mlp(ln2 X). */
g3d_status g3d_clip_block_forward(const g3d_clip_block *b, const g3d_clip_block_shape *s, float *X, int n,
                                  g3d_clip_scratch *w);
g3d_status g3d_clip_scratch_alloc(g3d_clip_scratch *w, int n, int D, int M);
void g3d_clip_scratch_free(g3d_clip_scratch *w);

#endif
