/* Masked L1 + D-SSIM loss and its gradient with respect to the rendered image. */
#include "gen3d/loss.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define R (G3D_SSIM_WINDOW / 2)

static void gaussian_taps(double g[G3D_SSIM_WINDOW])
{
    double s = 0;
    for (int i = 0; i < G3D_SSIM_WINDOW; i++) {
        double d = i - R;
        g[i] = exp(-d * d / (2 * G3D_SSIM_SIGMA * G3D_SSIM_SIGMA));
        s += g[i];
    }
    for (int i = 0; i < G3D_SSIM_WINDOW; i++) g[i] /= s;
}

/* out = G * in for one (h, w) plane, zero outside the image. The window is symmetric, so the
 * same filter is also its own transpose (used by the backward pass). tmp: (h, w). */
static void blur(const double *in, double *out, double *tmp, int w, int h, const double g[G3D_SSIM_WINDOW])
{
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            double s = 0;
            for (int k = -R; k <= R; k++) {
                int xx = x + k;
                if (xx >= 0 && xx < w) s += g[k + R] * in[(size_t)y * w + xx];
            }
            tmp[(size_t)y * w + x] = s;
        }
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            double s = 0;
            for (int k = -R; k <= R; k++) {
                int yy = y + k;
                if (yy >= 0 && yy < h) s += g[k + R] * tmp[(size_t)yy * w + x];
            }
            out[(size_t)y * w + x] = s;
        }
}

g3d_status g3d_loss_l1_dssim(const float *img, const float *target, const float *mask, int w, int h, double lambda,
                             float *dimg, g3d_loss_terms *out)
{
    const double C1 = 0.01 * 0.01, C2 = 0.03 * 0.03;
    size_t n = (size_t)w * h;
    int64_t valid = 0;
    for (size_t i = 0; i < n; i++) valid += !mask || mask[i] > 0.5f;
    if (valid == 0) return G3D_ERR(G3D_ERR_ARG, "loss: no valid pixel");
    double *buf = malloc(sizeof(double) * n * 12);
    if (!buf) return G3D_ERR(G3D_ERR_NOMEM, "loss: out of memory");
    double *x = buf, *y = buf + n, *mx = buf + 2 * n, *my = buf + 3 * n, *exx = buf + 4 * n, *eyy = buf + 5 * n,
           *exy = buf + 6 * n, *tmp = buf + 7 * n, *gmu = buf + 8 * n, *gxx = buf + 9 * n, *gxy = buf + 10 * n,
           *sq = buf + 11 * n;
    double g[G3D_SSIM_WINDOW];
    gaussian_taps(g);
    double norm = 1.0 / ((double)valid * 3.0), l1 = 0, ssim = 0;
    if (dimg) memset(dimg, 0, sizeof(float) * n * 3);
    for (int c = 0; c < 3; c++) {
        for (size_t i = 0; i < n; i++) { x[i] = img[3 * i + c]; y[i] = target[3 * i + c]; }
        blur(x, mx, tmp, w, h, g);
        blur(y, my, tmp, w, h, g);
        for (size_t i = 0; i < n; i++) sq[i] = x[i] * x[i];
        blur(sq, exx, tmp, w, h, g);
        for (size_t i = 0; i < n; i++) sq[i] = y[i] * y[i];
        blur(sq, eyy, tmp, w, h, g);
        for (size_t i = 0; i < n; i++) sq[i] = x[i] * y[i];
        blur(sq, exy, tmp, w, h, g);
        for (size_t i = 0; i < n; i++) {
            double wgt = (!mask || mask[i] > 0.5f) ? norm : 0.0;
            double d = x[i] - y[i];
            l1 += wgt * fabs(d);
            double sx = exx[i] - mx[i] * mx[i], sy = eyy[i] - my[i] * my[i], sxy = exy[i] - mx[i] * my[i];
            double A1 = 2 * mx[i] * my[i] + C1, A2 = 2 * sxy + C2, B1 = mx[i] * mx[i] + my[i] * my[i] + C1, B2 = sx + sy + C2;
            double S = A1 * A2 / (B1 * B2);
            ssim += wgt * S;
            /* dS with respect to the local moments mu_x, E[x^2], E[xy] (see the header). */
            gmu[i] = wgt * (2 * my[i] * (A2 - A1) / (B1 * B2) - 2 * mx[i] * S * (1 / B1 - 1 / B2));
            gxx[i] = wgt * (-S / B2);
            gxy[i] = wgt * (2 * A1 / (B1 * B2));
            if (dimg) dimg[3 * i + c] = (float)((1 - lambda) * wgt * (d > 0 ? 1.0 : d < 0 ? -1.0 : 0.0));
        }
        if (dimg) {
            /* Back through the window: d(mean S)/dx(q) = G^T gmu + 2 x G^T gxx + y G^T gxy. */
            blur(gmu, mx, tmp, w, h, g);
            blur(gxx, exx, tmp, w, h, g);
            blur(gxy, exy, tmp, w, h, g);
            for (size_t i = 0; i < n; i++)
                dimg[3 * i + c] += (float)(-lambda * (mx[i] + 2 * x[i] * exx[i] + y[i] * exy[i]));
        }
    }
    free(buf);
    out->l1 = l1;
    out->ssim = ssim;
    out->loss = (1 - lambda) * l1 + lambda * (1 - ssim);
    out->valid = valid;
    return G3D_OK;
}
