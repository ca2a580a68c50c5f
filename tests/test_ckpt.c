/* Checkpoints: the safetensors reader on the golden weights, every dtype, hostile headers. */
#include "golden.h"
#include "testutil.h"
#include "gen3d/ckpt.h"
#include "gen3d/recognize.h"

#include <cjson/cJSON.h>
#include <stdint.h>
#include <string.h>
#include <unistd.h>

static const char *FIX = G3D_SOURCE_DIR "/tests/fixtures/dtypes.safetensors";

/* A Depth Anything V2 checkpoint and its golden activations, as the loader must index them. */
typedef struct weights_case {
    const char *weights, *acts;
    int64_t count, width, pos;     /* tensors, ViT width, position-table rows */
    int blocks, img_h, img_w;      /* encoder depth; the golden picture's size */
    g3d_dtype dtype;               /* how the weights are stored */
    const char *model, *arch;      /* metadata "model" (safetensors only), text in the description */
} weights_case;

static void check_weights(const weights_case *c)
{
    g3d_ckpt *ck;
    CHECK_OK(g3d_ckpt_open(c->weights, &ck));
    if (!ck) return;
    CHECK(g3d_ckpt_count(ck) == c->count);
    const g3d_tensor_info *t = g3d_ckpt_find(ck, "pretrained.blocks.0.attn.qkv.weight");
    CHECK(t && t->dtype == c->dtype && t->ndim == 2 && t->shape[0] == 3 * c->width && t->shape[1] == c->width);
    t = g3d_ckpt_find(ck, "pretrained.pos_embed");
    CHECK(t && t->ndim == 3 && t->shape[1] == c->pos);
    char name[64];
    snprintf(name, sizeof name, "pretrained.blocks.%d.attn.qkv.weight", c->blocks);
    CHECK(g3d_ckpt_find(ck, name) == NULL);
    if (c->model) {
        const cJSON *model = cJSON_GetObjectItemCaseSensitive(g3d_ckpt_meta(ck), "model");
        CHECK(cJSON_IsString(model) && !strcmp(model->valuestring, c->model));
    }
    char arch[256], blocks[32];
    snprintf(blocks, sizeof blocks, "%d blocks", c->blocks);
    CHECK(g3d_model_describe(ck, arch, sizeof arch) && strstr(arch, c->arch) && strstr(arch, blocks));
    /* Reading with the right shape works; a wrong shape or name is an error naming it. */
    int64_t qkv_shape[2] = {3 * c->width, c->width}, wrong[2] = {c->width, 3 * c->width};
    float *w = NULL;
    CHECK_OK(g3d_ckpt_read_alloc(ck, "pretrained.blocks.0.attn.qkv.weight", 2, qkv_shape, &w));
    double sum = 0;
    int finite = 1;
    for (int64_t i = 0; w && i < 3 * c->width * c->width; i++) { sum += fabs(w[i]); finite &= isfinite(w[i]); }
    CHECK(finite && sum > 0);
    free(w);
    char got[64], want[64];
    snprintf(got, sizeof got, "[%lld, %lld]", (long long)qkv_shape[0], (long long)qkv_shape[1]);
    snprintf(want, sizeof want, "expected [%lld, %lld]", (long long)wrong[0], (long long)wrong[1]);
    CHECK_FAILS(g3d_ckpt_read_alloc(ck, "pretrained.blocks.0.attn.qkv.weight", 2, wrong, &w));
    CHECK(strstr(g3d_error_message(), got) && strstr(g3d_error_message(), want));
    CHECK_FAILS(g3d_ckpt_read_alloc(ck, "pretrained.blocks.0.attn.qkvv.weight", 0, NULL, &w));
    CHECK(strstr(g3d_error_message(), "qkvv") != NULL);
    printf("  %lld tensors, %lld parameters: %s\n", (long long)g3d_ckpt_count(ck), (long long)g3d_ckpt_numel(ck), arch);
    g3d_ckpt_free(ck);

    /* The activations file: U8 image and F32 tensors. */
    CHECK_OK(g3d_ckpt_open(c->acts, &ck));
    if (!ck) return;
    t = g3d_ckpt_find(ck, "input.image_rgb_u8");
    CHECK(t && t->dtype == G3D_DT_U8 && t->shape[0] == c->img_h && t->shape[1] == c->img_w && t->shape[2] == 3);
    float *img = NULL;
    CHECK_OK(g3d_ckpt_read_alloc(ck, "input.image_rgb_u8", 0, NULL, &img));
    int ints = img != NULL;
    for (int i = 0; img && i < c->img_h * c->img_w * 3; i++) ints &= img[i] >= 0 && img[i] <= 255 && img[i] == floorf(img[i]);
    CHECK(ints);
    free(img);
    CHECK(g3d_model_describe(ck, arch, sizeof arch) == NULL);
    g3d_ckpt_free(ck);
}

