/* The layer library against PyTorch 1.13 (tests/fixtures/make_nn_layers.py): every operator of
 * gen3d/nn.h on small odd-sized inputs, every configuration the project's models use.
 * Tolerance: relative L2 error 1e-5 (float32 sums taken in another order than PyTorch's). */
#include "gen3d/ckpt.h"
#include "gen3d/nn.h"
#include "testutil.h"

static const char *FIX = G3D_SOURCE_DIR "/tests/fixtures/nn_layers.safetensors";
static g3d_ckpt *ck;

static float *get(const char *name, int64_t *numel)
{
    const g3d_tensor_info *ti = g3d_ckpt_find(ck, name);
    if (!ti) {
        printf("  fixture tensor %s missing\n", name);
        return NULL;
    }
    float *p = NULL;
    if (g3d_ckpt_read_alloc(ck, name, 0, NULL, &p) != G3D_OK) return NULL;
    if (numel) *numel = ti->numel;
    return p;
}

static const int64_t *shape(const char *name) { return g3d_ckpt_find(ck, name)->shape; }

/* A layer's "<name>_w" and "<name>_b"; returns the weight's shape. */
static const int64_t *get_layer(const char *name, float **w, float **b)
{
    char wn[64], bn[64];
    snprintf(wn, sizeof wn, "%s_w", name);
    snprintf(bn, sizeof bn, "%s_b", name);
    *w = get(wn, NULL), *b = get(bn, NULL);
    return shape(wn);
}

static void compare(const char *name, const float *got, int64_t n)
{
    int64_t nref = 0;
    float *ref = get(name, &nref);
    CHECK_MSG(ref && nref == n, "%s: %lld values, fixture has %lld", name, (long long)n, (long long)nref);
    if (!ref || nref != n) {
        free(ref);
        return;
    }
    double e = test_rel_l2(got, ref, n);
    printf("  %-16s rel L2 %.3g\n", name, e);
    CHECK_MSG(e <= 1e-5, "%s: rel L2 %g", name, e);
    free(ref);
}

TEST(conv2d)
{
    static const struct {
        const char *name;
        int k, s, p, d, g;
        g3d_nn_padmode mode;
    } cases[] = {
        {"c3", 3, 1, 1, 1, 1, G3D_PAD_ZEROS},         {"c3s2_reflect", 3, 2, 1, 1, 1, G3D_PAD_REFLECT},
        {"c3_replicate", 3, 1, 1, 1, 1, G3D_PAD_REPLICATE}, {"c3d2", 3, 1, 2, 2, 1, G3D_PAD_ZEROS},
        {"c5s2", 5, 2, 2, 1, 1, G3D_PAD_ZEROS},       {"c7_reflect", 7, 1, 3, 1, 1, G3D_PAD_REFLECT},
        {"c1", 1, 1, 0, 1, 1, G3D_PAD_ZEROS},         {"c1s2", 1, 2, 0, 1, 1, G3D_PAD_ZEROS},
        {"dw3", 3, 1, 1, 1, 6, G3D_PAD_ZEROS},        {"dw3s2", 3, 2, 1, 1, 6, G3D_PAD_REPLICATE},
        {"g2", 3, 1, 1, 1, 2, G3D_PAD_ZEROS},         {"g3", 3, 2, 1, 1, 3, G3D_PAD_REFLECT},
    };
    float *x = get("x", NULL);
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        float *w, *b;
        const int cout = (int)get_layer(cases[i].name, &w, &b)[0];
        g3d_nn_conv c = g3d_nn_conv_make(6, cout, cases[i].k, cases[i].s, cases[i].p, w, b);
        c.dilation = cases[i].d, c.groups = cases[i].g, c.pad_mode = cases[i].mode;
        int ho, wo;
        CHECK_OK(g3d_nn_conv_out_size(&c, 9, 11, &ho, &wo));
        float *y = malloc(sizeof(float) * cout * ho * wo);
        CHECK_OK(g3d_nn_conv_forward(&c, x, 9, 11, y, NULL));
        compare(cases[i].name, y, (int64_t)cout * ho * wo);
        free(w), free(b), free(y);
    }
    /* prepared: Winograd F(2x2, 3x3) */
    float *x16 = get("x16", NULL), y16[18 * 9 * 11];
    static const char *const wn16[] = {"w3", "w3_reflect"};
    for (int i = 0; i < 2; i++) {
        float *w, *b;
        get_layer(wn16[i], &w, &b);
        g3d_nn_conv c = g3d_nn_conv_make(24, 18, 3, 1, 1, w, b);
        c.pad_mode = i ? G3D_PAD_REFLECT : G3D_PAD_ZEROS;
        CHECK_OK(g3d_nn_conv_prepare(&c));
        CHECK(c.prep != NULL);
        CHECK_OK(g3d_nn_conv_forward(&c, x16, 9, 11, y16, NULL));
        compare(wn16[i], y16, 18 * 9 * 11);
        g3d_nn_conv_release(&c);
        free(w), free(b);
    }
    free(x16);
    /* kernel 3 x 1, padding (1, 0), no bias */
    float *w = get("k31_w", NULL), y[5 * 9 * 11];
    g3d_nn_conv c = {.cin = 6, .cout = 5, .kh = 3, .kw = 1, .pad_h = 1, .w = w};
    CHECK_OK(g3d_nn_conv_forward(&c, x, 9, 11, y, NULL));
    compare("k31", y, 5 * 9 * 11);
    free(w), free(x);
}

