/* The register-blocked multiply at the heart of every product in src/nn, one copy per
 * instruction set, chosen once at run time (the library is built for the baseline x86-64 so a
 * user's binary runs anywhere; the AVX-512 and AVX2 copies carry GCC target attributes).
 *
 * Shape: C[6 x 16*nv] (+)= A[6 x K] B[K x 16*nv]. A is read by broadcasting single elements
 * (row i, step k at a[i*lda + k*ka]) so activations, weights and transposed operands need no
 * packing; B rows are vectors (b + k*ldb). Each element of C is one chain of fused
 * multiply-adds over k in order, whatever the tiling around it, which is what makes every
 * product independent of the thread count. This file is compiled with -ffp-contract=fast so
 * the vector a*b + c below becomes one FMA instruction. */
#include "nn/nn_int.h"

#include <immintrin.h>
#include <stdlib.h>
#include <string.h>

typedef float v16 __attribute__((vector_size(64)));
typedef float v16u __attribute__((vector_size(64), aligned(4), may_alias));
typedef float v8 __attribute__((vector_size(32)));
typedef float v8u __attribute__((vector_size(32), aligned(4), may_alias));

/* 6 rows x NCH vectors of type VT; the arrays are fully unrolled into registers. */
#define KERNEL_BODY(VT, VTU, NCH)                                                                  \
    VT r[NN_MR][NCH];                                                                              \
    _Pragma("GCC unroll 6") for (int i = 0; i < NN_MR; i++)                                        \
        _Pragma("GCC unroll 4") for (int j = 0; j < NCH; j++)                                      \
            r[i][j] = acc ? (VT) * (const VTU *)(c + i * ldc + j * (int)(sizeof(VT) / 4)) : (VT){0}; \
    const float *a0 = a, *a1 = a + lda, *a2 = a + 2 * lda, *a3 = a + 3 * lda, *a4 = a + 4 * lda,    \
                *a5 = a + 5 * lda;                                                                 \
    for (int k = 0; k < K; k++) {                                                                  \
        VT bv[NCH];                                                                                \
        _Pragma("GCC unroll 4") for (int j = 0; j < NCH; j++) bv[j] =                              \
            *(const VTU *)(b + j * (int)(sizeof(VT) / 4));                                         \
        b += ldb;                                                                                  \
        const float x[NN_MR] = {*a0, *a1, *a2, *a3, *a4, *a5};                                     \
        a0 += ka, a1 += ka, a2 += ka, a3 += ka, a4 += ka, a5 += ka;                                \
        _Pragma("GCC unroll 6") for (int i = 0; i < NN_MR; i++)                                    \
            _Pragma("GCC unroll 4") for (int j = 0; j < NCH; j++) r[i][j] += x[i] * bv[j];         \
    }                                                                                              \
    _Pragma("GCC unroll 6") for (int i = 0; i < NN_MR; i++)                                        \
        _Pragma("GCC unroll 4") for (int j = 0; j < NCH; j++)                                      \
            *(VTU *)(c + i * ldc + j * (int)(sizeof(VT) / 4)) = r[i][j];

#define KARGS int K, const float *restrict a, long lda, long ka, const float *restrict b, long ldb, \
              float *restrict c, long ldc, int acc

#define AVX512 __attribute__((target("avx512f,avx512vl,avx512bw,fma,f16c")))
#define AVX2 __attribute__((target("avx2,fma,f16c")))

/* The AVX-512 kernel is written so that GCC keeps all 6 x NCH accumulators, the NCH vectors of
 * B and one broadcast in the 32 registers: each row of A is broadcast just before its FMAs,
 * and the six rows are addressed from two pointers plus lda and 2 lda (x86 index addressing),
 * which leaves enough general registers. The generic body above spills an accumulator and the
 * broadcasts with 4 vectors per row (about 5 % slower). Same FMAs in the same order. */