/* The tiny Depth Anything V2 fixture: a .pth state dict stored in fp16. */
TEST(fixture_weights)
{
    weights_case c = {test_fixture("dav2_tiny.pth"), test_fixture("dav2_tiny_golden.safetensors"), 127, 128, 37, 4,
                      43, 61, G3D_DT_F16, NULL, "width 128"};
    check_weights(&c);
}

/* The ViT-S golden in ../shared: safetensors with the official names (240 header entries, one of
 * them __metadata__). */
TEST(golden_weights)
{
    weights_case c = {test_shared("golden/depth_anything_v2_vits/weights.safetensors"),
                      test_shared("golden/depth_anything_v2_vits/activations.safetensors"), 239, 384, 1370, 12, 425, 640,
                      G3D_DT_F16, "depth_anything_v2_vits", "vits"};
    check_weights(&c);
}

/* A MoGe-2 checkpoint in the official layout: {'model_config', 'model'} with state-dict names. */
static void check_moge_checkpoint(const char *path, int64_t width)
{
    g3d_ckpt *ck;
    CHECK_OK(g3d_ckpt_open(path, &ck));
    if (!ck) return;
    const g3d_tensor_info *t = g3d_ckpt_find(ck, "encoder.backbone.blocks.0.attn.qkv.weight");
    CHECK(t && t->dtype == G3D_DT_F16 && t->shape[0] == 3 * width && t->shape[1] == width);
    CHECK(g3d_ckpt_find(ck, "scale_head.0.weight") != NULL);
    CHECK(cJSON_IsObject(cJSON_GetObjectItemCaseSensitive(g3d_ckpt_meta(ck), "model_config")));
    printf("  MoGe-2 checkpoint: %lld tensors, %lld parameters\n", (long long)g3d_ckpt_count(ck), (long long)g3d_ckpt_numel(ck));
    g3d_ckpt_free(ck);
}

TEST(moge_checkpoint)
{
    check_moge_checkpoint(test_fixture("moge_tiny.pt"), 128);
}

TEST(moge_golden_checkpoint)
{
    check_moge_checkpoint(test_shared("golden/moge2_vits_config/model.pt"), 384);
}

TEST(every_dtype)
{
    g3d_ckpt *ck;
    CHECK_OK(g3d_ckpt_open(FIX, &ck));
    if (!ck) return;
    float v[12];
    const char *floats[] = {"f32", "f16", "bf16", "f64"};
    for (int k = 0; k < 4; k++) {
        const g3d_tensor_info *t = g3d_ckpt_find(ck, floats[k]);
        CHECK_OK(g3d_ckpt_read(ck, floats[k], 0, NULL, v));
        for (int i = 0; t && i < t->numel; i++) CHECK_MSG(v[i] == (float)((i - 5) * 0.75), "%s[%d] = %g", floats[k], i, v[i]);
    }
    CHECK_OK(g3d_ckpt_read(ck, "i64", 0, NULL, v));
    for (int i = 0; i < 6; i++) CHECK(v[i] == (float)(i - 3));
    int64_t s23[2] = {2, 3};
    CHECK_OK(g3d_ckpt_read(ck, "i32", 2, s23, v));
    CHECK(v[0] == -3 && v[5] == 2);
    CHECK_OK(g3d_ckpt_read(ck, "u8", 0, NULL, v));
    CHECK(v[5] == 200);
    CHECK_OK(g3d_ckpt_read(ck, "bool", 0, NULL, v));
    CHECK(v[0] == 1 && v[1] == 0 && v[3] == 1);
    CHECK_OK(g3d_ckpt_read(ck, "f16_special", 0, NULL, v));
    CHECK(v[0] == ldexpf(1, -24) && v[1] == 0 && signbit(v[1]) && isinf(v[2]) && v[2] > 0 && isinf(v[3]) && v[3] < 0);
    CHECK(v[4] == 65504.0f && v[5] == ldexpf(1, -14));
    const g3d_tensor_info *e = g3d_ckpt_find(ck, "empty");
    CHECK(e && e->numel == 0 && e->ndim == 2);
    g3d_ckpt_free(ck);
}

