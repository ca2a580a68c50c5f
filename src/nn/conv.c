/* Conv2d and ConvTranspose2d.
 *
 * Conv2d is a product W [cout, cin*kh*kw] x cols [cin*kh*kw, ho*wo] whose right-hand side is
 * never stored: the product driver packs each cache-sized block of it straight from the input
 * map (nn_convsrc, with the padding mode applied there). Depthwise convolutions, where that
 * product would have an inner dimension of 9, run as a direct stencil per channel instead.
 *
 * ConvTranspose2d is split by output phase: the outputs (oy, ox) with oy % s == ry and
 * ox % s == rx receive only the taps ky, kx with (ry + pad - ky*dil) divisible by s, so each
 * phase is an ordinary convolution of the input with a sub-kernel, written to every s-th
 * output pixel. No overlapping scatter-add, and each output is one fixed-order sum. */
#include "nn/nn_int.h"

#include <immintrin.h>
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

static int one(int v) { return v > 0 ? v : 1; }

g3d_nn_conv g3d_nn_conv_make(int cin, int cout, int k, int stride, int pad, const float *w, const float *b)
{
    g3d_nn_conv c = {.cin = cin, .cout = cout, .kh = k, .kw = k, .stride = stride, .pad_h = pad, .pad_w = pad,
                     .w = w, .b = b};
    return c;
}

g3d_status g3d_nn_conv_out_size(const g3d_nn_conv *c, int h, int w, int *ho, int *wo)
{
    const int s = one(c->stride), d = one(c->dilation), g = one(c->groups);
    if (c->cin <= 0 || c->cout <= 0 || c->kh <= 0 || c->kw <= 0 || c->pad_h < 0 || c->pad_w < 0 || h <= 0 || w <= 0)
        return G3D_ERR(G3D_ERR_ARG, "conv: bad configuration (%d->%d channels, kernel %dx%d, pad %d,%d) or input %dx%d",
                       c->cin, c->cout, c->kh, c->kw, c->pad_h, c->pad_w, w, h);
    if (c->cin % g || c->cout % g)
        return G3D_ERR(G3D_ERR_ARG, "conv: %d->%d channels not divisible by %d groups", c->cin, c->cout, g);
    if (c->wtype != G3D_DT_F32 && c->wtype != G3D_DT_F16 && c->wtype != G3D_DT_BF16)
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "conv: weights of type %s", g3d_dtype_name(c->wtype));
    if (c->transposed) {
        if (g != 1) return G3D_ERR(G3D_ERR_UNSUPPORTED, "conv_transpose2d: groups are not supported");
        if (c->pad_mode != G3D_PAD_ZEROS) return G3D_ERR(G3D_ERR_ARG, "conv_transpose2d: only zero padding");
        if (c->output_padding < 0 || (c->output_padding >= s && c->output_padding >= d))
            return G3D_ERR(G3D_ERR_ARG, "conv_transpose2d: output_padding %d must be smaller than stride or dilation",
                           c->output_padding);
        *ho = (h - 1) * s - 2 * c->pad_h + d * (c->kh - 1) + c->output_padding + 1;
        *wo = (w - 1) * s - 2 * c->pad_w + d * (c->kw - 1) + c->output_padding + 1;
    } else {
        if (c->pad_mode == G3D_PAD_SYMMETRIC) return G3D_ERR(G3D_ERR_ARG, "conv: symmetric padding is for g3d_nn_pad2d");
        if (c->pad_mode == G3D_PAD_REFLECT && (c->pad_h >= h || c->pad_w >= w))
            return G3D_ERR(G3D_ERR_ARG, "conv: reflect padding %d,%d needs an input larger than %dx%d", c->pad_h,
                           c->pad_w, w, h);
        *ho = (h + 2 * c->pad_h - d * (c->kh - 1) - 1) / s + 1;
        *wo = (w + 2 * c->pad_w - d * (c->kw - 1) - 1) / s + 1;
        if (h + 2 * c->pad_h < d * (c->kh - 1) + 1 || w + 2 * c->pad_w < d * (c->kw - 1) + 1) *ho = 0;
    }
    if (*ho <= 0 || *wo <= 0)
        return G3D_ERR(G3D_ERR_ARG, "conv: input %dx%d too small for kernel %dx%d (stride %d, pad %d,%d)", w, h, c->kw,
                       c->kh, s, c->pad_w, c->pad_h);
    return G3D_OK;
}

