/* The tuned operators of src/nn against their plain reference loops (src/nn/nn_int.h), on
 * shapes chosen to reach every edge of the tiling (partial row groups, partial panels, several
 * K blocks and tiles), on every instruction set the CPU has, with every epilogue; results that
 * must not depend on the thread count are compared bit for bit. */
#include "nn/nn_int.h"
#include "testutil.h"
#include "gen3d/resize.h"

#include <omp.h>

static float *rnd(size_t n, uint64_t seed, float scale)
{
    float *p = malloc(sizeof(float) * (n ? n : 1));
    g3d_rng r;
    g3d_rng_seed(&r, seed, 3);
    for (size_t i = 0; i < n; i++) p[i] = scale * g3d_rng_normal(&r);
    return p;
}

/* worst |a - b| relative to the root mean square of b: float sums over K terms err in
 * absolute terms, on the scale of the values, not of each result */
static double err(const float *a, const float *b, size_t n)
{
    double m = 0, s = 0;
    for (size_t i = 0; i < n; i++) m = fmax(m, fabs((double)a[i] - b[i])), s += (double)b[i] * b[i];
    return n ? m / (sqrt(s / n) + 1e-30) : 0;
}

static int isas[3], nisa;

static void find_isas(void)
{
    int best = nn_isa();
    for (int i = NN_ISA_BASE; i <= best; i++) isas[nisa++] = i;
}

TEST(matmul_shapes_and_transposes)
{
    static const int shapes[][3] = {{1, 1, 1},   {5, 17, 3},   {6, 64, 9},    {7, 65, 33},  {13, 130, 384},
                                    {29, 300, 385}, {100, 40, 700}, {250, 19, 50}, {3, 1000, 20}};
    for (int s = 0; s < (int)(sizeof shapes / sizeof *shapes); s++)
        for (int t = 0; t < 4; t++) {
            int M = shapes[s][0], N = shapes[s][1], K = shapes[s][2], ta = t & 1, tb = t >> 1;
            int lda = (ta ? M : K) + 3, ldb = (tb ? K : N) + 1, ldc = N + 2;
            float *A = rnd((size_t)lda * (ta ? K : M), s * 10 + t, 1), *B = rnd((size_t)ldb * (tb ? N : K), s * 10 + t + 5, 1);
            float *C = rnd((size_t)ldc * M, 99, 1), *R = malloc(sizeof(float) * ldc * M);
            memcpy(R, C, sizeof(float) * ldc * M);
            float beta = (float)(t == 3);
            nn_ref_matmul(ta, tb, M, N, K, 0.5f, A, lda, B, ldb, beta, R, ldc);
            for (int i = 0; i < nisa; i++) {
                int old = nn_isa_force(isas[i]);
                float *Y = malloc(sizeof(float) * ldc * M);
                memcpy(Y, C, sizeof(float) * ldc * M);
                CHECK_OK(g3d_nn_matmul(ta, tb, M, N, K, 0.5f, A, lda, B, ldb, beta, Y, ldc));
                double e = 0;
                for (int r = 0; r < M; r++) e = fmax(e, err(Y + (size_t)r * ldc, R + (size_t)r * ldc, N));
                CHECK_MSG(e < 2e-5, "%dx%dx%d ta %d tb %d isa %d: err %g", M, N, K, ta, tb, isas[i], e);
                /* the padding between rows is left alone */
                for (int r = 0; r < M; r++) CHECK(Y[(size_t)r * ldc + N] == C[(size_t)r * ldc + N]);
                nn_isa_force(old);
                free(Y);
            }
            free(A), free(B), free(C), free(R);
        }
    float c = 0;
    CHECK_FAILS(g3d_nn_matmul(0, 0, 1, 1, 1, 1.0f, &c, 1, &c, 1, 0.5f, &c, 1));
    CHECK_FAILS(g3d_nn_matmul(0, 0, -1, 1, 1, 1.0f, &c, 1, &c, 1, 0.0f, &c, 1));
}

/* n = 13: all rows in one tile, so the columns are split into tiles 16 wide, inside the panels */
static void check_linear(int n)
{
    const int in = 77, out = 150;
    float *x = rnd((size_t)n * in, 1, 1), *w = rnd((size_t)out * in, 2, 0.2f), *b = rnd(out, 3, 1), *g = rnd(out, 4, 1);
    float *res = rnd((size_t)n * out, 5, 1), *y = malloc(sizeof(float) * n * out), *r = malloc(sizeof(float) * n * out);
    for (g3d_act act = G3D_ACT_NONE; act <= G3D_ACT_TANH; act++)
        for (int i = 0; i < nisa; i++) {
            int old = nn_isa_force(isas[i]);
            g3d_nn_lin L;
            CHECK_OK(g3d_nn_lin_init(&L, w, G3D_DT_F32, b, out, in, G3D_DT_F32));
            /* in place on the residual */
            memcpy(y, res, sizeof(float) * n * out);
            g3d_nn_epi e = {.act = act, .scale = g, .res = y};
            CHECK_OK(g3d_nn_lin_forward(&L, x, n, 0, y, 0, &e));
            g3d_nn_epi er = {.act = act, .scale = g, .res = res};
            nn_ref_linear(x, n, in, w, b, out, &er, r);
            CHECK_MSG(err(y, r, (size_t)n * out) < 2e-5, "%d rows act %d isa %d: %g", n, act, isas[i],
                      err(y, r, (size_t)n * out));
            g3d_nn_lin_free(&L);
            nn_isa_force(old);
        }
    /* 16-bit storage: exactly the float32 product of the rounded weights */
    static const g3d_dtype types[] = {G3D_DT_BF16, G3D_DT_F16};
    for (int t = 0; t < 2; t++) {
        g3d_nn_lin L16, Lr;
        CHECK_OK(g3d_nn_lin_init(&L16, w, G3D_DT_F32, b, out, in, types[t]));
        /* the rounded weights as 16-bit values, widened through the checkpoint converter */
        uint16_t *h = malloc(sizeof(uint16_t) * out * in);
        float *wr = malloc(sizeof(float) * out * in);
        for (int j = 0; j < out; j++)
            for (int k = 0; k < in; k++) h[j * in + k] = ((const uint16_t *)L16.panels)[(size_t)(j / 64) * in * 64 + k * 64 + j % 64];
        g3d_dtype_to_f32(types[t], h, wr, (int64_t)out * in);
        CHECK_OK(g3d_nn_lin_init(&Lr, wr, G3D_DT_F32, b, out, in, G3D_DT_F32));
        float *y2 = malloc(sizeof(float) * n * out);
        CHECK_OK(g3d_nn_lin_forward(&L16, x, n, 0, y, 0, NULL));
        CHECK_OK(g3d_nn_lin_forward(&Lr, x, n, 0, y2, 0, NULL));
        CHECK(!memcmp(y, y2, sizeof(float) * n * out));
        /* rounding error of 16-bit weights stays at their precision */
        nn_ref_linear(x, n, in, w, b, out, NULL, r);
        CHECK(err(y, r, (size_t)n * out) < (t ? 2e-3 : 2e-2));
        /* packing straight from 16-bit checkpoint data gives the same panels */
        g3d_nn_lin L2;
        CHECK_OK(g3d_nn_lin_init(&L2, h, types[t], b, out, in, types[t]));
        CHECK(!memcmp(L2.panels, L16.panels, sizeof(uint16_t) * 3 * 64 * in));
        g3d_nn_lin_free(&L2), g3d_nn_lin_free(&L16), g3d_nn_lin_free(&Lr);
        free(h), free(wr), free(y2);
    }
    free(x), free(w), free(b), free(g), free(res), free(y), free(r);
}

