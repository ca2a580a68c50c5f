/* MoGe-2 against the official PyTorch activations (seeded weights): the tiny configuration in
 * tests/fixtures (made by make_moge_golden.py) and, in the extended run, the ViT-S-sized set in
 * shared/golden/moge2_vits_config. Every recorded tensor from the resized encoder input to
 * infer()'s depth, mask, normals and intrinsics; plus the refusals of wrong checkpoints. */
#include "golden.h"

#include "gen3d/depth_estimators.h"
#include "gen3d/moge.h"
#include "gen3d/npy.h"
#include "gen3d/resize.h"

#define GOLDEN "golden/moge2_vits_config/"

/* A golden set and what its model's configuration implies. */
typedef struct golden_set {
    const char *model, *acts;
    int tokens;              /* what the golden run used */
    int rows, cols;          /* the token grid that implies */
    int default_tokens;      /* the top of model_config.num_tokens_range */
    int width;               /* ViT width */
    const char *backbone;    /* model_config.encoder.backbone */
} golden_set;

static golden_set tiny(void)
{
    return (golden_set){test_fixture("moge_tiny.pt"), test_fixture("moge_tiny_golden.safetensors"), 35, 5, 7, 96,
                        128, "dinov2_vitt14"};
}

static golden_set vits(void)
{
    return (golden_set){test_shared(GOLDEN "model.pt"), test_shared(GOLDEN "activations.safetensors"), 600, 20, 30,
                        3600, 384, "dinov2_vits14"};
}

static void check_golden(golden_set g)
{
    g3d_ckpt *act = NULL;
    g3d_moge *m = NULL;
    float *rgb = NULL;
    int w = 0, h = 0;
    CHECK_OK(g3d_ckpt_open(g.acts, &act));
    CHECK_OK(g3d_moge_load_file(g.model, &m));
    if (!m || !act || !(rgb = golden_image(act, "input.image_rgb_u8", &w, &h))) goto out;
    CHECK(g3d_moge_has_normal(m) && g3d_moge_has_mask(m) && g3d_moge_has_scale(m));
    CHECK(g3d_moge_default_tokens(m) == g.default_tokens);
    char desc[160], width[32];
    printf("  %s\n", g3d_moge_describe(m, desc, sizeof desc));
    snprintf(width, sizeof width, "width %d;", g.width);
    CHECK(strstr(desc, g.backbone) != NULL && strstr(desc, width) != NULL);
    if (!strstr(desc, width)) goto out;   /* the sizes below assume this width */

    size_t npx = (size_t)w * h;
    g3d_moge_trace tr = {.want = 1};
    g3d_moge_output o;
    CHECK_OK(g3d_moge_forward(m, rgb, w, h, g.tokens, &o, &tr));
    CHECK(tr.rows == g.rows && tr.cols == g.cols); /* round(sqrt(N / a)), round(sqrt(N a)) */
    if (o.points) {
        size_t np = (size_t)tr.rows * tr.cols;
        golden_compare(act, "encoder.image_14", tr.image14, (size_t)3 * 14 * tr.rows * 14 * tr.cols);
        golden_compare(act, "encoder.features", tr.features, (size_t)tr.features_c * np);
        golden_compare(act, "encoder.cls_token", tr.cls, (size_t)g.width);
        char name[32];
        for (int l = 0; l < 5; l++) {
            snprintf(name, sizeof name, "neck.level%d", l);
            if (g3d_ckpt_find(act, name) || l < 3) golden_compare(act, name, tr.neck[l], (size_t)tr.neck_c[l] * (np << (2 * l)));
        }
        golden_compare(act, "forward.points", o.points, npx * 3);
        golden_compare(act, "forward.mask", o.mask, npx);
        if (g3d_ckpt_find(act, "forward.normal")) golden_compare(act, "forward.normal", o.normal, npx * 3);
        golden_compare(act, "forward.metric_scale", &o.metric_scale, 1);
    }
    g3d_moge_trace_free(&tr);
    g3d_moge_output_free(&o);

    g3d_moge_result r;
    CHECK_OK(g3d_moge_infer(m, rgb, w, h, g.tokens, 0, &r));
    if (r.depth) {
        golden_compare(act, "infer.points", r.points, npx * 3);
        golden_compare(act, "infer.depth", r.depth, npx);
        golden_compare(act, "infer.normal", r.normal, npx * 3);
        golden_compare(act, "infer.intrinsics", r.intrinsics, 9);
        const g3d_tensor_info *mt = g3d_ckpt_find(act, "infer.mask");
        CHECK(mt && (size_t)mt->numel == npx && mt->dtype == G3D_DT_U8);
        size_t differ = 0, valid = 0;
        if (mt && (size_t)mt->numel == npx && mt->dtype == G3D_DT_U8)
            for (size_t i = 0; i < npx; i++) {
                differ += ((const uint8_t *)mt->data)[i] != r.mask[i];
                valid += r.mask[i];
            }
        printf("  infer.mask: %zu of %zu pixels valid, %zu differ\n", valid, npx, differ);
        CHECK(differ == 0);
        CHECK(valid > 0 && valid < npx); /* the golden mask has both kinds: the comparison means something */
        g3d_intrinsics K = g3d_moge_intrinsics_pixels(&r);
        CHECK_NEAR(K.fx, r.intrinsics[0] * w, 1e-3);
        CHECK_NEAR(K.cx, 0.5 * (w - 1), 1e-9);
        CHECK_NEAR(K.cy, 0.5 * (h - 1), 1e-9);
    }
    g3d_moge_result_free(&r);
    /* A known horizontal field of view: only the shift is fitted. */
    if (g3d_ckpt_find(act, "infer_fov.depth")) {
        CHECK_OK(g3d_moge_infer(m, rgb, w, h, g.tokens, 60.0, &r));
        if (r.depth) {
            golden_compare(act, "infer_fov.depth", r.depth, npx);
            golden_compare(act, "infer_fov.intrinsics", r.intrinsics, 9);
        }
        g3d_moge_result_free(&r);
    }
out:
    free(rgb);
    g3d_moge_free(m);
    g3d_ckpt_free(act);
}

