/* The masked L1 + D-SSIM loss: agreement with the PyTorch reference (values and autograd
 * gradient) and central finite differences of its own gradient. */
#include "testutil.h"
#include "gen3d/depthio.h"
#include "gen3d/loss.h"

static const char *FIX = G3D_SOURCE_DIR "/tests/fixtures/ssim_ref.npz";

TEST(matches_pytorch_reference)
{
    g3d_array img, tgt, mask, terms, grad;
    CHECK_OK(g3d_npz_load(FIX, "img", &img));
    CHECK_OK(g3d_npz_load(FIX, "target", &tgt));
    CHECK_OK(g3d_npz_load(FIX, "mask", &mask));
    CHECK_OK(g3d_npz_load(FIX, "terms", &terms));
    CHECK_OK(g3d_npz_load(FIX, "grad", &grad));
    if (!img.data || !grad.data) return;
    int h = (int)img.shape[0], w = (int)img.shape[1];
    float *d = malloc(sizeof(float) * (size_t)w * h * 3);
    g3d_loss_terms t;
    CHECK_OK(g3d_loss_l1_dssim(img.data, tgt.data, mask.data, w, h, 0.2, d, &t));
    printf("  l1 %.7f (ref %.7f), ssim %.7f (ref %.7f), loss %.7f (ref %.7f)\n", t.l1, terms.data[0], t.ssim, terms.data[1],
           t.loss, terms.data[2]);
    CHECK_NEAR(t.l1, terms.data[0], 1e-6);
    CHECK_NEAR(t.ssim, terms.data[1], 1e-6);
    CHECK_NEAR(t.loss, terms.data[2], 1e-6);
    double rel = test_rel_l2(d, grad.data, (size_t)w * h * 3);
    printf("  gradient vs autograd: relative L2 error %.2e\n", rel);
    CHECK(rel < 1e-5);
    free(d);
    g3d_array_free(&img); g3d_array_free(&tgt); g3d_array_free(&mask); g3d_array_free(&terms); g3d_array_free(&grad);
}

TEST(finite_differences)
{
    int w = 13, h = 11;
    size_t n = (size_t)w * h * 3;
    float *x = malloc(sizeof(float) * n), *y = malloc(sizeof(float) * n), *m = malloc(sizeof(float) * w * h), *d = malloc(sizeof(float) * n);
    g3d_rng r;
    g3d_rng_seed(&r, 9, 0);
    for (size_t i = 0; i < n; i++) { x[i] = g3d_rng_float(&r); y[i] = g3d_rng_float(&r); }
    for (int i = 0; i < w * h; i++) m[i] = g3d_rng_float(&r) > 0.25f;
    g3d_loss_terms t, tp, tm;
    CHECK_OK(g3d_loss_l1_dssim(x, y, m, w, h, 0.2, d, &t));
    double worst = 0;
    int checked = 0;
    for (size_t i = 0; i < n; i += 3) {
        /* Skip pixels where |x - y| is within the step: L1's kink would spoil the difference. */
        if (fabsf(x[i] - y[i]) < 2e-3f) continue;
        float keep = x[i];
        const float eps = 1e-3f;
        x[i] = keep + eps;
        g3d_loss_l1_dssim(x, y, m, w, h, 0.2, NULL, &tp);
        x[i] = keep - eps;
        g3d_loss_l1_dssim(x, y, m, w, h, 0.2, NULL, &tm);
        x[i] = keep;
        double fd = (tp.loss - tm.loss) / (2.0 * eps), an = d[i];
        double err = fabs(fd - an) / fmax(fabs(fd), 1e-6);
        worst = fmax(worst, err);
        checked++;
    }
    printf("  %d pixels checked: worst relative error %.2e\n", checked, worst);
    CHECK(checked > 100);
    CHECK(worst < 1e-3);
    free(x); free(y); free(m); free(d);
}

TEST(properties)
{
    int w = 16, h = 12;
    size_t n = (size_t)w * h * 3;
    float *x = malloc(sizeof(float) * n), *m = calloc((size_t)w * h, sizeof(float));
    for (size_t i = 0; i < n; i++) x[i] = (float)((i * 37) % 101) / 100.0f;
    g3d_loss_terms t;
    CHECK_OK(g3d_loss_l1_dssim(x, x, NULL, w, h, 0.2, NULL, &t));
    CHECK(t.l1 == 0 && fabs(t.ssim - 1.0) < 1e-12 && fabs(t.loss) < 1e-12 && t.valid == w * h);
    CHECK_FAILS(g3d_loss_l1_dssim(x, x, m, w, h, 0.2, NULL, &t));
    free(x);
    free(m);
}

int main(void)
{
    RUN(matches_pytorch_reference);
    RUN(finite_differences);
    RUN(properties);
    return test_summary();
}