TEST(linear_epilogues_and_16bit_weights)
{
    check_linear(101);
    check_linear(13);
    g3d_nn_lin L;
    float w = 1;
    CHECK_FAILS(g3d_nn_lin_init(&L, &w, G3D_DT_I32, NULL, 1, 1, G3D_DT_F32));
    CHECK_FAILS(g3d_nn_lin_init(&L, &w, G3D_DT_F32, NULL, 0, 1, G3D_DT_F32));
}

typedef struct conv_case {
    int cin, cout, k, s, p, d, g, h, w, tr, op;
    g3d_nn_padmode mode;
} conv_case;

/* prepare: run through g3d_nn_conv_prepare (Winograd for 3x3 stride 1, phases for transposed);
 * 2: with wino_small (F(2x2) also where F(4x4) would be chosen) */
static void check_conv(const conv_case *cc, g3d_dtype wt, const g3d_nn_epi *epi, uint64_t seed, int prepare)
{
    const size_t nw = (size_t)cc->cout * (cc->cin / (cc->g ? cc->g : 1)) * cc->k * cc->k;
    float *w = rnd(nw, seed, 0.3f), *b = rnd(cc->cout, seed + 1, 1), *x = rnd((size_t)cc->cin * cc->h * cc->w, seed + 2, 1);
    uint16_t *w16 = NULL;
    g3d_nn_conv c = g3d_nn_conv_make(cc->cin, cc->cout, cc->k, cc->s, cc->p, w, b);
    c.dilation = cc->d, c.groups = cc->g, c.pad_mode = cc->mode, c.transposed = cc->tr, c.output_padding = cc->op;
    c.wino_small = prepare == 2;
    if (wt != G3D_DT_F32) {
        /* weights as 16-bit values: the reference reads them the same way */
        w16 = malloc(sizeof(uint16_t) * nw);
        for (size_t i = 0; i < nw; i++) {
            uint32_t u;
            memcpy(&u, &w[i], 4);
            /* F16: magnitudes in [1/8, 1) with the sign of w */
            w16[i] = wt == G3D_DT_BF16 ? (uint16_t)(u >> 16)
                                       : (uint16_t)(((u >> 16) & 0x8000) | (0x3000 + (i * 7919) % 0x0c00));
        }
        c.w = w16, c.wtype = wt;
    }
    int ho, wo;
    CHECK_OK(g3d_nn_conv_out_size(&c, cc->h, cc->w, &ho, &wo));
    if (prepare) CHECK_OK(g3d_nn_conv_prepare(&c));
    const size_t ny = (size_t)cc->cout * ho * wo;
    float *y = malloc(sizeof(float) * ny), *r = malloc(sizeof(float) * ny);
    CHECK_OK(nn_ref_conv(&c, x, cc->h, cc->w, epi, r));
    /* F(4x4)'s transforms multiply by up to 8 and 1/24: about 20x the rounding of the direct sum */
    const double tol = prepare && nn_wino_eligible(&c) && nn_wino_tile(&c) == 4 ? 1e-4 : 2e-5;
    for (int i = 0; i < nisa; i++) {
        int old = nn_isa_force(isas[i]);
        if (epi && epi->res) memcpy(y, epi->res, sizeof(float) * ny);
        g3d_nn_epi e = {0};
        if (epi) e = *epi, e.res = epi->res ? y : NULL; /* residual in place */
        CHECK_OK(g3d_nn_conv_forward(&c, x, cc->h, cc->w, y, epi ? &e : NULL));
        double er = err(y, r, ny);
        CHECK_MSG(er < tol, "conv %d->%d k%d s%d p%d d%d g%d %dx%d T%d op%d mode %d wt %d prep %d isa %d: err %g",
                  cc->cin, cc->cout, cc->k, cc->s, cc->p, cc->d, cc->g, cc->w, cc->h, cc->tr, cc->op, cc->mode, wt,
                  prepare, isas[i], er);
        nn_isa_force(old);
    }
    g3d_nn_conv_release(&c);
    free(w), free(b), free(x), free(w16), free(y), free(r);
}

