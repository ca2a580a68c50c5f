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

static void check_unet(g3d_sd_unet *m, const char *key, int expect_blocks)
{
    const g3d_sd_unet_config *c = g3d_sd_unet_get_config(m);
    char name[64];
    size_t nctx = 0;
    snprintf(name, sizeof name, "%s.x", key);
    float *x = golden_floats(g_act, name, NULL);
    snprintf(name, sizeof name, "%s.t", key);
    float *t = golden_floats(g_act, name, NULL);
    snprintf(name, sizeof name, "%s.context", key);
    float *ctx = golden_floats(g_act, name, &nctx);
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

TEST(vae)
{
    g3d_ckpt *ck = NULL;
    g3d_sd_vae *m = NULL;
    CHECK_OK(g3d_ckpt_open(test_fixture("sdunet_vae_tiny.safetensors"), &ck));
    if (ck) CHECK_OK(g3d_sd_vae_load(ck, &m));
    if (!m) {
        g3d_ckpt_free(ck);
        return;
    }
    const g3d_sd_vae_config *c = g3d_sd_vae_get_config(m);
    CHECK(c->ch == 32 && c->levels == 2 && c->mult[1] == 2 && c->nres == 1 && c->z_ch == 4 && c->factor == 2 &&
          !strcmp(c->prefix, "first_stage_model."));
    float *img = golden_floats(g_act, "vae.image", NULL), *z = golden_floats(g_act, "vae.z", NULL);
    float *mom = malloc(sizeof(float) * 8 * 8 * 12), *rgb = malloc(sizeof(float) * 3 * 16 * 24);
    trace_ctx tc = {"vae", 0};
    if (img && z && mom && rgb) {
        CHECK_OK(g3d_sd_vae_encode(m, img, 16, 24, mom, on_trace, &tc));
        CHECK(tc.compared == 2);
        /* the decoder from the official latent (the posterior's mode) */
        tc.compared = 0;
        CHECK_OK(g3d_sd_vae_decode(m, z, 8, 12, rgb, on_trace, &tc));
        golden_compare(g_act, "vae.decoded", rgb, 3 * 16 * 24);
        CHECK(tc.compared == 4);
        CHECK_FAILS(g3d_sd_vae_encode(m, img, 15, 24, mom, NULL, NULL));
        /* tiled decoding: one tile covering the latent is the plain decoder; with 4 x 4 tiles
         * sharing 2 latent pixels, a corner only one tile covers is that tile's own decoding */
        float *t = malloc(sizeof(float) * 3 * 16 * 24), *zt = malloc(sizeof(float) * 4 * 4 * 4), *one = malloc(sizeof(float) * 3 * 8 * 8);
        CHECK_OK(g3d_sd_vae_decode_tiled(m, z, 8, 12, 16, 4, t));
        CHECK(t && !memcmp(t, rgb, sizeof(float) * 3 * 16 * 24));
        CHECK_OK(g3d_sd_vae_decode_tiled(m, z, 8, 12, 4, 2, t));
        for (int c = 0; c < 4; c++)
            for (int y = 0; y < 4; y++) memcpy(zt + (c * 4 + y) * 4, z + (c * 8 + y) * 12, sizeof(float) * 4);
        CHECK_OK(g3d_sd_vae_decode(m, zt, 4, 4, one, NULL, NULL));
        int corner = 1;
        for (int c = 0; c < 3; c++)
            for (int y = 0; y < 4; y++)
                for (int x = 0; x < 4; x++) corner &= fabsf(t[(c * 16 + y) * 24 + x] - one[(c * 8 + y) * 8 + x]) < 1e-6f;
        CHECK(corner);
        CHECK_FAILS(g3d_sd_vae_decode_tiled(m, z, 8, 12, 4, 4, t));
        /* a latent whose maps outgrow the arena's first chunk (the decoder moves each map down) */
        float *zb = malloc(sizeof(float) * 4 * 48 * 48), *big = malloc(sizeof(float) * 3 * 96 * 96);
        for (int i = 0; zb && i < 4 * 48 * 48; i++) zb[i] = z[i % (4 * 8 * 12)];
        if (zb && big) CHECK_OK(g3d_sd_vae_decode(m, zb, 48, 48, big, NULL, NULL));
        int finite = 1;
        for (int i = 0; big && i < 3 * 96 * 96; i++) finite &= isfinite(big[i]);
        CHECK(finite);
        free(zb);
        free(big);
        free(t);
        free(zt);
        free(one);
    }
    free(img);
    free(z);
    free(mom);
    free(rgb);
    g3d_sd_vae_free(m);
    g3d_ckpt_free(ck);
}

TEST(bad_input)
{
    g3d_ckpt *ck = NULL;
    g3d_sd_unet *m = NULL;
    g3d_sd_vae *v = NULL;
    /* another model: refused, naming what a Stable Diffusion file would hold */
    CHECK_OK(g3d_ckpt_open(test_fixture("dav2_tiny.pth"), &ck));
    if (ck) {
        CHECK_FAILS(g3d_sd_unet_load(ck, NULL, &m));
        CHECK(strstr(g3d_error_message(), "input_blocks.0.0.weight") != NULL);
        CHECK_FAILS(g3d_sd_vae_load(ck, &v));
        CHECK(strstr(g3d_error_message(), "encoder.conv_in.weight") != NULL);
    }
    g3d_ckpt_free(ck);
    ck = NULL;
    /* a tensor missing deep inside: named */
    unsigned char *file = NULL;
    size_t n;
    CHECK_OK(g3d_read_file(test_fixture("sdunet_sd2_tiny.safetensors"), 4 << 20, &file, &n));
    const char *gone = "model.diffusion_model.output_blocks.4.1.transformer_blocks.0.attn2.to_v.weight";
    unsigned char *bad = file ? golden_edit_safetensors(file, n, gone) : NULL;
    if (bad) CHECK_OK(g3d_ckpt_open_memory(bad, n, "edited.safetensors", &ck));
    if (ck) {
        CHECK_FAILS(g3d_sd_unet_load(ck, "num_head_channels: 16", &m));
        CHECK(strstr(g3d_error_message(), gone) != NULL);
        /* a yaml that contradicts the tensors */
        CHECK_FAILS(g3d_sd_unet_probe(ck, "in_channels: 4\nnum_head_channels: 16\n", &(g3d_sd_unet_config){0}));
    }
    g3d_ckpt_free(ck);
    free(bad);
    free(file);
    CHECK(m == NULL && v == NULL);
    /* latent sizes the levels cannot halve */
    CHECK_OK(g3d_ckpt_open(test_fixture("sdunet_sd1_tiny.ckpt"), &ck));
    if (ck) CHECK_OK(g3d_sd_unet_load(ck, NULL, &m));
    if (m) {
        float x[4 * 6 * 6] = {0}, ctx[48] = {0}, out[4 * 6 * 6];
        CHECK_FAILS(g3d_sd_unet_forward(m, x, 6, 6, 1.0f, ctx, 1, out, NULL, NULL));
    }
    g3d_sd_unet_free(m);
    g3d_ckpt_free(ck);
}

int main(void)
{
    CHECK_OK(g3d_ckpt_open(test_fixture("sdunet_tiny_golden.safetensors"), &g_act));
    if (g_act) {
        RUN(sd1_unet);
        RUN(sd2_inpainting_unet);
        RUN(vae);
        RUN(bad_input);
    }
    g3d_ckpt_free(g_act);
    return test_summary();
}
