/* gen3d/membrane.h - harmonic ("membrane") interpolation: fills unknown pixels of a scalar
 * field so that it is smooth (Laplace equation) and equal to the known values where they are
 * given. Image borders are free (zero normal derivative), so a hole touching the border
 * continues the field flatly rather than pulling it to zero.
 *
 * Solved coarse to fine: the known values are averaged down a pyramid, the coarsest level is
 * relaxed to convergence, and each finer level starts from the upsampled solution and is
 * relaxed with red-black successive over-relaxation. Deterministic.
 */
#ifndef G3D_MEMBRANE_H
#define G3D_MEMBRANE_H

#include "gen3d/image.h"

#ifdef __cplusplus
extern "C" {
#endif

/* values: (h, w), known: (h, w) non-zero where values[i] is given. Unknown entries are
 * overwritten; known ones are left bit-identical. Fails if nothing is known. */
g3d_status g3d_membrane_fill(float *values, const uint8_t *known, int w, int h);

/* The same for fields with a trend: a least-squares plane a x + b y + c is fitted to the known
 * values selected by `fit` (NULL: all known), and only the residual is interpolated
 * harmonically. Inside holes the result still meets the known values; across wide holes and
 * towards free borders it follows the plane instead of flattening out. Known values are kept
 * up to float rounding. */
g3d_status g3d_membrane_fill_planar(float *values, const uint8_t *known, const uint8_t *fit, int w, int h);

#ifdef __cplusplus
}
#endif
#endif /* G3D_MEMBRANE_H */
