/* test_worldscore.c - WorldScore camera paths against the benchmark's own camera generator
 * (tests/fixtures/make_worldscore_fixture.py): every camera of a four-move path, the keyframes,
 * the intrinsics and frame count, and refusals. */
#include "gen3d/worldscore.h"
#include "testutil.h"

#include <cjson/cJSON.h>

static cJSON *load_json(const char *path)
{
    unsigned char *buf;
    size_t n;
    if (g3d_read_file(path, (size_t)1 << 24, &buf, &n) != G3D_OK) return NULL;
    cJSON *j = cJSON_Parse((const char *)buf);
    free(buf);
    return j;
}

/* Largest absolute difference between two arrays of 4x4 matrices. */
static double max_diff(const cJSON *a, const cJSON *b, int *count_ok)
{
    double worst = 0;
    *count_ok = cJSON_GetArraySize(a) == cJSON_GetArraySize(b);
    for (int i = 0; i < cJSON_GetArraySize(a) && i < cJSON_GetArraySize(b); i++)
        for (int r = 0; r < 4; r++)
            for (int c = 0; c < 4; c++) {
                double x = cJSON_GetArrayItem(cJSON_GetArrayItem(cJSON_GetArrayItem(a, i), r), c)->valuedouble;
                double y = cJSON_GetArrayItem(cJSON_GetArrayItem(cJSON_GetArrayItem(b, i), r), c)->valuedouble;
                worst = fmax(worst, fabs(x - y));
            }
    return worst;
}

TEST(matches_worldscore_generator)
{
    cJSON *ref = load_json(G3D_SOURCE_DIR "/tests/fixtures/worldscore_camera_data.json");
    CHECK(ref != NULL);
    if (!ref) return;
    g3d_camera *cams;
    int n;
    CHECK_OK(g3d_worldscore_path("orbit_left,push_in,pan_right,move_left", 0.7, &cams, &n));
    CHECK(n == 1 + 49 * 4);
    g3d_intrinsics K = g3d_worldscore_intrinsics();
    CHECK(K.width == 512 && K.height == 512 && K.fx == 500 && K.fy == 500 && K.cx == 255.5 && K.cy == 255.5);
    int same_k = 1;
    for (int i = 0; i < n; i++) same_k &= !memcmp(&cams[i].K, &K, sizeof K);
    CHECK(same_k);
    CHECK(g3d_mat4_max_abs_diff(cams[0].c2w, g3d_mat4_identity()) == 0);
    const char *path = test_tmp("worldscore_camera_data.json");
    CHECK_OK(g3d_worldscore_write_camera_data(path, cams, n, 0.7));
    cJSON *got = load_json(path);
    CHECK(got != NULL);
    if (got) {
        int ok_all, ok_keys;
        /* the reference is float32 arithmetic rounded to 9 digits */
        double d_all = max_diff(cJSON_GetObjectItem(got, "cameras_interp"), cJSON_GetObjectItem(ref, "cameras_interp"), &ok_all);
        double d_keys = max_diff(cJSON_GetObjectItem(got, "cameras"), cJSON_GetObjectItem(ref, "cameras"), &ok_keys);
        printf("       197 cameras vs WorldScore's generator: max |diff| %.2e (keyframes %.2e)\n", d_all, d_keys);
        CHECK(ok_all && ok_keys);
        CHECK(d_all < 1e-6 && d_keys < 1e-6);
        CHECK(cJSON_GetObjectItem(got, "focal_length")->valuedouble == 500);
        CHECK(cJSON_GetObjectItem(got, "scale")->valuedouble == 0.7);
    }
    /* WorldScore interpolates world-to-camera translations, so the orbit's middle camera is
     * off the straight line between the keyframe centres */
    g3d_vec3 c0 = g3d_camera_center(&cams[0]), c49 = g3d_camera_center(&cams[49]), mid = g3d_camera_center(&cams[24]);
    double t = 24.0 / 49;
    g3d_vec3 lin = g3d_v3_add(c0, g3d_v3_scale(g3d_v3_sub(c49, c0), t));
    CHECK(g3d_v3_norm(g3d_v3_sub(mid, lin)) > 0.01);
    cJSON_Delete(got);
    cJSON_Delete(ref);
    free(cams);
}

TEST(refusals)
{
    g3d_camera *cams = NULL;
    int n = 0;
    CHECK_FAILS(g3d_worldscore_path("spiral", 1.0, &cams, &n));
    CHECK_FAILS(g3d_worldscore_path("push_in,", 1.0, &cams, &n));
    CHECK_FAILS(g3d_worldscore_path("rotate", 1.0, &cams, &n)); /* a gen3d preset, not a WorldScore move */
    CHECK_FAILS(g3d_worldscore_path("push_in", 0.0, &cams, &n));
    CHECK_FAILS(g3d_worldscore_path("push_in", NAN, &cams, &n));
    CHECK(cams == NULL && n == 0);
    g3d_camera one[3] = {{g3d_worldscore_intrinsics(), g3d_mat4_identity()}};
    CHECK_FAILS(g3d_worldscore_write_camera_data(test_tmp("never.json"), one, 3, 1.0));
    CHECK(!test_file_exists(test_tmp("never.json")));
}

int main(void)
{
    RUN(matches_worldscore_generator);
    RUN(refusals);
    return test_summary();
}
