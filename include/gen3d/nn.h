/* gen3d/nn.h - the layer library every model runs on: CPU operators on flat float32 buffers.
 *
 * LAYOUTS (PyTorch's, so checkpoint tensors are used as stored; batch 1 everywhere)
 *   token matrices   [N, C] row-major, one row per token (row stride may be given as ld*)
 *   feature maps     [C, H, W], channels first; "hw" below is H*W
 *   Linear weights   [out, in];  Conv2d weights [C_out, C_in/groups, kH, kW];
 *   ConvTranspose2d weights [C_in, C_out/groups, kH, kW]
 * Weights may stay in the checkpoint's 16-bit type (F16 or BF16, even unaligned inside a
 * memory-mapped file): they are widened to float32 tile by tile, so the result equals the
 * float32 computation on the widened values.
 *
 * OWNERSHIP
 *   The caller owns every buffer. An output never aliases an input unless the function says
 *   so. Objects with an _init/_prepare function own what it allocates until the matching
 *   _free/_release. Functions that allocate scratch return a g3d_status (G3D_ERR_NOMEM with a
 *   message); void functions never fail.
 *
 * THREADS AND DETERMINISM
 *   Operators split their work over the OpenMP team (omp_set_num_threads) into tiles whose
 *   size depends only on the problem's shape, and each output element is summed in one fixed
 *   order: results are bit-identical for any thread count. Called from inside a parallel
 *   region, an operator runs on the calling thread alone.
 *
 * SPEED
 *   Products run on the library's own register-blocked kernel (AVX-512, AVX2 or plain x86-64,
 *   picked at run time; G3D_NN_ISA=avx2|base forces a lower one). Convolutions read the
 *   input map directly (no im2col copy of the image), attention never forms the score matrix,
 *   and bias, activation, LayerScale and the residual add are applied while a tile of the
 *   output is still in cache (g3d_nn_epi). docs/nn.md has the measured figures.
 */
#ifndef G3D_NN_H
#define G3D_NN_H

#include "gen3d/base.h"
#include "gen3d/ckpt.h" /* g3d_dtype */

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Name of the instruction set the kernels use ("AVX-512", "AVX2", "generic x86-64"). */
const char *g3d_nn_isa_name(void);

/* ======================================================================================
 * Activations and element-wise operations
 * ==================================================================================== */
typedef enum g3d_act {
    G3D_ACT_NONE,
    G3D_ACT_RELU,       /* max(x, 0) */
    G3D_ACT_GELU,       /* exact: x/2 (1 + erf(x / sqrt 2)) (PyTorch's default) */
    G3D_ACT_GELU_TANH,  /* x/2 (1 + tanh(sqrt(2/pi) (x + 0.044715 x^3))) */
    G3D_ACT_QUICK_GELU, /* x sigmoid(1.702 x) (OpenAI CLIP) */
    G3D_ACT_SILU,       /* x sigmoid(x) */
    G3D_ACT_SIGMOID,
    G3D_ACT_TANH
} g3d_act;

/* In place: x[i] = act(x[i]) for n values. The vectorised formulas agree with libm to 1e-6
 * relative (exp-based ones; up to 1e-5 in tails where |x| > 10) and 4e-7 absolute (GELU). */
void g3d_nn_activate(g3d_act act, float *x, size_t n);
/* In place: exact GELU (= g3d_nn_activate(G3D_ACT_GELU, ...)). */
void g3d_nn_gelu(float *x, size_t n);
/* In place: max(x, 0). */
void g3d_nn_relu(float *x, size_t n);
/* y[i] += x[i]. */
void g3d_nn_add(float *y, const float *x, size_t n);
/* GEGLU as diffusers / LDM split it: x [n, 2f] = [value | gate] along the last dim,
 * y [n, f] = value * GELU(gate) (exact GELU). y must not overlap x. */
void g3d_nn_geglu(const float *x, int n, int f, float *y);
/* In place softmax over each of `rows` rows of `cols` values. */
void g3d_nn_softmax(float *x, int rows, int cols);

/* What happens to a product's output tile before it is stored (NULL = nothing):
 *   y = res + scale * act(product + bias)
 * scale and bias are per output channel (Linear: per column; convolution: per map). res has
 * y's shape and row stride and may be y itself (in-place residual). */
