/* The text-to-image loop against the official pipeline (tests/fixtures/make_sdpipe_golden.py):
 * the tiny CLIP text encoder, a tiny SD 1.x UNet and the tiny VAE, DDIM 10 steps with guidance
 * 7.5 from the recorded initial noise, down to the 8-bit picture (the same seed giving the same
 * bytes is checked by test_cli_sd.sh). Then inpainting (a text-to-
 * image model: latent blending, the known pixels kept), the inpainter plug-in, refusals. */
#include "golden.h"

#include "gen3d/clip_text.h"
#include "gen3d/imageio.h"
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

/* Runs the golden's text-to-image loop (DDIM 10 steps, guidance 7.5, the recorded noise) on m and
 * compares the picture with the official one; the progress reports each step. */
static void check_txt2img(g3d_sd *m)
{
    g3d_ckpt *act = NULL;
    g3d_array noise = {0};
    g3d_image img = {0};
    float *dec = NULL;
    CHECK_OK(g3d_ckpt_open(test_fixture("sdpipe_golden.safetensors"), &act));
    CHECK_OK(g3d_npy_load(test_fixture("sdpipe_noise.npy"), &noise));
    if (!act || !noise.data) goto done;
    g3d_sd_params p = g3d_sd_defaults();
    p.prompt = g_prompt;
    p.width = 24;
    p.height = 16;
    p.sampler.steps = 10;
    p.noise = noise.data;
    steps_seen = 0;
    p.progress = (g3d_progress){count_steps, NULL};
    CHECK_OK(g3d_sd_txt2img(m, &p, &img));
    CHECK(p.truncated == 0 && steps_seen == 10);
    const g3d_tensor_info *ref = g3d_ckpt_find(act, "image");
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
done:
    free(dec);
    g3d_image_free(&img);
    g3d_array_free(&noise);
    g3d_ckpt_free(act);
}

TEST(txt2img_matches_official)
{
    check_txt2img(g_sd);
}

/* The official inpainting loop with a 9-channel UNet (tests/fixtures/make_sdinpaint_golden.py):
 * the same picture from the recorded noise. The official script returns the decoded picture
 * as it is; gen3d pastes the known pixels back with a seam feathered over 8 pixels inside the
 * mask: so pixels outside the mask are the input's, hole pixels 8 or more from every known
 * pixel the official ones, and those in between lie between the two. */
TEST(inpaint_matches_official)
{
    g3d_sd_paths q = *paths();
    char model[512];
    snprintf(model, sizeof model, "%s", test_fixture("sdinpaint_unet_tiny.safetensors"));
    q.model = model;
    g3d_sd *m = NULL;
    g3d_ckpt *act = NULL;
    g3d_array noise = {0};
    g3d_image img = {0}, mask = {0}, out = {0};
    float *dec = NULL;
    CHECK_OK(g3d_sd_load(&q, &m));
    CHECK_OK(g3d_ckpt_open(test_fixture("sdinpaint_golden.safetensors"), &act));
    CHECK_OK(g3d_npy_load(test_fixture("sdinpaint_noise.npy"), &noise));
    CHECK_OK(g3d_image_load(test_fixture("sdinpaint_image.png"), 3, &img));
    CHECK_OK(g3d_image_load(test_fixture("sdinpaint_mask.png"), 1, &mask));
    if (!m || !act || !noise.data || !img.data || !mask.data) goto done;
    CHECK(g3d_sd_get_unet(m)->in_ch == 9);
    g3d_sd_params p = g3d_sd_defaults();
    p.prompt = g_prompt;
    p.sampler.steps = 10;
    p.noise = noise.data;
    CHECK_OK(g3d_sd_inpaint(m, &p, &img, &mask, &out));
    CHECK(p.fallback == 0);
    const g3d_tensor_info *ref = g3d_ckpt_find(act, "image");
    CHECK_OK(g3d_ckpt_read_alloc(act, "decoded", 0, NULL, &dec));
    int W = img.w, H = img.h;
    if (!out.data || !ref || !dec || ref->numel != (int64_t)W * H * 3) goto done;
    const uint8_t *u8 = ref->data;
    double maxd = 0;
    int inner = 0, off = 0, kept = 1, between = 1;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            int i = y * W + x, d2 = 1 << 30;
            for (int v = 0; v < H; v++)
                for (int u = 0; u < W; u++)
                    if (mask.data[v * W + u] <= 0.5f && (u - x) * (u - x) + (v - y) * (v - y) < d2) d2 = (u - x) * (u - x) + (v - y) * (v - y);
            for (int c = 0; c < 3; c++) {
                float want = (dec[c * W * H + i] + 1) / 2, got = out.data[i * 3 + c], in = img.data[i * 3 + c];
                want = want < 0 ? 0 : want > 1 ? 1 : want;
                if (mask.data[i] <= 0.5f) {
                    kept &= got == in;
                } else if (d2 >= 64) {
                    maxd = fmax(maxd, fabs(got - want));
                    off += abs((int)(255.0f * got) - u8[i * 3 + c]) > 1;
                    inner += c == 0;
                } else {
                    between &= got >= fminf(want, in) - 1e-4f && got <= fmaxf(want, in) + 1e-4f;
                }
            }
        }
    printf("  %d hole pixels away from the seam: max |difference| %.2e, %d bytes off by more than 1\n", inner, maxd, off);
    CHECK(inner > 300 && maxd < 1e-4 && off == 0 && kept && between);
