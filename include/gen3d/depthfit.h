/* gen3d/depthfit.h - aligning a depth network's prediction to depth that is already known.
 *
 * Relative-depth networks (Depth Anything V2 relative) predict an affine-invariant inverse
 * depth ("disparity" up to an unknown scale and shift); metric networks predict metres that
 * are still off by a small scale and offset. Both are brought onto known metric depth with a
 * least-squares fit of scale s and shift t over the pixels where the known depth is valid:
 *   G3D_FIT_INVERSE:  s * pred + t ~= 1 / known     (relative models)
 *   G3D_FIT_DEPTH:    s * pred + t ~= known         (metric models)
 * The fit is plain least squares in double precision, summed in pixel order (deterministic);
 * it is not robust to outliers, so callers should pass only pixels they trust.
 */
#ifndef G3D_DEPTHFIT_H
#define G3D_DEPTHFIT_H

#include "gen3d/base.h"

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum g3d_fit_space { G3D_FIT_INVERSE, G3D_FIT_DEPTH } g3d_fit_space;

/* Fits s, t over the n pixels where known[i] > 0 (metres; 0 = unknown). pred [n] is the
 * network output, known [n] metric depth. Errors: G3D_ERR_ARG when known or pred holds a
 * non-finite value at a used pixel, when fewer than 2 pixels are known, or when pred is
 * constant over them (scale undetermined); *s and *t are then left untouched.
 * Thread-safe. */
g3d_status g3d_depthfit_affine(const float *pred, const float *known, size_t n, g3d_fit_space space, double *s,
                               double *t);

/* Writes metric depth [n] (metres) from pred [n] with a fitted s, t: s*pred + t, inverted for
 * G3D_FIT_INVERSE. Pixels whose result is not a positive finite depth (beyond the horizon of
 * the fit) get 0 = invalid. depth may equal pred. */
void g3d_depthfit_apply(const float *pred, size_t n, g3d_fit_space space, double s, double t, float *depth);

#ifdef __cplusplus
}
#endif
#endif /* G3D_DEPTHFIT_H */