typedef struct g3d_nn_epi {
    g3d_act act;
    const float *scale; /* LayerScale gamma, or NULL */
    const float *res;   /* residual, or NULL */
} g3d_nn_epi;

/* ======================================================================================
 * Products
 * ==================================================================================== */
/* Row-major C[M,N] = alpha op(A) op(B) + beta C with op(X) = X or X^T (ta/tb non-zero),
 * like cblas_sgemm; beta must be 0 or 1. */
g3d_status g3d_nn_matmul(int ta, int tb, int M, int N, int K, float alpha, const float *A, int lda, const float *B,
                         int ldb, float beta, float *C, int ldc);

/* y[n, out] = x[n, in] w[out, in]^T + b[out] (b may be NULL). Packs w on every call: a model
 * should hold a g3d_nn_lin instead. Falls back to the reference loop if scratch cannot be
 * allocated. */
void g3d_nn_linear(const float *x, int n, int in, const float *w, const float *b, int out, float *y);

/* A Linear layer with its weight packed once, at load time, in the kernel's panel layout. */
typedef struct g3d_nn_lin {
    int in, out;
    g3d_dtype store; /* G3D_DT_F32, G3D_DT_F16 or G3D_DT_BF16 */
    void *panels;    /* owned */
    float *bias;     /* owned copy, or NULL */
} g3d_nn_lin;

/* Packs w [out, in] (of type wtype: F32, F16 or BF16; any alignment, e.g. straight from
 * g3d_tensor_info.data) and copies b [out] (NULL: no bias). store picks the packed type:
 * F32 (fastest), or F16/BF16 (half the memory; F32 weights are rounded to nearest even).
 * Free with g3d_nn_lin_free. */
g3d_status g3d_nn_lin_init(g3d_nn_lin *L, const void *w, g3d_dtype wtype, const float *b, int out, int in,
                           g3d_dtype store);
void g3d_nn_lin_free(g3d_nn_lin *L);
/* y[i, :] = epi(x[i, :] W^T + b) for n rows; row strides ldx, ldy (0 = in, out). y must not
 * overlap x; y may equal epi->res. */
g3d_status g3d_nn_lin_forward(const g3d_nn_lin *L, const float *x, int n, int ldx, float *y, int ldy,
                              const g3d_nn_epi *epi);

/* ======================================================================================
 * Convolutions
 * ==================================================================================== */
typedef enum g3d_nn_padmode {
    G3D_PAD_ZEROS,
    G3D_PAD_REFLECT,   /* mirror without repeating the edge (PyTorch 'reflect'; pad < size) */
    G3D_PAD_REPLICATE, /* repeat the edge pixel */
    G3D_PAD_SYMMETRIC  /* mirror repeating the edge (numpy 'symmetric'); g3d_nn_pad2d only */
} g3d_nn_padmode;

/* One Conv2d or ConvTranspose2d layer. Zero-initialise, then set fields (or use
 * g3d_nn_conv_make); 0 in stride, dilation or groups means 1. */
typedef struct g3d_nn_conv {
    int cin, cout, kh, kw;
    int stride, pad_h, pad_w, dilation, groups;
    g3d_nn_padmode pad_mode; /* zeros, reflect or replicate (Conv2d only) */
    int transposed;          /* 1: ConvTranspose2d */
    int output_padding;      /* ConvTranspose2d only */
    const void *w;           /* weights in the layout of the header comment */
    g3d_dtype wtype;         /* G3D_DT_F32 (0), G3D_DT_F16 or G3D_DT_BF16 */
    const float *b;          /* [cout] or NULL */
    int wino_small;          /* 1: g3d_nn_conv_prepare keeps to F(2x2, 3x3) (a quarter of the memory) */
    void *prep;              /* owned by g3d_nn_conv_prepare; NULL otherwise */
} g3d_nn_conv;

/* A square float32 Conv2d with symmetric zero padding. */
g3d_nn_conv g3d_nn_conv_make(int cin, int cout, int k, int stride, int pad, const float *w, const float *b);

