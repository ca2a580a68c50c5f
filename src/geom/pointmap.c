/* A pinhole camera from a point map: view-plane coordinates and the focal/shift fit. */
#include "gen3d/pointmap.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define LOWRES 64   /* side of the subsample the focal/shift fit runs on */

void g3d_linspace_f(float start, float end, int n, float *out)
{
    if (n == 1) {
        out[0] = start;
        return;
    }
    float step = (end - start) / (float)(n - 1);
    for (int i = 0; i < n; i++) out[i] = i < n / 2 ? start + step * (float)i : end - step * (float)(n - 1 - i);
}
void g3d_view_plane_uv(int w, int h, double aspect, float *u, float *v)
{
    double sx = aspect / sqrt(1 + aspect * aspect), sy = 1 / sqrt(1 + aspect * aspect);
    g3d_linspace_f((float)(-sx * (w - 1) / w), (float)(sx * (w - 1) / w), w, u);
    g3d_linspace_f((float)(-sy * (h - 1) / h), (float)(sy * (h - 1) / h), h, v);
}

/* Residuals of the fit for shift x: r[2i], r[2i+1] = f * xy_i / (z_i + x) - uv_i, with f the
 * closed-form best focal for that shift (fit_focal) or the given one. */
typedef struct fit {
    int n;
    const float *xyz;   /* [n, 3] */
    const float *uv;    /* [n, 2] */
    int fit_focal;
    double focal;
} fit;

static void residuals(const fit *f, double shift, double *r)
{
    double focal = f->focal;
    if (f->fit_focal) {
        double num = 0, den = 0;
        for (int i = 0; i < f->n; i++) {
            double z = f->xyz[3 * i + 2] + shift, px = f->xyz[3 * i] / z, py = f->xyz[3 * i + 1] / z;
            num += px * f->uv[2 * i] + py * f->uv[2 * i + 1];
            den += px * px + py * py;
        }
        focal = num / den;
    }
    for (int i = 0; i < f->n; i++) {
        double z = f->xyz[3 * i + 2] + shift;
        r[2 * i] = focal * (f->xyz[3 * i] / z) - f->uv[2 * i];
        r[2 * i + 1] = focal * (f->xyz[3 * i + 1] / z) - f->uv[2 * i + 1];
    }
}

static double norm2(const double *v, int n)
{
    double s = 0;
    for (int i = 0; i < n; i++) s += v[i] * v[i];
    return sqrt(s);
}

/* Levenberg-Marquardt for one unknown starting at 0, following MINPACK's lmdif step for step
 * (forward-difference Jacobian, trust region with diag = 1, factor 100, xtol = gtol = 1e-8,
 * at most 200 evaluations), which is what the official code calls with ftol = 1e-3: the
 * early stop it allows makes the exact sequence of steps part of the result. m residuals;
 * work holds 2m doubles. */
