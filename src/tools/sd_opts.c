/* gen3d txt2img and gen3d inpaint -m MODEL: options, checks, and the library's loop. */
#include "sd_opts.h"

#include "cli.h"
#include "gen3d/imageio.h"
#include "gen3d/lama.h"
#include "gen3d/npy.h"
#include "gen3d/sd.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *DESC_COMMON =
    "The model is a single-file Stable Diffusion checkpoint (.safetensors or .ckpt: SD 1.x, SD 2.x,\n"
    "their inpainting versions) or a diffusers folder (unet/, vae/, text_encoder/, tokenizer/,\n"
    "scheduler/); a single file's yaml configuration beside it (same name, .yaml) or --config gives\n"
    "the head split and v-prediction when they differ from the family's defaults; --vae and\n"
    "--text-encoder take those parts from other files. The prompt is tokenized with --tokenizer or\n"
    "OpenAI's CLIP vocabulary (docs/text.md); a prompt longer than the 77-token context is refused.\n"
    "Samplers: ddim (eta: --eta), pndm (diffusers' default for SD 1.5), plms (ldm's), euler, euler_a, dpmpp_2m;\n"
    "--karras uses Karras et al.'s sigmas for the last three. The same seed gives the same picture, byte for byte; --noise FILE.npy gives the\n"
    "initial latent noise [1, 4, H/8, W/8] instead (to compare with another implementation).";

typedef struct sd_cli {
    g3d_cli_common common;
    g3d_sd_paths paths;
    const char *prompt, *negative, *sampler, *noise, *image, *mask, *prefill_lama;
    int steps, width, height, karras;
    double cfg, eta, control_scale;
} sd_cli;

#define SD_OPTS(c)                                                                                                    \
    {'m', "model", G3D_OPT_STRING, &(c)->paths.model, "MODEL", "Stable Diffusion checkpoint (.safetensors, .ckpt) or diffusers folder"},    \
    {'p', "prompt", G3D_OPT_STRING, &(c)->prompt, "TEXT", "what to draw"},                                            \
    {'n', "negative", G3D_OPT_STRING, &(c)->negative, "TEXT", "what to avoid (the unconditional prompt)"},             \
    {0, "steps", G3D_OPT_INT, &(c)->steps, "N", "denoising steps"},                                                   \
    G3D_SD_SAMPLING_OPTS(&(c)->cfg, &(c)->sampler, &(c)->karras, &(c)->eta),                                         \
    {0, "noise", G3D_OPT_STRING, &(c)->noise, "FILE.npy", "initial latent noise [1, 4, H/8, W/8] instead of the seed's"}, \
    G3D_SD_PARTS_OPTS(&(c)->paths, "config")

static void sd_cli_init(sd_cli *c)
{
    memset(c, 0, sizeof *c);
    g3d_cli_common_init(&c->common);
    c->paths.prediction = -1;
    g3d_sd_params d = g3d_sd_defaults();
    c->steps = d.sampler.steps;
    c->width = d.width;
    c->height = d.height;
    c->cfg = d.cfg;
    c->sampler = "ddim";
    c->control_scale = d.control_scale;
}

/* Checks the options every command shares; fills p (prompt, sampler, scale, seed). */
static int sd_cli_params(sd_cli *c, g3d_sd_params *p, const char *cmd)
{
    if (!c->paths.model) return g3d_cli_errorf(G3D_EXIT_USAGE, "-m MODEL is required (see gen3d %s --help)", cmd);
    if (!c->prompt || !c->prompt[strspn(c->prompt, " \t\r\n")]) return g3d_cli_errorf(G3D_EXIT_USAGE, "-p PROMPT is required and may not be empty");
    if (!c->common.output) return g3d_cli_errorf(G3D_EXIT_USAGE, "-o OUT.png is required");
    *p = g3d_sd_defaults();
    int rc = g3d_sd_cli_sampling(c->sampler, c->steps, "--steps", c->cfg, c->eta, c->karras, p);
    p->prompt = c->prompt;
    p->negative = c->negative;
    return rc;
}

int g3d_sd_cli_sampling(const char *sampler, int steps, const char *steps_flag, double cfg, double eta, int karras,
                        g3d_sd_params *p)
{
    int k = g3d_sd_sampler_parse(sampler);
    if (k < 0) return g3d_cli_errorf(G3D_EXIT_USAGE, "--sampler %s: ddim, pndm, plms, euler, euler_a or dpmpp_2m expected", sampler);
    if (steps < 1 || steps > 1000) return g3d_cli_errorf(G3D_EXIT_USAGE, "%s must be 1 to 1000", steps_flag);
    if (!(cfg >= 0 && cfg <= 100)) return g3d_cli_errorf(G3D_EXIT_USAGE, "--cfg must be 0 to 100");
    if (!(eta >= 0 && eta <= 1)) return g3d_cli_errorf(G3D_EXIT_USAGE, "--eta must be 0 to 1");
    if (karras && (k == G3D_SD_DDIM || k == G3D_SD_PNDM || k == G3D_SD_PLMS)) return g3d_cli_errorf(G3D_EXIT_USAGE, "--karras is for euler, euler_a and dpmpp_2m");
    p->sampler = (g3d_sd_sampler){(g3d_sd_sampler_kind)k, steps, (float)eta, karras, G3D_SD_PRED_EPS};
    p->cfg = (float)cfg;
    return G3D_EXIT_OK;
}

