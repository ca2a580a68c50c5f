/* Activations, GEGLU, softmax and the exponentials of attention, vectorised with GCC vector
 * types and compiled for AVX-512, AVX2 and baseline x86-64 (picked at load time).
 *
 * exp(x) = 2^(x log2 e), see vexp2; erf, see vgelu. The reference loops use libm. */
#include "nn/nn_int.h"

#include <immintrin.h>
#include <math.h>
#include <omp.h>
#include <string.h>

typedef float vf __attribute__((vector_size(64)));
typedef float vfu __attribute__((vector_size(64), aligned(4), may_alias));
typedef int vi __attribute__((vector_size(64)));
typedef unsigned vu __attribute__((vector_size(64)));

/* The helpers below are always inlined into the cloned loops, so the 64-byte vector
 * arguments never cross a call and the ABI note GCC gives for the baseline clone is moot. */
#pragma GCC diagnostic ignored "-Wpsabi"

#define CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#define INLINE static inline __attribute__((always_inline))

INLINE vf vsel(vi m, vf a, vf b) { return (vf)(((vi)a & m) | ((vi)b & ~m)); }
INLINE vf vmax(vf a, vf b) { return vsel(a > b, a, b); }
INLINE vf vmin(vf a, vf b) { return vsel(a < b, a, b); }
INLINE vf splat(float x) { return (vf){0} + x; }

/* 2^t: t = n + r with n = round(t) (the 1.5 * 2^23 trick), 2^r by a degree-5 polynomial fitted
 * on [-1/2, 1/2] (relative error 2.3e-7), 2^n added to the exponent bits; 0 below 2^-126. */
INLINE vf vexp2(vf t)
{
    vi under = t < -126.0f;
    t = vmin(t, splat(127.0f));
    vf tm = t + 12582912.0f;
    vi n = (vi)tm - 0x4B400000;
    vf r = t - (tm - 12582912.0f);
    vf p = 1.3276466634e-3f * r + 9.6755418926e-3f;
    p = p * r + 5.5507134646e-2f;
    p = p * r + 2.4022120237e-1f;
    p = p * r + 6.9314694405e-1f;
    p = p * r + 1.0000001192f;
    vf y = (vf)((vu)p + ((vu)n << 23)); /* unsigned: a negative n wraps as intended */
    return vsel(under, splat(0.0f), y);
}

INLINE vf vexp(vf x) { return vexp2(x * 1.44269504088896341f); }

INLINE vf vabs(vf x) { return (vf)((vi)x & 0x7fffffff); }

/* erf(a) = a P(a^2) / Q(a^2) on |a| <= 4 (clamped outside, where erf is 1 to 6e-8), a rational
 * fit of our own with absolute error 3.8e-7 in float arithmetic: one division and ten FMAs, about
 * half the work of an exp-based erfc, which matters in the epilogue of the MLP products. */
INLINE vf vgelu(vf x)
{
    vf a = vmin(vmax(x * 0.70710678118654752f, splat(-4.0f)), splat(4.0f)), z = a * a;
    vf p = 1.9217061720e-8f * z - 1.9903138764e-6f;
    p = p * z + 1.5553692356e-4f;
    p = p * z + 4.2930739000e-3f;
    p = p * z + 5.2433554083e-2f;
    p = p * z + 2.1394531429e-1f;
    p = p * z + 1.1283786297f;
    vf q = 1.0980417719e-3f * z + 1.5551141463e-2f;
    q = q * z + 1.2079987675e-1f;
    q = q * z + 5.2293175459e-1f;
    q = q * z + 1.0f;
    vf h = 0.5f * x;
    return h + h * (a * p / q);
}

INLINE vf vtanh(vf u)
{
    vf a = vabs(u), u2 = u * u;
    vf big = 1.0f - 2.0f / (vexp(2.0f * a) + 1.0f);
    big = (vf)((vi)big | ((vi)u & (int)0x80000000)); /* sign of u */
    vf small = u * (1.0f + u2 * (-0.333333333f + u2 * (0.133333333f - u2 * 0.0539682540f)));
    return vsel(a < 0.0625f, small, big);
}

