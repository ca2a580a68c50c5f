/* Adam on the Gaussian model against torch.optim.Adam, and moments following the model. */
#include "testutil.h"
#include "gen3d/adam.h"
#include "gen3d/depthio.h"

static const char *FIX = G3D_SOURCE_DIR "/tests/fixtures/adam_ref.npz";

TEST(matches_torch_adam)
{
    g3d_array p0, tgt, want_means, want_opacity, want_rest;
    CHECK_OK(g3d_npz_load(FIX, "p0", &p0));
    CHECK_OK(g3d_npz_load(FIX, "target", &tgt));
    CHECK_OK(g3d_npz_load(FIX, "means", &want_means));
    CHECK_OK(g3d_npz_load(FIX, "opacity", &want_opacity));
    CHECK_OK(g3d_npz_load(FIX, "rest", &want_rest));
    if (!want_rest.data) return;
    /* Two Gaussians of SH degree 1: means (2x3) and SH rest (2x9, of which 6 are used) and
     * opacities (2) carry the six reference parameters. */
    g3d_gaussians p, g;
    g3d_gaussians_create(&p, 2, 1);
    g3d_gaussians_create(&g, 2, 1);
    p.n = g.n = 2;
    for (int i = 0; i < 6; i++) { p.means[i] = p0.data[i]; p.sh[3 + i] = p0.data[i]; }
    p.opacity_logits[0] = p0.data[0];
    p.opacity_logits[1] = p0.data[1];
    g3d_adam a;
    CHECK_OK(g3d_adam_init(&a, &p, 2.0));
    for (int step = 0; step < 3; step++) {
        memset(g.block_, 0, sizeof(float) * (size_t)g.capacity * (3 + 3 + 4 + 1 + 12));
        for (int i = 0; i < 6; i++) { g.means[i] = 2 * (p.means[i] - tgt.data[i]); g.sh[3 + i] = 2 * (p.sh[3 + i] - tgt.data[i]); }
        for (int i = 0; i < 2; i++) g.opacity_logits[i] = 2 * (p.opacity_logits[i] - tgt.data[i]);
        CHECK_OK(g3d_adam_step(&a, &p, &g));
    }
    double worst = 0;
    for (int i = 0; i < 6; i++) {
        worst = fmax(worst, fabs(p.means[i] - want_means.data[i]));
        worst = fmax(worst, fabs(p.sh[3 + i] - want_rest.data[i]));
    }
    for (int i = 0; i < 2; i++) worst = fmax(worst, fabs(p.opacity_logits[i] - want_opacity.data[i]));
    printf("  after 3 steps: max |ours - torch| = %.2e\n", worst);
    CHECK(worst < 1e-6);
    /* Moments follow compaction and growth. */
    uint8_t keep[2] = {0, 1};
    float m1 = a.m.means[3];
    g3d_adam_compact(&a, keep);
    g3d_gaussians_compact(&p, keep);
    g3d_gaussians_compact(&g, keep);
    CHECK(a.m.n == 1 && a.m.means[0] == m1);
    CHECK_OK(g3d_gaussians_reserve(&p, 3));
    CHECK_OK(g3d_gaussians_reserve(&g, 3));
    p.n = g.n = 3;
    CHECK_OK(g3d_adam_step(&a, &p, &g));
    CHECK(a.m.n == 3 && a.v.opacity_logits[2] == 0);
    g.n = 2;
    CHECK_FAILS(g3d_adam_step(&a, &p, &g));
    g3d_adam_free(&a);
    g3d_gaussians_free(&p);
    g3d_gaussians_free(&g);
    g3d_array_free(&p0); g3d_array_free(&tgt); g3d_array_free(&want_means); g3d_array_free(&want_opacity); g3d_array_free(&want_rest);
}

int main(void)
{
    RUN(matches_torch_adam);
    return test_summary();
}