TEST(conv_against_reference)
{
    static const conv_case cases[] = {
        /* cin cout k s p d g  h   w  tr op mode */
        {3, 5, 3, 1, 1, 1, 1, 9, 7, 0, 0, G3D_PAD_ZEROS},
        {64, 22, 3, 1, 1, 1, 1, 17, 19, 0, 0, G3D_PAD_ZEROS},     /* K = 576: two K blocks, 4 rows of 6 - 2 */
        {48, 13, 3, 2, 1, 1, 1, 40, 37, 0, 0, G3D_PAD_REFLECT},   /* many pixel tiles, partial panels */
        {16, 16, 3, 1, 1, 1, 1, 5, 300, 0, 0, G3D_PAD_REPLICATE}, /* rows crossing panels */
        {8, 9, 5, 3, 2, 1, 1, 17, 19, 0, 0, G3D_PAD_REFLECT},
        {8, 6, 3, 1, 3, 3, 1, 12, 11, 0, 0, G3D_PAD_ZEROS},
        {8, 6, 3, 1, 2, 2, 1, 12, 11, 0, 0, G3D_PAD_REPLICATE},
        {12, 8, 3, 1, 1, 1, 4, 10, 9, 0, 0, G3D_PAD_ZEROS},
        {10, 10, 3, 2, 1, 1, 10, 15, 14, 0, 0, G3D_PAD_REFLECT},   /* depthwise */
        {10, 10, 5, 1, 4, 2, 10, 15, 14, 0, 0, G3D_PAD_REPLICATE}, /* depthwise, dilated */
        {40, 30, 1, 1, 0, 1, 1, 13, 21, 0, 0, G3D_PAD_ZEROS},      /* pointwise */
        {400, 9, 1, 1, 0, 1, 1, 7, 11, 0, 0, G3D_PAD_ZEROS},       /* pointwise, two K blocks */
        {12, 520, 1, 1, 0, 1, 1, 5, 7, 0, 0, G3D_PAD_ZEROS},       /* pointwise, two row tiles */
        {64, 64, 1, 1, 0, 1, 1, 37, 37, 0, 0, G3D_PAD_ZEROS},      /* pointwise, last rows in place */
        {7, 5, 1, 2, 0, 1, 1, 13, 21, 0, 0, G3D_PAD_ZEROS},
        {2, 3, 3, 1, 1, 1, 1, 1, 2, 0, 0, G3D_PAD_ZEROS},          /* mostly padding */
        {20, 11, 3, 2, 1, 1, 1, 9, 8, 1, 1, G3D_PAD_ZEROS},        /* transposed */
        {20, 11, 2, 2, 0, 1, 1, 9, 8, 1, 0, G3D_PAD_ZEROS},
        {20, 11, 2, 2, 0, 1, 1, 9, 8, 1, 1, G3D_PAD_ZEROS},
        {20, 11, 4, 4, 0, 1, 1, 9, 8, 1, 0, G3D_PAD_ZEROS},
        {20, 40, 4, 4, 0, 1, 1, 5, 70, 1, 0, G3D_PAD_ZEROS},       /* 640 interleaved rows: two row tiles */
        {9, 7, 3, 3, 0, 1, 1, 6, 5, 1, 0, G3D_PAD_ZEROS},          /* interleave by 3 */
        {400, 5, 2, 2, 0, 1, 1, 4, 7, 1, 0, G3D_PAD_ZEROS},        /* interleaved, two K blocks */
        {20, 11, 5, 3, 2, 2, 1, 9, 8, 1, 2, G3D_PAD_ZEROS},
        {70, 9, 3, 1, 1, 1, 1, 6, 7, 1, 0, G3D_PAD_ZEROS},
        /* Winograd when prepared: odd sizes, every padding, several channel and tile blocks */
        {100, 70, 3, 1, 1, 1, 1, 11, 37, 0, 0, G3D_PAD_ZEROS},
        {16, 18, 3, 1, 1, 1, 1, 3, 3, 0, 0, G3D_PAD_REFLECT},
        {20, 40, 3, 1, 0, 1, 1, 10, 13, 0, 0, G3D_PAD_ZEROS},
        {17, 20, 3, 1, 2, 1, 1, 70, 9, 0, 0, G3D_PAD_REPLICATE},
        /* F(4x4): panels across tile rows, two channel blocks, a map smaller than a tile */
        {64, 64, 3, 1, 1, 1, 1, 23, 70, 0, 0, G3D_PAD_REFLECT},
        {70, 140, 3, 1, 1, 1, 1, 9, 6, 0, 0, G3D_PAD_REPLICATE},
        {96, 64, 3, 1, 0, 1, 1, 5, 3, 0, 0, G3D_PAD_ZEROS},
        /* few output channels, large kernel: one row per (channel, tap) */
        {24, 3, 7, 1, 3, 1, 1, 19, 23, 0, 0, G3D_PAD_REFLECT},
        {16, 1, 5, 1, 2, 1, 1, 6, 40, 0, 0, G3D_PAD_ZEROS},
        {16, 4, 5, 1, 1, 1, 1, 9, 8, 0, 0, G3D_PAD_REPLICATE},
        {16, 4, 7, 1, 3, 1, 1, 6, 2000, 0, 0, G3D_PAD_REFLECT}, /* bands of 4 and 2 rows */
        /* depthwise, stride 1: rows in blocks of 64 and 16 outputs and a tail */
        {6, 6, 3, 1, 1, 1, 6, 9, 150, 0, 0, G3D_PAD_ZEROS},
        {5, 5, 7, 1, 6, 2, 5, 11, 83, 0, 0, G3D_PAD_REFLECT},
        {4, 4, 3, 1, 0, 1, 4, 5, 40, 0, 0, G3D_PAD_ZEROS},
    };
    const int n = (int)(sizeof cases / sizeof *cases);
    for (int i = 0; i < n; i++) {
        check_conv(&cases[i], G3D_DT_F32, NULL, 10 + i, 0);
        check_conv(&cases[i], G3D_DT_F32, NULL, 10 + i, 1);
        const conv_case *cc = &cases[i];
        if (cc->k == 3 && cc->s == 1 && cc->d == 1 && cc->g == 1 && !cc->tr && cc->cin >= 64 && cc->cout >= 64)
            check_conv(cc, G3D_DT_F32, NULL, 10 + i, 2); /* F(4x4) layers kept to F(2x2) */
    }
    /* epilogues, 16-bit weights */
    for (int i = 0; i < n; i++) {
        const conv_case *cc = &cases[i];
        /* room for any output: up to 16x the input with a transposed stride of 4 */
        const size_t nres = (size_t)cc->cout * (cc->h * cc->w * 16 > 2000 ? cc->h * cc->w * 16 : 2000);
        float *g = rnd(cc->cout, 50 + i, 1), *res = rnd(nres, 60 + i, 1);
        g3d_nn_epi e = {.act = (g3d_act)(1 + i % 7), .scale = g, .res = res};
        check_conv(cc, G3D_DT_F32, &e, 30 + i, i % 2);
        check_conv(cc, i % 2 ? G3D_DT_F16 : G3D_DT_BF16, i % 3 ? &e : NULL, 40 + i, i % 3 == 1);
        free(g), free(res);
    }
}

