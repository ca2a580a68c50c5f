/* Tests of the weight-free inpainter: periodic textures against a diffusion fill, texture
 * statistics on a real photo, determinism, untouched known pixels, error paths. */
#include "gen3d/imageio.h"
#include "gen3d/inpaint_classic.h"
#include "testutil.h"


/* Brick-like periodic texture: mortar lines every 8 rows, offset bricks, two colours. */
static void make_texture(g3d_image *im, int kind)
{
    for (int y = 0; y < im->h; y++)
        for (int x = 0; x < im->w; x++) {
            float *v = g3d_image_px(im, x, y);
            float a;
            if (kind == 0) a = (x / 4) % 2 ? 0.9f : 0.1f;                       /* stripes */
            else if (kind == 1) a = ((x / 5) + (y / 5)) % 2 ? 0.85f : 0.15f;    /* checker */
            else {                                                              /* bricks */
                int row = y / 8, off = (row % 2) * 8;
                a = (y % 8 == 0 || (x + off) % 16 == 0) ? 0.2f : 0.75f;
            }
            v[0] = a;
            v[1] = 0.5f * a + 0.2f;
            v[2] = 1.f - a;
        }
}

static void mask_rect(g3d_image *m, int x0, int y0, int x1, int y1)
{
    for (int y = y0; y < y1; y++)
        for (int x = x0; x < x1; x++) m->data[(size_t)y * m->w + x] = 1.f;
}

static double hole_mae(const g3d_image *a, const g3d_image *b, const g3d_image *m)
{
    double s = 0;
    size_t n = 0;
    for (size_t i = 0; i < (size_t)a->w * a->h; i++)
        if (m->data[i] > 0.5f) {
            for (int k = 0; k < a->c; k++) s += fabs(a->data[i * a->c + k] - b->data[i * a->c + k]);
            n += a->c;
        }
    return s / (double)n;
}

/* Every pixel outside the mask must be bit-identical. */
static int outside_identical(const g3d_image *a, const g3d_image *b, const g3d_image *m)
{
    for (size_t i = 0; i < (size_t)a->w * a->h; i++)
        if (!(m->data[i] > 0.5f) && memcmp(a->data + i * a->c, b->data + i * a->c, a->c * sizeof(float))) return 0;
    return 1;
}

static void known_answer(int kind, int border)
{
    g3d_image truth, pm, df, m;
    CHECK_OK(g3d_image_create(&truth, 96, 96, 3));
    CHECK_OK(g3d_image_create(&m, 96, 96, 1));
    make_texture(&truth, kind);
    if (border) mask_rect(&m, 66, 0, 96, 96); /* 31 % band along the right side */
    else mask_rect(&m, 30, 34, 62, 60);
    CHECK_OK(g3d_image_clone(&pm, &truth));
    CHECK_OK(g3d_image_clone(&df, &truth));
    for (size_t i = 0; i < 96 * 96; i++)
        if (m.data[i] > 0.5f) pm.data[3 * i] = pm.data[3 * i + 1] = pm.data[3 * i + 2] = df.data[3 * i] =
            df.data[3 * i + 1] = df.data[3 * i + 2] = 0.5f;
    CHECK_OK(g3d_inpaint_patchmatch(&pm, &m, NULL, 7));
    CHECK_OK(g3d_inpaint_diffusion(&df, &m));
    double e_pm = hole_mae(&pm, &truth, &m), e_df = hole_mae(&df, &truth, &m);
    printf("       texture %d %s: MAE patchmatch %.4f, diffusion %.4f\n", kind, border ? "border" : "centre", e_pm,
           e_df);
    /* A periodic texture is fully explained by its known part: the exemplar fill must be far
     * better (over 3x) than the smooth fill, which sits at about half the contrast everywhere;
     * bricks allow a phase-shifted but equally plausible course, hence not ~0 error. */
    CHECK_MSG(e_pm < 0.3 * e_df, "MAE %.4f vs diffusion %.4f", e_pm, e_df);
    CHECK(e_pm < 0.05);
    CHECK(outside_identical(&pm, &truth, &m));
    CHECK(outside_identical(&df, &truth, &m));
    g3d_image_free(&truth);
    g3d_image_free(&pm);
    g3d_image_free(&df);
    g3d_image_free(&m);
}