/* The epilogue of output channels lo.. as seen by a product over a slice of channels. */
static g3d_nn_epi epi_slice(const g3d_nn_epi *e, int lo, size_t plane)
{
    g3d_nn_epi s = {0};
    if (e) {
        s = *e;
        if (s.scale) s.scale += lo;
        if (s.res) s.res += (size_t)lo * plane;
    }
    return s;
}

/* ---- depthwise ------------------------------------------------------------------------- */
/* n (<= 64) outputs of one row, ox0.. : bias + the taps in order over the padded input rows
 * (rows[ky] is the row tap row ky reads). Called with constant n and s, the sums stay in
 * registers across the taps. */
static inline __attribute__((always_inline)) void dw_block(const float *const *rows, const float *wk, int kh, int kw,
                                                           int s, int d, int ox0, int n, float bias, float *y)
{
    float acc[64];
    for (int i = 0; i < n; i++) acc[i] = bias;
    for (int ky = 0; ky < kh; ky++)
        for (int kx = 0; kx < kw; kx++) {
            const float wv = wk[ky * kw + kx], *in = rows[ky] + (size_t)ox0 * s + kx * d;
            for (int i = 0; i < n; i++) acc[i] += wv * in[(size_t)i * s];
        }
    memcpy(y + ox0, acc, sizeof(float) * n);
}

/* Stride 1 with AVX-512: blocks of 64 and then 16 outputs, each sum in a register across the
 * taps (fused multiply-adds). Returns how many outputs it wrote. */
__attribute__((target("avx512f"))) static int dw_row512(const float *const *rows, const float *wk, int kh, int kw,
                                                        int d, int wo, float bias, float *y)
{
    int ox0 = 0;
    for (; ox0 + 64 <= wo; ox0 += 64) {
        __m512 a0 = _mm512_set1_ps(bias), a1 = a0, a2 = a0, a3 = a0;
        for (int ky = 0; ky < kh; ky++)
            for (int kx = 0; kx < kw; kx++) {
                const __m512 wv = _mm512_set1_ps(wk[ky * kw + kx]);
                const float *in = rows[ky] + ox0 + kx * d;
                a0 = _mm512_fmadd_ps(wv, _mm512_loadu_ps(in), a0);
                a1 = _mm512_fmadd_ps(wv, _mm512_loadu_ps(in + 16), a1);
                a2 = _mm512_fmadd_ps(wv, _mm512_loadu_ps(in + 32), a2);
                a3 = _mm512_fmadd_ps(wv, _mm512_loadu_ps(in + 48), a3);
            }
        _mm512_storeu_ps(y + ox0, a0), _mm512_storeu_ps(y + ox0 + 16, a1);
        _mm512_storeu_ps(y + ox0 + 32, a2), _mm512_storeu_ps(y + ox0 + 48, a3);
    }
    for (; ox0 + 16 <= wo; ox0 += 16) {
        __m512 a = _mm512_set1_ps(bias);
        for (int ky = 0; ky < kh; ky++)
            for (int kx = 0; kx < kw; kx++)
                a = _mm512_fmadd_ps(_mm512_set1_ps(wk[ky * kw + kx]), _mm512_loadu_ps(rows[ky] + ox0 + kx * d), a);
        _mm512_storeu_ps(y + ox0, a);
    }
    return ox0;
}

/* One output row of one channel: y[ox] = bias + sum over the taps of w * rows[ky][ox*s + kx*d]. */
__attribute__((target_clones("avx2", "default"))) static void dw_row(const float *const *rows, const float *wk,
                                                                     int kh, int kw, int s, int d, int wo,
                                                                     float bias, float *y)
{
    int ox0 = s == 1 && nn_isa() == NN_ISA_AVX512 ? dw_row512(rows, wk, kh, kw, d, wo, bias, y) : 0;
    if (s == 1)
        for (; ox0 + 64 <= wo; ox0 += 64) dw_block(rows, wk, kh, kw, 1, d, ox0, 64, bias, y);
    else
        for (; ox0 + 64 <= wo; ox0 += 64) dw_block(rows, wk, kh, kw, s, d, ox0, 64, bias, y);
    if (ox0 < wo) dw_block(rows, wk, kh, kw, s, d, ox0, wo - ox0, bias, y);
}

