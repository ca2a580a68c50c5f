/* sd_opts.h - the Stable Diffusion commands' logic (gen3d txt2img, gen3d inpaint -m MODEL),
 * kept out of the command files so that an inpaint command with other back ends can call it. */
#ifndef G3D_SD_OPTS_H
#define G3D_SD_OPTS_H

#include "gen3d/sd.h"

/* The sampling options (the fields: double cfg, const char *sampler, int karras, double eta). */
#define G3D_SD_SAMPLING_OPTS(cfg, sampler, karras, eta)                                                           \
    {0, "cfg", G3D_OPT_DOUBLE, cfg, "S", "classifier-free guidance scale (1: none)"},                             \
    {0, "sampler", G3D_OPT_STRING, sampler, "NAME", "ddim, pndm, plms, euler, euler_a or dpmpp_2m"},                  \
    {0, "karras", G3D_OPT_FLAG, karras, NULL, "Karras sigmas (euler, euler_a, dpmpp_2m)"},                        \
    {0, "eta", G3D_OPT_DOUBLE, eta, "E", "DDIM's eta (0: deterministic)"}

/* The options naming a model's parts in other files (paths: a g3d_sd_paths *); config_name is
 * the long name of the yaml option. */
#define G3D_SD_PARTS_OPTS(paths, config_name)                                                                     \
    {0, "vae", G3D_OPT_PATH, &(paths)->vae, "FILE", "the VAE from this file"},                                    \
    {0, "text-encoder", G3D_OPT_PATH, &(paths)->text_encoder, "FILE", "the text encoder from this file"},         \
    {0, "tokenizer", G3D_OPT_PATH, &(paths)->tokenizer, "DIR|FILE", "CLIP vocabulary (default: OpenAI's)"},       \
    {0, config_name, G3D_OPT_PATH, &(paths)->yaml, "YAML", "the model's original configuration (default: MODEL.yaml)"}

/* gen3d txt2img: argv[0] is the command name. Returns the exit code. */
int g3d_sd_cli_txt2img(int argc, char **argv);
/* gen3d inpaint with a Stable Diffusion model (-m MODEL -i IMAGE --mask MASK -p PROMPT). */
int g3d_sd_cli_inpaint(int argc, char **argv);

/* Checks the sampling options (sampler name, steps, guidance, eta, Karras sigmas; steps_flag
 * names the steps option in messages) and sets p->sampler and p->cfg. Returns G3D_EXIT_OK or
 * G3D_EXIT_USAGE after reporting the problem. */
int g3d_sd_cli_sampling(const char *sampler, int steps, const char *steps_flag, double cfg, double eta, int karras,
                        g3d_sd_params *p);

#endif
