/* test_adam.c - Adam over the Gaussian model: first-step closed form, a multi-step scalar
 * reference, group learning rates and the means schedule. */
#include "gen3d/adam.h"
#include "testutil.h"

/* Every float of the model, in block order, for element-wise comparison. */
static float *flat(const g3d_gaussians *g, int64_t i, int idx, double *lr, const g3d_adam_params *p,
                   double means_lr)
{
    int K3 = 3 * G3D_SH_COEFFS(g->sh_degree);
    if (idx < 3) { *lr = means_lr; return &g->means[i * 3 + idx]; }
    idx -= 3;
    if (idx < 3) { *lr = p->lr[G3D_PG_SCALES]; return &g->log_scales[i * 3 + idx]; }
    idx -= 3;
    if (idx < 4) { *lr = p->lr[G3D_PG_ROTS]; return &g->rots[i * 4 + idx]; }
    idx -= 4;
    if (idx < 1) { *lr = p->lr[G3D_PG_OPACITY]; return &g->opacity_logits[i]; }
    idx -= 1;
    *lr = idx < 3 ? p->lr[G3D_PG_SH_DC] : p->lr[G3D_PG_SH_REST];
    return &g->sh[i * K3 + idx];
}

TEST(matches_reference)
{
    const int N = 5, deg = 1, per = 3 + 3 + 4 + 1 + 3 * G3D_SH_COEFFS(1);
    const double extent = 2.5;
    g3d_gaussians g = {0}, grad = {0};
    CHECK_OK(g3d_gaussians_create(&g, N, deg));
    CHECK_OK(g3d_gaussians_create(&grad, N, deg));
    g.n = grad.n = N;
    g3d_rng r;
    g3d_rng_seed(&r, 42, 0);
    double x[5][32], m[5][32] = {{0}}, v[5][32] = {{0}}, lr;
    g3d_adam_params p;
    g3d_adam_params_default(&p);
    p.means_lr_steps = 10;
    for (int i = 0; i < N; i++)
        for (int k = 0; k < per; k++) x[i][k] = *flat(&g, i, k, &lr, &p, 0) = g3d_rng_normal(&r);
    g3d_adam a;
    CHECK_OK(g3d_adam_init(&a, &p, &g));
    double max_err = 0;
    for (int t = 1; t <= 4; t++) {
        double mlr = 1.6e-4 * extent * pow(1e-2, (t - 1) / 10.0);
        for (int i = 0; i < N; i++)
            for (int k = 0; k < per; k++) *flat(&grad, i, k, &lr, &p, 0) = g3d_rng_normal(&r);
        /* textbook Adam (Kingma & Ba, Algorithm 1) in double precision */
        for (int i = 0; i < N; i++)
            for (int k = 0; k < per; k++) {
                double gi = *flat(&grad, i, k, &lr, &p, mlr);
                m[i][k] = 0.9 * m[i][k] + 0.1 * gi;
                v[i][k] = 0.999 * v[i][k] + 0.001 * gi * gi;
                double mh = m[i][k] / (1 - pow(0.9, t)), vh = v[i][k] / (1 - pow(0.999, t));
                double before = x[i][k];
                x[i][k] -= lr * mh / (sqrt(vh) + 1e-15);
                if (t == 1) CHECK_NEAR(before - x[i][k], lr * (gi > 0 ? 1 : -1), 1e-9);
            }
        CHECK_OK(g3d_adam_step(&a, &g, &grad, extent));
        for (int i = 0; i < N; i++)
            for (int k = 0; k < per; k++) {
                double e = fabs(*flat(&g, i, k, &lr, &p, 0) - x[i][k]);
                if (e > max_err) max_err = e;
            }
    }
    printf("       max |C - reference| after 4 steps: %.2e\n", max_err);
    CHECK(max_err < 2e-6);
    CHECK(a.step == 4);
    /* a gradient of another size is refused */
    grad.n = 4;
    CHECK_FAILS(g3d_adam_step(&a, &g, &grad, extent));
    g3d_adam_free(&a);
    g3d_gaussians_free(&g);
    g3d_gaussians_free(&grad);
}

