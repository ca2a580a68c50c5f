/* generate_opts.h - the options of `gen3d generate`, shared with `gen3d batch`, whose manifest
 * keys are these options' long names: an option added here is a manifest key at once. */
#ifndef G3D_GENERATE_OPTS_H
#define G3D_GENERATE_OPTS_H

#include "diffusion_opts.h"
#include "input_opts.h"
#include "world_opts.h"

typedef struct g3d_cli_generate {
    g3d_cli_common common;
    g3d_cli_input in;
    g3d_cli_world wo;
    g3d_cli_diffusion df;
    g3d_generate_params p;
    int iters, no_video;
} g3d_cli_generate;

/* Room for the table g3d_cli_generate_opts fills. */
#define G3D_GENERATE_MAX_OPTS 64

/* The library's defaults (output folder "scene"). */
void g3d_cli_generate_init(g3d_cli_generate *g);
/* Fills opts (G3D_GENERATE_MAX_OPTS entries) with the option table pointing into g; returns
 * the count. */
int g3d_cli_generate_opts(g3d_cli_generate *g, g3d_opt *opts);
/* Usage checks; returns 0 or G3D_EXIT_USAGE after reporting the problem. */
int g3d_cli_generate_check(const g3d_cli_generate *g);
/* Copies the options into g->p (output folder, seed and thread-independent settings; progress
 * and cancel are the caller's). */
void g3d_cli_generate_apply(g3d_cli_generate *g);

#endif
