/* world_opts.h - the world-generation options, shared by the commands that grow a scene from
 * one frame (world, generate). */
#ifndef G3D_WORLD_OPTS_H
#define G3D_WORLD_OPTS_H

#include "cli.h"
#include "gen3d/generate.h"

typedef struct g3d_cli_world {
    const char *trajectory;
    const char *inpainter, *lama_model, *seg_model;
    int steps, extra, max_side, no_layers, explore_views, no_explore_views;
    double angle, distance, explore_distance, explore_angle;
} g3d_cli_world;

#define G3D_WORLD_OPTS(w)                                                                                         \
    {0, "trajectory", G3D_OPT_TRAJECTORY, &(w)->trajectory, "NAME|FILE", "camera path preset or pose file"},             \
    {0, "steps", G3D_OPT_INT, &(w)->steps, "N", "generation steps after the input (0: the preset's own count; 2 for a moving preset)"},     \
    {0, "angle", G3D_OPT_DOUBLE, &(w)->angle, "DEG", "rotate: total yaw (0: 60 degrees)"},                            \
    {0, "distance", G3D_OPT_DOUBLE, &(w)->distance, "M", "moving presets: distance in metres (0: a quarter of the median depth)"}, \
    {0, "extra", G3D_OPT_INT, &(w)->extra, "M", "extra training views rendered from the final cloud"},               \
    {0, "max-side", G3D_OPT_INT, &(w)->max_side, "PX", "downscale the input so that its longer side is at most this"}, \
    {0, "no-layers", G3D_OPT_FLAG, &(w)->no_layers, NULL, "skip the foreground/background split"},            \
    {0, "inpainter", G3D_OPT_STRING, &(w)->inpainter, "NAME", "classic (PatchMatch) or lama (needs --lama-model)"},  \
    {0, "lama-model", G3D_OPT_PATH, &(w)->lama_model, "CKPT", "LaMa checkpoint (big-lama/models/best.ckpt)"},       \
    {0, "seg-model", G3D_OPT_PATH, &(w)->seg_model, "CKPT", "Segment Anything checkpoint: the layers' masks (sam_vit_*.pth)"}, \
    {0, "explore-views", G3D_OPT_FLAG, &(w)->explore_views, NULL, "side steps at the exploration cameras, at most 384 px (the default, except with --inpaint-model)"}, \
    {0, "no-explore-views", G3D_OPT_FLAG, &(w)->no_explore_views, NULL, "no side steps at the exploration cameras (faster, holes behind depth edges)"}, \
    {0, "explore-distance", G3D_OPT_DOUBLE, &(w)->explore_distance, "M", "exploration set: step d in metres (0: a quarter of the median depth)"}, \
    {0, "explore-angle", G3D_OPT_DOUBLE, &(w)->explore_angle, "DEG", "exploration set: yaw and pitch reach in degrees, below 90"}

/* The library's defaults (g3d_generate_params_default). */
void g3d_cli_world_init(g3d_cli_world *w);
/* Usage checks; returns 0 or G3D_EXIT_USAGE after printing the problem. */
int g3d_cli_world_check(const g3d_cli_world *w);
/* Appends the trajectory section of --help (the preset list) to buf at offset k; returns the
 * new length. */
int g3d_cli_world_help(char *buf, int k, int cap);
/* Copies the options into the pipeline's world parameters. */
void g3d_cli_world_apply(const g3d_cli_world *w, g3d_generate_params *p);

#endif