TEST(stripes) { known_answer(0, 0); known_answer(0, 1); }
TEST(checker) { known_answer(1, 0); known_answer(1, 1); }
TEST(bricks) { known_answer(2, 0); known_answer(2, 1); }

/* Loads a photo, box-downsampled by `f` to keep the test quick. */
static int load_photo(const char *path, int f, g3d_image *out)
{
    g3d_image im;
    if (g3d_image_load(path, 3, &im) != G3D_OK) return 0;
    if (g3d_image_create(out, im.w / f, im.h / f, 3) != G3D_OK) {
        g3d_image_free(&im);
        return 0;
    }
    for (int y = 0; y < out->h; y++)
        for (int x = 0; x < out->w; x++)
            for (int k = 0; k < 3; k++) {
                float s = 0;
                for (int j = 0; j < f; j++)
                    for (int i = 0; i < f; i++) s += g3d_image_px(&im, x * f + i, y * f + j)[k];
                g3d_image_px(out, x, y)[k] = s / (float)(f * f);
            }
    g3d_image_free(&im);
    return 1;
}

/* Mean gradient magnitude of the luminance over pixels whose forward differences stay in the
 * hole: the texture energy a smear loses. */
static double grad_energy(const g3d_image *im, const g3d_image *m)
{
    double s = 0;
    size_t n = 0;
    for (int y = 0; y + 1 < im->h; y++)
        for (int x = 0; x + 1 < im->w; x++) {
            size_t i = (size_t)y * im->w + x;
            if (!(m->data[i] > 0.5f && m->data[i + 1] > 0.5f && m->data[i + im->w] > 0.5f)) continue;
            const float *a = g3d_image_px(im, x, y), *b = g3d_image_px(im, x + 1, y), *c = g3d_image_px(im, x, y + 1);
            double la = a[0] + a[1] + a[2], lb = b[0] + b[1] + b[2], lc = c[0] + c[1] + c[2];
            s += sqrt((lb - la) * (lb - la) + (lc - la) * (lc - la)) / 3.0;
            n++;
        }
    return s / (double)n;
}

/* A band along the bottom of a real photo (box-downsampled by 4), filled and judged by texture. */
static void border_band(const char *photo)
{
    g3d_image truth = {0}, pm, df, m;
    CHECK(load_photo(photo, 4, &truth));
    if (!truth.data) return;
    CHECK_OK(g3d_image_create(&m, truth.w, truth.h, 1));
    int band = truth.h * 3 / 10;
    mask_rect(&m, 0, truth.h - band, truth.w, truth.h); /* newly seen band along the bottom */
    CHECK_OK(g3d_image_clone(&pm, &truth));
    CHECK_OK(g3d_image_clone(&df, &truth));
    CHECK_OK(g3d_inpaint_patchmatch(&pm, &m, NULL, 1));
    CHECK_OK(g3d_inpaint_diffusion(&df, &m));
    double g_true = grad_energy(&truth, &m), g_pm = grad_energy(&pm, &m), g_df = grad_energy(&df, &m);
    printf("       %dx%d band %d: gradient energy truth %.4f, patchmatch %.4f, diffusion %.4f\n", truth.w, truth.h,
           band, g_true, g_pm, g_df);
    /* A smear or blur keeps only a small fraction of the texture energy (the diffusion fill
     * shows by how much); an exemplar fill copies real texture so it stays near the truth. */
    CHECK(g_pm > 0.5 * g_true && g_pm < 1.6 * g_true);
    CHECK(g_df < 0.2 * g_true);
    CHECK(g_pm > 4.0 * g_df);
    CHECK(outside_identical(&pm, &truth, &m));
    g3d_image_free(&truth);
    g3d_image_free(&pm);
    g3d_image_free(&df);
    g3d_image_free(&m);
}

