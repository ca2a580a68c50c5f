/* gen3d prepare: builds the input frame (RGB + metric depth + camera) and saves it. */
#include "cli.h"
#include "gen3d/frame.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *DESCRIPTION =
    "Builds the pipeline's input frame and writes it as a folder: rgb.png, depth.png (16-bit\n"
    "millimetres), depth.npy (metres), cameras.json, points.ply (the lifted coloured point cloud)\n"
    "and, for the default input, heldout.png (the real second view).\n"
    "Without -i it uses the built-in default input, Middlebury 2014 \"Motorcycle\" (fetched into\n"
    "cache/default-input by scripts/fetch-default-input.sh; --default-input DIR to use another copy).\n"
    "With -i RGB --depth DEPTH it reads an RGB-D pair; give the camera as --fx/--fy/--cx/--cy or\n"
    "--fov (horizontal, degrees); without either a 60 degree field of view is assumed.";

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    const char *rgb = NULL, *depth = NULL, *def_dir = "cache/default-input";
    double scale = 1000, fx = 0, fy = 0, cx = -1, cy = -1, fov = 0;
    g3d_cli_common_init(&common);
    common.output = "frame";
    g3d_opt opts[] = {
        {'i', "input", G3D_OPT_STRING, &rgb, "RGB", "colour image (PNG or JPEG)"},
        {0, "depth", G3D_OPT_STRING, &depth, "DEPTH", "depth map (.png .pfm .npy .npz)"},
        {0, "depth-scale", G3D_OPT_DOUBLE, &scale, "S", "16-bit PNG / integer depth units per metre (1000 mm, 5000 TUM)"},
        {0, "fx", G3D_OPT_DOUBLE, &fx, "PX", "focal length x in pixels"},
        {0, "fy", G3D_OPT_DOUBLE, &fy, "PX", "focal length y in pixels (default: fx)"},
        {0, "cx", G3D_OPT_DOUBLE, &cx, "PX", "principal point x (default: image centre)"},
        {0, "cy", G3D_OPT_DOUBLE, &cy, "PX", "principal point y (default: image centre)"},
        {0, "fov", G3D_OPT_DOUBLE, &fov, "DEG", "horizontal field of view instead of --fx"},
        {0, "default-input", G3D_OPT_STRING, &def_dir, "DIR", "folder of the default input"},
        G3D_COMMON_OPTS(&common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts), "gen3d prepare [-i RGB --depth DEPTH] [options] -o DIR",
                                  DESCRIPTION, pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if ((rgb == NULL) != (depth == NULL)) return g3d_cli_errorf(G3D_EXIT_USAGE, "-i and --depth go together");
    if (fx < 0 || fy < 0 || fov < 0 || fov >= 180 || !(scale > 0))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "focal lengths and scale must be positive, --fov below 180");
    if (fx > 0 && fov > 0) return g3d_cli_errorf(G3D_EXIT_USAGE, "give --fx or --fov, not both");
    g3d_cli_common_apply(&common);

    g3d_frame f;
    g3d_status rc;
    if (rgb) {
        g3d_intrinsics K = {0};
        K.fx = fx;
        K.fy = fy > 0 ? fy : fx;
        K.cx = cx;
        K.cy = cy;
        rc = g3d_frame_load_rgbd(rgb, depth, scale, K, &f);
        if (rc == G3D_OK && (fov > 0 || fx > 0)) {
            /* Fill what was left to defaults now that the image size is known. */
            g3d_intrinsics d = g3d_intrinsics_from_fov(fov > 0 ? fov : 60, f.rgb.w, f.rgb.h);
            if (fx > 0) { d.fx = fx; d.fy = fy > 0 ? fy : fx; }
            if (cx >= 0) d.cx = cx;
            if (cy >= 0) d.cy = cy;
            f.cam.K = d;
        }
    } else {
        rc = g3d_frame_load_middlebury(def_dir, &f);
        if (rc != G3D_OK) g3d_error_prefix("default input (run scripts/fetch-default-input.sh)");
    }
    if (rc != G3D_OK) return g3d_cli_fail(rc);

    size_t valid = 0, n = g3d_image_size(&f.depth);
    double lo = 1e30, hi = 0;
    for (size_t i = 0; i < n; i++)
        if (f.depth.data[i] > 0) { valid++; lo = f.depth.data[i] < lo ? f.depth.data[i] : lo; hi = f.depth.data[i] > hi ? f.depth.data[i] : hi; }
    g3d_log(G3D_LOG_INFO, "input %s: %dx%d, fx %.1f fy %.1f cx %.1f cy %.1f (horizontal fov %.1f deg)", f.name, f.rgb.w,
            f.rgb.h, f.cam.K.fx, f.cam.K.fy, f.cam.K.cx, f.cam.K.cy, g3d_intrinsics_fov_x_deg(f.cam.K));
    g3d_log(G3D_LOG_INFO, "depth %.3f .. %.3f m, %.1f %% of pixels valid%s", lo, hi, 100.0 * valid / n,
            f.heldout.data ? "; a real held-out view is included" : "");
    rc = g3d_frame_save(&f, common.output);
    g3d_frame_free(&f);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s\n", common.output);
    return G3D_EXIT_OK;
}

const g3d_command g3d_cmd_prepare = {"prepare", "build the input frame (RGB, metric depth, camera) and its point cloud", run};
