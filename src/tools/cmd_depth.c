/* gen3d depth: relative depth of one image with Depth Anything V2. */
#include "cli.h"
#include "depth_moge.h"
#include "gen3d/depth_anything.h"
#include "gen3d/depthio.h"
#include "gen3d/image.h"
#include "gen3d/imageio.h"
#include "gen3d/recognize.h"

#include <stdio.h>

static const char *DESCRIPTION =
    "Predicts depth for one image with Depth Anything V2 (ViT-S/B/L), loaded from the official\n"
    "checkpoint (depth_anything_v2_vits.pth, or a safetensors file with the same tensor names).\n"
    "The output is the network's relative inverse depth (larger = nearer, arbitrary scale, not\n"
    "metres) at the image's resolution, saved by extension: .npy or .pfm (float32), .png (16-bit,\n"
    "value x 1000, rounded). The metric checkpoints (depth_anything_v2_metric_hypersim_*.pth,\n"
    "_vkitti_*) give depth in metres: recognised by their file names (maximum depth 20 m and 80 m),\n"
    "or by --max-depth.\n"
    "A MoGe-2 checkpoint (model.pt with its model_config) is recognised automatically: the output\n"
    "is then metric depth in metres (0 where the model finds no valid surface, e.g. sky), and\n"
    "--intrinsics-out saves the camera it predicts.";

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    const char *model = NULL, *input = NULL;
    int input_size = 518, num_tokens = 0;
    double max_depth = 0;
    const char *intrinsics_out = NULL;
    g3d_cli_common_init(&common);
    common.output = NULL;
    g3d_opt opts[] = {
        {'m', "model", G3D_OPT_STRING, &model, "CKPT", "Depth Anything V2 or MoGe-2 checkpoint (.pth, .pt, .safetensors)"},
        {'i', "input", G3D_OPT_STRING, &input, "IMAGE", "input image (.png, .jpg)"},
        {0, "input-size", G3D_OPT_INT, &input_size, "N", "network input size (shorter side, rounded to 14)"},
        {0, "max-depth", G3D_OPT_DOUBLE, &max_depth, "M", "metric Depth Anything V2: maximum depth in metres (0: from the file name)"},
        {0, "num-tokens", G3D_OPT_INT, &num_tokens, "N", "MoGe-2: encoder tokens (0: the model's default, 3600)"},
        {0, "intrinsics-out", G3D_OPT_STRING, &intrinsics_out, "FILE", "MoGe-2: predicted camera as JSON (pixels)"},
        G3D_COMMON_OPTS(&common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts), "gen3d depth -m CKPT -i IMAGE -o OUT", DESCRIPTION,
                                  pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if (!model || !input || !common.output) return g3d_cli_errorf(G3D_EXIT_USAGE, "-m, -i and -o are required");
    if (input_size < 14 || input_size > 8192) return g3d_cli_errorf(G3D_EXIT_USAGE, "--input-size must be in 14..8192");
    if (max_depth < 0) return g3d_cli_errorf(G3D_EXIT_USAGE, "--max-depth must be positive");
    if (num_tokens < 0 || num_tokens > G3D_MOGE_MAX_TOKENS)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--num-tokens must be in 0..%d", G3D_MOGE_MAX_TOKENS);
    g3d_cli_common_apply(&common);
    const int is_moge = g3d_model_recognize_file(model) == G3D_MODEL_MOGE;
    if (is_moge && max_depth > 0)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "%s: --max-depth is for metric Depth Anything V2; MoGe-2 predicts its own scale", model);
    if (is_moge)
        return g3d_cli_depth_moge(model, input, common.output, num_tokens, intrinsics_out);
    if (intrinsics_out || num_tokens)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "%s: %s needs a MoGe-2 checkpoint (Depth Anything V2 predicts no camera)",
                              model, intrinsics_out ? "--intrinsics-out" : "--num-tokens");

    g3d_image img = {0}, depth = {0};
    g3d_dav2 *m = NULL;
    g3d_status rc = g3d_image_load(input, 3, &img);
    if (rc == G3D_OK) rc = g3d_dav2_load_file(model, &m);
    if (rc == G3D_OK) {
        g3d_dav2_set_metric(m, (float)(max_depth > 0 ? max_depth : g3d_dav2_metric_default(model)));
        if (g3d_dav2_max_depth(m) > 0)
            g3d_log(G3D_LOG_INFO, "metric depth, at most %.0f m", g3d_dav2_max_depth(m));
    }
    if (rc == G3D_OK) rc = g3d_image_create(&depth, img.w, img.h, 1);
    if (rc == G3D_OK) rc = g3d_dav2_predict(m, img.data, img.w, img.h, input_size, depth.data, NULL);
    if (rc == G3D_OK) rc = g3d_depth_save(common.output, &depth);
    g3d_dav2_free(m);
    g3d_image_free(&img);
    g3d_image_free(&depth);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s\n", common.output);
    return G3D_EXIT_OK;
}

const g3d_command g3d_cmd_depth = {"depth", "depth of an image with Depth Anything V2 (relative or metric) or MoGe-2", run};
