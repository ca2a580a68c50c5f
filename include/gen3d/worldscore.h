/* gen3d/worldscore.h - camera paths exactly as the WorldScore benchmark (static track) builds
 * them, and its camera_data.json.
 *
 * A path is a list of moves (WorldScore's "layouts"), each applied in the current camera's own
 * frame: push_in / pull_out (forward / backward by s), move_left / move_right (sideways by s/2),
 * orbit_left / orbit_right (30 degrees about a pivot s ahead, still facing it), pan_left /
 * pan_right (30 degrees in place), with s the camera speed. These are the moves of the presets of
 * the same names in trajectory.h. Between consecutive keyframes WorldScore inserts 48 cameras by
 * interpolating the WORLD-TO-CAMERA pose: slerp of the rotation and linear interpolation of the
 * translation t = -R c (not of the camera centre, so an orbit's in-between cameras differ from
 * g3d_pose_interp's). A path of k moves therefore has 1 + 49 k cameras, keyframes at 0, 49, 98...
 *
 * Every camera is the benchmark's: 512 x 512 pixels, fx = fy = 500, principal point at the
 * image centre (cx = cy = 255.5 in gen3d's convention, i.e. 256 in the pixel-edge convention
 * WorldScore's evaluation passes to DROID-SLAM). Poses are camera-to-world, OpenCV axes,
 * relative to the first camera (the identity: a generated scene's input camera).
 */
#ifndef G3D_WORLDSCORE_H
#define G3D_WORLDSCORE_H

#include "gen3d/camera.h"

#ifdef __cplusplus
extern "C" {
#endif

#define G3D_WORLDSCORE_SIDE 512
#define G3D_WORLDSCORE_FOCAL 500.0
#define G3D_WORLDSCORE_FRAMES_PER_MOVE 49

/* The benchmark camera: 512 x 512, fx = fy = 500, centred principal point. */
g3d_intrinsics g3d_worldscore_intrinsics(void);

/* The camera path of `moves`: move names separated by commas ("push_in",
 * "orbit_left,pan_right"), at most 64 moves. speed: s in metres (> 0, finite).
 * *cams is malloc'd (caller frees), *n = 1 + 49 * moves. Errors: G3D_ERR_ARG naming an unknown
 * or empty move (with the list of known ones) or a bad speed; G3D_ERR_NOMEM. */
g3d_status g3d_worldscore_path(const char *moves, double speed, g3d_camera **cams, int *n);

/* Writes WorldScore's camera_data.json for a path made by g3d_worldscore_path (n = 1 + 49 k):
 * "focal_length" 500, "scale" = speed, "cameras" (the k + 1 keyframes) and "cameras_interp"
 * (all n cameras) as 4x4 camera-to-world matrices in WorldScore's frames: Blender camera axes
 * (x right, y up, z backward) in a world whose axes are the first camera's PyTorch3D axes
 * (x left, y up, z forward). Atomic. Errors: G3D_ERR_ARG for a camera count that is not
 * 1 + 49 k, G3D_ERR_IO. */
g3d_status g3d_worldscore_write_camera_data(const char *path, const g3d_camera *cams, int n, double speed);

#ifdef __cplusplus
}
#endif
#endif /* G3D_WORLDSCORE_H */
