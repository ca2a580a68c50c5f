/* The loss and the optimiser against PyTorch references (tests/fixtures/make_ssim_fixture.py,
 * make_adam_fixture.py): loss terms and autograd gradient, three torch.optim.Adam steps. */
#include "testutil.h"
#include "gen3d/adam.h"
#include "gen3d/loss.h"
#include "gen3d/npy.h"

#define FIXDIR G3D_SOURCE_DIR "/tests/fixtures/"

static void to_image(const g3d_array *a, g3d_image *img)
{
    int c = a->ndim == 3 ? (int)a->shape[2] : 1;
    g3d_image_create(img, (int)a->shape[1], (int)a->shape[0], c);
    memcpy(img->data, a->data, g3d_image_size(img) * sizeof(float));
}

TEST(loss_matches_pytorch)
{
    g3d_array a_img, a_tgt, a_mask, terms, grad;
    CHECK_OK(g3d_npz_load(FIXDIR "ssim_ref.npz", "img", &a_img));
    CHECK_OK(g3d_npz_load(FIXDIR "ssim_ref.npz", "target", &a_tgt));
    CHECK_OK(g3d_npz_load(FIXDIR "ssim_ref.npz", "mask", &a_mask));
    CHECK_OK(g3d_npz_load(FIXDIR "ssim_ref.npz", "terms", &terms));
    CHECK_OK(g3d_npz_load(FIXDIR "ssim_ref.npz", "grad", &grad));
    if (!grad.data) return;
    g3d_image img, tgt, mask, g;
    to_image(&a_img, &img);
    to_image(&a_tgt, &tgt);
    to_image(&a_mask, &mask);
    g3d_image_create(&g, img.w, img.h, 3);
    double loss, ssim;
    CHECK_OK(g3d_loss_fwd_bwd(&img, &tgt, &mask, 0.2, &loss, &ssim, &g));
    printf("  loss %.7f (PyTorch %.7f), ssim %.7f (PyTorch %.7f)\n", loss, terms.data[2], ssim, terms.data[1]);
    CHECK_NEAR(loss, terms.data[2], 1e-6);
    CHECK_NEAR(ssim, terms.data[1], 1e-6);
    double norm = 0;
    for (size_t i = 0; i < g3d_image_size(&g); i++) norm += (double)g.data[i] * g.data[i];
    CHECK(norm > 1e-8); /* a real gradient, so that agreeing with it means something */
    double rel = test_rel_l2(g.data, grad.data, g3d_image_size(&g));
    printf("  gradient vs autograd: relative L2 error %.2e\n", rel);
    CHECK(rel < 1e-5);
    g3d_image_free(&img); g3d_image_free(&tgt); g3d_image_free(&mask); g3d_image_free(&g);
    g3d_array_free(&a_img); g3d_array_free(&a_tgt); g3d_array_free(&a_mask); g3d_array_free(&terms); g3d_array_free(&grad);
}

TEST(adam_matches_torch)
{
    g3d_array p0, tgt, want_means, want_opacity, want_rest;
    CHECK_OK(g3d_npz_load(FIXDIR "adam_ref.npz", "p0", &p0));
    CHECK_OK(g3d_npz_load(FIXDIR "adam_ref.npz", "target", &tgt));
    CHECK_OK(g3d_npz_load(FIXDIR "adam_ref.npz", "means", &want_means));
    CHECK_OK(g3d_npz_load(FIXDIR "adam_ref.npz", "opacity", &want_opacity));
    CHECK_OK(g3d_npz_load(FIXDIR "adam_ref.npz", "rest", &want_rest));
    if (!want_rest.data) return;
    /* Two Gaussians of SH degree 1 carry the six reference values in their means, SH rest and
     * (two of them) opacities; the fixture used constant rates, so the means rate does not decay. */
    g3d_gaussians p, g;
    g3d_gaussians_create(&p, 2, 1);
    g3d_gaussians_create(&g, 2, 1);
    p.n = g.n = 2;
    for (int i = 0; i < 6; i++) { p.means[i] = p0.data[i]; p.sh[3 + i] = p0.data[i]; }
    p.opacity_logits[0] = p0.data[0];
    p.opacity_logits[1] = p0.data[1];
    g3d_adam_params ap;
    g3d_adam_params_default(&ap);
    ap.lr[G3D_PG_MEANS] = 1.6e-4;
    ap.means_lr_final = 1.6e-4;
    ap.lr[G3D_PG_OPACITY] = 2.5e-2;
    ap.lr[G3D_PG_SH_REST] = 2.5e-3 / 20;
    ap.eps = 1e-15;
    g3d_adam a;
    CHECK_OK(g3d_adam_init(&a, &ap, &p));
    for (int step = 0; step < 3; step++) {
        memset(g.means, 0, sizeof(float) * 6);
        memset(g.sh, 0, sizeof(float) * 24);
        for (int i = 0; i < 6; i++) { g.means[i] = 2 * (p.means[i] - tgt.data[i]); g.sh[3 + i] = 2 * (p.sh[3 + i] - tgt.data[i]); }
        for (int i = 0; i < 2; i++) g.opacity_logits[i] = 2 * (p.opacity_logits[i] - tgt.data[i]);
        CHECK_OK(g3d_adam_step(&a, &p, &g, 2.0)); /* extent 2: means rate 3.2e-4 as in the fixture */
    }
    double worst = 0;
    for (int i = 0; i < 6; i++) {
        worst = fmax(worst, fabs(p.means[i] - want_means.data[i]));
        worst = fmax(worst, fabs(p.sh[3 + i] - want_rest.data[i]));
    }
    for (int i = 0; i < 2; i++) worst = fmax(worst, fabs(p.opacity_logits[i] - want_opacity.data[i]));
    printf("  after 3 steps: max |ours - torch.optim.Adam| = %.2e\n", worst);
    CHECK(worst < 1e-6);
    g3d_adam_free(&a);
    g3d_gaussians_free(&p);
    g3d_gaussians_free(&g);
    g3d_array_free(&p0); g3d_array_free(&tgt); g3d_array_free(&want_means); g3d_array_free(&want_opacity); g3d_array_free(&want_rest);
}

int main(void)
{
    RUN(loss_matches_pytorch);
    RUN(adam_matches_torch);
    return test_summary();
}
