/* The options of the whole pipeline and their mapping onto g3d_generate_params. */
#include "generate_opts.h"

#include <string.h>

void g3d_cli_generate_init(g3d_cli_generate *g)
{
    memset(g, 0, sizeof *g);
    g3d_generate_params_default(&g->p);
    g3d_cli_common_init(&g->common);
    g3d_cli_input_init(&g->in);
    g3d_cli_world_init(&g->wo);
    g3d_cli_diffusion_init(&g->df);
    g->common.output = "scene";
    g->common.seed = (int64_t)g->p.seed;
    g->iters = (int)g->p.train.iterations;
    g->no_video = !g->p.video;
}

int g3d_cli_generate_opts(g3d_cli_generate *g, g3d_opt *out)
{
    g3d_generate_params *p = &g->p;
    const g3d_opt opts[] = {
        G3D_INPUT_OPTS(&g->in),
        G3D_WORLD_OPTS(&g->wo),
        G3D_DIFFUSION_OPTS(&g->df),
        {0, "clip", G3D_OPT_PATH, &p->clip_model, "MODEL", "CLIP model: scene category in the background prompt (docs/describe.md)"},
        {0, "caption-model", G3D_OPT_PATH, &p->caption_model, "MODEL", "BLIP captioner: the views' inpainting prompt"},
        {0, "world", G3D_OPT_PATH, &p->world_dir, "DIR", "train on this world folder instead of generating one"},
        {0, "iters", G3D_OPT_INT, &g->iters, "N", "training iterations"},
        {0, "sh-degree", G3D_OPT_INT, &p->sh_degree, "D", "spherical-harmonics degree of the Gaussians (0..3)"},
        {0, "knn-init", G3D_OPT_FLAG, &p->knn_init, NULL, "start the Gaussians isotropic (3-NN scale, opacity 0.1), not as pixel footprints"},
        {0, "input-every", G3D_OPT_INT, &p->input_every, "N", "train on the input view every N iterations besides its turn (0: its turn only)"},
        {0, "coverage-weight", G3D_OPT_DOUBLE, &p->coverage_weight, "W", "weight of the training's pull towards opaque pixels (0: none; fewer empty pixels off the path)"},
        {0, "video-trajectory", G3D_OPT_STRING, &p->video_trajectory, "NAME", "video camera path: swing (a loop around the input view) or a preset below"},
        {0, "frames", G3D_OPT_INT, &p->video_frames, "N", "video frames"},
        {0, "fps", G3D_OPT_INT, &p->video_params.fps, "N", "video frame rate"},
        {0, "no-video", G3D_OPT_FLAG, &g->no_video, NULL, "skip the fly-through video"},
        G3D_COMMON_OPTS(&g->common),
    };
    _Static_assert(sizeof opts / sizeof opts[0] <= G3D_GENERATE_MAX_OPTS, "raise G3D_GENERATE_MAX_OPTS");
    memcpy(out, opts, sizeof opts);
    return G3D_COUNTOF(opts);
}

int g3d_cli_generate_check(const g3d_cli_generate *g)
{
    const g3d_generate_params *p = &g->p;
    int rc;
    if ((rc = g3d_cli_input_check(&g->in)) != 0) return rc;
    if ((rc = g3d_cli_world_check(&g->wo)) != 0) return rc;
    if ((rc = g3d_cli_diffusion_check(&g->df, g->in.rgb != NULL, g->in.depth_model != NULL)) != 0) return rc;
    if (g->iters < 1 || g->iters > 1000000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--iters must be in 1..1000000");
    if (p->input_every < 0 || p->input_every > 1000000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--input-every must be in 0..1000000");
    if (!(p->coverage_weight >= 0 && p->coverage_weight <= 100)) return g3d_cli_errorf(G3D_EXIT_USAGE, "--coverage-weight must be in 0..100");
    if (p->sh_degree < 0 || p->sh_degree > 3) return g3d_cli_errorf(G3D_EXIT_USAGE, "--sh-degree must be in 0..3");
    if (p->video_frames < 2 || p->video_frames > 100000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--frames must be in 2..100000");
    if (p->video_params.fps < 1 || p->video_params.fps > 240) return g3d_cli_errorf(G3D_EXIT_USAGE, "--fps must be in 1..240");
    if (p->world_dir && (p->clip_model || p->caption_model || g->df.inpaint_model || g->df.sd_model))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--world skips inpainting: no --clip, --caption-model, --sd-model or --inpaint-model");
    if (p->world_dir && (g->in.rgb || g->in.depth_model))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--world trains on a generated world: no -i or --depth-model");
    return 0;
}

void g3d_cli_generate_apply(g3d_cli_generate *g)
{
    g3d_generate_params *p = &g->p;
    g3d_cli_input_apply(&g->in, p);
    g3d_cli_world_apply(&g->wo, p);
    g3d_cli_diffusion_apply(&g->df, p);
    g3d_train_params_default(&p->train, g->iters);
    p->video = !g->no_video;
    p->output_dir = g->common.output;
    p->seed = (uint64_t)g->common.seed;
}
