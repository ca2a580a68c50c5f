/* Harmonic interpolation by a coarse-to-fine red-black SOR solve. */
#include "gen3d/membrane.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Red-black SOR sweeps of the 4-neighbour Laplacian with free borders. */
static void relax(float *v, const uint8_t *known, int w, int h, int sweeps)
{
    const float omega = 1.9f;
    for (int s = 0; s < sweeps; s++)
        for (int colour = 0; colour < 2; colour++) {
#pragma omp parallel for schedule(static)
            for (int y = 0; y < h; y++)
                for (int x = (y + colour) & 1; x < w; x += 2) {
                    size_t i = (size_t)y * w + x;
                    if (known[i]) continue;
                    float sum = 0;
                    int n = 0;
                    if (x > 0) { sum += v[i - 1]; n++; }
                    if (x < w - 1) { sum += v[i + 1]; n++; }
                    if (y > 0) { sum += v[i - w]; n++; }
                    if (y < h - 1) { sum += v[i + w]; n++; }
                    if (n) v[i] += omega * (sum / n - v[i]);
                }
        }
}

static g3d_status solve(float *v, const uint8_t *known, int w, int h)
{
    size_t n = (size_t)w * h;
    size_t nk = 0;
    for (size_t i = 0; i < n; i++) nk += known[i] != 0;
    if (nk == 0) return G3D_ERR(G3D_ERR_ARG, "membrane fill: no known value");
    if (nk == n) return G3D_OK;
    if (w <= 8 || h <= 8) {
        /* Small enough: start from the mean and relax to convergence. */
        double mean = 0;
        for (size_t i = 0; i < n; i++) if (known[i]) mean += v[i];
        mean /= (double)nk;
        for (size_t i = 0; i < n; i++) if (!known[i]) v[i] = (float)mean;
        relax(v, known, w, h, 400);
        return G3D_OK;
    }
    /* Coarse level: 2x2 averages of the known values. */
    int cw = (w + 1) / 2, ch = (h + 1) / 2;
    float *cv = calloc((size_t)cw * ch, sizeof(float));
    uint8_t *ck = calloc((size_t)cw * ch, 1);
    if (!cv || !ck) { free(cv); free(ck); return G3D_ERR(G3D_ERR_NOMEM, "membrane fill: out of memory"); }
    for (int y = 0; y < ch; y++)
        for (int x = 0; x < cw; x++) {
            double s = 0;
            int c = 0;
            for (int dy = 0; dy < 2; dy++)
                for (int dx = 0; dx < 2; dx++) {
                    int xx = 2 * x + dx, yy = 2 * y + dy;
                    if (xx < w && yy < h && known[(size_t)yy * w + xx]) { s += v[(size_t)yy * w + xx]; c++; }
                }
            if (c) { cv[(size_t)y * cw + x] = (float)(s / c); ck[(size_t)y * cw + x] = 1; }
        }
    g3d_status rc = solve(cv, ck, cw, ch);
    if (rc == G3D_OK) {
        /* Bilinear upsampling of the coarse solution as the starting point. */
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                size_t i = (size_t)y * w + x;
                if (known[i]) continue;
                float fx = fminf(fmaxf((x - 0.5f) * 0.5f, 0.0f), (float)(cw - 1));
                float fy = fminf(fmaxf((y - 0.5f) * 0.5f, 0.0f), (float)(ch - 1));
                int x0 = (int)fx, y0 = (int)fy, x1 = x0 + 1 < cw ? x0 + 1 : x0, y1 = y0 + 1 < ch ? y0 + 1 : y0;
                float ax = fx - x0, ay = fy - y0;
                v[i] = (cv[(size_t)y0 * cw + x0] * (1 - ax) + cv[(size_t)y0 * cw + x1] * ax) * (1 - ay) +
                       (cv[(size_t)y1 * cw + x0] * (1 - ax) + cv[(size_t)y1 * cw + x1] * ax) * ay;
            }
        relax(v, known, w, h, 40);
    }
    free(cv);
    free(ck);
    return rc;
}

g3d_status g3d_membrane_fill(float *values, const uint8_t *known, int w, int h)
{
    if (w < 1 || h < 1) return G3D_ERR(G3D_ERR_ARG, "membrane fill: empty field");
    return solve(values, known, w, h);
}

/* Least-squares plane v = a x + b y + c over the selected pixels; returns 0 if degenerate. */
static int fit_plane(const float *v, const uint8_t *sel, int w, int h, double p[3])
{
    double A[3][3] = {{0}}, r[3] = {0};
    size_t n = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            if (!sel[i]) continue;
            double f[3] = {x / (double)w, y / (double)h, 1.0};
            for (int a = 0; a < 3; a++) {
                for (int b = 0; b < 3; b++) A[a][b] += f[a] * f[b];
                r[a] += f[a] * v[i];
            }
            n++;
        }
    if (n < 10) return 0;
    /* Small ridge term keeps nearly collinear samples from producing wild slopes. */
    A[0][0] += 1e-3 * n;
    A[1][1] += 1e-3 * n;
    double det = A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) - A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0]) +
                 A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]);
    if (fabs(det) < 1e-12) return 0;
    for (int k = 0; k < 3; k++) {
        double M[3][3];
        memcpy(M, A, sizeof M);
        for (int a = 0; a < 3; a++) M[a][k] = r[a];
        p[k] = (M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1]) - M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0]) +
                M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0])) / det;
    }
    p[0] /= w;
    p[1] /= h;
    return 1;
}

g3d_status g3d_membrane_fill_planar(float *values, const uint8_t *known, const uint8_t *fit, int w, int h)
{
    size_t n = (size_t)w * h;
    double plane[3] = {0, 0, 0};
    if (!fit_plane(values, fit ? fit : known, w, h, plane) && !fit_plane(values, known, w, h, plane)) {
        /* Too few samples for a plane: the mean still gives a flat continuation. */
        double s = 0;
        size_t c = 0;
        for (size_t i = 0; i < n; i++) if (known[i]) { s += values[i]; c++; }
        if (c == 0) return G3D_ERR(G3D_ERR_ARG, "membrane fill: no known value");
        plane[2] = s / c;
    }
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            if (known[i]) values[i] -= (float)(plane[0] * x + plane[1] * y + plane[2]);
        }
    g3d_status rc = g3d_membrane_fill(values, known, w, h);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) values[(size_t)y * w + x] += (float)(plane[0] * x + plane[1] * y + plane[2]);
    return rc;
}
