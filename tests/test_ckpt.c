/* test_ckpt.c - checkpoint loading: the published golden files, conversions, hostile files. */
#include <cjson/cJSON.h>

#include "gen3d/ckpt.h"
#include "testutil.h"

static double sum_tensor(const g3d_ckpt *ck, const char *name)
{
    float *v = NULL;
    if (g3d_ckpt_read_alloc(ck, name, 0, NULL, &v) != G3D_OK) return NAN;
    const g3d_tensor_info *ti = g3d_ckpt_find(ck, name);
    double s = 0;
    for (int64_t i = 0; i < ti->numel; i++) s += v[i];
    free(v);
    return s;
}

TEST(dav2_weights)
{
    g3d_ckpt *ck = NULL;
    CHECK_OK(g3d_ckpt_open(test_shared("golden/depth_anything_v2_vits/weights.safetensors"), &ck));
    if (!ck) return;
    CHECK(g3d_ckpt_count(ck) == 239);
    const g3d_tensor_info *q = g3d_ckpt_find(ck, "pretrained.blocks.0.attn.qkv.weight");
    CHECK(q && q->dtype == G3D_DT_F16 && q->ndim == 2 && q->shape[0] == 1152 && q->shape[1] == 384);
    /* Sums computed with numpy from the same bytes (float16 widened to float64). */
    CHECK_NEAR(sum_tensor(ck, "pretrained.blocks.0.attn.qkv.weight"), 12.077771782875061, 1e-6);
    CHECK_NEAR(sum_tensor(ck, "pretrained.cls_token"), -1.6699740886688232, 1e-6);
    float b;
    int64_t one = 1;
    CHECK_OK(g3d_ckpt_read(ck, "depth_head.scratch.output_conv2.2.bias", 1, &one, &b));
    CHECK(b == 0.5f);
    int64_t wrong[2] = {384, 1152};
    float *tmp = NULL;
    CHECK_FAILS(g3d_ckpt_read_alloc(ck, "pretrained.blocks.0.attn.qkv.weight", 2, wrong, &tmp));
    CHECK(strstr(g3d_error_message(), "[1152, 384]") && strstr(g3d_error_message(), "[384, 1152]"));
    CHECK_FAILS(g3d_ckpt_read_alloc(ck, "pretrained.no_such", 0, NULL, &tmp));
    CHECK(tmp == NULL);
    const cJSON *m = g3d_ckpt_meta(ck);
    const cJSON *model = cJSON_GetObjectItemCaseSensitive(m, "model");
    CHECK(cJSON_IsString(model) && strcmp(model->valuestring, "depth_anything_v2_vits") == 0);
    g3d_ckpt_free(ck);
}

TEST(dav2_activations)
{
    g3d_ckpt *ck = NULL;
    CHECK_OK(g3d_ckpt_open(test_shared("golden/depth_anything_v2_vits/activations.safetensors"), &ck));
    if (!ck) return;
    const g3d_tensor_info *im = g3d_ckpt_find(ck, "input.image_rgb_u8");
    CHECK(im && im->dtype == G3D_DT_U8 && im->ndim == 3 && im->shape[0] == 425 && im->shape[2] == 3);
    CHECK_NEAR(sum_tensor(ck, "input.image_rgb_u8"), 76077629.0, 0.5);
    CHECK_NEAR(sum_tensor(ck, "out.block0"), 1874.1370933972066, 1e-2);
    g3d_ckpt_free(ck);
}

TEST(half_conversion)
{
    /* 1, -2, smallest subnormal, largest subnormal, 65504, +inf, -0, NaN */
    const uint16_t h[8] = {0x3c00, 0xc000, 0x0001, 0x03ff, 0x7bff, 0x7c00, 0x8000, 0x7e00};
    float f[8];
    g3d_dtype_to_f32(G3D_DT_F16, h, f, 8);
    CHECK(f[0] == 1.0f && f[1] == -2.0f);
    CHECK(f[2] == ldexpf(1.0f, -24));
    CHECK(f[3] == ldexpf(1023.0f, -24));
    CHECK(f[4] == 65504.0f);
    CHECK(isinf(f[5]) && f[5] > 0);
    CHECK(f[6] == 0.0f && signbit(f[6]));
    CHECK(isnan(f[7]));
    const uint16_t bf[2] = {0x3f80, 0xc049}; /* 1.0, -3.140625 */
    g3d_dtype_to_f32(G3D_DT_BF16, bf, f, 2);
    CHECK(f[0] == 1.0f && f[1] == -3.140625f);
    const int64_t i64[2] = {-7, 1 << 20};
    g3d_dtype_to_f32(G3D_DT_I64, i64, f, 2);
    CHECK(f[0] == -7.0f && f[1] == 1048576.0f);
    const unsigned char u8[3] = {0, 255, 2};
    g3d_dtype_to_f32(G3D_DT_BOOL, u8, f, 3);
    CHECK(f[0] == 0.0f && f[1] == 1.0f && f[2] == 1.0f);
    g3d_dtype_to_f32(G3D_DT_I8, u8, f, 3);
    CHECK(f[1] == -1.0f);
}

