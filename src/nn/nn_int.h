/* Internals shared by the files of src/nn: the multiply kernel, the tiled product driver that
 * every linear, convolution and matmul runs through, vectorised element-wise helpers, and the
 * plain reference loop of each public operator (kept beside the tuned code, used by tests). */
#ifndef G3D_NN_INT_H
#define G3D_NN_INT_H

#include "gen3d/nn.h"

#include <stdint.h>

/* ---- the kernel (kernel.c) ------------------------------------------------------------ */
#define NN_MR 6  /* rows of C per kernel call */
#define NN_NR 64 /* columns of C per packed panel: 4 AVX-512 vectors */

enum { NN_ISA_BASE, NN_ISA_AVX2, NN_ISA_AVX512 };
int nn_isa(void);
/* Forces a lower instruction set (never one the CPU lacks); returns the previous one. For tests. */
int nn_isa_force(int isa);

/* C[6 x 16nv] = (acc ? C : 0) + A[6 x K] B[K x 16nv]; A(i,k) = a[i*lda + k*ka], B(k,j) = b[k*ldb + j].
 * All six rows of A and 16nv columns of B must be readable; 1 <= nv <= 4. */
void nn_kernel(int K, const float *a, long lda, long ka, const float *b, long ldb, float *c, long ldc, int nv, int acc);

/* nn_kernel on ng groups of six rows: group g reads a + g*ga and writes c + g*gc (the same
 * multiply-adds in the same order as ng calls, with the setup paid once). */
void nn_kernel_groups(int K, const float *a, long lda, long ka, long ga, const float *b, long ldb, float *c, long ldc,
                      long gc, int nv, int ng, int acc);

/* Attention's scores: nn_kernel_groups with acc = 0, then, before the store, row r of the
 * 6 ng rows (group r / 6, row r % 6) gets add0[r][j] + add1[r][j] added for j < nvalid (with
 * add0; only those columns of the addends are read), and colmax[j] (16 nv values) becomes the
 * maximum of itself and column j of the rows (with colmax). The npf 64-byte lines from pf0 (to
 * be read) and from pf1 (to be written) are fetched into L2 along the way, one of each per step. */
void nn_kernel_scores(int K, const float *a, long lda, long ka, long ga, const float *b, long ldb, float *c, long ldc,
                      long gc, int nv, int ng, const float *const *add0, const float *const *add1, int nvalid,
                      float *colmax, const char *pf0, const char *pf1, int npf);

/* ---- the product driver (gemm.c) ------------------------------------------------------- */
/* Where the columns of B come from. */
enum {
    NN_B_ROWS,   /* B(k,j) = b[k*ldb + j], float */
    NN_B_COLS,   /* B(k,j) = b[j*ldb + k], float (a Linear weight [out, in] read as W^T) */
    NN_B_PANELS, /* pre-packed: panel j/64 holds K rows of 64 columns, float or 16-bit */
    NN_B_CONV    /* implicit im2col of a feature map, see nn_convsrc */
};

/* A feature map read as the B operand of a convolution: column j is output pixel
 * (qy, qx) = (j / qw, j % qw); row k is channel k / ntaps and tap k % ntaps, whose input
 * pixel is (qy*stride + dy[t], qx*stride + dx[t]); outside the map, pad decides. */
typedef struct nn_convsrc {
    const float *x;
    int h, w, qh, qw, stride, ntaps;
    const int *dy, *dx;
    g3d_nn_padmode pad;
} nn_convsrc;

typedef struct nn_gemm {
    int M, N, K;
    /* A: float with strides, or 16-bit rows (widened per tile) */
    const float *a;
    long lda, ka;
    const uint16_t *a16;
    g3d_dtype a16t;
    /* B */
    int bkind;
    const void *b;
    long ldb;
    g3d_dtype bt; /* element type of NN_B_PANELS */
    const nn_convsrc *conv;
    /* output: element (i, j) goes to y[row(i) + (j/qw)*oys + (j%qw)*oxs + ooff] (qw == 0: j),
     * row(i) = rowoff ? rowoff[i] : i*ldy; epi->res is read at the same place */
    float *y;
    long ldy;
    const long *rowoff;
    int qw;
    long oys, oxs, ooff;
    float alpha;          /* multiplies the product (1 unless set) */
    const float *bias;    /* per output channel */
    int chan_rows;        /* 1: channels are the rows of C (convolution), 0: the columns */
    int chan_div;         /* with chan_rows: row i is channel i / chan_div (0: channel i) */
    /* > 1 (with rowoff, qw, chan_rows): rows i + t, t < ilv, i a multiple of ilv, write the
     * pixels just after row i's, rowoff[i + t] = rowoff[i] + t and oxs = ilv, so an output row
     * is their values interleaved (a transposed convolution with kernel = stride); they share
     * a channel */
    int ilv;
    const g3d_nn_epi *epi;
} nn_gemm;

