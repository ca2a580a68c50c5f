/* The text-to-image loop against the official pipeline (tests/fixtures/make_sdpipe_golden.py):
 * the tiny CLIP text encoder, a tiny SD 1.x UNet and the tiny VAE, DDIM 10 steps with guidance
 * 7.5 from the recorded initial noise, down to the 8-bit picture (the same seed giving the same
 * bytes is checked by test_cli_sd.sh). Then inpainting (a text-to-
 * image model: latent blending, the known pixels kept), the inpainter plug-in, refusals. */
#include "golden.h"

#include "gen3d/npy.h"
#include "gen3d/sd.h"

#include <cjson/cJSON.h>

static g3d_sd *g_sd;
static const char *g_prompt;

static const g3d_sd_paths *paths(void)
{
    static char model[512], vae[512], text[512], tok[512];
    snprintf(model, sizeof model, "%s", test_fixture("sdpipe_unet_tiny.safetensors"));
    snprintf(vae, sizeof vae, "%s", test_fixture("sdunet_vae_tiny.safetensors"));
    snprintf(text, sizeof text, "%s", test_fixture("clip_sd1_tiny.ckpt"));
    snprintf(tok, sizeof tok, "%s", test_fixture("cliptok_merges.txt.gz"));
    static g3d_sd_paths p;
    p = (g3d_sd_paths){.model = model, .vae = vae, .text_encoder = text, .tokenizer = tok, .prediction = -1};
    return &p;
}

static int steps_seen;
static int count_steps(void *user, const char *stage, int64_t step, int64_t total, const char *info)
{
    (void)user, (void)info;
    CHECK(!strcmp(stage, "denoise") && step == steps_seen + 1 && total == 10);
    steps_seen = (int)step;
    return 0;
}

TEST(txt2img_matches_official)
{
    g3d_ckpt *act = NULL;
    g3d_array noise = {0};
    CHECK_OK(g3d_ckpt_open(test_fixture("sdpipe_golden.safetensors"), &act));
    CHECK_OK(g3d_npy_load(test_fixture("sdpipe_noise.npy"), &noise));
    if (!act || !noise.data) goto done;
    g3d_sd_params p = g3d_sd_defaults();
    p.prompt = g_prompt;
    p.width = 24;
    p.height = 16;
    p.sampler.steps = 10;
    p.noise = noise.data;
    p.progress = (g3d_progress){count_steps, NULL};
    g3d_image img = {0};
    CHECK_OK(g3d_sd_txt2img(g_sd, &p, &img));
    CHECK(steps_seen == 10 && p.truncated == 0);
    const g3d_tensor_info *ref = g3d_ckpt_find(act, "image");
    float *dec = NULL;
    CHECK_OK(g3d_ckpt_read_alloc(act, "decoded", 0, NULL, &dec));
    if (img.data && ref && dec && ref->numel == 16 * 24 * 3) {
        const uint8_t *u8 = ref->data;
        double maxd = 0;
        int off = 0;
        for (int i = 0; i < 16 * 24; i++)
            for (int c = 0; c < 3; c++) {
                float want = (dec[c * 16 * 24 + i] + 1) / 2;
                want = want < 0 ? 0 : want > 1 ? 1 : want;
                float got = img.data[i * 3 + c];
                if (fabs(got - want) > maxd) maxd = fabs(got - want);
                /* the official script truncates 255 x */
                off += abs((int)(255.0f * got) - u8[i * 3 + c]) > 1;
            }
        printf("  picture: max |difference| %.2e, %d of %d bytes off by more than 1\n", maxd, off, 16 * 24 * 3);
        CHECK(maxd < 1e-4 && off == 0);
    }
    free(dec);
    g3d_image_free(&img);
done:
    g3d_array_free(&noise);
    g3d_ckpt_free(act);
}

