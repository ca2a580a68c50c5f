/* Depth Anything V2 against the official PyTorch activations (seeded weights): the tiny
 * configuration in tests/fixtures (relative and metric heads; made by make_dav2_golden.py) and,
 * in the extended run, the ViT-S set in shared/golden/depth_anything_v2_vits. Every recorded
 * tensor from the raw image on, plus the refusals of wrong checkpoints. */
#include "golden.h"

#include "gen3d/depth_anything.h"
#include "gen3d/recognize.h"

#include <omp.h>

#define GOLDEN "golden/depth_anything_v2_vits/"

/* The architecture a golden was made with, as the checks expect the loader to read it. */
typedef struct golden_arch {
    int input_size, net_w, net_h;   /* input size given, network input it implies */
    int width, features;            /* ViT width, DPT features */
    int nblocks, blocks[12];        /* recorded block outputs */
} golden_arch;

/* Runs the model on the golden's picture and compares every recorded tensor: preprocessing,
 * patch embedding, block outputs, the head's inputs, the four fusion outputs, the depth at the
 * network's and at the image's size. Then the metric head (sigmoid times the maximum depth):
 * against the official metric run where the golden has one ("metric.*"), and always through its
 * relation to the relative head, which keeps the ReLU's input where it passed. Where recorded,
 * a square picture whose token grid is the position table's own ("square.*"). */
