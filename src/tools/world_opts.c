/* The shared world options and their mapping onto the pipeline's parameters. */
#include "world_opts.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

void g3d_cli_world_init(g3d_cli_world *w)
{
    g3d_generate_params d;
    g3d_generate_params_default(&d);
    memset(w, 0, sizeof *w);
    w->trajectory = d.trajectory;
    w->inpainter = "classic";
    w->extra = d.world.extra_views;
    w->max_side = d.input.max_side;
    w->explore_views = d.explore_views;
    w->explore_distance = d.explore.distance;
    w->explore_angle = d.explore.angle_deg;
}

int g3d_cli_world_check(const g3d_cli_world *w)
{
    if (w->steps < 0 || w->steps > 1000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--steps must be in 0..1000");
    if (w->extra < 0 || w->extra > 1000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--extra must be in 0..1000");
    if (w->max_side < 16 || w->max_side > G3D_MAX_IMAGE_SIDE)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--max-side must be in 16..%d", G3D_MAX_IMAGE_SIDE);
    if (strcmp(w->inpainter, "classic") && strcmp(w->inpainter, "lama"))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--inpainter must be classic or lama, not '%s'", w->inpainter);
    if (!strcmp(w->inpainter, "lama") != (w->lama_model != NULL))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--inpainter lama and --lama-model CKPT go together");
    if (w->distance < 0 || fabs(w->angle) > 360)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--distance must be >= 0 and --angle within a full turn");
    if (!(w->explore_distance >= 0 && w->explore_distance <= 1e4))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--explore-distance must be in 0..10000 metres");
    if (w->explore_views > 0 && w->no_explore_views)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--explore-views and --no-explore-views contradict each other");
    if (!(w->explore_angle >= 0 && w->explore_angle < 90))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--explore-angle must be at least 0 and below 90 degrees");
    return 0;
}

int g3d_cli_world_help(char *buf, int k, int cap)
{
    k += snprintf(buf + k, k < cap ? cap - k : 0,
                  "Trajectories (--trajectory NAME, or a cameras.json / transforms.json file of poses in the\n"
                  "input camera's frame; moving presets scale with the median depth unless --distance is given):\n");
    for (const char *const *n = g3d_trajectory_names(); *n && k < cap; n++)
        k += snprintf(buf + k, cap - k, "  %-12s %s\n", *n, g3d_trajectory_describe(*n));
    return k;
}

void g3d_cli_world_apply(const g3d_cli_world *w, g3d_generate_params *p)
{
    p->trajectory = w->trajectory;
    p->steps = w->steps;
    p->trajectory_params.angle_deg = w->angle;
    p->trajectory_params.distance = w->distance;
    p->world.extra_views = w->extra;
    p->input.max_side = w->max_side;
    p->layers = !w->no_layers;
    p->lama_model = w->lama_model;
    p->seg_model = w->seg_model;
    p->explore_views = w->no_explore_views ? 0 : w->explore_views;
    p->explore.distance = w->explore_distance;
    p->explore.angle_deg = w->explore_angle;
}
