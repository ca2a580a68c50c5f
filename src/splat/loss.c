/* loss.c - masked L1 + SSIM loss with its analytic gradient, masked PSNR, and the evaluation
 * SSIM. */
#include "gen3d/loss.h"

#include <math.h>
#include <stdlib.h>

#define WIN 11
#define HALF 5
#define SSIM_C1 (0.01 * 0.01)
#define SSIM_C2 (0.03 * 0.03)

static void gauss_window(double k[WIN])
{
    double s = 0;
    for (int i = 0; i < WIN; i++) {
        double d = i - HALF;
        k[i] = exp(-d * d / (2.0 * 1.5 * 1.5));
        s += k[i];
    }
    for (int i = 0; i < WIN; i++) k[i] /= s;
}

/* Separable 'same' filtering with zero padding; the kernel is symmetric, so this operator is
 * self-adjoint and serves the backward pass unchanged. tmp: w*h scratch. Rows run in parallel
 * and each pass adds the taps in ascending order over whole rows, so every output is the same
 * sum whatever the thread count, and the rows vectorise (built for AVX-512, AVX2 and SSE2). */
__attribute__((target_clones("avx512f", "avx2", "default")))
static void blur(const double *in, double *out, double *tmp, int w, int h, const double k[WIN])
{
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        const double *src = in + (size_t)y * w;
        double *dst = tmp + (size_t)y * w;
        for (int x = 0; x < w; x++) dst[x] = 0;
        for (int i = 0; i < WIN; i++) {
            const int off = i - HALF, x0 = off < 0 ? -off : 0, x1 = off > 0 ? w - off : w;
            const double kk = k[i];
            for (int x = x0; x < x1; x++) dst[x] += kk * src[x + off];
        }
    }
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        double *dst = out + (size_t)y * w;
        for (int x = 0; x < w; x++) dst[x] = 0;
        for (int i = -HALF; i <= HALF; i++) {
            int yy = y + i;
            if (yy < 0 || yy >= h) continue;
            const double *row = tmp + (size_t)yy * w, kk = k[i + HALF];
            for (int x = 0; x < w; x++) dst[x] += kk * row[x];
        }
    }
}

/* The windowed moments of one channel pair: means, second moments and the cross moment.
 * sq and tmp are w*h scratch planes. */
static void moments(const double *p, const double *t, double *mu1, double *mu2, double *e11, double *e22,
                    double *e12, double *sq, double *tmp, int w, int h, const double k[WIN])
{
    const size_t np = (size_t)w * h;
    blur(p, mu1, tmp, w, h, k);
    blur(t, mu2, tmp, w, h, k);
    for (size_t i = 0; i < np; i++) sq[i] = p[i] * p[i];
    blur(sq, e11, tmp, w, h, k);
    for (size_t i = 0; i < np; i++) sq[i] = t[i] * t[i];
    blur(sq, e22, tmp, w, h, k);
    for (size_t i = 0; i < np; i++) sq[i] = p[i] * t[i];
    blur(sq, e12, tmp, w, h, k);
}

static g3d_status check_inputs(const g3d_image *pred, const g3d_image *target,
                               const g3d_image *mask, int64_t *nvalid)
{
    if (!pred || !target || !pred->data || !target->data)
        return G3D_ERR(G3D_ERR_ARG, "loss: empty image");
    if (pred->w != target->w || pred->h != target->h || pred->c != target->c)
        return G3D_ERR(G3D_ERR_MISMATCH, "loss: prediction %dx%dx%d vs target %dx%dx%d",
                       pred->w, pred->h, pred->c, target->w, target->h, target->c);
    size_t np = (size_t)pred->w * pred->h;
    if (mask) {
        if (mask->w != pred->w || mask->h != pred->h || mask->c != 1)
            return G3D_ERR(G3D_ERR_MISMATCH, "loss: mask %dx%dx%d vs image %dx%d (1 channel expected)",
                           mask->w, mask->h, mask->c, pred->w, pred->h);
        int64_t n = 0;
        for (size_t i = 0; i < np; i++) n += mask->data[i] > 0.5f;
        *nvalid = n;
    } else {
        *nvalid = (int64_t)np;
    }
    if (*nvalid == 0) return G3D_ERR(G3D_ERR_ARG, "loss: the mask has no valid pixel");
    return G3D_OK;
}