TEST(golden_tiny) { check_golden(tiny()); }
TEST(golden_vits) { check_golden(vits()); }

/* The encoder's resize (bilinear with antialiasing) against PyTorch on a small random image. */
TEST(resize_bilinear_aa_matches_pytorch)
{
    static const char *FIX = G3D_SOURCE_DIR "/tests/fixtures/resize_aa_ref.npz";
    static const char *names[] = {"aa_down", "aa_third", "aa_up", "aa_mixed", "aa_same"};
    g3d_array src;
    CHECK_OK(g3d_npz_load(FIX, "src", &src));
    if (!src.data) return;
    for (int k = 0; k < 5; k++) {
        g3d_array ref;
        CHECK_OK(g3d_npz_load(FIX, names[k], &ref));
        if (!ref.data) continue;
        int dh = (int)ref.shape[0], dw = (int)ref.shape[1];
        size_t n = (size_t)dw * dh * 3;
        float *out = malloc(sizeof(float) * n);
        CHECK_OK(g3d_resize_buffer(src.data, (int)src.shape[1], (int)src.shape[0], 3, out, dw, dh, G3D_RESIZE_BILINEAR_AA));
        double d = 0;
        for (size_t i = 0; i < n; i++) d = fmax(d, fabs((double)out[i] - ref.data[i]));
        printf("  %-9s max |diff| %.2e\n", names[k], d);
        CHECK_MSG(d <= 1e-6, "%s: %.3g", names[k], d); /* float32 reference, values in [0, 1] */
        free(out);
        g3d_array_free(&ref);
    }
    g3d_array_free(&src);
}

/* The depth-estimator table: metric depth with 0 for invalid pixels and predicted intrinsics
 * when the camera is unknown; a known camera fixes the field of view (only the shift is fit). */
