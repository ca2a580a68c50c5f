/* gen3d/recognize.h - which model a checkpoint holds, told from its content (tensor names and
 * shapes, its configuration), never from its file name.
 *
 * The one place that knows every supported model's signature: the depth-estimator factory
 * (depth_estimators.h), `gen3d depth` and `gen3d info` all ask here.
 */
#ifndef G3D_RECOGNIZE_H
#define G3D_RECOGNIZE_H

#include "gen3d/ckpt.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum g3d_model_kind {
    G3D_MODEL_UNKNOWN = 0,
    G3D_MODEL_DEPTH_ANYTHING_V2, /* DINOv2 under "pretrained.", a DPT head under "depth_head." */
    G3D_MODEL_MOGE,              /* a 'model_config' dictionary beside the state dict (any MoGe
                                    generation: its loader says what it cannot handle) */
    G3D_MODEL_CLIP_TEXT,         /* a CLIP text tower (clip_text.h), alone or inside a Stable
                                    Diffusion checkpoint (cond_stage_model.*) */
    G3D_MODEL_LAMA,              /* LaMa's FFC generator under "generator.model." (a Lightning
                                    checkpoint) or "model." (the generator alone) */
    G3D_MODEL_SAM,               /* Segment Anything: image_encoder.*, prompt_encoder.*, mask_decoder.* */
    G3D_MODEL_STABLE_DIFFUSION,  /* a latent-diffusion UNet (model.diffusion_model.*, sd.h), with
                                    or without its VAE and text encoder */
    G3D_MODEL_CONTROLNET,        /* a ControlNet for the UNet (control_model.*, or diffusers'
                                    ControlNetModel; sd.h) */
    G3D_MODEL_KIND_COUNT
} g3d_model_kind;

/* The kind of model in an open checkpoint. */
g3d_model_kind g3d_model_recognize(const g3d_ckpt *ck);

/* The same for a file; G3D_MODEL_UNKNOWN when it cannot be opened as a checkpoint (the error
 * is cleared: the loader that runs next reports it). */
g3d_model_kind g3d_model_recognize_file(const char *path);

/* A one-line description of the architecture, e.g. "Depth Anything V2 (vits: ViT-S/14, 12
 * blocks, width 384)" or "MoGe-2 (dinov2_vits14, 12 blocks, width 384; heads: points, normal,
 * mask, metric scale)" or "LaMa (FFC ResNet generator, width 64, 18 residual blocks, 384 of
 * 512 channels global)", written into buf (n bytes) and returned; NULL when the tensors are not
 * those of a supported model. */
const char *g3d_model_describe(const g3d_ckpt *ck, char *buf, size_t n);

#ifdef __cplusplus
}
#endif
#endif /* G3D_RECOGNIZE_H */
