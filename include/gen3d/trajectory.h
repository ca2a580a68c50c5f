/* gen3d/trajectory.h - camera paths for world generation and rendering.
 *
 * Poses are camera-to-world in the scene's frame (camera.h): the first pose of every preset is
 * the identity (the input camera). "yaw" turns about the world's up axis (-y), positive =
 * counter-clockwise seen from above (the camera turns left); "pitch" tilts about the camera's
 * x axis, positive = looking down. Translations are in metres; presets that move scale with
 * the scene: `distance` <= 0 means 0.25 x the scene's median depth.
 *
 * Presets (g3d_trajectory_names lists them; --help prints g3d_trajectory_describe):
 *   rotate      the Gen3d paper's counter-clockwise rotating camera: `steps` poses after the
 *               input, yaw growing evenly to `angle_deg` (default 8 steps, 60 degrees)
 *   lookdown    LucidDreamer: yaw 0, 20, 40, 60, -20, -40, -60 at pitch 0, then at pitch 22.5 (14)
 *   lookaround  LucidDreamer: the same seven yaws at pitch 0, -22.5 and 22.5 (21)
 *   rotate360   LucidDreamer: yaw 0, 36, ..., 324 (10)
 *   push_in, pull_out, move_left, move_right, orbit_left, orbit_right, pan_left, pan_right
 *               WorldScore's moves: forward/backward by s, sideways by s/2, orbit 30 degrees
 *               about a pivot s ahead, pan 30 degrees in place (s = distance); a keyframe pair
 *               with `interp` interpolated poses between (WorldScore: 48, i.e. 50 frames)
 */
#ifndef G3D_TRAJECTORY_H
#define G3D_TRAJECTORY_H

#include "gen3d/camera.h"
#include "gen3d/cameras_json.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_trajectory_params {
    int steps;          /* rotate: poses after the input (0 = default 8) */
    double angle_deg;   /* rotate: total yaw (0 = default 60) */
    double distance;    /* metres for moving presets; <= 0: 0.25 x scene scale */
    int interp;         /* interpolated poses between keyframes (-1 = preset default), at most
                           G3D_TRAJECTORY_MAX_INTERP */
} g3d_trajectory_params;

#define G3D_TRAJECTORY_MAX_INTERP 1000

/* Fills the defaults above. */
void g3d_trajectory_params_default(g3d_trajectory_params *p);

/* Builds the named preset. scene_scale: the scene's median depth in metres (> 0).
 * *poses is malloc'd (caller frees), *n its length. Unknown names are G3D_ERR_ARG with the
 * list of known ones. */
g3d_status g3d_trajectory_make(const char *name, const g3d_trajectory_params *p, double scene_scale,
                               g3d_mat4 **poses, int *n);

/* NULL-terminated list of preset names. */
const char *const *g3d_trajectory_names(void);
/* One-line description of a preset (NULL if unknown). */
const char *g3d_trajectory_describe(const char *name);

/* Pose with the given yaw and pitch (degrees) at position t. */
g3d_mat4 g3d_pose_yaw_pitch(double yaw_deg, double pitch_deg, g3d_vec3 t);

/* Camera paths from files: cameras.json or transforms.json (cameras_json.h). A trajectory
 * argument names a file when it contains '/', ends in ".json" or exists; otherwise a preset. */
int g3d_trajectory_is_file(const char *name);

/* Reads the cameras of a camera file, in order, each with its own intrinsics and image size.
 * An empty list, an image size outside 1..G3D_MAX_IMAGE_SIDE or a focal length <= 0 is
 * G3D_ERR_FORMAT naming the file and the frame. *cams is malloc'd (caller frees), *n its
 * length. */
g3d_status g3d_trajectory_load(const char *path, g3d_camera **cams, int *n);

/* The same checks, keeping the whole list (image, depth and mask paths too): *l is created
 * (caller frees with g3d_camera_list_free). */
g3d_status g3d_trajectory_load_list(const char *path, g3d_camera_list *l);

/* n_out poses (>= 1) picked from poses[0..n) at evenly spaced indices, rounded to the nearest
 * (the first and last are kept), e.g. a preset cut to a number of generation steps. *out is
 * malloc'd (caller frees). */
g3d_status g3d_trajectory_pick(const g3d_mat4 *poses, int n, int n_out, g3d_mat4 **out);

/* Extra training views around each pose (LucidDreamer's "hemisphere"): per pose, `count`
 * cameras (up to 5) orbiting a pivot `pivot` metres ahead by `angle_deg`: (yaw, pitch) =
 * (a, 0), (0, -a), (0, a), (-a, 0), then (a, a). *out is malloc'd with n * count poses. */
g3d_status g3d_trajectory_orbits(const g3d_mat4 *poses, int n, int count, double pivot, double angle_deg,
                                 g3d_mat4 **out, int *n_out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_TRAJECTORY_H */
