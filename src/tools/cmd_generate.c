/* gen3d generate: one frame to a trained Gaussian-splat scene - world generation, training and
 * rendering in one run, into one output folder. */
#include "input_opts.h"
#include "world_opts.h"
#include "gen3d/cameras_json.h"
#include "gen3d/imageio.h"
#include "gen3d/init.h"
#include "gen3d/ply.h"
#include "gen3d/raster.h"
#include "gen3d/render.h"
#include "gen3d/spz.h"
#include "gen3d/train.h"

#include <cjson/cJSON.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static char g_description[4096];

static const char *description(void)
{
    int k = snprintf(g_description, sizeof g_description,
                     "Runs the whole pipeline on one RGB-D frame, or an RGB image with --depth-model (MoGe-2 or\n"
                     "metric Depth Anything V2): world generation along the trajectory (as\n"
                     "`gen3d world`), then 3D Gaussian splatting trained on the generated views and the extra\n"
                     "views' valid pixels (as `gen3d train`), then a fly-through video. Writes one folder:\n"
                     "  scene.ply        the trained Gaussians, standard 3DGS layout (any 3DGS viewer)\n"
                     "  scene.spz        the same, compressed (.spz version 2)\n"
                     "  video.mp4        a fly-through along --video-trajectory (PNG frames in frames/ when\n"
                     "                   ffmpeg is not installed); `gen3d render` renders other paths\n"
                     "  preview.png      the scene rendered from the input camera\n"
                     "  cameras.json, transforms.json  the training cameras (images under dataset/)\n"
                     "  points.ply       the aggregated coloured point cloud the Gaussians started from\n"
                     "  config.json      every setting and the seed; summary.json: timings and figures\n"
                     "  dataset/         the world-generation folder (views, depth, masks, points.ply, log)\n"
                     "A summary (timings per stage, Gaussian count, training PSNR) goes to stdout.\n\n");
    g3d_cli_world_help(g_description, k, (int)sizeof g_description);
    return g_description;
}

typedef struct generate_opts {
    g3d_cli_common common;
    g3d_cli_input in;
    g3d_cli_world wo;
    int iters, sh_degree, frames, fps, no_video;
    const char *video_trajectory;
} generate_opts;

/* The training views: every generated view whole, the extra views on their valid pixels. */
static g3d_status train_views(const g3d_world *w, g3d_train_view **out, int *n)
{
    *n = w->n_views + w->n_extra;
    g3d_train_view *v = g3d_calloc((size_t)*n, sizeof *v, "training views");
    if (!v) return G3D_ERR_NOMEM;
    for (int i = 0; i < w->n_views; i++) v[i] = (g3d_train_view){w->cams[i], &w->rgb[i], NULL};
    for (int i = 0; i < w->n_extra; i++)
        v[w->n_views + i] = (g3d_train_view){w->extra_cams[i], &w->extra_rgb[i], &w->extra_mask[i]};
    *out = v;
    return G3D_OK;
}

/* cameras.json, transforms.json and points.ply at the top of the folder (image paths under
 * dataset/), so that the folder is itself a dataset for `gen3d train` and nerfstudio tools. */
static g3d_status write_cameras(const char *tmp)
{
    char *src = g3d_path_join(tmp, "dataset/transforms.json");
    g3d_camera_list l;
    g3d_status rc = src ? g3d_camera_list_load(src, &l) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    free(src);
    if (rc != G3D_OK) return rc;
    char buf[4096];
    for (int i = 0; i < l.n && rc == G3D_OK; i++) {
        if (l.names[i]) {
            snprintf(buf, sizeof buf, "dataset/%s", l.names[i]);
            rc = g3d_camera_list_set_name(&l, i, buf);
        }
        if (rc == G3D_OK && l.mask_paths[i]) {
            snprintf(buf, sizeof buf, "dataset/%s", l.mask_paths[i]);
            rc = g3d_camera_list_set_mask(&l, i, buf);
        }
    }
    char *p;
    if (rc == G3D_OK) { p = g3d_path_join(tmp, "cameras.json"); rc = g3d_cameras_json_write(p, &l); free(p); }
    if (rc == G3D_OK) { p = g3d_path_join(tmp, "transforms.json"); rc = g3d_transforms_json_write(p, &l); free(p); }
    g3d_camera_list_free(&l);
    unsigned char *ply = NULL;
    size_t n = 0;
    if (rc == G3D_OK) { p = g3d_path_join(tmp, "dataset/points.ply"); rc = g3d_read_file(p, SIZE_MAX, &ply, &n); free(p); }
    if (rc == G3D_OK) { p = g3d_path_join(tmp, "points.ply"); rc = g3d_write_file_atomic(p, ply, n); free(p); }
    free(ply);
    return rc;
}

