/* The CLIP tokenizer against the official ones (tests/fixtures/make_cliptok_fixture.py: OpenAI
 * CLIP's simple_tokenizer and open_clip's tokenize(), with ftfy) on 69 prompts and a merges list
 * of our own: the cleaned text, the BPE ids, the framing with both paddings and truncation,
 * OpenCLIP's special strings, the Hugging Face folder layout (vocab.json ids read, not
 * derived; the padding token from special_tokens_map.json), and the refusals. */
#include "testutil.h"

#include "gen3d/clip_text.h"

#include <cjson/cJSON.h>

static cJSON *g_cases;

static cJSON *load_cases(void)
{
    unsigned char *d = NULL;
    size_t n;
    CHECK_OK(g3d_read_file(test_fixture("cliptok_cases.json"), 4 << 20, &d, &n));
    cJSON *j = d ? cJSON_Parse((const char *)d) : NULL;
    free(d);
    CHECK(j != NULL);
    return j;
}

/* ids[n] equal to the JSON array a (mapped through map[] when given)? Prints the first
 * difference. */
static int same_ids(const char *what, const char *text, const int32_t *ids, int n, const cJSON *a, const cJSON *map)
{
    int m = cJSON_GetArraySize(a);
    for (int i = 0; i < n || i < m; i++) {
        int want = i < m ? cJSON_GetArrayItem(a, i)->valueint : -1;
        if (map && want >= 0) want = cJSON_GetArrayItem(map, want)->valueint;
        if (i >= n || i >= m || ids[i] != want) {
            printf("  %s of \"%.40s\": token %d is %d, expected %d (%d vs %d tokens)\n", what, text, i, i < n ? ids[i] : -1,
                   want, n, m);
            return 0;
        }
    }
    return 1;
}

TEST(official_layout)
{
    g3d_clip_tokenizer *t = NULL;
    CHECK_OK(g3d_clip_tokenizer_load(test_fixture("cliptok_merges.txt.gz"), &t));
    if (!t || !g_cases) return;
    CHECK(g3d_clip_tokenizer_size(t) == cJSON_GetObjectItem(g_cases, "vocab")->valueint);
    CHECK(g3d_clip_tokenizer_sot(t) == cJSON_GetObjectItem(g_cases, "sot")->valueint);
    CHECK(g3d_clip_tokenizer_eot(t) == cJSON_GetObjectItem(g_cases, "eot")->valueint);
    CHECK(g3d_clip_tokenizer_pad(t) == -1);
    CHECK(!strcmp(g3d_clip_tokenizer_token(t, 0), "!") && !strcmp(g3d_clip_tokenizer_token(t, 256), "!</w>"));
    int ncase = 0, clean_ok = 0, ids_ok = 0, framed_ok = 0, oc_ok = 0, truncated = 0;
    const cJSON *c;
    cJSON_ArrayForEach(c, cJSON_GetObjectItem(g_cases, "cases"))
    {
        const char *text = cJSON_GetObjectItem(c, "text")->valuestring;
        ncase++;
        char *cl = NULL;
        CHECK_OK(g3d_clip_clean_text(text, G3D_CLIP_CLEAN_OFFICIAL, &cl));
        if (cl && !strcmp(cl, cJSON_GetObjectItem(c, "clean")->valuestring)) clean_ok++;
        else printf("  clean-up of \"%.40s\": got \"%.60s\", expected \"%.60s\"\n", text, cl ? cl : "",
                    cJSON_GetObjectItem(c, "clean")->valuestring);
        free(cl);
        int32_t *ids = NULL;
        int n = 0;
        CHECK_OK(g3d_clip_encode(t, text, &ids, &n));
        ids_ok += same_ids("BPE ids", text, ids, n, cJSON_GetObjectItem(c, "ids"), NULL);
        /* SD 1.x framing: start, at most 75 tokens, end, padded with the end token */
        int32_t framed[77];
        g3d_clip_tokens info;
        CHECK_OK(g3d_clip_tokenize(t, text, 77, g3d_clip_tokenizer_eot(t), framed, &info));
        int keep = n < 75 ? n : 75, ok = framed[0] == g3d_clip_tokenizer_sot(t) && info.length == keep + 2 &&
                                        info.eot_pos == keep + 1 && info.dropped == n - keep;
        for (int i = 0; i < 77; i++)
            ok &= framed[i] == (i == 0 ? g3d_clip_tokenizer_sot(t) : i <= keep ? ids[i - 1] : g3d_clip_tokenizer_eot(t));
        framed_ok += ok;
        truncated += info.dropped > 0;
        free(ids);
        /* SD 2.x: open_clip.tokenize(), padding 0 and OpenCLIP's special strings */
        g3d_clip_tokenizer_set_openclip(t, 1);
        CHECK_OK(g3d_clip_tokenize(t, text, 77, 0, framed, NULL));
        oc_ok += same_ids("open_clip.tokenize", text, framed, 77, cJSON_GetObjectItem(c, "open_clip77"), NULL);
        g3d_clip_tokenizer_set_openclip(t, 0);
    }
    printf("  %d prompts: clean-up %d, BPE ids %d, SD 1.x framing %d, open_clip.tokenize %d identical; %d truncated\n",
           ncase, clean_ok, ids_ok, framed_ok, oc_ok, truncated);
    CHECK(ncase >= 50 && clean_ok == ncase && ids_ok == ncase && framed_ok == ncase && oc_ok == ncase && truncated >= 2);
    g3d_clip_tokenizer_free(t);
}

