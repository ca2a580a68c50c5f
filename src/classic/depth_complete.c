/* Depth completion: plane in inverse depth plus a harmonic residual. */
#include "gen3d/depth_complete.h"
#include "gen3d/membrane.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Known pixels within this many pixels of a hole fit the plane. */
#define BAND 12

g3d_status g3d_depth_complete(g3d_image *depth, const g3d_image *fill_mask)
{
    int w = depth->w, h = depth->h;
    size_t n = (size_t)w * h;
    if (fill_mask && (fill_mask->w != w || fill_mask->h != h))
        return G3D_ERR(G3D_ERR_MISMATCH, "depth completion: mask %dx%d does not match depth %dx%d", fill_mask->w, fill_mask->h, w, h);
    float *v = malloc(sizeof(float) * n);
    uint8_t *known = malloc(n), *band = calloc(n, 1);
    int *dist = malloc(sizeof(int) * n);
    if (!v || !known || !band || !dist) { free(v); free(known); free(band); free(dist); return G3D_ERR(G3D_ERR_NOMEM, "depth completion: out of memory"); }
    double vmin = INFINITY, vmax = 0;
    for (size_t i = 0; i < n; i++) {
        float z = depth->data[i];
        known[i] = z > 0 && isfinite(z) && !(fill_mask && fill_mask->data[i] > 0.5f);
        v[i] = known[i] ? 1.0f / z : 0.0f;
        if (known[i]) { vmin = fmin(vmin, v[i]); vmax = fmax(vmax, v[i]); }
    }
    /* City-block distance to the nearest hole pixel (two passes) selects the fitting band. */
    for (size_t i = 0; i < n; i++) dist[i] = known[i] ? 1 << 20 : 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            if (x > 0 && dist[i - 1] + 1 < dist[i]) dist[i] = dist[i - 1] + 1;
            if (y > 0 && dist[i - w] + 1 < dist[i]) dist[i] = dist[i - w] + 1;
        }
    for (int y = h - 1; y >= 0; y--)
        for (int x = w - 1; x >= 0; x--) {
            size_t i = (size_t)y * w + x;
            if (x < w - 1 && dist[i + 1] + 1 < dist[i]) dist[i] = dist[i + 1] + 1;
            if (y < h - 1 && dist[i + w] + 1 < dist[i]) dist[i] = dist[i + w] + 1;
        }
    /* The depth range on the rim of the holes bounds the completion (as it bounds a harmonic
     * fill): a plane extrapolated far past its data could otherwise run towards the horizon,
     * and every later view would build on that and reach further. */
    double rmin = INFINITY, rmax = 0;
    for (size_t i = 0; i < n; i++) {
        band[i] = known[i] && dist[i] <= BAND;
        if (band[i]) { rmin = fmin(rmin, v[i]); rmax = fmax(rmax, v[i]); }
    }
    if (rmax == 0) { rmin = vmin; rmax = vmax; }

    g3d_status rc = vmax == 0 ? G3D_ERR(G3D_ERR_ARG, "depth completion: no valid depth to complete from")
                              : g3d_membrane_fill_planar(v, known, band, w, h);
    if (rc == G3D_OK)
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                size_t i = (size_t)y * w + x;
                if (known[i]) continue;
                double inv = fmin(fmax((double)v[i], rmin), rmax);
                depth->data[i] = (float)(1.0 / inv);
            }
    free(v);
    free(known);
    free(band);
    free(dist);
    return rc;
}

static g3d_status completion_estimate(void *ctx, const g3d_image *rgb, const g3d_image *known, const g3d_image *mask,
                                      g3d_image *depth_out, g3d_intrinsics *K_io)
{
    (void)ctx;
    (void)K_io;
    if (!known) return G3D_ERR(G3D_ERR_ARG, "depth completion needs known depth (no depth model was given)");
    if (known->w != rgb->w || known->h != rgb->h)
        return G3D_ERR(G3D_ERR_MISMATCH, "depth completion: depth %dx%d does not match the image %dx%d", known->w, known->h, rgb->w, rgb->h);
    G3D_TRY(g3d_image_clone(depth_out, known));
    g3d_status rc = g3d_depth_complete(depth_out, mask);
    if (rc != G3D_OK) g3d_image_free(depth_out);
    return rc;
}

g3d_status g3d_depth_estimator_completion_create(g3d_depth_estimator *out)
{
    *out = (g3d_depth_estimator){"completion", NULL, completion_estimate, NULL};
    return G3D_OK;
}