/* Loads the model, checks the prompts fit, reads --noise for a latent of w x h pixels. */
static int sd_cli_prepare(sd_cli *c, g3d_sd_params *p, g3d_sd **m, g3d_array *noise, int w, int h)
{
    g3d_cli_common_apply(&c->common);
    p->seed = (uint64_t)c->common.seed;
    p->progress = g3d_cli_progress();
    g3d_status rc = g3d_sd_load(&c->paths, m);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    int k = g3d_sd_size_multiple(*m);
    if (w % k || h % k || w < k || h < k)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "%dx%d: width and height must be multiples of %d for this model", w, h, k);
    const char *texts[2] = {c->prompt, c->negative};
    for (int i = 0; i < 2; i++) {
        int dropped = 0;
        if (!texts[i]) continue;
        if ((rc = g3d_sd_check_prompt(*m, texts[i], &dropped)) != G3D_OK) return g3d_cli_fail(rc);
        if (dropped)
            return g3d_cli_errorf(G3D_EXIT_FAIL, "the %sprompt is %d tokens longer than the text encoder's context", i ? "negative " : "",
                                  dropped);
    }
    if (c->noise) {
        int f = k >> (g3d_sd_get_unet(*m)->levels - 1), zc = 4;
        if ((rc = g3d_npy_load(c->noise, noise)) != G3D_OK) return g3d_cli_fail(rc);
        const int64_t *s = noise->shape + (noise->ndim == 4);
        if (noise->ndim < 3 || noise->ndim > 4 || (noise->ndim == 4 && noise->shape[0] != 1) || s[0] != zc || s[1] != h / f ||
            s[2] != w / f)
            return g3d_cli_errorf(G3D_EXIT_FAIL, "%s: noise of shape [1, %d, %d, %d] expected", c->noise, zc, h / f, w / f);
        for (int64_t i = 0; i < (int64_t)zc * (h / f) * (w / f); i++)
            if (!isfinite(noise->data[i])) return g3d_cli_errorf(G3D_EXIT_FAIL, "%s: not finite", c->noise);
        p->noise = noise->data;
    }
    return G3D_EXIT_OK;
}

/* Writes the picture as the official scripts quantize it (255 x truncated), then prints the path. */
static int sd_cli_save(const sd_cli *c, g3d_image *img)
{
    for (size_t i = 0; i < g3d_image_size(img); i++) img->data[i] = floorf(255.0f * img->data[i]) / 255.0f;
    g3d_status rc = g3d_image_save_png(c->common.output, img, 8);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s\n", c->common.output);
    return G3D_EXIT_OK;
}

int g3d_sd_cli_txt2img(int argc, char **argv)
{
    sd_cli c;
    sd_cli_init(&c);
    g3d_opt opts[] = {
        SD_OPTS(&c),
        {'W', "width", G3D_OPT_INT, &c.width, "W", "picture width (a multiple of 64 for SD)"},
        {'H', "height", G3D_OPT_INT, &c.height, "H", "picture height"},
        G3D_COMMON_OPTS(&c.common),
    };
    char desc[2048];
    snprintf(desc, sizeof desc, "Draws a picture for a text prompt with Stable Diffusion.\n%s", DESC_COMMON);
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts),
                                  "gen3d txt2img -m MODEL -p PROMPT [-n NEGATIVE] [--steps N] [--cfg S] [--sampler NAME] "
                                  "[-W W -H H] [-s SEED] [--noise FILE.npy] -o OUT.png",
                                  desc, pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    g3d_sd_params p;
    int rc = sd_cli_params(&c, &p, "txt2img");
    if (rc) return rc;
    if (c.width < 8 || c.height < 8 || c.width % 8 || c.height % 8)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "-W %d -H %d: width and height must be positive multiples of 8", c.width, c.height);
    g3d_sd *m = NULL;
    g3d_array noise = {0};
    g3d_image img = {0};
    rc = sd_cli_prepare(&c, &p, &m, &noise, c.width, c.height);
    if (rc == G3D_EXIT_OK) {
        p.width = c.width;
        p.height = c.height;
        g3d_status st = g3d_sd_txt2img(m, &p, &img);
        rc = st == G3D_OK ? sd_cli_save(&c, &img) : g3d_cli_fail(st);
    }
    g3d_image_free(&img);
    g3d_array_free(&noise);
    g3d_sd_free(m);
    return rc;
}

/* The picture with its masked pixels filled by LaMa, for the ControlNet's hint (the "inpaint +
 * LaMa" recipe). */
