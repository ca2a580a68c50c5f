/* Segment Anything against the official code (tests/fixtures/make_sam_golden.py): every block of
 * the image encoder, the prompt encoder and decoder for a point, a box and a mask prompt, the
 * predictor's masks, the automatic generator's masks; and refused input. */
#include "golden.h"
#include "testutil.h"

#include "gen3d/ckpt.h"
#include "gen3d/resize.h"
#include "gen3d/sam.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static g3d_ckpt *act;
static g3d_sam *model;
static g3d_sam_image image;
static uint8_t *rgb;
static int W, H;

static float *tensor(const char *name, size_t n)
{
    float *v = NULL;
    const g3d_tensor_info *t = g3d_ckpt_find(act, name);
    CHECK_MSG(t && (size_t)t->numel == n, "%s: missing or not %zu values", name, n);
    if (t && (size_t)t->numel == n) CHECK_OK(g3d_ckpt_read_alloc(act, name, 0, NULL, &v));
    return v;
}

/* Thresholded masks [n, h, w] against the recorded ones: a pixel may differ only where the
 * recorded logit is within 1e-4 of the largest logit's size from 0 (the sign of a value that
 * close to 0 is within float rounding); counts such pixels. */
static void compare_masks(const char *name, const uint8_t *got, const char *logits, size_t n)
{
    float *ref = tensor(name, n), *lg = tensor(logits, n);
    if (!ref || !lg) goto done;
    float big = 0;
    for (size_t i = 0; i < n; i++) big = fabsf(lg[i]) > big ? fabsf(lg[i]) : big;
    size_t flips = 0, bad = 0;
    for (size_t i = 0; i < n; i++)
        if ((got[i] != 0) != (ref[i] != 0)) {
            if (fabsf(lg[i]) <= 1e-4f * big)
                flips++;
            else
                bad++;
        }
    printf("  %-22s %zu pixels differ at |logit| <= 1e-4 max\n", name, flips);
    CHECK_MSG(bad == 0, "%s: %zu mask pixels differ away from a zero logit", name, bad);
done:
    free(ref);
    free(lg);
}

TEST(encoder)
{
    char desc[256];
    printf("  %s\n", g3d_sam_describe(model, desc, sizeof desc));
    CHECK(strstr(desc, "width 32, 4 blocks (2 global, windows of 14), 2 heads, input 256") != NULL);
    g3d_sam_trace tr = {.want = 1};
    g3d_sam_image img;
    CHECK_OK(g3d_sam_set_image(model, rgb, W, H, &img, &tr));
    CHECK(img.in_w == 256 && img.in_h == 181 && img.grid == 16 && img.c == 32);
    golden_compare(act, "enc.input", tr.input, 3 * 256 * 256);
    golden_compare(act, "enc.patch_embed", tr.patch_embed, 16 * 16 * 32);
    for (int i = 0; i < 4 && tr.block; i++) {
        char name[32];
        snprintf(name, sizeof name, "enc.block%d", i);
        golden_compare(act, name, tr.block[i], 16 * 16 * 32);
    }
    golden_compare(act, "enc.neck", tr.neck, 32 * 16 * 16);
    g3d_sam_trace_free(&tr);
    g3d_sam_image_free(&img);
}

static void check_prompt(const char *name, const g3d_sam_prompt *p)
{
    g3d_sam_trace tr = {.want = 1};
    g3d_sam_prediction pr;
    char key[64];
    CHECK_OK(g3d_sam_predict(model, &image, p, 1, &pr, &tr));
    if (!pr.logits) return;
    CHECK(pr.n == 3 && pr.w == W && pr.h == H && pr.low == 64);
    snprintf(key, sizeof key, "%s.sparse", name);
    golden_compare(act, key, tr.sparse, (size_t)tr.nsparse * 32);
    snprintf(key, sizeof key, "%s.dense", name);
    golden_compare(act, key, tr.dense, 32 * 16 * 16);
    snprintf(key, sizeof key, "%s.tokens", name);
    golden_compare(act, key, tr.tokens, (size_t)tr.ntokens * 32);
    snprintf(key, sizeof key, "%s.keys", name);
    golden_compare(act, key, tr.keys, 16 * 16 * 32);
    snprintf(key, sizeof key, "%s.low_res", name);
    golden_compare(act, key, pr.low_res, 3 * 64 * 64);
    snprintf(key, sizeof key, "%s.iou", name);
    golden_compare(act, key, pr.iou, 3);
    snprintf(key, sizeof key, "%s.logits", name);
    golden_compare(act, key, pr.logits, (size_t)3 * W * H);
    uint8_t *m = malloc((size_t)3 * W * H);
    for (size_t i = 0; m && i < (size_t)3 * W * H; i++) m[i] = pr.logits[i] > 0;
    char lk[64];
    snprintf(key, sizeof key, "%s.masks", name);
    snprintf(lk, sizeof lk, "%s.logits", name);
    if (m) compare_masks(key, m, lk, (size_t)3 * W * H);
    free(m);
    g3d_sam_prediction_free(&pr);
    g3d_sam_trace_free(&tr);
}

