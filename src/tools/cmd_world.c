/* gen3d world: layered point-cloud expansion along a camera trajectory. */
#include "input_opts.h"
#include "world_opts.h"

#include <stdio.h>

static char g_description[4096];

static const char *description(void)
{
    int k = snprintf(g_description, sizeof g_description,
                     "Builds a multi-view-consistent point cloud from one RGB-D frame (or an RGB image and\n"
                     "--depth-model, which then also estimates the depth of every new view): the input is split into\n"
                     "foreground and background layers, then at every pose of the trajectory the cloud is\n"
                     "rendered, its holes inpainted, their depth estimated and aligned to the cloud along the\n"
                     "camera rays, and the new pixels lifted. M extra views around the poses are rendered from\n"
                     "the final cloud with validity masks. Writes a dataset folder (views, depth, extra views and\n"
                     "masks, layers, cameras.json, transforms.json, points.ply, log.json) for `gen3d train`.\n"
                     "Without model weights the classical PatchMatch inpainter and depth completion are used.\n\n");
    g3d_cli_world_help(g_description, k, (int)sizeof g_description);
    return g_description;
}

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    g3d_cli_input in;
    g3d_cli_world wo;
    g3d_cli_common_init(&common);
    g3d_cli_input_init(&in);
    g3d_cli_world_init(&wo);
    common.output = "world";
    g3d_opt opts[] = {
        G3D_INPUT_OPTS(&in),
        G3D_WORLD_OPTS(&wo),
        G3D_COMMON_OPTS(&common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts), "gen3d world [-i RGB --depth DEPTH] [options] -o DIR",
                                  description(), pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if ((prc = g3d_cli_input_check(&in)) != 0) return prc;
    if ((prc = g3d_cli_world_check(&wo)) != 0) return prc;
    g3d_cli_common_apply(&common);

    g3d_generate_params p;
    g3d_generate_params_default(&p);
    g3d_cli_input_apply(&in, &p);
    g3d_cli_world_apply(&wo, &p);
    p.last_stage = G3D_STAGE_WORLD;
    p.output_dir = common.output;
    p.seed = (uint64_t)common.seed;
    p.progress = g3d_cli_progress();
    p.cancel = g3d_cli_cancel();
    g3d_status rc = g3d_generate(&p, NULL);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s\n", common.output);
    return G3D_EXIT_OK;
}

const g3d_command g3d_cmd_world = {"world", "grow a point cloud of the scene along a camera trajectory", run};
