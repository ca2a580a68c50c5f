/* LaMa: the generator against the official code's activations (tests/fixtures/
 * make_lama_golden.py), the predict pipeline, the local Fourier unit, and refused input. */
#include "golden.h"
#include "testutil.h"

#include "gen3d/ckpt.h"
#include "gen3d/lama.h"

#include <stdlib.h>
#include <string.h>

typedef struct taps {
    const g3d_ckpt *act;
    int seen;
} taps;

/* Every stage the forward pass reports is compared with the recorded one of that name. */
static void tap(void *user, const char *name, const float *x, int c, int h, int w)
{
    taps *t = user;
    char key[64];
    snprintf(key, sizeof key, "out.%s", name);
    golden_compare(t->act, key, x, (size_t)c * h * w);
    t->seen++;
}

static g3d_ckpt *open_golden(void)
{
    g3d_ckpt *act = NULL;
    CHECK_OK(g3d_ckpt_open(test_fixture("lama_tiny_golden.safetensors"), &act));
    return act;
}

TEST(generator_golden)
{
    g3d_ckpt *act = open_golden();
    g3d_lama *m = NULL;
    CHECK_OK(g3d_lama_load_file(test_fixture("lama_tiny.ckpt"), &m));
    if (!act || !m) goto done;
    char desc[256];
    printf("  %s\n", g3d_lama_describe(m, desc, sizeof desc));
    CHECK(strstr(desc, "4 -> 3 channels, width 8, 3 downsamplings, 2 residual blocks of 64 channels (48 global)") != NULL);
    const g3d_tensor_info *in = g3d_ckpt_find(act, "net.input");
    CHECK(in && in->ndim == 4 && in->shape[1] == 4);
    if (!in) goto done;
    const int h = (int)in->shape[2], w = (int)in->shape[3];
    float *x = NULL, *y = malloc(sizeof(float) * 3 * h * w);
    CHECK_OK(g3d_ckpt_read_alloc(act, "net.input", 0, NULL, &x));
    taps t = {act, 0};
    CHECK_OK(g3d_lama_forward(m, x, h, w, y, tap, &t));
    CHECK(t.seen == 1 + 3 + 2 + 3 + 1);
    /* a second pass reuses the arena and the FFT plans: the same numbers */
    float *y2 = malloc(sizeof(float) * 3 * h * w);
    CHECK_OK(g3d_lama_forward(m, x, h, w, y2, NULL, NULL));
    CHECK(y && y2 && memcmp(y, y2, sizeof(float) * 3 * h * w) == 0);
    /* sizes the network cannot take */
    CHECK_FAILS(g3d_lama_forward(m, x, h - 4, w, y, NULL, NULL));
    CHECK_FAILS(g3d_lama_forward(m, x, 8, 8, y, NULL, NULL));
    free(x);
    free(y);
    free(y2);
done:
    g3d_lama_free(m);
    g3d_ckpt_free(act);
}

/* The official predict pipeline: 45 x 37 picture padded to 48 x 40, faint mask pixels count
 * as holes (mask > 0), prediction pasted into the hole, cropped back. */
TEST(predict_pipeline)
{
    g3d_ckpt *act = open_golden();
    g3d_lama *m = NULL;
    CHECK_OK(g3d_lama_load_file(test_fixture("lama_tiny.ckpt"), &m));
    g3d_image img = {0}, mask = {0};
    int w = 0, h = 0;
    float *rgb = act ? golden_image(act, "input.image_u8", &w, &h) : NULL;
    if (!m || !rgb) goto done;
    CHECK_OK(g3d_image_create(&img, w, h, 3));
    CHECK_OK(g3d_image_create(&mask, w, h, 1));
    memcpy(img.data, rgb, sizeof(float) * 3 * w * h);
    float *m8 = NULL;
    CHECK_OK(g3d_ckpt_read_alloc(act, "input.mask_u8", 2, (int64_t[]){h, w}, &m8));
    if (!m8) goto done;
    /* the official binarisation (mask > 0) here; the plug-in's contract is mask > 0.5 */
    int64_t holes = 0;
    for (int i = 0; i < w * h; i++) holes += (mask.data[i] = m8[i] > 0 ? 1.0f : 0.0f) > 0;
    int64_t filled = -1;
    CHECK_OK(g3d_lama_inpaint(m, &img, &mask, &filled));
    CHECK(filled == holes);
    golden_compare(act, "out.inpainted", img.data, (size_t)3 * w * h);
    size_t changed = 0;
    for (int i = 0; i < w * h; i++)
        for (int k = 0; k < 3; k++)
            if (mask.data[i] == 0) changed += memcmp(&img.data[3 * i + k], &rgb[3 * i + k], sizeof(float)) != 0;
    CHECK_MSG(changed == 0, "%zu known values changed", changed);
    free(m8);
done:
    free(rgb);
    g3d_image_free(&img);
    g3d_image_free(&mask);
    g3d_lama_free(m);
    g3d_ckpt_free(act);
}