/* Builds a safetensors buffer from a header string and n data bytes. */
static size_t make(unsigned char *buf, const char *header, size_t data_bytes)
{
    size_t h = strlen(header);
    for (int i = 0; i < 8; i++) buf[i] = (unsigned char)(h >> (8 * i));
    memcpy(buf + 8, header, h);
    memset(buf + 8 + h, 0x3c, data_bytes);
    return 8 + h + data_bytes;
}

TEST(hostile_headers)
{
    unsigned char buf[4096];
    g3d_ckpt *ck;
    size_t n = make(buf, "{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]}}", 8);
    CHECK_OK(g3d_ckpt_open_memory(buf, n, "ok.safetensors", &ck));
    g3d_ckpt_free(ck);
    struct { const char *name, *header; size_t data; } cases[] = {
        {"not JSON", "{\"a\": [1, 2", 8},
        {"not an object", "[1, 2, 3]", 8},
        {"dtype/shape/bytes mismatch", "{\"a\":{\"dtype\":\"F32\",\"shape\":[3],\"data_offsets\":[0,8]}}", 8},
        {"offsets past the end", "{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[8,16]}}", 8},
        {"reversed offsets", "{\"a\":{\"dtype\":\"U8\",\"shape\":[0],\"data_offsets\":[8,0]}}", 8},
        {"overlap", "{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]},\"b\":{\"dtype\":\"F32\",\"shape\":[1],\"data_offsets\":[4,8]}}", 8},
        {"unknown dtype", "{\"a\":{\"dtype\":\"F8_E4M3\",\"shape\":[2],\"data_offsets\":[0,2]}}", 8},
        {"negative dimension", "{\"a\":{\"dtype\":\"F32\",\"shape\":[-2],\"data_offsets\":[0,8]}}", 8},
        {"absurd shape", "{\"a\":{\"dtype\":\"F32\",\"shape\":[1000000,1000000,1000000],\"data_offsets\":[0,8]}}", 8},
        {"fractional offset", "{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0.5,8.5]}}", 9},
        {"missing offsets", "{\"a\":{\"dtype\":\"F32\",\"shape\":[2]}}", 8},
        {"metadata not strings", "{\"__metadata__\":{\"x\":1},\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]}}", 8},
        {"two metadata objects", "{\"__metadata__\":{\"x\":\"1\"},\"__metadata__\":{\"y\":\"2\"}}", 0},
        {"duplicate name", "{\"a\":{\"dtype\":\"F32\",\"shape\":[1],\"data_offsets\":[0,4]},\"a\":{\"dtype\":\"F32\",\"shape\":[1],\"data_offsets\":[4,8]}}", 8},
    };
    for (size_t k = 0; k < sizeof cases / sizeof *cases; k++) {
        n = make(buf, cases[k].header, cases[k].data);
        printf("  %s:\n", cases[k].name);
        CHECK_FAILS(g3d_ckpt_open_memory(buf, n, "bad.safetensors", &ck));
    }
    /* Header length beyond the end of the file, and a truncated file. */
    n = make(buf, "{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]}}", 8);
    buf[3] = 0x7f;
    CHECK_FAILS(g3d_ckpt_open_memory(buf, n, "len.safetensors", &ck));
    CHECK_FAILS(g3d_ckpt_open_memory(buf, 5, "short.safetensors", &ck));
    /* Files on disk: missing, empty, and a zip (PyTorch) refused with a clear message. */
    CHECK_FAILS(g3d_ckpt_open(test_tmp("missing.safetensors"), &ck));
    FILE *f = fopen(test_tmp("empty.safetensors"), "wb");
    fclose(f);
    CHECK_FAILS(g3d_ckpt_open(test_tmp("empty.safetensors"), &ck));
    CHECK_FAILS(g3d_ckpt_open_memory("PK\x03\x04rest-of-a-zip", 18, "model.pth", &ck));
}

#define FIXDIR G3D_SOURCE_DIR "/tests/fixtures/"

