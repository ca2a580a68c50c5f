/* gen3d render: a Gaussian scene rendered along a camera path to frames, depth and a video. */
#include "cli.h"
#include "gen3d/explore.h"
#include "gen3d/trajectory.h"
#include "gen3d/render.h"
#include "gen3d/worldscore.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static char g_description[4096];

static const char *description(void)
{
    int k = snprintf(g_description, sizeof g_description,
        "Renders a 3D Gaussian-splat scene (.ply in the standard 3DGS layout, or .spz) along a camera\n"
        "path. --trajectory is either a camera file - transforms.json (nerfstudio) or cameras.json,\n"
        "rendered frame by frame with each frame's own intrinsics and image size - or a preset name;\n"
        "a preset starts at the identity pose (the scene's input camera) with the intrinsics given by\n"
        "--width/--height/--fov, moves by the scene's median depth (or --scale), and --frames\n"
        "resamples it to that many smoothly interpolated frames. Writes one folder:\n"
        "  frames/00000.png ...  8-bit RGB frames\n"
        "  video.mp4             H.264 at --fps (needs the ffmpeg program and one image size for\n"
        "                        all frames; otherwise a warning says why and only frames are written)\n"
        "  depth/00000.png ...   with --depth: 16-bit depth in millimetres, 0 where nothing was hit\n"
        "  cameras.json          the cameras of the frames (OpenCV axes, camera-to-world)\n"
        "--coverage measures instead of writing: for each camera, the fraction of empty pixels\n"
        "(accumulated opacity below 0.5, where the scene shows the background) goes to stdout,\n"
        "then their mean and the worst; nothing is written.\n"
        "Presets:\n"
        "  %-12s a closed loop sliding sideways and pushing in while aiming at the scene's centre\n"
        "  %-12s the exploration set: 27 cameras stepping sideways (+-d), up and down (+-d/2) and\n"
        "               forward (0..2d), turned by up to --explore-angle in yaw and pitch (d: --distance,\n"
        "               0: a quarter of the scene scale)\n",
        "swing", "explore");
    for (const char *const *n = g3d_trajectory_names(); *n && k > 0 && k < (int)sizeof g_description; n++)
        k += snprintf(g_description + k, sizeof g_description - (size_t)k, "  %-12s %s\n", *n,
                      g3d_trajectory_describe(*n));
    if (k > 0 && k < (int)sizeof g_description)
        snprintf(g_description + k, sizeof g_description - (size_t)k,
                 "Benchmark paths:\n"
                 "  worldscore:MOVE[,MOVE...]  WorldScore's static-track path: the WorldScore moves above chained,\n"
                 "               1 + 49 frames per move at 512x512 with focal 500, camera speed --distance (0: a\n"
                 "               quarter of the scene scale); also writes WorldScore's camera_data.json\n");
    return g_description;
}