static g3d_status lama_prefill(const sd_cli *c, const g3d_image *img, const g3d_image *mask, g3d_image *pre)
{
    g3d_inpainter lama = {0};
    g3d_image bin = {0};
    g3d_status rc = g3d_inpainter_lama_create(c->prefill_lama, &lama);
    if (rc == G3D_OK) rc = g3d_image_clone(pre, img);
    if (rc == G3D_OK) rc = g3d_image_clone(&bin, mask);
    for (size_t i = 0; rc == G3D_OK && i < g3d_image_size(&bin); i++) bin.data[i] = bin.data[i] > 0.5f;
    if (rc == G3D_OK) rc = lama.inpaint(lama.ctx, pre, &bin, NULL, 0);
    g3d_inpainter_free(&lama);
    g3d_image_free(&bin);
    return rc;
}

int g3d_sd_cli_inpaint(int argc, char **argv)
{
    sd_cli c;
    sd_cli_init(&c);
    g3d_opt opts[] = {
        SD_OPTS(&c),
        {'i', "image", G3D_OPT_STRING, &c.image, "IMAGE", "the picture (PNG or JPEG)"},
        {0, "mask", G3D_OPT_STRING, &c.mask, "MASK", "what to fill: white (> 50 %) pixels, same size as the picture"},
        {0, "controlnet", G3D_OPT_STRING, &c.paths.controlnet, "CN", "inpainting ControlNet (control_v11p_sd15_inpaint.pth)"},
        {0, "control-scale", G3D_OPT_DOUBLE, &c.control_scale, "S", "the ControlNet's strength"},
        {0, "prefill-lama", G3D_OPT_STRING, &c.prefill_lama, "CKPT", "fill the ControlNet's hint with LaMa (big-lama best.ckpt) first"},
        G3D_COMMON_OPTS(&c.common),
    };
    char desc[2048];
    snprintf(desc, sizeof desc,
             "Fills the white pixels of a mask with content for a prompt. An inpainting model (9 input\n"
             "channels) sees the mask and the masked picture; a text-to-image model inpaints by latent\n"
             "blending (said on stderr). The known pixels are pasted back, with an 8-pixel feathered seam\n"
             "inside the mask. The picture's sides must be multiples of 64 for SD (the VAE's 8 times the\n"
             "UNet's three halvings).\n"
             "--controlnet adds an inpainting ControlNet (control_v11p_sd15_inpaint, for SD 1.x; the\n"
             "diffusers folder too) to every step; its hint is the picture with the masked pixels at -1,\n"
             "or, with --prefill-lama, with them filled by LaMa first.\n%s", DESC_COMMON);
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts),
                                  "gen3d inpaint -m MODEL -i IMAGE --mask MASK -p PROMPT [-n NEGATIVE] [--steps N] [--cfg S] "
                                  "[--sampler NAME] [--controlnet CN [--control-scale S] [--prefill-lama CKPT]] [-s SEED] -o OUT.png",
                                  desc, pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    g3d_sd_params p;
    int rc = sd_cli_params(&c, &p, "inpaint");
    if (rc) return rc;
    if (!c.image || !c.mask) return g3d_cli_errorf(G3D_EXIT_USAGE, "-i IMAGE and --mask MASK are required");
    if ((c.prefill_lama || c.control_scale != 1.0) && !c.paths.controlnet)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "%s is for a --controlnet", c.prefill_lama ? "--prefill-lama" : "--control-scale");
    if (!(c.control_scale >= 0 && c.control_scale <= 10)) return g3d_cli_errorf(G3D_EXIT_USAGE, "--control-scale must be 0 to 10");
    p.control_scale = (float)c.control_scale;
    g3d_image img = {0}, mask = {0}, out = {0}, pre = {0};
    g3d_status st = g3d_image_load(c.image, 3, &img);
    if (st == G3D_OK) st = g3d_image_load(c.mask, 1, &mask);
    if (st != G3D_OK) return g3d_cli_fail(st);
    g3d_sd *m = NULL;
    g3d_array noise = {0};
    if (mask.w != img.w || mask.h != img.h)
        rc = g3d_cli_errorf(G3D_EXIT_FAIL, "%s: the mask is %dx%d, the picture %dx%d", c.mask, mask.w, mask.h, img.w, img.h);
    else
        rc = sd_cli_prepare(&c, &p, &m, &noise, img.w, img.h);
    if (rc == G3D_EXIT_OK) {
        if (g3d_sd_get_unet(m)->in_ch == 4)
            g3d_log(G3D_LOG_INFO, "%s is a text-to-image model: inpainting by latent blending", c.paths.model);
        st = c.prefill_lama ? lama_prefill(&c, &img, &mask, &pre) : G3D_OK;
        if (pre.data) p.prefill = &pre;
        if (st == G3D_OK) st = g3d_sd_inpaint(m, &p, &img, &mask, &out);
        rc = st == G3D_OK ? sd_cli_save(&c, &out) : g3d_cli_fail(st);
    }
    g3d_image_free(&img);
    g3d_image_free(&mask);
    g3d_image_free(&out);
    g3d_image_free(&pre);
    g3d_array_free(&noise);
    g3d_sd_free(m);
    return rc;
}