TEST(pytorch_zip)
{
    g3d_ckpt *ck;
    CHECK_OK(g3d_ckpt_open(FIXDIR "state.pth", &ck));
    if (!ck) return;
    /* {'model': state_dict, 'model_config': {...}, 'epoch': 7}: state-dict names, no wrapper. */
    CHECK(g3d_ckpt_count(ck) == 9);
    float v[20];
    const char *floats[] = {"encoder.weight", "encoder.bias", "encoder.norm.weight", "head.0.weight"};
    for (int k = 0; k < 4; k++) {
        const g3d_tensor_info *t = g3d_ckpt_find(ck, floats[k]);
        CHECK_MSG(t != NULL, "%s missing", floats[k]);
        if (!t) continue;
        CHECK_OK(g3d_ckpt_read(ck, floats[k], 0, NULL, v));
        for (int i = 0; i < t->numel; i++) CHECK_MSG(v[i] == (float)((i - 5) * 0.75), "%s[%d] = %g", floats[k], i, v[i]);
    }
    int64_t s34[2] = {3, 4};
    CHECK_OK(g3d_ckpt_read(ck, "encoder.weight", 2, s34, v));
    /* A view 8 elements into a storage it shares with another tensor. */
    CHECK_OK(g3d_ckpt_read(ck, "view", 0, NULL, v));
    CHECK(v[0] == (float)((8 - 5) * 0.75) && v[5] == (float)((13 - 5) * 0.75));
    const g3d_tensor_info *sc = g3d_ckpt_find(ck, "scalar");
    CHECK(sc && sc->ndim == 0 && sc->numel == 1);
    CHECK_OK(g3d_ckpt_read(ck, "head.0.steps", 0, NULL, v));
    CHECK(v[0] == -2 && v[4] == 2);
    CHECK_OK(g3d_ckpt_read(ck, "mask", 0, NULL, v));
    CHECK(v[0] == 1 && v[1] == 0);
    /* Everything else is JSON. */
    const cJSON *cfg = cJSON_GetObjectItemCaseSensitive(g3d_ckpt_meta(ck), "model_config");
    const cJSON *dim = cJSON_GetObjectItemCaseSensitive(cfg, "dim");
    CHECK(cJSON_IsArray(dim) && cJSON_GetArrayItem(dim, 0)->valuedouble == 384);
    CHECK(cJSON_IsString(cJSON_GetObjectItemCaseSensitive(cfg, "encoder")));
    CHECK(cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(cfg, "use_norm")) && cJSON_IsNull(cJSON_GetObjectItemCaseSensitive(cfg, "extra")));
    CHECK(cJSON_GetObjectItemCaseSensitive(g3d_ckpt_meta(ck), "epoch")->valuedouble == 7);
    g3d_ckpt_free(ck);
}

TEST(hostile_pickles)
{
    g3d_ckpt *ck;
    CHECK_OK(g3d_ckpt_open(FIXDIR "ok_handmade.pth", &ck));
    g3d_ckpt_free(ck);
    const char *bad[] = {"evil.pth", "noncontig.pth", "overrun.pth", "missing_storage.pth", "short_storage.pth",
                         "truncated.pth", "badop.pth", "underflow.pth", "leftover.pth", "ckpt_selfref.pth"};
    for (size_t k = 0; k < sizeof bad / sizeof *bad; k++) {
        char path[1024];
        snprintf(path, sizeof path, FIXDIR "%s", bad[k]);
        CHECK_FAILS(g3d_ckpt_open(path, &ck));
    }
    CHECK_FAILS(g3d_ckpt_open(FIXDIR "evil.pth", &ck));
    CHECK(strstr(g3d_error_message(), "system") != NULL);
    /* A zip that is not a checkpoint. */
    CHECK_FAILS(g3d_ckpt_open(FIXDIR "resize_ref.npz", &ck));
}

/* A PyTorch Lightning checkpoint (tests/fixtures/make_lama_golden.py): classes and config
 * objects beside the tensors become names, the state dict keeps its keys, and tensors kept in
 * callbacks and optimizer states load under their paths. */