INLINE vf vsigmoid(vf x) { return 1.0f / (1.0f + vexp(-x)); }

INLINE vf vact(g3d_act act, vf x)
{
    switch (act) {
    case G3D_ACT_RELU: return vmax(x, splat(0.0f));
    case G3D_ACT_GELU: return vgelu(x);
    /* x (1 + tanh u) / 2 = x sigmoid(2u): no cancellation for negative x */
    case G3D_ACT_GELU_TANH: return x * vsigmoid(1.5957691216057308f * (x + 0.044715f * x * x * x));
    case G3D_ACT_QUICK_GELU: return x * vsigmoid(1.702f * x);
    case G3D_ACT_SILU: return x * vsigmoid(x);
    case G3D_ACT_SIGMOID: return vsigmoid(x);
    case G3D_ACT_TANH: return vtanh(x);
    default: return x;
    }
}

/* One loop per activation, so the choice is not made again for every vector. */
#define ACT_LOOP(A)                                                                                \
    do {                                                                                           \
        long i = 0;                                                                                \
        for (; i + 16 <= n; i += 16) *(vfu *)(x + i) = vact(A, *(const vfu *)(x + i));             \
        if (i < n) {                                                                               \
            float tail[16] = {0};                                                                  \
            memcpy(tail, x + i, sizeof(float) * (size_t)(n - i));                                  \
            *(vfu *)tail = vact(A, *(const vfu *)tail);                                            \
            memcpy(x + i, tail, sizeof(float) * (size_t)(n - i));                                  \
        }                                                                                          \
    } while (0)

CLONES void nn_act(g3d_act act, float *x, long n)
{
    switch (act) {
    case G3D_ACT_RELU: ACT_LOOP(G3D_ACT_RELU); break;
    case G3D_ACT_GELU: ACT_LOOP(G3D_ACT_GELU); break;
    case G3D_ACT_GELU_TANH: ACT_LOOP(G3D_ACT_GELU_TANH); break;
    case G3D_ACT_QUICK_GELU: ACT_LOOP(G3D_ACT_QUICK_GELU); break;
    case G3D_ACT_SILU: ACT_LOOP(G3D_ACT_SILU); break;
    case G3D_ACT_SIGMOID: ACT_LOOP(G3D_ACT_SIGMOID); break;
    case G3D_ACT_TANH: ACT_LOOP(G3D_ACT_TANH); break;
    default: break;
    }
}

CLONES void nn_exp_rows(float *s, long lds, int rows, const float *m, float *sum, int n)
{
    for (int i = 0; i < n; i += 16) {
        vf mv = *(const vfu *)(m + i) * 1.44269504088896341f, acc = *(const vfu *)(sum + i);
        for (int r = 0; r < rows; r++) {
            vf e = vexp2(*(const vfu *)(s + r * lds + i) * 1.44269504088896341f - mv);
            *(vfu *)(s + r * lds + i) = e;
            acc += e;
        }
        *(vfu *)(sum + i) = acc;
    }
}

CLONES static void online_softmax(float *s, long lds, int rows, int n, const float *bmax, float *m, float *l,
                                  float *corr)
{
    for (int i0 = 0; i0 < n; i0 += 64) {
        /* column maxima: up to 4 vectors side by side and two rows at a time, so the max
         * instructions do not wait on one another */
        const int nv = (n - i0) / 16 < 4 ? (n - i0) / 16 : 4;
        vf mx[4], mx2[4];
        for (int v = 0; v < nv; v++) mx[v] = mx2[v] = *(const vfu *)(m + i0 + 16 * v);
        if (bmax)
            for (int v = 0; v < nv; v++) mx2[v] = vmax(mx2[v], *(const vfu *)(bmax + i0 + 16 * v));
        int r = bmax ? rows : 0;
        for (; r + 2 <= rows; r += 2)
            for (int v = 0; v < nv; v++) {
                mx[v] = vmax(mx[v], *(const vfu *)(s + r * lds + i0 + 16 * v));
                mx2[v] = vmax(mx2[v], *(const vfu *)(s + (r + 1) * lds + i0 + 16 * v));
            }
        for (; r < rows; r++)
            for (int v = 0; v < nv; v++) mx[v] = vmax(mx[v], *(const vfu *)(s + r * lds + i0 + 16 * v));
        for (int v = 0; v < nv; v++) {
            const int i = i0 + 16 * v;
            vf mnew = vmax(mx[v], mx2[v]);
            /* a column that has seen only -inf keeps m = -inf and subtracts 0 instead */
            vf meff = vsel(mnew == -INFINITY, splat(0.0f), mnew) * 1.44269504088896341f;
            vf c = vexp2(*(const vfu *)(m + i) * 1.44269504088896341f - meff), acc = *(const vfu *)(l + i) * c;
            for (int q = 0; q < rows; q++) {
                vf e = vexp2(*(const vfu *)(s + q * lds + i) * 1.44269504088896341f - meff);
                *(vfu *)(s + q * lds + i) = e;
                acc += e;
            }
            *(vfu *)(m + i) = mnew;
            *(vfu *)(l + i) = acc;
            *(vfu *)(corr + i) = c;
        }
    }
}

