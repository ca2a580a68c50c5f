/* gen3d inpaint: fills a masked region of a picture (Stable Diffusion with -m, sd_opts.c). */
#include "cli.h"
#include "sd_opts.h"

const g3d_command g3d_cmd_inpaint = {"inpaint", "fill a masked region of a picture (Stable Diffusion)", g3d_sd_cli_inpaint};
