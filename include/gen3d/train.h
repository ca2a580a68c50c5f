/* gen3d/train.h - optimises a Gaussian model against posed images (3DGS training loop).
 *
 * One iteration: pick the next view (a seeded random permutation, refilled every epoch),
 * render it (raster.h) with SH degree min(it / sh_degree_interval, model degree), masked
 * L1+SSIM loss (loss.h) plus the optional coverage term, backward, densification statistics,
 * one Adam step (adam.h), and on the densification schedule clone/split/prune and opacity
 * resets (densify.h).
 * Deterministic for a fixed seed and thread count.
 */
#ifndef G3D_TRAIN_H
#define G3D_TRAIN_H

#include "gen3d/adam.h"
#include "gen3d/camera.h"
#include "gen3d/densify.h"
#include "gen3d/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_train_view {
    g3d_camera cam;            /* its K.width/height must equal the image size */
    const g3d_image *image;    /* (h, w, 3) target, values in [0, 1]; borrowed */
    const g3d_image *mask;     /* (h, w, 1) validity (> 0.5 = train on it) or NULL; borrowed */
} g3d_train_view;

typedef struct g3d_train_params {
    int64_t iterations;         /* 3000 */
    uint64_t seed;              /* view order and split samples; 42 */
    double lambda_ssim;         /* 0.2 */
    double extent;              /* scene size for the lr and densification; 0 = from cameras */
    int64_t sh_degree_interval; /* the active SH degree rises every this many steps; 1000 */
    float bg[3];                /* background colour behind the splats; black */
    int densify;                /* 1 = adaptive density control on */
    int visible_adam;           /* 1 = Adam steps only the Gaussians the view sees (adam.h); 0:
                                   it saves little and cost 0.3 dB at the real held-out view */
    int64_t first_view_every;   /* > 0: every this many iterations train on views[0] (in
                                   g3d_generate the input, the only view that is all real
                                   pixels), besides its turn in the permutation; 0 = off */
    double coverage_weight;     /* > 0: the loss adds this weight x the mean of (1 - accumulated
                                   opacity) over each view's trained pixels: against the black
                                   background a dark surface can otherwise turn transparent, and
                                   the gaps open when seen from elsewhere; 0 = off (0) */
    int64_t coarse_until;       /* iterations 1..coarse_until see every view downscaled by
                                   coarse_factor (area filter; coarse to fine); 0 = off */
    int coarse_factor;          /* 2 */
    int64_t report_every;       /* progress callback period in iterations; 50 */
    g3d_adam_params adam;       /* defaults with means_lr_steps = iterations */
    g3d_densify_params dens;    /* g3d_densify_params_default(iterations) */
    g3d_progress progress;      /* stage "train"; info "loss L psnr P dB n N" */
    const char *checkpoint_path; /* NULL = none; else the whole training state is written here
                                    (safetensors, atomically replaced) every checkpoint_every
                                    iterations before the last */
    int64_t checkpoint_every;
    const char *resume_path;    /* NULL = start from g; else g is replaced by the model in this
                                   checkpoint and training continues after its iteration, exactly
                                   as the uninterrupted run would (same views, seed, settings) */
} g3d_train_params;

/* Defaults for a schedule of `iterations` steps (see the field comments). */
void g3d_train_params_default(g3d_train_params *p, int64_t iterations);

/* The reference scene extent: 1.1 x the largest distance of a camera centre from their mean
 * (a single view gives 1.1 x 1 m, since there is no baseline to measure). */
double g3d_train_scene_extent(const g3d_train_view *views, int nviews);

typedef struct g3d_train_result {
    double last_loss;           /* mean loss over the last report period */
    double last_psnr;           /* mean training PSNR over the last report period, dB */
    double seconds;             /* wall time */
} g3d_train_result;

/* Trains g in place (it may grow, shrink and be reallocated by densification). Views must
 * have matching sizes (G3D_ERR_MISMATCH naming the view otherwise); nviews >= 1.
 * Returns G3D_CANCELLED when the progress callback asks to stop (g stays valid).
 * Resuming refuses a checkpoint of another view count or seed, or one already at or past
 * p->iterations (G3D_ERR_MISMATCH / G3D_ERR_ARG, naming the file).
 * res may be NULL. */
g3d_status g3d_train(g3d_gaussians *g, const g3d_train_view *views, int nviews,
                     const g3d_train_params *p, g3d_train_result *res);

#ifdef __cplusplus
}
#endif
#endif /* G3D_TRAIN_H */