TEST(conv_bad_configurations)
{
    float w[64] = {0}, x[64] = {0}, y[256];
    g3d_nn_conv c = g3d_nn_conv_make(4, 6, 3, 1, 1, w, NULL);
    c.groups = 4;
    CHECK_FAILS(g3d_nn_conv_forward(&c, x, 4, 4, y, NULL));
    c = g3d_nn_conv_make(1, 1, 3, 1, 2, w, NULL);
    c.pad_mode = G3D_PAD_REFLECT;
    CHECK_FAILS(g3d_nn_conv_forward(&c, x, 2, 8, y, NULL));
    c.pad_mode = G3D_PAD_SYMMETRIC;
    CHECK_FAILS(g3d_nn_conv_forward(&c, x, 8, 8, y, NULL));
    c = g3d_nn_conv_make(1, 1, 3, 2, 0, w, NULL);
    c.transposed = 1, c.output_padding = 2;
    CHECK_FAILS(g3d_nn_conv_forward(&c, x, 3, 3, y, NULL));
    c = g3d_nn_conv_make(1, 1, 3, 1, 0, w, NULL);
    c.wtype = G3D_DT_I8;
    CHECK_FAILS(g3d_nn_conv_forward(&c, x, 3, 3, y, NULL));
    c = g3d_nn_conv_make(1, 1, 5, 1, 1, w, NULL);
    CHECK_FAILS(g3d_nn_conv_forward(&c, x, 2, 2, y, NULL));
}

TEST(transpose_tile_against_reference)
{
    /* attention's query (w > nr: zero rows) and output (per-row scale, partial 16-blocks) tiles */
    float *src = rnd(70 * 90, 31, 1), *rs = rnd(90, 32, 1), *d = malloc(sizeof(float) * 90 * 80),
          *r = malloc(sizeof(float) * 90 * 80);
    const int shapes[][3] = {{64, 40, 64}, {13, 40, 16}, {40, 64, 40}, {7, 9, 7}, {64, 64, 64}, {1, 1, 16}, {40, 23, 48}};
    for (size_t s = 0; s < sizeof shapes / sizeof *shapes; s++)
        for (int scaled = 0; scaled < 2; scaled++) {
            const int nr = shapes[s][0], nc = shapes[s][1], w = shapes[s][2];
            for (int i = 0; i < 90 * 80; i++) d[i] = r[i] = -7.0f;
            nn_transpose_tile(src + 3, 90, nr, nc, d, 80, w, 0.3f, scaled ? rs : NULL);
            nn_ref_transpose_tile(src + 3, 90, nr, nc, r, 80, w, 0.3f, scaled ? rs : NULL);
            CHECK_MSG(!memcmp(d, r, sizeof(float) * 90 * 80), "transpose %d x %d -> w %d differs", nr, nc, w);
        }
    free(src), free(rs), free(d), free(r);
}

TEST(kernel_groups_equal_single_calls)
{
    /* attention's runs of six-row groups: the same bits as one call per group, any width, with
     * and without accumulation, rows of A strided (keys) or consecutive (value channels) */
    float *a = rnd(40 * 300, 41, 1), *b = rnd(300 * 70, 42, 1), *c0 = rnd(40 * 6 * 70, 43, 1);
    float *x = malloc(sizeof(float) * 40 * 6 * 70), *y = malloc(sizeof(float) * 40 * 6 * 70);
    const struct {
        long lda, ka, ga;
    } lay[] = {{300, 1, 6 * 300}, {1, 300, 6}};
    for (int i = 0; i < nisa; i++) {
        int old = nn_isa_force(isas[i]);
        for (int l = 0; l < 2; l++)
            for (int nv = 1; nv <= 4; nv++)
                for (int acc = 0; acc < 2; acc++) {
                    const int K = l ? 35 : 77, ng = 5;
                    memcpy(x, c0, sizeof(float) * 40 * 6 * 70), memcpy(y, c0, sizeof(float) * 40 * 6 * 70);
                    nn_kernel_groups(K, a, lay[l].lda, lay[l].ka, lay[l].ga, b, 70, x, 70, 6 * 70, nv, ng, acc);
                    for (int g = 0; g < ng; g++)
                        nn_kernel(K, a + g * lay[l].ga, lay[l].lda, lay[l].ka, b, 70, y + g * 6 * 70, 70, nv, acc);
                    CHECK_MSG(!memcmp(x, y, sizeof(float) * 40 * 6 * 70), "groups differ (isa %d, layout %d, nv %d, acc %d)",
                              isas[i], l, nv, acc);
                }
        nn_isa_force(old);
    }
    free(a), free(b), free(c0), free(x), free(y);
}

