/* ControlNet against the official v1.1 code (tests/fixtures/make_sdcontrol_golden.py): the
 * tiny ControlNet in the published layout (control_model.* in a .pth) gives the official hint
 * features and residuals for an inpainting hint, and the tiny 9-channel SD 1.x inpainting UNet
 * with those residuals added gives ControlledUnetModel's output. Then the inpainting hint, the
 * ControlNet in the inpainting loop, the diffusers layout and the refusals. */
#include "golden.h"

#include "gen3d/sd.h"

static g3d_ckpt *g_act;

static void on_trace(void *ctx, const char *name, const float *x, int c, int h, int w)
{
    int *compared = ctx;
    if (!strcmp(name, "guided_hint") || !strncmp(name, "control", 7)) {
        golden_compare(g_act, name, x, (size_t)c * h * w);
        ++*compared;
    }
}

TEST(controlnet_matches_official)
{
    g3d_ckpt *cck = NULL, *uck = NULL;
    g3d_sd_controlnet *cn = NULL;
    g3d_sd_unet *unet = NULL;
    CHECK_OK(g3d_ckpt_open(test_fixture("sdcontrol_tiny.pth"), &cck));
    CHECK_OK(g3d_ckpt_open(test_fixture("sdinpaint_unet_tiny.safetensors"), &uck));
    if (cck) CHECK_OK(g3d_sd_controlnet_load(cck, NULL, &cn));
    if (uck) CHECK_OK(g3d_sd_unet_load(uck, NULL, &unet));
    float *x = golden_floats(g_act, "x", NULL), *t = golden_floats(g_act, "t", NULL), *ctx = golden_floats(g_act, "context", NULL);
    float *hint = golden_floats(g_act, "hint", NULL), *scale = golden_floats(g_act, "scale", NULL);
    if (cn && unet && x && t && ctx && hint && scale) {
        const g3d_sd_controlnet_config *c = g3d_sd_controlnet_get_config(cn);
        char d[768];
        printf("  %s\n", g3d_sd_controlnet_describe(c, d, sizeof d));
        CHECK(c->hint_ch == 3 && c->net.in_ch == 4 && c->net.model_ch == 32 && c->net.levels == 2 && c->net.mult[1] == 1 &&
              c->net.context_dim == 128 && c->net.heads == 8 && !strcmp(c->net.prefix, "control_model."));
        CHECK_OK(g3d_sd_controlnet_check(c, "sdcontrol_tiny.pth", g3d_sd_unet_get_config(unet)));
        size_t nr = g3d_sd_controlnet_residual_floats(cn, 8, 12);
        /* in0, in1: 32 channels at 8 x 12; in2 (the downsampling), in3 and the middle: 32 at 4 x 6 */
        CHECK(nr == (size_t)(2 * 32 * 96 + 3 * 32 * 24));
        float *res = malloc(sizeof(float) * nr), *eps = malloc(sizeof(float) * 4 * 96);
        int compared = 0;
        if (res && eps) {
            /* the ControlNet reads the first 4 of the UNet's 9 input channels */
            CHECK_OK(g3d_sd_controlnet_forward(cn, x, 8, 12, t[0], ctx, 77, hint, 1.0f, res, on_trace, &compared));
            CHECK(compared == 1 + 5);
            CHECK_OK(g3d_sd_controlnet_forward(cn, x, 8, 12, t[0], ctx, 77, hint, scale[0], res, NULL, NULL));
            CHECK_OK(g3d_sd_unet_forward_controlled(unet, x, 8, 12, t[0], ctx, 77, res, eps, NULL, NULL));
            golden_compare(g_act, "eps", eps, 4 * 96);
            CHECK_OK(g3d_sd_unet_forward_controlled(unet, x, 8, 12, t[0], ctx, 77, NULL, eps, NULL, NULL));
            golden_compare(g_act, "eps_plain", eps, 4 * 96);
        }
        free(res);
        free(eps);
    }
    free(x);
    free(t);
    free(ctx);
    free(hint);
    free(scale);
    g3d_sd_unet_free(unet);
    g3d_sd_controlnet_free(cn);
    g3d_ckpt_free(uck);
    g3d_ckpt_free(cck);
}

