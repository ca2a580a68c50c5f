/* gen3d/depth_complete.h - weight-free depth for the pixels of a view that nothing covers.
 *
 * Completion works in inverse depth, where a plane is an affine function of the pixel
 * coordinates: a plane is fitted (least squares) to the known inverse depth in a band around
 * the holes, and the residual is interpolated harmonically (membrane.h). Inside a hole the
 * result is smooth and matches the known depth at its rim; where a hole reaches the image
 * border the fitted plane carries the surface on (a floor keeps receding) instead of the
 * depth freezing at its last value, within the depth range found on the holes' rim.
 */
#ifndef G3D_DEPTH_COMPLETE_H
#define G3D_DEPTH_COMPLETE_H

#include "gen3d/providers.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Fills the pixels of depth (h, w, 1) that are 0 (or where fill_mask > 0.5 if fill_mask is
 * given) from the others. Fails when no pixel is known. */
g3d_status g3d_depth_complete(g3d_image *depth, const g3d_image *fill_mask);

/* The completion as a depth estimator (providers.h): it needs `known` depth and completes the
 * masked pixels; it cannot estimate depth from colour alone (no known depth = error). It holds
 * no state; release with g3d_depth_estimator_free all the same. Cannot fail. */
g3d_status g3d_depth_estimator_completion_create(g3d_depth_estimator *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_DEPTH_COMPLETE_H */
