/* test_viewer.c - viewer.html as gen3d writes it: the embedded .spz comes back byte for byte
 * through the page's binary-block encoding, the description's cameras follow the documented
 * OpenCV-to-three.js change, scene reduction, and every refusal leaves no file. Runs with a
 * small hand-made template, so it needs neither node nor a browser (test_viewer_browser.c
 * runs the real page). */
#include <cjson/cJSON.h>
#include <stdlib.h>
#include <unistd.h>

#include "gen3d/spz.h"
#include "gen3d/viewer.h"
#include "testutil.h"

static const char *TEMPLATE =
    "<!doctype html>\n<title>t</title>\n"
    "<script id=\"g3d-config\" type=\"application/json\">@@G3D_CONFIG@@</script>\n"
    "<script id=\"g3d-scene\" type=\"application/octet-stream\">@@G3D_SCENE@@</script>\n";

static const char *write_template(const char *name, const char *text)
{
    const char *path = test_tmp(name);
    CHECK_OK(g3d_write_file_atomic(path, text, strlen(text)));
    return path;
}

/* n Gaussians in front of the identity camera, all parameters random. */
static void random_scene(g3d_gaussians *g, int n, int deg, uint64_t seed)
{
    g3d_rng r;
    g3d_rng_seed(&r, seed, 1);
    g3d_gaussians_create(g, n, deg);
    g->n = n;
    const int K = G3D_SH_COEFFS(deg);
    for (int i = 0; i < n; i++) {
        g->means[3 * i + 0] = 2.0f * (g3d_rng_float(&r) - 0.5f);
        g->means[3 * i + 1] = 2.0f * (g3d_rng_float(&r) - 0.5f);
        g->means[3 * i + 2] = 2.0f + 2.0f * g3d_rng_float(&r);
        for (int a = 0; a < 3; a++) g->log_scales[3 * i + a] = -5.0f + 2.0f * g3d_rng_float(&r);
        for (int a = 0; a < 4; a++) g->rots[4 * i + a] = g3d_rng_normal(&r);
        g->opacity_logits[i] = 6.0f * (g3d_rng_float(&r) - 0.5f);
        for (int k = 0; k < 3 * K; k++) g->sh[(size_t)i * 3 * K + k] = 2.0f * g3d_rng_float(&r) - 1.0f;
    }
}

/* The text between the opening tag `open` and the next "</script>" of page p (n bytes). */
static const unsigned char *element(const unsigned char *p, size_t n, const char *open, size_t *len)
{
    const size_t m = strlen(open);
    for (size_t i = 0; i + m <= n; i++)
        if (!memcmp(p + i, open, m)) {
            const unsigned char *s = p + i + m;
            for (const unsigned char *e = s; e + 9 <= p + n; e++)
                if (!memcmp(e, "</script>", 9)) {
                    *len = (size_t)(e - s);
                    return s;
                }
        }
    return NULL;
}

/* Decodes a binary block; returns its length, or (size_t)-1 when the block breaks a rule of
 * the encoding (a raw NUL, CR or '=' at the end, or "</" / "<!" that would end the element). */
static size_t decode_block(const unsigned char *s, size_t n, unsigned char *out)
{
    size_t o = 0;
    for (size_t i = 0; i < n; i++) {
        if (s[i] == 0x00 || s[i] == 0x0d) return (size_t)-1;
        if (s[i] == '<' && i + 1 < n && (s[i + 1] == '/' || s[i + 1] == '!')) return (size_t)-1;
        if (s[i] == '=') {
            if (++i == n) return (size_t)-1;
            out[o++] = (unsigned char)(s[i] - 64);
        } else {
            out[o++] = s[i];
        }
    }
    return o;
}

static int read_page(const char *path, unsigned char **page, size_t *n)
{
    return g3d_read_file(path, (size_t)1 << 30, page, n) == G3D_OK;
}

static g3d_camera test_camera(void)
{
    g3d_camera c;
    c.K = g3d_intrinsics_make(300.0, 280.0, 170.3, 112.8, 320, 240);
    c.c2w = g3d_mat4_mul(g3d_mat4_rotation(g3d_v3(0, 1, 0), 0.35), g3d_mat4_rotation(g3d_v3(1, 0, 0), -0.2));
    c.c2w.m[0][3] = 0.3;
    c.c2w.m[1][3] = -0.2;
    c.c2w.m[2][3] = -0.5;
    return c;
}

