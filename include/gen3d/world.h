/* gen3d/world.h - world generation (the Gen3d paper, sections 3.1-3.2): from one RGB-D frame,
 * a multi-view-consistent coloured point cloud of a larger scene, and the training views for
 * Gaussian splatting.
 *
 *   0. The input is lifted into the cloud and, when its layers (layers.h) are given, the
 *      background behind its foreground too.
 *   1. For each pose of the trajectory: render the cloud (z-buffer), inpaint the holes,
 *      estimate the view's depth, align it to the cloud along the camera rays (align.h),
 *      lift only the new pixels.
 *      Side steps (side_from) do the same at a lower resolution, complete and align a hole that
 *      a depth edge runs into from the edge's far side (g3d_align_far_side with align.edge_ratio:
 *      what a step uncovers lies behind the occluder) and, with side_carve, do not lift the
 *      hole pixels that a path view saw through (a point in front of its depth).
 *   2. M extra views on small orbits around the poses are rendered from the final cloud with
 *      their validity masks; they are not inpainted (training uses their valid pixels only).
 *
 * The plug-ins (providers.h) decide the quality: without model weights the classical
 * inpainter and depth completion run. Deterministic for a seed.
 *
 * A world is saved as a folder (g3d_world_save) and read back (g3d_world_load); the folder is
 * also a dataset for `gen3d train` and nerfstudio tools (dataset.h).
 */
#ifndef G3D_WORLD_H
#define G3D_WORLD_H

#include "gen3d/align.h"
#include "gen3d/cameras_json.h"
#include "gen3d/cloud.h"
#include "gen3d/frame.h"
#include "gen3d/layers.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_world_params {
    int extra_views;             /* M: extra training views (10) */
    double extra_angle_deg;      /* their orbit angle about a pivot at the median depth (5) */
    int hole_stride;             /* the inpainted holes of each step are lifted one point per
                                    hole_stride x hole_stride block (g3d_cloud_lift_sparse); 1..16 (2) */
    int side_from;               /* the poses from this index on are side steps (g3d_generate: the
                                    exploration set's) that only fill what the path before them
                                    left: 0 (or n_poses and more) = none (0) */
    int side_max_side;           /* side steps run at the input's size, downscaled so that the longer
                                    side is at most this: they only fill what the path left, and
                                    their inpainting is most of their cost; >= 16 (384) */
    double side_carve;           /* > 0: a side step does not lift a hole pixel whose point a path
                                    view sees in front of its own depth by more than this fraction
                                    of that depth (that view saw through it: an inpainted guess
                                    that would hide what the path saw); 0..1, 0 = off (0.02) */
    g3d_cloud_render_params render;
    g3d_align_params align;
    g3d_progress progress;       /* stage "world": step per pose; stopping returns G3D_CANCELLED */
    const char *prompt;          /* given to the inpainter for every view (NULL: none) */
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
    g3d_layers layers;           /* a copy of the layers given; empty without */
} g3d_world;
void g3d_world_free(g3d_world *w);

/* Runs world generation from `input` along poses[0..n_poses) (poses[0] is the input camera,
 * normally the identity). layers: the input's layers from g3d_layers_compute, or NULL (none);
 * they are copied into out->layers. *out is filled (free with g3d_world_free); on failure it
 * is zeroed. Fails with a clear message if a pose sees none of the cloud, G3D_CANCELLED when
 * the progress callback asks to stop. */
g3d_status g3d_world_generate(const g3d_frame *input, const g3d_mat4 *poses, int n_poses, const g3d_inpainter *inpaint,
                              const g3d_depth_estimator *depth, const g3d_layers *layers,
                              const g3d_world_params *p, uint64_t seed, g3d_world *out);

/* The cameras of a world as they are listed in its folder: the generated views (names
 * "<prefix>views/view_NNN.png"), then the extra views ("<prefix>extra/extra_NNN.png" with mask
 * "<prefix>masks/extra_NNN.png"). prefix may be NULL. *out is created by the call. */
g3d_status g3d_world_cameras(const g3d_world *w, const char *prefix, g3d_camera_list *out);

/* Writes the world folder (atomically): views/view_NNN.png, depth/view_NNN.png (16-bit mm)
 * and .npy (metres), extra/extra_NNN.png, masks/extra_NNN.png, layers/{fg_mask,bg_rgb,
 * bg_depth}.png, cameras.json and transforms.json (g3d_world_cameras), points.ply, log.json
 * (per step: hole fraction, alignment residuals, points added; no timings, so that the folder
 * is byte-identical for the same input and seed). */
g3d_status g3d_world_save(const g3d_world *w, const char *dir, uint64_t seed);

/* Reads a world folder back: the cameras and images of the views and extra views with their
 * masks (dataset.h), depth/view_NNN.npy, the layers, points.ply as the cloud and log.json's
 * steps. What the folder does not hold comes back empty, so any dataset folder loads: without
 * log.json the frames with a mask are the extra views and the others the generated views;
 * views without depth files have empty depth, no points.ply gives an empty cloud. What saving
 * does not keep is lost: images are 8-bit, the layers' background depth is in millimetres,
 * points carry no footprint (size and span 0, view -1) and steps no timings. *out is zeroed
 * on failure; errors name the file. */
g3d_status g3d_world_load(const char *dir, g3d_world *out);

/* Median valid depth of a depth map (0 if none): the scene scale of trajectories. */
double g3d_depth_median(const g3d_image *depth);

#ifdef __cplusplus
}
#endif
#endif /* G3D_WORLD_H */
