/* gen3d/resize.h - image resampling with the exact conventions of the tools that models were
 * trained with.
 *
 *   G3D_RESIZE_BILINEAR          PyTorch F.interpolate(mode='bilinear', align_corners=False):
 *                                src = (dst + 0.5) * in/out - 0.5, negative clamped to 0.
 *   G3D_RESIZE_BILINEAR_AC       the same with align_corners=True: src = dst * (in-1)/(out-1).
 *   G3D_RESIZE_BILINEAR_AA       PyTorch F.interpolate(mode='bilinear', align_corners=False,
 *                                antialias=True): output pixel o centred at (o + 0.5) * in/out
 *                                takes a triangle filter widened by in/out when shrinking (plain
 *                                bilinear support when enlarging), weights renormalised over the
 *                                taps that fall inside the image (no clamping).
 *   G3D_RESIZE_CUBIC_OPENCV      OpenCV cv2.resize INTER_CUBIC: Keys cubic with a = -0.75, taps
 *                                at floor(src)-1 .. +2, indices clamped (border replicate), no
 *                                antialiasing when shrinking.
 *   G3D_RESIZE_CUBIC_HALF        the same mapping with a = -0.5 (Catmull-Rom / PIL's kernel).
 *   G3D_RESIZE_AREA              box filter with fractional pixel coverage (OpenCV INTER_AREA
 *                                when shrinking); when enlarging it falls back to bilinear.
 *   G3D_RESIZE_NEAREST           the source pixel whose centre is nearest (for depth and masks,
 *                                where averaging across an edge would invent values).
 *
 * All modes are separable (rows first, then columns) and computed in double precision.
 * Channels are interleaved and resized independently.
 */
#ifndef G3D_RESIZE_H
#define G3D_RESIZE_H

#include "gen3d/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum g3d_resize_mode {
    G3D_RESIZE_BILINEAR,
    G3D_RESIZE_BILINEAR_AC,
    G3D_RESIZE_CUBIC_OPENCV,
    G3D_RESIZE_CUBIC_HALF,
    G3D_RESIZE_AREA,
    G3D_RESIZE_NEAREST,
    G3D_RESIZE_BILINEAR_AA,
    G3D_RESIZE_MODE_COUNT
} g3d_resize_mode;

/* Resizes a (sh, sw, c) interleaved buffer into (dh, dw, c) at dst (caller-allocated). */
g3d_status g3d_resize_buffer(const float *src, int sw, int sh, int c, float *dst, int dw, int dh, g3d_resize_mode mode);

/* PIL's Image.resize(BICUBIC) on 8-bit pixels, bit for bit (what torchvision's Resize does to a
 * PIL image, hence CLIP's and BLIP's preprocessing): Keys cubic a = -0.5 widened by the
 * shrink factor (antialiasing), coefficients in fixed point with 22 fractional bits, the
 * horizontal pass rounded to 8 bits before the vertical one. src (sh, sw, c) interleaved,
 * dst (dh, dw, c) caller-allocated. */
g3d_status g3d_resize_u8_pil_bicubic(const uint8_t *src, int sw, int sh, int c, uint8_t *dst, int dw, int dh);

/* The size (*ow, *oh) of a w x h picture scaled so that its longer side is max_side, each side
 * rounded to the nearest pixel and at least 1 (the size of a frame limited to max_side). */
void g3d_fit_size(int w, int h, int max_side, int *ow, int *oh);

/* Resizes src into a new image *dst of dw x dh (same channels). */
g3d_status g3d_image_resize(const g3d_image *src, int dw, int dh, g3d_resize_mode mode, g3d_image *dst);

/* PIL's Image.resize(..., Image.BILINEAR) of an 8-bit (sh, sw, c) picture into (dh, dw, c) at dst,
 * pixel for pixel: its antialiasing triangle filter, 22-bit fixed-point weights, rows first
 * through an 8-bit intermediate (what torchvision's resize does to a PIL image; SAM's
 * preprocessing). G3D_ERR_ARG for empty or oversized pictures. */
g3d_status g3d_resize_u8_pil_bilinear(const uint8_t *src, int sw, int sh, int c, uint8_t *dst, int dw, int dh);

#ifdef __cplusplus
}
#endif
#endif /* G3D_RESIZE_H */