TEST(lightning_checkpoint)
{
    g3d_ckpt *ck = NULL;
    CHECK_OK(g3d_ckpt_open(FIXDIR "lama_tiny.ckpt", &ck));
    if (!ck) return;
    const g3d_tensor_info *w = g3d_ckpt_find(ck, "generator.model.1.ffc.convl2l.weight");
    CHECK(w && w->ndim == 4 && w->shape[0] == 8 && w->shape[1] == 4);
    CHECK(g3d_ckpt_find(ck, "discriminator.model0.0.weight") != NULL);
    float v[3];
    const char *score = "callbacks.pytorch_lightning.callbacks.model_checkpoint.ModelCheckpoint.best_model_score";
    CHECK_OK(g3d_ckpt_read(ck, score, 0, NULL, v));
    CHECK(v[0] == 0.875f);
    CHECK_OK(g3d_ckpt_read(ck, "optimizer_states.0.state.0.exp_avg", 0, NULL, v));
    const cJSON *meta = g3d_ckpt_meta(ck);
    const cJSON *cb = cJSON_GetObjectItemCaseSensitive(meta, "callbacks");
    const cJSON *mc = cJSON_GetObjectItemCaseSensitive(cb, "pytorch_lightning.callbacks.model_checkpoint.ModelCheckpoint");
    CHECK(cJSON_IsString(cJSON_GetObjectItemCaseSensitive(mc, "monitor")));
    /* a dict subclass holding a configuration object: kept by its class name */
    const cJSON *hp = cJSON_GetObjectItemCaseSensitive(meta, "hyper_parameters");
    CHECK(cJSON_IsString(hp) && !strcmp(hp->valuestring, "pytorch_lightning.utilities.parsing.AttributeDict"));
    CHECK(cJSON_GetObjectItemCaseSensitive(meta, "global_step")->valuedouble == 1200);
    g3d_ckpt_free(ck);

    /* Edited copies: a call into a module that reaches the system, and tensors inside an
     * object of a class the reader does not know (the state dict's OrderedDict renamed). */
    size_t n = 0;
    unsigned char *file = NULL;
    CHECK_OK(g3d_read_file(FIXDIR "lama_tiny.ckpt", (size_t)1 << 24, &file, &n));
    if (!file) return;
    const char *edits[][3] = {{"omegaconf.dictconfig", "subprocess.dictconfi", "subprocess.dictconfi.DictConfig"},
                              {"collections\nOrderedDict", "collectionz\nOrderedDict", "inside a 'collectionz.OrderedDict'"}};
    for (int k = 0; k < 2; k++) {
        unsigned char *z = golden_edit_pickle(file, n, edits[k][0], edits[k][1]);
        if (!z) continue;
        ck = NULL;
        CHECK_FAILS(g3d_ckpt_open_memory(z, n, "edited.ckpt", &ck));
        CHECK(ck == NULL);
        CHECK_MSG(strstr(g3d_error_message(), edits[k][2]) != NULL, "message does not name %s", edits[k][2]);
        free(z);
    }
    free(file);
}

/* Checkpoints written by torch.save (tests/fixtures/make_ckpt_fixtures.py). */
TEST(torch_save_fixtures)
{
    g3d_ckpt *ck = NULL;
    float v[12];
    int64_t s23[2] = {2, 3};
    CHECK_OK(g3d_ckpt_open(FIXDIR "ckpt_dtypes.pt", &ck));
    if (ck) {
        const char *exact[] = {"layer.f32", "layer.f16", "layer.bf16", "layer.f64"};
        for (int k = 0; k < 4; k++) {
            CHECK_OK(g3d_ckpt_read(ck, exact[k], 2, s23, v));
            for (int i = 0; i < 6; i++) CHECK(v[i] == (float)(i * 0.5 - 1));
        }
        /* Casting to integers truncates toward zero in torch. */
        const float ints[6] = {-1, 0, 0, 0, 1, 1};
        CHECK_OK(g3d_ckpt_read(ck, "layer.i64", 2, s23, v));
        for (int i = 0; i < 6; i++) CHECK(v[i] == ints[i]);
        CHECK_OK(g3d_ckpt_read(ck, "layer.i8", 2, s23, v));
        for (int i = 0; i < 6; i++) CHECK(v[i] == ints[i]);
        CHECK_OK(g3d_ckpt_read(ck, "layer.b", 2, s23, v));
        for (int i = 0; i < 6; i++) CHECK(v[i] == (i == 2 ? 0.0f : 1.0f));
        CHECK(g3d_ckpt_find(ck, "layer.bf16")->dtype == G3D_DT_BF16);
        g3d_ckpt_free(ck);
    }
    ck = NULL;
    CHECK_OK(g3d_ckpt_open(FIXDIR "ckpt_nested.pt", &ck));
    if (ck) {
        /* Two views into one shared storage: offsets 4 and 20. */
        int64_t s34[2] = {3, 4}, s4 = 4;
        CHECK_OK(g3d_ckpt_read(ck, "enc.w", 2, s34, v));
        for (int i = 0; i < 12; i++) CHECK(v[i] == (float)(4 + i));
        CHECK_OK(g3d_ckpt_read(ck, "enc.b", 1, &s4, v));
        for (int i = 0; i < 4; i++) CHECK(v[i] == (float)(20 + i));
        CHECK(g3d_ckpt_count(ck) == 3);
        const cJSON *cfg = cJSON_GetObjectItemCaseSensitive(g3d_ckpt_meta(ck), "config");
        const cJSON *sc = cJSON_GetObjectItemCaseSensitive(cfg, "scale");
        const cJSON *pair = cJSON_GetObjectItemCaseSensitive(cfg, "pair");
        CHECK(cJSON_IsNumber(sc) && sc->valuedouble == 0.25);
        CHECK(cJSON_GetArraySize(pair) == 2 && cJSON_GetArrayItem(pair, 1)->valuedouble == -300000);
        g3d_ckpt_free(ck);
    }
    ck = NULL;
    CHECK_FAILS(g3d_ckpt_open(FIXDIR "ckpt_noncontig.pt", &ck));
    CHECK(strstr(g3d_error_message(), "contiguous"));
    CHECK_OK(g3d_ckpt_open(FIXDIR "ckpt_lists.pt", &ck));
    if (ck) {
        CHECK(g3d_ckpt_count(ck) == 3);
        /* List and tuple elements are named by their index. */
        CHECK_OK(g3d_ckpt_read(ck, "a.1.0", 0, NULL, v));
        CHECK(v[0] == 1.0f);
        CHECK(g3d_ckpt_find(ck, "a.0") && g3d_ckpt_find(ck, "a.0")->numel == 2);
        CHECK_OK(g3d_ckpt_read(ck, "b", 0, NULL, v));
        CHECK(v[0] == 7.0f);
        g3d_ckpt_free(ck);
    }
}

