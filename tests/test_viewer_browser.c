/* test_viewer_browser.c - viewer.html in a real browser against gen3d's own renderer.
 *
 * A scene built to expose every convention a viewer can get wrong -- anisotropic, randomly
 * rotated Gaussians of all opacities, strong view-dependent colour in all three SH bands, an
 * input camera that is rotated, off-centre and has non-square pixels -- goes through
 * `gen3d view` (scene.ply -> .spz inside viewer.html) and `gen3d render` (scene.ply). Headless
 * Chromium with software WebGL (SwiftShader) opens the page from file:// and takes a
 * screenshot at the input camera (tests/browser/shoot.mjs); it must match the render to
 * >= 25 dB PSNR, with no console errors. So that the threshold means something, the same
 * screenshot must fall below it against renders of the scene with one convention broken
 * (axes, SH signs, quaternion order, log-scales), and match a render of the page's own .spz
 * far more closely (the rest is .spz quantisation). Finally a page whose embedded scene is
 * damaged must show a readable error, not a blank page.
 *
 * Skipped (exit 77, one line saying why) when no Chromium is installed, or when the viewer
 * template was not built (no node/npm at build time).
 */
#include <cjson/cJSON.h>
#include <stdarg.h>
#include <stdlib.h>
#include <unistd.h>

#include "gen3d/cameras_json.h"
#include "gen3d/cloud.h"
#include "gen3d/imageio.h"
#include "gen3d/loss.h"
#include "gen3d/ply.h"
#include "gen3d/raster.h"
#include "gen3d/spz.h"
#include "gen3d/viewer.h"
#include "testutil.h"

#define W 320
#define H 240
#define N 4000

/* PSNR of a against b over all pixels, NAN when they cannot be compared. */
static double image_psnr(const g3d_image *a, const g3d_image *b, const g3d_image *mask)
{
    double psnr = NAN;
    if (g3d_psnr(a, b, mask, &psnr) != G3D_OK) return NAN;
    return psnr;
}

static const char *g_browser, *g_node, *g_gen3d;

/* `name` in one of the PATH folders, or NULL. */
static const char *in_path(const char *name)
{
    static char found[4096];
    const char *path = getenv("PATH");
    while (path && *path) {
        const char *end = strchr(path, ':');
        size_t len = end ? (size_t)(end - path) : strlen(path);
        snprintf(found, sizeof found, "%.*s/%s", (int)len, path, name);
        if (access(found, X_OK) == 0) return found;
        path = end ? end + 1 : NULL;
    }
    return NULL;
}

static g3d_camera input_camera(void)
{
    g3d_camera c;
    c.K = g3d_intrinsics_make(300.0, 280.0, 170.3, 112.8, W, H);
    c.c2w = g3d_mat4_mul(g3d_mat4_rotation(g3d_v3(0, 1, 0), 0.35), g3d_mat4_rotation(g3d_v3(1, 0, 0), -0.2));
    c.c2w.m[0][3] = 0.3;
    c.c2w.m[1][3] = -0.2;
    c.c2w.m[2][3] = -0.5;
    return c;
}

/* Gaussians spread over the input camera's view, 2 to 5 m away. */
static void make_scene(g3d_gaussians *g, const g3d_camera *cam)
{
    g3d_rng r;
    g3d_rng_seed(&r, 2024, 16);
    g3d_gaussians_create(g, N, 3);
    g->n = N;
    for (int i = 0; i < N; i++) {
        double u = -20 + (W + 40) * g3d_rng_float(&r), v = -20 + (H + 40) * g3d_rng_float(&r);
        g3d_vec3 p = g3d_camera_unproject(cam, u, v, 2.0 + 3.0 * g3d_rng_float(&r));
        g->means[3 * i] = (float)p.x;
        g->means[3 * i + 1] = (float)p.y;
        g->means[3 * i + 2] = (float)p.z;
        /* needles and discs: one or two long axes, the others thin */
        const int shape = (int)g3d_rng_below(&r, 2);
        for (int a = 0; a < 3; a++) {
            const int is_long = shape == 0 ? a == 0 : a != 2;
            g->log_scales[3 * i + a] = logf(is_long ? 0.03f + 0.07f * g3d_rng_float(&r) : 0.003f + 0.007f * g3d_rng_float(&r));
        }
        for (int a = 0; a < 4; a++) g->rots[4 * i + a] = g3d_rng_normal(&r);
        g->opacity_logits[i] = -1.0f + 5.0f * g3d_rng_float(&r);
        for (int c = 0; c < 3; c++) g->sh[(size_t)i * 48 + c] = (0.25f + 0.5f * g3d_rng_float(&r) - 0.5f) / G3D_SH_C0;
        for (int k = 1; k < 16; k++) {
            const float amp = k < 4 ? 0.3f : k < 9 ? 0.2f : 0.12f;
            for (int c = 0; c < 3; c++) g->sh[((size_t)i * 16 + k) * 3 + c] = amp * (2 * g3d_rng_float(&r) - 1);
        }
    }
}