TEST(scene_round_trip)
{
    g3d_gaussians g;
    random_scene(&g, 3000, 3, 5);
    g3d_camera cam = test_camera();
    g3d_viewer_params o;
    g3d_viewer_params_default(&o);
    o.template_path = write_template("viewer_template.html", TEMPLATE);
    const char *out = test_tmp("viewer_rt.html");
    CHECK_OK(g3d_viewer_write(out, &g, &cam, NULL, 0, &o));

    uint8_t *spz = NULL;
    size_t spz_n = 0;
    CHECK_OK(g3d_spz_encode(&g, "test", &spz, &spz_n));
    unsigned char *page = NULL;
    size_t page_n = 0, block_n = 0;
    CHECK(read_page(out, &page, &page_n));
    const unsigned char *block = page ? element(page, page_n, "type=\"application/octet-stream\">", &block_n) : NULL;
    CHECK(block != NULL);
    if (block && spz) {
        unsigned char *dec = malloc(block_n);
        size_t dn = decode_block(block, block_n, dec);
        CHECK(dn == spz_n && !memcmp(dec, spz, spz_n));
        int seen[256] = {0};
        for (size_t i = 0; i < spz_n; i++) seen[spz[i]] = 1;
        int distinct = 0;
        for (int b = 0; b < 256; b++) distinct += seen[b];
        CHECK(distinct == 256);  /* every byte value went through the encoding */
        printf("       .spz %zu bytes, block %zu bytes (+%.2f %%)\n", spz_n, block_n,
               100.0 * ((double)block_n / (double)spz_n - 1.0));
        CHECK(block_n < spz_n + spz_n / 50);
        free(dec);
    }
    free(page);
    free(spz);
    g3d_gaussians_free(&g);
}

/* The description: counts, and cameras whose page pose sees the world as the OpenCV camera. */
TEST(description_cameras)
{
    g3d_gaussians g;
    random_scene(&g, 500, 1, 7);
    g3d_camera cam = test_camera(), path[3];
    for (int i = 0; i < 3; i++) {
        path[i] = cam;
        path[i].c2w.m[0][3] += 0.1 * i;
    }
    g3d_viewer_path paths[1] = {{"generation", path, 3, 2.0}};
    g3d_viewer_params o;
    g3d_viewer_params_default(&o);
    o.template_path = write_template("viewer_template.html", TEMPLATE);
    o.scene_scale = 2.5;
    const char *out = test_tmp("viewer_desc.html");
    CHECK_OK(g3d_viewer_write(out, &g, &cam, paths, 1, &o));
    unsigned char *page = NULL;
    size_t page_n = 0, len = 0;
    CHECK(read_page(out, &page, &page_n));
    const unsigned char *text = page ? element(page, page_n, "type=\"application/json\">", &len) : NULL;
    CHECK(text != NULL);
    cJSON *root = text ? cJSON_ParseWithLength((const char *)text, len) : NULL;
    CHECK(root != NULL);
    if (root) {
        for (size_t i = 0; i < len; i++) CHECK(text[i] >= 0x20 && text[i] < 0x7f);
        cJSON *scene = cJSON_GetObjectItem(root, "scene"), *input = cJSON_GetObjectItem(root, "input");
        CHECK(cJSON_GetObjectItem(root, "version")->valuedouble == 1);
        CHECK(cJSON_GetObjectItem(scene, "gaussians")->valuedouble == 500);
        CHECK(cJSON_GetObjectItem(scene, "sh_degree")->valuedouble == 1);
        CHECK_NEAR(cJSON_GetObjectItem(scene, "scale")->valuedouble, 2.5, 0);
        CHECK_NEAR(cJSON_GetObjectItem(input, "fx")->valuedouble, 300.0, 1e-12);
        CHECK_NEAR(cJSON_GetObjectItem(input, "cy")->valuedouble, 112.8, 1e-12);
        CHECK(cJSON_GetObjectItem(input, "w")->valuedouble == 320);
        cJSON *p0 = cJSON_GetArrayItem(cJSON_GetObjectItem(root, "paths"), 0);
        CHECK(!strcmp(cJSON_GetObjectItem(p0, "name")->valuestring, "generation"));
        CHECK(cJSON_GetArraySize(cJSON_GetObjectItem(p0, "cameras")) == 3);
        CHECK(cJSON_GetObjectItem(p0, "fps")->valuedouble == 2.0);
        /* c2w_page = diag(1,-1,-1,1) c2w diag(1,-1,-1,1) */
        cJSON *m = cJSON_GetObjectItem(input, "c2w");
        CHECK(cJSON_GetArraySize(m) == 16);
        const double s[4] = {1, -1, -1, 1};
        g3d_mat4 page_c2w;
        for (int r = 0; r < 4; r++)
            for (int k = 0; k < 4; k++) {
                page_c2w.m[r][k] = cJSON_GetArrayItem(m, 4 * r + k)->valuedouble;
                CHECK_NEAR(page_c2w.m[r][k], s[r] * cam.c2w.m[r][k] * s[k], 1e-12);
            }
        /* and in use: a world point projects to the same pixel through the OpenCV camera and
         * through the page's camera (three.js: looks along -z, y up) in the flipped world */
        g3d_vec3 p = g3d_v3(0.4, -0.3, 3.0);
        double u, v, z;
        CHECK(g3d_camera_project(&cam, p, &u, &v, &z));
        g3d_vec3 q = g3d_mat4_point(g3d_mat4_inverse_rigid(page_c2w), g3d_v3(p.x, -p.y, -p.z));
        CHECK(q.z < 0);
        CHECK_NEAR(300.0 * q.x / -q.z + 170.3, u, 1e-9);
        CHECK_NEAR(280.0 * -q.y / -q.z + 112.8, v, 1e-9);
        cJSON_Delete(root);
    }
    free(page);
    g3d_gaussians_free(&g);
}

