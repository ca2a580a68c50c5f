/* gen3d inpaint: fill the masked part of one image with Stable Diffusion (-m, sd_opts.c), LaMa
 * or the classical inpainter. */
#include "cli.h"
#include "gen3d/image.h"
#include "gen3d/imageio.h"
#include "gen3d/inpaint_classic.h"
#include "gen3d/lama.h"
#include "sd_opts.h"

#include <stdio.h>
#include <string.h>

static const char *DESCRIPTION =
    "Fills the holes of an image: with LaMa (--lama, the official big-lama/models/best.ckpt or any\n"
    "FFC generator checkpoint of advimman/lama), or without weights with the classical PatchMatch\n"
    "inpainter. As in LaMa's predict script, every non-zero mask pixel is a hole (grey masks: any\n"
    "value above 0), the picture is padded to a multiple of 8 and only the hole takes the\n"
    "network's output; known pixels are written back unchanged. An empty mask writes the image\n"
    "unchanged (and says so); a mask of another size or one covering the whole image is an error.\n"
    "With -m MODEL a Stable Diffusion checkpoint fills the holes from a prompt instead\n"
    "(gen3d inpaint -m MODEL --help lists its options; docs/diffusion.md).";

/* -m/--model selects the Stable Diffusion back end, which has options of its own. */
static int wants_diffusion(int argc, char **argv)
{
    for (int i = 1; i < argc; i++)
        if (!strcmp(argv[i], "-m") || !strcmp(argv[i], "--model") || !strncmp(argv[i], "--model=", 8)) return 1;
    return 0;
}

static int run(int argc, char **argv)
{
    if (wants_diffusion(argc, argv)) return g3d_sd_cli_inpaint(argc, argv);
    g3d_cli_common common;
    const char *input = NULL, *mask_path = NULL, *lama = NULL;
    g3d_cli_common_init(&common);
    common.output = NULL;
    g3d_opt opts[] = {
        {'i', "input", G3D_OPT_STRING, &input, "IMAGE", "input image (.png, .jpg)"},
        {0, "mask", G3D_OPT_STRING, &mask_path, "MASK", "hole mask (.png, .jpg): non-zero = fill"},
        {0, "lama", G3D_OPT_STRING, &lama, "CKPT", "LaMa checkpoint (best.ckpt); without: classical PatchMatch"},
        G3D_COMMON_OPTS(&common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts),
                                  "gen3d inpaint [--lama CKPT | -m MODEL -p PROMPT] -i IMAGE --mask MASK -o OUT.png", DESCRIPTION, pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if (!input || !mask_path || !common.output) return g3d_cli_errorf(G3D_EXIT_USAGE, "-i, --mask and -o are required");
    g3d_cli_common_apply(&common);

    g3d_image img = {0}, mask = {0};
    g3d_inpainter p = {0};
    int code = G3D_EXIT_OK;
    g3d_status rc = g3d_image_load(input, 3, &img);
    if (rc == G3D_OK) rc = g3d_image_load(mask_path, 1, &mask);
    if (rc != G3D_OK) {
        code = g3d_cli_fail(rc);
        goto done;
    }
    if (mask.w != img.w || mask.h != img.h) {
        code = g3d_cli_errorf(G3D_EXIT_FAIL, "%s: the mask is %d x %d, the image %s %d x %d", mask_path, mask.w, mask.h,
                              input, img.w, img.h);
        goto done;
    }
    size_t holes = 0, n = (size_t)img.w * img.h;
    for (size_t i = 0; i < n; i++) holes += (mask.data[i] = mask.data[i] > 0 ? 1.0f : 0.0f) > 0;
    if (holes == n) {
        code = g3d_cli_errorf(G3D_EXIT_FAIL, "%s: the mask covers the whole image; nothing is left to inpaint from", mask_path);
        goto done;
    }
    if (!holes) {
        g3d_log(G3D_LOG_WARN, "%s: the mask is empty; the image is written unchanged", mask_path);
    } else {
        rc = lama ? g3d_inpainter_lama_create(lama, &p) : g3d_inpainter_classic_create(NULL, &p);
        double t0 = g3d_time_now();
        if (rc == G3D_OK) rc = p.inpaint(p.ctx, &img, &mask, NULL, (uint64_t)common.seed);
        if (rc == G3D_OK)
            g3d_log(G3D_LOG_INFO, "%s: %zu hole pixels of %d x %d filled in %.2f s", p.name, holes, img.w, img.h,
                    g3d_time_now() - t0);
    }
    if (rc == G3D_OK) rc = g3d_image_save_png(common.output, &img, 8);
    if (rc != G3D_OK) code = g3d_cli_fail(rc);
    else printf("%s\n", common.output);
done:
    g3d_inpainter_free(&p);
    g3d_image_free(&img);
    g3d_image_free(&mask);
    return code;
}

const g3d_command g3d_cmd_inpaint = {"inpaint", "fill the holes of an image (Stable Diffusion, LaMa or classical PatchMatch)", run};