static void check_attention(g3d_nn_attn a, uint64_t seed, const char *what)
{
    const int hdv = a.hdv ? a.hdv : a.hd, nb = a.batch ? a.batch : 1, nq = a.nq ? a.nq : 1, nk = a.nk ? a.nk : 1;
    const long ldq = a.heads * a.hd + 3, ldk = a.heads * a.hd + 5, ldv = a.heads * hdv + 1, ldo = a.heads * hdv + 2;
    float *q = rnd((size_t)ldq * nq * nb, seed, 1), *k = rnd((size_t)ldk * nk * nb, seed + 1, 1),
          *v = rnd((size_t)ldv * nk * nb, seed + 2, 1);
    float *o = malloc(sizeof(float) * ldo * nq * nb), *r = malloc(sizeof(float) * ldo * nq * nb);
    a.q = q, a.k = k, a.v = v, a.ldq = ldq, a.ldk = ldk, a.ldv = ldv, a.ldo = ldo, a.out = o;
    a.bsq = ldq * nq, a.bsk = ldk * nk, a.bsv = ldv * nk, a.bso = ldo * nq;
    g3d_nn_attn ar = a;
    ar.out = r;
    nn_ref_attend(&ar);
    for (int i = 0; i < nisa; i++) {
        int old = nn_isa_force(isas[i]);
        CHECK_OK(g3d_nn_attend(&a));
        double e = 0;
        for (int t = 0; t < a.nq * nb; t++) e = fmax(e, err(o + (size_t)t * ldo, r + (size_t)t * ldo, (size_t)a.heads * hdv));
        CHECK_MSG(e < 1e-5, "%s (isa %d): err %g", what, isas[i], e);
        nn_isa_force(old);
    }
    free(q), free(k), free(v), free(o), free(r);
}

