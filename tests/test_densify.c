/* Densification on hand-built Gaussians: clone, split, prune, opacity reset, moments. */
#include "testutil.h"
#include "gen3d/densify.h"

static void set(g3d_gaussians *g, int64_t i, float x, float log_scale, float opacity)
{
    g->means[3 * i] = x;
    g->means[3 * i + 1] = g->means[3 * i + 2] = 0;
    for (int k = 0; k < 3; k++) g->log_scales[3 * i + k] = log_scale;
    g->rots[4 * i] = 1;
    g->rots[4 * i + 1] = g->rots[4 * i + 2] = g->rots[4 * i + 3] = 0;
    g->opacity_logits[i] = logf(opacity / (1 - opacity));
    g->sh[3 * i] = x; /* SH DC tags the Gaussian */
}

TEST(clone_split_prune)
{
    /* extent 10: percent_dense 0.01 -> clone when the largest scale <= 0.1. */
    g3d_gaussians g;
    g3d_gaussians_create(&g, 5, 0);
    g.n = 5;
    set(&g, 0, 1, logf(0.05f), 0.5f);  /* high gradient, small: clone */
    set(&g, 1, 2, logf(0.5f), 0.5f);   /* high gradient, large: split */
    set(&g, 2, 3, logf(0.05f), 0.001f);/* transparent: pruned */
    set(&g, 3, 4, logf(0.05f), 0.5f);  /* quiet: kept as it is */
    set(&g, 4, 5, logf(0.05f), 0.5f);  /* seen huge on screen: pruned when prune_big */
    g3d_adam opt;
    CHECK_OK(g3d_adam_init(&opt, &g, 10));
    for (int i = 0; i < 5; i++) opt.m.opacity_logits[i] = (float)(10 + i);
    g3d_densify_stats s;
    CHECK_OK(g3d_densify_stats_init(&s, g.capacity));
    float grad[5] = {0.001f, 0.001f, 0.0f, 0.00001f, 0.0f}, radius[5] = {3, 3, 3, 3, 50};
    CHECK_OK(g3d_densify_accumulate(&s, 5, grad, radius));
    CHECK_OK(g3d_densify_accumulate(&s, 5, grad, radius));
    g3d_rng rng;
    g3d_rng_seed(&rng, 1, 0);
    g3d_densify_report rep;
    CHECK_OK(g3d_densify(&g, &opt, &s, 10, 1, NULL, &rng, &rep));
    printf("  cloned %lld, split %lld, pruned %lld -> %lld Gaussians\n", (long long)rep.cloned, (long long)rep.split,
           (long long)rep.pruned, (long long)g.n);
    CHECK(rep.cloned == 1 && rep.split == 1 && rep.pruned == 2);
    CHECK(g.n == 5); /* 5 + 1 clone + 2 halves - 1 split original - 2 pruned */
    /* Order: survivors of the originals (0, 3), then the clone of 0, then the halves of 1. */
    CHECK(g.sh[0] == 1 && g.sh[3] == 4 && g.sh[6] == 1 && g.sh[9] == 2 && g.sh[12] == 2);
    CHECK(opt.m.opacity_logits[0] == 10 && opt.m.opacity_logits[1] == 13); /* moments followed */
    CHECK(opt.m.opacity_logits[2] == 0 && opt.m.opacity_logits[3] == 0);   /* new ones start at zero */
    for (int k = 3; k < 5; k++) {
        CHECK_NEAR(expf(g.log_scales[3 * k]), 0.5 / 1.6, 1e-6);
        double d = fabs(g.means[3 * k] - 2.0);
        CHECK(d < 4 * 0.5 && (g.means[3 * k] != 2.0f));
    }
    CHECK(s.capacity >= g.n && s.count[0] == 0);
    /* Opacity reset caps every opacity at 0.01 and forgets the opacity moments. */
    g3d_opacity_reset(&g, &opt, 0.01f);
    for (int64_t i = 0; i < g.n; i++) CHECK(1 / (1 + expf(-g.opacity_logits[i])) <= 0.01f + 1e-6f);
    CHECK(opt.m.opacity_logits[0] == 0);
    g3d_densify_stats_free(&s);
    g3d_adam_free(&opt);
    g3d_gaussians_free(&g);
}

int main(void)
{
    RUN(clone_split_prune);
    return test_summary();
}