/* The same with AVX-512's own instructions, which the generic vectors above cannot name: the
 * maxima in one instruction instead of a compare and a blend, and exp's 2^n by vscalefps, which
 * also flushes to 0 below the float range (the clamp only maps -inf), about 11 instructions per
 * score instead of 20: the softmax had been a tenth of short-key attention. Same polynomial. */
__attribute__((target("avx512f"))) static inline __m512 exp2_512(__m512 t)
{
    t = _mm512_max_ps(t, _mm512_set1_ps(-160.0f));
    const __m512 n = _mm512_roundscale_ps(t, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC), r = _mm512_sub_ps(t, n);
    __m512 p = _mm512_fmadd_ps(_mm512_set1_ps(1.3276466634e-3f), r, _mm512_set1_ps(9.6755418926e-3f));
    p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(5.5507134646e-2f));
    p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(2.4022120237e-1f));
    p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(6.9314694405e-1f));
    p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(1.0000001192f));
    return _mm512_scalef_ps(p, n);
}

__attribute__((target("avx512f"))) static void online_softmax512(float *s, long lds, int rows, int n,
                                                                const float *bmax, float *m, float *l, float *corr)
{
    const __m512 log2e = _mm512_set1_ps(1.44269504088896341f);
    for (int i0 = 0; i0 < n; i0 += 64) {
        const int nv = (n - i0) / 16 < 4 ? (n - i0) / 16 : 4;
        __m512 mx[4], mx2[4];
        for (int v = 0; v < nv; v++) mx[v] = mx2[v] = _mm512_loadu_ps(m + i0 + 16 * v);
        if (bmax)
            for (int v = 0; v < nv; v++) mx2[v] = _mm512_max_ps(mx2[v], _mm512_loadu_ps(bmax + i0 + 16 * v));
        int r = bmax ? rows : 0;
        for (; r + 2 <= rows; r += 2)
            for (int v = 0; v < nv; v++) {
                mx[v] = _mm512_max_ps(mx[v], _mm512_loadu_ps(s + r * lds + i0 + 16 * v));
                mx2[v] = _mm512_max_ps(mx2[v], _mm512_loadu_ps(s + (r + 1) * lds + i0 + 16 * v));
            }
        for (; r < rows; r++)
            for (int v = 0; v < nv; v++) mx[v] = _mm512_max_ps(mx[v], _mm512_loadu_ps(s + r * lds + i0 + 16 * v));
        for (int v = 0; v < nv; v++) {
            const int i = i0 + 16 * v;
            const __m512 mnew = _mm512_max_ps(mx[v], mx2[v]);
            /* a column that has seen only -inf keeps m = -inf and subtracts 0 instead */
            const __m512 meff = _mm512_mul_ps(
                _mm512_mask_blend_ps(_mm512_cmp_ps_mask(mnew, _mm512_set1_ps(-INFINITY), _CMP_EQ_OQ), mnew,
                                     _mm512_setzero_ps()),
                log2e);
            const __m512 c = exp2_512(_mm512_fmsub_ps(_mm512_loadu_ps(m + i), log2e, meff));
            __m512 acc = _mm512_mul_ps(_mm512_loadu_ps(l + i), c);
            float *sq = s + i;
            for (int q = 0; q < rows; q++, sq += lds) {
                const __m512 e = exp2_512(_mm512_fmsub_ps(_mm512_loadu_ps(sq), log2e, meff));
                _mm512_storeu_ps(sq, e);
                acc = _mm512_add_ps(acc, e);
            }
            _mm512_storeu_ps(m + i, mnew);
            _mm512_storeu_ps(l + i, acc);
            _mm512_storeu_ps(corr + i, c);
        }
    }
}