static int valid(const g3d_image *mask, size_t i) { return !mask || mask->data[i] > 0.5f; }

/* The SSIM terms at one pixel from the blurred moments: ssim = A * B / (C * D). */
static inline void ssim_terms(double m1, double m2, double e11, double e22, double e12, double *A, double *B,
                              double *C, double *D)
{
    double s11 = e11 - m1 * m1, s22 = e22 - m2 * m2, s12 = e12 - m1 * m2;
    *A = 2 * m1 * m2 + SSIM_C1;
    *B = 2 * s12 + SSIM_C2;
    *C = m1 * m1 + m2 * m2 + SSIM_C1;
    *D = s11 + s22 + SSIM_C2;
}

g3d_status g3d_loss_fwd_bwd(const g3d_image *pred, const g3d_image *target,
                            const g3d_image *mask, double lambda, double *loss, double *ssim,
                            g3d_image *grad)
{
    int64_t nvalid;
    G3D_TRY(check_inputs(pred, target, mask, &nvalid));
    if (!(lambda >= 0 && lambda <= 1))
        return G3D_ERR(G3D_ERR_ARG, "loss: SSIM weight %g outside [0, 1]", lambda);
    if (grad && (grad->w != pred->w || grad->h != pred->h || grad->c != pred->c || !grad->data))
        return G3D_ERR(G3D_ERR_MISMATCH, "loss: gradient image does not match the prediction");

    const int w = pred->w, h = pred->h, c = pred->c;
    const size_t np = (size_t)w * h;
    /* planes: p, t, mu1, mu2, e11, e22, e12, tmp, and 3 backward weights */
    double *buf = g3d_calloc(np, 11 * sizeof(double), "loss scratch");
    if (!buf) return G3D_ERR_NOMEM;
    double *p = buf, *t = p + np, *mu1 = t + np, *mu2 = mu1 + np, *e11 = mu2 + np,
           *e22 = e11 + np, *e12 = e22 + np, *tmp = e12 + np, *wa = tmp + np, *wb = wa + np,
           *wc = wb + np;
    double k[WIN];
    gauss_window(k);
    const double count = (double)nvalid * c;
    /* per-row partial sums, added in row order: the same total for any thread count */
    double *row_l1 = g3d_calloc((size_t)h, 2 * sizeof(double), "loss row sums");
    if (!row_l1) {
        free(buf);
        return G3D_ERR_NOMEM;
    }
    double *row_ssim = row_l1 + h;

    for (int ch = 0; ch < c; ch++) {
#pragma omp parallel for schedule(static)
        for (int y = 0; y < h; y++) {
            double l1 = 0;
            for (size_t i = (size_t)y * w; i < (size_t)(y + 1) * w; i++) {
                p[i] = pred->data[i * c + ch];
                t[i] = target->data[i * c + ch];
                if (valid(mask, i)) l1 += fabs(p[i] - t[i]);
            }
            row_l1[y] += l1;
        }
        moments(p, t, mu1, mu2, e11, e22, e12, wa, tmp, w, h, k);

#pragma omp parallel for schedule(static)
        for (int y = 0; y < h; y++) {
            double ssim_sum = 0;
            for (size_t i = (size_t)y * w; i < (size_t)(y + 1) * w; i++) {
                double m1 = mu1[i], m2 = mu2[i], A, B, C, D;
                ssim_terms(m1, m2, e11[i], e22[i], e12[i], &A, &B, &C, &D);
                double s = A * B / (C * D);
                if (valid(mask, i)) {
                    ssim_sum += s;
                    /* dL/dssim = -lambda / count; chain through mu1, E[p^2], E[pt] */
                    double ws = -lambda / count;
                    double dmu1 = (2 * m2 * B - 2 * m2 * A) / (C * D) - s * 2 * m1 / C + s * 2 * m1 / D;
                    wa[i] = ws * dmu1;
                    wb[i] = ws * (-s / D);
                    wc[i] = ws * (2 * A / (C * D));
                } else {
                    wa[i] = wb[i] = wc[i] = 0;
                }
            }
            row_ssim[y] += ssim_sum;
        }
        if (grad) {
            blur(wa, mu1, tmp, w, h, k); /* mu1/e11/e12 are no longer needed */
            blur(wb, e11, tmp, w, h, k);
            blur(wc, e12, tmp, w, h, k);
#pragma omp parallel for schedule(static)
            for (size_t i = 0; i < np; i++) {
                double g = mu1[i] + 2 * p[i] * e11[i] + t[i] * e12[i];
                if (valid(mask, i)) {
                    double d = p[i] - t[i];
                    g += (1 - lambda) * (d > 0 ? 1.0 : d < 0 ? -1.0 : 0.0) / count;
                }
                grad->data[i * c + ch] = (float)g;
            }
        }
    }
    double l1 = 0, ssim_sum = 0;
    for (int y = 0; y < h; y++) {
        l1 += row_l1[y];
        ssim_sum += row_ssim[y];
    }
    double mean_ssim = ssim_sum / count;
    *loss = (1 - lambda) * (l1 / count) + lambda * (1 - mean_ssim);
    if (ssim) *ssim = mean_ssim;
    free(row_l1);
    free(buf);
    return G3D_OK;
}