static g3d_status write_preview(const char *tmp, const g3d_gaussians *g, const g3d_camera *cam)
{
    g3d_raster_ws *ws;
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    g3d_image img;
    g3d_status rc = g3d_image_create(&img, cam->K.width, cam->K.height, 3);
    if (rc != G3D_OK) return rc;
    rc = g3d_raster_ws_create(&ws);
    if (rc == G3D_OK) rc = g3d_raster_fwd(ws, g, cam, &s, img.data, NULL, NULL, NULL);
    g3d_raster_ws_free(ws);
    char *p = g3d_path_join(tmp, "preview.png");
    if (rc == G3D_OK) rc = p ? g3d_image_save_png(p, &img, 8) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    free(p);
    g3d_image_free(&img);
    return rc;
}

/* The fly-through: video.mp4, or PNG frames in frames/ when ffmpeg is missing. */
static g3d_status write_video(const char *tmp, const g3d_gaussians *g, const g3d_camera *input,
                              const generate_opts *o, g3d_render_result *rr)
{
    g3d_camera *cams = NULL;
    int n = 0;
    g3d_status rc = g3d_render_flythrough(o->video_trajectory, NULL, g, input, 0, o->frames, &cams, &n);
    if (rc != G3D_OK) return rc;
    g3d_render_params ro;
    g3d_render_params_default(&ro);
    ro.progress = g3d_cli_progress();
    g3d_render_output_params out;
    g3d_render_output_params_default(&out);
    out.frames = 0;
    out.cameras = 0;
    out.video_params.fps = o->fps;
    rc = g3d_render_to_dir(g, cams, n, &ro, &out, tmp, rr);
    free(cams);
    return rc;
}

static g3d_status write_json(const char *tmp, const char *name, cJSON *o)
{
    char *text = cJSON_Print(o), *p = g3d_path_join(tmp, name);
    g3d_status rc = text && p ? g3d_write_file_atomic(p, text, strlen(text)) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    free(text);
    free(p);
    return rc;
}

static cJSON *config_json(const generate_opts *o, const g3d_frame *f)
{
    cJSON *c = cJSON_CreateObject();
    cJSON_AddStringToObject(c, "input", f->name);
    cJSON_AddNumberToObject(c, "width", f->rgb.w);
    cJSON_AddNumberToObject(c, "height", f->rgb.h);
    cJSON_AddNumberToObject(c, "fx", f->cam.K.fx);
    cJSON_AddNumberToObject(c, "fy", f->cam.K.fy);
    cJSON_AddNumberToObject(c, "cx", f->cam.K.cx);
    cJSON_AddNumberToObject(c, "cy", f->cam.K.cy);
    cJSON_AddNumberToObject(c, "seed", (double)o->common.seed);
    cJSON_AddStringToObject(c, "trajectory", o->wo.trajectory);
    cJSON_AddNumberToObject(c, "steps", o->wo.steps);
    cJSON_AddNumberToObject(c, "angle", o->wo.angle);
    cJSON_AddNumberToObject(c, "distance", o->wo.distance);
    cJSON_AddNumberToObject(c, "extra", o->wo.extra);
    cJSON_AddNumberToObject(c, "max_side", o->wo.max_side);
    cJSON_AddBoolToObject(c, "layers", !o->wo.no_layers);
    cJSON_AddStringToObject(c, "inpainter", "patchmatch");
    cJSON_AddStringToObject(c, "depth_estimator", o->in.model.estimate ? o->in.model.name : "completion");
    if (o->in.depth_model) cJSON_AddStringToObject(c, "depth_model", o->in.depth_model);
    cJSON_AddNumberToObject(c, "iterations", o->iters);
    cJSON_AddNumberToObject(c, "sh_degree", o->sh_degree);
    cJSON_AddStringToObject(c, "video_trajectory", o->video_trajectory);
    cJSON_AddNumberToObject(c, "video_frames", o->frames);
    cJSON_AddNumberToObject(c, "fps", o->fps);
    cJSON_AddBoolToObject(c, "video", !o->no_video);
    cJSON_AddNumberToObject(c, "threads", o->common.threads);
    return c;
}

