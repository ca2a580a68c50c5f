/* The automatic prompts: CIELAB conversion, colour names, k-means colours over a mask,
 * category files, the template, and the whole description with the tiny CLIP fixture. */
#include "testutil.h"

#include "gen3d/describe.h"
#include "gen3d/imageio.h"

TEST(lab)
{
    /* reference values of the CIE formulas (D65) for sRGB white, red and mid grey */
    float white[3] = {1, 1, 1}, red[3] = {1, 0, 0}, grey[3] = {0.5f, 0.5f, 0.5f}, l[3], back[3];
    g3d_srgb_to_lab(white, l);
    CHECK(fabsf(l[0] - 100) < 1e-3f && fabsf(l[1]) < 1e-2f && fabsf(l[2]) < 1e-2f);
    g3d_srgb_to_lab(red, l);
    CHECK_MSG(fabsf(l[0] - 53.24f) < 0.02f && fabsf(l[1] - 80.09f) < 0.05f && fabsf(l[2] - 67.20f) < 0.05f, "red: %g %g %g", l[0], l[1], l[2]);
    g3d_srgb_to_lab(grey, l);
    CHECK_MSG(fabsf(l[0] - 53.39f) < 0.02f && fabsf(l[1]) < 1e-2f, "grey: %g %g %g", l[0], l[1], l[2]);
    g3d_rng r;
    g3d_rng_seed(&r, 5, 0);
    for (int i = 0; i < 200; i++) {
        float c[3] = {g3d_rng_float(&r), g3d_rng_float(&r), g3d_rng_float(&r)};
        g3d_srgb_to_lab(c, l);
        g3d_lab_to_srgb(l, back);
        CHECK(fabsf(back[0] - c[0]) < 1e-4f && fabsf(back[1] - c[1]) < 1e-4f && fabsf(back[2] - c[2]) < 1e-4f);
    }
    float navy[3] = {20 / 255.f, 30 / 255.f, 80 / 255.f}, nearwhite[3] = {0.97f, 0.98f, 0.99f};
    g3d_srgb_to_lab(navy, l);
    CHECK(!strcmp(g3d_color_name(l), "navy"));
    g3d_srgb_to_lab(nearwhite, l);
    CHECK(!strcmp(g3d_color_name(l), "white"));
}

/* 40x20: left half red, right quarter navy, the rest beige; the mask covers the beige part. */
static void stripes(g3d_image *img, g3d_image *mask)
{
    CHECK_OK(g3d_image_create(img, 40, 20, 3));
    CHECK_OK(g3d_image_create(mask, 40, 20, 1));
    static const float col[3][3] = {{200 / 255.f, 30 / 255.f, 30 / 255.f}, {20 / 255.f, 30 / 255.f, 80 / 255.f},
                                    {220 / 255.f, 205 / 255.f, 170 / 255.f}};
    for (int y = 0; y < 20; y++)
        for (int x = 0; x < 40; x++) {
            int k = x < 20 ? 0 : x >= 30 ? 1 : 2;
            memcpy(g3d_image_px(img, x, y), col[k], sizeof col[k]);
            *g3d_image_px(mask, x, y) = k == 2;
        }
}

TEST(kmeans)
{
    g3d_image img, mask;
    stripes(&img, &mask);
    g3d_color c[G3D_MAX_COLORS], again[G3D_MAX_COLORS];
    int n = 0, m = 0;
    CHECK_OK(g3d_dominant_colors(&img, NULL, 3, 1, c, &n));
    CHECK(n == 3 && !strcmp(c[0].name, "red") && fabsf(c[0].share - 0.5f) < 1e-6f && fabsf(c[1].share - 0.25f) < 1e-6f);
    CHECK(n == 3 && !strcmp(c[1].name, "navy") && !strcmp(c[2].name, "beige") && fabsf(c[0].rgb[0] - 200 / 255.f) < 1e-4f);
    /* only two colours outside the mask: a third cluster cannot be seeded */
    CHECK_OK(g3d_dominant_colors(&img, &mask, 5, 1, c, &n));
    CHECK(n == 2 && fabsf(c[0].share - 2 / 3.f) < 1e-6f && !strcmp(c[0].name, "red") && !strcmp(c[1].name, "navy"));
    /* deterministic for a seed on a noisy picture */
    g3d_rng r;
    g3d_rng_seed(&r, 9, 0);
    for (size_t i = 0; i < g3d_image_size(&img); i++) img.data[i] = g3d_rng_float(&r);
    CHECK_OK(g3d_dominant_colors(&img, NULL, 4, 7, c, &n));
    CHECK_OK(g3d_dominant_colors(&img, NULL, 4, 7, again, &m));
    /* field by field: the struct's padding bytes carry no value */
    int same = n == 4 && m == 4;
    for (int i = 0; same && i < n; i++)
        same = !memcmp(c[i].lab, again[i].lab, sizeof c[i].lab) && !memcmp(c[i].rgb, again[i].rgb, sizeof c[i].rgb) &&
               c[i].share == again[i].share && c[i].name == again[i].name;
    CHECK(same);
    float total = 0;
    for (int i = 0; i < n; i++) total += c[i].share;
    CHECK(fabsf(total - 1) < 1e-5f && c[0].share >= c[1].share && c[1].share >= c[2].share);
    for (size_t i = 0; i < g3d_image_size(&mask); i++) mask.data[i] = 1;
    CHECK(g3d_dominant_colors(&img, &mask, 3, 1, c, &n) == G3D_ERR_ARG && n == 0);
    CHECK(g3d_dominant_colors(&img, NULL, G3D_MAX_COLORS + 1, 1, c, &n) == G3D_ERR_ARG);
    g3d_image_free(&img);
    g3d_image_free(&mask);
}