static void check_estimator(golden_set g)
{
    g3d_ckpt *act = NULL;
    g3d_moge *m = NULL;
    int w = 0, h = 0;
    CHECK_OK(g3d_ckpt_open(g.acts, &act));
    CHECK_OK(g3d_moge_load_file(g.model, &m));
    float *px = m && act ? golden_image(act, "input.image_rgb_u8", &w, &h) : NULL;
    if (!px) {
        g3d_moge_free(m);
        g3d_ckpt_free(act);
        return;
    }
    size_t npx = (size_t)w * h;
    g3d_image rgb = {w, h, 3, px}, d1 = {0}, d2 = {0};
    float *ref = NULL, *Kref = NULL;
    CHECK_OK(g3d_ckpt_read_alloc(act, "infer.depth", 0, NULL, &ref));
    CHECK_OK(g3d_ckpt_read_alloc(act, "infer.intrinsics", 0, NULL, &Kref));
    g3d_depth_estimator est = {0};
    CHECK_OK(g3d_depth_estimator_moge_create(m, g.tokens, &est));
    g3d_intrinsics K = {0};
    CHECK_OK(est.estimate(est.ctx, &rgb, NULL, NULL, &d1, &K));
    if (d1.data && ref && Kref) {
        double num = 0, den = 0;
        size_t bad = 0;
        for (size_t i = 0; i < npx; i++) {
            if (!isfinite(ref[i])) {
                bad += d1.data[i] != 0;
                continue;
            }
            num += (d1.data[i] - ref[i]) * (d1.data[i] - ref[i]);
            den += ref[i] * ref[i];
        }
        printf("  estimator depth rel L2 %.3e, %zu invalid pixels not 0\n", sqrt(num / den), bad);
        CHECK(sqrt(num / den) <= GOLDEN_TOL && bad == 0);
        CHECK_NEAR(K.fx, Kref[0] * w, 1e-4 * K.fx);
        CHECK_NEAR(K.fy, Kref[4] * h, 1e-4 * K.fy);
        CHECK_NEAR(K.cx, 0.5 * (w - 1), 1e-9);
        CHECK(K.width == w && K.height == h);
    }
    /* Known camera: kept as given, and only the z shift is refitted, so the depth moves by one
     * constant (small: the focal is the one just recovered). */
    g3d_intrinsics K2 = K;
    CHECK_OK(est.estimate(est.ctx, &rgb, NULL, NULL, &d2, &K2));
    CHECK(memcmp(&K, &K2, sizeof K) == 0);
    if (d1.data && d2.data) {
        double c = 0, mean = 0, spread = 0;
        size_t n = 0;
        for (size_t i = 0; i < npx; i++)
            if (d1.data[i] > 0 && d2.data[i] > 0) {
                c += d2.data[i] - d1.data[i];
                mean += d1.data[i];
                n++;
            }
        c /= n ? n : 1;
        mean /= n ? n : 1;
        for (size_t i = 0; i < npx; i++)
            if (d1.data[i] > 0 && d2.data[i] > 0) spread = fmax(spread, fabs(d2.data[i] - d1.data[i] - c));
        printf("  known camera: depth offset %.3e (mean depth %.3e), spread %.3e\n", c, mean, spread);
        CHECK(n > npx / 2);
        CHECK(fabs(c) < 0.01 * mean);
        CHECK(spread < 1e-5 * mean);
    }
    g3d_depth_estimator_free(&est);
    g3d_image_free(&rgb);
    g3d_image_free(&d1);
    g3d_image_free(&d2);
    free(ref);
    free(Kref);
    g3d_ckpt_free(act);
}

TEST(estimator_metric_depth_and_intrinsics) { check_estimator(tiny()); }
TEST(estimator_metric_depth_and_intrinsics_vits) { check_estimator(vits()); }

TEST(bad_arguments)
{
    g3d_moge *m = NULL;
    CHECK_OK(g3d_moge_load_file(test_fixture("moge_tiny.pt"), &m));
    if (!m) return;
    float rgb[3 * 4 * 4] = {0};
    g3d_moge_output o;
    CHECK_FAILS(g3d_moge_forward(m, rgb, 0, 4, 100, &o, NULL));
    CHECK(o.points == NULL);
    CHECK_FAILS(g3d_moge_forward(m, rgb, 40000, 4, 100, &o, NULL));
    CHECK_FAILS(g3d_moge_forward(m, rgb, 4, 4, G3D_MOGE_MAX_TOKENS + 1, &o, NULL)); /* too many tokens */
    CHECK_FAILS(g3d_moge_forward(m, rgb, 32768, 1, 600, &o, NULL)); /* no token row at this aspect */
    g3d_moge_result r;
    CHECK_FAILS(g3d_moge_infer(m, rgb, 4, 4, 100, 180.0, &r));
    CHECK(r.depth == NULL);
    g3d_moge_free(m);
}

