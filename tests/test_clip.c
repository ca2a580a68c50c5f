/* The whole CLIP model against OpenAI CLIP's model.py (tests/fixtures/make_clipvit_golden.py):
 * the preprocessing (PIL's bicubic, torchvision's crop, CLIP's mean and std), the image tower,
 * the pooled and projected text embeddings and the zero-shot logits, in the OpenAI layout
 * (.pt, fp16) and Hugging Face's CLIPModel layout (.safetensors); then refusals. */
#include "golden.h"

#include "gen3d/clip.h"
#include "gen3d/imageio.h"

#include <cjson/cJSON.h>

static g3d_ckpt *g_act;
static g3d_clip_tokenizer *g_tok;

/* The golden's prompts (metadata "prompts", '|'-separated) into p[3]. */
static int prompts(char p[3][64])
{
    const cJSON *s = cJSON_GetObjectItem(g3d_ckpt_meta(g_act), "prompts");
    CHECK(cJSON_IsString(s));
    if (!cJSON_IsString(s)) return 0;
    const char *a = s->valuestring;
    for (int i = 0; i < 3; i++) {
        const char *e = strchr(a, '|');
        size_t n = e ? (size_t)(e - a) : strlen(a);
        snprintf(p[i], 64, "%.*s", (int)n, a);
        a = e ? e + 1 : a + n;
    }
    return 1;
}

TEST(preprocess)
{
    g3d_image img = {0};
    CHECK_OK(g3d_image_load(test_fixture("clip_image.png"), 3, &img));
    float *px = malloc(sizeof(float) * 3 * 224 * 224), *want = malloc(sizeof(float) * 3 * 224 * 224);
    CHECK_OK(g3d_clip_preprocess(&img, 32, px));
    golden_compare(g_act, "pixels", px, 3 * 32 * 32);
    /* enlarged to 293x224 and cropped at 34.5 -> 34: the recorded 8-bit crop, exactly */
    const g3d_tensor_info *c = g3d_ckpt_find(g_act, "crop224");
    CHECK(c && c->numel == 224 * 224 * 3);
    CHECK_OK(g3d_clip_preprocess(&img, 224, px));
    static const float mean[3] = {0.48145466f, 0.4578275f, 0.40821073f}, sd[3] = {0.26862954f, 0.26130258f, 0.27577711f};
    int diff = 0;
    for (int ch = 0; c && ch < 3; ch++)
        for (int i = 0; i < 224 * 224; i++) {
            float v = ((float)((const unsigned char *)c->data)[i * 3 + ch] / 255.0f - mean[ch]) / sd[ch];
            want[ch * 224 * 224 + i] = v;
            diff += v != px[ch * 224 * 224 + i];
        }
    CHECK_MSG(diff == 0, "%d values differ from PIL's resize and torchvision's crop", diff);
    g3d_image_free(&img);
    free(px);
    free(want);
}

