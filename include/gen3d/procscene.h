/* gen3d/procscene.h - a procedural furnished room, ray traced on the CPU: the ground truth for
 * multi-view tests and novel-view benchmarks.
 *
 * The room (world frame = the default camera's frame: OpenCV axes, metres, y down):
 *   x in [-3, 3], y in [-1.5 (ceiling), 1.5 (floor)], z in [-1, 7] (back wall at z = 7);
 *   textured floor (checker + noise), striped walls, gridded ceiling; a window in the back
 *   wall opens onto a far landscape (a textured plane at z = 25, plus sky);
 *   two foreground objects near the camera (a box and a sphere, 2-2.7 m away) and two
 *   objects further back (a box and a sphere, 4.5-6 m).
 * Rendering is deterministic: one ray through each pixel centre, diffuse shading with a fixed
 * point light and ambient term, procedural textures from a fixed hash.
 */
#ifndef G3D_PROCSCENE_H
#define G3D_PROCSCENE_H

#include "gen3d/camera.h"
#include "gen3d/image.h"
#include "gen3d/ply.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Object ids written to the id image. */
enum {
    G3D_PROC_NONE = 0,      /* the ray escaped (never inside the room) */
    G3D_PROC_ROOM = 1,      /* floor, walls, ceiling */
    G3D_PROC_FAR = 2,       /* the landscape behind the window */
    G3D_PROC_NEAR_BOX = 10, /* foreground objects: ids 10..19 */
    G3D_PROC_NEAR_SPHERE = 11,
    G3D_PROC_BACK_BOX = 20, /* background objects: ids 20..29 */
    G3D_PROC_BACK_SPHERE = 21
};

/* True for the ids of the foreground objects. */
int g3d_procscene_is_near_object(int id);

/* The default camera: identity pose, 70 degree horizontal field of view, w x h. */
g3d_camera g3d_procscene_default_camera(int w, int h);

/* Renders the view of `cam`: rgb (h, w, 3) in [0, 1], depth (h, w, 1) z in metres (0 where
 * nothing is hit), ids (h, w, 1) object ids as floats. Any output may be NULL; the others are
 * created by the call. */
g3d_status g3d_procscene_render(const g3d_camera *cam, g3d_image *rgb, g3d_image *depth, g3d_image *ids);

/* Ground-truth coloured point cloud of the surfaces seen from n_views cameras spread on a
 * small arc around the default camera (w x h each, every `stride`-th pixel lifted). */
g3d_status g3d_procscene_points(int n_views, int w, int h, int stride, g3d_points *out);

/* The cameras used by g3d_procscene_points and by multi-view tests: view i of n on an arc of
 * +-0.6 m around the default camera, each looking at the middle of the room. */
g3d_camera g3d_procscene_arc_camera(int i, int n, int w, int h);

#ifdef __cplusplus
}
#endif
#endif /* G3D_PROCSCENE_H */
