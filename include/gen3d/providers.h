/* gen3d/providers.h - the plug-in points of the pipeline: inpainting, depth estimation,
 * candidate masks and prompts. Each is a small table of function pointers with a `ctx`.
 *
 * The world loop only sees these tables. Implementations: classical weight-free ones
 * (src/classic: inpaint_classic.h, depth_complete.h, regions.h), and neural ones (src/models:
 * g3d_inpainter_lama_create in lama.h, depth_estimators.h; the prompts of describe.h), chosen
 * once per run (g3d_generate, generate.h) from its parameters or passed in by the caller.
 * Every implementation is deterministic for a given seed.
 *
 * LIFETIME
 *   An implementation is made by g3d_<kind>_<impl>_create(..., &table) (e.g.
 *   g3d_inpainter_classic_create) and released by g3d_<kind>_free(&table), which calls the
 *   table's own `free` hook and zeroes the table. Callers never call the hook themselves.
 */
#ifndef G3D_PROVIDERS_H
#define G3D_PROVIDERS_H

#include "gen3d/camera.h"
#include "gen3d/image.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Fills the masked pixels of an image with plausible content. */
typedef struct g3d_inpainter {
    const char *name;
    void *ctx;
    /* image: (h, w, 3), modified in place where mask > 0.5; pixels outside the mask are
     * left bit-identical. mask: (h, w, 1), 1 = fill. prompt: text or NULL. */
    g3d_status (*inpaint)(void *ctx, g3d_image *image, const g3d_image *mask, const char *prompt,
                          uint64_t seed);
    void (*free)(void *ctx); /* releases ctx; may be NULL (use g3d_inpainter_free) */
} g3d_inpainter;

/* Releases the inpainter's context and zeroes the table. NULL or zeroed is fine. */
void g3d_inpainter_free(g3d_inpainter *p);

/* Estimates metric depth (and optionally intrinsics) for an image. */
typedef struct g3d_depth_estimator {
    const char *name;
    void *ctx;
    /* rgb: (h, w, 3). known: (h, w, 1) metric depth of pixels already known (0 = unknown),
     * or NULL. mask: (h, w, 1), 1 = pixels whose depth is wanted, or NULL for all.
     * depth_out: created by the callee, (h, w, 1) metres: the estimator's own estimate for
     * every pixel (a model predicts all of them, so that the caller can measure where it
     * disagrees with `known` and align it; completion returns `known` unchanged where given).
     * K_io: on input the camera if known (fx > 0), else zeroed; estimators that predict
     * intrinsics fill it when it was unknown. May be NULL. */
    g3d_status (*estimate)(void *ctx, const g3d_image *rgb, const g3d_image *known, const g3d_image *mask,
                           g3d_image *depth_out, g3d_intrinsics *K_io);
    void (*free)(void *ctx); /* releases ctx; may be NULL (use g3d_depth_estimator_free) */
} g3d_depth_estimator;

/* Releases the estimator's context and zeroes the table. NULL or zeroed is fine. */
void g3d_depth_estimator_free(g3d_depth_estimator *p);

/* Proposes candidate object masks with confidence scores (SAM-like). */
typedef struct g3d_mask_set {
    int n;             /* number of masks */
    int w, h;
    uint8_t *masks;    /* (n, h, w), 0/1 */
    float *scores;     /* (n) confidence in [0, 1] */
} g3d_mask_set;
void g3d_mask_set_free(g3d_mask_set *s);

typedef struct g3d_mask_provider {
    const char *name;
    void *ctx;
    /* rgb (h, w, 3), depth (h, w, 1) metres (0 = invalid). out is filled (caller frees with
     * g3d_mask_set_free). */
    g3d_status (*propose)(void *ctx, const g3d_image *rgb, const g3d_image *depth, g3d_mask_set *out);
    void (*free)(void *ctx); /* releases ctx; may be NULL (use g3d_mask_provider_free) */
} g3d_mask_provider;

/* Releases the provider's context and zeroes the table. NULL or zeroed is fine. */
void g3d_mask_provider_free(g3d_mask_provider *p);

/* Writes the inpainting prompts of an image that came without text (the paper's automatic
 * prompts: describe.h). */
typedef struct g3d_prompt_provider {
    const char *name;
    void *ctx;
    /* rgb (h, w, 3); exclude (h, w, 1): the foreground (1), left out of the background's
     * description, or NULL. *background: the prompt for inpainting the background layer,
     * *view: the prompt for inpainting the generated views; each malloc'd (caller frees) or
     * NULL when the provider has none. */
    g3d_status (*prompt)(void *ctx, const g3d_image *rgb, const g3d_image *exclude, char **background, char **view);
    void (*free)(void *ctx); /* releases ctx; may be NULL (use g3d_prompt_provider_free) */
} g3d_prompt_provider;

/* Releases the provider's context and zeroes the table. NULL or zeroed is fine. */
void g3d_prompt_provider_free(g3d_prompt_provider *p);

#ifdef __cplusplus
}
#endif
#endif /* G3D_PROVIDERS_H */
