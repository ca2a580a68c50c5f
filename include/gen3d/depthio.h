/* gen3d/depthio.h - depth maps on disk (numeric arrays in general: npy.h).
 *
 * Every reader returns depth as a 1-channel g3d_image in metres with 0 = invalid: zero,
 * negative, NaN and infinite values in the file all become 0. Errors name the file.
 *
 * Formats:
 *   .png  16-bit grey; metres = value / scale (1000 = millimetres, 5000 = TUM, 256 = KITTI);
 *         0 is invalid.
 *   .pfm  Portable Float Map, "Pf" (grey) header; the sign of the scale gives the byte order
 *         (negative = little-endian); rows are stored bottom-to-top. Values are metres.
 *   .npy  NumPy array of shape (H, W) or (H, W, 1): float32, float16, float64 or uint16,
 *         either byte order, C order. Values are metres (uint16 is divided by `scale`).
 *   .npz  a zip of .npy members; `member` picks one (NULL = "arr_0", else the first).
 */
#ifndef G3D_DEPTHIO_H
#define G3D_DEPTHIO_H

#include "gen3d/image.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Loads a depth map by file extension (.png .pfm .npy .npz); `scale` divides the stored
 * values of 16-bit PNG and uint16 NPY (pass 0 for the default of 1000, i.e. millimetres). */
g3d_status g3d_depth_load(const char *path, double scale, g3d_image *depth);
/* The same without the cleaning: NaN, infinite, zero and negative values are kept as stored,
 * for callers that must tell a missing value from a corrupt one (ground truth). */
g3d_status g3d_depth_load_raw(const char *path, double scale, g3d_image *depth);
/* Raw float map (PFM) without the invalid-value cleaning, e.g. a disparity map where inf
 * marks missing values; NaN/inf are kept. */
g3d_status g3d_pfm_load(const char *path, g3d_image *img);
/* Saves depth by extension: .png (16-bit millimetres, rounded), .pfm, .npy (float32 metres). */
g3d_status g3d_depth_save(const char *path, const g3d_image *depth);

/* Replaces 0, negative, NaN and infinite values by 0; returns the fraction of valid pixels. */
double g3d_depth_sanitize(g3d_image *depth);

/* Converts a disparity map (pixels) into depth (metres): Z = baseline * f / (d + doffs),
 * invalid where d is not finite or d + doffs <= 0. baseline in metres, f in pixels. In place. */
void g3d_disparity_to_depth(g3d_image *disp, double f, double baseline, double doffs);

#ifdef __cplusplus
}
#endif
#endif /* G3D_DEPTHIO_H */