static int run(const char *fmt, ...)
{
    char cmd[8192];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(cmd, sizeof cmd, fmt, ap);
    va_end(ap);
    int st = system(cmd);
    if (st != 0) printf("       command failed (%d): %s\n", st, cmd);
    return st;
}

/* Opens `page` in the browser and screenshots it into `png`, or runs `steps` (shoot.mjs);
 * returns the driver's JSON report (caller deletes) or NULL. */
static cJSON *shoot(const char *page, const char *png, const char *steps)
{
    const char *report = test_tmp("browser/report.json");
    remove(png);
    if (run("'%s' '%s/tests/browser/shoot.mjs' --browser '%s' --page '%s' --out '%s' --width %d --height %d%s%s%s > '%s'",
            g_node, G3D_SOURCE_DIR, g_browser, page, png, W, H, steps ? " --steps '" : "", steps ? steps : "",
            steps ? "'" : "", report) != 0)
        return NULL;
    unsigned char *text = NULL;
    size_t n = 0;
    if (g3d_read_file(report, 1 << 20, &text, &n) != G3D_OK) return NULL;
    cJSON *j = cJSON_ParseWithLength((const char *)text, n);
    free(text);
    return j;
}

/* The console entries that are errors (warnings, such as SwiftShader's "GPU stall due to
 * ReadPixels", are not). */
static int console_errors(const cJSON *report)
{
    int n = 0;
    const cJSON *e;
    cJSON_ArrayForEach(e, cJSON_GetObjectItem(report, "console"))
    {
        const char *level = cJSON_GetObjectItem(e, "level")->valuestring;
        if (!strcmp(level, "error") || !strcmp(level, "exception") || !strcmp(level, "assert")) {
            printf("       console %s: %s\n", level, cJSON_GetObjectItem(e, "text")->valuestring);
            n++;
        }
    }
    return n;
}

/* PSNR of the screenshot against our render of g at cam, turned upside down if asked. */
static double psnr_against(const g3d_image *shot, const g3d_gaussians *g, const g3d_camera *cam, int upside_down)
{
    g3d_raster_ws *ws = NULL;
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    g3d_image img;
    g3d_image_create(&img, W, H, 3);
    double psnr = NAN;
    if (g3d_raster_ws_create(&ws) == G3D_OK && g3d_raster_fwd(ws, g, cam, &s, img.data, NULL, NULL, NULL) == G3D_OK) {
        for (size_t i = 0; i < (size_t)W * H * 3; i++)  /* as a PNG would hold it */
            img.data[i] = roundf(fminf(fmaxf(img.data[i], 0.0f), 1.0f) * 255.0f) / 255.0f;
        for (size_t i = 0, j = (size_t)W * H - 1; upside_down && i < j; i++, j--)
            for (int c = 0; c < 3; c++) {
                float t = img.data[3 * i + c];
                img.data[3 * i + c] = img.data[3 * j + c];
                img.data[3 * j + c] = t;
            }
        psnr = image_psnr(shot, &img, NULL);
    }
    g3d_raster_ws_free(ws);
    g3d_image_free(&img);
    return psnr;
}