done:
    free(dec);
    g3d_image_free(&img);
    g3d_image_free(&mask);
    g3d_image_free(&out);
    g3d_array_free(&noise);
    g3d_ckpt_free(act);
    g3d_sd_free(m);
}

/* Original names -> diffusers' for the fixtures' shapes (UNet: two levels, one res block each,
 * attention at level 0; VAE: two levels, one res block), written out block by block. */
static const char *const UNET_MAP[][2] = {
    {"input_blocks.0.0.", "conv_in."}, {"input_blocks.1.0.", "down_blocks.0.resnets.0."}, {"input_blocks.1.1.", "down_blocks.0.attentions.0."},
    {"input_blocks.2.0.op.", "down_blocks.0.downsamplers.0.conv."}, {"input_blocks.3.0.", "down_blocks.1.resnets.0."},
    {"middle_block.0.", "mid_block.resnets.0."}, {"middle_block.1.", "mid_block.attentions.0."}, {"middle_block.2.", "mid_block.resnets.1."},
    {"output_blocks.0.0.", "up_blocks.0.resnets.0."}, {"output_blocks.1.0.", "up_blocks.0.resnets.1."},
    {"output_blocks.1.1.", "up_blocks.0.upsamplers.0."}, {"output_blocks.2.0.", "up_blocks.1.resnets.0."},
    {"output_blocks.2.1.", "up_blocks.1.attentions.0."}, {"output_blocks.3.0.", "up_blocks.1.resnets.1."},
    {"output_blocks.3.1.", "up_blocks.1.attentions.1."}, {"time_embed.0.", "time_embedding.linear_1."},
    {"time_embed.2.", "time_embedding.linear_2."}, {"out.0.", "conv_norm_out."}, {"out.2.", "conv_out."},
    /* VAE */
    {"encoder.down.0.block.0.", "encoder.down_blocks.0.resnets.0."}, {"encoder.down.0.downsample.", "encoder.down_blocks.0.downsamplers.0."},
    {"encoder.down.1.block.0.", "encoder.down_blocks.1.resnets.0."}, {"encoder.mid.block_1.", "encoder.mid_block.resnets.0."},
    {"encoder.mid.block_2.", "encoder.mid_block.resnets.1."}, {"encoder.mid.attn_1.", "encoder.mid_block.attentions.0."},
    {"encoder.norm_out.", "encoder.conv_norm_out."}, {"decoder.mid.block_1.", "decoder.mid_block.resnets.0."},
    {"decoder.mid.block_2.", "decoder.mid_block.resnets.1."}, {"decoder.mid.attn_1.", "decoder.mid_block.attentions.0."},
    {"decoder.up.1.block.0.", "decoder.up_blocks.0.resnets.0."}, {"decoder.up.1.block.1.", "decoder.up_blocks.0.resnets.1."},
    {"decoder.up.1.upsample.", "decoder.up_blocks.0.upsamplers.0."}, {"decoder.up.0.block.0.", "decoder.up_blocks.1.resnets.0."},
    {"decoder.up.0.block.1.", "decoder.up_blocks.1.resnets.1."}, {"decoder.norm_out.", "decoder.conv_norm_out."}};
