/* gen3d/nn_interp.h - resampling of feature maps with PyTorch's F.interpolate semantics.
 *
 * Feature maps are [C, H, W] float32, batch 1, channels first (the layout of gen3d/nn.h).
 * Sizes are given as output sizes (PyTorch's size= form), which is how the DPT heads call it.
 */
#ifndef G3D_NN_INTERP_H
#define G3D_NN_INTERP_H

#include "gen3d/base.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Bilinear resize x [c, h, w] -> y [c, ho, wo], matching
 * F.interpolate(x, size=(ho, wo), mode='bilinear', align_corners=align_corners):
 *   align_corners != 0: source = dst * (in - 1) / (out - 1)  (0 when out == 1),
 *   align_corners == 0: source = max((dst + 0.5) * in / out - 0.5, 0),
 * taps floor(source) and min(floor + 1, in - 1), weights computed in float as PyTorch does.
 * x and y must not overlap; the caller owns both. Returns G3D_ERR_ARG for non-positive sizes.
 * Thread-safe; parallel over channels with OpenMP (static schedule, deterministic). */
g3d_status g3d_nn_resize_bilinear(const float *x, int c, int h, int w, int ho, int wo, int align_corners,
                                  float *y);

#ifdef __cplusplus
}
#endif
#endif /* G3D_NN_INTERP_H */