/* The official demo's hint from the golden's picture and mask; a prefill fills the hole instead. */
TEST(inpaint_hint)
{
    int w = 0, h = 0;
    float *rgb = golden_image(g_act, "image", &w, &h), *ref = golden_floats(g_act, "hint", NULL);
    const g3d_tensor_info *mt = g3d_ckpt_find(g_act, "mask");
    g3d_image img = {0}, mask = {0}, pre = {0}, hint = {0};
    if (!rgb || !ref || !mt) goto done;
    CHECK_OK(g3d_image_create(&img, w, h, 3));
    CHECK_OK(g3d_image_create(&mask, w, h, 1));
    CHECK_OK(g3d_image_create(&pre, w, h, 3));
    if (!img.data || !mask.data || !pre.data) goto done;
    memcpy(img.data, rgb, sizeof(float) * 3 * w * h);
    for (int i = 0; i < w * h; i++) mask.data[i] = ((const uint8_t *)mt->data)[i];
    for (size_t i = 0; i < g3d_image_size(&pre); i++) pre.data[i] = 0.25f;
    CHECK_OK(g3d_sd_inpaint_hint(&img, &mask, NULL, w, h, &hint));
    int same = hint.data != NULL;
    for (int i = 0; same && i < w * h; i++)
        for (int c = 0; c < 3; c++) same &= fabsf(hint.data[i * 3 + c] - ref[c * w * h + i]) < 1e-6f;
    CHECK(same);
    g3d_image_free(&hint);
    CHECK_OK(g3d_sd_inpaint_hint(&img, &mask, &pre, w, h, &hint));
    int ok = hint.data != NULL;
    for (int i = 0; ok && i < w * h; i++)
        for (int c = 0; c < 3; c++) ok &= hint.data[i * 3 + c] == (mask.data[i] > 0.5f ? 0.25f : img.data[i * 3 + c]);
    CHECK(ok);
    g3d_image_free(&hint);
    /* four times the size, nearest: pixel (x, y) comes from (x / 4, y / 4) */
    CHECK_OK(g3d_sd_inpaint_hint(&img, &mask, NULL, 4 * w, 4 * h, &hint));
    if (hint.data) CHECK(g3d_image_px(&hint, 4 * 41 + 3, 4 * 21 + 2)[1] == -1.0f && g3d_image_px(&hint, 5, 6)[2] == img.data[(1 * w + 1) * 3 + 2]);
    g3d_image_free(&hint);
    CHECK_FAILS(g3d_sd_inpaint_hint(&img, &img, NULL, w, h, &hint));
done:
    free(rgb);
    free(ref);
    g3d_image_free(&img);
    g3d_image_free(&mask);
    g3d_image_free(&pre);
}

static g3d_sd_paths paths(const char *controlnet)
{
    static char model[512], vae[512], text[512], tok[512], cn[512];
    snprintf(model, sizeof model, "%s", test_fixture("sdinpaint_unet_tiny.safetensors"));
    snprintf(vae, sizeof vae, "%s", test_fixture("sdunet_vae_tiny.safetensors"));
    snprintf(text, sizeof text, "%s", test_fixture("clip_sd1_tiny.ckpt"));
    snprintf(tok, sizeof tok, "%s", test_fixture("cliptok_merges.txt.gz"));
    snprintf(cn, sizeof cn, "%s", test_fixture(controlnet));
    return (g3d_sd_paths){.model = model, .vae = vae, .text_encoder = text, .tokenizer = tok, .prediction = -1, .controlnet = cn};
}

/* The ControlNet in the inpainting loop: scale 0 gives the plain model's picture exactly (the
 * ControlNet is not run), also after a shared holder let go of the model; scale 1
 * another one with the known pixels kept; the hint built inside is the helper's. */
