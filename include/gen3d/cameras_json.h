/* gen3d/cameras_json.h - camera lists on disk: our cameras.json and nerfstudio's
 * transforms.json.
 *
 * cameras.json (ours; OpenCV axes, camera-to-world, pixel centres at integers):
 *   {"version": 1, "convention": "opencv_c2w",
 *    "frames": [{"name": "view_000", "file_path": "images/view_000.png",   (optional)
 *                "mask_path": "masks/view_000.png",                        (optional)
 *                "depth_path": "depth/view_000.npy",                       (optional)
 *                "fx": .., "fy": .., "cx": .., "cy": .., "width": .., "height": ..,
 *                "c2w": [[r00, r01, r02, tx], [..], [..], [0, 0, 0, 1]]}]}
 *
 * transforms.json (nerfstudio): camera_model "PINHOLE"/"OPENCV" (distortion must be zero),
 *   fl_x, fl_y, cx, cy, w, h at the top level and/or per frame (per-frame values win),
 *   frames[].file_path, frames[].mask_path and frames[].depth_file_path (optional; a
 *   16-bit PNG in millimetres, nerfstudio's default unit, or float metres in .npy/.pfm),
 *   frames[].transform_matrix =
 *   camera-to-world with OpenGL camera axes (x right, y up, z backward). nerfstudio puts
 *   pixel centres at i + 0.5, so cx_nerfstudio = cx_ours + 0.5 (and likewise cy).
 *   Poses are converted with g3d_pose_opencv_to_opengl; the world frame is kept as it is.
 *
 * Readers reject malformed JSON, missing fields, non-finite values and rotation blocks
 * that are not orthonormal, naming the file and the frame index.
 */
#ifndef G3D_CAMERAS_JSON_H
#define G3D_CAMERAS_JSON_H

#include "gen3d/camera.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_camera_list {
    int n;
    g3d_camera *cams;    /* (n) */
    char **names;        /* (n) frame names / file paths, may hold NULLs */
    char **mask_paths;   /* (n) optional mask paths, may hold NULLs */
    char **depth_paths;  /* (n) optional ground-truth depth paths, may hold NULLs */
} g3d_camera_list;

/* Allocates n cameras with NULL names. */
g3d_status g3d_camera_list_create(g3d_camera_list *l, int n);
void g3d_camera_list_free(g3d_camera_list *l);
/* Sets entry i's name / mask path / depth path (copied; NULL clears). */
g3d_status g3d_camera_list_set_name(g3d_camera_list *l, int i, const char *name);
g3d_status g3d_camera_list_set_mask(g3d_camera_list *l, int i, const char *mask_path);
g3d_status g3d_camera_list_set_depth(g3d_camera_list *l, int i, const char *depth_path);

g3d_status g3d_cameras_json_write(const char *path, const g3d_camera_list *l);
g3d_status g3d_cameras_json_read(const char *path, g3d_camera_list *l);

/* nerfstudio transforms.json. Names become file_path; mask and depth paths become mask_path
 * and depth_file_path. */
g3d_status g3d_transforms_json_write(const char *path, const g3d_camera_list *l);
g3d_status g3d_transforms_json_read(const char *path, g3d_camera_list *l);

/* Reads either kind: a file with "transform_matrix" frames is nerfstudio's, else ours. */
g3d_status g3d_camera_list_load(const char *path, g3d_camera_list *l);

#ifdef __cplusplus
}
#endif
#endif /* G3D_CAMERAS_JSON_H */
