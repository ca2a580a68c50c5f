/* sd_opts.h - the Stable Diffusion commands' logic (gen3d txt2img, gen3d inpaint -m MODEL),
 * kept out of the command files so that an inpaint command with other back ends can call it. */
#ifndef G3D_SD_OPTS_H
#define G3D_SD_OPTS_H

#include "gen3d/sd.h"

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