static int run(int argc, char **argv)
{
    generate_opts o;
    g3d_cli_common_init(&o.common);
    g3d_cli_input_init(&o.in);
    g3d_cli_world_init(&o.wo);
    o.common.output = "scene";
    o.common.seed = 42;
    o.iters = 3000;
    o.sh_degree = 3;
    o.frames = 120;
    o.fps = 30;
    o.no_video = 0;
    o.video_trajectory = "swing";
    g3d_opt opts[] = {
        G3D_INPUT_OPTS(&o.in),
        G3D_WORLD_OPTS(&o.wo),
        {0, "iters", G3D_OPT_INT, &o.iters, "N", "training iterations"},
        {0, "sh-degree", G3D_OPT_INT, &o.sh_degree, "D", "spherical-harmonics degree of the Gaussians (0..3)"},
        {0, "video-trajectory", G3D_OPT_STRING, &o.video_trajectory, "NAME", "video camera path: swing (a loop around the input view) or a preset below"},
        {0, "frames", G3D_OPT_INT, &o.frames, "N", "video frames"},
        {0, "fps", G3D_OPT_INT, &o.fps, "N", "video frame rate"},
        {0, "no-video", G3D_OPT_FLAG, &o.no_video, NULL, "skip the fly-through video"},
        G3D_COMMON_OPTS(&o.common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts), "gen3d generate [-i RGB --depth DEPTH] [options] -o DIR",
                                  description(), pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if ((prc = g3d_cli_input_check(&o.in)) != 0) return prc;
    if ((prc = g3d_cli_world_check(&o.wo)) != 0) return prc;
    if (o.iters < 1 || o.iters > 1000000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--iters must be in 1..1000000");
    if (o.sh_degree < 0 || o.sh_degree > 3) return g3d_cli_errorf(G3D_EXIT_USAGE, "--sh-degree must be in 0..3");
    if (o.frames < 2 || o.frames > 100000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--frames must be in 2..100000");
    if (o.fps < 1 || o.fps > 240) return g3d_cli_errorf(G3D_EXIT_USAGE, "--fps must be in 1..240");
    g3d_cli_common_apply(&o.common);

    double t_start = g3d_time_now(), t_world = 0, t_train = 0, t_render = 0, t_write = 0;
    g3d_frame f;
    g3d_world w = {0};
    g3d_gaussians g = {0};
    g3d_train_view *views = NULL;
    g3d_train_result res = {0};
    int nviews = 0;
    int64_t n0 = 0;
    char *tmp = NULL;
    o.in.max_side = o.wo.max_side;
    g3d_status rc = g3d_cli_input_load(&o.in, &f);
    if (rc == G3D_OK) rc = g3d_frame_limit_size(&f, o.wo.max_side);
    if (rc != G3D_OK) g3d_cli_input_free(&o.in);
    if (rc == G3D_OK && !o.no_video) { /* an unknown video path fails now, not after training */
        g3d_camera *probe = NULL;
        int np;
        rc = g3d_render_flythrough(o.video_trajectory, NULL, NULL, &f.cam, 1.0, 2, &probe, &np);
        free(probe);
        if (rc != G3D_OK) {
            g3d_frame_free(&f);
            g3d_cli_input_free(&o.in);
        }
    }
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    /* claim the output folder first, so a bad -o fails before minutes of work */
    rc = g3d_atomic_dir_begin(o.common.output, &tmp);

    double t = g3d_time_now();
    if (rc == G3D_OK) rc = g3d_cli_world_run(&o.wo, &f, g3d_cli_input_model(&o.in), (uint64_t)o.common.seed, &w);
    t_world = g3d_time_now() - t;

    t = g3d_time_now();
    if (rc == G3D_OK) rc = train_views(&w, &views, &nviews);
    if (rc == G3D_OK) rc = g3d_gaussians_init_from_points(&g, w.cloud.xyz, w.cloud.rgb, w.cloud.n, o.sh_degree);
    if (rc == G3D_OK) {
        n0 = g.n;
        g3d_train_params tp;
        g3d_train_params_default(&tp, o.iters);
        tp.seed = (uint64_t)o.common.seed;
        tp.progress = g3d_cli_progress();
        rc = g3d_train(&g, views, nviews, &tp, &res);
    }
    t_train = g3d_time_now() - t;

    t = g3d_time_now();
    char *p;
    if (rc == G3D_OK) { p = g3d_path_join(tmp, "dataset"); rc = g3d_world_save(&w, p, (uint64_t)o.common.seed); free(p); }
    if (rc == G3D_OK) rc = write_cameras(tmp);
    if (rc == G3D_OK) { p = g3d_path_join(tmp, "scene.ply"); rc = g3d_ply_write_gaussians(p, &g); free(p); }
    if (rc == G3D_OK) { p = g3d_path_join(tmp, "scene.spz"); rc = g3d_spz_save(p, &g); free(p); }
    t_write = g3d_time_now() - t;

    t = g3d_time_now();
    g3d_render_result rr = {0};
    if (rc == G3D_OK) rc = write_preview(tmp, &g, &w.cams[0]);
    if (rc == G3D_OK && !o.no_video) rc = write_video(tmp, &g, &w.cams[0], &o, &rr);
    t_render = g3d_time_now() - t;

    if (rc == G3D_OK) {
        cJSON *c = config_json(&o, &f);
        rc = write_json(tmp, "config.json", c);
        cJSON_Delete(c);
    }
    cJSON *sum = cJSON_CreateObject();
    if (rc == G3D_OK) {
        cJSON_AddNumberToObject(sum, "points", (double)w.cloud.n);
        cJSON_AddNumberToObject(sum, "views", w.n_views);
        cJSON_AddNumberToObject(sum, "extra_views", w.n_extra);
        cJSON_AddNumberToObject(sum, "initial_gaussians", (double)n0);
        cJSON_AddNumberToObject(sum, "gaussians", (double)g.n);
        cJSON_AddNumberToObject(sum, "train_loss", res.last_loss);
        cJSON_AddNumberToObject(sum, "train_psnr_db", res.last_psnr);
        cJSON_AddNumberToObject(sum, "seconds_world", t_world);
        cJSON_AddNumberToObject(sum, "seconds_train", t_train);
        cJSON_AddBoolToObject(sum, "video", rr.video_written);
        if (rr.note) cJSON_AddStringToObject(sum, "video_note", rr.note);
        cJSON_AddNumberToObject(sum, "seconds_render", t_render);
        cJSON_AddNumberToObject(sum, "seconds_write", t_write);
        cJSON_AddNumberToObject(sum, "seconds_total", g3d_time_now() - t_start);
        rc = write_json(tmp, "summary.json", sum);
    }
    if (rc == G3D_OK) rc = g3d_atomic_dir_commit(tmp, o.common.output);
    if (rc != G3D_OK && tmp) g3d_atomic_dir_abort(tmp);
    const int64_t npoints = w.cloud.n, ngauss = g.n;
    const int nv = w.n_views, ne = w.n_extra;
    free(tmp);
    free(views);
    g3d_gaussians_free(&g);
    g3d_world_free(&w);
    g3d_frame_free(&f);
    g3d_cli_input_free(&o.in);
    if (rc != G3D_OK) {
        cJSON_Delete(sum);
        return g3d_cli_fail(rc);
    }
    /* the summary is the command's result, printed even with --quiet */
    printf("%s\n", o.common.output);
    printf("  world     %6.1f s  %lld points, %d views + %d extra\n", t_world, (long long)npoints, nv, ne);
    printf("  train     %6.1f s  %d iterations, %lld -> %lld Gaussians, PSNR %.2f dB\n", t_train, o.iters,
           (long long)n0, (long long)ngauss, res.last_psnr);
    printf("  render    %6.1f s  %s\n", t_render,
           o.no_video ? "preview" : rr.video_written ? "preview, video.mp4" : "preview, PNG frames (no video)");
    printf("  write     %6.1f s\n", t_write);
    printf("  total     %6.1f s\n", g3d_time_now() - t_start);
    cJSON_Delete(sum);
    return G3D_EXIT_OK;
}

const g3d_command g3d_cmd_generate = {"generate", "one frame to a trained Gaussian-splat scene, its video and cameras", run};
