/* gen3d/viewer.h - the single-file browser viewer: viewer.html = the viewer template (three.js
 * and Spark, built from web/ when node and npm are present at build time) with one scene and
 * its cameras written into it. The page works from file://, offline, with no server.
 *
 * WHAT GOES INTO THE PAGE
 *   - the scene as .spz version 2 (g3d_spz_encode), whose RUB axes (x right, y up, z towards
 *     the viewer) are three.js's world axes, so the scene shows upright with no transform;
 *   - a JSON description: Gaussian count, SH degree, scene scale, the input camera and the
 *     camera paths. Cameras keep their pixel intrinsics (fx, fy, cx, cy, width, height;
 *     pixel centres at integers) and carry their pose as a row-major 4x4 camera-to-world
 *     matrix in three.js axes: c2w_page = W * c2w * diag(1, -1, -1, 1), where W is the world
 *     flip (x, y, z) -> (x, -y, -z) that .spz applies (g3d_world_flip_yz) and the right
 *     factor turns OpenCV camera axes into OpenGL's (g3d_pose_opencv_to_opengl). This is the
 *     only place the OpenCV-to-viewer change happens (docs/conventions.md).
 *
 *   Binary data is written as bytes into the windows-1252 page, with 0x00, 0x0D, '=' and
 *   any '<' before '/' or '!' written as '=' followed by the byte + 64 (1.2 % larger, where
 *   base64 would be 33 %); web/src/boot.js decodes it.
 *
 * THE TEMPLATE is found, in this order, at $G3D_VIEWER_TEMPLATE, next to the running program
 * (the build folder: build/gen3d-viewer.html beside build/gen3d), in ../share/gen3d beside the
 * program's folder (an installed gen3d), or in the data folder compiled in at build time.
 */
#ifndef G3D_VIEWER_H
#define G3D_VIEWER_H

#include "gen3d/camera.h"
#include "gen3d/gaussians.h"

#ifdef __cplusplus
extern "C" {
#endif

#define G3D_VIEWER_TEMPLATE_NAME "gen3d-viewer.html"
/* The largest .spz the page embeds: browsers read it as one string of up to ~2^29
 * characters, and decoding it takes several times its size in memory. */
#define G3D_VIEWER_MAX_SCENE_BYTES ((size_t)256 << 20)

/* A camera path the page can play; it shows a button for "generation" and for "video". */
typedef struct g3d_viewer_path {
    const char *name;
    const g3d_camera *cams;   /* OpenCV axes, camera-to-world */
    int n;
    double fps;               /* cameras per second when played (poses are blended between) */
} g3d_viewer_path;

typedef struct g3d_viewer_params {
    const char *template_path;  /* NULL (default): g3d_viewer_find_template */
    const char *label;          /* names the scene in error messages; default "scene" */
    size_t max_scene_bytes;     /* default G3D_VIEWER_MAX_SCENE_BYTES */
    double scene_scale;         /* metres; the orbit distance and flying speed. <= 0 (default):
                                   the median depth in front of the input camera
                                   (g3d_render_scene_scale), or 1 when nothing is in front */
} g3d_viewer_params;

void g3d_viewer_params_default(g3d_viewer_params *o);

/* Locates the template (order above). *path is malloc'd (caller frees). Errors:
 * G3D_ERR_UNSUPPORTED when there is none (the viewer was not built), G3D_ERR_IO when
 * $G3D_VIEWER_TEMPLATE names a file that cannot be read. */
g3d_status g3d_viewer_find_template(char **path);

/* Writes `path` (atomically: nothing is left behind on failure) for the first g->n Gaussians,
 * opening at `input` (its pose and intrinsics), with npaths camera paths (paths may be NULL
 * when npaths is 0); o may be NULL (defaults). Errors: G3D_ERR_ARG (no Gaussians; a camera
 * with a non-positive size or focal length), G3D_ERR_UNSUPPORTED (no template, see
 * g3d_viewer_find_template; a .spz larger than o->max_scene_bytes, saying the size, the limit
 * and what to do), those of g3d_spz_encode, G3D_ERR_FORMAT (a damaged template), G3D_ERR_IO,
 * G3D_ERR_NOMEM. */
g3d_status g3d_viewer_write(const char *path, const g3d_gaussians *g, const g3d_camera *input,
                            const g3d_viewer_path *paths, int npaths, const g3d_viewer_params *o);

/* What gen3d generate writes: dir/viewer.html for a generated scene, with the generation
 * trajectory `views` (views[0] is the input camera) and, when video_trajectory is not NULL,
 * the video path g3d_render_flythrough(video_trajectory, ..., video_frames) played at
 * video_fps cameras per second, as the video is. When the viewer is not installed or the scene is too large to embed,
 * it logs a warning saying so, sets *written = 0 and returns G3D_OK; other errors are
 * returned. written may be NULL. */
g3d_status g3d_viewer_write_generated(const char *dir, const g3d_gaussians *g, const g3d_camera *views,
                                      int n_views, const char *video_trajectory, int video_frames,
                                      double video_fps, int *written);

/* Keeps at most max_gaussians Gaussians (<= 0: all), those with the largest
 * sigmoid(opacity) * exp(sum of log scales), in their original order, and drops the SH bands
 * above sh_degree (< 0 or >= the model's: keep all). *out is created (caller frees). Errors:
 * G3D_ERR_NOMEM. */
g3d_status g3d_viewer_reduce(const g3d_gaussians *g, int64_t max_gaussians, int sh_degree,
                             g3d_gaussians *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_VIEWER_H */
