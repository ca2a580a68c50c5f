/* test_loss.c - masked L1+SSIM loss: finite-difference gradient checks, known values. */
#include "gen3d/loss.h"
#include "testutil.h"

#include <omp.h>
#include <string.h>

/* pred = target + an offset of at least 0.02 in magnitude, so the finite-difference steps
 * never cross the kink of |p - t|. */
static void make_pair(g3d_image *pred, g3d_image *target, g3d_image *mask, int w, int h,
                      uint64_t seed, float keep)
{
    g3d_rng r;
    g3d_rng_seed(&r, seed, 1);
    g3d_image_create(pred, w, h, 3);
    g3d_image_create(target, w, h, 3);
    g3d_image_create(mask, w, h, 1);
    for (size_t i = 0; i < g3d_image_size(target); i++) {
        target->data[i] = 0.2f + 0.6f * g3d_rng_float(&r);
        float off = 0.02f + 0.15f * g3d_rng_float(&r);
        pred->data[i] = target->data[i] + (g3d_rng_float(&r) < 0.5f ? -off : off);
    }
    for (size_t i = 0; i < g3d_image_size(mask); i++) mask->data[i] = g3d_rng_float(&r) < keep;
    mask->data[0] = 1;
}

static void gradcheck(const g3d_image *mask_or_null, g3d_image *pred, const g3d_image *target,
                      double lambda, double *rel_out)
{
    g3d_image grad = {0};
    g3d_image_create(&grad, pred->w, pred->h, pred->c);
    double loss;
    CHECK_OK(g3d_loss_fwd_bwd(pred, target, mask_or_null, lambda, &loss, NULL, &grad));
    double num = 0, den = 0;
    for (size_t i = 0; i < g3d_image_size(pred); i++) {
        float v = pred->data[i];
        float vp = v + 1e-3f, vm = v - 1e-3f;
        double lp, lm;
        pred->data[i] = vp;
        CHECK_OK(g3d_loss_fwd_bwd(pred, target, mask_or_null, lambda, &lp, NULL, NULL));
        pred->data[i] = vm;
        CHECK_OK(g3d_loss_fwd_bwd(pred, target, mask_or_null, lambda, &lm, NULL, NULL));
        pred->data[i] = v;
        double fd = (lp - lm) / ((double)vp - (double)vm);
        double d = grad.data[i] - fd;
        num += d * d;
        den += fd * fd;
    }
    *rel_out = sqrt(num / den);
    g3d_image_free(&grad);
}

TEST(gradient_masked)
{
    g3d_image p = {0}, t = {0}, m = {0};
    make_pair(&p, &t, &m, 13, 11, 7, 0.6f);
    double rel;
    gradcheck(&m, &p, &t, 0.2, &rel);
    printf("       masked L1+SSIM (lambda 0.2) gradient rel. error %.2e\n", rel);
    CHECK(rel <= 1e-3);
    gradcheck(&m, &p, &t, 1.0, &rel);
    printf("       masked pure SSIM gradient rel. error %.2e\n", rel);
    CHECK(rel <= 1e-3);
    g3d_image_free(&p); g3d_image_free(&t); g3d_image_free(&m);
}

TEST(gradient_unmasked)
{
    g3d_image p = {0}, t = {0}, m = {0};
    make_pair(&p, &t, &m, 16, 9, 11, 1.0f);
    double rel;
    gradcheck(NULL, &p, &t, 0.2, &rel);
    printf("       unmasked gradient rel. error %.2e\n", rel);
    CHECK(rel <= 1e-3);
    g3d_image_free(&p); g3d_image_free(&t); g3d_image_free(&m);
}

