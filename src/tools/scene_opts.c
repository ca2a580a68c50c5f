/* scene_opts.c - reading the trajectory and camera files given on the command line. */
#include "scene_opts.h"

#include <string.h>
#include <sys/stat.h>

int g3d_cli_is_file_arg(const char *s)
{
    char ext[16];
    struct stat st;
    return strchr(s, '/') || !strcmp(g3d_path_ext(s, ext, sizeof ext), "json") || stat(s, &st) == 0;
}

g3d_status g3d_cli_load_camera_file(const char *path, g3d_camera_list *l)
{
    G3D_TRY(g3d_camera_list_load(path, l));
    g3d_status rc = G3D_OK;
    if (l->n < 1) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: the camera list is empty", path);
    for (int i = 0; i < l->n && rc == G3D_OK; i++) {
        const g3d_intrinsics K = l->cams[i].K;
        if (K.width < 1 || K.height < 1 || K.width > G3D_MAX_IMAGE_SIDE || K.height > G3D_MAX_IMAGE_SIDE)
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d: image size %dx%d out of range 1..%d", path, i, K.width,
                         K.height, G3D_MAX_IMAGE_SIDE);
        else if (!(K.fx > 0 && K.fy > 0))
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d: focal lengths must be positive", path, i);
    }
    if (rc != G3D_OK) g3d_camera_list_free(l);
    return rc;
}

g3d_status g3d_cli_load_camera_path(const char *path, g3d_camera **cams, int *n)
{
    g3d_camera_list l;
    G3D_TRY(g3d_cli_load_camera_file(path, &l));
    *cams = l.cams;  /* taken over from the list */
    *n = l.n;
    l.cams = NULL;
    g3d_camera_list_free(&l);
    return G3D_OK;
}