/* The generator with local Fourier units, on the square 64 x 64 input they need. */
TEST(local_fourier_unit)
{
    g3d_ckpt *act = open_golden();
    g3d_lama *m = NULL;
    CHECK_OK(g3d_lama_load_file(test_fixture("lama_tiny_lfu.ckpt"), &m));
    float *x = NULL, *y = malloc(sizeof(float) * 3 * 64 * 64);
    if (act) CHECK_OK(g3d_ckpt_read_alloc(act, "lfu.input", 4, (int64_t[]){1, 4, 64, 64}, &x));
    if (m && x && y) {
        char desc[256];
        CHECK(strstr(g3d_lama_describe(m, desc, sizeof desc), "local Fourier units") != NULL);
        CHECK_OK(g3d_lama_forward(m, x, 64, 64, y, NULL, NULL));
        golden_compare(act, "lfu.pred", y, 3 * 64 * 64);
        /* the official split only works on square maps */
        CHECK_FAILS(g3d_lama_forward(m, x, 32, 64, y, NULL, NULL));
        CHECK(strstr(g3d_error_message(), "square") != NULL);
    }
    free(x);
    free(y);
    g3d_lama_free(m);
    g3d_ckpt_free(act);
}

/* Checkpoints without (part of) a generator: each message names the tensor. */
TEST(refused_checkpoints)
{
    g3d_lama *m = (g3d_lama *)1;
    CHECK_FAILS(g3d_lama_load_file(test_fixture("dav2_tiny.pth"), &m));
    CHECK(m == NULL);
    CHECK(strstr(g3d_error_message(), "no LaMa generator") && strstr(g3d_error_message(), "generator.model.1.ffc.convl2l.weight"));
    unsigned char *file = NULL;
    size_t n = 0;
    CHECK_OK(g3d_read_file(test_fixture("lama_tiny.ckpt"), (size_t)1 << 24, &file, &n));
    if (!file) return;
    /* renamed in data.pkl (same length), so the loader finds them missing */
    const char *names[][2] = {
        {"generator.model.5.conv1.ffc.convg2g.fu.bn.running_var", "generator.model.5.conv1.ffc.convg2g.fu.bn.running_vaX"},
        {"generator.model.6.conv2.ffc.convl2g.weight", "generator.model.6.conv2.ffc.convl2g.weighX"},
        {"generator.model.9.running_mean", "generator.model.9.running_meaX"},
        {"generator.model.18.bias", "generator.model.18.biaX"},
    };
    for (size_t k = 0; k < sizeof names / sizeof *names; k++) {
        unsigned char *z = golden_edit_pickle(file, n, names[k][0], names[k][1]);
        g3d_ckpt *ck = NULL;
        if (z) CHECK_OK(g3d_ckpt_open_memory(z, n, "edited.ckpt", &ck));
        if (ck) {
            m = (g3d_lama *)1;
            CHECK_FAILS(g3d_lama_load(ck, &m));
            CHECK(m == NULL);
            CHECK_MSG(strstr(g3d_error_message(), names[k][0]) != NULL, "message does not name %s", names[k][0]);
        }
        g3d_ckpt_free(ck);
        free(z);
    }
    free(file);
}

/* Masks the pipeline refuses or skips. */
TEST(bad_masks)
{
    g3d_lama *m = NULL;
    CHECK_OK(g3d_lama_load_file(test_fixture("lama_tiny.ckpt"), &m));
    g3d_image img = {0}, mask = {0}, small = {0}, before = {0};
    if (!m) return;
    CHECK_OK(g3d_image_create(&img, 40, 24, 3));
    CHECK_OK(g3d_image_create(&mask, 40, 24, 1));
    for (size_t i = 0; i < (size_t)40 * 24 * 3; i++) img.data[i] = (float)(i % 251) / 250.0f;
    CHECK_OK(g3d_image_clone(&before, &img));
    int64_t filled = -1;
    /* empty: nothing to do, nothing changed */
    CHECK_OK(g3d_lama_inpaint(m, &img, &mask, &filled));
    CHECK(filled == 0 && memcmp(img.data, before.data, sizeof(float) * 40 * 24 * 3) == 0);
    /* full: refused, image untouched */
    for (int i = 0; i < 40 * 24; i++) mask.data[i] = 1;
    CHECK_FAILS(g3d_lama_inpaint(m, &img, &mask, &filled));
    CHECK(strstr(g3d_error_message(), "every pixel") != NULL);
    CHECK(memcmp(img.data, before.data, sizeof(float) * 40 * 24 * 3) == 0);
    /* another size */
    CHECK_OK(g3d_image_create(&small, 20, 24, 1));
    small.data[0] = 1;
    CHECK_FAILS(g3d_lama_inpaint(m, &img, &small, &filled));
    g3d_image_free(&small);
    /* too small a picture */
    g3d_image tiny = {0}, tmask = {0};
    CHECK_OK(g3d_image_create(&tiny, 12, 30, 3));
    CHECK_OK(g3d_image_create(&tmask, 12, 30, 1));
    tmask.data[5] = 1;
    CHECK_FAILS(g3d_lama_inpaint(m, &tiny, &tmask, &filled));
    g3d_image_free(&tiny);
    g3d_image_free(&tmask);
    g3d_image_free(&img);
    g3d_image_free(&mask);
    g3d_image_free(&before);
    g3d_lama_free(m);
}

int main(void)
{
    RUN(generator_golden);
    RUN(predict_pipeline);
    RUN(local_fourier_unit);
    RUN(refused_checkpoints);
    RUN(bad_masks);
    return test_summary();
}
