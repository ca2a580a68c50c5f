/* gen3d/image.h - the float image type every stage passes around.
 *
 * LAYOUT
 *   Row-major, top-left pixel first, channels interleaved, no row padding:
 *       value(x, y, ch) = data[((size_t)y * w + x) * c + ch]
 *   Colour: c = 3 (RGB) or 1 (grey), values in [0, 1].
 *   Depth:  c = 1, metres along the camera z axis; 0 means invalid (NaN/inf never get past
 *   the readers). Masks: c = 1, 0 or 1.
 *
 * OWNERSHIP
 *   g3d_image_create allocates `data`; g3d_image_free releases it and zeroes the struct.
 *   A zeroed struct is an empty image and may be freed.
 */
#ifndef G3D_IMAGE_H
#define G3D_IMAGE_H

#include "gen3d/base.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_image {
    int w, h, c;  /* width, height, channels */
    float *data;  /* (h, w, c) */
} g3d_image;

/* Allocates a zero-filled w x h x c image. Rejects sides outside 1..G3D_MAX_IMAGE_SIDE. */
g3d_status g3d_image_create(g3d_image *img, int w, int h, int c);
/* Frees the pixels and zeroes the struct. NULL and empty images are fine. */
void g3d_image_free(g3d_image *img);
/* Deep copy into dst (dst is overwritten, not freed first). */
g3d_status g3d_image_clone(g3d_image *dst, const g3d_image *src);
/* Number of floats (w*h*c). */
size_t g3d_image_size(const g3d_image *img);

static inline float *g3d_image_px(const g3d_image *img, int x, int y)
{
    return img->data + ((size_t)y * (size_t)img->w + (size_t)x) * (size_t)img->c;
}

#ifdef __cplusplus
}
#endif
#endif /* G3D_IMAGE_H */
