/* gen3d prepare: builds the input frame (RGB + metric depth + camera) and saves it. */
#include "cli.h"
#include "input_opts.h"

#include <stdio.h>

static const char *DESCRIPTION =
    "Builds the pipeline's input frame and writes it as a folder: rgb.png, depth.png (16-bit\n"
    "millimetres), depth.npy (metres), cameras.json, points.ply (the lifted coloured point cloud)\n"
    "and, for the default input, heldout.png (the real second view).\n"
    "Without -i it uses the built-in default input, Middlebury 2014 \"Motorcycle\" (fetched into\n"
    "cache/default-input by scripts/fetch-default-input.sh; --default-input DIR to use another copy).\n"
    "With -i RGB --depth DEPTH it reads an RGB-D pair; give the camera as --fx/--fy/--cx/--cy or\n"
    "--fov (horizontal, degrees); without either a 60 degree field of view is assumed.";

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    g3d_cli_input in;
    g3d_cli_common_init(&common);
    g3d_cli_input_init(&in);
    common.output = "frame";
    g3d_opt opts[] = {G3D_INPUT_OPTS(&in), G3D_COMMON_OPTS(&common)};
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts), "gen3d prepare [-i RGB --depth DEPTH] [options] -o DIR",
                                  DESCRIPTION, pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if ((prc = g3d_cli_input_check(&in)) != 0) return prc;
    g3d_cli_common_apply(&common);

    g3d_generate_params p;
    g3d_generate_params_default(&p);
    g3d_cli_input_apply(&in, &p);
    p.input.max_side = 0;   /* the frame at its own size */
    p.last_stage = G3D_STAGE_INPUT;
    p.output_dir = common.output;
    p.progress = g3d_cli_progress();
    p.cancel = g3d_cli_cancel();
    g3d_status rc = g3d_generate(&p, NULL);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s\n", common.output);
    return G3D_EXIT_OK;
}

const g3d_command g3d_cmd_prepare = {"prepare", "build the input frame (RGB, metric depth, camera) and its point cloud", run};
