/* gen3d/sam.h - Segment Anything (SAM): the ViT image encoder, the prompt encoder and the
 * two-way mask decoder, loaded from the official release files (sam_vit_b_01ec64.pth,
 * sam_vit_l_0b3195.pth, sam_vit_h_4b8939.pth: plain state dicts with the prefixes
 * image_encoder., prompt_encoder., mask_decoder.), with the official predictor's pre- and
 * post-processing and its automatic mask generator.
 *
 * The architecture comes from the tensors: encoder width, depth, head width (rel_pos_h's
 * columns), input size (the position grid times the patch), window size and which blocks
 * attend globally (a windowed block's rel_pos has 2 * window - 1 rows, a global one 2 * grid - 1),
 * prompt width, mask-input channels, decoder depth and MLP width, the IoU head's depth, the number
 * of masks. Not in the tensors: the decoder's 8 heads, LayerNorm epsilons, pixel mean and std
 * (constants of every released model).
 *
 * Preprocessing is SamPredictor.set_image's: the picture (8-bit RGB) resized with PIL's bilinear
 * filter so that its longer side is the input size (ResizeLongestSide's rounding), normalised by
 * the pixel mean and std, zero-padded at the bottom and right to a square. Masks come back at
 * the picture's size: the decoder's low-resolution logits resized bilinearly to the input
 * square, cropped to the resized picture and resized to the original (align_corners=False),
 * positive logits inside.
 */
#ifndef G3D_SAM_H
#define G3D_SAM_H

#include "gen3d/ckpt.h"
#include "gen3d/providers.h"

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_sam g3d_sam; /* opaque, read-only once loaded: any number of calls at a time */

/* Loads SAM from an open checkpoint (which may be freed afterwards). Errors: G3D_ERR_MODEL
 * ("not a Segment Anything checkpoint" when the image encoder's patch embedding is absent; else
 * naming the first missing or misshapen tensor), G3D_ERR_NOMEM. Free with g3d_sam_free. */
g3d_status g3d_sam_load(const g3d_ckpt *ck, g3d_sam **out);
/* The same from a file path. */
g3d_status g3d_sam_load_file(const char *path, g3d_sam **out);
void g3d_sam_free(g3d_sam *m);
/* One line describing the configuration into buf; returns buf. */
const char *g3d_sam_describe(const g3d_sam *m, char *buf, size_t n);
/* Side of the square the encoder takes (1024 for the released models). */
int g3d_sam_input_size(const g3d_sam *m);

/* Activations of one run, for tests: set `want` before the call; every pointer is a malloc'd copy
 * (NULL where the run had no such stage) freed by g3d_sam_trace_free. Layouts as the official
 * tensors with the batch dimension dropped. */
typedef struct g3d_sam_trace {
    int want;
    float *input;       /* [3, S, S] normalised and padded */
    float *patch_embed; /* [g, g, D] */
    float **block;      /* nblocks x [g, g, D] */
    int nblocks;
    float *neck;        /* [C, g, g] the image embedding */
    float *sparse;      /* [nsparse, C] */
    int nsparse;
    float *dense;       /* [C, g, g] */
    float *tokens;      /* [ntokens, C] the two-way transformer's queries */
    int ntokens;
    float *keys;        /* [g*g, C] */
} g3d_sam_trace;
void g3d_sam_trace_free(g3d_sam_trace *t);

/* A picture's embedding (SamPredictor.set_image). */
typedef struct g3d_sam_image {
    int w, h;           /* the picture */
    int in_w, in_h;     /* after ResizeLongestSide */
    int c, grid;        /* embedding [c, grid, grid] */
    float *embed;       /* owned */
} g3d_sam_image;
/* Encodes rgb (h, w, 3) 8-bit RGB, row-major. trace may be NULL. Errors: G3D_ERR_ARG for an empty
 * picture or one with a side over G3D_MAX_IMAGE_SIDE, G3D_ERR_NOMEM. Free with g3d_sam_image_free. */
g3d_status g3d_sam_set_image(const g3d_sam *m, const uint8_t *rgb, int w, int h, g3d_sam_image *out,
                             g3d_sam_trace *trace);
void g3d_sam_image_free(g3d_sam_image *img);
/* Packs a float picture (h, w, 3) in [0, 1] into 8-bit RGB (rounded); NULL if out of memory. */
uint8_t *g3d_sam_rgb8(const g3d_image *rgb);

