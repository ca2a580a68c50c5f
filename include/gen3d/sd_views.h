/* gen3d/sd_views.h - Stable Diffusion as the inpainter of the world's views (the paper's "S"
 * at every camera pose) and of the background behind the foreground.
 *
 * A view of any size goes to the model at a size it was trained for: scaled as a whole so that
 * its longer side is the model's native side (512 for SD 1.5), padded at the right and bottom
 * to the model's size multiple, inpainted, cropped and scaled back. The scaling maps the view's
 * full extent onto the picture's, so the picture is the same camera with scaled intrinsics
 * (nothing is cut off or shifted; the padding lies beyond the last column and row). The hole
 * the model fills is the view's hole grown by a few pixels, so that the seam around it is
 * redrawn and feathered by the engine (sd.h, g3d_sd_inpaint); then only the view's own hole
 * pixels are written: every pixel outside the mask stays bit-identical.
 *
 *   g3d_sd *sd;  g3d_inpainter inp;
 *   g3d_sd_load(&(g3d_sd_paths){.model = "sd-v1-5-inpainting.ckpt"}, &sd);
 *   g3d_sd_view_params vp;  g3d_sd_view_params_default(&vp);
 *   g3d_inpainter_sd_views_create(sd, &vp, &inp);          // owns sd from here
 *   inp.inpaint(inp.ctx, &view, &holes, "a cosy living room", seed);
 *   g3d_inpainter_free(&inp);
 */
#ifndef G3D_SD_VIEWS_H
#define G3D_SD_VIEWS_H

#include "gen3d/sd.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_sd_view_params {
    g3d_sd_params sd;        /* negative prompt, sampler and steps, guidance (DPM++ 2M, 25 steps,
                                guidance 7.5, the negative prompt below); a non-NULL prompt
                                replaces each call's; seed, size and noise come from the call */
    int size;                /* the longer side the model draws at (512, SD 1.x / 2.x base); rounded
                                down to the model's size multiple, one multiple at least */
    int dilate;              /* the hole grown by this many view pixels for the model (4) */
    g3d_progress progress;   /* each call's denoising steps: stage "denoise", step of total */
    const g3d_inpainter *prefill; /* with a ControlNet loaded (sd.h): fills the hole of the
                                picture the model draws first (e.g. LaMa), and the ControlNet's
                                hint carries those colours (g3d_sd_inpaint_hint); NULL: the
                                hint's hole is -1, as in the official inpainting demo. The
                                caller keeps it alive while the plug-in runs */
} g3d_sd_view_params;

/* The negative prompt of the defaults. */
#define G3D_SD_VIEW_NEGATIVE "blurry, low quality, distorted, text, watermark"

/* Fills the defaults above. */
void g3d_sd_view_params_default(g3d_sd_view_params *p);

/* G3D_OK when the size is in 8..4096 and the dilation in 0..64; else G3D_ERR_ARG saying which. */
g3d_status g3d_sd_view_params_check(const g3d_sd_view_params *p);

/* The picture size for a w x h view: the view scaled to dw x dh (its longer side `size` rounded
 * down to a multiple of `multiple`, at least one multiple; the other side in proportion,
 * rounded), then padded to pw x ph, the next multiples of `multiple`. */
void g3d_sd_view_geometry(int w, int h, int size, int multiple, int *dw, int *dh, int *pw, int *ph);

/* The inpainter plug-in (providers.h) on a loaded model, which it owns from here (freed with
 * the plug-in, and on failure). A text-to-image model (4 input channels) inpaints by the
 * engine's latent blending; that is logged once, here. G3D_ERR_ARG for size < 8 or dilate
 * outside 0..64. */
g3d_status g3d_inpainter_sd_views_create(g3d_sd *model, const g3d_sd_view_params *p, g3d_inpainter *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_SD_VIEWS_H */
