/* MoGe-2 against the official PyTorch activations (seeded weights, ViT-S-sized configuration)
 * in shared/golden/moge2_vits_config: every recorded tensor from the resized encoder input to
 * infer()'s depth, mask, normals and intrinsics; plus the refusals of wrong checkpoints. */
#include "testutil.h"

#include "gen3d/depth_estimators.h"
#include "gen3d/moge.h"
#include "gen3d/npy.h"
#include "gen3d/resize.h"

#define GOLDEN "golden/moge2_vits_config/"
#define TOL 1e-4    /* the golden README's bound for a float32 implementation */
#define TOKENS 600  /* what the golden run used */

/* Relative L2 error over the entries finite in the reference; *mismatch counts entries where
 * exactly one of the two is finite. */
static double rel_l2(const float *got, const float *ref, size_t n, size_t *mismatch)
{
    double num = 0, den = 0;
    *mismatch = 0;
    for (size_t i = 0; i < n; i++) {
        if (isfinite(ref[i]) != isfinite(got[i])) (*mismatch)++;
        if (!isfinite(ref[i]) || !isfinite(got[i])) continue;
        double d = (double)got[i] - ref[i];
        num += d * d;
        den += (double)ref[i] * ref[i];
    }
    return sqrt(num / (den > 0 ? den : 1));
}

/* Compares `got` ([n] floats) with golden tensor `name`. */
static void compare(const g3d_ckpt *act, const char *name, const float *got, size_t n)
{
    const g3d_tensor_info *t = g3d_ckpt_find(act, name);
    CHECK_MSG(t && (size_t)t->numel == n, "%s: missing or %lld elements, expected %zu", name,
              t ? (long long)t->numel : -1LL, n);
    CHECK_MSG(got != NULL, "%s: no output", name);
    if (!t || (size_t)t->numel != n || !got) return;
    float *ref = NULL;
    CHECK_OK(g3d_ckpt_read_alloc(act, name, 0, NULL, &ref));
    if (!ref) return;
    size_t bad;
    double e = rel_l2(got, ref, n, &bad);
    printf("  %-22s rel L2 %.3e\n", name, e);
    CHECK_MSG(e <= TOL, "%s: relative L2 error %.3e > %g", name, e, TOL);
    CHECK_MSG(bad == 0, "%s: %zu entries finite in only one of the two", name, bad);
    free(ref);
}

