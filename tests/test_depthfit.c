/* Scale/shift alignment of predicted depth to known depth. */
#include "gen3d/depthfit.h"
#include "testutil.h"

enum { N = 500 };

/* A disparity-like prediction and the metric depth it maps to under s = 0.7, t = 0.05. */
static void make(float *pred, float *known)
{
    g3d_rng rng;
    g3d_rng_seed(&rng, 42, 1);
    for (int i = 0; i < N; i++) {
        pred[i] = 2.0f + 10.0f * g3d_rng_float(&rng);
        known[i] = (float)(1.0 / (0.7 * pred[i] + 0.05));
    }
}

TEST(inverse_recovers_exact_affine)
{
    float pred[N], known[N], out[N];
    make(pred, known);
    for (int i = 0; i < N; i += 3) known[i] = 0;   /* unknown pixels do not take part */
    double s = 0, t = 0;
    CHECK_OK(g3d_depthfit_affine(pred, known, N, G3D_FIT_INVERSE, &s, &t));
    CHECK_NEAR(s, 0.7, 1e-6);
    CHECK_NEAR(t, 0.05, 1e-5);
    g3d_depthfit_apply(pred, N, G3D_FIT_INVERSE, s, t, out);
    for (int i = 1; i < N; i += 7) CHECK_NEAR(out[i], 1.0 / (0.7 * pred[i] + 0.05), 1e-5 * out[i]);
}

TEST(depth_space_least_squares)
{
    /* Metric space with noise: the result must equal the closed-form least-squares line. */
    float pred[N], known[N];
    g3d_rng rng;
    g3d_rng_seed(&rng, 7, 3);
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (int i = 0; i < N; i++) {
        pred[i] = 1.0f + 4.0f * g3d_rng_float(&rng);
        known[i] = 1.3f * pred[i] + 0.4f + 0.05f * (g3d_rng_float(&rng) - 0.5f);
        sx += pred[i], sy += known[i], sxx += (double)pred[i] * pred[i], sxy += (double)pred[i] * known[i];
    }
    double s_ref = (N * sxy - sx * sy) / (N * sxx - sx * sx), t_ref = (sy - s_ref * sx) / N;
    double s = 0, t = 0;
    CHECK_OK(g3d_depthfit_affine(pred, known, N, G3D_FIT_DEPTH, &s, &t));
    CHECK_NEAR(s, s_ref, 1e-9);
    CHECK_NEAR(t, t_ref, 1e-9);
    CHECK_NEAR(s, 1.3, 0.01);
}

TEST(apply_marks_beyond_horizon_invalid)
{
    float pred[3] = {1.0f, -1.0f, 0.0f}, out[3];
    g3d_depthfit_apply(pred, 3, G3D_FIT_INVERSE, 2.0, 0.0, out);
    CHECK_NEAR(out[0], 0.5, 1e-7);
    CHECK(out[1] == 0.0f && out[2] == 0.0f);
}

TEST(errors)
{
    float pred[N], known[N];
    make(pred, known);
    double s = 3, t = 4;
    float none[N] = {0};
    CHECK_FAILS(g3d_depthfit_affine(pred, none, N, G3D_FIT_INVERSE, &s, &t));
    float flat[N];
    for (int i = 0; i < N; i++) flat[i] = 5.0f;
    CHECK_FAILS(g3d_depthfit_affine(flat, known, N, G3D_FIT_INVERSE, &s, &t));
    known[10] = NAN;
    CHECK_FAILS(g3d_depthfit_affine(pred, known, N, G3D_FIT_INVERSE, &s, &t));
    known[10] = 1.0f;
    pred[11] = INFINITY;
    CHECK_FAILS(g3d_depthfit_affine(pred, known, N, G3D_FIT_DEPTH, &s, &t));
    CHECK(s == 3 && t == 4);
}

int main(void)
{
    RUN(inverse_recovers_exact_affine);
    RUN(depth_space_least_squares);
    RUN(apply_marks_beyond_horizon_invalid);
    RUN(errors);
    return test_summary();
}
