/* Real 2-D FFTs through FFTW3 (single precision), PyTorch's conventions.
 *
 * Forward: one r2c plan per (h, w). Inverse: PyTorch (pocketfft) runs a complex inverse
 * transform along H first and the complex-to-real one along W last, so the imaginary parts of
 * the W-axis DC and Nyquist bins are dropped *after* the H transform; a non-Hermitian input
 * (LaMa's spectra after a convolution are) gives different numbers if the axes are done the
 * other way round, so the inverse is two explicit 1-D passes in that order.
 *
 * Plans are made with FFTW_ESTIMATE (the same plan, hence the same numbers, on every run),
 * cached per size and executed with the new-array interface on per-thread buffers from
 * fftwf_malloc (same alignment as at planning). Planning and destroying take a lock: FFTW's
 * planner is not thread-safe; executing a plan is. */
#include "nn/nn_int.h"

#include <fftw3.h>
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

enum { FWD, INV_COLS, INV_ROWS };

typedef struct plan_entry {
    int kind, h, w;
    fftwf_plan p;
    struct plan_entry *next;
} plan_entry;

static pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;
static plan_entry *g_plans;

/* The cached plan of this kind and size, planned on first use with scratch arrays. */
static fftwf_plan get_plan(int kind, int h, int w)
{
    const int wf = w / 2 + 1;
    pthread_mutex_lock(&g_lock);
    plan_entry *e = g_plans;
    while (e && (e->kind != kind || e->h != h || e->w != w)) e = e->next;
    fftwf_plan p = e ? e->p : NULL;
    if (!e) {
        float *re = fftwf_malloc(sizeof(float) * (size_t)h * w);
        fftwf_complex *cx = fftwf_malloc(sizeof(fftwf_complex) * (size_t)h * wf);
        e = malloc(sizeof *e);
        if (re && cx && e) {
            if (kind == FWD)
                p = fftwf_plan_dft_r2c_2d(h, w, re, cx, FFTW_ESTIMATE);
            else if (kind == INV_COLS) /* wf transforms of length h down the columns, in place */
                p = fftwf_plan_many_dft(1, &h, wf, cx, NULL, wf, 1, cx, NULL, wf, 1, FFTW_BACKWARD, FFTW_ESTIMATE);
            else /* h complex-to-real transforms of length w along the rows */
                p = fftwf_plan_many_dft_c2r(1, &w, h, cx, NULL, 1, wf, re, NULL, 1, w, FFTW_ESTIMATE);
        }
        if (p) {
            *e = (plan_entry){kind, h, w, p, g_plans};
            g_plans = e;
        } else {
            free(e);
        }
        fftwf_free(re);
        fftwf_free(cx);
    }
    pthread_mutex_unlock(&g_lock);
    return p;
}

void g3d_nn_fft_forget(void)
{
    pthread_mutex_lock(&g_lock);
    while (g_plans) {
        plan_entry *e = g_plans;
        g_plans = e->next;
        fftwf_destroy_plan(e->p);
        free(e);
    }
    fftwf_cleanup();
    pthread_mutex_unlock(&g_lock);
}

static g3d_status check(int c, int h, int w, const char *what)
{
    if (c < 0 || h <= 0 || w <= 0 || (size_t)h * w > ((size_t)1 << 31))
        return G3D_ERR(G3D_ERR_ARG, "%s: bad size %d x %d x %d", what, c, h, w);
    return G3D_OK;
}

/* Runs one channel at a time over the OpenMP team, each thread with FFTW-aligned buffers of
 * a real plane and a half spectrum. */
typedef struct job {
    fftwf_plan p, p2;
    const float *in;
    float *out;
    int h, w;
    float scale;
} job;

static g3d_status per_channel(const job *j, int c, void (*fn)(const job *, int, float *, fftwf_complex *),
                              const char *what)
{
    const size_t n = (size_t)j->h * j->w, nf = (size_t)j->h * (j->w / 2 + 1);
    int failed = 0;
#pragma omp parallel
    {
        float *re = fftwf_malloc(sizeof(float) * n);
        fftwf_complex *cx = fftwf_malloc(sizeof(fftwf_complex) * nf);
        if (!re || !cx) {
#pragma omp atomic write
            failed = 1;
        }
#pragma omp for schedule(dynamic, 1)
        for (int ch = 0; ch < c; ch++)
            if (re && cx) fn(j, ch, re, cx);
        fftwf_free(re);
        fftwf_free(cx);
    }
    if (failed) return G3D_ERR(G3D_ERR_NOMEM, "%s: cannot allocate %dx%d buffers", what, j->w, j->h);
    return G3D_OK;
}

static void forward_one(const job *j, int ch, float *re, fftwf_complex *cx)
{
    const size_t n = (size_t)j->h * j->w, nf = (size_t)j->h * (j->w / 2 + 1);
    memcpy(re, j->in + ch * n, sizeof(float) * n);
    fftwf_execute_dft_r2c(j->p, re, cx);
    float *yr = j->out + 2 * ch * nf, *yi = yr + nf;
    for (size_t i = 0; i < nf; i++) yr[i] = cx[i][0] * j->scale, yi[i] = cx[i][1] * j->scale;
}