TEST(categories_and_template)
{
    int n;
    const char *const *builtin = g3d_scene_categories(&n);
    CHECK(n > 60 && !strcmp(builtin[0], "living room"));
    const char *path = test_tmp("categories.txt");
    const char *text = "# rooms\n  kitchen \n\nliving room\r\nbeach";
    CHECK_OK(g3d_write_file_atomic(path, text, strlen(text)));
    char **labels = NULL;
    CHECK_OK(g3d_scene_categories_load(path, &labels, &n));
    CHECK(n == 3 && labels && !strcmp(labels[0], "kitchen") && !strcmp(labels[1], "living room") && !strcmp(labels[2], "beach"));
    g3d_scene_categories_free(labels, n);
    CHECK_OK(g3d_write_file_atomic(path, "\n  \n# none\n", 11));
    CHECK(g3d_scene_categories_load(path, &labels, &n) == G3D_ERR_FORMAT && !labels && n == 0);
    CHECK(strstr(g3d_error_message(), "no categories"));
    const char *cols[3] = {"white", "beige", "brown"};
    char *p = g3d_background_prompt("kitchen", cols, 3);
    CHECK(p && !strcmp(p, "high-resolution kitchen background with white, beige and brown colors, photorealistic, 8K"));
    free(p);
    p = g3d_background_prompt("beach", cols, 1);
    CHECK(p && !strcmp(p, "high-resolution beach background with white colors, photorealistic, 8K"));
    free(p);
}

TEST(describe)
{
    g3d_clip *clip = NULL;
    g3d_clip_tokenizer *tok = NULL;
    CHECK_OK(g3d_clip_load(test_fixture("clip_vit_tiny_hf.safetensors"), &clip));
    CHECK_OK(g3d_clip_tokenizer_load(test_fixture("cliptok_merges.txt.gz"), &tok));
    g3d_image img = {0};
    CHECK_OK(g3d_image_load(test_fixture("clip_image.png"), 3, &img));
    if (!clip || !tok || !img.data) return;
    const char *labels[4] = {"kitchen", "beach", "forest path", "attic"};
    g3d_description d;
    CHECK_OK(g3d_describe_scene(clip, tok, &img, NULL, labels, 4, 3, 0, &d));
    float probs[4], emb[32];
    CHECK_OK(g3d_clip_encode_image(clip, &img, emb, NULL));
    CHECK_OK(g3d_clip_zero_shot(clip, tok, emb, labels, 4, G3D_SCENE_PROMPT, NULL, probs));
    int best = 0;
    for (int i = 1; i < 4; i++) best = probs[i] > probs[best] ? i : best;
    CHECK(d.ncat == 3 && !strcmp(d.category[0], labels[best]) && d.prob[0] == probs[best] && d.prob[0] >= d.prob[1] &&
          d.prob[1] >= d.prob[2]);
    CHECK(d.ncolors == 5 && d.background_prompt && strstr(d.background_prompt, labels[best]) &&
          strstr(d.background_prompt, d.colors[0].name));
    g3d_description_free(&d);
    CHECK_OK(g3d_describe_scene(NULL, NULL, &img, NULL, NULL, 0, 3, 0, &d));
    CHECK(d.ncat == 0 && d.background_prompt && !strncmp(d.background_prompt, "high-resolution scene background with ", 38));
    g3d_description_free(&d);
    g3d_image_free(&img);
    g3d_clip_tokenizer_free(tok);
    g3d_clip_free(clip);
}

int main(void)
{
    RUN(lab);
    RUN(kmeans);
    RUN(categories_and_template);
    RUN(describe);
    return test_summary();
}