/* One prompt, in the picture's pixel coordinates (SamPredictor.predict). */
typedef struct g3d_sam_prompt {
    int n_points;
    const float *points;     /* [n_points, 2] (x, y), or NULL */
    const int *labels;       /* [n_points]: 1 foreground, 0 background, -1 ignored */
    const float *box;        /* [4] x0, y0, x1, y1, or NULL */
    const float *mask_input; /* [4 grid, 4 grid] low-resolution logits of an earlier prediction, or NULL */
} g3d_sam_prompt;

typedef struct g3d_sam_prediction {
    int n;              /* masks: 3 with multimask output (of the released models), else 1 */
    int w, h;           /* the picture */
    float *logits;      /* [n, h, w] mask logits at the picture's size (> 0: inside) */
    float iou[8];       /* predicted IoU of each mask */
    int low;            /* side of the low-resolution logits (4 grid) */
    float *low_res;     /* [n, low, low] */
} g3d_sam_prediction;
/* Predicts the masks of one prompt (at least a point or a box; NULL arrays where absent).
 * multimask: the official multimask_output. trace may be NULL. Errors: G3D_ERR_ARG for an empty
 * prompt, G3D_ERR_NOMEM. Free with g3d_sam_prediction_free. */
g3d_status g3d_sam_predict(const g3d_sam *m, const g3d_sam_image *img, const g3d_sam_prompt *p, int multimask,
                           g3d_sam_prediction *out, g3d_sam_trace *trace);
void g3d_sam_prediction_free(g3d_sam_prediction *p);

/* ---- automatic mask generation (SamAutomaticMaskGenerator, one crop layer) ----------------
 * Grid points are decoded in parallel (one per thread); the result does not depend on the
 * thread count. */
typedef struct g3d_sam_amg_params {
    int points_per_side;          /* 32: a points_per_side^2 grid of foreground points */
    float pred_iou_thresh;        /* 0.88: keep masks with predicted IoU above it (0: no test) */
    float stability_score_thresh; /* 0.95: keep masks with stability at least this (0: no test) */
    float stability_score_offset; /* 1.0: logit offset of the stability score */
    float box_nms_thresh;         /* 0.7: box IoU above which the lower-scored mask goes */
    int min_mask_region_area;     /* 0 (off); > 0 fills holes and removes islands (8-connected)
                                     smaller than this many pixels, then NMS again (at the larger of
                                     box_nms_thresh and 0.7, the official crop_nms_thresh) preferring
                                     unchanged masks */
} g3d_sam_amg_params;
/* Fills the official defaults above. */
void g3d_sam_amg_params_default(g3d_sam_amg_params *p);

typedef struct g3d_sam_masks {
    int n, w, h;
    uint8_t *masks;     /* [n, h, w] 0/1 */
    float *iou;         /* [n] predicted IoU */
    float *stability;   /* [n] */
    int *boxes;         /* [n, 4] x, y, w, h of the mask's bounding box (w = x1 - x0 as SAM's) */
    int *area;          /* [n] pixels */
    float *points;      /* [n, 2] the grid point that made it */
} g3d_sam_masks;
void g3d_sam_masks_free(g3d_sam_masks *s);

/* A prediction's masks (logits > 0) in the generator's form, in the prediction's order, with
 * their stability scores (at stability_offset), boxes and areas; (px, py) is recorded as every
 * mask's point. Free with g3d_sam_masks_free. */
g3d_status g3d_sam_prediction_masks(const g3d_sam_prediction *pr, float stability_offset, float px, float py,
                                    g3d_sam_masks *out);

/* The masks of img (already encoded), ordered by decreasing predicted IoU (the official order).
 * NULL params: the defaults. progress (may be NULL) hears of each grid point, stage "masks". Errors: G3D_ERR_ARG for parameters out of range, G3D_ERR_NOMEM,
 * G3D_CANCELLED. Free with g3d_sam_masks_free. */
g3d_status g3d_sam_generate(const g3d_sam *m, const g3d_sam_image *img, const g3d_sam_amg_params *p,
                            const g3d_progress *progress, g3d_sam_masks *out);

/* A mask provider (providers.h) running the automatic generator with params (NULL: defaults) on
 * the picture; scores are the predicted IoUs. Loads the model from path (errors as
 * g3d_sam_load_file). Release with g3d_mask_provider_free. */
g3d_status g3d_mask_provider_sam_create(const char *path, const g3d_sam_amg_params *params, g3d_mask_provider *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_SAM_H */