void nn_online_softmax(float *s, long lds, int rows, int n, const float *bmax, float *m, float *l, float *corr)
{
    if (nn_isa() == NN_ISA_AVX512)
        online_softmax512(s, lds, rows, n, bmax, m, l, corr);
    else
        online_softmax(s, lds, rows, n, bmax, m, l, corr);
}

/* Transposes of attention's query and output tiles: 16 x 16 blocks through four stages of
 * two-vector shuffles (each swaps the off-diagonal sub-blocks of size 8, 4, 2, 1), so the
 * scattered scalar stores of a plain loop (which missed the cache on every output row of
 * short-key attention) become whole-vector ones. */
INLINE void transpose16(vf t[16])
{
    static const vi lo8 = {0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23},
                    hi8 = {8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31},
                    lo4 = {0, 1, 2, 3, 16, 17, 18, 19, 8, 9, 10, 11, 24, 25, 26, 27},
                    hi4 = {4, 5, 6, 7, 20, 21, 22, 23, 12, 13, 14, 15, 28, 29, 30, 31},
                    lo2 = {0, 1, 16, 17, 4, 5, 20, 21, 8, 9, 24, 25, 12, 13, 28, 29},
                    hi2 = {2, 3, 18, 19, 6, 7, 22, 23, 10, 11, 26, 27, 14, 15, 30, 31},
                    lo1 = {0, 16, 2, 18, 4, 20, 6, 22, 8, 24, 10, 26, 12, 28, 14, 30},
                    hi1 = {1, 17, 3, 19, 5, 21, 7, 23, 9, 25, 11, 27, 13, 29, 15, 31};
#define STAGE(B, LO, HI)                                                                           \
    for (int r = 0; r < 16; r++)                                                                   \
        if (!(r & B)) {                                                                            \
            vf x = t[r], y = t[r + B];                                                             \
            t[r] = __builtin_shuffle(x, y, LO), t[r + B] = __builtin_shuffle(x, y, HI);            \
        }
    STAGE(8, lo8, hi8) STAGE(4, lo4, hi4) STAGE(2, lo2, hi2) STAGE(1, lo1, hi1)
#undef STAGE
}

/* In-lane unpacks, then 128-bit lane shuffles: the same 64 shuffles as transpose16 but cheaper
 * ones, each stage in place so the 16 rows and two temporaries stay in registers. Column c of the
 * block ends in t[c ^ ((c ^ (c >> 1)) & 1) * 3 ...], i.e. columns 4m+1 and 4m+2 swap places:
 * see TCOL. */
#define TCOL(c) ((c) & 3) == 1 ? (c) + 1 : ((c) & 3) == 2 ? (c) - 1 : (c)
__attribute__((target("avx512f"))) static inline void transpose16_512(__m512 t[16])
{
    for (int i = 0; i < 16; i += 2) {
        const __m512 x = t[i], y = t[i + 1];
        t[i] = _mm512_unpacklo_ps(x, y), t[i + 1] = _mm512_unpackhi_ps(x, y);
    }
    for (int i = 0; i < 16; i += 4)
        for (int j = 0; j < 2; j++) {
            const __m512d x = (__m512d)t[i + j], y = (__m512d)t[i + j + 2];
            t[i + j] = (__m512)_mm512_unpacklo_pd(x, y), t[i + j + 2] = (__m512)_mm512_unpackhi_pd(x, y);
        }
    for (int i = 0; i < 16; i += 8)
        for (int k = 0; k < 4; k++) {
            const __m512 x = t[i + k], y = t[i + k + 4];
            t[i + k] = _mm512_shuffle_f32x4(x, y, 0x88), t[i + k + 4] = _mm512_shuffle_f32x4(x, y, 0xdd);
        }
    for (int k = 0; k < 8; k++) {
        const __m512 x = t[k], y = t[k + 8];
        t[k] = _mm512_shuffle_f32x4(x, y, 0x88), t[k + 8] = _mm512_shuffle_f32x4(x, y, 0xdd);
    }
}

