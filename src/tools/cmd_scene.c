/* gen3d scene: renders views of the procedural ground-truth room. */
#include "cli.h"
#include "gen3d/cameras_json.h"
#include "gen3d/depthio.h"
#include "gen3d/imageio.h"
#include "gen3d/procscene.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *DESCRIPTION =
    "Renders the built-in procedural room (textured walls and floor, boxes and spheres at\n"
    "several depths, a window onto a far landscape) with a deterministic ray tracer. For each\n"
    "view it writes rgb_NNN.png, depth_NNN.png (16-bit millimetres), depth_NNN.npy (float32\n"
    "metres), ids_NNN.png (object ids), plus cameras.json and transforms.json (which name each\n"
    "view's image and depth_NNN.png, so the folder is a set of ground-truth views for gen3d eval).\n"
    "Without --pose or --cameras it renders the default camera; --arc N renders N views on an arc.\n"
    "--pose x,y,z,yaw,pitch places one camera (metres; degrees; OpenCV axes: y down, z forward).";

static g3d_status write_view(const char *dir, int i, const g3d_camera *cam, g3d_camera_list *list)
{
    g3d_image rgb, depth, ids;
    char name[64], *path;
    g3d_status rc;
    G3D_TRY(g3d_procscene_render(cam, &rgb, &depth, &ids));
    for (size_t k = 0; k < g3d_image_size(&ids); k++) ids.data[k] /= 255.0f;
    snprintf(name, sizeof name, "rgb_%03d.png", i);
    path = g3d_path_join(dir, name);
    rc = g3d_image_save_png(path, &rgb, 8);
    free(path);
    if (rc == G3D_OK) {
        snprintf(name, sizeof name, "depth_%03d.png", i);
        path = g3d_path_join(dir, name);
        rc = g3d_depth_save(path, &depth);
        free(path);
    }
    if (rc == G3D_OK) {
        snprintf(name, sizeof name, "depth_%03d.npy", i);
        path = g3d_path_join(dir, name);
        rc = g3d_depth_save(path, &depth);
        free(path);
    }
    if (rc == G3D_OK) {
        snprintf(name, sizeof name, "ids_%03d.png", i);
        path = g3d_path_join(dir, name);
        rc = g3d_image_save_png(path, &ids, 8);
        free(path);
    }
    if (rc == G3D_OK) {
        snprintf(name, sizeof name, "rgb_%03d.png", i);
        list->cams[i] = *cam;
        rc = g3d_camera_list_set_name(list, i, name);
    }
    if (rc == G3D_OK) {
        snprintf(name, sizeof name, "depth_%03d.png", i);
        rc = g3d_camera_list_set_depth(list, i, name);
    }
    g3d_image_free(&rgb);
    g3d_image_free(&depth);
    g3d_image_free(&ids);
    return rc;
}

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    int width = 512, height = 384, arc = 0;
    const char *pose = NULL, *cameras = NULL;
    g3d_cli_common_init(&common);
    common.output = "scene-views";
    g3d_opt opts[] = {
        {0, "width", G3D_OPT_INT, &width, "W", "image width in pixels"},
        {0, "height", G3D_OPT_INT, &height, "H", "image height in pixels"},
        {0, "pose", G3D_OPT_STRING, &pose, "x,y,z,yaw,pitch", "one camera: position (m) and yaw/pitch (degrees)"},
        {0, "arc", G3D_OPT_INT, &arc, "N", "N views on an arc around the default camera"},
        {0, "cameras", G3D_OPT_STRING, &cameras, "FILE", "cameras.json or transforms.json to render"},
        G3D_COMMON_OPTS(&common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts), "gen3d scene [options] -o DIR", DESCRIPTION, pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if (width < 1 || height < 1 || width > 8192 || height > 8192)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--width/--height must be in 1..8192");
    if (arc < 0 || arc > 1000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--arc must be in 0..1000");
    if ((pose != NULL) + (cameras != NULL) + (arc > 0) > 1)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "use only one of --pose, --arc and --cameras");
    g3d_cli_common_apply(&common);

    g3d_camera_list in = {0}, out = {0};
    g3d_status rc = G3D_OK;
    int n = 1;
    if (cameras) {
        if ((rc = g3d_camera_list_load(cameras, &in)) != G3D_OK) return g3d_cli_fail(rc);
        n = in.n;
        if (n == 0) { g3d_camera_list_free(&in); return g3d_cli_errorf(G3D_EXIT_FAIL, "%s: no cameras", cameras); }
    } else if (arc > 0) {
        n = arc;
    }
    g3d_camera single = g3d_procscene_default_camera(width, height);
    if (pose) {
        double x, y, z, yaw, pitch;
        char extra;
        if (sscanf(pose, "%lf,%lf,%lf,%lf,%lf%c", &x, &y, &z, &yaw, &pitch, &extra) != 5)
            return g3d_cli_errorf(G3D_EXIT_USAGE, "--pose wants x,y,z,yaw,pitch (five numbers), got '%s'", pose);
        /* Yaw about the world's up axis (-y), then pitch about the camera's x axis. */
        g3d_mat4 r = g3d_mat4_mul(g3d_mat4_rotation(g3d_v3(0, -1, 0), yaw * M_PI / 180),
                                  g3d_mat4_rotation(g3d_v3(1, 0, 0), -pitch * M_PI / 180));
        r.m[0][3] = x; r.m[1][3] = y; r.m[2][3] = z;
        single.c2w = r;
    }

    char *tmp = NULL;
    if ((rc = g3d_camera_list_create(&out, n)) == G3D_OK && (rc = g3d_atomic_dir_begin(common.output, &tmp)) == G3D_OK) {
        g3d_progress prog = g3d_cli_progress();
        for (int i = 0; i < n && rc == G3D_OK; i++) {
            g3d_camera cam = cameras ? in.cams[i] : arc ? g3d_procscene_arc_camera(i, n, width, height) : single;
            rc = write_view(tmp, i, &cam, &out);
            g3d_progress_report(&prog, "render", i + 1, n, NULL);
        }
        char *p;
        if (rc == G3D_OK) { p = g3d_path_join(tmp, "cameras.json"); rc = g3d_cameras_json_write(p, &out); free(p); }
        if (rc == G3D_OK) { p = g3d_path_join(tmp, "transforms.json"); rc = g3d_transforms_json_write(p, &out); free(p); }
        if (rc == G3D_OK) rc = g3d_atomic_dir_commit(tmp, common.output);
        if (rc != G3D_OK) g3d_atomic_dir_abort(tmp);
    }
    free(tmp);
    g3d_camera_list_free(&in);
    g3d_camera_list_free(&out);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s\n", common.output);
    return G3D_EXIT_OK;
}

const g3d_command g3d_cmd_scene = {"scene", "render views of the procedural ground-truth room", run};
