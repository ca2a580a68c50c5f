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
    if ((in->rgb == NULL) != (in->depth == NULL)) return g3d_cli_errorf(G3D_EXIT_USAGE, "-i and --depth go together");
    if (in->fx < 0 || in->fy < 0 || in->fov < 0 || in->fov >= 180 || !(in->scale > 0))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "focal lengths and --depth-scale must be positive, --fov below 180");
    if (in->fx > 0 && in->fov > 0) return g3d_cli_errorf(G3D_EXIT_USAGE, "give --fx or --fov, not both");
    return 0;
}

g3d_status g3d_cli_input_load(const g3d_cli_input *in, g3d_frame *f)
{
    if (!in->rgb) {
        g3d_status rc = g3d_frame_load_middlebury(in->default_dir, f);
        if (rc != G3D_OK) g3d_error_prefix("default input (run scripts/fetch-default-input.sh)");
        return rc;
    }
    g3d_intrinsics K = g3d_intrinsics_make(in->fx, in->fy, in->cx, in->cy, 0, 0);
    return g3d_frame_load_rgbd(in->rgb, in->depth, in->scale, K, in->fov, f);
}
