/* The Depth Anything V2 depth estimator: alignment of its relative prediction onto known
 * metric depth, with the tiny golden fixture's weights and image (tests/fixtures/dav2_tiny*). */
#include "gen3d/depth_estimators.h"
#include "testutil.h"

#define WEIGHTS test_fixture("dav2_tiny.pth")
#define ACTS test_fixture("dav2_tiny_golden.safetensors")

TEST(aligns_to_known_inverse_depth)
{
    g3d_ckpt *act = NULL;
    g3d_dav2 *m = NULL;
    CHECK_OK(g3d_ckpt_open(ACTS, &act));
    CHECK_OK(g3d_dav2_load_file(WEIGHTS, &m));
    const g3d_tensor_info *ti = act ? g3d_ckpt_find(act, "input.image_rgb_u8") : NULL;
    CHECK(ti && ti->ndim == 3 && ti->shape[2] == 3);
    if (!ti || !m) {
        g3d_dav2_free(m), g3d_ckpt_free(act);
        return;
    }
    int h = (int)ti->shape[0], w = (int)ti->shape[1];
    size_t n = (size_t)w * h;
    g3d_image rgb = {0}, known = {0}, out = {0};
    CHECK_OK(g3d_image_create(&rgb, w, h, 3));
    CHECK_OK(g3d_image_create(&known, w, h, 1));
    CHECK_OK(g3d_ckpt_read(act, "input.image_rgb_u8", 0, NULL, rgb.data));
    for (size_t i = 0; i < n * 3; i++) rgb.data[i] /= 255.0f;

    /* Known depth: the network's own prediction mapped through 1 / (0.5 p + 0.2) on a sparse
     * subset of pixels; the estimator (which then owns the model) must recover that mapping
     * for every pixel. */
    enum { SIZE = 126 };
    float *pred = malloc(sizeof(float) * n);
    CHECK_OK(g3d_dav2_predict(m, rgb.data, w, h, SIZE, pred, NULL));
    for (size_t i = 0; i < n; i += 17) known.data[i] = 1.0f / (0.5f * pred[i] + 0.2f);

    g3d_depth_estimator est = {0};
    CHECK_OK(g3d_depth_estimator_dav2_create(m, SIZE, &est));
    CHECK_OK(est.estimate(est.ctx, &rgb, &known, NULL, &out, NULL));
    CHECK(out.w == w && out.h == h && out.c == 1);
    if (out.data) {
        double worst = 0;
        for (size_t i = 0; i < n; i++) {
            double ref = 1.0 / (0.5 * pred[i] + 0.2), e = fabs(out.data[i] - ref) / ref;
            if (e > worst) worst = e;
        }
        printf("  worst relative depth error %.3g\n", worst);
        CHECK(worst < 1e-4);
    }

    /* Without known depth, or with a mismatched one, there is nothing to align to. */
    g3d_image bad = {0}, out2 = {0};
    CHECK_FAILS(est.estimate(est.ctx, &rgb, NULL, NULL, &out2, NULL));
    CHECK_OK(g3d_image_create(&bad, w / 2, h, 1));
    CHECK_FAILS(est.estimate(est.ctx, &rgb, &bad, NULL, &out2, NULL));
    g3d_image_free(&bad);
    memset(known.data, 0, sizeof(float) * n);
    CHECK_FAILS(est.estimate(est.ctx, &rgb, &known, NULL, &out2, NULL));
    CHECK(out2.data == NULL);

    g3d_depth_estimator_free(&est);
    free(pred);
    g3d_image_free(&rgb), g3d_image_free(&known), g3d_image_free(&out);
    g3d_ckpt_free(act);
}

/* A metric model needs no known depth: the estimator returns its prediction in metres. */
TEST(metric_model_returns_metres)
{
    g3d_ckpt *act = NULL;
    g3d_dav2 *m = NULL;
    CHECK_OK(g3d_ckpt_open(ACTS, &act));
    CHECK_OK(g3d_dav2_load_file(WEIGHTS, &m));
    const g3d_tensor_info *ti = act ? g3d_ckpt_find(act, "input.image_rgb_u8") : NULL;
    if (!ti || !m) {
        g3d_dav2_free(m), g3d_ckpt_free(act);
        return;
    }
    int h = (int)ti->shape[0], w = (int)ti->shape[1];
    size_t n = (size_t)w * h;
    g3d_image rgb = {0}, out = {0};
    CHECK_OK(g3d_image_create(&rgb, w, h, 3));
    CHECK_OK(g3d_ckpt_read(act, "input.image_rgb_u8", 0, NULL, rgb.data));
    for (size_t i = 0; i < n * 3; i++) rgb.data[i] /= 255.0f;
    g3d_dav2_set_metric(m, 80.0f);
    float *pred = malloc(sizeof(float) * n);
    CHECK_OK(g3d_dav2_predict(m, rgb.data, w, h, 70, pred, NULL));
    g3d_depth_estimator est = {0};
    CHECK_OK(g3d_depth_estimator_dav2_create(m, 70, &est));
    CHECK_OK(est.estimate(est.ctx, &rgb, NULL, NULL, &out, NULL));
    int same = out.data != NULL, in_range = 1;
    for (size_t i = 0; same && i < n; i++) {
        same = out.data[i] == pred[i];
        in_range &= pred[i] > 0 && pred[i] < 80.0f;
    }
    CHECK(same && in_range);
    g3d_depth_estimator_free(&est);
    free(pred);
    g3d_image_free(&rgb), g3d_image_free(&out);
    g3d_ckpt_free(act);
}

TEST(bad_input_size)
{
    g3d_depth_estimator est = {0};
    CHECK_FAILS(g3d_depth_estimator_dav2_create(NULL, 10, &est));
}

int main(void)
{
    RUN(aligns_to_known_inverse_depth);
    RUN(metric_model_returns_metres);
    RUN(bad_input_size);
    return test_summary();
}