static void inverse_one(const job *j, int ch, float *re, fftwf_complex *cx)
{
    const size_t n = (size_t)j->h * j->w, nf = (size_t)j->h * (j->w / 2 + 1);
    const float *yr = j->in + 2 * ch * nf, *yi = yr + nf;
    for (size_t i = 0; i < nf; i++) cx[i][0] = yr[i] * j->scale, cx[i][1] = yi[i] * j->scale;
    fftwf_execute_dft(j->p, cx, cx);
    fftwf_execute_dft_c2r(j->p2, cx, re);
    memcpy(j->out + ch * n, re, sizeof(float) * n);
}

g3d_status g3d_nn_rfft2(const float *x, int c, int h, int w, float *y)
{
    G3D_TRY(check(c, h, w, "rfft2"));
    job j = {get_plan(FWD, h, w), NULL, x, y, h, w, 1.0f / sqrtf((float)h * w)};
    if (!j.p) return G3D_ERR(G3D_ERR_NOMEM, "rfft2: cannot plan a %dx%d transform", w, h);
    return per_channel(&j, c, forward_one, "rfft2");
}

g3d_status g3d_nn_irfft2(const float *y, int c, int h, int w, float *x)
{
    G3D_TRY(check(c, h, w, "irfft2"));
    job j = {get_plan(INV_COLS, h, w), get_plan(INV_ROWS, h, w), y, x, h, w, 1.0f / sqrtf((float)h * w)};
    if (!j.p || !j.p2) return G3D_ERR(G3D_ERR_NOMEM, "irfft2: cannot plan a %dx%d transform", w, h);
    return per_channel(&j, c, inverse_one, "irfft2");
}

/* ---- reference: the DFT sums in double, O(n^2) per channel ------------------------------- */
g3d_status nn_ref_rfft2(const float *x, int c, int h, int w, float *y)
{
    G3D_TRY(check(c, h, w, "rfft2"));
    const int wf = w / 2 + 1;
    const size_t nf = (size_t)h * wf;
    const double s = 1.0 / sqrt((double)h * w);
    for (int ch = 0; ch < c; ch++)
        for (int u = 0; u < h; u++)
            for (int v = 0; v < wf; v++) {
                double re = 0, im = 0;
                for (int a = 0; a < h; a++)
                    for (int b = 0; b < w; b++) {
                        double ang = -2 * M_PI * ((double)u * a / h + (double)v * b / w);
                        double val = x[((size_t)ch * h + a) * w + b];
                        re += val * cos(ang), im += val * sin(ang);
                    }
                y[2 * ch * nf + (size_t)u * wf + v] = (float)(re * s);
                y[(2 * ch + 1) * nf + (size_t)u * wf + v] = (float)(im * s);
            }
    return G3D_OK;
}

g3d_status nn_ref_irfft2(const float *y, int c, int h, int w, float *x)
{
    G3D_TRY(check(c, h, w, "irfft2"));
    const int wf = w / 2 + 1;
    const size_t nf = (size_t)h * wf;
    const double s = 1.0 / sqrt((double)h * w);
    double *cr = malloc(sizeof(double) * nf * 2);
    if (!cr) return G3D_ERR(G3D_ERR_NOMEM, "irfft2 reference: out of memory");
    double *ci = cr + nf;
    for (int ch = 0; ch < c; ch++) {
        const float *yr = y + 2 * ch * nf, *yi = yr + nf;
        /* inverse DFT down the columns */
        for (int a = 0; a < h; a++)
            for (int v = 0; v < wf; v++) {
                double re = 0, im = 0;
                for (int u = 0; u < h; u++) {
                    double ang = 2 * M_PI * (double)u * a / h, cs = cos(ang), sn = sin(ang);
                    re += yr[(size_t)u * wf + v] * cs - yi[(size_t)u * wf + v] * sn;
                    im += yr[(size_t)u * wf + v] * sn + yi[(size_t)u * wf + v] * cs;
                }
                cr[(size_t)a * wf + v] = re, ci[(size_t)a * wf + v] = im;
            }
        /* Hermitian completion along the rows: bins 0 and w/2 (even w) count their real part only */
        for (int a = 0; a < h; a++)
            for (int b = 0; b < w; b++) {
                double acc = 0;
                for (int v = 0; v < wf; v++) {
                    double ang = 2 * M_PI * (double)v * b / w;
                    double term = cr[(size_t)a * wf + v] * cos(ang) - ci[(size_t)a * wf + v] * sin(ang);
                    int edge = v == 0 || (w % 2 == 0 && v == w / 2);
                    acc += edge ? cr[(size_t)a * wf + v] * cos(ang) : 2 * term;
                }
                x[((size_t)ch * h + a) * w + b] = (float)(acc * s);
            }
    }
    free(cr);
    return G3D_OK;
}