TEST(conv_transpose2d)
{
    static const struct {
        const char *name;
        int k, s, p, op, d;
    } cases[] = {{"t3s2", 3, 2, 1, 1, 1},   {"t2s2", 2, 2, 0, 0, 1},   {"t4s4", 4, 4, 0, 0, 1}, {"t3s1", 3, 1, 1, 0, 1},
                 {"t4s2p1", 4, 2, 1, 0, 1}, {"t3s2d2", 3, 2, 2, 1, 2}, {"t1s3", 1, 3, 0, 2, 1}};
    float *x = get("xt", NULL);
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        float *w, *b;
        const int cout = (int)get_layer(cases[i].name, &w, &b)[1];
        g3d_nn_conv c = g3d_nn_conv_make(6, cout, cases[i].k, cases[i].s, cases[i].p, w, b);
        c.transposed = 1, c.output_padding = cases[i].op, c.dilation = cases[i].d;
        int ho, wo;
        CHECK_OK(g3d_nn_conv_out_size(&c, 5, 7, &ho, &wo));
        CHECK(ho == (int)shape(cases[i].name)[1] && wo == (int)shape(cases[i].name)[2]);
        float *y = malloc(sizeof(float) * cout * ho * wo);
        /* once building the phase kernels per call, once prepared */
        CHECK_OK(g3d_nn_conv_forward(&c, x, 5, 7, y, NULL));
        compare(cases[i].name, y, (int64_t)cout * ho * wo);
        CHECK_OK(g3d_nn_conv_prepare(&c));
        memset(y, 0, sizeof(float) * cout * ho * wo);
        CHECK_OK(g3d_nn_conv_forward(&c, x, 5, 7, y, NULL));
        compare(cases[i].name, y, (int64_t)cout * ho * wo);
        g3d_nn_conv_release(&c);
        free(w), free(b), free(y);
    }
    free(x);
}

TEST(batchnorm_folding)
{
    float *x = get("x", NULL), *w = get("bn_w", NULL), *g = get("bn_gamma", NULL), *be = get("bn_beta", NULL),
          *m = get("bn_mean", NULL), *v = get("bn_var", NULL), bias[4] = {0}, y[4 * 9 * 11];
    g3d_nn_fold_bn(w, bias, 1, 4, 6 * 9, g, be, m, v, 1e-5f);
    g3d_nn_conv c = g3d_nn_conv_make(6, 4, 3, 1, 1, w, bias);
    CHECK_OK(g3d_nn_conv_forward(&c, x, 9, 11, y, NULL));
    compare("bn", y, 4 * 9 * 11);
    free(x), free(w), free(g), free(be), free(m), free(v);
}

