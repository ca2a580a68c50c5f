/* The CLIP text encoders against the official code (tests/fixtures/make_clip_golden.py): SD 1.x
 * (OpenAI CLIP's network in the single-file .ckpt layout, fp16), SD 2.x (open_clip's tower run
 * by FrozenOpenCLIPEmbedder with the penultimate layer, .safetensors), and the diffusers
 * text_encoder/ folder (written here from the SD 1.x weights, fp32, with config.json): token
 * ids from the tokenizer fixture, the embeddings, every block, the output. Then refusals. */
#include "golden.h"

#include "gen3d/clip_text.h"

#include <cjson/cJSON.h>

static g3d_ckpt *g_act;
static g3d_clip_tokenizer *g_tok;

/* Tokenizes the golden's prompt as the model's family does, checks the ids against `key`.ids,
 * runs the encoder and compares every recorded tensor. */
static void check_model(g3d_clip_text *m, const char *key, int openclip)
{
    const g3d_clip_text_config *c = g3d_clip_text_get_config(m);
    const cJSON *prompt = cJSON_GetObjectItem(g3d_ckpt_meta(g_act), "prompt");
    int32_t ids[77], want[77];
    char name[64];
    snprintf(name, sizeof name, "%s.ids", key);
    const g3d_tensor_info *wi = g3d_ckpt_find(g_act, name);
    CHECK(wi && wi->numel == 77 && wi->dtype == G3D_DT_I32 && cJSON_IsString(prompt) && c->context == 77);
    if (!wi || wi->numel != 77 || wi->dtype != G3D_DT_I32 || !cJSON_IsString(prompt) || c->context != 77) return;
    memcpy(want, wi->data, sizeof want);
    g3d_clip_tokenizer_set_openclip(g_tok, openclip);
    CHECK_OK(g3d_clip_tokenize(g_tok, prompt->valuestring, 77, g3d_clip_text_pad_id(m, g_tok), ids, NULL));
    g3d_clip_tokenizer_set_openclip(g_tok, 0);
    CHECK(!memcmp(ids, want, sizeof ids));
    size_t n = 77 * (size_t)c->width;
    float *out = malloc(sizeof(float) * n);
    g3d_clip_text_trace tr = {.want = 1};
    CHECK_OK(g3d_clip_text_forward(m, want, 77, out, &tr));
    snprintf(name, sizeof name, "%s.embed", key);
    golden_compare(g_act, name, tr.embed, n);
    for (int i = 0; i < tr.nhidden; i++) {
        snprintf(name, sizeof name, "%s.hidden%d", key, i);
        golden_compare(g_act, name, tr.hidden[i], n);
    }
    snprintf(name, sizeof name, "%s.out", key);
    golden_compare(g_act, name, out, n);
    g3d_clip_text_trace_free(&tr);
    free(out);
}

TEST(sd1_single_file)
{
    g3d_clip_text *m = NULL;
    CHECK_OK(g3d_clip_text_load(test_fixture("clip_sd1_tiny.ckpt"), &m));
    if (!m) return;
    const g3d_clip_text_config *c = g3d_clip_text_get_config(m);
    char d[256];
    printf("  %s\n", g3d_clip_text_describe(c, d, sizeof d));
    CHECK(c->family == G3D_CLIP_HF && !strcmp(c->prefix, "cond_stage_model.transformer.") && c->width == 128 &&
          c->heads == 2 && c->layers == 3 && c->run_layers == 3 && c->mlp == 512 && c->vocab == g3d_clip_tokenizer_size(g_tok) &&
          c->act == G3D_ACT_QUICK_GELU && c->pad_id == -1);
    CHECK(g3d_clip_text_pad_id(m, g_tok) == g3d_clip_tokenizer_eot(g_tok));
    check_model(m, "sd1", 0);
    g3d_clip_text_free(m);
}

TEST(sd2_single_file)
{
    g3d_clip_text *m = NULL;
    CHECK_OK(g3d_clip_text_load(test_fixture("clip_sd2_tiny.safetensors"), &m));
    if (!m) return;
    const g3d_clip_text_config *c = g3d_clip_text_get_config(m);
    char d[256];
    printf("  %s\n", g3d_clip_text_describe(c, d, sizeof d));
    CHECK(c->family == G3D_CLIP_OPENCLIP && !strcmp(c->prefix, "cond_stage_model.model.") && c->width == 128 &&
          c->layers == 3 && c->run_layers == 2 && c->act == G3D_ACT_GELU && c->pad_id == 0);
    check_model(m, "sd2", 1);
    g3d_clip_text_free(m);
}

/* The diffusers layout: text_encoder/model.safetensors with the Hugging Face names (fp32 here)
 * and config.json, written from the SD 1.x file. */