static void check_golden(const char *weights, const char *acts, const golden_arch *a)
{
    g3d_ckpt *act = NULL, *wts = NULL;
    g3d_dav2 *m = NULL;
    float *rgb = NULL, *depth = NULL;
    g3d_dav2_trace tr = {.want = 1}, mt = {.want = 1};
    CHECK_OK(g3d_ckpt_open(acts, &act));
    CHECK_OK(g3d_ckpt_open(weights, &wts));
    if (!act || !wts) goto out;
    CHECK_OK(g3d_dav2_load(wts, &m));
    const g3d_tensor_info *pos = g3d_ckpt_find(wts, "pretrained.pos_embed");
    const g3d_tensor_info *rn = g3d_ckpt_find(wts, "depth_head.scratch.layer1_rn.weight");
    CHECK(pos && pos->ndim == 3 && pos->shape[2] == a->width && rn && rn->shape[0] == a->features);
    int w = 0, h = 0;
    if (!m || !pos || pos->ndim != 3 || pos->shape[2] != a->width || !rn || rn->shape[0] != a->features ||
        !(rgb = golden_image(act, "input.image_rgb_u8", &w, &h)))
        goto out;
    size_t npx = (size_t)w * h, D = (size_t)a->width, F = (size_t)a->features;
    depth = malloc(sizeof(float) * npx);
    CHECK_OK(g3d_dav2_predict(m, rgb, w, h, a->input_size, depth, &tr));
    CHECK(tr.net_w == a->net_w && tr.net_h == a->net_h);
    if (tr.input && tr.net_w == a->net_w && tr.net_h == a->net_h) {
        size_t np = (size_t)(tr.net_w / 14) * (tr.net_h / 14);
        golden_compare(act, "input.tensor", tr.input, 3 * (size_t)tr.net_w * tr.net_h);
        golden_compare(act, "out.patch_embed", tr.backbone.patch_embed, np * D);
        char name[64];
        for (int i = 0; i < a->nblocks; i++) {
            snprintf(name, sizeof name, "out.block%d", a->blocks[i]);
            golden_compare(act, name, tr.backbone.block[a->blocks[i]], (np + 1) * D);
        }
        for (int i = 0; i < 4; i++) {
            snprintf(name, sizeof name, "out.feature%d", i);
            golden_compare(act, name, tr.feature[i], np * D);
        }
        for (int i = 3; i >= 0; i--) {
            snprintf(name, sizeof name, "out.path_%d", i + 1);
            golden_compare(act, name, tr.path[i], F * tr.path_h[i] * tr.path_w[i]);
        }
        golden_compare(act, "out.depth", tr.depth, (size_t)tr.net_w * tr.net_h);
        golden_compare(act, "out.depth_full", depth, npx);
    }
    g3d_dav2_set_metric(m, 20.0f);
    CHECK(g3d_dav2_max_depth(m) == 20.0f);
    CHECK_OK(g3d_dav2_predict(m, rgb, w, h, a->input_size, depth, &mt));
    if (g3d_ckpt_find(act, "metric.depth") && mt.depth) {
        golden_compare(act, "metric.depth", mt.depth, (size_t)mt.net_w * mt.net_h);
        golden_compare(act, "metric.depth_full", depth, npx);
    }
    /* Where the ReLU passed its input, the metric output is 20 sigmoid(it); where it clipped,
     * the input was <= 0 and the metric output at most 10 m. */
    if (tr.depth && mt.depth) {
        size_t n = (size_t)tr.net_w * tr.net_h, passed = 0;
        double worst = 0;
        int clipped_ok = 1;
        for (size_t i = 0; i < n; i++) {
            if (tr.depth[i] > 0) {
                double want = 20.0 / (1.0 + exp(-(double)tr.depth[i]));
                worst = fmax(worst, fabs(mt.depth[i] - want) / want);
                passed++;
            } else {
                clipped_ok &= mt.depth[i] > 0 && mt.depth[i] <= 10.0f;
            }
        }
        printf("  metric head: %zu of %zu values checked, worst rel error %.2e\n", passed, n, worst);
        CHECK(passed > n / 10 && worst < 1e-5 && clipped_ok);
    }
    g3d_dav2_set_metric(m, 0);
    /* A square picture whose token grid is the position table's own: the table is used as it is. */
    const g3d_tensor_info *sq = g3d_ckpt_find(act, "square.depth");
    float *sqrgb = sq ? golden_image(act, "square.image_rgb_u8", &w, &h) : NULL;
    if (sqrgb && sq->ndim == 3) {
        g3d_dav2_trace st = {.want = 1};
        float *sqdepth = malloc(sizeof(float) * (size_t)w * h);
        CHECK_OK(g3d_dav2_predict(m, sqrgb, w, h, (int)sq->shape[1], sqdepth, &st));
        CHECK(st.net_w == st.net_h && st.net_w == (int)sq->shape[1]);
        if (st.depth) golden_compare(act, "square.depth", st.depth, (size_t)st.net_w * st.net_h);
        g3d_dav2_trace_free(&st);
        free(sqdepth);
    }
    free(sqrgb);
out:
    g3d_dav2_trace_free(&mt);
    g3d_dav2_trace_free(&tr);
    free(rgb);
    free(depth);
    g3d_dav2_free(m);
    g3d_ckpt_free(act);
    g3d_ckpt_free(wts);
}

/* 4 blocks of width 128 (2 heads), a 6x6 position grid, DPT features 16, a 61x43 picture at
 * input size 70 (a 7x5 token grid). */
TEST(golden_tiny)
{
    golden_arch a = {.input_size = 70, .net_w = 98, .net_h = 70, .width = 128, .features = 16,
                     .nblocks = 4, .blocks = {0, 1, 2, 3}};
    check_golden(test_fixture("dav2_tiny.pth"), test_fixture("dav2_tiny_golden.safetensors"), &a);
}

TEST(golden_vits)
{
    golden_arch a = {.input_size = 196, .net_w = 294, .net_h = 196, .width = 384, .features = 64,
                     .nblocks = 5, .blocks = {0, 2, 5, 8, 11}};
    check_golden(test_shared(GOLDEN "weights.safetensors"), test_shared(GOLDEN "activations.safetensors"), &a);
}

/* The prediction is the same, bit for bit, with 1, 2 and 3 threads (the products, Winograd
 * convolutions and attention give every output one fixed order of operations). */
