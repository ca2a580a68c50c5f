/* gen3d/loss.h - the photometric training loss of 3D Gaussian splatting, PSNR, and the
 * evaluation SSIM.
 *
 *   L = (1 - lambda) * L1 + lambda * (1 - SSIM)
 *
 * L1 and SSIM are both means over the VALID pixels only (mask value > 0.5) and all channels,
 * so views reprojected from another camera train only where they carry information.
 * SSIM follows the reference 3DGS implementation: per channel, 11x11 Gaussian window with
 * sigma 1.5, C1 = 0.01^2, C2 = 0.03^2, the local statistics computed over the whole image
 * with zero padding outside it ('same' convolution); only the averaging of the SSIM map is
 * masked. All arithmetic is in double precision with fixed-order loops (deterministic).
 *
 * Images: g3d_image (image.h), same w/h/c for pred and target; mask c = 1, same w/h, or NULL
 * for "all pixels valid".
 */
#ifndef G3D_LOSS_H
#define G3D_LOSS_H

#include "gen3d/image.h"

#ifdef __cplusplus
extern "C" {
#endif

#define G3D_LOSS_LAMBDA_SSIM 0.2

/* Loss value and, optionally, its gradient with respect to every value of `pred`.
 *   pred, target: (h, w, c) images;  mask: (h, w, 1) or NULL.
 *   lambda:  SSIM weight in [0, 1] (G3D_LOSS_LAMBDA_SSIM is the 3DGS default).
 *   loss:    out, the scalar loss.
 *   ssim:    out (may be NULL), the masked mean SSIM.
 *   grad:    NULL, or a caller-owned image of pred's shape that receives dL/dpred
 *            (overwritten, not accumulated).
 * Fails with G3D_ERR_MISMATCH on shape disagreement, G3D_ERR_ARG when no pixel is valid or
 * lambda is out of range; outputs are untouched on failure. Thread-safe (allocates its own
 * scratch). */
g3d_status g3d_loss_fwd_bwd(const g3d_image *pred, const g3d_image *target,
                            const g3d_image *mask, double lambda, double *loss, double *ssim,
                            g3d_image *grad);

/* Peak signal-to-noise ratio in dB for values in [0, 1], over the valid pixels (mask > 0.5,
 * or all when mask is NULL) and all channels: 10 log10(1 / MSE). An exact match gives
 * +infinity. Same failure cases as g3d_loss_fwd_bwd. */
g3d_status g3d_psnr(const g3d_image *pred, const g3d_image *target, const g3d_image *mask,
                    double *psnr);

/* SSIM as image-quality evaluations report it (Wang et al. 2004; scikit-image's
 * structural_similarity with gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
 * data_range=1, and pytorch-msssim's ssim with data_range=1 compute the same number): per
 * channel, 11x11 Gaussian window with sigma 1.5, population statistics, C1 = 0.01^2,
 * C2 = 0.03^2; the SSIM map is averaged over the pixels whose whole window lies inside the
 * image (a 5-pixel border is left out) and, with a mask, whose mask value is > 0.5; then over
 * the channels. Unlike the training loss above, the border never enters.
 * Errors: as g3d_psnr, and G3D_ERR_ARG for images under 11x11 or a mask with no valid pixel
 * inside the border. Thread-safe. */
g3d_status g3d_ssim(const g3d_image *a, const g3d_image *b, const g3d_image *mask, double *ssim);

#ifdef __cplusplus
}
#endif
#endif /* G3D_LOSS_H */