static void check_model(const char *file, g3d_clip_family family)
{
    g3d_clip *m = NULL;
    CHECK_OK(g3d_clip_load(test_fixture(file), &m));
    if (!m) return;
    const g3d_clip_config *c = g3d_clip_get_config(m);
    char d[320];
    printf("  %s\n", g3d_clip_describe(m, d, sizeof d));
    CHECK(c->family == family && c->image_size == 32 && c->patch == 8 && c->width == 64 && c->heads == 1 && c->layers == 2 &&
          c->mlp == 256 && c->embed == 32 && c->act == G3D_ACT_QUICK_GELU && fabsf(c->logit_scale - 100.0f) < 0.05f);
    const g3d_tensor_info *px = g3d_ckpt_find(g_act, "pixels");
    float *pix = malloc(sizeof(float) * 3 * 32 * 32), emb[32], cls[64], text[3][32], logits[3], probs[3];
    CHECK_OK(g3d_ckpt_read(g_act, "pixels", 0, NULL, pix));
    CHECK_OK(g3d_clip_encode_pixels(m, pix, emb, cls));
    golden_compare(g_act, "class_token", cls, 64);
    golden_compare(g_act, "image_embed", emb, 32);
    char p[3][64];
    const g3d_tensor_info *ids = g3d_ckpt_find(g_act, "ids");
    CHECK(px && ids && ids->numel == 3 * 77);
    if (prompts(p) && ids) {
        for (int i = 0; i < 3; i++) {
            int32_t got[77];
            CHECK_OK(g3d_clip_tokenize(g_tok, p[i], 77, 0, got, NULL));
            CHECK(!memcmp(got, (const int32_t *)ids->data + 77 * i, sizeof got));
            CHECK_OK(g3d_clip_encode_text(m, g_tok, p[i], text[i]));
        }
        golden_compare(g_act, "text_embed", &text[0][0], 3 * 32);
        const char *labels[3] = {"kitchen", "beach", "forest path"};
        CHECK_OK(g3d_clip_zero_shot(m, g_tok, emb, labels, 3, "a photo of a {}.", logits, probs));
        golden_compare(g_act, "logits", logits, 3);
        CHECK(fabsf(probs[0] + probs[1] + probs[2] - 1.0f) < 1e-5f && probs[2] > probs[1] && probs[1] > probs[0]);
        CHECK(g3d_clip_zero_shot(m, g_tok, emb, labels, 3, "a photo of a thing.", NULL, probs) == G3D_ERR_ARG);
    }
    free(pix);
    g3d_clip_free(m);
}

TEST(openai_layout) { check_model("clip_vit_tiny.pt", G3D_CLIP_OPENCLIP); }
TEST(hf_layout) { check_model("clip_vit_tiny_hf.safetensors", G3D_CLIP_HF); }

TEST(bad_input)
{
    g3d_clip *m = NULL;
    /* a text tower alone: named as not a CLIP model */
    CHECK(g3d_clip_load(test_fixture("clip_sd2_tiny.safetensors"), &m) == G3D_ERR_MODEL && !m);
    CHECK(strstr(g3d_error_message(), "not a CLIP model"));
    CHECK(g3d_clip_load(test_fixture("no_such_model"), &m) == G3D_ERR_IO && !m);
    /* the image tower without its projection */
    unsigned char *f = NULL;
    size_t n;
    CHECK_OK(g3d_read_file(test_fixture("clip_vit_tiny_hf.safetensors"), 1 << 24, &f, &n));
    unsigned char *e = f ? golden_edit_safetensors(f, n, "visual_projection.weight") : NULL;
    const char *path = test_tmp("clip_noproj.safetensors");
    if (e) CHECK_OK(g3d_write_file_atomic(path, e, n));
    CHECK(e && g3d_clip_load(path, &m) == G3D_ERR_MODEL && !m && strstr(g3d_error_message(), "visual_projection.weight"));
    free(e);
    free(f);
    /* an image too small to classify */
    CHECK_OK(g3d_clip_load(test_fixture("clip_vit_tiny.pt"), &m));
    g3d_image img = {0};
    CHECK_OK(g3d_image_create(&img, 200, G3D_CLIP_MIN_SIDE - 1, 3));
    float emb[32];
    CHECK(m && g3d_clip_encode_image(m, &img, emb, NULL) == G3D_ERR_ARG && strstr(g3d_error_message(), "200x31"));
    g3d_image_free(&img);
    g3d_clip_free(m);
}

int main(void)
{
    CHECK_OK(g3d_ckpt_open(test_fixture("clipvit_tiny_golden.safetensors"), &g_act));
    CHECK_OK(g3d_clip_tokenizer_load(test_fixture("cliptok_merges.txt.gz"), &g_tok));
    if (g_act && g_tok) {
        RUN(preprocess);
        RUN(openai_layout);
        RUN(hf_layout);
        RUN(bad_input);
    }
    g3d_clip_tokenizer_free(g_tok);
    g3d_ckpt_free(g_act);
    return test_summary();
}
