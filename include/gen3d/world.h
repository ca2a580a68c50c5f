/* gen3d/world.h - world generation (the Gen3d paper, sections 3.1-3.2): from one RGB-D frame,
 * a multi-view-consistent coloured point cloud of a larger scene, and the training views for
 * Gaussian splatting.
 *
 *   0. The input is split into layers (layers.h) when a mask provider is given; the input and
 *      the background behind its foreground are lifted into the cloud.
 *   1. For each pose of the trajectory: render the cloud (z-buffer), inpaint the holes,
 *      estimate the view's depth, align it to the cloud along the camera rays (align.h),
 *      lift only the new pixels.
 *   2. M extra views on small orbits around the poses are rendered from the final cloud with
 *      their validity masks; they are not inpainted (training uses their valid pixels only).
 *
 * The plug-ins (providers.h) decide the quality: without model weights the classical
 * inpainter and depth completion run. Deterministic for a seed.
 */
#ifndef G3D_WORLD_H
#define G3D_WORLD_H

#include "gen3d/align.h"
#include "gen3d/cloud.h"
#include "gen3d/frame.h"
#include "gen3d/layers.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_world_params {
    int extra_views;             /* M: extra training views (10) */
    double extra_angle_deg;      /* their orbit angle about a pivot at the median depth (5) */
    g3d_cloud_render_params render;
    g3d_align_params align;
    g3d_layers_params layers;
    g3d_progress progress;       /* stage "world": step per pose */
} g3d_world_params;
/* Fills the defaults above. */
void g3d_world_params_default(g3d_world_params *p);

/* What one step did (step 0 is the input). */
typedef struct g3d_world_step {
    double hole_fraction;        /* pixels the cloud did not cover before inpainting */
    g3d_align_stats align;
    int64_t points_added;
    double seconds_reproject, seconds_inpaint, seconds_depth, seconds_align, seconds_lift;
} g3d_world_step;

typedef struct g3d_world {
    g3d_cloud cloud;
    int n_views;                 /* N + 1 generated views, the input first */
    g3d_camera *cams;            /* (n_views) */
    g3d_image *rgb, *depth;      /* (n_views) the generated images and their (aligned) depth */
    g3d_world_step *steps;       /* (n_views) */
    int n_extra;                 /* M */
    g3d_camera *extra_cams;      /* (n_extra) */
    g3d_image *extra_rgb, *extra_mask;
    g3d_layers layers;           /* empty when no mask provider was given */
} g3d_world;
void g3d_world_free(g3d_world *w);

/* Runs world generation from `input` along poses[0..n_poses) (poses[0] is the input camera,
 * normally the identity). masks may be NULL (no layers). *out is filled (free with
 * g3d_world_free). Fails with a clear message if a pose sees none of the cloud. */
g3d_status g3d_world_generate(const g3d_frame *input, const g3d_mat4 *poses, int n_poses, const g3d_inpainter *inpaint,
                              const g3d_depth_estimator *depth, const g3d_mask_provider *masks,
                              const g3d_world_params *p, uint64_t seed, g3d_world *out);

/* Writes the dataset folder (atomically): views/view_NNN.png, depth/view_NNN.png (16-bit mm)
 * and .npy (metres), extra/extra_NNN.png, masks/extra_NNN.png, layers/{fg_mask,bg_rgb,
 * bg_depth}.png, cameras.json and transforms.json (generated views, then the extra views with
 * their mask_path), points.ply, log.json (per step: hole fraction, alignment residuals,
 * points added; no timings, so that the folder is byte-identical for the same input and seed). */
g3d_status g3d_world_save(const g3d_world *w, const char *dir, uint64_t seed);

/* Median valid depth of a depth map (0 if none): the scene scale of trajectories. */
double g3d_depth_median(const g3d_image *depth);

#ifdef __cplusplus
}
#endif
#endif /* G3D_WORLD_H */