/* "r,g,b" with components in [0, 1]. */
static int parse_rgb(const char *s, float out[3])
{
    char *end;
    for (int i = 0; i < 3; i++) {
        double v = strtod(s, &end);
        if (end == s || !(v >= 0.0 && v <= 1.0)) return 0;
        out[i] = (float)v;
        s = end;
        if (i < 2) {
            if (*s != ',') return 0;
            s++;
        }
    }
    return *s == '\0';
}

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    g3d_cli_common_init(&common);
    common.output = "render";
    const char *scene = NULL, *trajectory = "swing", *background = "0,0,0";
    int width = 512, height = 384, fps = 30, crf = 18, frames = 0, depth = 0, no_video = 0, sh_degree = -1, coverage = 0;
    double fov = 60.0, scale = 0.0, ws_speed = 0.0;
    g3d_explore_params ep;
    g3d_explore_params_default(&ep);
    g3d_trajectory_params tp;
    g3d_trajectory_params_default(&tp);
    g3d_opt opts[] = {
        {0, "scene", G3D_OPT_STRING, &scene, "FILE", "scene to render (.ply 3DGS layout or .spz)"},
        {0, "trajectory", G3D_OPT_STRING, &trajectory, "NAME|FILE", "preset name, worldscore:MOVE[,MOVE...], or transforms.json / cameras.json"},
        {0, "width", G3D_OPT_INT, &width, "W", "image width for presets, pixels"},
        {0, "height", G3D_OPT_INT, &height, "H", "image height for presets, pixels"},
        {0, "fov", G3D_OPT_DOUBLE, &fov, "DEG", "horizontal field of view for presets, degrees"},
        {0, "frames", G3D_OPT_INT, &frames, "N", "resample a preset to N smooth frames (0: the preset's own poses)"},
        {0, "scale", G3D_OPT_DOUBLE, &scale, "M", "scene scale for moving presets, metres (0: median depth)"},
        {0, "steps", G3D_OPT_INT, &tp.steps, "N", "rotate: poses after the input (0: 8)"},
        {0, "angle", G3D_OPT_DOUBLE, &tp.angle_deg, "DEG", "rotate: total yaw (0: 60)"},
        {0, "distance", G3D_OPT_DOUBLE, &tp.distance, "M", "moving presets: distance (0: a quarter of the scene scale)"},
        {0, "fps", G3D_OPT_INT, &fps, "N", "video frame rate"},
        {0, "crf", G3D_OPT_INT, &crf, "N", "video quality, x264 CRF (0 lossless .. 51; lower is better)"},
        {0, "sh-degree", G3D_OPT_INT, &sh_degree, "D", "SH degree to evaluate (-1: the scene's)"},
        {0, "background", G3D_OPT_STRING, &background, "R,G,B", "background colour, components in [0, 1]"},
        {0, "depth", G3D_OPT_FLAG, &depth, NULL, "also write 16-bit depth frames (millimetres)"},
        {0, "no-video", G3D_OPT_FLAG, &no_video, NULL, "write PNG frames only"},
        {0, "explore-angle", G3D_OPT_DOUBLE, &ep.angle_deg, "DEG", "explore: yaw and pitch reach, degrees (0..90)"},
        {0, "coverage", G3D_OPT_FLAG, &coverage, NULL, "print each camera's empty-pixel fraction instead of writing frames"},
        G3D_COMMON_OPTS(&common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts),
                                  "gen3d render --scene FILE [--trajectory NAME|FILE] [options] -o DIR", description(), pos,
                                  0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    float bg[3];
    if (!scene) return g3d_cli_errorf(G3D_EXIT_USAGE, "render needs --scene FILE");
    if (width < 1 || height < 1 || width > G3D_MAX_IMAGE_SIDE || height > G3D_MAX_IMAGE_SIDE)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--width and --height must be in 1..%d", G3D_MAX_IMAGE_SIDE);
    if (!(fov > 1.0 && fov < 179.0)) return g3d_cli_errorf(G3D_EXIT_USAGE, "--fov must be in 1..179 degrees");
    if (frames < 0 || frames > 100000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--frames must be in 0..100000");
    if (!(scale >= 0.0)) return g3d_cli_errorf(G3D_EXIT_USAGE, "--scale must be >= 0");
    if (tp.steps < 0 || tp.steps > 10000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--steps must be in 0..10000");
    if (!(fabs(tp.angle_deg) <= 3600.0)) return g3d_cli_errorf(G3D_EXIT_USAGE, "--angle must be in -3600..3600");
    if (!(tp.distance >= 0.0)) return g3d_cli_errorf(G3D_EXIT_USAGE, "--distance must be >= 0");
    if (fps < 1 || fps > 240) return g3d_cli_errorf(G3D_EXIT_USAGE, "--fps must be in 1..240");
    if (crf < 0 || crf > 51) return g3d_cli_errorf(G3D_EXIT_USAGE, "--crf must be in 0..51");
    if (sh_degree < -1 || sh_degree > G3D_SH_MAX_DEGREE) return g3d_cli_errorf(G3D_EXIT_USAGE, "--sh-degree must be in -1..3");
    if (!parse_rgb(background, bg))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--background must be R,G,B with components in [0, 1], got '%s'", background);
    if (!(ep.angle_deg >= 0 && ep.angle_deg < 90))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--explore-angle must be at least 0 and below 90 degrees");
    const int worldscore = !strncmp(trajectory, "worldscore:", 11), explore = !strcmp(trajectory, "explore");
    const int from_file = !worldscore && g3d_trajectory_is_file(trajectory);
    if (explore && frames > 0) return g3d_cli_errorf(G3D_EXIT_USAGE, "--frames does not apply to the exploration set");
    if (from_file && frames > 0)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--frames resamples presets; a trajectory file is rendered as given");
    if (worldscore && (frames > 0 || width != 512 || height != 384 || fov != 60.0))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "a worldscore: path has the benchmark's frame count and 512x512 camera "
                                              "with focal 500; --frames, --width, --height and --fov do not apply");
    g3d_cli_common_apply(&common);

    g3d_gaussians g = {0};
    g3d_camera *cams = NULL;
    int n = 0;
    char *tmp = NULL;
    g3d_status rc = g3d_gaussians_load(scene, &g);
    if (rc == G3D_OK && sh_degree > g.sh_degree)
        rc = G3D_ERR(G3D_ERR_ARG, "%s: --sh-degree %d asked for, the scene has SH degree %d", scene, sh_degree, g.sh_degree);
    if (rc == G3D_OK) {
        if (from_file) {
            rc = g3d_trajectory_load(trajectory, &cams, &n);
        } else if (worldscore) {
            g3d_camera input = {g3d_worldscore_intrinsics(), g3d_mat4_identity()};
            if (!(tp.distance > 0) && !(scale > 0)) rc = g3d_render_scene_scale(&g, &input, &scale);
            ws_speed = tp.distance > 0 ? tp.distance : 0.25 * scale;
            if (rc == G3D_OK) rc = g3d_worldscore_path(trajectory + 11, ws_speed, &cams, &n);
        } else if (explore) {
            g3d_camera input = {g3d_intrinsics_from_fov(fov, width, height), g3d_mat4_identity()};
            if (!(scale > 0)) rc = g3d_render_scene_scale(&g, &input, &scale);
            ep.distance = tp.distance;
            if (rc == G3D_OK) rc = g3d_explore_cameras(&input, scale, &ep, &cams, NULL);
            n = G3D_EXPLORE_CAMERAS;
        } else {
            g3d_camera input;
            input.K = g3d_intrinsics_from_fov(fov, width, height);
            input.c2w = g3d_mat4_identity();
            rc = g3d_render_flythrough(trajectory, &tp, &g, &input, scale, frames, &cams, &n);
        }
    }
    if (coverage) {
        double *empty = rc == G3D_OK ? g3d_calloc((size_t)n, sizeof *empty, "coverage") : NULL;
        if (rc == G3D_OK && !empty) rc = G3D_ERR_NOMEM;
        if (rc == G3D_OK) rc = g3d_explore_coverage(&g, cams, n, empty, NULL, 0, 0);
        free(cams);
        g3d_gaussians_free(&g);
        if (rc != G3D_OK) {
            free(empty);
            return g3d_cli_fail(rc);
        }
        double mean = 0, worst = 0;
        for (int i = 0; i < n; i++) {
            printf("camera %d: %.4f %% empty\n", i, 100 * empty[i]);
            mean += empty[i] / n;
            worst = empty[i] > worst ? empty[i] : worst;
        }
        printf("mean %.4f %% empty, worst %.4f %%, over %d cameras\n", 100 * mean, 100 * worst, n);
        free(empty);
        return G3D_EXIT_OK;
    }
    if (rc == G3D_OK) rc = g3d_atomic_dir_begin(common.output, &tmp);
    g3d_render_params p;
    g3d_render_params_default(&p);
    memcpy(p.background, bg, sizeof bg);
    p.sh_degree = sh_degree;
    p.depth = depth;
    p.progress = g3d_cli_progress();
    g3d_render_output_params o;
    g3d_render_output_params_default(&o);
    o.video = !no_video;
    o.video_params.fps = fps;
    o.video_params.crf = crf;
    g3d_render_result res = {0};
    double t0 = g3d_time_now();
    if (rc == G3D_OK) rc = g3d_render_to_dir(&g, cams, n, &p, &o, tmp, &res);
    if (rc == G3D_OK && worldscore) {
        char *cd = g3d_path_join(tmp, "camera_data.json");
        rc = cd ? g3d_worldscore_write_camera_data(cd, cams, n, ws_speed) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        free(cd);
    }
    if (rc == G3D_OK) rc = g3d_atomic_dir_commit(tmp, common.output);
    if (rc != G3D_OK && tmp) g3d_atomic_dir_abort(tmp);
    free(tmp);
    if (rc == G3D_OK)
        g3d_log(G3D_LOG_INFO, "render: %d frames (first %dx%d) in %.1f s%s", n, cams[0].K.width, cams[0].K.height,
                g3d_time_now() - t0, res.video_written ? ", video.mp4" : "");
    free(cams);
    g3d_gaussians_free(&g);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s\n", common.output);
    return G3D_EXIT_OK;
}

const g3d_command g3d_cmd_render = {"render", "render a Gaussian scene along a camera path to frames, depth and a video", run};
