/* depth_moge.h - the MoGe-2 branch of `gen3d depth` (metric depth and the predicted camera). */
#ifndef G3D_DEPTH_MOGE_H
#define G3D_DEPTH_MOGE_H

#include "gen3d/moge.h"   /* G3D_MOGE_MAX_TOKENS for the option check */

/* Runs MoGe-2 from checkpoint `model` on image `input`, saves metric depth (0 = invalid) to
 * `output` and, when intrinsics_out is non-NULL, the predicted camera as JSON. num_tokens <= 0:
 * the model's default. Returns a CLI exit code; on failure nothing is left behind. */
int g3d_cli_depth_moge(const char *model, const char *input, const char *output, int num_tokens,
                       const char *intrinsics_out);

#endif /* G3D_DEPTH_MOGE_H */