/* Whole 16 x 16 blocks take plain loads and stores; the partial ones (head sizes 40, 80: a
 * third of SD's blocks; short query blocks) masked ones. Rows are addressed by stepping one
 * pointer (indexing by r * lds made GCC keep 16 row addresses and spill them). */
__attribute__((target("avx512f"))) static void transpose_tile512(const float *src, long lds, int nr, int nc,
                                                                float *dst, long ldd, int w, float scale,
                                                                const float *rscale)
{
    for (int c0 = 0; c0 < nc; c0 += 16) {
        const int cn = nc - c0 < 16 ? nc - c0 : 16;
        const __mmask16 cm = (__mmask16)((1u << cn) - 1);
        for (int r0 = 0; r0 < w; r0 += 16) {
            const int rn = nr - r0 < 16 ? (nr - r0 > 0 ? nr - r0 : 0) : 16, wn = w - r0 < 16 ? w - r0 : 16;
            const __mmask16 wm = (__mmask16)((1u << wn) - 1);
            const float *p = src + (long)r0 * lds + c0;
            __m512 t[16];
            for (int r = 0; r < 16; r++, p += lds) t[r] = r < rn ? _mm512_maskz_loadu_ps(cm, p) : _mm512_setzero_ps();
            transpose16_512(t);
            float *q = dst + (long)c0 * ldd + r0;
            for (int c = 0; c < cn; c++, q += ldd)
                _mm512_mask_storeu_ps(q, wm, _mm512_mul_ps(t[TCOL(c)], _mm512_set1_ps(rscale ? rscale[c0 + c] : scale)));
        }
    }
}
#undef TCOL

static void transpose_tile(const float *src, long lds, int nr, int nc, float *dst, long ldd, int w, float scale,
                           const float *rscale)
{
    for (int c0 = 0; c0 < nc; c0 += 16) {
        const int cn = nc - c0 < 16 ? nc - c0 : 16;
        for (int r0 = 0; r0 < w; r0 += 16) {
            const int rn = nr - r0 < 16 ? (nr - r0 > 0 ? nr - r0 : 0) : 16, wn = w - r0 < 16 ? w - r0 : 16;
            const float *p = src + (long)r0 * lds + c0;
            float *q = dst + (long)c0 * ldd + r0, tmp[16][16] = {{0}};
            vf t[16];
            for (int r = 0; r < rn; r++)
                for (int c = 0; c < cn; c++) tmp[r][c] = p[r * lds + c];
            for (int r = 0; r < 16; r++) t[r] = *(const vfu *)tmp[r];
            transpose16(t);
            for (int c = 0; c < cn; c++) *(vfu *)tmp[c] = rscale ? t[c] * rscale[c0 + c] : t[c] * scale;
            for (int c = 0; c < cn; c++)
                for (int r = 0; r < wn; r++) q[c * ldd + r] = tmp[c][r];
        }
    }
}

void nn_transpose_tile(const float *src, long lds, int nr, int nc, float *dst, long ldd, int w, float scale,
                       const float *rscale)
{
    if (nn_isa() == NN_ISA_AVX512)
        transpose_tile512(src, lds, nr, nc, dst, ldd, w, scale, rscale);
    else
        transpose_tile(src, lds, nr, nc, dst, ldd, w, scale, rscale);
}

void nn_ref_transpose_tile(const float *src, long lds, int nr, int nc, float *dst, long ldd, int w, float scale,
                           const float *rscale)
{
    for (int c = 0; c < nc; c++)
        for (int r = 0; r < w; r++) {
            const float x = r < nr ? src[(long)r * lds + c] : 0.0f;
            dst[(long)c * ldd + r] = rscale ? x * rscale[c] : x * scale;
        }
}