static g3d_gaussians g_scene;
static g3d_camera g_cam;
static g3d_image g_shot;

TEST(page_matches_render)
{
    const char *ply = test_tmp("browser/scene.ply"), *cams = test_tmp("browser/cameras.json");
    const char *page = test_tmp("browser/viewer.html"), *shot = test_tmp("browser/shot.png");
    const char *render = test_tmp("browser/render");
    CHECK_OK(g3d_ply_write_gaussians(ply, &g_scene));
    g3d_camera_list l;
    CHECK_OK(g3d_camera_list_create(&l, 2));
    l.cams[0] = l.cams[1] = g_cam;
    l.cams[1].c2w.m[0][3] += 0.2;
    CHECK_OK(g3d_cameras_json_write(cams, &l));
    g3d_camera_list_free(&l);

    CHECK(run("'%s' view '%s' --cameras '%s' -q -o '%s' > /dev/null", g_gen3d, ply, cams, page) == 0);
    /* the page costs at most 1 MB more than the scene's .spz */
    uint8_t *spz = NULL;
    size_t spz_n = 0;
    struct stat st;
    CHECK_OK(g3d_spz_encode(&g_scene, "scene", &spz, &spz_n));
    CHECK(stat(page, &st) == 0);
    printf("       viewer.html %lld bytes for a %zu-byte .spz (+%lld)\n", (long long)st.st_size, spz_n,
           (long long)st.st_size - (long long)spz_n);
    CHECK(st.st_size - (long long)spz_n <= 1000000);
    free(spz);
    g3d_remove_tree(render);
    CHECK(run("'%s' render --scene '%s' --trajectory '%s' --no-video -q -o '%s' > /dev/null", g_gen3d, ply, cams, render) == 0);
    cJSON *report = shoot(page, shot, NULL);
    CHECK(report != NULL);
    if (!report) return;
    const cJSON *state = cJSON_GetObjectItem(report, "state");
    printf("       browser WebGL: %s\n", cJSON_GetStringValue(cJSON_GetObjectItem(report, "webgl")));
    CHECK(cJSON_IsTrue(cJSON_GetObjectItem(state, "ready")));
    CHECK(cJSON_IsNull(cJSON_GetObjectItem(state, "error")));
    CHECK(cJSON_GetObjectItem(state, "gaussians")->valuedouble == N);
    CHECK(console_errors(report) == 0);
    cJSON_Delete(report);

    g3d_image ref;
    CHECK_OK(g3d_image_load(shot, 3, &g_shot));
    char *frame = g3d_path_join(render, "frames/00000.png");
    CHECK_OK(g3d_image_load(frame, 3, &ref));
    free(frame);
    CHECK(g_shot.w == W && g_shot.h == H && ref.w == W && ref.h == H);
    if (g_shot.w == W && ref.w == W) {
        double psnr = image_psnr(&g_shot, &ref, NULL);
        printf("       browser screenshot vs gen3d render at the input camera: PSNR %.2f dB\n", psnr);
        CHECK(psnr >= 25.0);
    }
    g3d_image_free(&ref);
}