#define ROW512(R, P, OFF)                                                                                      \
    do {                                                                                                       \
        const v16 x = _mm512_set1_ps((P)[OFF]);                                                                \
        _Pragma("GCC unroll 4") for (int j = 0; j < NCH; j++) r[R][j] += x * bv[j];                            \
    } while (0)
#define KERNEL512_PRODUCT(NCH_, STEP)                                                                            \
    enum { NCH = NCH_ };                                                                                       \
    v16 r[NN_MR][NCH];                                                                                         \
    _Pragma("GCC unroll 6") for (int i = 0; i < NN_MR; i++)                                                    \
        _Pragma("GCC unroll 4") for (int j = 0; j < NCH; j++)                                                  \
            r[i][j] = acc ? (v16) * (const v16u *)(c + i * ldc + 16 * j) : (v16){0};                           \
    const float *p0 = a, *p3 = a + 3 * lda;                                                                    \
    const long l2 = 2 * lda;                                                                                   \
    for (int k = 0; k < K; k++) {                                                                              \
        v16 bv[NCH];                                                                                           \
        _Pragma("GCC unroll 4") for (int j = 0; j < NCH; j++) bv[j] = *(const v16u *)(b + 16 * j);             \
        b += ldb;                                                                                              \
        ROW512(0, p0, 0);                                                                                      \
        ROW512(1, p0, lda);                                                                                    \
        ROW512(2, p0, l2);                                                                                     \
        ROW512(3, p3, 0);                                                                                      \
        ROW512(4, p3, lda);                                                                                    \
        ROW512(5, p3, l2);                                                                                     \
        p0 += ka, p3 += ka;                                                                                    \
        STEP                                                                                                   \
    }
#define KERNEL512_STORE                                                                                        \
    _Pragma("GCC unroll 6") for (int i = 0; i < NN_MR; i++)                                                    \
        _Pragma("GCC unroll 4") for (int j = 0; j < NCH; j++) *(v16u *)(c + i * ldc + 16 * j) = r[i][j];
#define KERNEL512_BODY(NCH_) KERNEL512_PRODUCT(NCH_, ) KERNEL512_STORE

AVX512 static void k512_1(KARGS) { KERNEL512_BODY(1) }
AVX512 static void k512_2(KARGS) { KERNEL512_BODY(2) }
AVX512 static void k512_3(KARGS) { KERNEL512_BODY(3) }
AVX512 static void k512_4(KARGS) { KERNEL512_BODY(4) }
/* ng groups of six rows in one call, group g at a + g ga and c + g gc: attention's products
 * have only 40-77 steps per group (the head size, or a short key set), and a call per group
 * had paid the kernel's setup of its 24 row addresses every time (QK^T ran at 73 % of the
 * sgemm rate, against 113 % for the same call with ten times the steps). */
#define KGROUPS512(NAME, NCH_)                                                                                \
    AVX512 static void NAME(int K, const float *restrict a, long lda, long ka, const float *restrict b0,       \
                            long ldb, float *restrict c, long ldc, int acc, long ga, long gc, int ng)        \
    {                                                                                                        \
        for (int g = 0; g < ng; g++, a += ga, c += gc) {                                                     \
            const float *b = b0;                                                                             \
            KERNEL512_BODY(NCH_)                                                                             \
        }                                                                                                    \
    }
KGROUPS512(k512g_1, 1)
KGROUPS512(k512g_2, 2)
KGROUPS512(k512g_3, 3)
KGROUPS512(k512g_4, 4)

/* one line of each prefetch range per step, while any is left */
#define KSCORES_PREFETCH                                                                                      \
    if (npf > 0) {                                                                                            \
        __builtin_prefetch(pf0, 0, 2), __builtin_prefetch(pf1, 1, 2);                                         \
        pf0 += 64, pf1 += 64, npf--;                                                                          \
    }
/* nn_kernel_scores: the groups' products, then on the registers the two addend rows of each
 * row (masked to the valid columns, so a table's last row may end there) and the running
 * column maxima, before the one store. */