TEST(photo_border_band)
{
    char photo[1024];
    snprintf(photo, sizeof photo, "%s/motorcycle_left.png", test_default_input());
    border_band(photo);
}

TEST(photo_border_band_nyu)
{
    border_band(test_shared("testdata/nyu_v2_metric3d/rgb/rgb_00050.jpg"));
}

TEST(determinism_and_small_holes)
{
    g3d_image base, a, b, c, m;
    CHECK_OK(g3d_image_create(&base, 80, 64, 3));
    CHECK_OK(g3d_image_create(&m, 80, 64, 1));
    make_texture(&base, 2);
    mask_rect(&m, 10, 10, 40, 40);
    m.data[50 * 80 + 60] = 1.f;           /* single-pixel hole */
    mask_rect(&m, 70, 55, 73, 57);        /* 3x2 hole */
    mask_rect(&m, 0, 0, 80, 3);           /* band along the top edge */
    CHECK_OK(g3d_image_clone(&a, &base));
    CHECK_OK(g3d_image_clone(&b, &base));
    CHECK_OK(g3d_image_clone(&c, &base));
    CHECK_OK(g3d_inpaint_patchmatch(&a, &m, NULL, 42));
    CHECK_OK(g3d_inpaint_patchmatch(&b, &m, NULL, 42));
    CHECK_OK(g3d_inpaint_patchmatch(&c, &m, NULL, 43));
    CHECK(memcmp(a.data, b.data, g3d_image_size(&a) * sizeof(float)) == 0);
    CHECK(outside_identical(&a, &base, &m));
    CHECK(outside_identical(&c, &base, &m));
    CHECK(hole_mae(&a, &base, &m) < 0.05);
    for (size_t i = 0; i < g3d_image_size(&a); i++)
        if (!isfinite(a.data[i]) || a.data[i] < 0.f || a.data[i] > 1.f) { CHECK(!"fill out of range"); break; }
    g3d_image_free(&base);
    g3d_image_free(&a);
    g3d_image_free(&b);
    g3d_image_free(&c);
    g3d_image_free(&m);
}

/* 70 % of the image missing (an L-shaped region touching two borders) plus speckle holes
 * like those of a reprojection: still completes, stays in range and beats the smooth fill. */
TEST(large_and_speckled_masks)
{
    g3d_image truth, pm, df, m;
    CHECK_OK(g3d_image_create(&truth, 120, 100, 3));
    CHECK_OK(g3d_image_create(&m, 120, 100, 1));
    make_texture(&truth, 1);
    mask_rect(&m, 0, 0, 120, 50);
    mask_rect(&m, 0, 50, 48, 100);
    g3d_rng rng;
    g3d_rng_seed(&rng, 5, 0);
    for (size_t i = 0; i < 120 * 100; i++)
        if (g3d_rng_below(&rng, 10) == 0) m.data[i] = 1.f;
    size_t holes = 0;
    for (size_t i = 0; i < 120 * 100; i++) holes += m.data[i] > 0.5f;
    CHECK(holes > 120 * 100 * 7 / 10);
    CHECK_OK(g3d_image_clone(&pm, &truth));
    CHECK_OK(g3d_image_clone(&df, &truth));
    /* Whatever the hole held before (here NaN) must not leak into the fill. */
    for (size_t i = 0; i < 120 * 100; i++)
        if (m.data[i] > 0.5f)
            for (int k = 0; k < 3; k++) pm.data[3 * i + k] = df.data[3 * i + k] = NAN;
    CHECK_OK(g3d_inpaint_patchmatch(&pm, &m, NULL, 9));
    CHECK_OK(g3d_inpaint_diffusion(&df, &m));
    double e_pm = hole_mae(&pm, &truth, &m), e_df = hole_mae(&df, &truth, &m);
    printf("       %.0f %% hole: MAE patchmatch %.4f, diffusion %.4f\n", 100.0 * holes / (120 * 100), e_pm, e_df);
    CHECK(e_pm < 0.5 * e_df);
    CHECK(outside_identical(&pm, &truth, &m));
    for (size_t i = 0; i < g3d_image_size(&pm); i++)
        if (!isfinite(pm.data[i]) || pm.data[i] < 0.f || pm.data[i] > 1.f) { CHECK(!"fill out of range"); break; }
    g3d_image_free(&truth);
    g3d_image_free(&pm);
    g3d_image_free(&df);
    g3d_image_free(&m);
}