TEST(linear_and_activations)
{
    float *x = get("tok", NULL), *w = get("lin_w", NULL), *b = get("lin_b", NULL), *res = get("res", NULL),
          *gam = get("gamma", NULL), y[37 * 70];
    g3d_nn_lin L;
    CHECK_OK(g3d_nn_lin_init(&L, w, G3D_DT_F32, b, 70, 45, G3D_DT_F32));
    static const struct {
        const char *name;
        g3d_act act;
    } acts[] = {{"lin", G3D_ACT_NONE},          {"lin_gelu", G3D_ACT_GELU},  {"lin_gelu_tanh", G3D_ACT_GELU_TANH},
                {"lin_quick_gelu", G3D_ACT_QUICK_GELU}, {"lin_silu", G3D_ACT_SILU},  {"lin_relu", G3D_ACT_RELU},
                {"lin_sigmoid", G3D_ACT_SIGMOID}, {"lin_tanh", G3D_ACT_TANH}};
    for (size_t i = 0; i < sizeof acts / sizeof *acts; i++) {
        /* fused in the product's epilogue, and as a separate pass */
        g3d_nn_epi e = {.act = acts[i].act};
        CHECK_OK(g3d_nn_lin_forward(&L, x, 37, 0, y, 0, &e));
        compare(acts[i].name, y, 37 * 70);
        g3d_nn_linear(x, 37, 45, w, b, 70, y);
        g3d_nn_activate(acts[i].act, y, 37 * 70);
        compare(acts[i].name, y, 37 * 70);
    }
    /* y = res + gamma * gelu(x W^T + b), in place on the residual */
    g3d_nn_epi e = {.act = G3D_ACT_GELU, .scale = gam, .res = res};
    CHECK_OK(g3d_nn_lin_forward(&L, x, 37, 0, res, 0, &e));
    compare("lin_ls_res", res, 37 * 70);
    g3d_nn_lin_free(&L);
    float *gin = get("geglu_in", NULL), gy[37 * 24];
    g3d_nn_geglu(gin, 37, 24, gy);
    compare("geglu", gy, 37 * 24);
    g3d_nn_linear(x, 37, 45, w, b, 70, y);
    g3d_nn_softmax(y, 37, 70);
    compare("softmax", y, 37 * 70);
    free(x), free(w), free(b), free(res), free(gam), free(gin);
}

TEST(normalisation)
{
    float *fm = get("fm", NULL), *g = get("g64", NULL), *b = get("b64", NULL), y[64 * 30];
    g3d_nn_groupnorm(fm, 64, 30, 32, g, b, 1e-6f, G3D_ACT_NONE, y);
    compare("groupnorm", y, 64 * 30);
    memcpy(y, fm, sizeof y);
    g3d_nn_groupnorm(y, 64, 30, 32, g, b, 1e-5f, G3D_ACT_SILU, y); /* in place */
    compare("groupnorm_silu", y, 64 * 30);
    g3d_nn_layernorm2d(fm, 64, 30, g, b, 1e-6f, y);
    compare("layernorm2d", y, 64 * 30);
    float *tok = get("tok", NULL), *lg = get("ln_g", NULL), *lb = get("ln_b", NULL), t[37 * 45];
    g3d_nn_layernorm(tok, 37, 45, lg, lb, 1e-5f, t);
    compare("layernorm", t, 37 * 45);
    free(fm), free(g), free(b), free(tok), free(lg), free(lb);
}

TEST(attention)
{
    float *q = get("aq", NULL), *k = get("ak", NULL), *v = get("av", NULL), out[13 * 12];
    g3d_nn_attn a = {.nq = 13, .nk = 7, .heads = 3, .hd = 5, .hdv = 4, .q = q, .k = k, .v = v, .out = out,
                     .scale = 1.0f / sqrtf(5.0f)};
    CHECK_OK(g3d_nn_attend(&a));
    compare("cross", out, 13 * 12);
    free(q), free(k), free(v);

    float *qkv = get("qkv9", NULL), o9[9 * 16];
    a = (g3d_nn_attn){.nq = 9, .nk = 9, .heads = 2, .hd = 8, .q = qkv, .k = qkv + 16, .v = qkv + 32, .ldq = 48,
                      .ldk = 48, .ldv = 48, .out = o9, .scale = 1.0f / sqrtf(8.0f), .causal = 1};
    CHECK_OK(g3d_nn_attend(&a));
    compare("causal", o9, 9 * 16);
    float *dense = get("dense_bias", NULL);
    g3d_nn_bias_dense bd = {dense, 81, 9};
    a.causal = 0, a.bias = g3d_nn_bias_dense_fn, a.bias_ctx = &bd;
    CHECK_OK(g3d_nn_attend(&a));
    compare("biased", o9, 9 * 16);
    free(qkv), free(dense);

    float *big = get("qkv300", NULL), *o300 = malloc(sizeof(float) * 300 * 16);
    CHECK_OK(g3d_nn_attention(big, 300, 2, 8, 1.0f / sqrtf(8.0f), o300));
    compare("self300", o300, 300 * 16);
    a = (g3d_nn_attn){.nq = 300, .nk = 300, .heads = 2, .hd = 8, .q = big, .k = big + 16, .v = big + 32, .ldq = 48,
                      .ldk = 48, .ldv = 48, .out = o300, .scale = 1.0f / sqrtf(8.0f), .causal = 1};
    CHECK_OK(g3d_nn_attend(&a));
    compare("causal300", o300, 300 * 16);
    free(big), free(o300);

    /* SAM: decomposed relative positions, 4 x 5 grid, 2 heads of 6 */
    float *rq = get("rq", NULL), *rk = get("rk", NULL), *rv = get("rv", NULL), *relh = get("rel_h", NULL),
          *relw = get("rel_w", NULL), rh[2 * 20 * 4], rw[2 * 20 * 5], o20[20 * 12];
    CHECK_OK(g3d_nn_relpos_tables(rq, 12, 2, 6, 4, 5, 4, 5, relh, relw, rh, rw));
    g3d_nn_bias_relpos rp = {rh, rw, 20, 4, 5, 2};
    a = (g3d_nn_attn){.nq = 20, .nk = 20, .heads = 2, .hd = 6, .q = rq, .k = rk, .v = rv, .out = o20,
                      .scale = 1.0f / sqrtf(6.0f), .bias = g3d_nn_bias_relpos_fn, .bias_ctx = &rp};
    CHECK_OK(g3d_nn_attend(&a));
    compare("relpos", o20, 20 * 12);
    CHECK_FAILS(g3d_nn_relpos_tables(rq, 12, 2, 6, 4, 5, 5, 4, relh, relw, rh, rw));
    free(rq), free(rk), free(rv), free(relh), free(relw);
}