/* Runs the product over fixed tiles of C shared out dynamically among the OpenMP threads. */
g3d_status nn_gemm_run(const nn_gemm *g);

/* Widens n 16-bit floats of type t (G3D_DT_F16 or G3D_DT_BF16) to float32. */
void nn_widen(g3d_dtype t, const uint16_t *src, float *dst, long n);

/* ---- Winograd F(2x2, 3x3) and F(4x4, 3x3) (winograd.c) -------------------------------- */
/* 1 if c is a 3x3, stride-1, undilated, ungrouped Conv2d wide enough to gain from it. */
int nn_wino_eligible(const g3d_nn_conv *c);
/* Outputs per tile side for an eligible c: 4 (F(4x4)) or 2 (F(2x2)), from its channels. */
int nn_wino_tile(const g3d_nn_conv *c);
/* The transformed kernels U [(m+2)^2, cout rounded up to 6, cin] for m = nn_wino_tile(c)
 * (zero rows past cout); NULL if out of memory. */
float *nn_wino_weights(const g3d_nn_conv *c);
g3d_status nn_wino_forward(const g3d_nn_conv *c, const float *U, const float *x, int h, int w, int ho, int wo, float *y,
                           const g3d_nn_epi *epi);

/* Index of a padded coordinate inside [0, n) for reflect or replicate padding (reflect needs
 * pad < n, checked by callers). */
static inline int nn_pad_index(g3d_nn_padmode m, int i, int n)
{
    if (m == G3D_PAD_REFLECT) return i < 0 ? -i : i >= n ? 2 * (n - 1) - i : i;
    return i < 0 ? 0 : i >= n ? n - 1 : i;
}

/* ---- element-wise helpers (act.c) ----------------------------------------------------- */
/* Tuned in-place activation over n contiguous values. */
void nn_act(g3d_act act, float *x, long n);
/* x[i] = exp(x[i] - m) for i < n and returns their sum (in a fixed order); x below the
 * float range flushes to 0. */
float nn_exp_sum(float *x, long n, float m);
/* s[r*lds + i] = exp(s[r*lds + i] - m[i]), sum[i] += that, for r < rows, i < n (n a multiple
 * of 16; lanes summed row by row). */
void nn_exp_rows(float *s, long lds, int rows, const float *m, float *sum, int n);
/* One block of keys of an online softmax over the columns of s [rows x n] (n a multiple of 16):
 * m (running maxima) and l (running sums) are updated, s becomes exp(s - m_new), and
 * corr[i] = exp(m_old - m_new) is the factor for what was accumulated before. bmax, if not
 * NULL, holds the block's column maxima already (as nn_kernel_scores takes them). */
void nn_online_softmax(float *s, long lds, int rows, int n, const float *bmax, float *m, float *l, float *corr);

/* dst[c*ldd + r] = src[r*lds + c] * (rscale ? rscale[c] : scale) for c < nc, r < w, where
 * rows r >= nr of src read as 0 (w >= nr; only rows < nr and columns < nc of src are read). */
void nn_transpose_tile(const float *src, long lds, int nr, int nc, float *dst, long ldd, int w, float scale,
                       const float *rscale);

/* ---- reference loops (each beside its tuned operator) ---------------------------------- */
float nn_ref_act1(g3d_act act, float x);
void nn_ref_matmul(int ta, int tb, int M, int N, int K, float alpha, const float *A, int lda, const float *B, int ldb,
                   float beta, float *C, int ldc);
void nn_ref_linear(const float *x, int n, int in, const float *w, const float *b, int out, const g3d_nn_epi *epi,
                   float *y);
g3d_status nn_ref_conv(const g3d_nn_conv *c, const float *x, int h, int w, const g3d_nn_epi *epi, float *y);
void nn_ref_attend(const g3d_nn_attn *a);
void nn_ref_transpose_tile(const float *src, long lds, int nr, int nc, float *dst, long ldd, int w, float scale,
                           const float *rscale);
void nn_ref_layernorm(const float *x, int n, int c, const float *g, const float *b, float eps, float *y);
void nn_ref_groupnorm(const float *x, int c, int hw, int groups, const float *g, const float *b, float eps, g3d_act act,
                      float *y);
void nn_ref_layernorm2d(const float *x, int c, int hw, const float *g, const float *b, float eps, float *y);
void nn_ref_softmax(float *x, int rows, int cols);
void nn_ref_resize_bilinear(const float *x, int c, int h, int w, float *y, int oh, int ow, int align_corners);
g3d_status nn_ref_rfft2(const float *x, int c, int h, int w, float *y);
g3d_status nn_ref_irfft2(const float *y, int c, int h, int w, float *x);

#endif /* G3D_NN_INT_H */
