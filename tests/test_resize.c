/* Resampling against references from OpenCV and PyTorch (tests/fixtures/make_resize_fixture.py). */
#include "testutil.h"
#include "gen3d/npy.h"
#include "gen3d/resize.h"

static const char *FIX = G3D_SOURCE_DIR "/tests/fixtures/resize_ref.npz";

static double max_abs_diff(const float *a, const float *b, size_t n)
{
    double m = 0;
    for (size_t i = 0; i < n; i++) m = fmax(m, fabs((double)a[i] - b[i]));
    return m;
}

static void check_case(const g3d_array *src, const char *ref_name, g3d_resize_mode mode, double tol)
{
    g3d_array ref;
    CHECK_OK(g3d_npz_load(FIX, ref_name, &ref));
    if (!ref.data) return;
    int dh = (int)ref.shape[0], dw = (int)ref.shape[1], c = (int)src->shape[2];
    float *out = malloc(sizeof(float) * (size_t)dw * dh * c);
    CHECK_OK(g3d_resize_buffer(src->data, (int)src->shape[1], (int)src->shape[0], c, out, dw, dh, mode));
    double d = max_abs_diff(out, ref.data, (size_t)dw * dh * c);
    printf("  %-20s max |diff| %.2e\n", ref_name, d);
    CHECK_MSG(d <= tol, "%s: %.3g > %.3g", ref_name, d, tol);
    free(out);
    g3d_array_free(&ref);
}

TEST(matches_opencv_and_pytorch)
{
    g3d_array src, big;
    CHECK_OK(g3d_npz_load(FIX, "src", &src));
    CHECK_OK(g3d_npz_load(FIX, "big", &big));
    if (!src.data || !big.data) return;
    const char *names[] = {"up", "down", "odd", "x2"};
    for (int i = 0; i < 4; i++) {
        char n[64];
        snprintf(n, sizeof n, "cubic_%s", names[i]);
        check_case(&src, n, G3D_RESIZE_CUBIC_OPENCV, 2e-6);
        snprintf(n, sizeof n, "bilinear_%s", names[i]);
        check_case(&src, n, G3D_RESIZE_BILINEAR, 2e-6);
        snprintf(n, sizeof n, "bilinear_ac_%s", names[i]);
        check_case(&src, n, G3D_RESIZE_BILINEAR_AC, 2e-6);
    }
    check_case(&src, "cubic64_down", G3D_RESIZE_CUBIC_OPENCV, 2e-6);
    check_case(&src, "area_down", G3D_RESIZE_AREA, 2e-6);
    check_case(&big, "area_third", G3D_RESIZE_AREA, 2e-6);
    g3d_array_free(&src);
    g3d_array_free(&big);
}

TEST(properties)
{
    /* Constant images stay constant in every mode; a = -0.5 differs from a = -0.75. */
    g3d_image a, b, c2;
    CHECK_OK(g3d_image_create(&a, 9, 7, 2));
    for (size_t i = 0; i < g3d_image_size(&a); i++) a.data[i] = 0.25f;
    for (int m = 0; m < G3D_RESIZE_MODE_COUNT; m++) {
        CHECK_OK(g3d_image_resize(&a, 20, 3, (g3d_resize_mode)m, &b));
        double worst = 0;
        for (size_t i = 0; i < g3d_image_size(&b); i++) worst = fmax(worst, fabs(b.data[i] - 0.25));
        CHECK_MSG(worst < 1e-6, "mode %d", m);
        g3d_image_free(&b);
    }
    for (size_t i = 0; i < g3d_image_size(&a); i++) a.data[i] = (float)(i % 5);
    CHECK_OK(g3d_image_resize(&a, 20, 15, G3D_RESIZE_CUBIC_OPENCV, &b));
    CHECK_OK(g3d_image_resize(&a, 20, 15, G3D_RESIZE_CUBIC_HALF, &c2));
    CHECK(max_abs_diff(b.data, c2.data, g3d_image_size(&b)) > 1e-3);
    g3d_image_free(&b);
    g3d_image_free(&c2);
    /* Identity size is exact for bilinear. */
    CHECK_OK(g3d_image_resize(&a, 9, 7, G3D_RESIZE_BILINEAR, &b));
    CHECK(max_abs_diff(b.data, a.data, g3d_image_size(&a)) == 0);
    g3d_image_free(&b);
    CHECK_FAILS(g3d_image_resize(&a, 0, 7, G3D_RESIZE_BILINEAR, &b));
    CHECK_FAILS(g3d_resize_buffer(a.data, 9, 7, 2, a.data, 40000, 7, G3D_RESIZE_BILINEAR));
    g3d_image_free(&a);
}

TEST(cubic_half_reproduces_quadratics)
{
    /* Keys' kernel reproduces quadratics exactly only for a = -0.5; a = -0.75 does not. Away
     * from the replicated border, an upsampled x^2 ramp must equal x^2 at OpenCV's source
     * coordinate src = (dst + 0.5) * in / out - 0.5. */
    const int sw = 12, dw = 29;
    g3d_image a, b, c2;
    CHECK_OK(g3d_image_create(&a, sw, 1, 1));
    for (int x = 0; x < sw; x++) a.data[x] = (float)(x * x) / 16.0f;
    CHECK_OK(g3d_image_resize(&a, dw, 1, G3D_RESIZE_CUBIC_HALF, &b));
    CHECK_OK(g3d_image_resize(&a, dw, 1, G3D_RESIZE_CUBIC_OPENCV, &c2));
    double worst_half = 0, worst_opencv = 0;
    for (int x = 0; x < dw; x++) {
        double s = (x + 0.5) * sw / dw - 0.5;
        if (s < 1 || s > sw - 3) continue;
        worst_half = fmax(worst_half, fabs(b.data[x] - s * s / 16.0));
        worst_opencv = fmax(worst_opencv, fabs(c2.data[x] - s * s / 16.0));
    }
    printf("  x^2 ramp: a=-0.5 max error %.2e, a=-0.75 max error %.2e\n", worst_half, worst_opencv);
    CHECK(worst_half < 1e-5);
    CHECK(worst_opencv > 1e-3);
    g3d_image_free(&a);
    g3d_image_free(&b);
    g3d_image_free(&c2);
}

int main(void)
{
    RUN(matches_opencv_and_pytorch);
    RUN(properties);
    RUN(cubic_half_reproduces_quadratics);
    return test_summary();
}