/* Each channel is a stencil over its own plane, read row by row: a ring of the last
 * (kh-1)*d+1 padded input rows holds what one output row needs, so the plane is read from
 * memory once and written once, with no padded copy of it. */
static g3d_status depthwise(const g3d_nn_conv *c, const float *x, int h, int w, int ho, int wo, float *y,
                            const g3d_nn_epi *epi)
{
    const int s = one(c->stride), d = one(c->dilation), ph = c->pad_h, pw = c->pad_w, kh = c->kh;
    const int wp = w + 2 * pw, kk = kh * c->kw, ring = (kh - 1) * d + 1, zeros = c->pad_mode == G3D_PAD_ZEROS;
    const size_t plane = (size_t)ho * wo;
    int failed = 0;
#pragma omp parallel
    {
        float *buf = malloc(sizeof(float) * ((size_t)ring * wp + kk + wo));
        const float **rows = malloc(sizeof(float *) * kh);
        if (!buf || !rows) {
#pragma omp atomic write
            failed = 1;
        }
#pragma omp for schedule(dynamic, 1)
        for (int ch = 0; ch < c->cin; ch++) {
            if (!buf || !rows) continue;
            const float *xc = x + (size_t)ch * h * w;
            float *wk = buf + (size_t)ring * wp, *t = wk + kk, *yc = y + (size_t)ch * plane;
            if (c->wtype == G3D_DT_F32)
                memcpy(wk, (const float *)c->w + (size_t)ch * kk, sizeof(float) * kk);
            else
                nn_widen(c->wtype, (const uint16_t *)c->w + (size_t)ch * kk, wk, kk);
            const float bias = c->b ? c->b[ch] : 0.0f;
            int filled = 0; /* padded rows 0..filled-1 have been through the ring */
            for (int oy = 0; oy < ho; oy++) {
                for (; filled <= oy * s + (kh - 1) * d; filled++) {
                    float *r = buf + (size_t)(filled % ring) * wp;
                    const int iy = filled - ph;
                    if (zeros && (iy < 0 || iy >= h)) {
                        memset(r, 0, sizeof(float) * wp);
                        continue;
                    }
                    const float *src = xc + (size_t)nn_pad_index(c->pad_mode, iy, h) * w;
                    memcpy(r + pw, src, sizeof(float) * w);
                    for (int j = 0; j < pw; j++) {
                        r[j] = zeros ? 0.0f : src[nn_pad_index(c->pad_mode, j - pw, w)];
                        r[pw + w + j] = zeros ? 0.0f : src[nn_pad_index(c->pad_mode, w + j, w)];
                    }
                }
                for (int ky = 0; ky < kh; ky++) rows[ky] = buf + (size_t)((oy * s + ky * d) % ring) * wp;
                float *yr = yc + (size_t)oy * wo, *o = epi && epi->res ? t : yr;
                dw_row(rows, wk, kh, c->kw, s, d, wo, bias, o);
                if (epi) {
                    nn_act(epi->act, o, wo);
                    if (epi->scale)
                        for (int i = 0; i < wo; i++) o[i] *= epi->scale[ch];
                    if (epi->res) /* y may be the residual: o is t, stored after the residual is read */
                        for (int i = 0; i < wo; i++) yr[i] = t[i] + epi->res[(size_t)ch * plane + (size_t)oy * wo + i];
                }
            }
        }
        free(buf);
        free(rows);
    }
    if (failed) return G3D_ERR(G3D_ERR_NOMEM, "depthwise conv: cannot allocate scratch for %d rows of %d", ring, wp);
    return G3D_OK;
}

/* ---- ConvTranspose2d phases -------------------------------------------------------------- */
typedef struct phase {
    int ry, rx, ntaps;
    int *dy, *dx;
    float *w; /* [cout, cin*ntaps] */
} phase;

typedef struct convt_prep {
    int nph;
    phase *ph;
    /* kernel = stride, no padding: each phase is one tap at offset 0, so all phases are one
     * product [cout*nph x cin] x x, packing the input once: the phases' kernels stacked, row
     * co*nph + ry*s + rx for output channel co of phase (ry, rx), so the s rows of one (co, ry)
     * fill an output row together (the product's interleaved epilogue) */
    float *stack;
} convt_prep;

