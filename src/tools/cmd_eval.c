/* gen3d eval: a scene scored against ground-truth views (PSNR, SSIM, depth error), with the
 * baselines that tell whether it helps. */
#include "cli.h"
#include "gen3d/eval.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *DESCRIPTION =
    "Renders the scene at every ground-truth view (each with its own intrinsics and image size) and\n"
    "scores it: PSNR, SSIM (11x11 Gaussian window, sigma 1.5, as scikit-image and pytorch-msssim)\n"
    "and, where the views give depth, depth abs rel and RMSE - on all pixels and on the co-visible\n"
    "pixels, those whose ground truth the input camera sees too (from depth when known, else where\n"
    "the scene has alpha >= 0.5). Renders are rounded to 8 bits first, as saved frames would be.\n"
    "--views is a transforms.json / cameras.json (images; optional depth_file_path / depth_path and\n"
    "mask_path, relative to the file), a folder holding one, or a Middlebury stereo folder (calib.txt,\n"
    "im0.png, im1.png, disp0.pfm, optional disp1.pfm; or the default input from\n"
    "scripts/fetch-default-input.sh), whose left view is the input and right view is scored.\n"
    "When the input view is known (--input-view; by default the frame at the identity pose), two\n"
    "baselines are scored in the same report: the input image taken as the view, and a nearest,\n"
    "z-buffered forward warp of the input with its depth. --input-only scores just these.\n"
    "Writes DIR/eval.json (per view and mean; infinite PSNR is the string \"inf\", undefined metrics\n"
    "null) and DIR/sheets/NNN_<view>.png (per method: ground truth | prediction | error heat map).";

/* "auto", "none" or a frame index. */
static int parse_input_view(const char *s, int *out)
{
    if (!strcmp(s, "auto")) *out = -1;
    else if (!strcmp(s, "none")) *out = -2;
    else {
        char *end;
        long v = strtol(s, &end, 10);
        if (end == s || *end || v < 0 || v > 1000000) return 0;
        *out = (int)v;
    }
    return 1;
}

static void print_metrics(const char *label, const g3d_eval_metrics *m)
{
    if (!m->pixels) {
        printf("  %-13s -\n", label);
        return;
    }
    printf("  %-13s PSNR %6.2f dB  SSIM %.4f", label, m->psnr, m->ssim);
    if (!isnan(m->depth_abs_rel)) printf("  depth abs rel %.4f  RMSE %.4f m", m->depth_abs_rel, m->depth_rmse);
    printf("\n");
}

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    g3d_cli_common_init(&common);
    common.output = "eval";
    const char *scene = NULL, *views = NULL, *input_view = "auto";
    int input_only = 0, max_side = 0;
    g3d_opt opts[] = {
        {0, "scene", G3D_OPT_STRING, &scene, "FILE", "scene to score (.ply 3DGS layout or .spz)"},
        {0, "views", G3D_OPT_STRING, &views, "PATH", "ground-truth views: transforms.json, cameras.json or a Middlebury folder"},
        {0, "input-only", G3D_OPT_FLAG, &input_only, NULL, "score only the baselines made from the input view (no --scene)"},
        {0, "input-view", G3D_OPT_STRING, &input_view, "auto|none|N", "the input frame of a camera file (auto: the identity pose)"},
        {0, "max-side", G3D_OPT_INT, &max_side, "N", "downscale views to this longer side first (0: as given)"},
        G3D_COMMON_OPTS(&common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts),
                                  "gen3d eval (--scene FILE | --input-only) --views PATH [options] -o DIR", DESCRIPTION, pos, 0,
                                  &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    g3d_eval_views_params vp;
    g3d_eval_views_params_default(&vp);
    if (!views) return g3d_cli_errorf(G3D_EXIT_USAGE, "eval needs --views PATH");
    if (!scene && !input_only) return g3d_cli_errorf(G3D_EXIT_USAGE, "eval needs --scene FILE (or --input-only)");
    if (scene && input_only) return g3d_cli_errorf(G3D_EXIT_USAGE, "--input-only scores the baselines alone; drop --scene");
    if (!parse_input_view(input_view, &vp.input_view))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--input-view must be auto, none or a frame index, got '%s'", input_view);
    if (max_side != 0 && (max_side < 16 || max_side > G3D_MAX_IMAGE_SIDE))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--max-side must be 0 or in 16..%d", G3D_MAX_IMAGE_SIDE);
    vp.max_side = max_side;
    g3d_cli_common_apply(&common);

    g3d_gaussians g = {0};
    g3d_eval_views v = {0};
    g3d_eval_report r = {0};
    g3d_status rc = scene ? g3d_gaussians_load(scene, &g) : G3D_OK;
    if (rc == G3D_OK) rc = g3d_eval_views_load(views, &vp, &v);
    if (rc == G3D_OK && input_only && !v.input.rgb.data)
        rc = G3D_ERR(G3D_ERR_ARG, "%s: no input view for the baselines (name it with --input-view N)", views);
    g3d_eval_params p;
    g3d_eval_params_default(&p);
    p.progress = g3d_cli_progress();
    double t0 = g3d_time_now();
    if (rc == G3D_OK) rc = g3d_eval_to_dir(scene ? &g : NULL, &v, &p, common.output, scene, views, &r);
    if (rc == G3D_OK) {
        g3d_log(G3D_LOG_INFO, "eval: %d view%s in %.1f s", v.n, v.n == 1 ? "" : "s", g3d_time_now() - t0);
        printf("%s\n", common.output);
        printf("mean over %d view%s, all pixels:\n", v.n, v.n == 1 ? "" : "s");
        for (int m = 0; m < G3D_EVAL_METHODS; m++)
            if (r.scored[m]) print_metrics(g3d_eval_method_name(m), &r.mean_all[m]);
        printf("co-visible pixels:\n");
        for (int m = 0; m < G3D_EVAL_METHODS; m++)
            if (r.scored[m]) print_metrics(g3d_eval_method_name(m), &r.mean_covisible[m]);
    }
    g3d_eval_report_free(&r);
    g3d_eval_views_free(&v);
    g3d_gaussians_free(&g);
    return rc == G3D_OK ? G3D_EXIT_OK : g3d_cli_fail(rc);
}

const g3d_command g3d_cmd_eval = {"eval", "score a scene against ground-truth views (PSNR, SSIM, depth error)", run};