static double lm_shift(const fit *f, int m, double ftol, double *work)
{
    const double xtol = 1e-8, gtol = 1e-8, epsmch = DBL_EPSILON, dwarf = DBL_MIN;
    const int maxfev = 200;
    double *fvec = work, *wa = work + m;
    double x = 0, par = 0, delta = 0, xnorm = 0;
    residuals(f, x, fvec);
    int nfev = 1, iter = 1;
    double fnorm = norm2(fvec, m);
    for (;;) {
        double h = sqrt(epsmch) * fabs(x);
        if (h == 0) h = sqrt(epsmch);
        residuals(f, x + h, wa);
        nfev++;
        double jj = 0, jf = 0;
        for (int i = 0; i < m; i++) {
            double J = (wa[i] - fvec[i]) / h;
            jj += J * J;
            jf += J * fvec[i];
        }
        double r = sqrt(jj);   /* |R| of the one-column QR factorisation */
        if (iter == 1) {
            xnorm = fabs(x);
            delta = 100 * xnorm;
            if (delta == 0) delta = 100;
        }
        double gnorm = fnorm != 0 && r != 0 ? fabs(jf / fnorm / r) : 0;
        if (gnorm <= gtol) return x;
        double qtb = jf / r;   /* first component of Q^T f */
        for (;;) {
            /* lmpar: the step s(par) = qtb r / (r^2 + par) with |s| close to delta. */
            double s = qtb / r, dxnorm = fabs(s), fp = dxnorm - delta;
            if (fp <= 0.1 * delta) {
                par = 0;
            } else {
                double parl = (fp / delta) * r * r;   /* ((fp / delta) / |1/r|) / |1/r| */
                double gn = fabs(r * qtb), paru = gn / delta;
                if (paru == 0) paru = dwarf / fmin(delta, 0.1);
                par = fmax(par, parl);
                par = fmin(par, paru);
                if (par == 0) par = gn / dxnorm;
                for (int it = 1;; it++) {
                    if (par == 0) par = fmax(dwarf, 0.001 * paru);
                    double sdiag = sqrt(r * r + par);
                    s = r * qtb / (r * r + par);
                    dxnorm = fabs(s);
                    double prev = fp;
                    fp = dxnorm - delta;
                    if (fabs(fp) <= 0.1 * delta || (parl == 0 && fp <= prev && prev < 0) || it == 10) break;
                    double wn = 1 / sdiag;   /* |(s / |s|) / sdiag| */
                    double parc = (fp / delta) / wn / wn;
                    if (fp > 0) parl = fmax(parl, par);
                    if (fp < 0) paru = fmin(paru, par);
                    par = fmax(parl, par + parc);
                }
            }
            double p = -s, x1 = x + p, pnorm = fabs(p);
            if (iter == 1) delta = fmin(delta, pnorm);
            residuals(f, x1, wa);
            nfev++;
            double fnorm1 = norm2(wa, m);
            double actred = 0.1 * fnorm1 < fnorm ? 1 - (fnorm1 / fnorm) * (fnorm1 / fnorm) : -1;
            double t1 = r * pnorm / fnorm, t2 = sqrt(par) * pnorm / fnorm;
            double prered = t1 * t1 + t2 * t2 / 0.5, dirder = -(t1 * t1 + t2 * t2);
            double ratio = prered != 0 ? actred / prered : 0;
            if (ratio <= 0.25) {
                double t = actred >= 0 ? 0.5 : 0.5 * dirder / (dirder + 0.5 * actred);
                if (0.1 * fnorm1 >= fnorm || t < 0.1) t = 0.1;
                delta = t * fmin(delta, pnorm / 0.1);
                par /= t;
            } else if (par == 0 || ratio >= 0.75) {
                delta = pnorm / 0.5;
                par *= 0.5;
            }
            if (ratio >= 1e-4) {
                x = x1;
                memcpy(fvec, wa, sizeof(double) * (size_t)m);
                xnorm = fabs(x);
                fnorm = fnorm1;
                iter++;
            }
            if (fabs(actred) <= ftol && prered <= ftol && 0.5 * ratio <= 1) return x;
            if (delta <= xtol * xnorm) return x;
            if (nfev >= maxfev) return x;
            if ((fabs(actred) <= epsmch && prered <= epsmch && 0.5 * ratio <= 1) || delta <= epsmch * xnorm ||
                gnorm <= epsmch)
                return x;
            if (ratio >= 1e-4) break;
        }
    }
}

/* PyTorch's nearest index for resizing `in` samples to `out` (scale in float). */
static int nearest_src(int o, int in, int out)
{
    if (in == out) return o;
    int i = (int)floorf((float)o * ((float)in / (float)out));
    return i < in - 1 ? i : in - 1;
}

g3d_status g3d_pointmap_focal_shift(const float *points, const uint8_t *mask, int w, int h, double focal_in,
                                    float *focal_out, float *shift_out)
{
    int nmax = LOWRES * LOWRES;
    float *xyz = malloc(sizeof(float) * 3 * (size_t)nmax), *uv = malloc(sizeof(float) * 2 * (size_t)nmax);
    float *uvx = malloc(sizeof(float) * ((size_t)w + h));
    double *work = malloc(sizeof(double) * 4 * (size_t)nmax);
    if (!xyz || !uv || !uvx || !work) {
        free(xyz); free(uv); free(uvx); free(work);
        return G3D_ERR(G3D_ERR_NOMEM, "focal/shift fit: out of memory");
    }
    float *uu = uvx, *vv = uvx + w;
    g3d_view_plane_uv(w, h, (double)w / h, uu, vv);
    int n = 0;
    for (int i = 0; i < LOWRES; i++) {
        int r = nearest_src(i, h, LOWRES);
        for (int j = 0; j < LOWRES; j++) {
            int c = nearest_src(j, w, LOWRES);
            size_t k = (size_t)r * w + c;
            if (mask && !mask[k]) continue;
            memcpy(xyz + 3 * n, points + 3 * k, sizeof(float) * 3);
            uv[2 * n] = uu[c];
            uv[2 * n + 1] = vv[r];
            n++;
        }
    }
    if (n < 2) {
        *focal_out = focal_in > 0 ? (float)focal_in : 1.0f;
        *shift_out = 0;
    } else {
        fit f = {n, xyz, uv, focal_in <= 0, focal_in};
        float shift = (float)lm_shift(&f, 2 * n, 1e-3, work);
        double focal = focal_in;
        if (focal_in <= 0) {
            /* the official code re-evaluates the focal in float32 at the float32 shift */
            double num = 0, den = 0;
            for (int i = 0; i < n; i++) {
                float z = xyz[3 * i + 2] + shift, px = xyz[3 * i] / z, py = xyz[3 * i + 1] / z;
                num += (double)(px * uv[2 * i]) + (double)(py * uv[2 * i + 1]);
                den += (double)(px * px) + (double)(py * py);
            }
            focal = num / den;
        }
        *focal_out = (float)focal;
        *shift_out = shift;
    }
    free(xyz); free(uv); free(uvx); free(work);
    return G3D_OK;
}
