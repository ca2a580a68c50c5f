/* LayerNorm over rows, GroupNorm, LayerNorm2d. Statistics are two-pass (mean, then the mean
 * squared deviation) in double over float partial sums taken in a fixed order, so they do not
 * depend on the thread count. */
#include "nn/nn_int.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Sum of x[i] (or of (x[i] - m)^2 when sq) over n values: 64 float lanes (four independent
 * vector sums), then double. */
__attribute__((target_clones("avx512f", "avx2", "default"))) static double lane_sum(const float *x, size_t n,
                                                                                   int sq, float m)
{
    float lane[64] = {0};
    size_t i = 0;
    if (sq)
        for (; i + 64 <= n; i += 64)
            for (int j = 0; j < 64; j++) lane[j] += (x[i + j] - m) * (x[i + j] - m);
    else
        for (; i + 64 <= n; i += 64)
            for (int j = 0; j < 64; j++) lane[j] += x[i + j];
    double s = 0;
    for (; i < n; i++) s += sq ? (double)(x[i] - m) * (x[i] - m) : x[i];
    for (int j = 0; j < 64; j++) s += lane[j];
    return s;
}

void g3d_nn_layernorm(const float *x, int n, int c, const float *g, const float *b, float eps, float *y)
{
#pragma omp parallel for schedule(static)
    for (int i = 0; i < n; i++) {
        const float *xi = x + (size_t)i * c;
        float *yi = y + (size_t)i * c;
        float mean = (float)(lane_sum(xi, c, 0, 0) / c);
        float var = (float)(lane_sum(xi, c, 1, mean) / c);
        float inv = 1.0f / sqrtf(var + eps);
        for (int j = 0; j < c; j++) yi[j] = (xi[j] - mean) * inv * g[j] + b[j];
    }
}

/* Group statistics over chunks of at most 64 K values, so a large group (VAE at 512x512:
 * 1 M values) is split over the threads without changing the order of its sums. Groups go in
 * batches of about 8 MB, each read for its mean, its variance and the output while it is still
 * in the last-level cache: the map is read from memory once instead of three times. */
void g3d_nn_groupnorm(const float *x, int c, int hw, int groups, const float *g, const float *b, float eps, g3d_act act,
                      float *y)
{
    const int cg = c / groups;
    const size_t gsize = (size_t)cg * hw, chunk = 1 << 16, nch = (gsize + chunk - 1) / chunk;
    const size_t cchunks = ((size_t)hw + chunk - 1) / chunk; /* per channel, for the output */
    const int batch = gsize * sizeof(float) >= (8u << 20) ? 1 : (int)((8u << 20) / (gsize * sizeof(float)));
    double *part = malloc(sizeof(double) * nch * groups);
    float *mean = malloc(sizeof(float) * groups), *inv = malloc(sizeof(float) * groups);
    if (!part || !mean || !inv) {
        free(part), free(mean), free(inv);
        nn_ref_groupnorm(x, c, hw, groups, g, b, eps, act, y);
        return;
    }
#pragma omp parallel
    for (int g0 = 0; g0 < groups; g0 += batch) {
        const int g1 = g0 + batch < groups ? g0 + batch : groups;
        for (int pass = 0; pass < 2; pass++) {
#pragma omp for schedule(static)
            for (long t = (long)(g0 * nch); t < (long)(g1 * nch); t++) {
                size_t gr = t / nch, lo = (t % nch) * chunk, n = gsize - lo < chunk ? gsize - lo : chunk;
                part[t] = lane_sum(x + gr * gsize + lo, n, pass, pass ? mean[gr] : 0.0f);
            }
#pragma omp single
            for (int gr = g0; gr < g1; gr++) {
                double s = 0;
                for (size_t k = 0; k < nch; k++) s += part[gr * nch + k];
                if (!pass)
                    mean[gr] = (float)(s / gsize);
                else
                    inv[gr] = 1.0f / sqrtf((float)(s / gsize) + eps);
            }
        }
#pragma omp for schedule(static)
        for (long t = (long)(g0 * cg * cchunks); t < (long)(g1 * cg * cchunks); t++) {
            const int ch = (int)(t / cchunks), gr = ch / cg;
            const size_t lo = (t % cchunks) * chunk, n = hw - lo < chunk ? hw - lo : chunk;
            const float k = inv[gr] * g[ch], off = b[ch] - mean[gr] * k;
            const float *xc = x + (size_t)ch * hw + lo;
            float *yc = y + (size_t)ch * hw + lo;
            for (size_t i = 0; i < n; i++) yc[i] = xc[i] * k + off;
            nn_act(act, yc, (long)n);
        }
    }
    free(part), free(mean), free(inv);
}