TEST(provider_and_errors)
{
    g3d_inpainter ip;
    g3d_image im, orig, m, m_small, m3;
    CHECK_OK(g3d_inpainter_classic_create(NULL, &ip));
    CHECK(strcmp(ip.name, "classic") == 0);
    CHECK_OK(g3d_image_create(&im, 40, 30, 3));
    make_texture(&im, 1);
    CHECK_OK(g3d_image_clone(&orig, &im));
    CHECK_OK(g3d_image_create(&m, 40, 30, 1));
    /* No hole: nothing changes. */
    CHECK_OK(ip.inpaint(ip.ctx, &im, &m, "a prompt", 3));
    CHECK(memcmp(im.data, orig.data, g3d_image_size(&im) * sizeof(float)) == 0);
    /* Full mask: nothing to copy from. */
    for (size_t i = 0; i < 40 * 30; i++) m.data[i] = 1.f;
    CHECK_FAILS(ip.inpaint(ip.ctx, &im, &m, NULL, 3));
    CHECK(memcmp(im.data, orig.data, g3d_image_size(&im) * sizeof(float)) == 0);
    /* Size and channel mismatches. */
    CHECK_OK(g3d_image_create(&m_small, 39, 30, 1));
    CHECK_FAILS(ip.inpaint(ip.ctx, &im, &m_small, NULL, 3));
    CHECK_OK(g3d_image_create(&m3, 40, 30, 3));
    CHECK_FAILS(ip.inpaint(ip.ctx, &im, &m3, NULL, 3));
    g3d_image grey;
    CHECK_OK(g3d_image_create(&grey, 40, 30, 1));
    m.data[5] = 0.f; /* the provider takes RGB only */
    CHECK_FAILS(ip.inpaint(ip.ctx, &grey, &m, NULL, 3));
    m.data[5] = 1.f;
    g3d_image_free(&grey);
    /* Bad parameters. */
    g3d_inpaint_params p;
    g3d_inpaint_params_default(&p);
    p.patch = 6;
    m.data[0] = 0.f;
    CHECK_FAILS(g3d_inpaint_patchmatch(&im, &m, &p, 1));
    g3d_inpainter bad;
    CHECK_FAILS(g3d_inpainter_classic_create(&p, &bad));
    /* A mask leaving too little for one full patch still fills (smooth fallback). */
    CHECK_OK(g3d_inpaint_patchmatch(&im, &m, NULL, 1));
    CHECK(outside_identical(&im, &orig, &m));
    g3d_inpainter_free(&ip);
    g3d_image_free(&im);
    g3d_image_free(&orig);
    g3d_image_free(&m);
    g3d_image_free(&m_small);
    g3d_image_free(&m3);
}

int main(int argc, char **argv)
{
    if (test_extended(argc, argv)) {
        RUN(photo_border_band_nyu);
        return test_summary();
    }
    RUN(stripes);
    RUN(checker);
    RUN(bricks);
    RUN(photo_border_band);
    RUN(determinism_and_small_holes);
    RUN(large_and_speckled_masks);
    RUN(provider_and_errors);
    return test_summary();
}