TEST(controlnet_in_the_loop)
{
    g3d_sd_paths pp = paths("sdcontrol_tiny.pth");
    g3d_sd *m = NULL, *plain = NULL;
    CHECK_OK(g3d_sd_load(&pp, &m));
    pp.controlnet = NULL;
    CHECK_OK(g3d_sd_load(&pp, &plain));
    g3d_image img = {0}, mask = {0}, a = {0}, b = {0}, c = {0}, ctl = {0};
    if (!m || !plain) goto done;
    CHECK(g3d_sd_get_controlnet(m) && !g3d_sd_get_controlnet(plain));
    CHECK_OK(g3d_image_create(&img, 24, 16, 3));
    CHECK_OK(g3d_image_create(&mask, 24, 16, 1));
    if (!img.data || !mask.data) goto done;
    for (int y = 0; y < 16; y++)
        for (int x = 0; x < 24; x++) {
            float *px = g3d_image_px(&img, x, y);
            px[0] = x / 23.0f, px[1] = y / 15.0f, px[2] = 0.6f;
            *g3d_image_px(&mask, x, y) = x >= 8 && x < 20 && y >= 4;
        }
    g3d_sd_params p = g3d_sd_defaults();
    p.prompt = "a red chair";
    p.sampler.steps = 3;
    p.control_scale = 0.0f;
    CHECK_OK(g3d_sd_inpaint(m, &p, &img, &mask, &a));
    CHECK_OK(g3d_sd_inpaint(plain, &p, &img, &mask, &b));
    CHECK(a.data && b.data && !memcmp(a.data, b.data, sizeof(float) * g3d_image_size(&a)));
    g3d_image_free(&b);
    /* a second holder: the first free leaves the model whole, the last (at done) frees it */
    CHECK(g3d_sd_share(m) == m);
    g3d_sd_free(m);
    CHECK_OK(g3d_sd_inpaint(m, &p, &img, &mask, &b));
    CHECK(a.data && b.data && !memcmp(a.data, b.data, sizeof(float) * g3d_image_size(&a)));
    g3d_image_free(&a);
    g3d_image_free(&b);
    p.control_scale = 1.0f;
    CHECK_OK(g3d_sd_inpaint(m, &p, &img, &mask, &a));
    CHECK_OK(g3d_sd_inpaint(plain, &p, &img, &mask, &b));
    int kept = a.data && b.data, differs = 0;
    for (int i = 0; kept && i < 24 * 16; i++)
        for (int k = 0; k < 3; k++) {
            if (mask.data[i] > 0.5f) differs += a.data[i * 3 + k] != b.data[i * 3 + k];
            else kept &= a.data[i * 3 + k] == img.data[i * 3 + k];
        }
    CHECK(kept && differs > 0 && p.control == NULL);
    /* the same hint given: the same picture (8x the latent: the VAE's factor is 2 here, so 4x the picture) */
    CHECK_OK(g3d_sd_inpaint_hint(&img, &mask, NULL, 96, 64, &ctl));
    p.control = &ctl;
    CHECK_OK(g3d_sd_inpaint(m, &p, &img, &mask, &c));
    CHECK(a.data && c.data && !memcmp(a.data, c.data, sizeof(float) * g3d_image_size(&a)));
    g3d_image_free(&c);
    /* a control image for a plain model, one of the wrong size */
    CHECK_FAILS(g3d_sd_inpaint(plain, &p, &img, &mask, &c));
    p.control = &img;
    CHECK_FAILS(g3d_sd_inpaint(m, &p, &img, &mask, &c));
    CHECK(strstr(g3d_error_message(), "96x64") != NULL && c.data == NULL);
done:
    g3d_image_free(&a);
    g3d_image_free(&b);
    g3d_image_free(&ctl);
    g3d_image_free(&img);
    g3d_image_free(&mask);
    g3d_sd_free(m);
    g3d_sd_free(plain);
}

/* diffusers' ControlNetModel names for the fixture's shape (two levels, one res block each,
 * attention at level 0), prefix by prefix, and its res blocks' leaves. */