TEST(refusals_leave_no_file)
{
    g3d_gaussians g, empty;
    random_scene(&g, 2000, 3, 9);
    g3d_gaussians_create(&empty, 1, 0);
    g3d_camera cam = test_camera();
    g3d_viewer_params o;
    g3d_viewer_params_default(&o);
    o.template_path = write_template("viewer_template.html", TEMPLATE);
    o.label = "big.ply";
    const char *out = test_tmp("viewer_refused.html");
    unlink(out);

    CHECK_FAILS(g3d_viewer_write(out, &empty, &cam, NULL, 0, &o));
    CHECK(strstr(g3d_error_message(), "no Gaussians") != NULL);
    o.max_scene_bytes = 10000;
    g3d_error_clear();
    CHECK(g3d_viewer_write(out, &g, &cam, NULL, 0, &o) == G3D_ERR_UNSUPPORTED);
    printf("       %s\n", g3d_error_message());
    CHECK(strstr(g3d_error_message(), "big.ply") && strstr(g3d_error_message(), "--max-gaussians") &&
          strstr(g3d_error_message(), "--sh-degree"));
    o.max_scene_bytes = G3D_VIEWER_MAX_SCENE_BYTES;
    g3d_camera bad = cam;
    bad.K.fx = 0;
    CHECK_FAILS(g3d_viewer_write(out, &g, &bad, NULL, 0, &o));
    o.template_path = write_template("viewer_bad1.html", "<!doctype html>\n@@G3D_SCENE@@\n");
    CHECK(g3d_viewer_write(out, &g, &cam, NULL, 0, &o) == G3D_ERR_FORMAT);
    o.template_path = write_template("viewer_bad2.html", "<!doctype html>@@G3D_CONFIG@@@@G3D_SCENE@@@@G3D_SCENE@@");
    CHECK(g3d_viewer_write(out, &g, &cam, NULL, 0, &o) == G3D_ERR_FORMAT);
    o.template_path = test_tmp("no_such_template.html");
    CHECK_FAILS(g3d_viewer_write(out, &g, &cam, NULL, 0, &o));
    CHECK(!test_file_exists(out));

    /* a template named by the environment must exist */
    setenv("G3D_VIEWER_TEMPLATE", test_tmp("no_such_template.html"), 1);
    char *found = NULL;
    CHECK(g3d_viewer_find_template(&found) == G3D_ERR_IO && !found);
    unsetenv("G3D_VIEWER_TEMPLATE");
    g3d_gaussians_free(&g);
    g3d_gaussians_free(&empty);
}

