/* BLIP captioning against Salesforce BLIP's vit.py and med.py (tests/fixtures/make_blip_golden.py):
 * preprocessing, the image embeddings, the decoder's first scores, the ids of a greedy and a
 * beam-search caption (identical), decoding, and the refusals. */
#include "golden.h"

#include "gen3d/blip.h"
#include "gen3d/imageio.h"

static g3d_ckpt *g_act;

static int ids_equal(const char *name, const int32_t *got, int n)
{
    const g3d_tensor_info *t = g3d_ckpt_find(g_act, name);
    CHECK(t && t->dtype == G3D_DT_I32);
    if (!t || t->dtype != G3D_DT_I32) return 0;
    int same = t->numel == n && !memcmp(t->data, got, sizeof(int32_t) * (size_t)n);
    printf("  %-8s %d ids%s\n", name, n, same ? ", identical" : "");
    for (int i = 0; !same && i < n; i++) printf("    %d: %d (%d)\n", i, got[i], i < t->numel ? ((const int32_t *)t->data)[i] : -1);
    CHECK_MSG(same, "%s: ids differ", name);
    return same;
}

static void check_model(const char *folder, int hf)
{
    g3d_blip *m = NULL;
    CHECK_OK(g3d_blip_load(test_fixture(folder), &m));
    if (!m) return;
    const g3d_blip_config *c = g3d_blip_get_config(m);
    char d[256];
    printf("  %s\n", g3d_blip_describe(m, d, sizeof d));
    CHECK(c->hf == hf && c->vis_eps == 1e-6f && c->image_size == 32 && c->patch == 8 && c->vis_width == 64 && c->vis_layers == 2 && c->width == 64 &&
          c->layers == 2 && c->mlp == 256 && c->positions == 40 && c->vocab == 116 && c->bos == 114 && c->eos == 3 && c->pad == 0);
    g3d_image img = {0};
    CHECK_OK(g3d_image_load(test_fixture("clip_image.png"), 3, &img));
    float px[3 * 32 * 32], emb[17 * 64], logits[116];
    CHECK_OK(g3d_blip_preprocess(&img, 32, px));
    golden_compare(g_act, "pixels", px, 3 * 32 * 32);
    CHECK_OK(g3d_blip_encode_pixels(m, px, emb));
    golden_compare(g_act, "image_embeds", emb, 17 * 64);
    int32_t *ids = NULL;
    int n = 0;
    g3d_blip_gen g;
    g3d_blip_gen_default(&g);
    CHECK(g.num_beams == 3 && g.max_length == 20 && g.min_length == 5 && g.repetition_penalty == 1.0f);
    CHECK_OK(g3d_blip_prompt_ids(m, g.prompt, &ids, &n));
    ids_equal("prompt", ids, n);
    CHECK_OK(g3d_blip_next_logits(m, emb, ids, n, logits));
    golden_compare(g_act, "logits0", logits, 116);
    free(ids);
    CHECK_OK(g3d_blip_generate(m, emb, &g, &ids, &n));
    ids_equal("beam", ids, n);
    char *beam_text = g3d_blip_decode(m, ids, n);
    free(ids);
    g.num_beams = 1;
    CHECK_OK(g3d_blip_generate(m, emb, &g, &ids, &n));
    ids_equal("greedy", ids, n);
    char *text = g3d_blip_decode(m, ids, n);
    printf("  greedy text: \"%s\"\n", text);
    CHECK(text && !strncmp(text, "a picture of", 12));
    free(text);
    free(ids);
    char *cap = NULL;
    g3d_blip_gen_default(&g);
    CHECK_OK(g3d_blip_caption(m, &img, &g, &cap));
    printf("  beam caption: \"%s\"\n", cap);
    /* BLIP_Decoder.generate: the decoded text less len("a picture of ") characters */
    CHECK(cap && beam_text && strlen(beam_text) > 13 && !strcmp(cap, beam_text + 13));
    free(cap);
    free(beam_text);
    g3d_image_free(&img);
    g3d_blip_free(m);
}

TEST(salesforce_layout) { check_model("blip_tiny", 0); }
TEST(hf_layout) { check_model("blip_tiny_hf", 1); }

TEST(tokens)
{
    g3d_blip *m = NULL;
    CHECK_OK(g3d_blip_load(test_fixture("blip_tiny/model.pth"), &m));
    if (!m) return;
    int32_t *ids = NULL;
    int n = 0;
    /* lower case, punctuation split, "##" pieces, an unknown word */
    CHECK_OK(g3d_blip_prompt_ids(m, "Two Dogs, sitting!  qqqq", &ids, &n));
    char *t = ids ? g3d_blip_decode(m, ids, n) : NULL;
    CHECK_MSG(t && !strcmp(t, "two dogs, sitting!"), "decoded \"%s\"", t ? t : "");
    CHECK(n == 8 && ids[0] == g3d_blip_get_config(m)->bos && ids[7] == 1);
    free(t);
    free(ids);
    g3d_blip_free(m);
}

TEST(bad_input)
{
    g3d_blip *m = NULL;
    CHECK(g3d_blip_load(test_fixture("clip_vit_tiny.pt"), &m) == G3D_ERR_MODEL && !m);
    CHECK(strstr(g3d_error_message(), "a CLIP model, not a BLIP captioner"));
    CHECK(g3d_blip_load(test_fixture("clip_sd2_tiny.safetensors"), &m) == G3D_ERR_MODEL && !m);
    CHECK(strstr(g3d_error_message(), "not a BLIP captioner"));
    /* the weights without vocab.txt beside them */
    unsigned char *f = NULL;
    size_t n;
    CHECK_OK(g3d_read_file(test_fixture("blip_tiny/model.pth"), 1 << 24, &f, &n));
    const char *dir = test_tmp("blip_novocab");
    CHECK_OK(g3d_mkdirs(dir));
    char *path = g3d_path_join(dir, "model.pth");
    if (f && path) CHECK_OK(g3d_write_file_atomic(path, f, n));
    CHECK(g3d_blip_load(dir, &m) == G3D_ERR_IO && !m && strstr(g3d_error_message(), "vocab.txt"));
    free(path);
    free(f);
    CHECK_OK(g3d_blip_load(test_fixture("blip_tiny"), &m));
    g3d_image img = {0};
    char *cap = NULL;
    g3d_blip_gen g;
    g3d_blip_gen_default(&g);
    CHECK_OK(g3d_image_create(&img, 100, 20, 3));
    CHECK(m && g3d_blip_caption(m, &img, &g, &cap) == G3D_ERR_ARG && !cap && strstr(g3d_error_message(), "100x20"));
    g.max_length = 4; /* the prompt alone is 4 tokens */
    img.h = 40;
    g3d_image_free(&img);
    CHECK_OK(g3d_image_create(&img, 40, 40, 3));
    CHECK(m && g3d_blip_caption(m, &img, &g, &cap) == G3D_ERR_ARG && !cap);
    g3d_image_free(&img);
    g3d_blip_free(m);
}

int main(void)
{
    CHECK_OK(g3d_ckpt_open(test_fixture("blip_tiny_golden.safetensors"), &g_act));
    if (g_act) {
        RUN(salesforce_layout);
        RUN(hf_layout);
        RUN(tokens);
        RUN(bad_input);
    }
    g3d_ckpt_free(g_act);
    return test_summary();
}