/* The Hugging Face layout: a model folder with tokenizer/{vocab.json, merges.txt,
 * special_tokens_map.json}; ids come from vocab.json (shuffled against the derived ones). */
TEST(hugging_face_layout)
{
    if (!g_cases) return;
    char *dir = strdup(test_tmp("clip_hf_model")), *tok = g3d_path_join(dir, "tokenizer");
    g3d_remove_tree(dir);
    CHECK_OK(g3d_mkdirs(tok));
    static const char *const copy[][2] = {{"cliptok_vocab.json", "vocab.json"}, {"cliptok_merges.txt", "merges.txt"}};
    for (int i = 0; i < 2; i++) {
        unsigned char *d = NULL;
        size_t n;
        char *dst = g3d_path_join(tok, copy[i][1]);
        CHECK_OK(g3d_read_file(test_fixture(copy[i][0]), 4 << 20, &d, &n));
        CHECK_OK(g3d_write_file_atomic(dst, d, n));
        free(d);
        free(dst);
    }
    const cJSON *map = cJSON_GetObjectItem(g_cases, "hf_ids");
    g3d_clip_tokenizer *t = NULL;
    CHECK_OK(g3d_clip_tokenizer_load(dir, &t));
    if (t) { /* no configuration: Hugging Face's default pad_token, <|endoftext|> */
        CHECK(g3d_clip_tokenizer_eot(t) == cJSON_GetArrayItem(map, cJSON_GetObjectItem(g_cases, "eot")->valueint)->valueint);
        CHECK(g3d_clip_tokenizer_pad(t) == g3d_clip_tokenizer_eot(t));
        g3d_clip_tokenizer_free(t);
        t = NULL;
    }
    const char *sd2 = "{\"bos_token\": \"<|startoftext|>\", \"eos_token\": \"<|endoftext|>\", \"pad_token\": \"!\", "
                      "\"unk_token\": {\"content\": \"<|endoftext|>\", \"lstrip\": false}}";
    char *stm = g3d_path_join(tok, "special_tokens_map.json");
    CHECK_OK(g3d_write_file_atomic(stm, sd2, strlen(sd2)));
    CHECK_OK(g3d_clip_tokenizer_load(dir, &t));
    if (t) {
        CHECK(g3d_clip_tokenizer_pad(t) == cJSON_GetArrayItem(map, 0)->valueint); /* "!" is the first byte symbol */
        int ok = 0, hf_ok = 0, ncase = 0;
        const cJSON *c;
        cJSON_ArrayForEach(c, cJSON_GetObjectItem(g_cases, "cases"))
        {
            const char *text = cJSON_GetObjectItem(c, "text")->valuestring;
            int32_t *ids = NULL;
            int n = 0;
            /* by default Hugging Face's own clean-up (with ftfy): no html.unescape */
            CHECK_OK(g3d_clip_encode(t, text, &ids, &n));
            hf_ok += same_ids("HF clean-up ids", text, ids, n, cJSON_GetObjectItem(c, "hf_ftfy_ids"), NULL);
            free(ids);
            g3d_clip_tokenizer_set_clean(t, G3D_CLIP_CLEAN_OFFICIAL);
            CHECK_OK(g3d_clip_encode(t, text, &ids, &n));
            ok += same_ids("HF ids", text, ids, n, cJSON_GetObjectItem(c, "ids"), map);
            g3d_clip_tokenizer_set_clean(t, G3D_CLIP_CLEAN_HF_FTFY);
            ncase++;
            free(ids);
        }
        printf("  Hugging Face layout: %d of %d prompts identical with Hugging Face's clean-up, %d with OpenAI's\n",
               hf_ok, ncase, ok);
        CHECK(ok == ncase && hf_ok == ncase);
        g3d_clip_tokenizer_free(t);
    }
    /* the merges file alone, vocab.json beside it */
    char *merges = g3d_path_join(tok, "merges.txt");
    CHECK_OK(g3d_clip_tokenizer_load(merges, &t));
    if (t) CHECK(g3d_clip_tokenizer_pad(t) == cJSON_GetArrayItem(map, 0)->valueint);
    g3d_clip_tokenizer_free(t);
    free(merges);
    free(stm);
    free(tok);
    free(dir);
}