/* Output size for an h x w input; G3D_ERR_ARG (with a message) if it is empty or the
 * configuration is invalid (channels not divisible by groups, reflect pad >= size, ...). */
g3d_status g3d_nn_conv_out_size(const g3d_nn_conv *c, int h, int w, int *ho, int *wo);

/* y [cout, ho, wo] = epi(conv(x [cin, h, w]) + b). y must not overlap x (it may equal
 * epi->res). Errors: G3D_ERR_ARG for bad sizes, G3D_ERR_NOMEM for scratch. */
g3d_status g3d_nn_conv_forward(const g3d_nn_conv *c, const float *x, int h, int w, float *y, const g3d_nn_epi *epi);

/* Optional, once at load time, after the weights are final (BatchNorm folded):
 *  - a 3x3, stride-1, undilated, ungrouped Conv2d with at least 16 input and output channels
 *    switches to Winograd: F(2x2, 3x3), about 1.5x faster, within a few float roundings of the
 *    direct sum, transformed kernels (float32) 16/9 the size of float32 weights; with at least
 *    64 channels on both sides F(4x4, 3x3), about 2x faster (slower on maps under ~32x32),
 *    about 20x the rounding error of F(2x2), transformed kernels 4x the float32 weights
 *    (unless wino_small is set before preparing);
 *  - a ConvTranspose2d keeps its per-phase kernels (otherwise rebuilt on every call);
 *  - anything else: nothing to do (G3D_OK).
 * Undo with g3d_nn_conv_release before freeing the weights or changing the layer. */
g3d_status g3d_nn_conv_prepare(g3d_nn_conv *c);
void g3d_nn_conv_release(g3d_nn_conv *c);

/* Legacy entry points (same results as the struct forms above). */
/* Output size along one axis: (size + 2*pad - k) / stride + 1. */
int g3d_nn_conv_out(int size, int k, int stride, int pad);
/* Square Conv2d, zero padding: x [cin, h, w], w [cout, cin, k, k], b [cout] or NULL. */
g3d_status g3d_nn_conv2d(const float *x, int cin, int h, int w, const float *wt, const float *b, int cout, int k,
                         int stride, int pad, float *y);
/* ConvTranspose2d with stride = kernel = k, no padding: x [cin, h, w], w [cin, cout, k, k]
 * -> y [cout, h*k, w*k]. */
g3d_status g3d_nn_conv_transpose2d(const float *x, int cin, int h, int w, const float *wt, const float *b, int cout,
                                   int k, float *y);

/* Folds eval-mode BatchNorm (gamma, beta, running mean, var, eps) into the layer before it:
 * w is viewed as [outer, c, inner] with c the BatchNorm channels (Conv2d: outer 1, inner
 * cin/groups*kh*kw; ConvTranspose2d: outer cin, inner kh*kw; Linear: outer 1, inner in).
 * bias [c] must exist (zeros if the layer had none) and receives the folded bias. */
void g3d_nn_fold_bn(float *w, float *bias, int outer, int c, int inner, const float *gamma, const float *beta,
                    const float *mean, const float *var, float eps);

/* ======================================================================================
 * Normalisation
 * ==================================================================================== */
/* Row-wise LayerNorm of x [n, c] into y (may equal x): (x - mean) / sqrt(var + eps) * g + b. */
void g3d_nn_layernorm(const float *x, int n, int c, const float *g, const float *b, float eps, float *y);
/* GroupNorm of x [c, hw] with `groups` groups (c divisible by it), affine g, b [c], then act
 * (G3D_ACT_SILU for the ResBlocks of SD, or NONE). y may equal x. */
void g3d_nn_groupnorm(const float *x, int c, int hw, int groups, const float *g, const float *b, float eps, g3d_act act,
                      float *y);
/* LayerNorm2d (SAM): every pixel of x [c, hw] normalised over its c channels, then g, b [c]
 * per channel. y may equal x. */
void g3d_nn_layernorm2d(const float *x, int c, int hw, const float *g, const float *b, float eps, float *y);

/* ======================================================================================
 * Resampling, padding, embeddings
 * ==================================================================================== */
