/* loss.c - masked L1 + SSIM loss with its analytic gradient, masked PSNR, and the evaluation
 * SSIM. */
#include "gen3d/loss.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

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

/* The SSIM statistics are separable 'same' blurs with zero padding, computed row by row on the
 * interleaved image: neighbours in x are c values apart, so all channels go through one pass.
 * Each thread takes a band of output rows and keeps the horizontally blurred rows its window
 * needs in a ring of WIN slots (the few rows at a band's edges are blurred by both threads).
 * Every output is 0 plus the WIN taps in ascending order, those outside the image being zero
 * (adding a zero product leaves a nonzero sum unchanged, so this equals skipping them), in
 * registers: the same sum whatever the thread count, and the rows vectorise (the passes are
 * built for AVX-512, AVX2 and SSE2). The kernel is symmetric, so the blur is self-adjoint and
 * serves the backward pass unchanged. */
enum { FWD_PLANES = 5, BWD_PLANES = 3 }; /* p, t, p^2, t^2, pt; the three backward weights */

typedef struct window {
    double *ring;             /* WIN slots x planes x n: horizontally blurred rows */
    const double *zero;       /* n zeros: the rows above and below the image */
    int planes, n, c, h, top; /* rows below top are in the ring */
} window;

static double *slot(const window *wd, int y, int plane)
{
    return wd->ring + ((size_t)(y % WIN) * wd->planes + plane) * wd->n;
}

/* out[j] = 0 + k[0] r[0][j] + ... + k[WIN-1] r[WIN-1][j], in that order; written out so that the
 * loop vectorises */
static inline void blur_row(double *restrict out, const double *const r[WIN], const double k[WIN], int n)
{
    const double *restrict r0 = r[0], *restrict r1 = r[1], *restrict r2 = r[2], *restrict r3 = r[3],
                           *restrict r4 = r[4], *restrict r5 = r[5], *restrict r6 = r[6], *restrict r7 = r[7],
                           *restrict r8 = r[8], *restrict r9 = r[9], *restrict r10 = r[10];
    const double k0 = k[0], k1 = k[1], k2 = k[2], k3 = k[3], k4 = k[4], k5 = k[5], k6 = k[6], k7 = k[7],
                 k8 = k[8], k9 = k[9], k10 = k[10];
    for (int j = 0; j < n; j++) {
        double acc = 0;
        acc += k0 * r0[j];
        acc += k1 * r1[j];
        acc += k2 * r2[j];
        acc += k3 * r3[j];
        acc += k4 * r4[j];
        acc += k5 * r5[j];
        acc += k6 * r6[j];
        acc += k7 * r7[j];
        acc += k8 * r8[j];
        acc += k9 * r9[j];
        acc += k10 * r10[j];
        out[j] = acc;
    }
}

/* Blurs the padded source rows (HALF * c zeros, n values, HALF * c zeros; plane pl at
 * src + pl * stride) horizontally into the ring as row wd->top. */
static inline void window_push(window *wd, const double *src, size_t stride, const double k[WIN])
{
    const int n = wd->n, c = wd->c;
    for (int pl = 0; pl < wd->planes; pl++) {
        const double *r[WIN];
        for (int i = 0; i < WIN; i++) r[i] = src + pl * stride + (size_t)i * c;
        blur_row(slot(wd, wd->top, pl), r, k, n);
    }
    wd->top++;
}

/* The vertical pass for output row y (rows y - HALF .. y + HALF must be in the ring) into
 * out[plane * n ..]. */
static inline void window_row(const window *wd, int y, double *out, const double k[WIN])
{
    const int n = wd->n;
    for (int pl = 0; pl < wd->planes; pl++) {
        const double *r[WIN];
        for (int i = 0; i < WIN; i++) {
            const int yy = y + i - HALF;
            r[i] = yy < 0 || yy >= wd->h ? wd->zero : slot(wd, yy, pl);
        }
        blur_row(out + (size_t)pl * n, r, k, n);
    }
}

static int valid(const float *mask, size_t i) { return !mask || mask[i] > 0.5f; }

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

/* One evaluation of the loss (or, with eval set, of g3d_ssim's sum) over all rows. */
typedef struct loss_job {
    const float *pred, *target, *mask; /* mask: w*h or NULL */
    float *grad;                       /* NULL: no backward pass */
    int w, h, c, eval;
    double lambda, count, k[WIN];
    double *wts;     /* 3 planes of h padded rows: the backward weights, shared by the threads */
    double *scratch; /* thread_scratch() values per thread */
    double *row_l1, *row_ssim; /* per-row sums, added in row order by the caller */
} loss_job;

