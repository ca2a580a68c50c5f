/* Which pixels of a held-out view the input camera sees, and the forward warp of the input. */
#include "gen3d/eval.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

const char *g3d_covis_kind_name(g3d_covis_kind k)
{
    switch (k) {
    case G3D_COVIS_VIEW_DEPTH: return "view_depth";
    case G3D_COVIS_INPUT_WARP: return "input_depth_warp";
    case G3D_COVIS_SCENE_ALPHA: return "scene_alpha";
    default: return "none";
    }
}

/* Whether (u, v) rounds (lround: halves away from zero) to a pixel of a w x h image; tested
 * before rounding, so far-off projections never reach lround. */
static int inside(double u, double v, int w, int h)
{
    return u > -0.5 && v > -0.5 && u < w - 0.5 && v < h - 0.5;
}

g3d_status g3d_eval_forward_warp(const g3d_camera *src, const g3d_image *rgb, const g3d_image *depth,
                                 const g3d_camera *dst, g3d_image *out_rgb, g3d_image *out_depth)
{
    const int w = dst->K.width, h = dst->K.height;
    if (depth->c != 1 || depth->w != src->K.width || depth->h != src->K.height)
        return G3D_ERR(G3D_ERR_MISMATCH, "forward warp: depth %dx%dx%d does not match its %dx%d camera", depth->w,
                       depth->h, depth->c, src->K.width, src->K.height);
    if (out_rgb && (!rgb || rgb->w != depth->w || rgb->h != depth->h || rgb->c != 3))
        return G3D_ERR(G3D_ERR_MISMATCH, "forward warp: the colour image does not match the depth");
    G3D_TRY(g3d_image_create(out_depth, w, h, 1));
    if (out_rgb && g3d_image_create(out_rgb, w, h, 3) != G3D_OK) {
        g3d_image_free(out_depth);
        return G3D_ERR_NOMEM;
    }
    float *z = out_depth->data;
    for (size_t i = 0; i < (size_t)w * h; i++) z[i] = INFINITY;
    for (int y = 0; y < depth->h; y++)
        for (int x = 0; x < depth->w; x++) {
            const float d = *g3d_image_px(depth, x, y);
            if (!(d > 0)) continue;
            double u, v, zz;
            if (!g3d_camera_project(dst, g3d_camera_unproject(src, x, y, d), &u, &v, &zz) || !inside(u, v, w, h))
                continue;
            const size_t k = (size_t)lround(v) * w + (size_t)lround(u);
            if (!(zz < z[k])) continue;
            z[k] = (float)zz;
            if (out_rgb) memcpy(out_rgb->data + 3 * k, g3d_image_px(rgb, x, y), 3 * sizeof(float));
        }
    for (size_t i = 0; i < (size_t)w * h; i++)
        if (isinf(z[i])) z[i] = 0.0f;
    return G3D_OK;
}

/* View pixels whose ground-truth surface point projects into the input image in front of (or
 * within the slack of) the input depth at the nearest input pixel. */
static g3d_status depth_test(const g3d_eval_view *in, const g3d_eval_view *view, g3d_image *mask)
{
    const int w = view->cam.K.width, h = view->cam.K.height, iw = in->depth.w, ih = in->depth.h;
    G3D_TRY(g3d_image_create(mask, w, h, 1));
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float d = *g3d_image_px(&view->depth, x, y);
            double u, v, z;
            if (!(d > 0) || !g3d_camera_project(&in->cam, g3d_camera_unproject(&view->cam, x, y, d), &u, &v, &z) ||
                !inside(u, v, iw, ih))
                continue;
            const float zi = *g3d_image_px(&in->depth, (int)lround(u), (int)lround(v));
            mask->data[(size_t)y * w + x] = zi > 0 && z <= zi * (1.0 + G3D_EVAL_COVIS_DEPTH_TOL);
        }
    return G3D_OK;
}

g3d_status g3d_eval_covisible(const g3d_eval_view *input, const g3d_eval_view *view, g3d_image *mask,
                              g3d_covis_kind *kind)
{
    memset(mask, 0, sizeof *mask);
    *kind = G3D_COVIS_NONE;
    if (!input || !input->depth.data) return G3D_OK;
    if (view->depth.data) {
        G3D_TRY(depth_test(input, view, mask));
        *kind = G3D_COVIS_VIEW_DEPTH;
        return G3D_OK;
    }
    g3d_image z;
    G3D_TRY(g3d_eval_forward_warp(&input->cam, NULL, &input->depth, &view->cam, NULL, &z));
    for (size_t i = 0; i < g3d_image_size(&z); i++) z.data[i] = z.data[i] > 0;
    *mask = z;
    *kind = G3D_COVIS_INPUT_WARP;
    return G3D_OK;
}
