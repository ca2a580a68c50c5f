/* input_opts.h - the options that choose the pipeline's input frame, shared by the commands
 * that take one (prepare, world, generate): an RGB-D pair, or an RGB image and a depth model,
 * or the default input. */
#ifndef G3D_INPUT_OPTS_H
#define G3D_INPUT_OPTS_H

#include "cli.h"
#include "gen3d/generate.h"

typedef struct g3d_cli_input {
    const char *rgb, *depth, *default_dir, *depth_model;
    double scale, fx, fy, cx, cy, fov, max_depth;
    int depth_tokens;            /* MoGe-2 encoder tokens; 0: the model's default */
} g3d_cli_input;

#define G3D_INPUT_OPTS(in)                                                                                        \
    {'i', "input", G3D_OPT_PATH, &(in)->rgb, "RGB", "colour image (PNG or JPEG); without it: the default input"}, \
    {0, "depth", G3D_OPT_PATH, &(in)->depth, "DEPTH", "depth map (.png .pfm .npy .npz)"},                       \
    {0, "depth-model", G3D_OPT_PATH, &(in)->depth_model, "CKPT", "MoGe-2 or Depth Anything V2 checkpoint: depth of -i without --depth, and of new views"}, \
    {0, "max-depth", G3D_OPT_DOUBLE, &(in)->max_depth, "M", "metric Depth Anything V2: its maximum depth (0: 20 or 80 from the file name)"}, \
    {0, "depth-tokens", G3D_OPT_INT, &(in)->depth_tokens, "N", "MoGe-2: encoder tokens (0: the model's default; 1200 is about 4x faster)"}, \
    {0, "depth-scale", G3D_OPT_DOUBLE, &(in)->scale, "S", "16-bit PNG / integer depth units per metre (1000 mm, 5000 TUM)"}, \
    {0, "fx", G3D_OPT_DOUBLE, &(in)->fx, "PX", "focal length x in pixels"},                                        \
    {0, "fy", G3D_OPT_DOUBLE, &(in)->fy, "PX", "focal length y in pixels (default: fx)"},                          \
    {0, "cx", G3D_OPT_DOUBLE, &(in)->cx, "PX", "principal point x (default: image centre)"},                       \
    {0, "cy", G3D_OPT_DOUBLE, &(in)->cy, "PX", "principal point y (default: image centre)"},                       \
    {0, "fov", G3D_OPT_DOUBLE, &(in)->fov, "DEG", "horizontal field of view instead of --fx (default 60)"},        \
    {0, "default-input", G3D_OPT_PATH, &(in)->default_dir, "DIR", "folder of the default input (Middlebury Motorcycle)"}

/* The library's defaults (g3d_frame_params_default). */
void g3d_cli_input_init(g3d_cli_input *in);
/* Usage checks; returns 0 or G3D_EXIT_USAGE after printing the problem. */
int g3d_cli_input_check(const g3d_cli_input *in);
/* Copies the options into the pipeline's input and depth-model parameters. */
void g3d_cli_input_apply(const g3d_cli_input *in, g3d_generate_params *p);

#endif