void g3d_nn_layernorm2d(const float *x, int c, int hw, const float *g, const float *b, float eps, float *y)
{
    const int blk = 256;
    const int nb = (hw + blk - 1) / blk;
#pragma omp parallel for schedule(static)
    for (int bi = 0; bi < nb; bi++) {
        int p0 = bi * blk, n = hw - p0 < blk ? hw - p0 : blk;
        float mean[256], inv[256];
        for (int p = 0; p < n; p++) mean[p] = 0.0f, inv[p] = 0.0f;
        for (int ch = 0; ch < c; ch++) {
            const float *xc = x + (size_t)ch * hw + p0;
            for (int p = 0; p < n; p++) mean[p] += xc[p];
        }
        for (int p = 0; p < n; p++) mean[p] /= c;
        for (int ch = 0; ch < c; ch++) {
            const float *xc = x + (size_t)ch * hw + p0;
            for (int p = 0; p < n; p++) inv[p] += (xc[p] - mean[p]) * (xc[p] - mean[p]);
        }
        for (int p = 0; p < n; p++) inv[p] = 1.0f / sqrtf(inv[p] / c + eps);
        for (int ch = 0; ch < c; ch++) {
            const float *xc = x + (size_t)ch * hw + p0;
            float *yc = y + (size_t)ch * hw + p0;
            for (int p = 0; p < n; p++) yc[p] = (xc[p] - mean[p]) * inv[p] * g[ch] + b[ch];
        }
    }
}

/* Mean and 1/sqrt(var + eps) of n values spaced `stride` apart, in double. */
static void ref_stats(const float *x, size_t n, size_t stride, float eps, double *mean, double *inv)
{
    double m = 0, v = 0;
    for (size_t i = 0; i < n; i++) m += x[i * stride];
    m /= n;
    for (size_t i = 0; i < n; i++) v += (x[i * stride] - m) * (x[i * stride] - m);
    *mean = m;
    *inv = 1.0 / sqrt(v / n + eps);
}

void nn_ref_groupnorm(const float *x, int c, int hw, int groups, const float *g, const float *b, float eps, g3d_act act,
                      float *y)
{
    const int cg = c / groups;
    for (int gr = 0; gr < groups; gr++) {
        double m, inv;
        ref_stats(x + (size_t)gr * cg * hw, (size_t)cg * hw, 1, eps, &m, &inv);
        for (int cc = 0; cc < cg; cc++) {
            int ch = gr * cg + cc;
            for (int i = 0; i < hw; i++) {
                size_t at = (size_t)ch * hw + i;
                y[at] = nn_ref_act1(act, (float)((x[at] - m) * inv * g[ch] + b[ch]));
            }
        }
    }
}

void nn_ref_layernorm2d(const float *x, int c, int hw, const float *g, const float *b, float eps, float *y)
{
    for (int p = 0; p < hw; p++) {
        double m, inv;
        ref_stats(x + p, c, hw, eps, &m, &inv);
        for (int ch = 0; ch < c; ch++) y[(size_t)ch * hw + p] = (float)((x[(size_t)ch * hw + p] - m) * inv * g[ch] + b[ch]);
    }
}

void nn_ref_layernorm(const float *x, int n, int c, const float *g, const float *b, float eps, float *y)
{
    for (int i = 0; i < n; i++) {
        const float *xi = x + (size_t)i * c;
        double m, inv;
        ref_stats(xi, c, 1, eps, &m, &inv);
        for (int j = 0; j < c; j++) y[(size_t)i * c + j] = (float)((xi[j] - m) * inv) * g[j] + b[j];
    }
}