#define KSCORES512(NAME, NCH_)                                                                                \
    AVX512 static void NAME(int K, const float *restrict a, long lda, long ka, const float *restrict b0,       \
                            long ldb, float *restrict c, long ldc, long ga, long gc, int ng,                 \
                            const float *const *add0, const float *const *add1, int nvalid, float *colmax,   \
                            const char *pf0, const char *pf1, int npf)                                       \
    {                                                                                                        \
        const int acc = 0;                                                                                   \
        __mmask16 vm[4];                                                                                     \
        for (int j = 0; j < 4; j++) {                                                                        \
            const int n = nvalid - 16 * j;                                                                   \
            vm[j] = n >= 16 ? (__mmask16)0xffff : n > 0 ? (__mmask16)((1u << n) - 1) : 0;                    \
        }                                                                                                    \
        v16 mx[NCH_];                                                                                        \
        for (int j = 0; j < NCH_; j++) mx[j] = colmax ? (v16) * (const v16u *)(colmax + 16 * j) : (v16){0}; \
        for (int g = 0; g < ng; g++, a += ga, c += gc) {                                                     \
            const float *b = b0;                                                                             \
            KERNEL512_PRODUCT(NCH_, KSCORES_PREFETCH)                                                        \
            if (add0)                                                                                        \
                _Pragma("GCC unroll 6") for (int i = 0; i < NN_MR; i++) {                                    \
                    const float *x0 = add0[NN_MR * g + i], *x1 = add1[NN_MR * g + i];                        \
                    _Pragma("GCC unroll 4") for (int j = 0; j < NCH; j++) r[i][j] +=                         \
                        (v16)_mm512_maskz_loadu_ps(vm[j], x0 + 16 * j) +                                     \
                        (v16)_mm512_maskz_loadu_ps(vm[j], x1 + 16 * j);                                      \
                }                                                                                            \
            if (colmax)                                                                                      \
                _Pragma("GCC unroll 6") for (int i = 0; i < NN_MR; i++)                                      \
                    _Pragma("GCC unroll 4") for (int j = 0; j < NCH; j++) mx[j] =                            \
                        (v16)_mm512_max_ps((__m512)mx[j], (__m512)r[i][j]);                                  \
            KERNEL512_STORE                                                                                  \
        }                                                                                                    \
        if (colmax)                                                                                          \
            for (int j = 0; j < NCH_; j++) *(v16u *)(colmax + 16 * j) = mx[j];                               \
    }
KSCORES512(k512s_1, 1)
KSCORES512(k512s_2, 2)
KSCORES512(k512s_3, 3)
KSCORES512(k512s_4, 4)

/* 16 ymm registers: 6 rows x 16 columns is the widest tile that stays in them */
AVX2 static void k256(KARGS) { KERNEL_BODY(v8, v8u, 2) }
static void kbase(KARGS) { KERNEL_BODY(v8, v8u, 2) }

static int g_isa = -1;

static int detect(void)
{
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512bw") &&
        __builtin_cpu_supports("fma"))
        return NN_ISA_AVX512;
    if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return NN_ISA_AVX2;
    return NN_ISA_BASE;
}

int nn_isa(void)
{
    int isa = __atomic_load_n(&g_isa, __ATOMIC_RELAXED);
    if (isa < 0) {
        isa = detect();
        const char *e = getenv("G3D_NN_ISA");
        /* a lower level may be forced (to compare paths); never a higher one */
        if (e && !strcmp(e, "avx2") && isa > NN_ISA_AVX2) isa = NN_ISA_AVX2;
        if (e && !strcmp(e, "base")) isa = NN_ISA_BASE;
        __atomic_store_n(&g_isa, isa, __ATOMIC_RELAXED);
    }
    return isa;
}

int nn_isa_force(int isa)
{
    int best = detect(), old = nn_isa();
    __atomic_store_n(&g_isa, isa < best ? isa : best, __ATOMIC_RELAXED);
    return old;
}