static const char *const DIFFUSERS[][2] = {
    {"time_embed.0.", "time_embedding.linear_1."}, {"time_embed.2.", "time_embedding.linear_2."}, {"input_blocks.0.0.", "conv_in."},
    {"input_blocks.1.0.", "down_blocks.0.resnets.0."}, {"input_blocks.1.1.", "down_blocks.0.attentions.0."},
    {"input_blocks.2.0.op.", "down_blocks.0.downsamplers.0.conv."}, {"input_blocks.3.0.", "down_blocks.1.resnets.0."},
    {"middle_block.0.", "mid_block.resnets.0."}, {"middle_block.1.", "mid_block.attentions.0."}, {"middle_block.2.", "mid_block.resnets.1."},
    {"input_hint_block.0.", "controlnet_cond_embedding.conv_in."}, {"input_hint_block.2.", "controlnet_cond_embedding.blocks.0."},
    {"input_hint_block.4.", "controlnet_cond_embedding.blocks.1."}, {"input_hint_block.6.", "controlnet_cond_embedding.blocks.2."},
    {"input_hint_block.8.", "controlnet_cond_embedding.blocks.3."}, {"input_hint_block.10.", "controlnet_cond_embedding.blocks.4."},
    {"input_hint_block.12.", "controlnet_cond_embedding.blocks.5."}, {"input_hint_block.14.", "controlnet_cond_embedding.conv_out."},
    {"zero_convs.0.0.", "controlnet_down_blocks.0."}, {"zero_convs.1.0.", "controlnet_down_blocks.1."},
    {"zero_convs.2.0.", "controlnet_down_blocks.2."}, {"zero_convs.3.0.", "controlnet_down_blocks.3."},
    {"middle_block_out.0.", "controlnet_mid_block."}};
static const char *const RES_LEAVES[][2] = {{"in_layers.0.", "norm1."}, {"in_layers.2.", "conv1."}, {"emb_layers.1.", "time_emb_proj."},
                                            {"out_layers.0.", "norm2."}, {"out_layers.3.", "conv2."}, {"skip_connection.", "conv_shortcut."}};

/* The fixture as a diffusers ControlNetModel folder gives the same residuals, bit for bit. */
TEST(diffusers_layout)
{
    g3d_ckpt *ck = NULL, *dck = NULL;
    CHECK_OK(g3d_ckpt_open(test_fixture("sdcontrol_tiny.pth"), &ck));
    if (!ck) return;
    char *dir = strdup(test_tmp("sd_controlnet_diffusers"));
    g3d_remove_tree(dir);
    CHECK_OK(g3d_mkdirs(dir));
    int64_t n = g3d_ckpt_count(ck), k = 0;
    g3d_tensor_out *t = calloc((size_t)n, sizeof *t);
    char(*names)[256] = calloc((size_t)n, sizeof *names);
    for (int64_t i = 0; t && names && i < n; i++) {
        const g3d_tensor_info *ti = g3d_ckpt_tensor(ck, i);
        const char *nm = ti->name + strlen("control_model.");
        for (size_t r = 0; r < sizeof DIFFUSERS / sizeof *DIFFUSERS; r++) {
            size_t len = strlen(DIFFUSERS[r][0]);
            if (strncmp(nm, DIFFUSERS[r][0], len)) continue;
            const char *leaf = nm + len, *to = "";
            for (size_t q = 0; strstr(DIFFUSERS[r][1], "resnets") && q < sizeof RES_LEAVES / sizeof *RES_LEAVES; q++)
                if (!strncmp(leaf, RES_LEAVES[q][0], strlen(RES_LEAVES[q][0]))) to = RES_LEAVES[q][1], leaf += strlen(RES_LEAVES[q][0]);
            snprintf(names[k], sizeof names[k], "%s%s%s", DIFFUSERS[r][1], to, leaf);
            t[k] = (g3d_tensor_out){.name = names[k], .dtype = ti->dtype, .ndim = ti->ndim, .data = ti->data};
            memcpy(t[k].shape, ti->shape, sizeof ti->shape);
            k++;
            break;
        }
    }
    CHECK(k == n);
    char *file = g3d_path_join(dir, "diffusion_pytorch_model.safetensors"), *cfg = g3d_path_join(dir, "config.json");
    CHECK_OK(g3d_safetensors_write(file, t, (int)k, NULL));
    const char *json = "{\"_class_name\": \"ControlNetModel\", \"attention_head_dim\": 8, \"cross_attention_dim\": 128, \"in_channels\": 4}";
    CHECK_OK(g3d_write_file_atomic(cfg, json, strlen(json)));
    CHECK_OK(g3d_ckpt_open(file, &dck));
    g3d_sd_controlnet *a = NULL, *b = NULL;
    if (dck) CHECK_OK(g3d_sd_controlnet_load(dck, json, &b));
    CHECK_OK(g3d_sd_controlnet_load(ck, NULL, &a));
    float *x = golden_floats(g_act, "x", NULL), *ts = golden_floats(g_act, "t", NULL), *ctx = golden_floats(g_act, "context", NULL);
    float *hint = golden_floats(g_act, "hint", NULL);
    if (a && b && x && ts && ctx && hint) {
        CHECK(g3d_sd_controlnet_get_config(b)->net.diffusers && g3d_sd_controlnet_get_config(b)->net.heads == 8);
        size_t nr = g3d_sd_controlnet_residual_floats(a, 8, 12);
        float *ra = malloc(sizeof(float) * nr), *rb = malloc(sizeof(float) * nr);
        if (ra && rb) {
            CHECK_OK(g3d_sd_controlnet_forward(a, x, 8, 12, ts[0], ctx, 77, hint, 1.0f, ra, NULL, NULL));
            CHECK_OK(g3d_sd_controlnet_forward(b, x, 8, 12, ts[0], ctx, 77, hint, 1.0f, rb, NULL, NULL));
            CHECK(!memcmp(ra, rb, sizeof(float) * nr));
        }
        free(ra);
        free(rb);
    }
    /* the folder through the pipeline's loader */
    g3d_sd_paths pp = paths("sdcontrol_tiny.pth");
    pp.controlnet = dir;
    g3d_sd *m = NULL;
    CHECK_OK(g3d_sd_load(&pp, &m));
    CHECK(m && g3d_sd_get_controlnet(m) && g3d_sd_controlnet_get_config(g3d_sd_get_controlnet(m))->net.diffusers);
    g3d_sd_free(m);
    free(x);
    free(ts);
    free(ctx);
    free(hint);
    g3d_sd_controlnet_free(a);
    g3d_sd_controlnet_free(b);
    g3d_ckpt_free(dck);
    g3d_ckpt_free(ck);
    free(file);
    free(cfg);
    free(t);
    free(names);
    free(dir);
}