TEST(attention_against_reference)
{
    float *dense = rnd(3 * 130 * 250, 7, 2), *tables = rnd(3 * 2 * (4 + 5) * 20, 8, 1);
    g3d_nn_bias_dense bd = {dense, 130 * 250, 250}, bd49 = {dense, 49 * 49, 49};
    /* per window (3) and head (2): rh [4 keys rows x 20], rw [5 x 20] */
    g3d_nn_bias_relpos rp = {tables, tables + 3 * 2 * 4 * 20, 20, 4, 5, 2};
    /* SAM's windows of 14 x 14 (2 windows, 3 heads: more keys and values than fit the tiles of
     * every head, so a head at a time) and 77 keys on a 7 x 11 grid, the terms added by the
     * kernel */
    float *t196 = rnd(2 * 3 * (14 + 14) * 196, 9, 1), *t77 = rnd(2 * (7 + 11) * 77, 10, 1);
    g3d_nn_bias_relpos rp196 = {t196, t196 + 2 * 3 * 14 * 196, 196, 14, 14, 3}, rp77 = {t77, t77 + 2 * 7 * 77, 77, 7, 11, 2};
    struct {
        g3d_nn_attn a;
        const char *what;
    } cases[] = {
        {{.nq = 1, .nk = 1, .heads = 1, .hd = 1, .scale = 1}, "one token"},
        {{.nq = 130, .nk = 250, .heads = 3, .hd = 40, .scale = 0.15f}, "cross, head 40"},
        {{.nq = 70, .nk = 77, .heads = 2, .hd = 64, .hdv = 32, .scale = 0.125f}, "77 keys, hdv 32"},
        {{.nq = 200, .nk = 200, .heads = 2, .hd = 16, .scale = 0.25f, .causal = 1}, "causal"},
        {{.nq = 5, .nk = 300, .heads = 2, .hd = 16, .scale = 0.25f, .causal = 1}, "causal with a cache"},
        {{.nq = 130, .nk = 250, .heads = 3, .hd = 24, .scale = 0.2f, .bias = g3d_nn_bias_dense_fn, .bias_ctx = &bd},
         "dense bias"},
        {{.nq = 67, .nk = 40, .heads = 1, .hd = 520, .scale = 0.04f}, "single head of 520"},
        {{.nq = 49, .nk = 49, .heads = 3, .hd = 16, .scale = 0.25f, .batch = 7, .bias = g3d_nn_bias_dense_fn,
          .bias_ctx = &bd49},
         "7 windows of 49 tokens, dense bias"},
        {{.nq = 20, .nk = 20, .heads = 2, .hd = 8, .scale = 0.3f, .batch = 3, .bias = g3d_nn_bias_relpos_fn,
          .bias_ctx = &rp},
         "3 windows, relative positions"},
        {{.nq = 200, .nk = 77, .heads = 5, .hd = 40, .scale = 0.15f}, "SD cross-attention shape, 4 query blocks"},
        {{.nq = 100, .nk = 77, .heads = 4, .hd = 120, .scale = 0.09f}, "77 keys, a head at a time"},
        {{.nq = 196, .nk = 196, .heads = 3, .hd = 64, .scale = 0.125f, .batch = 2, .bias = g3d_nn_bias_relpos_fn,
          .bias_ctx = &rp196},
         "2 SAM windows, relative positions"},
        {{.nq = 77, .nk = 77, .heads = 2, .hd = 40, .scale = 0.15f, .bias = g3d_nn_bias_relpos_fn, .bias_ctx = &rp77},
         "77 tokens, relative positions"},
        {{.nq = 196, .nk = 196, .heads = 3, .hd = 64, .scale = 0.125f, .batch = 2}, "2 windows of 196, last block split"},
        {{.nq = 70, .nk = 300, .heads = 2, .hd = 256, .hdv = 250, .scale = 0.06f}, "wide heads, values transposed"},
        {{.nq = 20, .nk = 3, .heads = 3, .hd = 10, .hdv = 7, .scale = 0.3f}, "three keys, odd value heads"},
        {{.nq = 0, .nk = 10, .heads = 2, .hd = 8, .scale = 1}, "no queries"},
        {{.nq = 9, .nk = 0, .heads = 2, .hd = 8, .scale = 1}, "no keys"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) check_attention(cases[i].a, 100 + i, cases[i].what);
    free(dense), free(tables), free(t196), free(t77);
    g3d_nn_attn bad = {.nq = 3, .nk = 3, .heads = 0, .hd = 4};
    CHECK_FAILS(g3d_nn_attend(&bad));
    bad.heads = 2, bad.ldq = 5;
    CHECK_FAILS(g3d_nn_attend(&bad));
}

TEST(activations_against_libm)
{
    enum { N = 2003 };
    float x[N], y[N];
    for (int i = 0; i < N; i++) x[i] = (float)(i - N / 2) * 0.02f;
    x[0] = -100, x[1] = 100, x[2] = -1e-7f, x[3] = 88, x[4] = -88;
    for (g3d_act act = G3D_ACT_NONE; act <= G3D_ACT_TANH; act++)
        for (int i = 0; i < nisa; i++) {
            int old = nn_isa_force(isas[i]);
            memcpy(y, x, sizeof y);
            g3d_nn_activate(act, y, N);
            double e = 0;
            for (int j = 0; j < N; j++) {
                double ref = nn_ref_act1(act, x[j]);
                /* GELU's erf is accurate in absolute terms; exp-based ones relatively, up to the
                 * float rounding of the exponent's argument when that is large */
                double xv = x[j], arg = act == G3D_ACT_QUICK_GELU ? 1.702 * xv
                                        : act == G3D_ACT_GELU_TANH ? 1.5957691 * (xv + 0.044715 * xv * xv * xv)
                                        : act == G3D_ACT_TANH      ? 2 * xv
                                                                   : xv;
                double tol = act == G3D_ACT_GELU ? 4e-7 * (fabs(xv) + 1) : (1e-6 + 3e-7 * fabs(arg)) * fabs(ref) + 1e-30;
                if (!(fabs(y[j] - ref) <= tol)) e = fmax(e, fabs(y[j] - ref) / tol);
            }
            CHECK_MSG(e == 0, "act %d isa %d: %g x tolerance", act, isas[i], e);
            nn_isa_force(old);
        }
}

TEST(norms_and_softmax_against_reference)
{
    const int c = 96, hw = 70001 / 3, groups = 32;
    float *x = rnd((size_t)c * hw, 9, 2), *g = rnd(c, 10, 1), *b = rnd(c, 11, 1);
    float *y = malloc(sizeof(float) * c * hw), *r = malloc(sizeof(float) * c * hw);
    for (int i = 0; i < c * hw; i++) x[i] += 3.0f; /* an offset makes one-pass variances fail */
    g3d_nn_groupnorm(x, c, hw, groups, g, b, 1e-6f, G3D_ACT_SILU, y);
    nn_ref_groupnorm(x, c, hw, groups, g, b, 1e-6f, G3D_ACT_SILU, r);
    CHECK(err(y, r, (size_t)c * hw) < 1e-5);
    g3d_nn_layernorm2d(x, c, 1000, g, b, 1e-6f, y);
    nn_ref_layernorm2d(x, c, 1000, g, b, 1e-6f, r);
    CHECK(err(y, r, (size_t)c * 1000) < 1e-5);
    g3d_nn_layernorm(x, 300, c, g, b, 1e-5f, y);
    nn_ref_layernorm(x, 300, c, g, b, 1e-5f, r);
    CHECK(err(y, r, (size_t)c * 300) < 1e-5);
    memcpy(y, x, sizeof(float) * 37 * 301), memcpy(r, x, sizeof(float) * 37 * 301);
    y[5] = r[5] = -INFINITY;
    g3d_nn_softmax(y, 37, 301);
    nn_ref_softmax(r, 37, 301);
    CHECK(err(y, r, (size_t)37 * 301) < 1e-5 && y[5] == 0.0f);
    free(x), free(g), free(b), free(y), free(r);
}

TEST(fft_against_dft)
{
    static const int sizes[][2] = {{1, 1}, {3, 5}, {13, 8}, {16, 17}, {11, 22}};
    for (int s = 0; s < 5; s++) {
        int h = sizes[s][0], w = sizes[s][1], nf = 2 * h * (w / 2 + 1);
        float *x = rnd((size_t)2 * h * w, s, 1), *y = malloc(sizeof(float) * 2 * nf), *yr = malloc(sizeof(float) * 2 * nf);
        float *spec = rnd((size_t)2 * nf, s + 9, 1), *b = malloc(sizeof(float) * 2 * h * w), *br = malloc(sizeof(float) * 2 * h * w);
        CHECK_OK(g3d_nn_rfft2(x, 2, h, w, y));
        CHECK_OK(nn_ref_rfft2(x, 2, h, w, yr));
        CHECK_MSG(err(y, yr, (size_t)2 * nf) < 1e-5, "rfft2 %dx%d", w, h);
        CHECK_OK(g3d_nn_irfft2(spec, 2, h, w, b));
        CHECK_OK(nn_ref_irfft2(spec, 2, h, w, br));
        CHECK_MSG(err(b, br, (size_t)2 * h * w) < 1e-5, "irfft2 %dx%d", w, h);
        free(x), free(y), free(yr), free(spec), free(b), free(br);
    }
}

/* The same input gives the same bits with 1, 2 or 3 threads. */
TEST(independent_of_thread_count)
{
    const int cin = 40, cout = 50, h = 33, w = 35, n = 333, in = 200, out = 130;
    float *x = rnd((size_t)cin * h * w, 1, 1), *wc = rnd((size_t)cout * cin * 9, 2, 0.1f), *wl = rnd((size_t)out * in, 3, 0.1f);
    float *tok = rnd((size_t)n * in, 4, 1), *qkv = rnd((size_t)n * 3 * 64, 5, 1), *g = rnd(cout, 6, 1);
    /* prepared: F(2x2) at 40->50, F(4x4) at 64->70 */
    float *x4 = rnd((size_t)64 * h * w, 7, 1), *w4 = rnd((size_t)70 * 64 * 9, 8, 0.1f);
    /* a 1x1 convolution and a transposed one with kernel = stride (interleaved rows), residuals */
    float *res1 = rnd((size_t)cout * h * w, 9, 1), *resT = rnd((size_t)30 * 4 * h * w, 10, 1), *b64 = rnd(64, 11, 1);
    float *bl = rnd(out, 12, 1);
    /* few rows: column tiles 16 wide (float32 and bf16 panels) */
    const int nf = 13;
    g3d_nn_lin lf, lb;
    CHECK_OK(g3d_nn_lin_init(&lf, wl, G3D_DT_F32, bl, out, in, G3D_DT_F32));
    CHECK_OK(g3d_nn_lin_init(&lb, wl, G3D_DT_F32, bl, out, in, G3D_DT_BF16));
    float *ref[13] = {0}, *got[13];
    const int maxt = omp_get_max_threads();
    for (int t = 1; t <= 3; t++) {
        omp_set_num_threads(t);
        g3d_nn_conv c = g3d_nn_conv_make(cin, cout, 3, 1, 1, wc, NULL);
        got[0] = malloc(sizeof(float) * cout * h * w);
        CHECK_OK(g3d_nn_conv_forward(&c, x, h, w, got[0], NULL));
        got[1] = malloc(sizeof(float) * n * out);
        g3d_nn_linear(tok, n, in, wl, NULL, out, got[1]);
        got[2] = malloc(sizeof(float) * n * 64);
        CHECK_OK(g3d_nn_attention(qkv, n, 4, 16, 0.25f, got[2]));
        got[3] = malloc(sizeof(float) * cout * h * w);
        g3d_nn_groupnorm(got[0], cout, h * w, 5, g, g, 1e-5f, G3D_ACT_SILU, got[3]);
        got[4] = malloc(sizeof(float) * cin * h * w);
        g3d_nn_conv dw = g3d_nn_conv_make(cin, cin, 3, 1, 1, wc, NULL);
        dw.groups = cin;
        CHECK_OK(g3d_nn_conv_forward(&dw, x, h, w, got[4], NULL));
        got[5] = malloc(sizeof(float) * cout * h * w);
        CHECK_OK(g3d_nn_conv_prepare(&c));
        CHECK_OK(g3d_nn_conv_forward(&c, x, h, w, got[5], NULL));
        g3d_nn_conv_release(&c);
        got[6] = malloc(sizeof(float) * 70 * h * w);
        g3d_nn_conv c4 = g3d_nn_conv_make(64, 70, 3, 1, 1, w4, NULL);
        c4.wino_small = 1;
        CHECK(nn_wino_tile(&c4) == 2);
        c4.wino_small = 0;
        CHECK(nn_wino_tile(&c4) == 4);
        CHECK_OK(g3d_nn_conv_prepare(&c4));
        CHECK_OK(g3d_nn_conv_forward(&c4, x4, h, w, got[6], NULL));
        g3d_nn_conv_release(&c4);
        got[7] = malloc(sizeof(float) * cout * h * w);
        g3d_nn_conv c1 = g3d_nn_conv_make(cin, cout, 1, 1, 0, wc, g);
        g3d_nn_epi e1 = {.act = G3D_ACT_GELU, .scale = g, .res = res1};
        CHECK_OK(g3d_nn_conv_forward(&c1, x, h, w, got[7], &e1));
        got[8] = malloc(sizeof(float) * 30 * 4 * h * w);
        g3d_nn_conv ct = g3d_nn_conv_make(cin, 30, 2, 2, 0, wc, g);
        ct.transposed = 1;
        CHECK_OK(g3d_nn_conv_prepare(&ct));
        memcpy(got[8], resT, sizeof(float) * 30 * 4 * h * w);
        g3d_nn_epi eT = {.act = G3D_ACT_SILU, .res = got[8]};
        CHECK_OK(g3d_nn_conv_forward(&ct, x, h, w, got[8], &eT));
        g3d_nn_conv_release(&ct);
        /* short key set: every head of a few query blocks per task, the next block prefetched */
        got[9] = malloc(sizeof(float) * n * 64);
        g3d_nn_attn cross = {.nq = n, .nk = 77, .heads = 4, .hd = 16, .q = qkv, .k = qkv + 64, .v = qkv + 128,
                             .ldq = 192, .ldk = 192, .ldv = 192, .out = got[9], .scale = 0.25f};
        CHECK_OK(g3d_nn_attend(&cross));
        const g3d_nn_epi gelu = {.act = G3D_ACT_GELU};
        got[10] = malloc(sizeof(float) * nf * out);
        CHECK_OK(g3d_nn_lin_forward(&lf, tok, nf, 0, got[10], 0, &gelu));
        got[11] = malloc(sizeof(float) * nf * out);
        CHECK_OK(g3d_nn_lin_forward(&lb, tok, nf, 0, got[11], 0, NULL));
        /* 64 output channels: the last four rows of each tile in place with the two before */
        got[12] = malloc(sizeof(float) * 64 * h * w);
        g3d_nn_conv p64 = g3d_nn_conv_make(64, 64, 1, 1, 0, w4, b64);
        CHECK_OK(g3d_nn_conv_forward(&p64, x4, h, w, got[12], &gelu));
        const size_t sz[13] = {(size_t)cout * h * w,   (size_t)n * out,     (size_t)n * 64,     (size_t)cout * h * w,
                               (size_t)cin * h * w,    (size_t)cout * h * w, (size_t)70 * h * w, (size_t)cout * h * w,
                               (size_t)30 * 4 * h * w, (size_t)n * 64,      (size_t)nf * out,   (size_t)nf * out,
                               (size_t)64 * h * w};
        for (int i = 0; i < 13; i++) {
            if (t == 1) {
                ref[i] = got[i];
                continue;
            }
            CHECK_MSG(!memcmp(got[i], ref[i], sizeof(float) * sz[i]), "operator %d differs with %d threads", i, t);
            free(got[i]);
        }
    }
    omp_set_num_threads(maxt);
    for (int i = 0; i < 13; i++) free(ref[i]);
    g3d_nn_lin_free(&lf), g3d_nn_lin_free(&lb);
    free(x4), free(w4), free(res1), free(resT), free(b64), free(bl);
    free(x), free(wc), free(wl), free(tok), free(qkv), free(g);
}

TEST(resize_bilinear_against_reference)
{
    /* c, h, w -> oh, ow, align_corners: the DPT head's and MoGe's resizes, odd factors,
     * shrinking, identity, single pixels */
    static const int cases[][6] = {{3, 5, 7, 10, 14, 0},      {2, 5, 7, 10, 14, 1},  {4, 37, 37, 74, 74, 1},
                                   {2, 148, 148, 296, 296, 1}, {3, 74, 99, 518, 400, 1}, {3, 43, 29, 86, 58, 0},
                                   {1, 9, 13, 4, 5, 0},        {2, 9, 13, 4, 5, 1},   {5, 17, 40, 17, 40, 0},
                                   {2, 1, 1, 3, 4, 0},         {1, 6, 4, 1, 1, 1},    {2, 33, 21, 20, 35, 0}};
    const int maxt = omp_get_max_threads();
    for (int k = 0; k < (int)(sizeof cases / sizeof *cases); k++) {
        const int c = cases[k][0], h = cases[k][1], w = cases[k][2], oh = cases[k][3], ow = cases[k][4], ac = cases[k][5];
        const size_t n = (size_t)c * oh * ow;
        float *x = rnd((size_t)c * h * w, 500 + k, 1), *ref = malloc(sizeof(float) * n), *img = malloc(sizeof(float) * n);
        float *y[3];
        nn_ref_resize_bilinear(x, c, h, w, ref, oh, ow, ac);
        for (int ch = 0; ch < c; ch++)
            CHECK_OK(g3d_resize_buffer(x + (size_t)ch * h * w, w, h, 1, img + (size_t)ch * oh * ow, ow, oh,
                                       ac ? G3D_RESIZE_BILINEAR_AC : G3D_RESIZE_BILINEAR));
        for (int t = 0; t < 3; t++) {
            omp_set_num_threads(t + 1);
            y[t] = malloc(sizeof(float) * n);
            CHECK_OK(g3d_nn_resize_bilinear(x, c, h, w, y[t], oh, ow, ac));
        }
        omp_set_num_threads(maxt);
        double e = err(y[0], ref, n), ei = err(ref, img, n);
        CHECK_MSG(e < 1e-6 && ei < 1e-6, "%dx%d -> %dx%d ac %d: err %g (reference vs image resizer %g)", w, h, ow, oh,
                  ac, e, ei);
        CHECK_MSG(!memcmp(y[0], y[1], sizeof(float) * n) && !memcmp(y[0], y[2], sizeof(float) * n),
                  "%dx%d -> %dx%d: differs between thread counts", w, h, ow, oh);
        for (int t = 0; t < 3; t++) free(y[t]);
        free(x), free(ref), free(img);
    }
    float v = 1.0f, o = 0.0f;
    CHECK(g3d_nn_resize_bilinear(&v, 1, 0, 1, &o, 1, 1, 0) == G3D_ERR_ARG);
    CHECK(g3d_nn_resize_bilinear(&v, 1, 1, 1, &o, 1, -2, 1) == G3D_ERR_ARG);
    g3d_error_clear();
}

TEST(arena)
{
    g3d_nn_arena *a = g3d_nn_arena_new(1000);
    CHECK(a != NULL);
    float *p = g3d_nn_arena_floats(a, 10);
    CHECK(p && ((uintptr_t)p & 63) == 0);
    size_t m = g3d_nn_arena_mark(a);
    float *q = g3d_nn_arena_floats(a, 100);
    CHECK(q && ((uintptr_t)q & 63) == 0 && q >= p + 10);
    /* grows past the first chunk; earlier pointers stay valid */
    p[0] = 1.0f, q[99] = 2.0f;
    float *big = g3d_nn_arena_floats(a, 1 << 20);
    CHECK(big && ((uintptr_t)big & 63) == 0);
    big[(1 << 20) - 1] = 3.0f;
    CHECK(p[0] == 1.0f && q[99] == 2.0f);
    size_t peak = g3d_nn_arena_peak(a);
    CHECK(peak >= sizeof(float) * ((1 << 20) + 110));
    /* reset to a mark: the space after it is handed out again */
    g3d_nn_arena_reset(a, m);
    CHECK(g3d_nn_arena_floats(a, 100) == q);
    /* reset to 0 merges the chunks: a whole pass fits in one block */
    g3d_nn_arena_reset(a, 0);
    float *p2 = g3d_nn_arena_floats(a, 10), *b2 = g3d_nn_arena_floats(a, 1 << 20);
    CHECK(p2 && b2 && (char *)b2 - (char *)p2 < (ptrdiff_t)peak);
    CHECK(g3d_nn_arena_peak(a) == peak);
    g3d_error_clear();
    CHECK(g3d_nn_arena_floats(a, (size_t)1 << 62) == NULL && g3d_error_message()[0]);
    g3d_nn_arena_free(a);
    a = g3d_nn_arena_new(0);
    CHECK(a && g3d_nn_arena_floats(a, 0) != NULL);
    g3d_nn_arena_free(a);
}

int main(void)
{
    find_isas();
    printf("kernels: %s (testing %d instruction sets)\n", g3d_nn_isa_name(), nisa);
    RUN(matmul_shapes_and_transposes);
    RUN(transpose_tile_against_reference);
    RUN(kernel_groups_equal_single_calls);
    RUN(linear_epilogues_and_16bit_weights);
    RUN(conv_against_reference);
    RUN(conv_bad_configurations);
    RUN(attention_against_reference);
    RUN(activations_against_libm);
    RUN(norms_and_softmax_against_reference);
    RUN(fft_against_dft);
    RUN(independent_of_thread_count);
    RUN(resize_bilinear_against_reference);
    RUN(arena);
    g3d_nn_fft_forget();
    return test_summary();
}