static const char *const LEAF_MAP[][2] = {
    {"in_layers.0.", "norm1."}, {"in_layers.2.", "conv1."}, {"emb_layers.1.", "time_emb_proj."}, {"out_layers.0.", "norm2."},
    {"out_layers.3.", "conv2."}, {"skip_connection.", "conv_shortcut."}, {"nin_shortcut.", "conv_shortcut."},
    {"norm.", "group_norm."}, {"q.", "to_q."}, {"k.", "to_k."}, {"v.", "to_v."}, {"proj_out.", "to_out.0."}};

/* Writes the tensors of `file` under `prefix` into dir/sub/name with diffusers' names. */
static void write_diffusers(const char *file, const char *prefix, const char *dir, const char *sub, const char *name, int map)
{
    g3d_ckpt *ck = NULL;
    CHECK_OK(g3d_ckpt_open(file, &ck));
    if (!ck) return;
    int64_t n = g3d_ckpt_count(ck), k = 0;
    g3d_tensor_out *t = calloc((size_t)n, sizeof *t);
    char (*names)[256] = calloc((size_t)n, sizeof *names);
    for (int64_t i = 0; i < n; i++) {
        const g3d_tensor_info *ti = g3d_ckpt_tensor(ck, i);
        const char *nm = ti->name + strlen(prefix);
        if (strncmp(ti->name, prefix, strlen(prefix)) || ti->dtype == G3D_DT_I64) continue;
        snprintf(names[k], sizeof names[k], "%s", nm);
        t[k] = (g3d_tensor_out){.name = names[k], .dtype = ti->dtype, .ndim = ti->ndim, .data = ti->data};
        memcpy(t[k].shape, ti->shape, sizeof ti->shape);
        for (size_t r = 0; map && r < sizeof UNET_MAP / sizeof *UNET_MAP; r++) {
            size_t len = strlen(UNET_MAP[r][0]);
            if (strncmp(nm, UNET_MAP[r][0], len)) continue;
            const char *leaf = nm + len;
            int attn = strstr(UNET_MAP[r][1], "mid_block.attentions") && (!strncmp(nm, "encoder", 7) || !strncmp(nm, "decoder", 7));
            for (size_t q = 0; q < sizeof LEAF_MAP / sizeof *LEAF_MAP; q++) {
                size_t ll = strlen(LEAF_MAP[q][0]);
                int vae_leaf = q >= 7;
                if (vae_leaf == attn && !strncmp(leaf, LEAF_MAP[q][0], ll) && (strstr(UNET_MAP[r][1], "resnets") || attn)) {
                    snprintf(names[k], sizeof names[k], "%s%s%s", UNET_MAP[r][1], LEAF_MAP[q][1], leaf + ll);
                    if (attn && t[k].ndim == 4) t[k].ndim = 2;   /* diffusers' attention: Linear layers */
                    break;
                }
                snprintf(names[k], sizeof names[k], "%s%s", UNET_MAP[r][1], leaf);
            }
            break;
        }
        k++;
    }
    char *d = g3d_path_join(dir, sub), *f = g3d_path_join(d, name);
    CHECK_OK(g3d_mkdirs(d));
    CHECK_OK(g3d_safetensors_write(f, t, (int)k, NULL));
    free(d);
    free(f);
    free(t);
    free(names);
    g3d_ckpt_free(ck);
}

static void write_text(const char *dir, const char *sub, const char *name, const char *text)
{
    char *d = g3d_path_join(dir, sub), *f = g3d_path_join(d, name);
    CHECK_OK(g3d_mkdirs(d));
    CHECK_OK(g3d_write_file_atomic(f, text, strlen(text)));
    free(d);
    free(f);
}

static void copy_to(const char *from, const char *dir, const char *sub, const char *name)
{
    unsigned char *b = NULL;
    size_t n;
    CHECK_OK(g3d_read_file(from, 16 << 20, &b, &n));
    char *d = g3d_path_join(dir, sub), *f = g3d_path_join(d, name);
    CHECK_OK(g3d_mkdirs(d));
    if (b) CHECK_OK(g3d_write_file_atomic(f, b, n));
    free(b);
    free(d);
    free(f);
}

