/* gen3d/dinov2.h - DINOv2 ViT backbone (cls token, LayerScale, no registers), as in the
 * official DINOv2 / Depth Anything V2 code, loaded from a checkpoint by tensor name.
 *
 * Tensor names are `prefix` + the official module path, e.g. prefix "pretrained." (Depth
 * Anything V2) or "encoder.backbone." (MoGe-2): cls_token, pos_embed, patch_embed.proj.*,
 * blocks.{i}.{norm1,attn.qkv,attn.proj,ls1.gamma,norm2,mlp.fc1,mlp.fc2,ls2.gamma}, norm.*.
 * Width, depth, MLP width, patch size and the trained position grid come from the tensor
 * shapes, so any configuration of the architecture loads; heads = width / 64 (the head width of
 * every published DINOv2, which the tensors do not record). Only the plain MLP variant is
 * supported: the SwiGLU of ViT-g and register tokens are refused naming the tensor.
 */
#ifndef G3D_DINOV2_H
#define G3D_DINOV2_H

#include "gen3d/ckpt.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_dinov2 g3d_dinov2;   /* opaque, immutable after loading */

/* Optional intermediate outputs of one forward pass, for inspection and tests. Set `want` to
 * non-zero before the call; the forward then allocates and fills every field (the caller
 * frees them with g3d_dinov2_trace_free). Shapes: patch_embed [h*w, D] (before the cls
 * token and positions); block[i] [1 + h*w, D] (output of block i, cls token first). */
typedef struct g3d_dinov2_trace {
    int want;
    int nblocks;
    float *patch_embed;
    float **block;
} g3d_dinov2_trace;

void g3d_dinov2_trace_free(g3d_dinov2_trace *t);

/* Loads every backbone tensor under `prefix` from ck, checking each shape. A missing tensor or
 * wrong shape is G3D_ERR_MODEL naming the tensor. *out is freed with g3d_dinov2_free. */
g3d_status g3d_dinov2_load(const g3d_ckpt *ck, const char *prefix, g3d_dinov2 **out);
void g3d_dinov2_free(g3d_dinov2 *m);

int g3d_dinov2_width(const g3d_dinov2 *m);   /* embedding width D (384 for ViT-S) */
int g3d_dinov2_depth(const g3d_dinov2 *m);   /* number of blocks */
int g3d_dinov2_patch(const g3d_dinov2 *m);   /* patch side in pixels (14 in the published models) */

/* Runs the backbone on a normalised image x [3, H, W] (H, W multiples of the patch size, at
 * most 32768) and returns the outputs of the blocks listed in `layers` (0-based, increasing),
 * each passed through the final LayerNorm with the cls token removed: feats[i] is [h*w, D]
 * with h = H/patch, w = W/patch, allocated here and freed by the caller; when cls is non-NULL,
 * cls[i] receives the normalised cls token [D] of the same block (allocated likewise).
 * The 37x37 (or whatever was trained) position grid is resized bicubically with the
 * official +0.1 offset in the scale factor. trace may be NULL. */
g3d_status g3d_dinov2_forward(const g3d_dinov2 *m, const float *x, int H, int W, const int *layers, int nlayers,
                              float **feats, float **cls, g3d_dinov2_trace *trace);

#ifdef __cplusplus
}
#endif
#endif /* G3D_DINOV2_H */