TEST(prompts)
{
    float *pts = tensor("point.coords", 4), *box = tensor("box.box", 4), *low = tensor("point.low_res", 3 * 64 * 64);
    float *iou = tensor("point.iou", 3);
    int labels[2] = {1, 0};
    if (!pts || !box || !low || !iou) goto done;
    g3d_sam_prompt point = {2, pts, labels, NULL, NULL}, boxp = {0, NULL, NULL, box, NULL};
    check_prompt("point", &point);
    check_prompt("box", &boxp);
    int best = 0;
    for (int k = 1; k < 3; k++)
        if (iou[k] > iou[best]) best = k;
    g3d_sam_prompt withmask = {2, pts, labels, NULL, low + (size_t)best * 64 * 64};
    check_prompt("mask", &withmask);
    g3d_sam_prediction pr;
    g3d_sam_prompt empty = {0};
    CHECK_FAILS(g3d_sam_predict(model, &image, &empty, 1, &pr, NULL));
done:
    free(pts); free(box); free(low); free(iou);
}

/* The generator's masks: the same masks pixel for pixel, in the same order, with the same
 * scores, boxes and areas (min_area: the small-region clean-up). */
static void check_generator(const char *prefix, float nms, int min_area)
{
    g3d_sam_amg_params p;
    g3d_sam_amg_params_default(&p);
    p.points_per_side = 4;
    p.stability_score_thresh = 0.15f;
    p.box_nms_thresh = nms;
    p.min_mask_region_area = min_area;
    g3d_sam_masks mk;
    CHECK_OK(g3d_sam_generate(model, &image, &p, NULL, &mk));
    char key[64];
    snprintf(key, sizeof key, "%s.masks", prefix);
    const g3d_tensor_info *t = g3d_ckpt_find(act, key);
    CHECK(t && t->ndim == 3);
    if (!t || t->ndim != 3) return;
    int n = (int)t->shape[0];
    printf("  %s: %d masks (recorded %d)\n", prefix, mk.n, n);
    CHECK(mk.n == n && mk.w == W && mk.h == H);
    size_t npx = (size_t)W * H;
    float *ref = tensor(key, (size_t)n * npx);
    snprintf(key, sizeof key, "%s.iou", prefix);
    if (mk.n == n) golden_compare(act, key, mk.iou, (size_t)n);
    if (mk.n == n && !strcmp(prefix, "amg")) golden_compare(act, "amg.stability", mk.stability, (size_t)n);
    snprintf(key, sizeof key, "%s.area", prefix);
    if (mk.n == n && g3d_ckpt_find(act, key)) {
        float *fa = tensor(key, (size_t)n);
        snprintf(key, sizeof key, "%s.boxes", prefix);
        float *fb = tensor(key, 4 * (size_t)n);
        for (int i = 0; fa && fb && i < n; i++) {
            CHECK_MSG(mk.area[i] == (int)fa[i], "%s mask %d: area %d, recorded %d", prefix, i, mk.area[i], (int)fa[i]);
            for (int k = 0; k < 4; k++) CHECK(mk.boxes[4 * i + k] == (int)fb[4 * i + k]);
        }
        free(fa);
        free(fb);
    }
    size_t differ = 0;
    for (int i = 0; ref && mk.n == n && i < n; i++)
        for (size_t j = 0; j < npx; j++) differ += (mk.masks[i * npx + j] != 0) != (ref[i * npx + j] != 0);
    printf("  %s: %zu mask pixels differ\n", prefix, differ);
    /* a pixel could only flip at a logit within float rounding of 0; none does on this fixture */
    CHECK_MSG(differ == 0, "%zu mask pixels differ", differ);
    free(ref);
    g3d_sam_masks_free(&mk);
}

TEST(generator)
{
    check_generator("amg", 1.0f, 0);
    check_generator("amg_nms", 0.7f, 0);
    check_generator("amg_small", 1.0f, 6);
    g3d_sam_amg_params p;
    g3d_sam_amg_params_default(&p);
    p.points_per_side = 0;
    g3d_sam_masks mk;
    CHECK_FAILS(g3d_sam_generate(model, &image, &p, NULL, &mk));
}

