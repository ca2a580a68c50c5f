/* The shared input options and their mapping onto the pipeline's parameters. */
#include "input_opts.h"

#include <string.h>

void g3d_cli_input_init(g3d_cli_input *in)
{
    g3d_frame_params d;
    g3d_frame_params_default(&d);
    memset(in, 0, sizeof *in);
    in->default_dir = d.default_dir;
    in->scale = d.depth_scale;
    in->cx = d.K.cx;
    in->cy = d.K.cy;
}

int g3d_cli_input_check(const g3d_cli_input *in)
{
    if (in->depth && !in->rgb) return g3d_cli_errorf(G3D_EXIT_USAGE, "--depth needs -i");
    if (in->rgb && !in->depth && !in->depth_model)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "-i needs --depth, or --depth-model to predict it");
    if (in->max_depth < 0) return g3d_cli_errorf(G3D_EXIT_USAGE, "--max-depth must be positive");
    if (in->depth_tokens < 0 || in->depth_tokens > G3D_MOGE_MAX_TOKENS)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--depth-tokens must be in 0..%d", G3D_MOGE_MAX_TOKENS);
    if (in->fx < 0 || in->fy < 0 || in->fov < 0 || in->fov >= 180 || !(in->scale > 0))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "focal lengths and --depth-scale must be positive, --fov below 180");
    if (in->fx > 0 && in->fov > 0) return g3d_cli_errorf(G3D_EXIT_USAGE, "give --fx or --fov, not both");
    return 0;
}

void g3d_cli_input_apply(const g3d_cli_input *in, g3d_generate_params *p)
{
    p->input.rgb_path = in->rgb;
    p->input.depth_path = in->depth;
    p->input.depth_scale = in->scale;
    p->input.K = g3d_intrinsics_make(in->fx, in->fy, in->cx, in->cy, 0, 0);
    p->input.fov_deg = in->fov;
    p->input.default_dir = in->default_dir;
    p->depth_model = in->depth_model;
    if (in->max_depth > 0) p->depth_model_params.max_depth = in->max_depth;
    p->depth_model_params.num_tokens = in->depth_tokens;
}