/* A thread's scratch: the ring, FWD_PLANES padded source rows, FWD_PLANES blurred rows, and
 * four rows: zeros, the SSIM map, |p - t|, the validity of each value. */
static size_t padded(int n, int c) { return (size_t)n + 2 * HALF * (size_t)c; }
static size_t thread_scratch(int n, int c)
{
    return (size_t)(WIN * FWD_PLANES + FWD_PLANES + 4) * n + FWD_PLANES * padded(n, c);
}

typedef struct rows {
    double *ring, *src, *out, *zero, *smap, *adiff, *ok;
} rows;

static rows thread_rows(const loss_job *jb, int thread)
{
    const int n = jb->w * jb->c;
    rows r;
    r.ring = jb->scratch + thread * thread_scratch(n, jb->c);
    r.src = r.ring + (size_t)WIN * FWD_PLANES * n;
    r.out = r.src + FWD_PLANES * padded(n, jb->c);
    r.zero = r.out + (size_t)FWD_PLANES * n;
    r.smap = r.zero + n;
    r.adiff = r.smap + n;
    r.ok = r.adiff + n;
    memset(r.src, 0, sizeof(double) * FWD_PLANES * padded(n, jb->c));
    memset(r.zero, 0, sizeof(double) * n);
    return r;
}

/* An empty window of `planes` planes whose first output row is y0. */
static window window_from(const loss_job *jb, const rows *r, int planes, int y0)
{
    return (window){r->ring, r->zero, planes, jb->w * jb->c, jb->c, jb->h, y0 - HALF > 0 ? y0 - HALF : 0};
}

/* ok[j] = 1 where the pixel of value j is valid, else 0 */
static inline void validity(const float *mrow, double *ok, int w, int c)
{
    for (int x = 0; x < w; x++)
        for (int ch = 0; ch < c; ch++) ok[x * c + ch] = valid(mrow, x);
}

/* *sum += the sum over x of v[x * c + ch] where ok, for each channel in turn (the order of a
 * loop per channel), up to four channels' chains at a time */
static inline void add_channel_sums(const double *v, const double *ok, int w, int c, double *sum)
{
    for (int c0 = 0; c0 < c; c0 += 4) {
        const int m = c - c0 < 4 ? c - c0 : 4;
        double a0 = 0, a1 = 0, a2 = 0, a3 = 0;
        for (int x = 0; x < w; x++) {
            const double *vx = v + x * c + c0, *ox = ok + x * c + c0;
            a0 = ox[0] != 0 ? a0 + vx[0] : a0;
            if (m > 1) a1 = ox[1] != 0 ? a1 + vx[1] : a1;
            if (m > 2) a2 = ox[2] != 0 ? a2 + vx[2] : a2;
            if (m > 3) a3 = ox[3] != 0 ? a3 + vx[3] : a3;
        }
        *sum += a0;
        if (m > 1) *sum += a1;
        if (m > 2) *sum += a2;
        if (m > 3) *sum += a3;
    }
}

/* The SSIM map and its gradient weights for a row: dL/dssim = ws chained through mu1, E[p^2]
 * and E[pt] (the three planes that the backward blurs). */
static inline void ssim_weights(const double *restrict mu1, const double *restrict mu2, const double *restrict e11,
                                const double *restrict e22, const double *restrict e12, double ws,
                                double *restrict smap, double *restrict wa, double *restrict wb, double *restrict wc,
                                int n)
{
    for (int j = 0; j < n; j++) {
        double m1 = mu1[j], m2 = mu2[j], A, B, C, D;
        ssim_terms(m1, m2, e11[j], e22[j], e12[j], &A, &B, &C, &D);
        double s = A * B / (C * D);
        double dmu1 = (2 * m2 * B - 2 * m2 * A) / (C * D) - s * 2 * m1 / C + s * 2 * m1 / D;
        smap[j] = s;
        wa[j] = ws * dmu1;
        wb[j] = ws * (-s / D);
        wc[j] = ws * (2 * A / (C * D));
    }
}

/* dL/dpred for a row from the blurred weights, plus the L1 term where ok */
static inline void row_gradient(const double *restrict ba, const double *restrict bb, const double *restrict bc,
                                const float *restrict pr, const float *restrict tr, const double *restrict ok,
                                double l1w, double count, float *restrict gr, int n)
{
    for (int j = 0; j < n; j++) {
        const double p = pr[j], t = tr[j], d = p - t;
        double g = ba[j] + 2 * p * bb[j] + t * bc[j];
        const double gl = g + l1w * ((double)(d > 0) - (double)(d < 0)) / count;
        g = ok[j] != 0 ? gl : g;
        gr[j] = (float)g;
    }
}