/* The same models as a diffusers folder (names and files as diffusers lays them out): the same
 * picture as from the single files, bit for bit. */
TEST(diffusers_folder)
{
    char *dir = strdup(test_tmp("sd_diffusers"));
    g3d_remove_tree(dir);
    write_diffusers(test_fixture("sdpipe_unet_tiny.safetensors"), "model.diffusion_model.", dir, "unet",
                    "diffusion_pytorch_model.safetensors", 1);
    write_text(dir, "unet", "config.json", "{\"_class_name\": \"UNet2DConditionModel\", \"attention_head_dim\": 8, "
               "\"in_channels\": 4, \"cross_attention_dim\": 128}");
    write_diffusers(test_fixture("sdunet_vae_tiny.safetensors"), "first_stage_model.", dir, "vae", "diffusion_pytorch_model.safetensors", 1);
    write_diffusers(test_fixture("clip_sd1_tiny.ckpt"), "cond_stage_model.transformer.", dir, "text_encoder", "model.safetensors", 0);
    write_text(dir, "text_encoder", "config.json", "{\"hidden_act\": \"quick_gelu\", \"num_hidden_layers\": 3}");
    /* tokenizer/: the merges and the vocabulary numbered as the official tokenizer numbers them
     * (the fixture's own vocab.json numbers its tokens differently, on purpose) */
    copy_to(test_fixture("cliptok_merges.txt"), dir, "tokenizer", "merges.txt");
    g3d_clip_tokenizer *tok = NULL;
    CHECK_OK(g3d_clip_tokenizer_load(test_fixture("cliptok_merges.txt.gz"), &tok));
    cJSON *vocab = cJSON_CreateObject();
    for (int32_t i = 0; tok && i < g3d_clip_tokenizer_size(tok); i++)
        cJSON_AddNumberToObject(vocab, g3d_clip_tokenizer_token(tok, i), i);
    char *vj = cJSON_PrintUnformatted(vocab);
    if (vj) write_text(dir, "tokenizer", "vocab.json", vj);
    free(vj);
    cJSON_Delete(vocab);
    g3d_clip_tokenizer_free(tok);
    write_text(dir, "scheduler", "scheduler_config.json", "{\"prediction_type\": \"epsilon\"}");
    g3d_sd *m = NULL;
    CHECK_OK(g3d_sd_load(&(g3d_sd_paths){.model = dir, .prediction = -1}, &m));
    if (m) {
        char d[512];
        printf("  %s\n", g3d_sd_unet_describe(g3d_sd_get_unet(m), d, sizeof d));
        CHECK(g3d_sd_get_unet(m)->diffusers && g3d_sd_get_unet(m)->heads == 8);
        g3d_sd_params p = g3d_sd_defaults();
        p.prompt = g_prompt;
        p.width = 24;
        p.height = 16;
        p.sampler.steps = 2;
        g3d_image a = {0}, b = {0};
        CHECK_OK(g3d_sd_txt2img(m, &p, &a));
        CHECK_OK(g3d_sd_txt2img(g_sd, &p, &b));
        CHECK(a.data && b.data && !memcmp(a.data, b.data, sizeof(float) * g3d_image_size(&a)));
        g3d_image_free(&a);
        g3d_image_free(&b);
        g3d_sd_free(m);
    }
    /* v-prediction from the scheduler's configuration */
    write_text(dir, "scheduler", "scheduler_config.json", "{\"prediction_type\": \"v_prediction\"}");
    CHECK_OK(g3d_sd_load(&(g3d_sd_paths){.model = dir, .prediction = -1}, &m));
    if (m) CHECK(g3d_sd_get_unet(m)->pred == G3D_SD_PRED_V);
    g3d_sd_free(m);
    free(dir);
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
        RUN(inpaint_matches_official);
        RUN(diffusers_folder);
        RUN(inpaint_fallback_and_plugin);
        RUN(refusals);
    }
    g3d_sd_free(g_sd);
    g3d_ckpt_free(clip);
    return test_summary();
}
