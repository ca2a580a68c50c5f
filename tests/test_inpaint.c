/* Exemplar inpainting: periodic textures are continued, real texture is not smeared, outside
 * pixels are untouched, results are deterministic. */
#include "testutil.h"
#include "gen3d/imageio.h"
#include "gen3d/inpaint_classic.h"
#include "gen3d/resize.h"

static double mae_in(const g3d_image *a, const g3d_image *b, const g3d_image *mask)
{
    double s = 0;
    size_t n = 0;
    for (size_t i = 0; i < (size_t)a->w * a->h; i++)
        if (mask->data[i] > 0.5f) { for (int c = 0; c < 3; c++) s += fabs(a->data[3 * i + c] - b->data[3 * i + c]); n += 3; }
    return s / n;
}

/* Mean gradient magnitude inside the mask: a blur or smear has little of it. */
static double texture_energy(const g3d_image *a, const g3d_image *mask)
{
    double s = 0;
    size_t n = 0;
    for (int y = 0; y < a->h - 1; y++)
        for (int x = 0; x < a->w - 1; x++) {
            size_t i = (size_t)y * a->w + x;
            if (mask->data[i] < 0.5f) continue;
            for (int c = 0; c < 3; c++)
                s += fabs(a->data[3 * (i + 1) + c] - a->data[3 * i + c]) + fabs(a->data[3 * (i + a->w) + c] - a->data[3 * i + c]);
            n++;
        }
    return s / n;
}

TEST(periodic_texture)
{
    /* Bricks: a pattern the smooth fill cannot continue but patches can. */
    int w = 128, h = 96;
    g3d_image truth, img, smooth, mask;
    g3d_image_create(&truth, w, h, 3);
    g3d_image_create(&mask, w, h, 1);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            int row = y / 8, xs = x + (row & 1) * 8;
            int mortar = y % 8 == 0 || xs % 16 == 0;
            float *p = g3d_image_px(&truth, x, y);
            p[0] = mortar ? 0.85f : 0.6f;
            p[1] = mortar ? 0.85f : 0.25f;
            p[2] = mortar ? 0.8f : 0.2f;
            int centre = (x - 60) * (x - 60) + (y - 40) * (y - 40) < 18 * 18, border = x >= w - 30;
            mask.data[(size_t)y * w + x] = (float)(centre || border);
        }
    g3d_image_clone(&img, &truth);
    g3d_image_clone(&smooth, &truth);
    for (size_t i = 0; i < (size_t)w * h; i++)
        if (mask.data[i] > 0.5f) for (int c = 0; c < 3; c++) img.data[3 * i + c] = smooth.data[3 * i + c] = 0;
    CHECK_OK(g3d_inpaint_patchmatch(&img, &mask, NULL, 1));
    CHECK_OK(g3d_inpaint_smooth(&smooth, &mask));
    double e_pm = mae_in(&img, &truth, &mask), e_smooth = mae_in(&smooth, &truth, &mask);
    double t_truth = texture_energy(&truth, &mask), t_pm = texture_energy(&img, &mask), t_sm = texture_energy(&smooth, &mask);
    printf("  bricks: mean abs error %.4f (smooth fill %.4f); texture energy %.3f vs truth %.3f (smooth %.3f)\n", e_pm,
           e_smooth, t_pm, t_truth, t_sm);
    CHECK(e_pm * 2 < e_smooth);
    CHECK(t_pm > 0.6 * t_truth && t_sm < 0.3 * t_truth);
    g3d_image_save_png(test_tmp("inpaint_bricks.png"), &img, 8);
    /* Outside the mask nothing changed, bit for bit. */
    int same = 1;
    for (size_t i = 0; i < (size_t)w * h; i++)
        if (mask.data[i] < 0.5f) same &= !memcmp(img.data + 3 * i, truth.data + 3 * i, 12);
    CHECK(same);
    g3d_image_free(&truth); g3d_image_free(&img); g3d_image_free(&smooth); g3d_image_free(&mask);
}

