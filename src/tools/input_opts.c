/* Loading the input frame from the shared input options. */
#include "input_opts.h"

#include <string.h>

void g3d_cli_input_init(g3d_cli_input *in)
{
    memset(in, 0, sizeof *in);
    in->default_dir = "cache/default-input";
    in->scale = 1000;
    in->cx = in->cy = -1;
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

g3d_status g3d_cli_input_load(g3d_cli_input *in, g3d_frame *f)
{
    memset(f, 0, sizeof *f);
    int metric = 0;
    if (in->depth_model && !in->model.estimate) {
        g3d_depth_model_params o;
        g3d_depth_model_params_default(&o);
        if (in->max_depth > 0) o.max_depth = in->max_depth;
        o.num_tokens = in->depth_tokens;
        G3D_TRY(g3d_depth_estimator_model_create(in->depth_model, &o, &in->model, &metric));
        g3d_log(G3D_LOG_INFO, "depth model: %s (%s)", in->depth_model, in->model.name);
        if (in->rgb && !in->depth && !metric)
            return G3D_ERR(G3D_ERR_ARG, "%s: relative Depth Anything V2 gives no metres for %s; use MoGe-2 or a "
                           "metric checkpoint (--max-depth), or give --depth", in->depth_model, in->rgb);
    }
    if (in->rgb && !in->depth) {
        g3d_intrinsics K = g3d_intrinsics_make(in->fx, in->fy, in->cx, in->cy, 0, 0);
        return g3d_frame_load_rgb(in->rgb, &in->model, K, in->fov, in->max_side, f);
    }
    if (!in->rgb) {
        g3d_status rc = g3d_frame_load_middlebury(in->default_dir, f);
        if (rc != G3D_OK) g3d_error_prefix("default input (run scripts/fetch-default-input.sh)");
        return rc;
    }
    g3d_intrinsics K = g3d_intrinsics_make(in->fx, in->fy, in->cx, in->cy, 0, 0);
    return g3d_frame_load_rgbd(in->rgb, in->depth, in->scale, K, in->fov, f);
}

const g3d_depth_estimator *g3d_cli_input_model(const g3d_cli_input *in)
{
    return in->model.estimate ? &in->model : NULL;
}

void g3d_cli_input_free(g3d_cli_input *in)
{
    g3d_depth_estimator_free(&in->model);
}