TEST(inpaint_fallback_and_plugin)
{
    g3d_image img = {0}, mask = {0}, out = {0};
    CHECK_OK(g3d_image_create(&img, 24, 16, 3));
    CHECK_OK(g3d_image_create(&mask, 24, 16, 1));
    if (!img.data || !mask.data) return;
    for (int y = 0; y < 16; y++)
        for (int x = 0; x < 24; x++) {
            float *px = g3d_image_px(&img, x, y);
            px[0] = x / 23.0f, px[1] = y / 15.0f, px[2] = 0.3f;
            *g3d_image_px(&mask, x, y) = x >= 12 && y >= 4 && y < 12;
        }
    g3d_sd_params p = g3d_sd_defaults();
    p.prompt = g_prompt;
    p.sampler = (g3d_sd_sampler){G3D_SD_EULER_A, 2, 0, 1, G3D_SD_PRED_EPS};
    CHECK_OK(g3d_sd_inpaint(g_sd, &p, &img, &mask, &out));
    CHECK(p.fallback == 1);
    int same = 1, changed = 0;
    for (int i = 0; out.data && i < 24 * 16; i++)
        for (int c = 0; c < 3; c++) {
            float a = img.data[i * 3 + c], b = out.data[i * 3 + c];
            if (mask.data[i] > 0.5f) changed += a != b;
            else same &= a == b;
        }
    CHECK(same && changed > 0);
    g3d_image_free(&out);
    /* a mask of another size */
    g3d_image small = {0};
    CHECK_OK(g3d_image_create(&small, 16, 16, 1));
    CHECK_FAILS(g3d_sd_inpaint(g_sd, &p, &img, &small, &out));
    g3d_image_free(&small);

    /* the plug-in: any size (padded to the model's multiple), pixels outside the mask untouched */
    g3d_sd *m = NULL;
    g3d_inpainter ip = {0};
    CHECK_OK(g3d_sd_load(paths(), &m));
    if (m) CHECK_OK(g3d_inpainter_sd_create(m, &p, &ip));
    if (ip.inpaint) {
        g3d_image odd = {0}, om = {0};
        CHECK_OK(g3d_image_create(&odd, 21, 13, 3));
        CHECK_OK(g3d_image_create(&om, 21, 13, 1));
        for (size_t i = 0; i < g3d_image_size(&odd); i++) odd.data[i] = (float)(i % 7) / 7.0f;
        for (int x = 5; x < 11; x++) *g3d_image_px(&om, x, 6) = 1;
        g3d_image before = {0};
        CHECK_OK(g3d_image_clone(&before, &odd));
        CHECK_OK(ip.inpaint(ip.ctx, &odd, &om, "a chair", 3));
        int kept = 1, moved = 0;
        for (int i = 0; i < 21 * 13; i++)
            for (int c = 0; c < 3; c++) {
                if (om.data[i] > 0.5f) moved += odd.data[i * 3 + c] != before.data[i * 3 + c];
                else kept &= odd.data[i * 3 + c] == before.data[i * 3 + c];
            }
        CHECK(kept && moved > 0);
        g3d_image_free(&odd);
        g3d_image_free(&om);
        g3d_image_free(&before);
    }
    g3d_inpainter_free(&ip);
    g3d_image_free(&img);
    g3d_image_free(&mask);
}

TEST(refusals)
{
    g3d_sd_params p = g3d_sd_defaults();
    g3d_image out = {0};
    p.prompt = g_prompt;
    p.width = 22;   /* not a multiple of 4 (VAE factor 2, two UNet levels) */
    p.height = 16;
    CHECK_FAILS(g3d_sd_txt2img(g_sd, &p, &out));
    CHECK(out.data == NULL);
    /* parts that do not fit: the 9-channel UNet (context 64) with the 128-wide text encoder */
    g3d_sd_paths q = *paths();
    char model[512];
    snprintf(model, sizeof model, "%s", test_fixture("sdunet_sd2_tiny.safetensors"));
    q.model = model;
    g3d_sd *m = NULL;
    CHECK_FAILS(g3d_sd_load(&q, &m));
    CHECK(strstr(g3d_error_message(), "context width 64") != NULL);
    /* not a diffusion checkpoint */
    snprintf(model, sizeof model, "%s", test_fixture("dav2_tiny.pth"));
    CHECK_FAILS(g3d_sd_load(&q, &m));
    /* NaN weights: named */
    unsigned char *file = NULL;
    size_t n;
    CHECK_OK(g3d_read_file(test_fixture("sdpipe_unet_tiny.safetensors"), 4 << 20, &file, &n));
    if (file) {
        char *tmp = strdup(test_tmp("sd_nan.safetensors"));
        /* the last tensor's last bytes: an fp16 NaN */
        file[n - 1] = 0x7e;
        file[n - 2] = 0x01;
        CHECK_OK(g3d_write_file_atomic(tmp, file, n));
        q.model = tmp;
        CHECK_FAILS(g3d_sd_load(&q, &m));
        CHECK(strstr(g3d_error_message(), "NaN") != NULL);
        free(tmp);
    }
    free(file);
    CHECK(m == NULL);
}

int main(void)
{
    g3d_ckpt *clip = NULL;
    CHECK_OK(g3d_ckpt_open(test_fixture("clip_tiny_golden.safetensors"), &clip));
    const cJSON *pr = clip ? cJSON_GetObjectItem(g3d_ckpt_meta(clip), "prompt") : NULL;
    g_prompt = cJSON_GetStringValue(pr);
    CHECK_OK(g3d_sd_load(paths(), &g_sd));
    if (g_sd && g_prompt) {
        RUN(txt2img_matches_official);
        RUN(inpaint_fallback_and_plugin);
        RUN(refusals);
    }
    g3d_sd_free(g_sd);
    g3d_ckpt_free(clip);
    return test_summary();
}