TEST(same_result_for_any_thread_count)
{
    g3d_dav2 *m = NULL;
    CHECK_OK(g3d_dav2_load_file(test_fixture("dav2_tiny.pth"), &m));
    if (!m) return;
    const int w = 75, h = 61;
    float *rgb = malloc(sizeof(float) * 3 * w * h), *d[3] = {0};
    g3d_rng r;
    g3d_rng_seed(&r, 5, 1);
    for (int i = 0; i < 3 * w * h; i++) rgb[i] = g3d_rng_float(&r);
    const int saved = omp_get_max_threads();
    for (int t = 0; t < 3; t++) {
        d[t] = malloc(sizeof(float) * w * h);
        omp_set_num_threads(t + 1);
        CHECK_OK(g3d_dav2_predict(m, rgb, w, h, 112, d[t], NULL));
    }
    omp_set_num_threads(saved);
    CHECK(memcmp(d[0], d[1], sizeof(float) * w * h) == 0);
    CHECK(memcmp(d[0], d[2], sizeof(float) * w * h) == 0);
    for (int t = 0; t < 3; t++) free(d[t]);
    free(rgb);
    g3d_dav2_free(m);
}

TEST(metric_defaults_from_names)
{
    CHECK(g3d_dav2_metric_default("ckpt/depth_anything_v2_metric_hypersim_vits.pth") == 20.0f);
    CHECK(g3d_dav2_metric_default("depth_anything_v2_metric_vkitti_vitl.pth") == 80.0f);
    CHECK(g3d_dav2_metric_default("metric_vkitti/depth_anything_v2_vits.pth") == 0.0f);
    CHECK(g3d_dav2_metric_default("depth_anything_v2_vitb.pth") == 0.0f);
}

TEST(net_size_rule)
{
    int w, h;
    /* official lower_bound rule: COCO 640x480 at 518 -> 686x518; the golden 640x425 at 196 -> 294x196 */
    CHECK_OK(g3d_dav2_net_size(640, 480, 518, &w, &h));
    CHECK(w == 686 && h == 518);
    CHECK_OK(g3d_dav2_net_size(640, 425, 196, &w, &h));
    CHECK(w == 294 && h == 196);
    CHECK_OK(g3d_dav2_net_size(100, 1000, 518, &w, &h)); /* 518 x 5180: both sides >= 518 */
    CHECK(w == 518 && h == 5180);
    CHECK_FAILS(g3d_dav2_net_size(0, 10, 518, &w, &h));
    CHECK_FAILS(g3d_dav2_net_size(40000, 10, 518, &w, &h));
    CHECK_FAILS(g3d_dav2_net_size(640, 480, 5, &w, &h));
    CHECK_FAILS(g3d_dav2_net_size(10, 32768, 518, &w, &h)); /* would need a 1700000-wide input */
}

/* Activations, a README and an image are not Depth Anything checkpoints. */
static void expect_not_a_model(const char *acts, const char *other)
{
    g3d_dav2 *m = (g3d_dav2 *)1;
    CHECK_FAILS(g3d_dav2_load_file(acts, &m));
    CHECK(m == NULL);
    CHECK(strstr(g3d_error_message(), "depth_head.scratch.layer1_rn.weight") != NULL);
    CHECK_FAILS(g3d_dav2_load_file(other, &m));
    CHECK(m == NULL);
}

TEST(wrong_checkpoint_refused)
{
    expect_not_a_model(test_fixture("dav2_tiny_golden.safetensors"), test_fixture("jpeg_420_61x47.jpg"));
}

TEST(wrong_checkpoint_refused_vits)
{
    expect_not_a_model(test_shared(GOLDEN "activations.safetensors"), test_shared(GOLDEN "README.md"));
}