TEST(real_photo_border_band)
{
    g3d_image full, truth, img, smooth, mask;
    CHECK_OK(g3d_image_load(test_shared("testdata/demo_inputs/images/wj_58_woodland.png"), 3, &full));
    if (!full.data) return;
    CHECK_OK(g3d_image_resize(&full, 256, 256 * full.h / full.w, G3D_RESIZE_AREA, &truth));
    g3d_image_free(&full);
    int w = truth.w, h = truth.h;
    g3d_image_create(&mask, w, h, 1);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) mask.data[(size_t)y * w + x] = (float)(x < w * 3 / 10);
    g3d_image_clone(&img, &truth);
    g3d_image_clone(&smooth, &truth);
    CHECK_OK(g3d_inpaint_patchmatch(&img, &mask, NULL, 7));
    CHECK_OK(g3d_inpaint_smooth(&smooth, &mask));
    double t_truth = texture_energy(&truth, &mask), t_pm = texture_energy(&img, &mask), t_sm = texture_energy(&smooth, &mask);
    printf("  woodland, 30 %% border band: texture energy %.4f, truth %.4f, smooth fill %.4f\n", t_pm, t_truth, t_sm);
    /* A smear or blur has a small fraction of the real texture energy; the exemplar fill keeps
     * most of it, without inventing noise far beyond it. */
    CHECK(t_pm > 0.6 * t_truth && t_pm < 1.5 * t_truth);
    CHECK(t_sm < 0.25 * t_truth);
    g3d_image_save_png(test_tmp("inpaint_woodland.png"), &img, 8);

    /* Determinism: the same seed gives the same pixels. */
    g3d_image again;
    g3d_image_clone(&again, &truth);
    CHECK_OK(g3d_inpaint_patchmatch(&again, &mask, NULL, 7));
    CHECK(!memcmp(again.data, img.data, g3d_image_size(&img) * sizeof(float)));
    g3d_image_free(&again);
    g3d_image_free(&truth); g3d_image_free(&img); g3d_image_free(&smooth); g3d_image_free(&mask);
}

TEST(edge_cases)
{
    g3d_image img, mask, bad;
    g3d_image_create(&img, 40, 30, 3);
    g3d_image_create(&mask, 40, 30, 1);
    for (size_t i = 0; i < g3d_image_size(&img); i++) img.data[i] = (float)(i % 7) / 7;
    g3d_image before;
    g3d_image_clone(&before, &img);
    CHECK_OK(g3d_inpaint_patchmatch(&img, &mask, NULL, 0)); /* empty mask: unchanged */
    CHECK(!memcmp(before.data, img.data, g3d_image_size(&img) * sizeof(float)));
    /* A one-pixel crack and a hole covering 70 % of the image. */
    mask.data[15 * 40 + 20] = 1;
    CHECK_OK(g3d_inpaint_patchmatch(&img, &mask, NULL, 0));
    for (size_t i = 0; i < g3d_image_size(&mask); i++) mask.data[i] = (float)(i % 40 >= 12);
    CHECK_OK(g3d_inpaint_patchmatch(&img, &mask, NULL, 0));
    for (size_t i = 0; i < g3d_image_size(&img); i++) CHECK(isfinite(img.data[i]) && img.data[i] >= 0 && img.data[i] <= 1);
    for (size_t i = 0; i < g3d_image_size(&mask); i++) mask.data[i] = 1;
    CHECK_FAILS(g3d_inpaint_patchmatch(&img, &mask, NULL, 0));
    g3d_image_create(&bad, 41, 30, 1);
    CHECK_FAILS(g3d_inpaint_patchmatch(&img, &bad, NULL, 0));
    g3d_inpainter ip;
    CHECK_OK(g3d_inpainter_classic_create(NULL, &ip));
    mask.data[5] = 0;
    for (size_t i = 0; i < g3d_image_size(&mask); i++) mask.data[i] = (float)(i % 40 < 5);
    CHECK_OK(ip.inpaint(ip.ctx, &img, &mask, "a prompt", 3));
    ip.free(ip.ctx);
    g3d_image_free(&img); g3d_image_free(&mask); g3d_image_free(&bad); g3d_image_free(&before);
}

int main(void)
{
    RUN(periodic_texture);
    RUN(real_photo_border_band);
    RUN(edge_cases);
    return test_summary();
}