static int floordiv(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

static void convt_prep_free(convt_prep *p)
{
    if (!p) return;
    for (int i = 0; i < p->nph; i++) {
        free(p->ph[i].dy);
        free(p->ph[i].dx);
        free(p->ph[i].w);
    }
    free(p->ph);
    free(p->stack);
    free(p);
}

static g3d_status convt_build(const g3d_nn_conv *c, convt_prep **out)
{
    const int s = one(c->stride), d = one(c->dilation), kk = c->kh * c->kw;
    convt_prep *p = calloc(1, sizeof *p);
    float *wf = malloc(sizeof(float) * (size_t)c->cin * c->cout * kk);
    if (p) p->ph = calloc((size_t)s * s, sizeof(phase));
    if (!p || !p->ph || !wf) goto nomem;
    if (c->wtype == G3D_DT_F32)
        memcpy(wf, c->w, sizeof(float) * (size_t)c->cin * c->cout * kk);
    else
        nn_widen(c->wtype, c->w, wf, (long)c->cin * c->cout * kk);
    p->nph = s * s;
    for (int ry = 0; ry < s; ry++)
        for (int rx = 0; rx < s; rx++) {
            phase *f = &p->ph[ry * s + rx];
            f->ry = ry, f->rx = rx;
            f->dy = malloc(sizeof(int) * kk);
            f->dx = malloc(sizeof(int) * kk);
            int *ky_of = malloc(sizeof(int) * kk);
            if (!f->dy || !f->dx || !ky_of) {
                free(ky_of);
                goto nomem;
            }
            for (int ky = 0; ky < c->kh; ky++) {
                int ny = ry + c->pad_h - ky * d;
                if (ny - floordiv(ny, s) * s) continue;
                for (int kx = 0; kx < c->kw; kx++) {
                    int nx = rx + c->pad_w - kx * d;
                    if (nx - floordiv(nx, s) * s) continue;
                    f->dy[f->ntaps] = floordiv(ny, s);
                    f->dx[f->ntaps] = floordiv(nx, s);
                    ky_of[f->ntaps++] = ky * c->kw + kx;
                }
            }
            if (f->ntaps) {
                const int K = c->cin * f->ntaps;
                f->w = malloc(sizeof(float) * (size_t)c->cout * K);
                if (!f->w) {
                    free(ky_of);
                    goto nomem;
                }
                for (int co = 0; co < c->cout; co++)
                    for (int ci = 0; ci < c->cin; ci++)
                        for (int t = 0; t < f->ntaps; t++)
                            f->w[(size_t)co * K + ci * f->ntaps + t] = wf[((size_t)ci * c->cout + co) * kk + ky_of[t]];
            }
            free(ky_of);
        }
    free(wf);
    int single = c->output_padding == 0; /* else the padded border gets no tap, only the bias */
    for (int i = 0; i < p->nph; i++) single &= p->ph[i].ntaps == 1 && !p->ph[i].dy[0] && !p->ph[i].dx[0];
    if (single) {
        p->stack = malloc(sizeof(float) * (size_t)c->cout * c->cin * p->nph);
        if (!p->stack) goto nomem_p;
        for (int co = 0; co < c->cout; co++)
            for (int i = 0; i < p->nph; i++)
                memcpy(p->stack + ((size_t)co * p->nph + i) * c->cin, p->ph[i].w + (size_t)co * c->cin,
                       sizeof(float) * c->cin);
    }
    *out = p;
    return G3D_OK;
nomem_p:
    wf = NULL;
nomem:
    free(wf);
    convt_prep_free(p);
    return G3D_ERR(G3D_ERR_NOMEM, "conv_transpose2d: cannot allocate the %d->%d phase kernels", c->cin, c->cout);
}

static g3d_status convt_forward(const g3d_nn_conv *c, const convt_prep *p, const float *x, int h, int w, int ho, int wo,
                                float *y, const g3d_nn_epi *epi)
{
    const int s = one(c->stride);
    const size_t plane = (size_t)ho * wo;
    if (p->stack) {
        /* row r of the stacked product is channel r / nph of phase r % nph */
        long *rowoff = malloc(sizeof(long) * p->nph * c->cout);
        if (!rowoff) return G3D_ERR(G3D_ERR_NOMEM, "conv_transpose2d: out of memory");
        for (int co = 0; co < c->cout; co++)
            for (int i = 0; i < p->nph; i++)
                rowoff[co * p->nph + i] = (long)co * plane + (long)p->ph[i].ry * wo + p->ph[i].rx;
        nn_gemm g = {.M = p->nph * c->cout, .N = h * w, .K = c->cin, .a = p->stack, .lda = c->cin, .ka = 1,
                     .bkind = NN_B_ROWS, .b = x, .ldb = (long)h * w, .y = y, .rowoff = rowoff, .qw = w,
                     .oys = (long)s * wo, .oxs = s, .alpha = 1.0f, .bias = c->b, .chan_rows = 1, .chan_div = p->nph,
                     .ilv = s, .epi = epi};
        g3d_status rc = nn_gemm_run(&g);
        free(rowoff);
        return rc;
    }
    for (int i = 0; i < p->nph; i++) {
        const phase *f = &p->ph[i];
        int qh = f->ry < ho ? (ho - 1 - f->ry) / s + 1 : 0, qw = f->rx < wo ? (wo - 1 - f->rx) / s + 1 : 0;
        if (!qh || !qw) continue;
        if (!f->ntaps) {
            /* no tap reaches these pixels: bias and epilogue only */
            for (int co = 0; co < c->cout; co++)
                for (int qy = 0; qy < qh; qy++)
                    for (int qx = 0; qx < qw; qx++) {
                        size_t off = (size_t)co * plane + (size_t)(qy * s + f->ry) * wo + qx * s + f->rx;
                        float v = nn_ref_act1(epi ? epi->act : G3D_ACT_NONE, c->b ? c->b[co] : 0.0f);
                        if (epi && epi->scale) v *= epi->scale[co];
                        if (epi && epi->res) v += epi->res[off];
                        y[off] = v;
                    }
            continue;
        }
        nn_convsrc src = {.x = x, .h = h, .w = w, .qh = qh, .qw = qw, .stride = 1, .ntaps = f->ntaps, .dy = f->dy,
                          .dx = f->dx, .pad = G3D_PAD_ZEROS};
        nn_gemm g = {.M = c->cout, .N = qh * qw, .K = c->cin * f->ntaps, .a = f->w, .lda = c->cin * f->ntaps, .ka = 1,
                     .bkind = NN_B_CONV, .conv = &src, .y = y, .ldy = (long)plane, .qw = qw, .oys = (long)s * wo,
                     .oxs = s, .ooff = (long)f->ry * wo + f->rx, .alpha = 1.0f, .bias = c->b, .chan_rows = 1,
                     .epi = epi};
        G3D_TRY(nn_gemm_run(&g));
    }
    return G3D_OK;
}

/* ---- forward ----------------------------------------------------------------------------- */
/* ---- few output channels, large kernel -------------------------------------------------------- */
/* With a handful of output channels and a large kernel (LaMa's 7x7 64->3 output layer) the
 * product would have only cout rows: mostly padding of the kernel's row tile, and every input
 * value gathered into a panel would serve only those rows. Instead every (channel, tap) pair
 * becomes a row: Z [cout*kk, rows*wp] = W' [cout*kk, cin] P [cin, rows*wp] over a band of the
 * padded input, and each output adds up its kk shifted taps in a fixed order. */
#define TAP_Z_FLOATS ((size_t)4 << 20) /* Z per band: 16 MB */

static int tapwise_eligible(const g3d_nn_conv *c)
{
    return !c->transposed && one(c->groups) == 1 && one(c->stride) == 1 && one(c->dilation) == 1 && c->cout <= 4 &&
           c->kh * c->kw >= 25 && c->cin >= 16;
}

static float wval(const g3d_nn_conv *c, size_t i);

static g3d_status tapwise(const g3d_nn_conv *c, const float *x, int h, int w, int ho, int wo, float *y,
                          const g3d_nn_epi *epi)
{
    const int kk = c->kh * c->kw, rz = c->cout * kk, wp = w + 2 * c->pad_w, halo = c->kh - 1;
    long rows = (long)(TAP_Z_FLOATS / ((size_t)rz * wp));
    int band = rows - halo < 1 ? 1 : rows - halo > ho ? ho : (int)(rows - halo);
    const size_t zn = (size_t)(band + halo) * wp;
    float *wt = malloc(sizeof(float) * (size_t)rz * c->cin), *P = malloc(sizeof(float) * (size_t)c->cin * zn);
    float *Z = malloc(sizeof(float) * (size_t)rz * zn), *S = malloc(sizeof(float) * (size_t)c->cout * band * wo);
    g3d_status rc = wt && P && Z && S ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "conv: out of memory");
    if (rc == G3D_OK)
        for (int o = 0; o < c->cout; o++)
            for (int t = 0; t < kk; t++)
                for (int ci = 0; ci < c->cin; ci++) wt[((size_t)o * kk + t) * c->cin + ci] = wval(c, ((size_t)o * c->cin + ci) * kk + t);
    const size_t plane = (size_t)ho * wo;
    for (int oy0 = 0; oy0 < ho && rc == G3D_OK; oy0 += band) {
        const int nb = ho - oy0 < band ? ho - oy0 : band, nrow = nb + halo;
        /* input rows a..b of the padded map, the part inside the image padded by g3d_nn_pad2d */
        const int a = oy0 - c->pad_h, b = a + nrow - 1, a1 = a < 0 ? 0 : a, b1 = b > h - 1 ? h - 1 : b;
        for (int ci = 0; ci < c->cin && rc == G3D_OK; ci++)
            rc = g3d_nn_pad2d(x + ((size_t)ci * h + a1) * w, 1, b1 - a1 + 1, w, a1 - a, b - b1, c->pad_w, c->pad_w,
                              c->pad_mode, P + (size_t)ci * nrow * wp);
        if (rc != G3D_OK) break;
        const long n = (long)nrow * wp;
        nn_gemm m = {.M = rz, .N = (int)n, .K = c->cin, .a = wt, .lda = c->cin, .ka = 1, .bkind = NN_B_ROWS, .b = P,
                     .ldb = n, .y = Z, .ldy = n, .alpha = 1.0f, .chan_rows = 1};
        if ((rc = nn_gemm_run(&m)) != G3D_OK) break;
        const int nr = c->cout * nb;
#pragma omp parallel for schedule(static) if (!omp_in_parallel())
        for (int i = 0; i < nr; i++) {
            const int o = i / nb, r = i % nb;
            float *s = S + (size_t)i * wo;
            const float bias = c->b ? c->b[o] : 0.0f;
            for (int ox = 0; ox < wo; ox++) s[ox] = bias;
            for (int ky = 0; ky < c->kh; ky++)
                for (int kx = 0; kx < c->kw; kx++) {
                    const float *z = Z + ((size_t)o * kk + ky * c->kw + kx) * n + (size_t)(r + ky) * wp + kx;
                    for (int ox = 0; ox < wo; ox++) s[ox] += z[ox];
                }
            if (epi && epi->act != G3D_ACT_NONE) nn_act(epi->act, s, wo);
            float *yr = y + o * plane + (size_t)(oy0 + r) * wo;
            const float *res = epi && epi->res ? epi->res + o * plane + (size_t)(oy0 + r) * wo : NULL;
            const float sc = epi && epi->scale ? epi->scale[o] : 1.0f;
            for (int ox = 0; ox < wo; ox++) yr[ox] = (res ? res[ox] : 0.0f) + sc * s[ox];
        }
    }
    free(wt), free(P), free(Z), free(S);
    return rc;
}

