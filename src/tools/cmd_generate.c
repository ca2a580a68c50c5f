/* gen3d generate: the options of the whole pipeline, handed to g3d_generate (generate.h). */
#include "generate_opts.h"

#include <stdint.h>
#include <stdio.h>

static char g_description[8192];

static const char *description(void)
{
    int k = snprintf(g_description, sizeof g_description,
                     "Runs the whole pipeline on one RGB-D frame, an RGB image with --depth-model (MoGe-2 or\n"
                     "metric Depth Anything V2), or a text prompt (-p PROMPT --sd-model MODEL --depth-model\n"
                     "MOGE2: Stable Diffusion draws the first image, MoGe-2 gives its depth and camera):\n"
                     "world generation along the trajectory (as\n"
                     "`gen3d world`), then 3D Gaussian splatting trained on the generated views and the extra\n"
                     "views' valid pixels (as `gen3d train`), then a fly-through video. Writes one folder:\n"
                     "  scene.ply        the trained Gaussians, standard 3DGS layout (any 3DGS viewer)\n"
                     "  scene.spz        the same, compressed (.spz version 2)\n"
                     "  viewer.html      the scene in a web page to explore (when the viewer is built)\n"
                     "  video.mp4        a fly-through along --video-trajectory (PNG frames in frames/ when\n"
                     "                   ffmpeg is not installed); `gen3d render` renders other paths\n"
                     "  preview.png      the scene rendered from the input camera\n"
                     "  cameras.json, transforms.json  the training cameras (images under dataset/)\n"
                     "  points.ply       the aggregated coloured point cloud the Gaussians started from\n"
                     "  config.json      every setting and the seed; summary.json: timings and figures\n"
                     "  exploration.png  the scene from 27 cameras a visitor reaches around the input view\n"
                     "                   (sideways, up/down and forward steps, turns), empty pixels in magenta;\n"
                     "                   their cameras in exploration_cameras.json, the empty fractions in\n"
                     "                   summary.json\n"
                     "  dataset/         the world-generation folder (views, depth, masks, points.ply, log)\n"
                     "A summary (timings per stage, Gaussian count, training PSNR) goes to stdout.\n"
                     "--world DIR trains on a world folder written earlier (by `gen3d world`, or a dataset/)\n"
                     "instead of generating one.\n"
                     "--inpaint-model MODEL fills every new view and the background behind the foreground\n"
                     "with Stable Diffusion (an inpainting checkpoint such as sd-v1-5-inpainting.ckpt; a\n"
                     "text-to-image one inpaints by latent blending, said once), at --sd-size and back, the\n"
                     "known pixels kept exactly; without it LaMa (--inpainter lama) or PatchMatch fill them.\n"
                     "--controlnet CN (control_v11p_sd15_inpaint) fills the background through the ControlNet,\n"
                     "its hint prefilled by LaMa (--lama-model) or PatchMatch, as the paper does.\n"
                     "Prompts: -p for the views (and the text input); else --clip and --caption-model write\n"
                     "them (as `gen3d describe`): the background template \"high-resolution [category]\n"
                     "background with [colours] colors, photorealistic, 8K\" and BLIP's caption for the views;\n"
                     "else neutral ones (category \"scene\", colours \"natural\"). config.json records them\n"
                     "and every diffusion setting (docs/generate.md).\n\n");
    g3d_cli_world_help(g_description, k, (int)sizeof g_description);
    return g_description;
}

static int run(int argc, char **argv)
{
    g3d_cli_generate g;
    g3d_opt opts[G3D_GENERATE_MAX_OPTS];
    g3d_cli_generate_init(&g);
    int nopts = g3d_cli_generate_opts(&g, opts);
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, nopts, "gen3d generate [-i RGB --depth DEPTH | -p PROMPT --sd-model MODEL] [options] -o DIR",
                                  description(), pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if ((prc = g3d_cli_generate_check(&g)) != 0) return prc;
    g3d_cli_common_apply(&g.common);
    g3d_cli_generate_apply(&g);
    if ((prc = g3d_cli_check_models(&g.p)) != 0) return prc;
    g3d_generate_params p = g.p;
    p.progress = g3d_cli_progress();
    p.cancel = g3d_cli_cancel();
    const int iters = g.iters;
    g3d_generate_result r;
    g3d_status rc = g3d_generate(&p, &r);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    /* the summary is the command's result, printed even with --quiet */
    const double *s = r.seconds;
    printf("%s\n", p.output_dir);
    if (!p.world_dir) {
        printf("  input     %6.1f s  %dx%d\n", s[G3D_STAGE_INPUT], r.width, r.height);
        printf("  layers    %6.1f s  %d foreground objects\n", s[G3D_STAGE_LAYERS], r.foreground_objects);
    }
    printf("  world     %6.1f s  %lld points, %d views + %d extra\n", s[G3D_STAGE_WORLD], (long long)r.points, r.views,
           r.extra_views);
    printf("  splats    %6.1f s  %d training iterations, %lld -> %lld Gaussians, PSNR %.2f dB\n", s[G3D_STAGE_SPLATS], iters,
           (long long)r.initial_gaussians, (long long)r.gaussians, r.train_psnr);
    printf("  outputs   %6.1f s  %s\n", s[G3D_STAGE_OUTPUTS],
           !p.video ? "preview" : r.video_written ? "preview, video.mp4" : "preview, PNG frames (no video)");
    printf("  explore             %d cameras within %.2f m: %.3f %% empty pixels on average, %.3f %% at worst\n",
           G3D_EXPLORE_CAMERAS, r.explore_distance, 100 * r.explore_mean_empty, 100 * r.explore_max_empty);
    printf("  total     %6.1f s\n", r.seconds_total);
    g3d_generate_result_free(&r);
    return G3D_EXIT_OK;
}

const g3d_command g3d_cmd_generate = {"generate", "one frame to a trained Gaussian-splat scene, its video and cameras", run};