/* The source rows of the forward blur: p, t, p^2, t^2, pt (planes stride apart) */
static inline void moment_sources(const float *restrict pr, const float *restrict tr, double *restrict p,
                                  double *restrict t, double *restrict pp, double *restrict tt, double *restrict pt,
                                  int n)
{
    for (int j = 0; j < n; j++) {
        p[j] = pr[j];
        t[j] = tr[j];
        pp[j] = p[j] * p[j];
        tt[j] = t[j] * t[j];
        pt[j] = p[j] * t[j];
    }
}

/* Forward rows [y0, y1) of one thread: the moments, then the SSIM map's row sums and, for the
 * training loss, the L1 row sums and the three weights that the backward blurs. */
__attribute__((target_clones("avx512f", "avx2", "default")))
static void forward_rows(const loss_job *jb, const rows *r, int y0, int y1)
{
    const int w = jb->w, h = jb->h, c = jb->c, n = w * c;
    const size_t np = padded(n, c);
    window wd = window_from(jb, r, FWD_PLANES, y0);
    for (int y = y0; y < y1; y++) {
        for (; wd.top < h && wd.top <= y + HALF;) {
            double *p = r->src + HALF * c;
            moment_sources(jb->pred + (size_t)wd.top * n, jb->target + (size_t)wd.top * n, p, p + np, p + 2 * np,
                           p + 3 * np, p + 4 * np, n);
            window_push(&wd, r->src, np, jb->k);
        }
        window_row(&wd, y, r->out, jb->k);
        const double *mu1 = r->out, *mu2 = mu1 + n, *e11 = mu2 + n, *e22 = e11 + n, *e12 = e22 + n;
        const float *mrow = jb->mask ? jb->mask + (size_t)y * w : NULL;
        if (jb->eval) { /* the map over the pixels whose window lies inside the image */
            for (int ch = 0; ch < c; ch++) {
                double sum = 0;
                for (int x = HALF; x < w - HALF; x++) {
                    if (!valid(mrow, x)) continue;
                    const int j = x * c + ch;
                    double A, B, C, D;
                    ssim_terms(mu1[j], mu2[j], e11[j], e22[j], e12[j], &A, &B, &C, &D);
                    sum += A * B / (C * D);
                }
                jb->row_ssim[y] += sum;
            }
            continue;
        }
        /* the map, and dL/dssim = -lambda / count chained through mu1, E[p^2] and E[pt] */
        double *restrict smap = r->smap, *restrict ok = r->ok;
        validity(mrow, ok, w, c);
        double *wa = jb->wts + y * np + HALF * c, *wb = wa + h * np, *wc = wb + h * np;
        ssim_weights(mu1, mu2, e11, e22, e12, -jb->lambda / jb->count, smap, wa, wb, wc, n);
        if (mrow)
            for (int j = 0; j < n; j++)
                if (ok[j] == 0) wa[j] = wb[j] = wc[j] = 0;
        const float *restrict pr = jb->pred + (size_t)y * n, *restrict tr = jb->target + (size_t)y * n;
        double *restrict ad = r->adiff;
        for (int j = 0; j < n; j++) ad[j] = fabs((double)pr[j] - (double)tr[j]);
        add_channel_sums(ad, ok, w, c, &jb->row_l1[y]);
        add_channel_sums(smap, ok, w, c, &jb->row_ssim[y]);
    }
}

/* Backward rows [y0, y1): the blurred weights, chained to dL/dpred, plus the L1 term. */
__attribute__((target_clones("avx512f", "avx2", "default")))
static void backward_rows(const loss_job *jb, const rows *r, int y0, int y1)
{
    const int w = jb->w, h = jb->h, c = jb->c, n = w * c;
    const size_t np = padded(n, c);
    window wd = window_from(jb, r, BWD_PLANES, y0);
    const double l1w = 1 - jb->lambda, count = jb->count;
    for (int y = y0; y < y1; y++) {
        for (; wd.top < h && wd.top <= y + HALF;) window_push(&wd, jb->wts + wd.top * np, h * np, jb->k);
        window_row(&wd, y, r->out, jb->k);
        const double *restrict ba = r->out, *restrict bb = ba + n, *restrict bc = bb + n, *restrict ok = r->ok;
        const float *restrict pr = jb->pred + (size_t)y * n, *restrict tr = jb->target + (size_t)y * n;
        validity(jb->mask ? jb->mask + (size_t)y * w : NULL, r->ok, w, c);
        row_gradient(ba, bb, bc, pr, tr, ok, l1w, count, jb->grad + (size_t)y * n, n);
    }
}