g3d_status g3d_nn_conv_forward(const g3d_nn_conv *c, const float *x, int h, int w, float *y, const g3d_nn_epi *epi)
{
    int ho, wo;
    G3D_TRY(g3d_nn_conv_out_size(c, h, w, &ho, &wo));
    if (c->transposed) {
        if (c->prep) return convt_forward(c, c->prep, x, h, w, ho, wo, y, epi);
        convt_prep *p;
        G3D_TRY(convt_build(c, &p));
        g3d_status rc = convt_forward(c, p, x, h, w, ho, wo, y, epi);
        convt_prep_free(p);
        return rc;
    }
    if (c->prep) return nn_wino_forward(c, c->prep, x, h, w, ho, wo, y, epi);
    if (tapwise_eligible(c)) return tapwise(c, x, h, w, ho, wo, y, epi);
    const int G = one(c->groups), s = one(c->stride), d = one(c->dilation);
    if (G > 1 && G == c->cin && G == c->cout) return depthwise(c, x, h, w, ho, wo, y, epi);
    const int cg = c->cin / G, og = c->cout / G, K = cg * c->kh * c->kw, kk = c->kh * c->kw;
    const size_t plane = (size_t)ho * wo;
    int *dy = malloc(sizeof(int) * 2 * kk), *dx = dy + kk;
    if (!dy) return G3D_ERR(G3D_ERR_NOMEM, "conv: out of memory");
    for (int ky = 0; ky < c->kh; ky++)
        for (int kx = 0; kx < c->kw; kx++) {
            dy[ky * c->kw + kx] = ky * d - c->pad_h;
            dx[ky * c->kw + kx] = kx * d - c->pad_w;
        }
    const int pointwise = kk == 1 && s == 1 && c->pad_h == 0 && c->pad_w == 0;
    const size_t esz = g3d_dtype_size(c->wtype);
    g3d_status rc = G3D_OK;
    for (int g = 0; g < G && rc == G3D_OK; g++) {
        const float *xg = x + (size_t)g * cg * h * w;
        nn_convsrc src = {.x = xg, .h = h, .w = w, .qh = ho, .qw = wo, .stride = s, .ntaps = kk, .dy = dy, .dx = dx,
                          .pad = c->pad_mode};
        g3d_nn_epi e = epi_slice(epi, g * og, plane);
        const void *wg = (const char *)c->w + (size_t)g * og * K * esz;
        nn_gemm m = {.M = og, .N = (int)plane, .K = K, .lda = K, .ka = 1, .y = y + (size_t)g * og * plane,
                     .ldy = (long)plane, .alpha = 1.0f, .bias = c->b ? c->b + g * og : NULL, .chan_rows = 1,
                     .epi = epi ? &e : NULL};
        if (c->wtype == G3D_DT_F32)
            m.a = wg;
        else
            m.a16 = wg, m.a16t = c->wtype;
        if (pointwise)
            m.bkind = NN_B_ROWS, m.b = xg, m.ldb = (long)plane;
        else
            m.bkind = NN_B_CONV, m.conv = &src;
        rc = nn_gemm_run(&m);
    }
    free(dy);
    return rc;
}