TEST(golden_vits)
{
    g3d_ckpt *act = NULL;
    g3d_moge *m = NULL;
    CHECK_OK(g3d_ckpt_open(test_shared(GOLDEN "activations.safetensors"), &act));
    CHECK_OK(g3d_moge_load_file(test_shared(GOLDEN "model.pt"), &m));
    const g3d_tensor_info *img = act ? g3d_ckpt_find(act, "input.image_rgb_u8") : NULL;
    CHECK(img && img->ndim == 3 && img->shape[2] == 3);
    if (!m || !img) goto out;
    CHECK(g3d_moge_has_normal(m) && g3d_moge_has_mask(m) && g3d_moge_has_scale(m));
    CHECK(g3d_moge_default_tokens(m) == 3600);
    char desc[160];
    printf("  %s\n", g3d_moge_describe(m, desc, sizeof desc));
    CHECK(strstr(desc, "dinov2_vits14") != NULL);

    int h = (int)img->shape[0], w = (int)img->shape[1];
    size_t npx = (size_t)w * h;
    float *rgb = malloc(sizeof(float) * npx * 3);
    CHECK_OK(g3d_ckpt_read(act, "input.image_rgb_u8", 0, NULL, rgb));
    for (size_t i = 0; i < npx * 3; i++) rgb[i] /= 255.0f;

    g3d_moge_trace tr = {.want = 1};
    g3d_moge_output o;
    CHECK_OK(g3d_moge_forward(m, rgb, w, h, TOKENS, &o, &tr));
    CHECK(tr.rows == 20 && tr.cols == 30); /* round(sqrt(600 / a)), round(sqrt(600 a)) */
    if (o.points) {
        size_t np = (size_t)tr.rows * tr.cols;
        compare(act, "encoder.image_14", tr.image14, (size_t)3 * 14 * tr.rows * 14 * tr.cols);
        compare(act, "encoder.features", tr.features, (size_t)tr.features_c * np);
        compare(act, "encoder.cls_token", tr.cls, 384);
        char name[32];
        for (int l = 0; l < 3; l++) {
            snprintf(name, sizeof name, "neck.level%d", l);
            compare(act, name, tr.neck[l], (size_t)tr.neck_c[l] * (np << (2 * l)));
        }
        compare(act, "forward.points", o.points, npx * 3);
        compare(act, "forward.mask", o.mask, npx);
        compare(act, "forward.metric_scale", &o.metric_scale, 1);
    }
    g3d_moge_trace_free(&tr);
    g3d_moge_output_free(&o);

    g3d_moge_result r;
    CHECK_OK(g3d_moge_infer(m, rgb, w, h, TOKENS, 0, &r));
    if (r.depth) {
        compare(act, "infer.points", r.points, npx * 3);
        compare(act, "infer.depth", r.depth, npx);
        compare(act, "infer.normal", r.normal, npx * 3);
        compare(act, "infer.intrinsics", r.intrinsics, 9);
        uint8_t *mask = malloc(npx);
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
        free(mask);
    }
    g3d_moge_result_free(&r);
    free(rgb);
out:
    g3d_moge_free(m);
    g3d_ckpt_free(act);
}

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
TEST(estimator_metric_depth_and_intrinsics)
{
    g3d_ckpt *act = NULL;
    g3d_moge *m = NULL;
    CHECK_OK(g3d_ckpt_open(test_shared(GOLDEN "activations.safetensors"), &act));
    CHECK_OK(g3d_moge_load_file(test_shared(GOLDEN "model.pt"), &m));
    const g3d_tensor_info *img = act ? g3d_ckpt_find(act, "input.image_rgb_u8") : NULL;
    if (!m || !img) {
        g3d_moge_free(m);
        g3d_ckpt_free(act);
        return;
    }
    int h = (int)img->shape[0], w = (int)img->shape[1];
    size_t npx = (size_t)w * h;
    g3d_image rgb = {0}, d1 = {0}, d2 = {0};
    CHECK_OK(g3d_image_create(&rgb, w, h, 3));
    CHECK_OK(g3d_ckpt_read(act, "input.image_rgb_u8", 0, NULL, rgb.data));
    for (size_t i = 0; i < npx * 3; i++) rgb.data[i] /= 255.0f;
    float *ref = NULL, *Kref = NULL;
    CHECK_OK(g3d_ckpt_read_alloc(act, "infer.depth", 0, NULL, &ref));
    CHECK_OK(g3d_ckpt_read_alloc(act, "infer.intrinsics", 0, NULL, &Kref));
    g3d_depth_estimator est = {0};
    CHECK_OK(g3d_depth_estimator_moge_create(m, TOKENS, &est));
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
        CHECK(sqrt(num / den) <= TOL && bad == 0);
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

TEST(bad_arguments)
{
    g3d_moge *m = NULL;
    CHECK_OK(g3d_moge_load_file(test_shared(GOLDEN "model.pt"), &m));
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

TEST(wrong_checkpoint_refused)
{
    g3d_moge *m = (g3d_moge *)1;
    CHECK_FAILS(g3d_moge_load_file(test_shared("golden/depth_anything_v2_vits/weights.safetensors"), &m));
    CHECK(m == NULL);
    CHECK(strstr(g3d_error_message(), "not a MoGe checkpoint") != NULL);
    CHECK(strstr(g3d_error_message(), "weights.safetensors") != NULL);
    m = (g3d_moge *)1;
    CHECK_FAILS(g3d_moge_load_file(test_shared(GOLDEN "README.md"), &m));
    CHECK(m == NULL);
}

/* CRC-32 (zip's polynomial), to keep an edited zip entry valid. */
static uint32_t crc32_of(const unsigned char *p, size_t n)
{
    uint32_t c = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++) {
        c ^= p[i];
        for (int k = 0; k < 8; k++) c = c & 1 ? (c >> 1) ^ 0xEDB88320u : c >> 1;
    }
    return ~c;
}

static uint32_t rd32(const unsigned char *p) { return p[0] | p[1] << 8 | p[2] << 16 | (uint32_t)p[3] << 24; }
static void wr32(unsigned char *p, uint32_t v) { p[0] = v; p[1] = v >> 8; p[2] = v >> 16; p[3] = v >> 24; }

/* Replaces the first occurrence of `from` in the stored data.pkl entry of a PyTorch zip by
 * `to` (same length), fixes the entry's CRC in both headers, then expects the MoGe loader to
 * fail with a message containing `expect`. */
static void expect_refused(const unsigned char *file, size_t n, const char *from, const char *to, const char *expect)
{
    unsigned char *z = malloc(n);
    memcpy(z, file, n);
    size_t len = strlen(from);
    int done = 0;
    for (size_t c = 0; c + 46 < n && !done; c++) {
        if (rd32(z + c) != 0x02014b50u) continue;    /* central directory entry */
        size_t nlen = z[c + 28] | z[c + 29] << 8;
        if (nlen < 8 || memcmp(z + c + 46 + nlen - 8, "data.pkl", 8)) continue;
        size_t lh = rd32(z + c + 42), size = rd32(z + c + 24);
        size_t data = lh + 30 + (z[lh + 26] | z[lh + 27] << 8) + (z[lh + 28] | z[lh + 29] << 8);
        for (size_t i = data; i + len <= data + size; i++)
            if (!memcmp(z + i, from, len)) {
                memcpy(z + i, to, len);
                uint32_t crc = crc32_of(z + data, size);
                wr32(z + c + 16, crc);
                wr32(z + lh + 14, crc);
                done = 1;
                break;
            }
    }
    CHECK_MSG(done, "'%s' not found in data.pkl", from);
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

TEST(missing_tensor_or_bad_config_named)
{
    unsigned char *file = NULL;
    size_t n = 0;
    CHECK_OK(g3d_read_file(test_shared(GOLDEN "model.pt"), (size_t)1 << 30, &file, &n));
    if (!file) return;
    expect_refused(file, n, "neck.res_blocks.2.1.layers.5.bias", "neck.res_blocks.2.1.layers.5.biaX",
                   "neck.res_blocks.2.1.layers.5.bias");
    expect_refused(file, n, "encoder.backbone.blocks.7.mlp.fc2.weight", "encoder.backbone.blocks.7.mlp.fc2.weighX",
                   "encoder.backbone.blocks.7.mlp.fc2.weight");
    expect_refused(file, n, "encoder.backbone.pos_embed", "encoder.backbone.pos_embeX", "encoder.backbone.pos_embed");
    expect_refused(file, n, "scale_head.2.weight", "scale_head.2.weighX", "scale_head.2.weight");
    expect_refused(file, n, "encoder.image_std", "encoder.image_stX", "encoder.image_std");
    expect_refused(file, n, "mask_head.output_blocks.4.weight", "mask_head.output_blocks.4.weighX",
                   "mask_head.output_blocks.4.weight");
    /* configuration values: normalisation layers, resamplers, backbone name, the config itself */
    expect_refused(file, n, "none", "gn32", "res_block_in_norm");
    expect_refused(file, n, "conv_transpose", "pixel_shuffle!", "resampler 'pixel_shuffle!'");
    expect_refused(file, n, "dinov2_vits14", "dinov2_vitg14", "dinov2_vitg14");
    expect_refused(file, n, "model_config", "model_confiX", "model_config");
    free(file);
}

int main(void)
{
    RUN(wrong_checkpoint_refused);
    RUN(missing_tensor_or_bad_config_named);
    RUN(resize_bilinear_aa_matches_pytorch);
    RUN(bad_arguments);
    RUN(golden_vits);
    RUN(estimator_metric_depth_and_intrinsics);
    return test_summary();
}
