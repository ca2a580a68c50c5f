/* gen3d/pointmap.h - a pinhole camera from a point map: the focal length and depth shift that
 * make a network's camera-space points a perspective projection of the image (MoGe's
 * recover_focal_shift), and the normalised view-plane coordinates it is expressed in.
 *
 * VIEW PLANE
 *   An image of aspect a = w / h is mapped to the plane z = 1 so that its half-diagonal has
 *   length 1: pixel column i (centre) sits at u_i, row j at v_j, with u spanning
 *   +-(a / sqrt(1 + a^2)) (w - 1) / w and v spanning +-(1 / sqrt(1 + a^2)) (h - 1) / h, sampled
 *   exactly as torch.linspace in float32 (MoGe's normalized_view_plane_uv). A focal length in
 *   these units is relative to half the image diagonal.
 */
#ifndef G3D_POINTMAP_H
#define G3D_POINTMAP_H

#include "gen3d/base.h"

#ifdef __cplusplus
extern "C" {
#endif

/* n >= 1 values from start to end as torch.linspace computes them in float32 (the first half
 * counts up from start, the second down from end), into out (n). */
void g3d_linspace_f(float start, float end, int n, float *out);

/* The view-plane coordinates of a w x h grid whose image has aspect `aspect` (w / h for the
 * image itself): u (w) and v (h), caller-allocated. */
void g3d_view_plane_uv(int w, int h, double aspect, float *u, float *v);

/* Fits the focal length f (view-plane units) and the z shift t that best explain points
 * (h, w, 3) as a projection: f * (x, y) / (z + t) ~= (u, v) in least squares, over a 64 x 64
 * nearest-neighbour subsample (PyTorch's index rule) of the pixels where mask (h, w) is
 * non-zero (mask NULL: all). focal > 0 fixes f and fits t only. t is found by
 * Levenberg-Marquardt from 0 following MINPACK's lmdif step for step with ftol = 1e-3, as the
 * official code does (its early stop makes the exact steps part of the result); f is then
 * recomputed in float32 at the float32 t. Fewer than 2 usable pixels give f = focal (or 1)
 * and t = 0. Errors: G3D_ERR_NOMEM only. Thread-safe. */
g3d_status g3d_pointmap_focal_shift(const float *points, const uint8_t *mask, int w, int h, double focal,
                                    float *focal_out, float *shift_out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_POINTMAP_H */
