/* test_densify.c - clone / split / prune on hand-built models, moments kept in step. */
#include "gen3d/densify.h"
#include "testutil.h"

static float logit(float p) { return logf(p / (1 - p)); }

/* 4 Gaussians, extent 10 (clone/split boundary 0.1, world-size prune 1.0):
 *   0 small, high gradient -> cloned      1 large, high gradient -> split
 *   2 low opacity          -> pruned      3 quiet                -> kept */
static void build(g3d_gaussians *g, g3d_adam *a, g3d_densify_stats *st)
{
    g3d_gaussians_create(g, 4, 0);
    g->n = 4;
    const float scale[4] = {0.05f, 0.5f, 0.05f, 0.05f}, op[4] = {0.5f, 0.5f, 0.001f, 0.5f};
    for (int i = 0; i < 4; i++) {
        for (int k = 0; k < 3; k++) {
            g->means[i * 3 + k] = (float)(i * 10 + k);
            g->log_scales[i * 3 + k] = logf(scale[i]);
            g->sh[i * 3 + k] = 0.1f * (float)i;
        }
        g->rots[i * 4] = 1;
        g->opacity_logits[i] = logit(op[i]);
    }
    g->log_scales[1 * 3 + 2] = logf(0.05f); /* Gaussian 1: flat in z */
    g3d_adam_params p;
    g3d_adam_params_default(&p);
    g3d_adam_init(a, &p, g);
    for (int i = 0; i < 4; i++) a->m.means[i * 3] = a->v.means[i * 3] = 1.0f + (float)i;
    g3d_densify_stats_init(st, 4);
    const float grad[4] = {0.001f, 0.001f, 0.00001f, 0.00001f};
    const int32_t radii[4] = {3, 3, 3, 3};
    g3d_densify_accumulate(st, grad, radii, 4);
    g3d_densify_accumulate(st, grad, radii, 4);
}

TEST(clone_split_prune)
{
    g3d_gaussians g;
    g3d_adam a;
    g3d_densify_stats st;
    build(&g, &a, &st);
    g3d_densify_params p;
    g3d_densify_params_default(&p, 3000);
    g3d_rng r;
    g3d_rng_seed(&r, 1, 2);
    g3d_densify_result res;
    CHECK_OK(g3d_densify_step(&g, &a, &st, &p, 10.0, 0, &r, &res));
    CHECK(res.cloned == 1 && res.split == 1 && res.pruned == 1);
    /* order: 0, 3 (originals kept), clone of 0, 2 children of 1 */
    CHECK(g.n == 5 && a.m.n == 5 && a.v.n == 5);
    CHECK_NEAR(g.means[0], 0, 0);
    CHECK_NEAR(g.means[3], 30, 0);
    CHECK_NEAR(g.means[6], 0, 0);
    CHECK_NEAR(a.m.means[0], 1, 0);   /* originals keep their moments */
    CHECK_NEAR(a.m.means[3], 4, 0);
    CHECK_NEAR(a.m.means[6], 0, 0);   /* new ones start at zero */
    CHECK_NEAR(a.v.means[9], 0, 0);
    for (int c = 3; c < 5; c++) {
        CHECK_NEAR(expf(g.log_scales[c * 3]), 0.5 / 1.6, 1e-6);
        CHECK_NEAR(expf(g.log_scales[c * 3 + 2]), 0.05 / 1.6, 1e-7);
        CHECK_NEAR(g.sh[c * 3], 0.1, 1e-7);
        /* offsets are samples of the parent Gaussian: within 5 sigma per axis */
        CHECK(fabs(g.means[c * 3] - 10) < 2.5 && fabs(g.means[c * 3 + 2] - 12) < 0.25);
    }
    CHECK(g.means[9] != g.means[12]);
    CHECK(st.count[0] == 0 && st.capacity >= g.n);
    g3d_densify_stats_free(&st);
    g3d_adam_free(&a);
    g3d_gaussians_free(&g);
}

TEST(prune_large_and_reset)
{
    g3d_gaussians g;
    g3d_adam a;
    g3d_densify_stats st;
    build(&g, &a, &st);
    g3d_densify_params p;
    g3d_densify_params_default(&p, 3000);
    p.grad_threshold = 1.0; /* nothing densifies */
    st.max_radius[3] = 40;  /* too big on screen */
    g.log_scales[0] = logf(2.0f); /* too big in the world */
    g3d_rng r;
    g3d_rng_seed(&r, 1, 2);
    g3d_densify_result res;
    CHECK_OK(g3d_densify_step(&g, &a, &st, &p, 10.0, 0, &r, &res));
    CHECK(g.n == 3 && res.pruned == 1);  /* only the transparent one without size pruning */
    g3d_densify_accumulate(&st, (const float[]){0, 0, 0}, (const int32_t[]){1, 1, 40}, 3);
    CHECK_OK(g3d_densify_step(&g, &a, &st, &p, 10.0, 1, &r, &res));
    CHECK(g.n == 1 && res.pruned == 2 && a.m.n == 1);
    CHECK_NEAR(g.means[0], 10, 0);
    g3d_densify_reset_opacity(&g, &a);
    CHECK_NEAR(1 / (1 + expf(-g.opacity_logits[0])), 0.01, 1e-6);
    CHECK_NEAR(a.m.opacity_logits[0], 0, 0);
    /* mismatched moments are refused */
    a.m.n = 7;
    CHECK_FAILS(g3d_densify_step(&g, &a, &st, &p, 10.0, 1, &r, &res));
    g3d_densify_stats_free(&st);
    g3d_adam_free(&a);
    g3d_gaussians_free(&g);
}

TEST(schedule_defaults)
{
    g3d_densify_params p;
    g3d_densify_params_default(&p, 30000);
    CHECK(p.from == 500 && p.until == 15000 && p.interval == 100 && p.opacity_reset_interval == 3000);
    g3d_densify_params_default(&p, 3000);
    CHECK(p.from == 100 && p.until == 1500 && p.opacity_reset_interval == 1000);
}

int main(void)
{
    RUN(clone_split_prune);
    RUN(prune_large_and_reset);
    RUN(schedule_defaults);
    return test_summary();
}
