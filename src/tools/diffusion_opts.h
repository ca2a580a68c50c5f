/* diffusion_opts.h - generate's text and diffusion options (text input, the inpainting model,
 * prompts, sampling), and the check that every model flag names a model of its kind. */
#ifndef G3D_DIFFUSION_OPTS_H
#define G3D_DIFFUSION_OPTS_H

#include "cli.h"
#include "gen3d/generate.h"
#include "sd_opts.h"

typedef struct g3d_cli_diffusion {
    const char *prompt, *negative, *sampler, *sd_model, *inpaint_model, *controlnet;
    g3d_sd_paths parts;          /* vae, text_encoder, tokenizer, yaml for both models */
    int steps, karras, size;
    double cfg, eta;
} g3d_cli_diffusion;

#define G3D_DIFFUSION_OPTS(d)                                                                                     \
    {'p', "prompt", G3D_OPT_STRING, &(d)->prompt, "TEXT", "text input with --sd-model; else the views' inpainting prompt"}, \
    {'n', "negative", G3D_OPT_STRING, &(d)->negative, "TEXT", "what the diffusion models avoid (negative prompt)"}, \
    {0, "sd-model", G3D_OPT_PATH, &(d)->sd_model, "MODEL", "text input: Stable Diffusion text-to-image model drawing the first image"}, \
    {0, "inpaint-model", G3D_OPT_PATH, &(d)->inpaint_model, "MODEL", "Stable Diffusion (inpainting) model filling the new views and the background"}, \
    {0, "controlnet", G3D_OPT_PATH, &(d)->controlnet, "MODEL", "inpainting ControlNet for the background (with --inpaint-model; its hint prefilled by --lama-model, else the classical inpainter)"}, \
    {0, "sd-steps", G3D_OPT_INT, &(d)->steps, "N", "denoising steps per image"},                                \
    G3D_SD_SAMPLING_OPTS(&(d)->cfg, &(d)->sampler, &(d)->karras, &(d)->eta),                                      \
    {0, "sd-size", G3D_OPT_INT, &(d)->size, "PX", "longer side the diffusion models draw at (their native size)"}, \
    G3D_SD_PARTS_OPTS(&(d)->parts, "sd-config")

/* The library's defaults (g3d_sd_view_params_default). */
void g3d_cli_diffusion_init(g3d_cli_diffusion *d);
/* Usage checks (rgb: -i was given, depth_model: --depth-model was); returns 0 or G3D_EXIT_USAGE
 * after printing the problem. */
int g3d_cli_diffusion_check(const g3d_cli_diffusion *d, int rgb, int depth_model);
/* Copies the options into the pipeline's parameters; warns when the prompt has no model to use it. */
void g3d_cli_diffusion_apply(const g3d_cli_diffusion *d, g3d_generate_params *p);
/* Checks that each model flag of p names a model of its kind (--depth-model, --sd-model,
 * --inpaint-model, --controlnet, --lama-model, --seg-model) and that --tokenizer loads: returns 0, or
 * G3D_EXIT_FAIL after one line naming the flag and the file. */
int g3d_cli_check_models(const g3d_generate_params *p);

#endif