/* The same screenshot against renders with one convention broken: each must be far off. */
TEST(broken_conventions_are_caught)
{
    if (g_shot.w != W) {
        CHECK(!"no screenshot");
        return;
    }
    g3d_gaussians b;
    const double floor = 25.0;  /* the threshold page_matches_render applies */
    double psnr;

    /* axes: the picture upside down, as a y-down scene shown in a y-up viewer */
    psnr = psnr_against(&g_shot, &g_scene, &g_cam, 1);
    printf("       upside down: %.2f dB\n", psnr);
    CHECK(psnr < floor);

    /* SH: coefficients odd in y or z not negated with the axes */
    g3d_gaussians_clone(&b, &g_scene);
    static const int odd_yz[] = {1, 2, 4, 7, 9, 11, 12, 14};
    for (int i = 0; i < N; i++)
        for (int k = 0; k < 8; k++)
            for (int c = 0; c < 3; c++) b.sh[((size_t)i * 16 + odd_yz[k]) * 3 + c] *= -1.0f;
    psnr = psnr_against(&g_shot, &b, &g_cam, 0);
    printf("       SH signs not flipped: %.2f dB\n", psnr);
    CHECK(psnr < floor);
    g3d_gaussians_free(&b);

    /* rotation: quaternions read as (x, y, z, w) */
    g3d_gaussians_clone(&b, &g_scene);
    for (int i = 0; i < N; i++) {
        float *q = b.rots + 4 * i, w = q[0];
        q[0] = q[1], q[1] = q[2], q[2] = q[3], q[3] = w;
    }
    psnr = psnr_against(&g_shot, &b, &g_cam, 0);
    printf("       quaternion order xyzw: %.2f dB\n", psnr);
    CHECK(psnr < floor);
    g3d_gaussians_free(&b);

    /* scale: stored values taken as log-variances instead of log standard deviations */
    g3d_gaussians_clone(&b, &g_scene);
    for (int i = 0; i < 3 * N; i++) b.log_scales[i] *= 0.5f;
    psnr = psnr_against(&g_shot, &b, &g_cam, 0);
    printf("       scales as log-variance: %.2f dB\n", psnr);
    CHECK(psnr < floor);
    g3d_gaussians_free(&b);

    /* and the library's own render of the original matches as the CLI's did */
    psnr = psnr_against(&g_shot, &g_scene, &g_cam, 0);
    printf("       original, for comparison: %.2f dB\n", psnr);
    CHECK(psnr >= floor);
}

/* What is left between the page and the render is the .spz quantisation (4 to 5 bits per SH
 * coefficient above the first band): against a render of the .spz the page holds, the
 * match is much closer. */
TEST(page_draws_its_spz_as_gen3d_does)
{
    if (g_shot.w != W) {
        CHECK(!"no screenshot");
        return;
    }
    g3d_gaussians d;
    const char *spz = test_tmp("browser/scene.spz");
    CHECK_OK(g3d_spz_save(spz, &g_scene));
    CHECK_OK(g3d_spz_load(spz, &d));
    double psnr = psnr_against(&g_shot, &d, &g_cam, 0);
    printf("       browser screenshot vs gen3d render of the page's .spz: %.2f dB\n", psnr);
    CHECK(psnr >= 35.0);
    g3d_gaussians_free(&d);
}

static double psnr_files(const char *a, const char *b)
{
    g3d_image x = {0}, y = {0};
    double psnr = NAN;
    if (g3d_image_load(a, 3, &x) == G3D_OK && g3d_image_load(b, 3, &y) == G3D_OK && x.w == y.w && x.h == y.h)
        psnr = image_psnr(&x, &y, NULL);
    g3d_image_free(&x);
    g3d_image_free(&y);
    return psnr;
}

/* Key 1 plays the generation path and stops at its last camera; W flies; R comes back to
 * the input view; a drag orbits and the wheel zooms. Each stop is checked against gen3d
 * render of the camera it should be at, or shown to have left it. */
TEST(paths_flight_and_reset)
{
    const char *page = test_tmp("browser/viewer.html");
    char steps[4096];
    snprintf(steps, sizeof steps,
             "press:Digit1;idle;shot:%s;hold:KeyW:700;shot:%s;press:KeyR;shot:%s;"
             "drag:100,120,200,140;shot:%s;press:KeyR;wheel:160,120,-500;shot:%s",
             test_tmp("browser/path_end.png"), test_tmp("browser/flown.png"), test_tmp("browser/reset.png"),
             test_tmp("browser/orbited.png"), test_tmp("browser/zoomed.png"));
    cJSON *report = shoot(page, test_tmp("browser/unused.png"), steps);
    CHECK(report && cJSON_GetObjectItem(report, "screenshots")->valuedouble == 5);
    CHECK(report && console_errors(report) == 0);
    cJSON_Delete(report);
    double end = psnr_files(test_tmp("browser/path_end.png"), test_tmp("browser/render/frames/00001.png"));
    double flown = psnr_files(test_tmp("browser/flown.png"), test_tmp("browser/render/frames/00001.png"));
    double reset = psnr_files(test_tmp("browser/reset.png"), test_tmp("browser/render/frames/00000.png"));
    printf("       end of the generation path vs its last camera: %.2f dB; after flying: %.2f dB; "
           "after reset vs the input camera: %.2f dB\n", end, flown, reset);
    CHECK(end >= 25.0);
    CHECK(flown < 20.0);
    CHECK(reset >= 25.0);
    double orbited = psnr_files(test_tmp("browser/orbited.png"), test_tmp("browser/render/frames/00000.png"));
    double zoomed = psnr_files(test_tmp("browser/zoomed.png"), test_tmp("browser/render/frames/00000.png"));
    printf("       after a drag: %.2f dB; after the wheel: %.2f dB\n", orbited, zoomed);
    CHECK(orbited < 20.0);
    CHECK(zoomed < 20.0);
}

