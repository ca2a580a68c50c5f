/* gen3d/explore.h - how explorable a scene is: the cameras a visitor reaches around the input
 * view, and the fraction of each one's pixels that the scene leaves empty.
 *
 * The exploration set is a 3 x 3 x 3 grid of camera positions around the input camera, in its
 * own frame (camera.h: x right, y down, z forward): sideways -d, 0, +d; up and down -d/2, 0,
 * +d/2; forward 0, d, 2d. Each position gets one of the nine view directions (yaw, pitch) in
 * {-a, 0, +a}^2 (yaw and pitch as in trajectory.h), assigned as an orthogonal array so that
 * every direction appears three times, once at each forward distance and with every sideways
 * step, and the input camera itself (the grid's centre column at distance 0) looks straight
 * ahead. d defaults to a quarter of the scene's median depth, a to 15 degrees. Every camera
 * has the input's intrinsics and image size.
 *
 * An empty pixel is one whose accumulated opacity is below 0.5 (render.h's depth rule): what
 * a viewer shows there is the background colour, a hole in the world.
 */
#ifndef G3D_EXPLORE_H
#define G3D_EXPLORE_H

#include "gen3d/camera.h"
#include "gen3d/gaussians.h"
#include "gen3d/image.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Cameras in the exploration set. */
#define G3D_EXPLORE_CAMERAS 27

typedef struct g3d_explore_params {
    double distance;    /* d in metres; 0 = 0.25 x the scene's median depth; at most the median depth */
    double angle_deg;   /* a: yaw and pitch reach, degrees in [0, 90); default 15 */
} g3d_explore_params;

/* Fills the defaults above. */
void g3d_explore_params_default(g3d_explore_params *p);

/* The exploration set around `input` (poses relative to input->c2w, its intrinsics and size).
 * scene_scale: the scene's median depth in metres (> 0). p NULL = defaults. *cams is
 * malloc'd with G3D_EXPLORE_CAMERAS cameras (caller frees). *distance (may be NULL) gets the d
 * used. Errors: G3D_ERR_ARG for a scale that is not positive, a negative or non-finite
 * distance or one beyond the median depth (the forward cameras would pass through the
 * scene), an angle outside [0, 90). */
g3d_status g3d_explore_cameras(const g3d_camera *input, double scene_scale, const g3d_explore_params *p,
                               g3d_camera **cams, double *distance);

/* Renders the first g->n Gaussians from each of the n cameras (n >= 1) and stores the fraction
 * of empty pixels (accumulated opacity < 0.5) of camera i in empty[i]. With `sheet` non-NULL
 * it is created (caller frees) as a contact sheet of the renders, `columns` per row, each
 * shrunk to at most `thumb_side` pixels on its longer side, empty pixels in magenta (a
 * thumbnail pixel is magenta when any pixel it covers is empty, so one-pixel cracks stay
 * visible), on a one-pixel grey grid. Errors: G3D_ERR_ARG (no Gaussians, n < 1, columns or
 * thumb_side < 1, bad cameras as in g3d_render_path), G3D_ERR_NOMEM. */
g3d_status g3d_explore_coverage(const g3d_gaussians *g, const g3d_camera *cams, int n, double *empty,
                                g3d_image *sheet, int columns, int thumb_side);

#ifdef __cplusplus
}
#endif
#endif /* G3D_EXPLORE_H */