TEST(resampling_padding_embedding)
{
    float *s = get("small", NULL), y[3 * 8 * 10];
    g3d_nn_upsample2x(s, 3, 4, 5, y);
    compare("up2", y, 3 * 8 * 10);
    static const struct {
        const char *name;
        g3d_nn_padmode mode;
    } pads[] = {{"pad_reflect", G3D_PAD_REFLECT},
                {"pad_replicate", G3D_PAD_REPLICATE},
                {"pad_zeros", G3D_PAD_ZEROS},
                {"pad_symmetric", G3D_PAD_SYMMETRIC}};
    for (int i = 0; i < 4; i++) {
        float p[3 * 7 * 8];
        CHECK_OK(g3d_nn_pad2d(s, 3, 4, 5, 3, 0, 2, 1, pads[i].mode, p));
        compare(pads[i].name, p, 3 * 7 * 8);
    }
    float p[3 * 20 * 20];
    CHECK_FAILS(g3d_nn_pad2d(s, 3, 4, 5, 4, 0, 0, 0, G3D_PAD_REFLECT, p));
    CHECK_FAILS(g3d_nn_pad2d(s, 3, 4, 5, 0, 0, 6, 0, G3D_PAD_SYMMETRIC, p));
    CHECK_FAILS(g3d_nn_pad2d(s, 3, 4, 5, -1, 0, 0, 0, G3D_PAD_ZEROS, p));
    float e[320];
    g3d_nn_timestep_embedding(981.0f, 320, 10000.0f, e);
    compare("temb320", e, 320);
    g3d_nn_timestep_embedding(3.0f, 7, 10000.0f, e);
    compare("temb7", e, 7);
    free(s);
}

TEST(fft)
{
    static const int sizes[][2] = {{8, 12}, {7, 9}, {5, 16}, {6, 1}};
    for (int i = 0; i < 4; i++) {
        int h = sizes[i][0], w = sizes[i][1], wf = w / 2 + 1;
        char name[64];
        snprintf(name, sizeof name, "fft_x_%dx%d", h, w);
        float *x = get(name, NULL), *y = malloc(sizeof(float) * 3 * 2 * h * wf), *back = malloc(sizeof(float) * 3 * h * w);
        CHECK_OK(g3d_nn_rfft2(x, 3, h, w, y));
        snprintf(name, sizeof name, "rfft_%dx%d", h, w);
        compare(name, y, 3 * 2 * h * wf);
        /* the round trip returns the input */
        CHECK_OK(g3d_nn_irfft2(y, 3, h, w, back));
        CHECK(test_rel_l2(back, x, 3 * h * w) < 1e-6);
        snprintf(name, sizeof name, "spec_%dx%d", h, w);
        float *spec = get(name, NULL);
        CHECK_OK(g3d_nn_irfft2(spec, 3, h, w, back));
        snprintf(name, sizeof name, "irfft_%dx%d", h, w);
        compare(name, back, 3 * h * w);
        free(x), free(y), free(back), free(spec);
    }
    CHECK_FAILS(g3d_nn_rfft2(NULL, 1, 0, 4, NULL));
    g3d_nn_fft_forget();
}

int main(void)
{
    if (g3d_ckpt_open(FIX, &ck) != G3D_OK) {
        printf("cannot open %s: %s\n", FIX, g3d_error_message());
        return 1;
    }
    RUN(conv2d);
    RUN(conv_transpose2d);
    RUN(batchnorm_folding);
    RUN(linear_and_activations);
    RUN(normalisation);
    RUN(attention);
    RUN(resampling_padding_embedding);
    RUN(fft);
    g3d_ckpt_free(ck);
    return test_summary();
}