/* Our writer's files read back through the same reader, tensors, dtypes and metadata intact. */
TEST(write_round_trip)
{
    float a[6] = {1.5f, -2.0f, 3.25f, 0.0f, 1e-30f, -7.0f};
    int32_t b[3] = {-5, 0, 1 << 30};
    g3d_tensor_out t[3] = {
        {"a", G3D_DT_F32, 2, {2, 3}, a},
        {"b.counts", G3D_DT_I32, 1, {3}, b},
        {"empty", G3D_DT_F32, 1, {0}, a},
    };
    cJSON *meta = cJSON_CreateObject();
    cJSON_AddStringToObject(meta, "k", "v");
    const char *path = test_tmp("written.safetensors");
    CHECK_OK(g3d_safetensors_write(path, t, 3, meta));
    g3d_ckpt *ck = NULL;
    CHECK_OK(g3d_ckpt_open(path, &ck));
    if (ck) {
        CHECK(g3d_ckpt_count(ck) == 3);
        float back[6];
        int64_t shape[2] = {2, 3};
        CHECK_OK(g3d_ckpt_read(ck, "a", 2, shape, back));
        CHECK(memcmp(back, a, sizeof a) == 0);
        const g3d_tensor_info *bi = g3d_ckpt_find(ck, "b.counts");
        CHECK(bi && bi->dtype == G3D_DT_I32 && bi->numel == 3 && memcmp(bi->data, b, sizeof b) == 0);
        CHECK(((uintptr_t)bi->data & 7) == 0 || ((uintptr_t)g3d_ckpt_find(ck, "a")->data & 7) == 0);
        const cJSON *k = cJSON_GetObjectItemCaseSensitive(g3d_ckpt_meta(ck), "k");
        CHECK(cJSON_IsString(k) && strcmp(k->valuestring, "v") == 0);
        g3d_ckpt_free(ck);
    }
    /* metadata must be strings (the format says so); nothing is left behind on refusal */
    cJSON_AddNumberToObject(meta, "n", 1);
    const char *bad = test_tmp("refused.safetensors");
    remove(bad);
    CHECK_FAILS(g3d_safetensors_write(bad, t, 3, meta));
    CHECK(access(bad, F_OK) != 0);
    cJSON_Delete(meta);
}

int main(int argc, char **argv)
{
    if (test_extended(argc, argv)) {
        RUN(golden_weights);
        RUN(moge_golden_checkpoint);
        return test_summary();
    }
    RUN(fixture_weights);
    RUN(moge_checkpoint);
    RUN(every_dtype);
    RUN(hostile_headers);
    RUN(pytorch_zip);
    RUN(hostile_pickles);
    RUN(torch_save_fixtures);
    RUN(lightning_checkpoint);
    RUN(write_round_trip);
    return test_summary();
}
