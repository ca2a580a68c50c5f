/* generate's text and diffusion options, and the model-kind check of every model flag. */
#include "diffusion_opts.h"

#include "gen3d/clip_text.h"
#include "gen3d/recognize.h"

#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

void g3d_cli_diffusion_init(g3d_cli_diffusion *d)
{
    g3d_sd_view_params v;
    g3d_sd_view_params_default(&v);
    memset(d, 0, sizeof *d);
    d->parts.prediction = -1;
    d->negative = v.sd.negative;
    d->sampler = g3d_sd_sampler_name(v.sd.sampler.kind);
    d->steps = v.sd.sampler.steps;
    d->cfg = v.sd.cfg;
    d->size = v.size;
}

int g3d_cli_diffusion_check(const g3d_cli_diffusion *d, int rgb, int depth_model)
{
    g3d_sd_params p = g3d_sd_defaults();
    int rc = g3d_sd_cli_sampling(d->sampler, d->steps, "--sd-steps", d->cfg, d->eta, d->karras, &p);
    if (rc) return rc;
    if (d->prompt && !d->prompt[strspn(d->prompt, " \t\r\n")]) return g3d_cli_errorf(G3D_EXIT_USAGE, "-p PROMPT may not be empty");
    if (d->size < 8 || d->size > 4096) return g3d_cli_errorf(G3D_EXIT_USAGE, "--sd-size must be in 8..4096");
    if (d->sd_model && !d->prompt) return g3d_cli_errorf(G3D_EXIT_USAGE, "--sd-model draws the first image from -p PROMPT: give one");
    if (d->sd_model && rgb) return g3d_cli_errorf(G3D_EXIT_USAGE, "--sd-model draws the first image: no -i");
    if (d->sd_model && !depth_model)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "text input needs --depth-model (MoGe-2) for the drawn image's depth and camera");
    if (d->controlnet && !d->inpaint_model) return g3d_cli_errorf(G3D_EXIT_USAGE, "--controlnet needs --inpaint-model (its base model)");
    if (!d->sd_model && !d->inpaint_model && (d->parts.vae || d->parts.text_encoder || d->parts.tokenizer || d->parts.yaml))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--vae, --text-encoder, --tokenizer and --sd-config go with --sd-model or --inpaint-model");
    return 0;
}

void g3d_cli_diffusion_apply(const g3d_cli_diffusion *d, g3d_generate_params *p)
{
    g3d_sd_cli_sampling(d->sampler, d->steps, "--sd-steps", d->cfg, d->eta, d->karras, &p->diffusion.sd);
    p->diffusion.sd.negative = d->negative;
    p->diffusion.size = d->size;
    p->prompt = d->prompt;
    p->sd_model = d->sd_model;
    p->inpaint_model = d->inpaint_model;
    p->controlnet_model = d->controlnet;
    p->sd_parts = d->parts;
    if (d->prompt && !d->sd_model && !d->inpaint_model)
        g3d_log(G3D_LOG_WARN, "the prompt is not used: without --inpaint-model the views are filled by an inpainter that "
                              "takes no text");
    if (d->inpaint_model && p->lama_model && !d->controlnet)
        g3d_log(G3D_LOG_WARN, "--lama-model is not used: --inpaint-model fills the views and the background");
}

static const char *kind_name(g3d_model_kind k)
{
    switch (k) {
    case G3D_MODEL_DEPTH_ANYTHING_V2: return "a Depth Anything V2 depth model";
    case G3D_MODEL_MOGE: return "a MoGe depth model";
    case G3D_MODEL_CLIP_TEXT: return "a CLIP text encoder without a UNet";
    case G3D_MODEL_LAMA: return "a LaMa inpainter";
    case G3D_MODEL_SAM: return "a Segment Anything model";
    case G3D_MODEL_STABLE_DIFFUSION: return "a Stable Diffusion model";
    case G3D_MODEL_CONTROLNET: return "a ControlNet";
    default: return "no model gen3d recognises";
    }
}

/* 0 when the file at `path` (for `flag`) holds a model of kind a or b (b may be a); else one
 * line and G3D_EXIT_FAIL. A folder is left to the loader (a diffusers layout). in_ch > 0: a
 * Stable Diffusion UNet must have that many input channels. */