/* Nearest-neighbour x2 upsampling: x [c, h, w] -> y [c, 2h, 2w]. */
void g3d_nn_upsample2x(const float *x, int c, int h, int w, float *y);
/* Bilinear resize x [c, h, w] -> y [c, oh, ow], PyTorch's F.interpolate(mode="bilinear",
 * antialias=False): align_corners 1 maps the corner pixels onto each other (source coordinate
 * o (in-1)/(out-1)), 0 maps pixel centres (clamped at 0). y must not alias x. Returns
 * G3D_ERR_ARG for empty sizes, G3D_ERR_NOMEM. */
g3d_status g3d_nn_resize_bilinear(const float *x, int c, int h, int w, float *y, int oh, int ow, int align_corners);
/* Pads x [c, h, w] by top/bottom/left/right pixels -> y [c, h+top+bottom, w+left+right].
 * Reflect needs each pad < the side, symmetric <= the side (else G3D_ERR_ARG). Negative pads
 * are refused. */
g3d_status g3d_nn_pad2d(const float *x, int c, int h, int w, int top, int bottom, int left, int right,
                        g3d_nn_padmode mode, float *y);
/* Sinusoidal timestep embedding of LDM / diffusers (flip_sin_to_cos, shift 0):
 * out[j] = cos(t f_j), out[half + j] = sin(t f_j), f_j = max_period^(-j/half), half = dim/2;
 * an odd dim gets a trailing 0. max_period is 10000 for Stable Diffusion. */
void g3d_nn_timestep_embedding(float t, int dim, float max_period, float *out);

/* ======================================================================================
 * Real 2-D FFT (FFTW3, single precision, norm "ortho", any size)
 * ==================================================================================== */
/* x [c, h, w] -> y [c, 2, h, w/2+1]: per channel the real plane then the imaginary plane of
 * torch.fft.rfftn(x, dim=(-2,-1), norm='ortho'), i.e. LaMa's [re, im] channel pairs.
 * Plans are made once per size (under a lock: FFTW's planner is not thread-safe) and reused. */
g3d_status g3d_nn_rfft2(const float *x, int c, int h, int w, float *y);
/* Inverse: y [c, 2, h, w/2+1] -> x [c, h, w] as torch.fft.irfftn(y, s=(h, w), norm='ortho')
 * (the imaginary parts the real output cannot carry are dropped the way PyTorch does). */
g3d_status g3d_nn_irfft2(const float *y, int c, int h, int w, float *x);
/* Frees the cached plans (optional; e.g. before checking a process for leaks). */
void g3d_nn_fft_forget(void);

/* ======================================================================================
 * Activation arena: one per forward pass (or per model), reused between layers
 * ==================================================================================== */
/* A stack of 64-byte aligned buffers. Allocate a layer's outputs and temporaries from it,
 * take a mark before a block and reset to the mark after it: everything allocated since is
 * released at once and the memory is reused by the next block. The arena grows in chunks
 * when a request does not fit (earlier pointers stay valid); g3d_nn_arena_reset to 0 merges
 * the chunks into one of the peak size, so from the second pass on it never allocates. Not
 * thread-safe: one arena per concurrent forward pass. */
typedef struct g3d_nn_arena g3d_nn_arena;

/* An empty arena with `bytes` reserved up front (0: grow on demand); NULL if out of memory. */
g3d_nn_arena *g3d_nn_arena_new(size_t bytes);
void g3d_nn_arena_free(g3d_nn_arena *a);
/* n floats, 64-byte aligned, uninitialised; NULL (and a G3D_ERR_NOMEM message) on failure. */
float *g3d_nn_arena_floats(g3d_nn_arena *a, size_t n);
/* The current top, for g3d_nn_arena_reset. */
size_t g3d_nn_arena_mark(const g3d_nn_arena *a);
/* Releases everything allocated after `mark` (pointers from then on become invalid). */
void g3d_nn_arena_reset(g3d_nn_arena *a, size_t mark);
/* Largest top reached so far, in bytes (the memory a pass needs). */
size_t g3d_nn_arena_peak(const g3d_nn_arena *a);

#ifdef __cplusplus
}
#endif

#include "gen3d/nn_attention.h"

#endif /* G3D_NN_H */