/* PIL's bilinear resize, which the preprocessing uses, on the recorded picture. */
TEST(pil_resize)
{
    uint8_t *a = malloc(256 * 181 * 3);
    float *in = tensor("enc.input", 3 * 256 * 256);
    if (!a || !in) goto done;
    CHECK_OK(g3d_resize_u8_pil_bilinear(rgb, W, H, 3, a, 256, 181));
    static const float mean[3] = {123.675f, 116.28f, 103.53f}, sd[3] = {58.395f, 57.12f, 57.375f};
    size_t bad = 0;
    for (int c = 0; c < 3; c++)
        for (int y = 0; y < 256; y++)
            for (int x = 0; x < 256; x++) {
                float want = in[((size_t)c * 256 + y) * 256 + x];
                float v = y < 181 ? ((float)a[((size_t)y * 256 + x) * 3 + c] - mean[c]) / sd[c] : 0.0f;
                bad += v != want;
            }
    CHECK_MSG(bad == 0, "%zu preprocessed values differ from the official ones", bad);
    /* shrinking 300 x 170 to 256 x 145 (the antialiasing filter spans more than two pixels) */
    float *src = tensor("resize.src_u8", 170 * 300 * 3), *want = tensor("resize.out_u8", 145 * 256 * 3);
    uint8_t *s8 = malloc(170 * 300 * 3);
    if (src && want && s8) {
        for (int i = 0; i < 170 * 300 * 3; i++) s8[i] = (uint8_t)src[i];
        CHECK_OK(g3d_resize_u8_pil_bilinear(s8, 300, 170, 3, a, 256, 145));
        bad = 0;
        for (int i = 0; i < 145 * 256 * 3; i++) bad += a[i] != (uint8_t)want[i];
        CHECK_MSG(bad == 0, "%zu shrunk values differ from PIL's", bad);
    }
    free(src);
    free(want);
    free(s8);
    CHECK_FAILS(g3d_resize_u8_pil_bilinear(rgb, 0, H, 3, a, 256, 181));
done:
    free(a);
    free(in);
}

TEST(refused)
{
    g3d_sam *m = (g3d_sam *)1;
    CHECK_FAILS(g3d_sam_load_file(test_fixture("dav2_tiny.pth"), &m));
    CHECK(m == NULL && strstr(g3d_error_message(), "not a Segment Anything checkpoint"));
    CHECK_FAILS(g3d_sam_load_file(test_fixture("truncated.pth"), &m));
    unsigned char *file = NULL;
    size_t n = 0;
    CHECK_OK(g3d_read_file(test_fixture("sam_tiny.pth"), (size_t)1 << 24, &file, &n));
    if (!file) return;
    const char *names[][2] = {
        {"image_encoder.blocks.2.attn.rel_pos_w", "image_encoder.blocks.2.attn.rel_pos_X"},
        {"mask_decoder.transformer.layers.1.cross_attn_image_to_token.v_proj.bias",
         "mask_decoder.transformer.layers.1.cross_attn_image_to_token.v_proj.biaX"},
        {"prompt_encoder.mask_downscaling.4.bias", "prompt_encoder.mask_downscaling.4.biaX"},
    };
    for (size_t k = 0; k < sizeof names / sizeof *names; k++) {
        unsigned char *z = golden_edit_pickle(file, n, names[k][0], names[k][1]);
        g3d_ckpt *ck = NULL;
        if (z) CHECK_OK(g3d_ckpt_open_memory(z, n, "edited.pth", &ck));
        if (ck) {
            m = (g3d_sam *)1;
            CHECK_FAILS(g3d_sam_load(ck, &m));
            CHECK(m == NULL);
            CHECK_MSG(strstr(g3d_error_message(), names[k][0]) != NULL, "message does not name %s", names[k][0]);
        }
        g3d_ckpt_free(ck);
        free(z);
    }
    free(file);
    g3d_sam_image img;
    CHECK_FAILS(g3d_sam_set_image(model, rgb, 0, 10, &img, NULL));
    CHECK_FAILS(g3d_sam_set_image(model, rgb, 40000, 10, &img, NULL));
}

int main(void)
{
    CHECK_OK(g3d_ckpt_open(test_fixture("sam_tiny_golden.safetensors"), &act));
    CHECK_OK(g3d_sam_load_file(test_fixture("sam_tiny.pth"), &model));
    const g3d_tensor_info *t = act ? g3d_ckpt_find(act, "input.image_rgb_u8") : NULL;
    CHECK(t && t->ndim == 3 && t->shape[2] == 3);
    if (!act || !model || !t) return test_summary();
    H = (int)t->shape[0];
    W = (int)t->shape[1];
    rgb = malloc((size_t)W * H * 3);
    float *f = tensor("input.image_rgb_u8", (size_t)W * H * 3);
    for (size_t i = 0; f && rgb && i < (size_t)W * H * 3; i++) rgb[i] = (uint8_t)f[i];
    free(f);
    CHECK_OK(g3d_sam_set_image(model, rgb, W, H, &image, NULL));
    RUN(pil_resize);
    RUN(encoder);
    RUN(prompts);
    RUN(generator);
    RUN(refused);
    g3d_sam_image_free(&image);
    g3d_sam_free(model);
    g3d_ckpt_free(act);
    free(rgb);
    return test_summary();
}