/* Loads an edited copy of a checkpoint and expects the loader to refuse it naming `tensor`. */
static void expect_refused(unsigned char *edited, size_t n, const char *label, const char *tensor)
{
    g3d_ckpt *ck = NULL;
    g3d_dav2 *m = (g3d_dav2 *)1;
    if (!edited) return;
    CHECK_OK(g3d_ckpt_open_memory(edited, n, label, &ck));
    if (ck) {
        CHECK_FAILS(g3d_dav2_load(ck, &m));
        CHECK(m == NULL);
        CHECK_MSG(strstr(g3d_error_message(), tensor) != NULL, "message does not name %s", tensor);
    }
    g3d_ckpt_free(ck);
    free(edited);
}

/* The tiny .pth with one tensor renamed in its pickle: the loader names the missing tensor. */
TEST(missing_tensor_named)
{
    unsigned char *file = NULL;
    size_t n = 0;
    CHECK_OK(g3d_read_file(test_fixture("dav2_tiny.pth"), (size_t)1 << 30, &file, &n));
    if (!file) return;
    static const char *names[] = {"pretrained.blocks.3.mlp.fc2.bias", "pretrained.norm.weight",
                                  "depth_head.resize_layers.1.weight",
                                  "depth_head.scratch.refinenet2.resConfUnit1.conv2.bias",
                                  "depth_head.scratch.output_conv2.2.weight"};
    for (size_t i = 0; i < sizeof names / sizeof *names; i++) {
        char to[96];
        snprintf(to, sizeof to, "%s", names[i]);
        to[strlen(to) - 1] = 'X';
        expect_refused(golden_edit_pickle(file, n, names[i], to), n, "renamed.pth", names[i]);
    }
    free(file);
}

TEST(missing_tensor_named_vits)
{
    unsigned char *file = NULL;
    size_t n = 0;
    CHECK_OK(g3d_read_file(test_shared(GOLDEN "weights.safetensors"), (size_t)1 << 30, &file, &n));
    if (!file) return;
    static const char *names[] = {"pretrained.blocks.7.mlp.fc2.bias", "pretrained.norm.weight",
                                  "depth_head.resize_layers.1.weight",
                                  "depth_head.scratch.refinenet2.resConfUnit1.conv2.bias",
                                  "depth_head.scratch.output_conv2.2.weight"};
    for (size_t i = 0; i < sizeof names / sizeof *names; i++)
        expect_refused(golden_edit_safetensors(file, n, names[i]), n, "renamed.safetensors", names[i]);
    free(file);
}

/* Writes the tiny checkpoint's tensors as safetensors, with tensor `odd` (if any) given
 * `shape` instead of its own (filled with zeros), plus `extra` (if any) as one more tensor. */
static void rewrite(const g3d_ckpt *ck, const char *path, const char *odd, int ndim, const int64_t *shape,
                    const char *extra)
{
    int n = (int)g3d_ckpt_count(ck);
    g3d_tensor_out *t = calloc((size_t)n + 1, sizeof *t);
    float *zeros = calloc(1 << 20, sizeof(float));
    for (int i = 0; i < n; i++) {
        const g3d_tensor_info *s = g3d_ckpt_tensor(ck, i);
        t[i] = (g3d_tensor_out){s->name, s->dtype, s->ndim, {0}, s->data};
        memcpy(t[i].shape, s->shape, sizeof s->shape);
        if (odd && !strcmp(s->name, odd)) {
            t[i] = (g3d_tensor_out){s->name, G3D_DT_F32, ndim, {0}, zeros};
            memcpy(t[i].shape, shape, sizeof(int64_t) * (size_t)ndim);
        }
    }
    if (extra) t[n++] = (g3d_tensor_out){extra, G3D_DT_F32, 1, {4}, zeros};
    CHECK_OK(g3d_safetensors_write(path, t, n, NULL));
    free(t);
    free(zeros);
}

/* The same tensors as safetensors load and run alike; a tensor whose shape disagrees with the
 * architecture the others imply, or a head variant no published checkpoint has, is refused
 * naming the tensor. */