const char *g3d_nn_isa_name(void)
{
    static const char *const names[] = {"generic x86-64", "AVX2", "AVX-512"};
    return names[nn_isa()];
}

void nn_kernel(int K, const float *a, long lda, long ka, const float *b, long ldb, float *c, long ldc, int nv, int acc)
{
    switch (nn_isa()) {
    case NN_ISA_AVX512:
        switch (nv) {
        case 1: k512_1(K, a, lda, ka, b, ldb, c, ldc, acc); return;
        case 2: k512_2(K, a, lda, ka, b, ldb, c, ldc, acc); return;
        case 3: k512_3(K, a, lda, ka, b, ldb, c, ldc, acc); return;
        default: k512_4(K, a, lda, ka, b, ldb, c, ldc, acc); return;
        }
    case NN_ISA_AVX2:
        for (int j = 0; j < nv; j++) k256(K, a, lda, ka, b + 16 * j, ldb, c + 16 * j, ldc, acc);
        return;
    default:
        for (int j = 0; j < nv; j++) kbase(K, a, lda, ka, b + 16 * j, ldb, c + 16 * j, ldc, acc);
        return;
    }
}

void nn_kernel_groups(int K, const float *a, long lda, long ka, long ga, const float *b, long ldb, float *c, long ldc,
                      long gc, int nv, int ng, int acc)
{
    if (nn_isa() == NN_ISA_AVX512) {
        switch (nv) {
        case 1: k512g_1(K, a, lda, ka, b, ldb, c, ldc, acc, ga, gc, ng); return;
        case 2: k512g_2(K, a, lda, ka, b, ldb, c, ldc, acc, ga, gc, ng); return;
        case 3: k512g_3(K, a, lda, ka, b, ldb, c, ldc, acc, ga, gc, ng); return;
        default: k512g_4(K, a, lda, ka, b, ldb, c, ldc, acc, ga, gc, ng); return;
        }
    }
    for (int g = 0; g < ng; g++) nn_kernel(K, a + g * ga, lda, ka, b, ldb, c + g * gc, ldc, nv, acc);
}

void nn_kernel_scores(int K, const float *a, long lda, long ka, long ga, const float *b, long ldb, float *c, long ldc,
                      long gc, int nv, int ng, const float *const *add0, const float *const *add1, int nvalid,
                      float *colmax, const char *pf0, const char *pf1, int npf)
{
    if (nn_isa() == NN_ISA_AVX512) {
        switch (nv) {
        case 1: k512s_1(K, a, lda, ka, b, ldb, c, ldc, ga, gc, ng, add0, add1, nvalid, colmax, pf0, pf1, npf); return;
        case 2: k512s_2(K, a, lda, ka, b, ldb, c, ldc, ga, gc, ng, add0, add1, nvalid, colmax, pf0, pf1, npf); return;
        case 3: k512s_3(K, a, lda, ka, b, ldb, c, ldc, ga, gc, ng, add0, add1, nvalid, colmax, pf0, pf1, npf); return;
        default: k512s_4(K, a, lda, ka, b, ldb, c, ldc, ga, gc, ng, add0, add1, nvalid, colmax, pf0, pf1, npf); return;
        }
    }
    for (int i = 0; i < npf; i++) __builtin_prefetch(pf0 + 64 * i, 0, 2), __builtin_prefetch(pf1 + 64 * i, 1, 2);
    nn_kernel_groups(K, a, lda, ka, ga, b, ldb, c, ldc, gc, nv, ng, 0);
    for (int r = 0; r < NN_MR * ng; r++) {
        float *cr = c + r / NN_MR * gc + r % NN_MR * ldc;
        for (int j = 0; j < 16 * nv; j++) {
            if (add0 && j < nvalid) cr[j] += add0[r][j] + add1[r][j];
            if (colmax) colmax[j] = cr[j] > colmax[j] ? cr[j] : colmax[j];
        }
    }
}