static void run_job(const loss_job *jb)
{
#pragma omp parallel
    {
        const int nt = omp_get_num_threads(), ti = omp_get_thread_num();
        const rows r = thread_rows(jb, ti);
        const int lo = jb->eval ? HALF : 0, hi = jb->eval ? jb->h - HALF : jb->h;
        const int y0 = lo + (int)((int64_t)(hi - lo) * ti / nt), y1 = lo + (int)((int64_t)(hi - lo) * (ti + 1) / nt);
        forward_rows(jb, &r, y0, y1);
        if (jb->grad) {
#pragma omp barrier
            const int b0 = (int)((int64_t)jb->h * ti / nt), b1 = (int)((int64_t)jb->h * (ti + 1) / nt);
            backward_rows(jb, &r, b0, b1);
        }
    }
}

/* Allocates the job's scratch and row sums (zeroed); G3D_ERR_NOMEM on failure. */
static g3d_status job_alloc(loss_job *jb, int with_weights)
{
    const int n = jb->w * jb->c;
    const size_t nt = (size_t)omp_get_max_threads();
    const size_t per = thread_scratch(n, jb->c), wts = with_weights ? BWD_PLANES * jb->h * padded(n, jb->c) : 0;
    jb->scratch = malloc(sizeof(double) * (nt * per + wts));
    jb->row_l1 = g3d_calloc((size_t)jb->h, 2 * sizeof(double), "loss row sums");
    if (!jb->scratch || !jb->row_l1) {
        free(jb->scratch);
        free(jb->row_l1);
        return G3D_ERR(G3D_ERR_NOMEM, "loss: out of memory for a %dx%d image's scratch", jb->w, jb->h);
    }
    jb->wts = with_weights ? jb->scratch + nt * per : NULL;
    for (size_t row = 0; with_weights && row < (size_t)BWD_PLANES * jb->h; row++) {
        double *v = jb->wts + row * padded(n, jb->c);
        memset(v, 0, sizeof(double) * HALF * jb->c);
        memset(v + HALF * jb->c + n, 0, sizeof(double) * HALF * jb->c);
    }
    jb->row_ssim = jb->row_l1 + jb->h;
    gauss_window(jb->k);
    return G3D_OK;
}

static void job_free(loss_job *jb)
{
    free(jb->scratch);
    free(jb->row_l1);
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
    loss_job jb = {.pred = pred->data, .target = target->data, .mask = mask ? mask->data : NULL,
                   .grad = grad ? grad->data : NULL, .w = pred->w, .h = pred->h, .c = pred->c,
                   .lambda = lambda, .count = (double)nvalid * pred->c};
    G3D_TRY(job_alloc(&jb, 1));
    run_job(&jb);
    double l1 = 0, ssim_sum = 0;
    for (int y = 0; y < jb.h; y++) {
        l1 += jb.row_l1[y];
        ssim_sum += jb.row_ssim[y];
    }
    job_free(&jb);
    double mean_ssim = ssim_sum / jb.count;
    *loss = (1 - lambda) * (l1 / jb.count) + lambda * (1 - mean_ssim);
    if (ssim) *ssim = mean_ssim;
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
        if (!valid(mask ? mask->data : NULL, i)) continue;
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
    /* Only pixels whose whole window lies inside the image are averaged; there the zero padding
     * of the blur never enters, so this is the 'valid' convolution of the usual definition. */
    int64_t count = 0;
    for (int y = HALF; y < h - HALF; y++)
        for (int x = HALF; x < w - HALF; x++) count += valid(mask ? mask->data : NULL, (size_t)y * w + x);
    if (count == 0) return G3D_ERR(G3D_ERR_ARG, "ssim: no valid pixel lies %d pixels inside the image border", HALF);
    loss_job jb = {.pred = a->data, .target = b->data, .mask = mask ? mask->data : NULL,
                   .w = w, .h = h, .c = c, .eval = 1};
    G3D_TRY(job_alloc(&jb, 0));
    run_job(&jb);
    double total = 0;
    for (int y = 0; y < h; y++) total += jb.row_ssim[y];
    job_free(&jb);
    *ssim = total / ((double)count * c);
    return G3D_OK;
}