/* A page whose scene bytes are damaged shows a sentence, not a blank page. */
TEST(damaged_scene_shows_an_error)
{
    const char *page = test_tmp("browser/viewer.html"), *bad = test_tmp("browser/damaged.html");
    const char *shot = test_tmp("browser/damaged.png");
    unsigned char *html = NULL;
    size_t n = 0;
    CHECK_OK(g3d_read_file(page, (size_t)1 << 30, &html, &n));
    if (!html) return;
    const char *mark = "id=\"g3d-scene\" type=\"application/octet-stream\">";
    unsigned char *start = NULL;
    for (size_t i = 0; i + strlen(mark) < n && !start; i++)
        if (!memcmp(html + i, mark, strlen(mark))) start = html + i + strlen(mark);
    CHECK(start != NULL);
    if (start) {
        memset(start + 5000, 'A', 300);  /* inside the deflate stream */
        CHECK_OK(g3d_write_file_atomic(bad, html, n));
        cJSON *report = shoot(bad, shot, NULL);
        CHECK(report != NULL);
        const char *error = report ? cJSON_GetStringValue(cJSON_GetObjectItem(cJSON_GetObjectItem(report, "state"), "error")) : NULL;
        printf("       the page says: %s\n", error ? error : "(nothing)");
        CHECK(error && strstr(error, "damaged"));
        g3d_image img;
        if (g3d_image_load(shot, 3, &img) == G3D_OK) {
            double lo = 1, hi = 0;  /* the error box: dark red with light text */
            for (size_t i = 0; i < (size_t)img.w * img.h * 3; i++) lo = fmin(lo, img.data[i]), hi = fmax(hi, img.data[i]);
            CHECK(hi - lo > 0.5);
            g3d_image_free(&img);
        } else {
            CHECK(!"no screenshot of the damaged page");
        }
        cJSON_Delete(report);
    }
    free(html);
}

int main(void)
{
    g_gen3d = getenv("GEN3D");
    g_browser = getenv("G3D_CHROMIUM");
    if (!g_browser || !*g_browser) g_browser = in_path("chromium");
    if (!g_browser) {
        printf("skipped: no Chromium installed (Debian's chromium package; or set G3D_CHROMIUM)\n");
        return 77;
    }
    g_browser = strdup(g_browser);
    char *tmpl = NULL;
    if (g3d_viewer_find_template(&tmpl) != G3D_OK) {
        printf("skipped: the viewer template was not built (node and npm were missing at build time)\n");
        return 77;
    }
    free(tmpl);
    g_node = getenv("G3D_NODE");
    if (!g_node || !*g_node) g_node = in_path("node");
    if (!g_node || !g_gen3d) {
        printf("FAIL: the test needs node and $GEN3D\n");
        return 1;
    }
    g_node = strdup(g_node);
    g3d_mkdirs(test_tmp("browser"));
    g_cam = input_camera();
    make_scene(&g_scene, &g_cam);
    RUN(page_matches_render);
    RUN(broken_conventions_are_caught);
    RUN(page_draws_its_spz_as_gen3d_does);
    RUN(paths_flight_and_reset);
    RUN(damaged_scene_shows_an_error);
    g3d_gaussians_free(&g_scene);
    g3d_image_free(&g_shot);
    return test_summary();
}