TEST(refusals)
{
    /* a ControlNet for another UNet: the context-48 SD 1.x fixture, named with both sets of figures */
    g3d_ckpt *cck = NULL, *uck = NULL;
    g3d_sd_controlnet_config cc;
    g3d_sd_unet_config uc;
    CHECK_OK(g3d_ckpt_open(test_fixture("sdcontrol_tiny.pth"), &cck));
    CHECK_OK(g3d_ckpt_open(test_fixture("sdunet_sd1_tiny.ckpt"), &uck));
    if (cck && uck) {
        CHECK_OK(g3d_sd_controlnet_probe(cck, NULL, &cc));
        CHECK_OK(g3d_sd_unet_probe(uck, NULL, &uc));
        CHECK_FAILS(g3d_sd_controlnet_check(&cc, "cn.pth", &uc));
        printf("  %s\n", g3d_error_message());
        CHECK(!strncmp(g3d_error_message(), "cn.pth: ", 8) && strstr(g3d_error_message(), "context 128") &&
              strstr(g3d_error_message(), "context 48"));
        /* a UNet is not a ControlNet, nor the other way round */
        CHECK_FAILS(g3d_sd_controlnet_probe(uck, NULL, &cc));
        CHECK(strstr(g3d_error_message(), "not a ControlNet") != NULL);
        CHECK_FAILS(g3d_sd_unet_probe(cck, NULL, &uc));
    }
    g3d_ckpt_free(cck);
    g3d_ckpt_free(uck);
    g3d_sd *m = NULL;
    g3d_sd_paths pp = paths("sdunet_vae_tiny.safetensors");
    CHECK_FAILS(g3d_sd_load(&pp, &m));
    /* the text-to-image golden's UNet has multipliers 1/2 */
    pp = paths("sdcontrol_tiny.pth");
    char model[512];
    snprintf(model, sizeof model, "%s", test_fixture("sdpipe_unet_tiny.safetensors"));
    pp.model = model;
    CHECK_FAILS(g3d_sd_load(&pp, &m));
    CHECK(strstr(g3d_error_message(), "multipliers 1/1") && strstr(g3d_error_message(), "multipliers 1/2"));
    CHECK(m == NULL);
}

int main(void)
{
    CHECK_OK(g3d_ckpt_open(test_fixture("sdcontrol_golden.safetensors"), &g_act));
    if (g_act) {
        RUN(controlnet_matches_official);
        RUN(inpaint_hint);
        RUN(controlnet_in_the_loop);
        RUN(diffusers_layout);
        RUN(refusals);
    }
    g3d_ckpt_free(g_act);
    return test_summary();
}