/* ftfy's mojibake repair (tests/fixtures/make_cliptok_mojibake_fixture.py): prompts that were
 * UTF-8 read as Windows-1252 or Latin-1, once or twice, with 0xA0 bytes turned into spaces, and
 * correct non-ASCII prompts that stay: both clean-ups and the ids. */
TEST(mojibake)
{
    unsigned char *d = NULL;
    size_t n;
    CHECK_OK(g3d_read_file(test_fixture("cliptok_mojibake.json"), 1 << 20, &d, &n));
    cJSON *j = d ? cJSON_Parse((const char *)d) : NULL;
    free(d);
    g3d_clip_tokenizer *t = NULL;
    CHECK_OK(g3d_clip_tokenizer_load(test_fixture("cliptok_merges.txt.gz"), &t));
    int ncase = 0, ok = 0, repaired = 0;
    const cJSON *c;
    cJSON_ArrayForEach(c, cJSON_GetObjectItem(j, "cases"))
    {
        const char *text = cJSON_GetObjectItem(c, "text")->valuestring;
        const char *want[2] = {cJSON_GetObjectItem(c, "clean")->valuestring, cJSON_GetObjectItem(c, "hf_clean")->valuestring};
        int good = 1;
        ncase++;
        for (int k = 0; k < 2; k++) {
            char *cl = NULL;
            CHECK_OK(g3d_clip_clean_text(text, k ? G3D_CLIP_CLEAN_HF_FTFY : G3D_CLIP_CLEAN_OFFICIAL, &cl));
            if (!cl || strcmp(cl, want[k])) {
                printf("  %s clean-up of \"%.40s\": got \"%.60s\", expected \"%.60s\"\n", k ? "HF" : "official", text, cl ? cl : "", want[k]);
                good = 0;
            }
            free(cl);
        }
        int32_t *ids = NULL;
        int m = 0;
        if (t) CHECK_OK(g3d_clip_encode(t, text, &ids, &m));
        good &= ids && same_ids("BPE ids", text, ids, m, cJSON_GetObjectItem(c, "ids"), NULL);
        free(ids);
        ok += good;
        repaired += strchr(text, 0xC3) && !strchr(want[0], 0xC3);   /* an "Ã" gone */
    }
    printf("  %d prompts (%d with an \"Ã\" repaired): %d identical\n", ncase, repaired, ok);
    CHECK(ncase >= 30 && ok == ncase && repaired >= 10);
    g3d_clip_tokenizer_free(t);
    cJSON_Delete(j);
}

TEST(bad_input)
{
    g3d_clip_tokenizer *t = NULL;
    CHECK_FAILS(g3d_clip_tokenizer_load(test_tmp("no_such_tokenizer"), &t));
    CHECK_FAILS(g3d_clip_tokenizer_load(G3D_SOURCE_DIR "/tests", &t));           /* a folder without one */
    CHECK_FAILS(g3d_clip_tokenizer_load(test_fixture("jpeg_grey_23x17.png"), &t)); /* not a merges file */
    CHECK(t == NULL);
    CHECK_OK(g3d_clip_tokenizer_load(test_fixture("cliptok_merges.txt.gz"), &t));
    if (!t) return;
    int32_t ids[77];
    char *cl = NULL;
    CHECK_FAILS(g3d_clip_clean_text("bad \xC3\x28 utf-8", G3D_CLIP_CLEAN_HF_FTFY, &cl));
    CHECK_FAILS(g3d_clip_tokenize(t, "overlong \xE0\x80\xAF", 77, 0, ids, NULL));
    CHECK_FAILS(g3d_clip_tokenize(t, "surrogate \xED\xA0\x80", 77, 0, ids, NULL));
    CHECK_FAILS(g3d_clip_tokenize(t, "short", 1, 0, ids, NULL));
    g3d_clip_tokens info;
    CHECK_OK(g3d_clip_tokenize(t, "", 77, 0, ids, &info));   /* empty: start and end only */
    CHECK(info.length == 2 && info.dropped == 0 && ids[0] == g3d_clip_tokenizer_sot(t) &&
          ids[1] == g3d_clip_tokenizer_eot(t) && ids[2] == 0 && ids[76] == 0);
    CHECK_OK(g3d_clip_tokenize(t, "a b c d e f", 5, 7, ids, &info)); /* a short context truncates */
    CHECK(info.length == 5 && info.dropped == 3 && ids[4] == g3d_clip_tokenizer_eot(t));
    g3d_clip_tokenizer_free(t);
}

int main(void)
{
    g_cases = load_cases();
    RUN(official_layout);
    RUN(hugging_face_layout);
    RUN(mojibake);
    RUN(bad_input);
    cJSON_Delete(g_cases);
    return test_summary();
}
