/* gen3d/loss.h - the photometric loss of 3D Gaussian splatting, restricted to valid pixels.
 *
 *   L = (1 - lambda) * L1 + lambda * (1 - SSIM),   lambda = 0.2 in the reference training
 *
 * SSIM follows the reference implementation: per channel, local means, variances and
 * covariance from an 11 x 11 Gaussian window (sigma 1.5) with zero padding ("same" size),
 * C1 = 0.01^2, C2 = 0.03^2, and the SSIM map averaged. Both terms here average only over the
 * pixels where mask > 0.5 (the paper trains the extra reprojected views on their valid
 * pixels only); mask NULL means every pixel. The window itself still sees the neighbours'
 * values, as in the reference.
 *
 * Images are (h, w, 3) float, channels interleaved. Computed in double precision.
 */
#ifndef G3D_LOSS_H
#define G3D_LOSS_H

#include "gen3d/base.h"

#ifdef __cplusplus
extern "C" {
#endif

#define G3D_SSIM_WINDOW 11
#define G3D_SSIM_SIGMA 1.5

typedef struct g3d_loss_terms {
    double l1;       /* masked mean absolute error */
    double ssim;     /* masked mean SSIM */
    double loss;     /* (1 - lambda) l1 + lambda (1 - ssim) */
    int64_t valid;   /* pixels that counted */
} g3d_loss_terms;

/* Loss of `img` against `target`. If dimg is not NULL it receives dL/dimg (h, w, 3),
 * overwritten. Fails (G3D_ERR_ARG) when no pixel is valid. */
g3d_status g3d_loss_l1_dssim(const float *img, const float *target, const float *mask, int w, int h, double lambda,
                             float *dimg, g3d_loss_terms *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_LOSS_H */