g3d_status g3d_psnr(const g3d_image *pred, const g3d_image *target, const g3d_image *mask,
                    double *psnr)
{
    int64_t nvalid;
    G3D_TRY(check_inputs(pred, target, mask, &nvalid));
    const int c = pred->c;
    const size_t np = (size_t)pred->w * pred->h;
    double se = 0;
    for (size_t i = 0; i < np; i++) {
        if (!valid(mask, i)) continue;
        for (int ch = 0; ch < c; ch++) {
            double d = (double)pred->data[i * c + ch] - target->data[i * c + ch];
            se += d * d;
        }
    }
    double mse = se / ((double)nvalid * c);
    *psnr = mse > 0 ? 10.0 * log10(1.0 / mse) : INFINITY;
    return G3D_OK;
}

g3d_status g3d_ssim(const g3d_image *a, const g3d_image *b, const g3d_image *mask, double *ssim)
{
    int64_t nvalid;
    G3D_TRY(check_inputs(a, b, mask, &nvalid));
    const int w = a->w, h = a->h, c = a->c;
    if (w < WIN || h < WIN)
        return G3D_ERR(G3D_ERR_ARG, "ssim: a %dx%d image is smaller than the %dx%d window", w, h, WIN, WIN);
    const size_t np = (size_t)w * h;
    double *buf = g3d_calloc(np, 9 * sizeof(double), "ssim scratch");
    double *rows = g3d_calloc((size_t)h, sizeof(double), "ssim row sums");
    if (!buf || !rows) {
        free(buf);
        free(rows);
        return G3D_ERR_NOMEM;
    }
    double *p = buf, *t = p + np, *mu1 = t + np, *mu2 = mu1 + np, *e11 = mu2 + np, *e22 = e11 + np,
           *e12 = e22 + np, *sq = e12 + np, *tmp = sq + np;
    double k[WIN];
    gauss_window(k);
    /* Only pixels whose whole window lies inside the image are averaged; there the zero padding
     * of blur() never enters, so this is the 'valid' convolution of the usual definition. */
    int64_t count = 0;
    for (int y = HALF; y < h - HALF; y++)
        for (int x = HALF; x < w - HALF; x++) count += valid(mask, (size_t)y * w + x);
    for (int ch = 0; ch < c && count > 0; ch++) {
        for (size_t i = 0; i < np; i++) {
            p[i] = a->data[i * c + ch];
            t[i] = b->data[i * c + ch];
        }
        moments(p, t, mu1, mu2, e11, e22, e12, sq, tmp, w, h, k);
#pragma omp parallel for schedule(static)
        for (int y = HALF; y < h - HALF; y++) {
            double sum = 0;
            for (size_t i = (size_t)y * w + HALF; i < (size_t)y * w + (w - HALF); i++) {
                if (!valid(mask, i)) continue;
                double A, B, C, D;
                ssim_terms(mu1[i], mu2[i], e11[i], e22[i], e12[i], &A, &B, &C, &D);
                sum += A * B / (C * D);
            }
            rows[y] += sum;
        }
    }
    double total = 0;
    for (int y = 0; y < h; y++) total += rows[y];
    free(buf);
    free(rows);
    if (count == 0) return G3D_ERR(G3D_ERR_ARG, "ssim: no valid pixel lies %d pixels inside the image border", HALF);
    *ssim = total / ((double)count * c);
    return G3D_OK;
}
