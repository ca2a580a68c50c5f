/* gen3d/layers.h - splitting the input into a foreground and a background layer (the Gen3d
 * paper, section 3.1).
 *
 * Selection (as the paper applies it to SAM masks): keep candidate masks with score >
 * min_score and area within [min_area, max_area] of the image; the foreground is the union
 * of those whose median depth is below theta_d, the `percentile` quantile of the depth map,
 * and that stand in front of their surroundings: at least `min_occluding` of the mask's
 * boundary pixels have a neighbour outside that is deeper by more than 5 %. (Without this
 * test, patches of floor, ceiling or a wall close to the camera would count as objects.)
 * The background layer is the input with the foreground removed: its colour is inpainted and
 * its depth completed behind the foreground, so that moving the camera reveals plausible
 * background rather than holes.
 *
 * The candidates come from a mask provider (providers.h): a segmentation model, or the
 * weight-free region proposals of regions.h.
 */
#ifndef G3D_LAYERS_H
#define G3D_LAYERS_H

#include "gen3d/providers.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_layers_params {
    float min_score;      /* 0.85 (SAM's predicted IoU threshold in the paper) */
    float min_area;       /* 0.005 of the image */
    float max_area;       /* 0.60 of the image */
    float percentile;     /* theta_d = this quantile of the valid depth (0.35) */
    float min_occluding;  /* fraction of the boundary that must occlude something (0.3) */
    int dilate;           /* grow the foreground by this many pixels before inpainting (2) */
    const g3d_prompt_provider *prompts; /* asked once the foreground is known (NULL: no prompts) */
} g3d_layers_params;
/* Fills the defaults above. */
void g3d_layers_params_default(g3d_layers_params *p);

typedef struct g3d_layers {
    g3d_image fg_mask;    /* (h, w, 1) 1 = foreground */
    g3d_image bg_rgb;     /* (h, w, 3) background with the foreground inpainted */
    g3d_image bg_depth;   /* (h, w, 1) background depth, completed behind the foreground */
    int n_candidates, n_kept, n_foreground;
    float theta_d;
    char *bg_prompt;      /* from params.prompts (malloc'd, or NULL): the background's inpainting prompt */
    char *view_prompt;    /* and the prompt for inpainting the generated views */
} g3d_layers;
void g3d_layers_free(g3d_layers *l);
/* Deep copy into dst (overwritten, not freed first); on failure dst is left empty. */
g3d_status g3d_layers_clone(g3d_layers *dst, const g3d_layers *src);

/* Computes the layers of (rgb, depth). masks proposes candidates; inpaint fills the
 * background colour; depth_fill completes the background depth (called with the depth
 * outside the foreground as `known` and the foreground as `mask`). */
g3d_status g3d_layers_compute(const g3d_image *rgb, const g3d_image *depth, const g3d_mask_provider *masks,
                              const g3d_inpainter *inpaint, const g3d_depth_estimator *depth_fill,
                              const g3d_layers_params *p, uint64_t seed, g3d_layers *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_LAYERS_H */