/* Writes a safetensors file with the given header and `ndata` zero data bytes. */
static const char *write_st(const char *name, const char *hdr, uint64_t claimed_len, size_t ndata)
{
    const char *p = test_tmp(name);
    FILE *f = fopen(p, "wb");
    unsigned char len[8];
    for (int i = 0; i < 8; i++) len[i] = (unsigned char)(claimed_len >> (8 * i));
    fwrite(len, 1, 8, f);
    fwrite(hdr, 1, strlen(hdr), f);
    for (size_t i = 0; i < ndata; i++) fputc(0, f);
    fclose(f);
    return p;
}

static void expect_st_fail(const char *hdr, uint64_t claimed_len, size_t ndata, const char *needle)
{
    g3d_ckpt *ck = (g3d_ckpt *)1;
    CHECK_FAILS(g3d_ckpt_open(write_st("bad.safetensors", hdr, claimed_len, ndata), &ck));
    CHECK(ck == NULL);
    CHECK_MSG(strstr(g3d_error_message(), needle) != NULL, "'%s' lacks '%s'", g3d_error_message(), needle);
}

TEST(safetensors_roundtrip)
{
    const char *h = "{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]},"
                    "\"b\":{\"dtype\":\"I16\",\"shape\":[],\"data_offsets\":[8,10]}}";
    const char *p = test_tmp("ok.safetensors");
    FILE *f = fopen(p, "wb");
    uint64_t n = strlen(h);
    unsigned char len[8];
    for (int i = 0; i < 8; i++) len[i] = (unsigned char)(n >> (8 * i));
    fwrite(len, 1, 8, f);
    fwrite(h, 1, n, f);
    const float a[2] = {1.5f, -4.0f};
    const int16_t b = -300;
    fwrite(a, 4, 2, f);
    fwrite(&b, 2, 1, f);
    fclose(f);
    g3d_ckpt *ck = NULL;
    CHECK_OK(g3d_ckpt_open(p, &ck));
    if (!ck) return;
    float out[2];
    int64_t two = 2;
    CHECK_OK(g3d_ckpt_read(ck, "a", 1, &two, out));
    CHECK(out[0] == 1.5f && out[1] == -4.0f);
    CHECK_OK(g3d_ckpt_read(ck, "b", 0, NULL, out));
    CHECK(out[0] == -300.0f);
    CHECK(g3d_ckpt_find(ck, "b")->ndim == 0 && g3d_ckpt_find(ck, "b")->numel == 1);
    CHECK(g3d_ckpt_meta(ck) == NULL);
    g3d_ckpt_free(ck);
}

TEST(safetensors_hostile)
{
    const char *ok1 = "{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]}}";
    expect_st_fail(ok1, 1u << 20, 8, "past the end");
    expect_st_fail(ok1, UINT64_MAX, 8, "past the end");
    expect_st_fail("{not json at all}", 17, 0, "not a JSON object");
    expect_st_fail("{\"a\":1} trailing", 16, 0, "not a JSON object");
    const char *h;
    h = "{\"a\":{\"dtype\":\"F32\",\"shape\":[3],\"data_offsets\":[0,8]}}";
    expect_st_fail(h, strlen(h), 8, "does not match");
    h = "{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,16]}}";
    expect_st_fail(h, strlen(h), 8, "outside the data section");
    h = "{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[8,0]}}";
    expect_st_fail(h, strlen(h), 8, "outside the data section");
    h = "{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]},"
        "\"b\":{\"dtype\":\"I32\",\"shape\":[1],\"data_offsets\":[4,8]}}";
    expect_st_fail(h, strlen(h), 8, "overlap");
    h = "{\"a\":{\"dtype\":\"Q4\",\"shape\":[2],\"data_offsets\":[0,8]}}";
    expect_st_fail(h, strlen(h), 8, "unsupported dtype 'Q4'");
    h = "{\"a\":{\"dtype\":\"F32\",\"shape\":[-2],\"data_offsets\":[0,8]}}";
    expect_st_fail(h, strlen(h), 8, "negative");
    h = "{\"a\":{\"dtype\":\"F32\",\"shape\":[4294967296,4294967296],\"data_offsets\":[0,8]}}";
    expect_st_fail(h, strlen(h), 8, "does not match");
    h = "{\"a\":{\"dtype\":\"F32\",\"shape\":[2]}}";
    expect_st_fail(h, strlen(h), 8, "data_offsets");
    h = "{\"__metadata__\":[1]}";
    expect_st_fail(h, strlen(h), 0, "__metadata__");
    g3d_ckpt *ck = NULL;
    CHECK_FAILS(g3d_ckpt_open(test_tmp("missing.safetensors"), &ck));
    CHECK_FAILS(g3d_ckpt_open(write_st("junk.bin", "xxxxxxxx", 0x7878787878787878ull, 0), &ck));
    CHECK(strstr(g3d_error_message(), "neither"));
}

int main(void)
{
    RUN(dav2_weights);
    RUN(dav2_activations);
    RUN(half_conversion);
    RUN(safetensors_roundtrip);
    RUN(safetensors_hostile);
    return test_summary();
}