/* gen3d generate's page: the generation views and the video path resampled to its frames. */
TEST(generated_page)
{
    g3d_gaussians g;
    random_scene(&g, 800, 0, 11);
    g3d_camera views[4];
    for (int i = 0; i < 4; i++) {
        views[i].K = g3d_intrinsics_from_fov(60, 64, 48);
        views[i].c2w = g3d_mat4_rotation(g3d_v3(0, 1, 0), 0.1 * i);
    }
    const char *dir = test_tmp("viewer_generated");
    g3d_mkdirs(dir);
    setenv("G3D_VIEWER_TEMPLATE", write_template("viewer_template.html", TEMPLATE), 1);
    int written = 0;
    CHECK_OK(g3d_viewer_write_generated(dir, &g, views, 4, "swing", 24, 30.0, &written));
    unsetenv("G3D_VIEWER_TEMPLATE");
    CHECK(written == 1);
    char *path = g3d_path_join(dir, "viewer.html");
    unsigned char *page = NULL;
    size_t n = 0, len = 0;
    CHECK(read_page(path, &page, &n));
    const unsigned char *text = page ? element(page, n, "type=\"application/json\">", &len) : NULL;
    cJSON *root = text ? cJSON_ParseWithLength((const char *)text, len) : NULL;
    CHECK(root != NULL);
    if (root) {
        cJSON *paths = cJSON_GetObjectItem(root, "paths");
        CHECK(cJSON_GetArraySize(paths) == 2);
        cJSON *gen = cJSON_GetArrayItem(paths, 0), *video = cJSON_GetArrayItem(paths, 1);
        CHECK(cJSON_GetArraySize(cJSON_GetObjectItem(gen, "cameras")) == 4);
        CHECK(!strcmp(cJSON_GetObjectItem(video, "name")->valuestring, "video"));
        CHECK(cJSON_GetArraySize(cJSON_GetObjectItem(video, "cameras")) == 24);
        CHECK(cJSON_GetObjectItem(video, "fps")->valuedouble == 30.0);
        cJSON_Delete(root);
    }
    free(page);
    free(path);
    g3d_gaussians_free(&g);
}

TEST(reduce)
{
    g3d_gaussians g, r;
    random_scene(&g, 1000, 3, 13);
    CHECK_OK(g3d_viewer_reduce(&g, 100, 1, &r));
    CHECK(r.n == 100 && r.sh_degree == 1);
    /* the kept ones are the 100 best by opacity x volume, in their original order */
    double worst_kept = INFINITY, best_dropped = -INFINITY;
    int64_t k = 0, last = -1;
    for (int64_t i = 0; i < g.n; i++) {
        const float *ls = g.log_scales + 3 * i;
        double score = exp(ls[0] + ls[1] + ls[2]) / (1 + exp(-g.opacity_logits[i]));
        int kept = k < r.n && !memcmp(r.means + 3 * k, g.means + 3 * i, 3 * sizeof(float));
        if (kept) {
            CHECK(i > last);
            last = i;
            for (int c = 0; c < 4 * 3; c++) CHECK(r.sh[(size_t)k * 12 + c] == g.sh[(size_t)i * 48 + c]);
            CHECK(r.opacity_logits[k] == g.opacity_logits[i] && r.rots[4 * k + 3] == g.rots[4 * i + 3]);
            worst_kept = fmin(worst_kept, score);
            k++;
        } else {
            best_dropped = fmax(best_dropped, score);
        }
    }
    CHECK(k == 100);
    CHECK(worst_kept >= best_dropped);
    g3d_gaussians_free(&r);
    CHECK_OK(g3d_viewer_reduce(&g, 0, -1, &r));
    CHECK(r.n == g.n && r.sh_degree == 3 && !memcmp(r.sh, g.sh, (size_t)g.n * 48 * sizeof(float)));
    g3d_gaussians_free(&r);
    g3d_gaussians_free(&g);
}

int main(void)
{
    RUN(scene_round_trip);
    RUN(description_cameras);
    RUN(refusals_leave_no_file);
    RUN(generated_page);
    RUN(reduce);
    return test_summary();
}
