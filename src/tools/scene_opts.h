/* scene_opts.h - the trajectory and camera-file arguments shared by the commands that read a
 * trained scene (render, view). */
#ifndef G3D_SCENE_OPTS_H
#define G3D_SCENE_OPTS_H

#include "cli.h"
#include "gen3d/cameras_json.h"
#include "gen3d/gaussians.h"

/* 1 when a trajectory argument names a file (it contains '/', ends in .json or exists),
 * 0 when it is a preset name. */
int g3d_cli_is_file_arg(const char *arg);

/* Reads a camera file (cameras.json or transforms.json) that must hold at least one camera,
 * each with a size in 1..G3D_MAX_IMAGE_SIDE and positive focal lengths. *l is created (caller
 * frees with g3d_camera_list_free). */
g3d_status g3d_cli_load_camera_file(const char *path, g3d_camera_list *l);

/* The same, the cameras only: *cams (malloc'd, caller frees) holds *n cameras. */
g3d_status g3d_cli_load_camera_path(const char *path, g3d_camera **cams, int *n);

#endif /* G3D_SCENE_OPTS_H */