/* A Depth Anything checkpoint (named `name` in the message) and a file that is no checkpoint. */
static void expect_not_moge(const char *dav2, const char *name, const char *other)
{
    g3d_moge *m = (g3d_moge *)1;
    CHECK_FAILS(g3d_moge_load_file(dav2, &m));
    CHECK(m == NULL);
    CHECK(strstr(g3d_error_message(), "not a MoGe checkpoint") != NULL);
    CHECK(strstr(g3d_error_message(), name) != NULL);
    m = (g3d_moge *)1;
    CHECK_FAILS(g3d_moge_load_file(other, &m));
    CHECK(m == NULL);
}

TEST(wrong_checkpoint_refused)
{
    expect_not_moge(test_fixture("dav2_tiny.pth"), "dav2_tiny.pth", test_fixture("moge_tiny_golden.safetensors"));
}

TEST(wrong_checkpoint_refused_vits)
{
    expect_not_moge(test_shared("golden/depth_anything_v2_vits/weights.safetensors"), "weights.safetensors",
                    test_shared(GOLDEN "README.md"));
}

/* Replaces the first occurrence of `from` in the checkpoint's data.pkl by `to` (same length),
 * then expects the MoGe loader to fail with a message containing `expect`. */
static void expect_refused(const unsigned char *file, size_t n, const char *from, const char *to, const char *expect)
{
    unsigned char *z = golden_edit_pickle(file, n, from, to);
    if (!z) return;
    g3d_ckpt *ck = NULL;
    g3d_moge *m = (g3d_moge *)1;
    CHECK_OK(g3d_ckpt_open_memory(z, n, "edited.pt", &ck));
    if (ck) {
        CHECK_FAILS(g3d_moge_load(ck, &m));
        CHECK(m == NULL);
        CHECK_MSG(strstr(g3d_error_message(), expect) != NULL, "message does not name %s", expect);
        CHECK(strstr(g3d_error_message(), "edited.pt") != NULL);
    }
    g3d_ckpt_free(ck);
    free(z);
}

/* Renames `name` (its last letter becomes X) and expects the loader to name it. */
static void expect_missing(const unsigned char *file, size_t n, const char *name)
{
    char to[128];
    snprintf(to, sizeof to, "%s", name);
    to[strlen(to) - 1] = 'X';
    expect_refused(file, n, name, to, name);
}

/* block: a tensor of one of the checkpoint's encoder blocks. */
static void check_refusals(golden_set g, const char *block)
{
    unsigned char *file = NULL;
    size_t n = 0;
    CHECK_OK(g3d_read_file(g.model, (size_t)1 << 30, &file, &n));
    if (!file) return;
    expect_missing(file, n, "neck.res_blocks.2.1.layers.5.bias");
    expect_missing(file, n, block);
    expect_missing(file, n, "encoder.backbone.pos_embed");
    expect_missing(file, n, "scale_head.2.weight");
    expect_missing(file, n, "encoder.image_std");
    expect_missing(file, n, "mask_head.output_blocks.4.weight");
    /* configuration values: normalisation layers, resamplers, backbone name, the config itself */
    expect_refused(file, n, "none", "gn32", "res_block_in_norm");
    expect_refused(file, n, "conv_transpose", "pixel_shuffle!", "resampler 'pixel_shuffle!'");
    expect_refused(file, n, g.backbone, "dinov2_vitg14", "dinov2_vitg14");
    expect_refused(file, n, g.backbone, "dinov3_vits14", "dinov3_vits14");
    expect_refused(file, n, "model_config", "model_confiX", "model_config");
    free(file);
}

TEST(missing_tensor_or_bad_config_named) { check_refusals(tiny(), "encoder.backbone.blocks.3.mlp.fc2.weight"); }
TEST(missing_tensor_or_bad_config_named_vits) { check_refusals(vits(), "encoder.backbone.blocks.7.mlp.fc2.weight"); }

int main(int argc, char **argv)
{
    if (test_extended(argc, argv)) {
        RUN(wrong_checkpoint_refused_vits);
        RUN(missing_tensor_or_bad_config_named_vits);
        RUN(golden_vits);
        RUN(estimator_metric_depth_and_intrinsics_vits);
        return test_summary();
    }
    RUN(wrong_checkpoint_refused);
    RUN(missing_tensor_or_bad_config_named);
    RUN(resize_bilinear_aa_matches_pytorch);
    RUN(bad_arguments);
    RUN(golden_tiny);
    RUN(estimator_metric_depth_and_intrinsics);
    return test_summary();
}