TEST(architecture_from_shapes)
{
    g3d_ckpt *ck = NULL;
    CHECK_OK(g3d_ckpt_open(test_fixture("dav2_tiny.pth"), &ck));
    if (!ck) return;
    char arch[256];
    CHECK(g3d_model_describe(ck, arch, sizeof arch) != NULL);
    printf("  %s\n", arch);
    CHECK(strstr(arch, "4 blocks") && strstr(arch, "width 128") && strstr(arch, "2 attention heads") &&
          strstr(arch, "features 16") && strstr(arch, "16, 32, 48, 64"));
    rewrite(ck, test_tmp("dav2_tiny.safetensors"), NULL, 0, NULL, NULL);
    golden_arch a = {.input_size = 70, .net_w = 98, .net_h = 70, .width = 128, .features = 16,
                     .nblocks = 1, .blocks = {3}};
    check_golden(test_tmp("dav2_tiny.safetensors"), test_fixture("dav2_tiny_golden.safetensors"), &a);

    static const struct { const char *name; int ndim; int64_t shape[4]; } odd[] = {
        {"pretrained.blocks.2.mlp.fc1.weight", 2, {192, 128}},          /* another MLP width */
        {"pretrained.blocks.1.attn.qkv.weight", 2, {384, 96}},          /* another width */
        {"pretrained.patch_embed.proj.weight", 4, {128, 3, 16, 16}},    /* 16-pixel patches */
        {"depth_head.projects.2.weight", 4, {48, 96, 1, 1}},            /* not the ViT's width */
        {"depth_head.resize_layers.3.weight", 4, {64, 64, 2, 2}},       /* not the official kernel */
        {"depth_head.scratch.layer3_rn.weight", 4, {16, 40, 3, 3}},     /* not the projection's width */
        {"depth_head.scratch.refinenet4.out_conv.weight", 4, {8, 16, 1, 1}},
        {"depth_head.scratch.output_conv2.2.weight", 4, {1, 24, 1, 1}}, /* not output_conv2.0's width */
    };
    for (size_t i = 0; i < sizeof odd / sizeof *odd; i++) {
        rewrite(ck, test_tmp("dav2_odd.safetensors"), odd[i].name, odd[i].ndim, odd[i].shape, NULL);
        g3d_dav2 *m = (g3d_dav2 *)1;
        CHECK_FAILS(g3d_dav2_load_file(test_tmp("dav2_odd.safetensors"), &m));
        CHECK(m == NULL);
        CHECK_MSG(strstr(g3d_error_message(), odd[i].name) != NULL, "message does not name %s", odd[i].name);
    }
    static const char *variants[] = {"depth_head.readout_projects.0.0.weight",
                                     "depth_head.scratch.refinenet1.resConfUnit1.bn1.weight",
                                     "pretrained.register_tokens"};
    for (size_t i = 0; i < sizeof variants / sizeof *variants; i++) {
        rewrite(ck, test_tmp("dav2_odd.safetensors"), NULL, 0, NULL, variants[i]);
        g3d_dav2 *m = (g3d_dav2 *)1;
        CHECK_FAILS(g3d_dav2_load_file(test_tmp("dav2_odd.safetensors"), &m));
        CHECK(m == NULL && strstr(g3d_error_message(), variants[i]) != NULL);
    }
    g3d_ckpt_free(ck);
}

int main(int argc, char **argv)
{
    if (test_extended(argc, argv)) {
        RUN(wrong_checkpoint_refused_vits);
        RUN(missing_tensor_named_vits);
        RUN(golden_vits);
        return test_summary();
    }
    RUN(metric_defaults_from_names);
    RUN(net_size_rule);
    RUN(wrong_checkpoint_refused);
    RUN(missing_tensor_named);
    RUN(golden_tiny);
    RUN(same_result_for_any_thread_count);
    RUN(architecture_from_shapes);
    return test_summary();
}
