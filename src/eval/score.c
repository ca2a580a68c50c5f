/* The metrics of one prediction against one ground-truth view on one region. */
#include "gen3d/eval.h"

#include "gen3d/loss.h"

#include <math.h>
#include <string.h>

g3d_status g3d_eval_score(const g3d_image *rgb, const g3d_image *depth, const g3d_eval_view *gt,
                          const g3d_image *region, g3d_eval_metrics *m)
{
    const int w = gt->cam.K.width, h = gt->cam.K.height;
    const size_t np = (size_t)w * h;
    if (rgb->w != w || rgb->h != h || rgb->c != 3 || (depth && (depth->w != w || depth->h != h || depth->c != 1)) ||
        (region && (region->w != w || region->h != h || region->c != 1)))
        return G3D_ERR(G3D_ERR_MISMATCH, "eval: prediction %dx%d does not match the %dx%d view %s", rgb->w, rgb->h, w, h,
                       gt->name ? gt->name : "");
    const double nan = NAN;
    *m = (g3d_eval_metrics){0, nan, nan, nan, 0, nan, nan, nan};

    /* the scored pixels: the region within the view's own mask */
    g3d_image sel;
    G3D_TRY(g3d_image_create(&sel, w, h, 1));
    for (size_t i = 0; i < np; i++) {
        int on = (!region || region->data[i] > 0.5f) && (!gt->mask.data || gt->mask.data[i] > 0.5f);
        sel.data[i] = (float)on;
        m->pixels += on;
    }
    g3d_status rc = G3D_OK;
    if (m->pixels > 0) {
        rc = g3d_psnr(rgb, &gt->rgb, &sel, &m->psnr);
        m->mse = pow(10.0, -m->psnr / 10.0); /* 0 for an exact match */
        /* SSIM needs pixels away from the border; a region without any has no SSIM */
        if (rc == G3D_OK && g3d_ssim(rgb, &gt->rgb, &sel, &m->ssim) != G3D_OK) {
            m->ssim = nan;
            g3d_error_clear();
        }
    }
    if (rc == G3D_OK && gt->depth.data) {
        int64_t n_gt = 0, n = 0;
        double rel = 0, sq = 0;
        for (size_t i = 0; i < np; i++) {
            const float g = gt->depth.data[i];
            if (sel.data[i] < 0.5f || !(g > 0)) continue;
            n_gt++;
            const float d = depth ? depth->data[i] : 0.0f;
            if (!(d > 0)) continue;
            n++;
            rel += fabs((double)d - g) / g;
            sq += ((double)d - g) * ((double)d - g);
        }
        m->depth_pixels = n;
        if (n_gt) m->depth_coverage = (double)n / n_gt;
        if (n) {
            m->depth_abs_rel = rel / n;
            m->depth_rmse = sqrt(sq / n);
        }
    }
    g3d_image_free(&sel);
    return rc;
}