TEST(known_values)
{
    g3d_image p = {0}, t = {0}, m = {0};
    make_pair(&p, &t, &m, 12, 12, 3, 0.5f);
    double loss, ssim, psnr;
    /* identical images: SSIM 1, loss 0, infinite PSNR */
    CHECK_OK(g3d_loss_fwd_bwd(&t, &t, &m, 0.2, &loss, &ssim, NULL));
    CHECK_NEAR(ssim, 1.0, 1e-12);
    CHECK_NEAR(loss, 0.0, 1e-12);
    CHECK_OK(g3d_psnr(&t, &t, NULL, &psnr));
    CHECK(isinf(psnr));
    /* lambda 0: loss is the masked mean absolute error */
    double sum = 0; int64_t n = 0;
    for (int i = 0; i < 144; i++)
        if (m.data[i] > 0.5f)
            for (int ch = 0; ch < 3; ch++) { sum += fabs((double)p.data[i*3+ch] - t.data[i*3+ch]); n++; }
    CHECK_OK(g3d_loss_fwd_bwd(&p, &t, &m, 0.0, &loss, NULL, NULL));
    CHECK_NEAR(loss, sum / n, 1e-12);
    /* an all-ones mask equals no mask */
    double l2;
    for (int i = 0; i < 144; i++) m.data[i] = 1;
    CHECK_OK(g3d_loss_fwd_bwd(&p, &t, &m, 0.2, &loss, NULL, NULL));
    CHECK_OK(g3d_loss_fwd_bwd(&p, &t, NULL, 0.2, &l2, NULL, NULL));
    CHECK_NEAR(loss, l2, 1e-15);
    /* a uniform error of 0.1 is 20 dB; masked-out pixels do not count */
    for (size_t i = 0; i < g3d_image_size(&p); i++) p.data[i] = t.data[i] + 0.1f;
    for (int i = 0; i < 144; i++) m.data[i] = i % 2;
    p.data[0] = 5; /* pixel 0 is masked out */
    CHECK_OK(g3d_psnr(&p, &t, &m, &psnr));
    CHECK_NEAR(psnr, 20.0, 1e-4);
    g3d_image_free(&p); g3d_image_free(&t); g3d_image_free(&m);
}

TEST(errors)
{
    g3d_image p = {0}, t = {0}, m = {0}, small = {0};
    make_pair(&p, &t, &m, 8, 8, 5, 1.0f);
    g3d_image_create(&small, 7, 8, 3);
    double loss, psnr;
    CHECK_FAILS(g3d_loss_fwd_bwd(&p, &small, NULL, 0.2, &loss, NULL, NULL));
    for (int i = 0; i < 64; i++) m.data[i] = 0;
    CHECK_FAILS(g3d_loss_fwd_bwd(&p, &t, &m, 0.2, &loss, NULL, NULL));
    CHECK_FAILS(g3d_psnr(&p, &t, &m, &psnr));
    CHECK_FAILS(g3d_loss_fwd_bwd(&p, &t, NULL, 1.5, &loss, NULL, NULL));
    g3d_image_free(&p); g3d_image_free(&t); g3d_image_free(&m); g3d_image_free(&small);
}

/* Each thread blurs a band of rows (and the few rows beside it again): the loss, its gradient
 * and the evaluation SSIM must be the same bits for any thread count, also with bands of a
 * few rows. */
TEST(thread_count_invariance)
{
    g3d_image p = {0}, t = {0}, m = {0};
    make_pair(&p, &t, &m, 40, 23, 13, 0.7f);
    const int threads[4] = {1, 2, 3, 7};
    double loss[4], ssim[4], eval[4];
    g3d_image grad[4];
    for (int r = 0; r < 4; r++) {
        omp_set_num_threads(threads[r]);
        CHECK_OK(g3d_image_create(&grad[r], p.w, p.h, p.c));
        CHECK_OK(g3d_loss_fwd_bwd(&p, &t, &m, 0.2, &loss[r], &ssim[r], &grad[r]));
        CHECK_OK(g3d_ssim(&p, &t, &m, &eval[r]));
    }
    for (int r = 1; r < 4; r++) {
        CHECK(memcmp(&loss[r], &loss[0], sizeof(double)) == 0);
        CHECK(memcmp(&ssim[r], &ssim[0], sizeof(double)) == 0);
        CHECK(memcmp(&eval[r], &eval[0], sizeof(double)) == 0);
        CHECK(memcmp(grad[r].data, grad[0].data, sizeof(float) * g3d_image_size(&p)) == 0);
    }
    CHECK(loss[0] > 0 && ssim[0] < 1);
    for (int r = 0; r < 4; r++) g3d_image_free(&grad[r]);
    g3d_image_free(&p); g3d_image_free(&t); g3d_image_free(&m);
}

int main(void)
{
    RUN(gradient_masked);
    RUN(gradient_unmasked);
    RUN(known_values);
    RUN(errors);
    RUN(thread_count_invariance);
    return test_summary();
}
