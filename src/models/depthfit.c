/* Least-squares scale and shift between a depth prediction and known depth (gen3d/depthfit.h). */
#include "gen3d/depthfit.h"

#include <math.h>

g3d_status g3d_depthfit_affine(const float *pred, const float *known, size_t n, g3d_fit_space space, double *s,
                               double *t)
{
    /* Moments are taken about the first used sample, which keeps the normal equations well
     * conditioned when the values sit far from zero. */
    double p0 = 0, y0 = 0, sp = 0, sy = 0, spp = 0, spy = 0;
    size_t m = 0;
    for (size_t i = 0; i < n; i++) {
        if (!(known[i] != 0)) continue;
        if (!isfinite(known[i]) || known[i] < 0)
            return G3D_ERR(G3D_ERR_ARG, "depth fit: known depth at pixel %zu is %g", i, (double)known[i]);
        if (!isfinite(pred[i]))
            return G3D_ERR(G3D_ERR_ARG, "depth fit: prediction at pixel %zu is %g", i, (double)pred[i]);
        double y = space == G3D_FIT_INVERSE ? 1.0 / known[i] : known[i];
        if (m == 0) p0 = pred[i], y0 = y;
        double p = pred[i] - p0, q = y - y0;
        sp += p, sy += q, spp += p * p, spy += p * q;
        m++;
    }
    if (m < 2) return G3D_ERR(G3D_ERR_ARG, "depth fit: %zu known pixels, need at least 2", m);
    double var = spp - sp * sp / (double)m;
    if (!(var > 1e-12 * (spp > 0 ? spp : 1)))
        return G3D_ERR(G3D_ERR_ARG, "depth fit: the prediction is constant over the %zu known pixels", m);
    double scale = (spy - sp * sy / (double)m) / var;
    double shift_c = (sy - scale * sp) / (double)m;
    *s = scale;
    *t = y0 + shift_c - scale * p0;
    return G3D_OK;
}

void g3d_depthfit_apply(const float *pred, size_t n, g3d_fit_space space, double s, double t, float *depth)
{
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < n; i++) {
        double v = s * pred[i] + t;
        if (space == G3D_FIT_INVERSE) v = v > 0 ? 1.0 / v : 0.0;
        depth[i] = (isfinite(v) && v > 0 && v < 3.0e38) ? (float)v : 0.0f;
    }
}