g3d_status g3d_nn_conv_prepare(g3d_nn_conv *c)
{
    if (c->prep) return G3D_OK;
    int ho, wo;
    /* validates the configuration; the input size does not matter here (reflect needs pad < size) */
    G3D_TRY(g3d_nn_conv_out_size(c, c->kh + c->pad_h + 1, c->kw + c->pad_w + 1, &ho, &wo));
    if (c->transposed) {
        convt_prep *p;
        G3D_TRY(convt_build(c, &p));
        c->prep = p;
    } else if (nn_wino_eligible(c)) {
        c->prep = nn_wino_weights(c);
        if (!c->prep) return G3D_ERR(G3D_ERR_NOMEM, "conv: cannot allocate the transformed %d->%d kernels", c->cin, c->cout);
    }
    return G3D_OK;
}

void g3d_nn_conv_release(g3d_nn_conv *c)
{
    if (c->transposed)
        convt_prep_free(c->prep);
    else
        free(c->prep);
    c->prep = NULL;
}

/* ---- legacy entry points ----------------------------------------------------------------- */
int g3d_nn_conv_out(int size, int k, int stride, int pad) { return (size + 2 * pad - k) / stride + 1; }

g3d_status g3d_nn_conv2d(const float *x, int cin, int h, int w, const float *wt, const float *b, int cout, int k,
                         int stride, int pad, float *y)
{
    g3d_nn_conv c = g3d_nn_conv_make(cin, cout, k, stride, pad, wt, b);
    return g3d_nn_conv_forward(&c, x, h, w, y, NULL);
}

