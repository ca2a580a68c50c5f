/* The dataset reader: a camera file, the images and masks it names, and points.ply. */
#include "gen3d/dataset.h"
#include "gen3d/imageio.h"
#include "gen3d/resize.h"

#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

void g3d_dataset_free(g3d_dataset *d)
{
    if (!d) return;
    for (int i = 0; i < d->n; i++) {
        if (d->images) g3d_image_free(&d->images[i]);
        if (d->masks) g3d_image_free(&d->masks[i]);
    }
    free(d->images);
    free(d->masks);
    g3d_camera_list_free(&d->cams);
    g3d_points_free(&d->points);
    memset(d, 0, sizeof *d);
}

/* Loads dir/rel, checks it is w x h, and downscales it by `down`. */
static g3d_status load_scaled(const char *dir, const char *rel, int channels, int w, int h, int down, g3d_image *out)
{
    char *p = g3d_path_join(dir, rel);
    if (!p) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_image img = {0};
    g3d_status rc = g3d_image_load(p, channels, &img);
    if (rc == G3D_OK && (img.w != w || img.h != h))
        rc = G3D_ERR(G3D_ERR_MISMATCH, "%s: image is %dx%d but its camera says %dx%d", p, img.w, img.h, w, h);
    free(p);
    if (rc != G3D_OK) {
        g3d_image_free(&img);
        return rc;
    }
    if (down == 1) { *out = img; return G3D_OK; }
    rc = g3d_image_resize(&img, w / down, h / down, channels == 1 ? G3D_RESIZE_NEAREST : G3D_RESIZE_AREA, out);
    g3d_image_free(&img);
    return rc;
}

/* dir/name when that file exists (malloc'd), else NULL; *rc is set only when out of memory. */
static char *existing(const char *dir, const char *name, g3d_status *rc)
{
    struct stat st;
    char *p = g3d_path_join(dir, name);
    if (!p) *rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (p && stat(p, &st) != 0) {
        free(p);
        p = NULL;
    }
    return p;
}

g3d_status g3d_dataset_load(const char *dir, int downscale, g3d_dataset *d)
{
    memset(d, 0, sizeof *d);
    if (downscale < 1 || downscale > 16) return G3D_ERR(G3D_ERR_ARG, "%s: downscale factor %d is not in 1..16", dir, downscale);
    g3d_status rc = G3D_OK;
    char *tj = existing(dir, "transforms.json", &rc), *cj = tj ? NULL : existing(dir, "cameras.json", &rc);
    if (rc == G3D_OK) {
        rc = tj ? g3d_camera_list_load(tj, &d->cams)
           : cj ? g3d_camera_list_load(cj, &d->cams)
                : G3D_ERR(G3D_ERR_IO, "%s: no transforms.json or cameras.json", dir);
    }
    free(tj);
    free(cj);
    if (rc == G3D_OK && d->cams.n == 0) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: the camera list is empty", dir);
    if (rc == G3D_OK) {
        d->images = calloc((size_t)d->cams.n, sizeof *d->images);
        d->masks = calloc((size_t)d->cams.n, sizeof *d->masks);
        if (!d->images || !d->masks) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        else d->n = d->cams.n;
    }
    for (int i = 0; i < d->n && rc == G3D_OK; i++) {
        g3d_camera *c = &d->cams.cams[i];
        if (!d->cams.names[i]) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d names no image", dir, i);
            break;
        }
        rc = load_scaled(dir, d->cams.names[i], 3, c->K.width, c->K.height, downscale, &d->images[i]);
        if (rc == G3D_OK && d->cams.mask_paths[i])
            rc = load_scaled(dir, d->cams.mask_paths[i], 1, c->K.width, c->K.height, downscale, &d->masks[i]);
        if (downscale > 1) c->K = g3d_intrinsics_resize(c->K, c->K.width / downscale, c->K.height / downscale);
    }
    char *pp = rc == G3D_OK ? existing(dir, "points.ply", &rc) : NULL;
    if (pp) rc = g3d_ply_read_points(pp, &d->points);
    free(pp);
    if (rc != G3D_OK) g3d_dataset_free(d);
    return rc;
}
