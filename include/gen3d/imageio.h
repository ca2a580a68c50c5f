/* gen3d/imageio.h - reading and writing image files.
 *
 * Readers take PNG (8 or 16 bits, grey / grey+alpha / RGB / RGBA) and JPEG, check the
 * header before decoding (sides above G3D_MAX_IMAGE_SIDE are rejected), and return a
 * g3d_image with values in [0, 1]. Alpha is dropped. Errors name the file. JPEG files decode
 * to exactly the pixels PIL and OpenCV decode (libjpeg-turbo with their settings), so a model
 * sees what its official code sees; EXIF orientation is not applied; truncated and CMYK files
 * are refused.
 *
 * The PNG writer is our own (zlib deflate), so 8- and 16-bit output share one code path.
 * Writes are atomic: a failed write leaves nothing under the final name.
 */
#ifndef G3D_IMAGEIO_H
#define G3D_IMAGEIO_H

#include "gen3d/image.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Reads an image file as `channels` channels (1 = grey, 3 = RGB; 0 = as stored, with alpha
 * dropped). *img is created by the call (free with g3d_image_free). */
g3d_status g3d_image_load(const char *path, int channels, g3d_image *img);

/* Reads a 16-bit single-channel PNG (e.g. a depth map) as raw integer values 0..65535 in a
 * float image. 8-bit files are rejected: depth needs 16 bits. */
g3d_status g3d_image_load_u16(const char *path, g3d_image *img);

/* Writes img (1 or 3 channels, values clamped to [0, 1]) as PNG with `bits` = 8 or 16. */
g3d_status g3d_image_save_png(const char *path, const g3d_image *img, int bits);

/* Writes raw 16-bit values (rounded, clamped to 0..65535) of a 1- or 3-channel image. */
g3d_status g3d_image_save_png_u16(const char *path, const g3d_image *img);

/* Encodes interleaved samples as a PNG file in memory: w x h, c channels (1 or 3), bits 8 or
 * 16, samples given as integers in `px` (uint8_t for 8 bits, uint16_t for 16 bits).
 * *out is malloc'd (caller frees). */
g3d_status g3d_png_encode(const void *px, int w, int h, int c, int bits, unsigned char **out, size_t *out_n);

#ifdef __cplusplus
}
#endif
#endif /* G3D_IMAGEIO_H */