TEST(means_schedule)
{
    g3d_adam_params p;
    g3d_adam_params_default(&p);
    p.means_lr_steps = 3000;
    CHECK_NEAR(g3d_adam_means_lr(&p, 0, 2.0), 3.2e-4, 1e-12);
    CHECK_NEAR(g3d_adam_means_lr(&p, 1500, 2.0), 3.2e-5, 1e-12);
    CHECK_NEAR(g3d_adam_means_lr(&p, 3000, 2.0), 3.2e-6, 1e-14);
    CHECK_NEAR(g3d_adam_means_lr(&p, 9000, 2.0), 3.2e-6, 1e-14);
}

/* Only the visible Gaussians step, exactly as a full step would move them; the others keep
 * their parameters and moments. */
TEST(visible_only)
{
    const int N = 600;   /* more than one block of 256, with runs crossing block edges */
    g3d_gaussians g = {0}, h = {0}, grad = {0};
    CHECK_OK(g3d_gaussians_create(&g, N, 3));
    CHECK_OK(g3d_gaussians_create(&h, N, 3));
    CHECK_OK(g3d_gaussians_create(&grad, N, 3));
    g.n = h.n = grad.n = N;
    g3d_rng r;
    g3d_rng_seed(&r, 7, 0);
    const size_t per = 3 + 3 + 4 + 1 + 48;
    for (int i = 0; i < N; i++)
        for (size_t k = 0; k < per; k++) {
            double lr;
            g3d_adam_params p0;
            g3d_adam_params_default(&p0);
            *flat(&g, i, (int)k, &lr, &p0, 0) = *flat(&h, i, (int)k, &lr, &p0, 0) = g3d_rng_normal(&r);
            *flat(&grad, i, (int)k, &lr, &p0, 0) = g3d_rng_normal(&r);
        }
    int32_t radii[600];
    for (int i = 0; i < N; i++) radii[i] = (i / 7) % 3 == 0 ? 0 : 1 + i % 5;
    g3d_adam_params p;
    g3d_adam_params_default(&p);
    g3d_adam a, b;
    CHECK_OK(g3d_adam_init(&a, &p, &g));
    CHECK_OK(g3d_adam_init(&b, &p, &h));
    CHECK_OK(g3d_adam_step_visible(&a, &g, &grad, 3.0, radii));
    CHECK_OK(g3d_adam_step(&b, &h, &grad, 3.0));
    CHECK(a.step == 1 && b.step == 1);
    /* visible: as the full step, parameters and moments; invisible: the starting value (the
     * generator replayed) and zero moments */
    int bad = 0;
    g3d_rng_seed(&r, 7, 0);
    for (int i = 0; i < N; i++)
        for (size_t k = 0; k < per; k++) {
            double lr;
            float x0 = (float)g3d_rng_normal(&r);
            (void)g3d_rng_normal(&r);
            float x = *flat(&g, i, (int)k, &lr, &p, 0), m = *flat(&a.m, i, (int)k, &lr, &p, 0);
            float v = *flat(&a.v, i, (int)k, &lr, &p, 0);
            if (radii[i] > 0)
                bad += x != *flat(&h, i, (int)k, &lr, &p, 0) || m != *flat(&b.m, i, (int)k, &lr, &p, 0) ||
                       v != *flat(&b.v, i, (int)k, &lr, &p, 0) || x == x0;
            else
                bad += x != x0 || m != 0.0f || v != 0.0f;
        }
    printf("       %d of %d values differ from the expected ones\n", bad, (int)(N * per));
    CHECK(bad == 0);
    g3d_adam_free(&a);
    g3d_adam_free(&b);
    g3d_gaussians_free(&g);
    g3d_gaussians_free(&h);
    g3d_gaussians_free(&grad);
}

int main(void)
{
    RUN(matches_reference);
    RUN(visible_only);
    RUN(means_schedule);
    return test_summary();
}