g3d_status g3d_nn_conv_transpose2d(const float *x, int cin, int h, int w, const float *wt, const float *b, int cout,
                                   int k, float *y)
{
    g3d_nn_conv c = g3d_nn_conv_make(cin, cout, k, k, 0, wt, b);
    c.transposed = 1;
    return g3d_nn_conv_forward(&c, x, h, w, y, NULL);
}

void g3d_nn_fold_bn(float *w, float *bias, int outer, int c, int inner, const float *gamma, const float *beta,
                    const float *mean, const float *var, float eps)
{
    for (int ch = 0; ch < c; ch++) {
        const float k = gamma[ch] / sqrtf(var[ch] + eps);
        for (int o = 0; o < outer; o++) {
            float *p = w + ((size_t)o * c + ch) * inner;
            for (int i = 0; i < inner; i++) p[i] *= k;
        }
        bias[ch] = (bias[ch] - mean[ch]) * k + beta[ch];
    }
}

/* ---- reference ----------------------------------------------------------------------------- */
static float wval(const g3d_nn_conv *c, size_t i)
{
    float v;
    if (c->wtype == G3D_DT_F32) return ((const float *)c->w)[i];
    g3d_dtype_to_f32(c->wtype, (const uint16_t *)c->w + i, &v, 1);
    return v;
}

