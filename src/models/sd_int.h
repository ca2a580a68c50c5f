/* Pieces the Stable Diffusion UNet and VAE share: tensor look-up under a key prefix with the
 * messages the loaders give, and the residual block both networks are built from. */
#ifndef G3D_SD_INT_H
#define G3D_SD_INT_H

#include "gen3d/ckpt.h"
#include "gen3d/nn.h"

/* Where tensors are looked up. Names are always given as the original (ldm) checkpoints spell
 * them; with `layout` set they are translated to diffusers' names first (its UNet needs the res
 * blocks per level, its VAE the level count: diffusers lists the decoder's levels the other
 * way round). */
typedef enum sd_layout { SD_ORIGINAL, SD_DIFFUSERS_UNET, SD_DIFFUSERS_VAE } sd_layout;
typedef struct sd_ld {
    const g3d_ckpt *ck;
    const char *prefix;
    sd_layout layout;
    int nres, levels;
} sd_ld;

/* The file's key for an original name into key[n] (the prefix included); 0 when the name has
 * no counterpart in the layout. */
int sd_key(const sd_ld *ld, const char *name, char *key, size_t n);

/* The tensor <prefix><formatted name>, or NULL. */
const g3d_tensor_info *sd_find(const sd_ld *ld, const char *fmt, ...);
/* The tensor <prefix><name> with exactly the given shape (a 1x1 convolution's [o, i, 1, 1]
 * also matches [o, i] when ndim is 2 and flat is set); else G3D_ERR_MODEL naming it. */
g3d_status sd_need(const sd_ld *ld, const g3d_tensor_info **t, int ndim, const int64_t *shape, const char *name);
/* <base>.weight and <base>.bias as float32 vectors of n values (malloc'd). */
g3d_status sd_vec(const sd_ld *ld, float **dst, int n, const char *base, const char *leaf);

/* A Conv2d k x k with padding k/2 (stride 1 or 2) from <base>.weight / .bias; the weights stay
 * where the checkpoint holds them. Free with sd_conv_free. */
g3d_status sd_conv_load(const sd_ld *ld, g3d_nn_conv *c, int cin, int cout, int k, int stride, const char *base);
void sd_conv_free(g3d_nn_conv *c);
/* A Linear layer from <base>.weight ([out, in], or a 1x1 convolution's [out, in, 1, 1]) and,
 * when bias is set, <base>.bias; kept in the file's 16-bit type when it has one. */
g3d_status sd_lin_load(const sd_ld *ld, g3d_nn_lin *L, int out, int in, int bias, const char *base);

/* Several Linear layers of the same shape [out, in] stacked into one [parts*out, in] layer (q, k
 * and v read with one product): <base>.<leaves[k]>.weight (and .bias when bias is set). */
g3d_status sd_lin_packed(const sd_ld *ld, g3d_nn_lin *L, int parts, int out, int in, int bias, const char *base,
                         const char *const *leaves);

/* The residual block of both networks: GroupNorm 32 + SiLU, 3x3 conv, (+ a projection of the
 * timestep embedding), GroupNorm 32 + SiLU, 3x3 conv, plus the input (through a 1x1 conv when
 * the channel count changes). */
typedef struct sd_res {
    int cin, cout, has_emb, has_skip;
    float eps;
    float *g1, *b1, *g2, *b2;
    g3d_nn_conv c1, c2, skip;
    g3d_nn_lin emb;
} sd_res;

/* Names as the UNet spells them (in_layers.0, in_layers.2, emb_layers.1, out_layers.0,
 * out_layers.3, skip_connection; emb_dim > 0) or the VAE (norm1, conv1, norm2, conv2,
 * nin_shortcut; emb_dim 0). cout < 0: read it from the first convolution. */
g3d_status sd_res_load(const sd_ld *ld, sd_res *r, int cin, int cout, int emb_dim, float eps, const char *base);
void sd_res_free(sd_res *r);
/* y [cout, h*w] = block(x [cin, h*w]); emb_silu = SiLU(timestep embedding) or NULL. y must not
 * overlap x; tmp holds max(cin, cout) * h * w floats + cout. */
g3d_status sd_res_forward(const sd_res *r, const float *x, int h, int w, const float *emb_silu, float *y, float *tmp);

/* y [n, c] = x [c, n] transposed (add: y += instead). */
void sd_transpose(const float *x, int c, int n, float *y, int add);

#endif