static int check_kind(const char *flag, const char *path, g3d_model_kind a, g3d_model_kind b, int in_ch, const char *want)
{
    struct stat st;
    if (!path || (stat(path, &st) == 0 && S_ISDIR(st.st_mode))) return 0;
    g3d_ckpt *ck;
    if (g3d_ckpt_open(path, &ck) != G3D_OK) return g3d_cli_errorf(G3D_EXIT_FAIL, "%s: %s", flag, g3d_error_message());
    g3d_model_kind k = g3d_model_recognize(ck);
    int rc = 0;
    g3d_sd_unet_config c;
    if (k != a && k != b) {
        rc = g3d_cli_errorf(G3D_EXIT_FAIL, "%s %s: %s, not %s", flag, path, kind_name(k), want);
    } else if (in_ch && g3d_sd_unet_probe(ck, NULL, &c) == G3D_OK && c.in_ch != in_ch) {
        rc = g3d_cli_errorf(G3D_EXIT_FAIL, "%s %s: an inpainting UNet (%d input channels) cannot draw from text alone; it "
                                           "goes to --inpaint-model", flag, path, c.in_ch);
    }
    g3d_error_clear();
    g3d_ckpt_free(ck);
    return rc;
}

/* 0 when the ControlNet file fits the inpainting model's UNet (both single files; folders are
 * left to the loader); else one line naming --controlnet and the file, G3D_EXIT_FAIL. */
static int check_controlnet_fits(const char *cn_path, const char *unet_path)
{
    struct stat st;
    if (!cn_path || !unet_path || stat(cn_path, &st) != 0 || S_ISDIR(st.st_mode) || stat(unet_path, &st) != 0 || S_ISDIR(st.st_mode))
        return 0;
    g3d_ckpt *cn = NULL, *un = NULL;
    g3d_sd_controlnet_config cc;
    g3d_sd_unet_config uc;
    char *yaml = g3d_sd_yaml_beside(unet_path);
    int rc = 0;
    if (g3d_ckpt_open(cn_path, &cn) == G3D_OK && g3d_ckpt_open(unet_path, &un) == G3D_OK &&
        g3d_sd_controlnet_probe(cn, NULL, &cc) == G3D_OK && g3d_sd_unet_probe(un, yaml, &uc) == G3D_OK &&
        g3d_sd_controlnet_check(&cc, cn_path, &uc) != G3D_OK)
        rc = g3d_cli_errorf(G3D_EXIT_FAIL, "--controlnet %s", g3d_error_message());
    g3d_error_clear();
    free(yaml);
    g3d_ckpt_free(cn);
    g3d_ckpt_free(un);
    return rc;
}

int g3d_cli_check_models(const g3d_generate_params *p)
{
    const g3d_model_kind sd = G3D_MODEL_STABLE_DIFFUSION;
    int rc = check_kind("--depth-model", p->depth_model, G3D_MODEL_MOGE, G3D_MODEL_DEPTH_ANYTHING_V2, 0,
                        "a depth model (MoGe-2 or Depth Anything V2)");
    if (!rc) rc = check_kind("--sd-model", p->sd_model, sd, sd, 4, "a Stable Diffusion text-to-image model");
    if (!rc) rc = check_kind("--inpaint-model", p->inpaint_model, sd, sd, 0, "a Stable Diffusion inpainting model");
    if (!rc) rc = check_kind("--controlnet", p->controlnet_model, G3D_MODEL_CONTROLNET, G3D_MODEL_CONTROLNET, 0,
                             "an inpainting ControlNet (control_v11p_sd15_inpaint)");
    if (!rc) rc = check_controlnet_fits(p->controlnet_model, p->inpaint_model);
    if (!rc) rc = check_kind("--lama-model", p->lama_model, G3D_MODEL_LAMA, G3D_MODEL_LAMA, 0, "a LaMa checkpoint (big-lama best.ckpt)");
    if (!rc) rc = check_kind("--seg-model", p->seg_model, G3D_MODEL_SAM, G3D_MODEL_SAM, 0, "a Segment Anything checkpoint");
    if (!rc && p->sd_parts.tokenizer && (p->sd_model || p->inpaint_model)) {
        g3d_clip_tokenizer *tok;
        if (g3d_clip_tokenizer_load(p->sd_parts.tokenizer, &tok) != G3D_OK)
            return g3d_cli_errorf(G3D_EXIT_FAIL, "--tokenizer: %s", g3d_error_message());
        g3d_clip_tokenizer_free(tok);
    }
    return rc;
}