g3d_status nn_ref_conv(const g3d_nn_conv *c, const float *x, int h, int w, const g3d_nn_epi *epi, float *y)
{
    int ho, wo;
    G3D_TRY(g3d_nn_conv_out_size(c, h, w, &ho, &wo));
    const int s = one(c->stride), d = one(c->dilation), G = one(c->groups);
    const int cg = c->cin / G, og = c->cout / G;
    const size_t plane = (size_t)ho * wo;
    double *acc = calloc((size_t)c->cout * plane, sizeof(double));
    if (!acc) return G3D_ERR(G3D_ERR_NOMEM, "conv reference: out of memory");
    if (c->transposed) {
        /* scatter form, straight from the definition */
        for (int ci = 0; ci < c->cin; ci++)
            for (int iy = 0; iy < h; iy++)
                for (int ix = 0; ix < w; ix++)
                    for (int co = 0; co < c->cout; co++)
                        for (int ky = 0; ky < c->kh; ky++)
                            for (int kx = 0; kx < c->kw; kx++) {
                                int oy = iy * s - c->pad_h + ky * d, ox = ix * s - c->pad_w + kx * d;
                                if (oy < 0 || oy >= ho || ox < 0 || ox >= wo) continue;
                                acc[co * plane + (size_t)oy * wo + ox] +=
                                    (double)x[((size_t)ci * h + iy) * w + ix] *
                                    wval(c, (((size_t)ci * c->cout + co) * c->kh + ky) * c->kw + kx);
                            }
    } else {
        for (int co = 0; co < c->cout; co++) {
            int g = co / og;
            for (int oy = 0; oy < ho; oy++)
                for (int ox = 0; ox < wo; ox++) {
                    double sum = 0;
                    for (int cc = 0; cc < cg; cc++)
                        for (int ky = 0; ky < c->kh; ky++)
                            for (int kx = 0; kx < c->kw; kx++) {
                                int iy = oy * s - c->pad_h + ky * d, ix = ox * s - c->pad_w + kx * d;
                                if (iy < 0 || iy >= h || ix < 0 || ix >= w) {
                                    if (c->pad_mode == G3D_PAD_ZEROS) continue;
                                    if (c->pad_mode == G3D_PAD_REFLECT) {
                                        iy = iy < 0 ? -iy : iy >= h ? 2 * h - 2 - iy : iy;
                                        ix = ix < 0 ? -ix : ix >= w ? 2 * w - 2 - ix : ix;
                                    } else {
                                        iy = iy < 0 ? 0 : iy >= h ? h - 1 : iy;
                                        ix = ix < 0 ? 0 : ix >= w ? w - 1 : ix;
                                    }
                                }
                                sum += (double)x[((size_t)(g * cg + cc) * h + iy) * w + ix] *
                                       wval(c, (((size_t)co * cg + cc) * c->kh + ky) * c->kw + kx);
                            }
                    acc[co * plane + (size_t)oy * wo + ox] = sum;
                }
        }
    }
    for (int co = 0; co < c->cout; co++)
        for (size_t i = 0; i < plane; i++) {
            float v = (float)(acc[co * plane + i] + (c->b ? c->b[co] : 0.0));
            if (epi) {
                v = nn_ref_act1(epi->act, v);
                if (epi->scale) v *= epi->scale[co];
                if (epi->res) v += epi->res[co * plane + i];
            }
            y[co * plane + i] = v;
        }
    free(acc);
    return G3D_OK;
}
