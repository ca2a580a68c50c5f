/* gen3d txt2img: a picture from a text prompt with Stable Diffusion (sd_opts.c). */
#include "cli.h"
#include "sd_opts.h"

const g3d_command g3d_cmd_txt2img = {"txt2img", "a picture from a text prompt (Stable Diffusion)", g3d_sd_cli_txt2img};
