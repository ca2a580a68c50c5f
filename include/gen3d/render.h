/* gen3d/render.h - rendering a Gaussian scene along a camera path: frames, depth, video.
 *
 * Cameras follow camera.h (OpenCV axes, camera-to-world, pixel centres at integers); every
 * camera carries its own intrinsics and image size, so one path may mix sizes. Frames are
 * rendered with the tile rasterizer (raster.h) one after another, reusing one workspace.
 *
 * Depth frames are the rasterizer's alpha-weighted view z divided by the accumulated alpha
 * (metres along the camera z axis), and 0 (invalid, as everywhere in gen3d) where the
 * accumulated alpha is below `depth_min_alpha`: background is not given a depth.
 *
 * Thread-safety: functions are reentrant; the rasterizer parallelises each frame with OpenMP.
 */
#ifndef G3D_RENDER_H
#define G3D_RENDER_H

#include "gen3d/camera.h"
#include "gen3d/gaussians.h"
#include "gen3d/image.h"
#include "gen3d/trajectory.h"
#include "gen3d/video.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_render_params {
    float background[3];    /* RGB in [0, 1] behind the splats; default black */
    int sh_degree;          /* SH degree evaluated, 0..model's; -1 = the model's (default) */
    int depth;              /* 1: also produce depth frames; default 0 */
    float depth_min_alpha;  /* depth is 0 where accumulated alpha is below this; default 0.5 */
    g3d_progress progress;  /* stage "render", one step per frame; may cancel */
} g3d_render_params;

void g3d_render_params_default(g3d_render_params *p);

/* Receives frame `index` (0..n-1) seen by `cam`: rgb (H, W, 3) in [0, 1]; depth (H, W)
 * metres or NULL when opts.depth is 0. The images belong to the renderer and are valid
 * only during the call. A non-OK return stops the rendering and is returned as is. */
typedef g3d_status (*g3d_render_frame_fn)(void *user, int index, const g3d_camera *cam,
                                          const g3d_image *rgb, const g3d_image *depth);

/* Renders the first g->n Gaussians from each of the n cameras (n >= 1), in order, handing each
 * frame to fn. Errors: G3D_ERR_ARG (n < 1, a camera size outside 1..G3D_MAX_IMAGE_SIDE,
 * non-finite intrinsics or pose, sh_degree above the model's), G3D_CANCELLED, G3D_ERR_NOMEM, and
 * whatever fn returns. */
g3d_status g3d_render_path(const g3d_gaussians *g, const g3d_camera *cams, int n,
                           const g3d_render_params *p, g3d_render_frame_fn fn, void *user);

/* What g3d_render_to_dir writes into its folder. */
typedef struct g3d_render_output_params {
    int frames;       /* frames/00000.png, ... (8-bit RGB); default 1 */
    int video;        /* video.mp4 (needs ffmpeg and one size for all cameras); default 1 */
    int cameras;      /* cameras.json: the path, names pointing at the frames (and depth
                         frames); default 1 */
    g3d_video_params video_params;
} g3d_render_output_params;

void g3d_render_output_params_default(g3d_render_output_params *o);

typedef struct g3d_render_result {
    int video_written;   /* video.mp4 exists */
    int frames_written;  /* frames/ holds the PNG frames */
    const char *note;    /* why no video was written when one was asked for, else NULL (static) */
} g3d_render_result;

/* Renders the path into the existing folder `dir` (typically the temporary folder of
 * g3d_atomic_dir_begin): frames/%05d.png, video.mp4, depth/%05d.png (16-bit millimetres, 0 =
 * no depth; with p->depth) and cameras.json, as o asks. A video is skipped, with a warning in
 * the log and in res->note, when ffmpeg is not installed or the cameras differ in size; the
 * PNG frames are then written even when o->frames is 0, so the render is never lost.
 * res may be NULL. Errors: those of g3d_render_path, G3D_ERR_IO (write failures, ffmpeg
 * failing). Files already written stay in dir on failure: abort the whole folder. */
g3d_status g3d_render_to_dir(const g3d_gaussians *g, const g3d_camera *cams, int n,
                             const g3d_render_params *p, const g3d_render_output_params *o,
                             const char *dir, g3d_render_result *res);

/* The scene scale used by the moving presets: median view depth (metres) of the Gaussian
 * centres in front of `cam` (z > 0.01 m). Errors: G3D_ERR_ARG when none is in front. */
g3d_status g3d_render_scene_scale(const g3d_gaussians *g, const g3d_camera *cam, double *scale);

/* Resamples a pose sequence (n >= 1) to `frames` (>= 1) poses evenly spaced in keyframe
 * index, smoothly: Catmull-Rom splines through the camera centres and through the
 * (sign-aligned) quaternions, renormalised. The first and last poses are kept exactly.
 * *out is malloc'd (caller frees). Errors: G3D_ERR_ARG, G3D_ERR_NOMEM. */
g3d_status g3d_render_resample_poses(const g3d_mat4 *poses, int n, int frames, g3d_mat4 **out);

/* A fly-through camera path for a scene seen from `input` (its intrinsics and size are used
 * for every frame; its pose is the path's origin). `name` is a trajectory.h preset, or
 * "swing": a closed loop that slides sideways by +-0.15 s and pushes in by up to 0.1 s while
 * aiming at the point s ahead of the input camera, suited to single-image scenes (s = scene
 * scale). Preset poses are relative to the input camera (pose_i = input.c2w * preset_i).
 * tp: preset parameters (NULL = defaults). scene_scale <= 0: g3d_render_scene_scale(g, input)
 * (g may be NULL when scene_scale > 0). frames > 0 resamples the preset to that many frames
 * with g3d_render_resample_poses; frames <= 0 keeps the preset's poses (swing: 120).
 * *cams is malloc'd (caller frees), *n its length. Errors: G3D_ERR_ARG (unknown name, listing
 * the known ones; no scale), G3D_ERR_NOMEM. */
g3d_status g3d_render_flythrough(const char *name, const g3d_trajectory_params *tp,
                                 const g3d_gaussians *g, const g3d_camera *input,
                                 double scene_scale, int frames, g3d_camera **cams, int *n);

#ifdef __cplusplus
}
#endif
#endif /* G3D_RENDER_H */
