/* gen3d world: layered point-cloud expansion along a camera trajectory. */
#include "input_opts.h"
#include "gen3d/cameras_json.h"
#include "gen3d/depth_complete.h"
#include "gen3d/inpaint_classic.h"
#include "gen3d/trajectory.h"
#include "gen3d/world.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static char g_description[4096];

static const char *description(void)
{
    int k = snprintf(g_description, sizeof g_description,
                     "Builds a multi-view-consistent point cloud from one RGB-D frame: the input is split into\n"
                     "foreground and background layers, then at every pose of the trajectory the cloud is\n"
                     "rendered, its holes inpainted, their depth estimated and aligned to the cloud along the\n"
                     "camera rays, and the new pixels lifted. M extra views around the poses are rendered from\n"
                     "the final cloud with validity masks. Writes a dataset folder (views, depth, extra views and\n"
                     "masks, layers, cameras.json, transforms.json, points.ply, log.json) for `gen3d train`.\n"
                     "Without model weights the classical PatchMatch inpainter and depth completion are used.\n\n"
                     "Trajectories (--trajectory NAME, or a cameras.json / transforms.json file of poses in the\n"
                     "input camera's frame; moving presets scale with the median depth unless --distance is given):\n");
    for (const char *const *n = g3d_trajectory_names(); *n && k < (int)sizeof g_description; n++)
        k += snprintf(g_description + k, sizeof g_description - k, "  %-12s %s\n", *n, g3d_trajectory_describe(*n));
    return g_description;
}

/* Resamples poses to n_out evenly spaced ones (first and last kept). */
static g3d_mat4 *resample(const g3d_mat4 *p, int n, int n_out)
{
    g3d_mat4 *o = malloc(sizeof(g3d_mat4) * (size_t)n_out);
    if (!o) return NULL;
    for (int i = 0; i < n_out; i++) o[i] = p[n_out > 1 ? (int)lround((double)i * (n - 1) / (n_out - 1)) : 0];
    return o;
}

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    g3d_cli_input in;
    const char *trajectory = "rotate";
    int steps = 0, extra = 10, max_side = 512, no_layers = 0;
    double angle = 0, distance = 0;
    g3d_cli_common_init(&common);
    g3d_cli_input_init(&in);
    common.output = "world";
    g3d_opt opts[] = {
        G3D_INPUT_OPTS(&in),
        {0, "trajectory", G3D_OPT_STRING, &trajectory, "NAME|FILE", "camera path preset or pose file"},
        {0, "steps", G3D_OPT_INT, &steps, "N", "generation steps after the input (0: the preset's own count)"},
        {0, "angle", G3D_OPT_DOUBLE, &angle, "DEG", "rotate: total yaw (0: 60 degrees)"},
        {0, "distance", G3D_OPT_DOUBLE, &distance, "M", "moving presets: distance in metres (0: a quarter of the median depth)"},
        {0, "extra", G3D_OPT_INT, &extra, "M", "extra training views rendered from the final cloud"},
        {0, "max-side", G3D_OPT_INT, &max_side, "PX", "downscale the input so that its longer side is at most this"},
        {0, "no-layers", G3D_OPT_FLAG, &no_layers, NULL, "skip the foreground/background split"},
        G3D_COMMON_OPTS(&common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts), "gen3d world [-i RGB --depth DEPTH] [options] -o DIR",
                                  description(), pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if ((prc = g3d_cli_input_check(&in)) != 0) return prc;
    if (steps < 0 || steps > 1000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--steps must be in 0..1000");
    if (extra < 0 || extra > 1000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--extra must be in 0..1000");
    if (max_side < 16 || max_side > G3D_MAX_IMAGE_SIDE) return g3d_cli_errorf(G3D_EXIT_USAGE, "--max-side must be in 16..%d", G3D_MAX_IMAGE_SIDE);
    if (distance < 0 || fabs(angle) > 360) return g3d_cli_errorf(G3D_EXIT_USAGE, "--distance must be >= 0 and --angle within a full turn");
    g3d_cli_common_apply(&common);

    g3d_frame f;
    g3d_status rc = g3d_cli_input_load(&in, &f);
    if (rc == G3D_OK) rc = g3d_frame_limit_size(&f, max_side);
    if (rc != G3D_OK) return g3d_cli_fail(rc);

    /* Poses: a file if one exists under that name, else a preset. */
    g3d_mat4 *poses = NULL;
    int n = 0;
    struct stat st;
    if (stat(trajectory, &st) == 0) {
        g3d_camera_list l;
        rc = g3d_camera_list_load(trajectory, &l);
        if (rc == G3D_OK && l.n == 0) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: no poses", trajectory);
        if (rc == G3D_OK && !(poses = malloc(sizeof(g3d_mat4) * (size_t)l.n))) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        if (rc == G3D_OK) { n = l.n; for (int i = 0; i < n; i++) poses[i] = l.cams[i].c2w; }
        g3d_camera_list_free(&l);
    } else {
        g3d_trajectory_params tp = g3d_trajectory_params_default();
        tp.steps = !strcmp(trajectory, "rotate") ? steps : 0;
        tp.angle_deg = angle;
        tp.distance = distance;
        rc = g3d_trajectory_make(trajectory, &tp, g3d_depth_median(&f.depth), &poses, &n);
    }
    if (rc == G3D_OK && steps > 0 && steps + 1 != n) {
        g3d_mat4 *r = resample(poses, n, steps + 1);
        if (!r) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        else { free(poses); poses = r; n = steps + 1; }
    }
    if (rc != G3D_OK) { g3d_frame_free(&f); free(poses); return g3d_cli_fail(rc); }

    g3d_inpainter ip = {0};
    g3d_mask_provider mp = {0};
    g3d_depth_estimator de = g3d_depth_estimator_completion();
    g3d_world w;
    g3d_world_params wp = g3d_world_params_default();
    wp.extra_views = extra;
    wp.progress = g3d_cli_progress();
    rc = g3d_inpainter_classic_create(NULL, &ip);
    if (rc == G3D_OK && !no_layers) rc = g3d_mask_provider_regions(NULL, f.cam.K, &mp);
    g3d_log(G3D_LOG_INFO, "world: %s, %dx%d, %d poses (%s), %d extra views", f.name, f.rgb.w, f.rgb.h, n, trajectory, extra);
    double t0 = g3d_time_now();
    if (rc == G3D_OK) rc = g3d_world_generate(&f, poses, n, &ip, &de, no_layers ? NULL : &mp, &wp, (uint64_t)common.seed, &w);
    if (rc == G3D_OK) {
        rc = g3d_world_save(&w, common.output, (uint64_t)common.seed);
        g3d_log(G3D_LOG_INFO, "world: %lld points, %d views + %d extra, %d foreground objects, %.1f s", (long long)w.cloud.n,
                w.n_views, w.n_extra, w.layers.n_foreground, g3d_time_now() - t0);
        g3d_world_free(&w);
    }
    if (ip.free) ip.free(ip.ctx);
    if (mp.free) mp.free(mp.ctx);
    free(poses);
    g3d_frame_free(&f);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s\n", common.output);
    return G3D_EXIT_OK;
}

const g3d_command g3d_cmd_world = {"world", "grow a point cloud of the scene along a camera trajectory", run};