float nn_exp_sum(float *x, long n, float m)
{
    float tail[16], sum[16] = {0}, mv[16];
    for (int i = 0; i < 16; i++) mv[i] = m;
    long full = n / 16 * 16;
    if (full) {
        /* one row of `full` values as full/16 rows of 16: per-lane sums in row order */
        nn_exp_rows(x, 16, (int)(full / 16), mv, sum, 16);
    }
    if (n > full) {
        for (int i = 0; i < 16; i++) tail[i] = i < n - full ? x[full + i] : -INFINITY;
        float s2[16] = {0};
        nn_exp_rows(tail, 16, 1, mv, s2, 16);
        memcpy(x + full, tail, sizeof(float) * (size_t)(n - full));
        for (int i = 0; i < 16; i++) sum[i] += s2[i];
    }
    float s = 0;
    for (int i = 0; i < 16; i++) s += sum[i];
    return s;
}

float nn_ref_act1(g3d_act act, float x)
{
    switch (act) {
    case G3D_ACT_RELU: return x > 0 ? x : 0.0f;
    case G3D_ACT_GELU: return (float)(0.5 * x * (1.0 + erf(x * M_SQRT1_2)));
    case G3D_ACT_GELU_TANH: /* x (1 + tanh u) / 2 written as x sigmoid(2u), exact in double */
        return (float)(x / (1.0 + exp(-1.5957691216057308 * (x + 0.044715 * (double)x * x * x))));
    case G3D_ACT_QUICK_GELU: return (float)(x / (1.0 + exp(-1.702 * x)));
    case G3D_ACT_SILU: return (float)(x / (1.0 + exp(-(double)x)));
    case G3D_ACT_SIGMOID: return (float)(1.0 / (1.0 + exp(-(double)x)));
    case G3D_ACT_TANH: return tanhf(x);
    default: return x;
    }
}

void g3d_nn_activate(g3d_act act, float *x, size_t n)
{
    const long chunk = 1 << 14;
    long nc = (long)((n + chunk - 1) / chunk);
#pragma omp parallel for schedule(static) if (nc > 1)
    for (long c = 0; c < nc; c++) {
        long lo = c * chunk, len = (long)n - lo < chunk ? (long)n - lo : chunk;
        nn_act(act, x + lo, len);
    }
}

void g3d_nn_gelu(float *x, size_t n) { g3d_nn_activate(G3D_ACT_GELU, x, n); }
void g3d_nn_relu(float *x, size_t n) { g3d_nn_activate(G3D_ACT_RELU, x, n); }

void g3d_nn_add(float *y, const float *x, size_t n)
{
#pragma omp parallel for schedule(static) if (n > (1 << 16))
    for (size_t i = 0; i < n; i++) y[i] += x[i];
}

void g3d_nn_geglu(const float *x, int n, int f, float *y)
{
#pragma omp parallel for schedule(static)
    for (int i = 0; i < n; i++) {
        const float *xv = x + (size_t)i * 2 * f;
        float *yr = y + (size_t)i * f;
        memcpy(yr, xv + f, sizeof(float) * (size_t)f);
        nn_act(G3D_ACT_GELU, yr, f);
        for (int j = 0; j < f; j++) yr[j] *= xv[j];
    }
}

void g3d_nn_softmax(float *x, int rows, int cols)
{
#pragma omp parallel for schedule(static)
    for (int r = 0; r < rows; r++) {
        float *row = x + (size_t)r * cols, m = -INFINITY;
        for (int j = 0; j < cols; j++) m = row[j] > m ? row[j] : m;
        float inv = 1.0f / nn_exp_sum(row, cols, m);
        for (int j = 0; j < cols; j++) row[j] *= inv;
    }
}

void nn_ref_softmax(float *x, int rows, int cols)
{
    for (int r = 0; r < rows; r++) {
        float *row = x + (size_t)r * cols, m = -INFINITY;
        for (int j = 0; j < cols; j++) m = row[j] > m ? row[j] : m;
        double s = 0;
        for (int j = 0; j < cols; j++) s += exp((double)row[j] - m);
        for (int j = 0; j < cols; j++) row[j] = (float)(exp((double)row[j] - m) / s);
    }
}