TEST(diffusers_folder)
{
    g3d_ckpt *ck = NULL;
    CHECK_OK(g3d_ckpt_open(test_fixture("clip_sd1_tiny.ckpt"), &ck));
    if (!ck) return;
    char *dir = strdup(test_tmp("clip_diffusers")), *te = g3d_path_join(dir, "text_encoder");
    g3d_remove_tree(dir);
    CHECK_OK(g3d_mkdirs(te));
    int64_t nt = g3d_ckpt_count(ck), k = 0;
    g3d_tensor_out *t = calloc((size_t)nt, sizeof *t);
    float **data = calloc((size_t)nt, sizeof *data);
    const char *prefix = "cond_stage_model.transformer.";
    for (int64_t i = 0; i < nt; i++) {
        const g3d_tensor_info *ti = g3d_ckpt_tensor(ck, i);
        if (ti->dtype != G3D_DT_F16) continue;   /* position_ids: left out, as newer files do */
        CHECK_OK(g3d_ckpt_read_alloc(ck, ti->name, 0, NULL, &data[k]));
        t[k] = (g3d_tensor_out){.name = ti->name + strlen(prefix), .dtype = G3D_DT_F32, .ndim = ti->ndim, .data = data[k]};
        memcpy(t[k].shape, ti->shape, sizeof ti->shape);
        k++;
    }
    char *st = g3d_path_join(te, "model.safetensors"), *cfg = g3d_path_join(te, "config.json");
    const char *js = "{\"architectures\": [\"CLIPTextModel\"], \"hidden_act\": \"quick_gelu\", \"hidden_size\": 128, "
                     "\"num_attention_heads\": 2, \"num_hidden_layers\": 3, \"layer_norm_eps\": 1e-05}";
    CHECK_OK(g3d_safetensors_write(st, t, (int)k, NULL));
    CHECK_OK(g3d_write_file_atomic(cfg, js, strlen(js)));
    g3d_clip_text *m = NULL;
    CHECK_OK(g3d_clip_text_load(dir, &m));
    if (m) {
        const g3d_clip_text_config *c = g3d_clip_text_get_config(m);
        CHECK(c->family == G3D_CLIP_HF && !strcmp(c->prefix, "") && c->run_layers == 3 && c->act == G3D_ACT_QUICK_GELU);
        check_model(m, "sd1", 0);
        g3d_clip_text_free(m);
    }
    /* config.json decides the activation and the layers used (SD 2.x's diffusers files keep 23 of 24) */
    const char *gelu = "{\"hidden_act\": \"gelu\", \"num_hidden_layers\": 2}";
    CHECK_OK(g3d_write_file_atomic(cfg, gelu, strlen(gelu)));
    CHECK_OK(g3d_clip_text_load(te, &m));
    if (m) CHECK(g3d_clip_text_get_config(m)->act == G3D_ACT_GELU && g3d_clip_text_get_config(m)->run_layers == 2);
    g3d_clip_text_free(m);
    const char *silu = "{\"hidden_act\": \"silu\"}";
    CHECK_OK(g3d_write_file_atomic(cfg, silu, strlen(silu)));
    CHECK_FAILS(g3d_clip_text_load(te, &m));
    for (int64_t i = 0; i < k; i++) free(data[i]);
    free(data);
    free(t);
    free(st);
    free(cfg);
    free(te);
    free(dir);
    g3d_ckpt_free(ck);
}

TEST(bad_input)
{
    g3d_clip_text *m = NULL;
    CHECK_FAILS(g3d_clip_text_load(test_fixture("dav2_tiny.pth"), &m));   /* no text encoder */
    CHECK(strstr(g3d_error_message(), "token_embedding") != NULL);
    CHECK_FAILS(g3d_clip_text_load(test_tmp("no_such_model"), &m));
    CHECK_FAILS(g3d_clip_text_load(G3D_SOURCE_DIR "/tests", &m));        /* a folder without one */
    /* a block's tensor missing: named in the message */
    unsigned char *file = NULL;
    size_t n;
    CHECK_OK(g3d_read_file(test_fixture("clip_sd2_tiny.safetensors"), 4 << 20, &file, &n));
    unsigned char *bad = file ? golden_edit_safetensors(file, n, "cond_stage_model.model.transformer.resblocks.1.mlp.c_fc.bias") : NULL;
    g3d_ckpt *ck = NULL;
    if (bad) CHECK_OK(g3d_ckpt_open_memory(bad, n, "edited.safetensors", &ck));
    if (ck) {
        CHECK_FAILS(g3d_clip_text_load_ckpt(ck, NULL, &m));
        CHECK(strstr(g3d_error_message(), "resblocks.1.mlp.c_fc.bias") != NULL);
    }
    g3d_ckpt_free(ck);
    free(bad);
    free(file);
    CHECK(m == NULL);
    /* the empty prompt is start and end tokens; token counts and ids are checked */
    CHECK_OK(g3d_clip_text_load(test_fixture("clip_sd1_tiny.ckpt"), &m));
    if (!m) return;
    int32_t ids[78];
    g3d_clip_tokens info;
    CHECK_OK(g3d_clip_tokenize(g_tok, "", 77, g3d_clip_text_pad_id(m, g_tok), ids, &info));
    CHECK(info.length == 2);
    float *out = malloc(sizeof(float) * 78 * 128);
    CHECK_OK(g3d_clip_text_forward(m, ids, 77, out, NULL));
    int finite = 1;
    for (int i = 0; i < 77 * 128; i++) finite &= isfinite(out[i]);
    CHECK(finite);
    CHECK_FAILS(g3d_clip_text_forward(m, ids, 78, out, NULL));
    ids[3] = g3d_clip_tokenizer_size(g_tok);
    CHECK_FAILS(g3d_clip_text_forward(m, ids, 77, out, NULL));
    free(out);
    g3d_clip_text_free(m);
}

int main(void)
{
    CHECK_OK(g3d_ckpt_open(test_fixture("clip_tiny_golden.safetensors"), &g_act));
    CHECK_OK(g3d_clip_tokenizer_load(test_fixture("cliptok_merges.txt.gz"), &g_tok));
    if (g_act && g_tok) {
        RUN(sd1_single_file);
        RUN(sd2_single_file);
        RUN(diffusers_folder);
        RUN(bad_input);
    }
    g3d_clip_tokenizer_free(g_tok);
    g3d_ckpt_free(g_act);
    return test_summary();
}
