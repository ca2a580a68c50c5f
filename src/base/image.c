/* The g3d_image container: allocation, copy, release. */
#include "gen3d/image.h"

#include <stdlib.h>
#include <string.h>

size_t g3d_image_size(const g3d_image *img) { return (size_t)img->w * (size_t)img->h * (size_t)img->c; }

g3d_status g3d_image_create(g3d_image *img, int w, int h, int c)
{
    memset(img, 0, sizeof *img);
    if (w < 1 || h < 1 || w > G3D_MAX_IMAGE_SIDE || h > G3D_MAX_IMAGE_SIDE || c < 1 || c > 16)
        return G3D_ERR(G3D_ERR_ARG, "image size %dx%dx%d out of range (sides 1..%d)", w, h, c, G3D_MAX_IMAGE_SIDE);
    img->data = g3d_calloc((size_t)w * (size_t)h * (size_t)c, sizeof(float), "image");
    if (!img->data) return G3D_ERR_NOMEM;
    img->w = w;
    img->h = h;
    img->c = c;
    return G3D_OK;
}

void g3d_image_free(g3d_image *img)
{
    if (!img) return;
    free(img->data);
    memset(img, 0, sizeof *img);
}

g3d_status g3d_image_clone(g3d_image *dst, const g3d_image *src)
{
    G3D_TRY(g3d_image_create(dst, src->w, src->h, src->c));
    memcpy(dst->data, src->data, g3d_image_size(src) * sizeof(float));
    return G3D_OK;
}
