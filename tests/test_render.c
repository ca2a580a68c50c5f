/* test_render.c - rendering along camera paths: frames equal to the rasterizer's, depth
 * normalisation, output folders (frames, depth, cameras.json, video or PNG fallback), pose
 * resampling and fly-through paths. */
#include <stdlib.h>
#include <string.h>

#include "gen3d/cameras_json.h"
#include "gen3d/depthio.h"
#include "gen3d/imageio.h"
#include "gen3d/raster.h"
#include "gen3d/render.h"
#include "testutil.h"

/* n Gaussians in a slab 2..4 m in front of the identity camera, SH degree 1. */
static void small_scene(g3d_gaussians *g, int n)
{
    g3d_rng r;
    g3d_rng_seed(&r, 5, 1);
    g3d_gaussians_create(g, n, 1);
    g->n = n;
    for (int i = 0; i < n; i++) {
        g->means[i * 3 + 0] = 2.0f * (g3d_rng_float(&r) - 0.5f);
        g->means[i * 3 + 1] = 1.5f * (g3d_rng_float(&r) - 0.5f);
        g->means[i * 3 + 2] = 2.0f + 2.0f * g3d_rng_float(&r);
        for (int a = 0; a < 3; a++) g->log_scales[i * 3 + a] = logf(0.15f + 0.1f * g3d_rng_float(&r));
        g->rots[i * 4] = 1.0f;
        g->opacity_logits[i] = 3.0f;
        for (int k = 0; k < 12; k++) g->sh[i * 12 + k] = (k < 3 ? 1.2f : 0.3f) * (2 * g3d_rng_float(&r) - 1);
    }
}

static void two_cameras(g3d_camera c[2])
{
    c[0].K = g3d_intrinsics_from_fov(60, 40, 30);
    c[0].c2w = g3d_mat4_identity();
    c[1].K = g3d_intrinsics_make(30, 28, 12.0, 20.5, 27, 35);  /* other size, off-centre */
    c[1].c2w = g3d_pose_yaw_pitch(10, 5, g3d_v3(0.2, 0, 0.1));
}

typedef struct capture {
    int calls;
    double max_rgb_diff, max_depth_diff;
    int depth_zero_ok;
    const g3d_gaussians *g;
    float bg[3];
} capture;

static g3d_status compare_frame(void *user, int index, const g3d_camera *cam, const g3d_image *rgb,
                                const g3d_image *depth)
{
    capture *c = user;
    CHECK(index == c->calls);
    c->calls++;
    const int W = cam->K.width, H = cam->K.height;
    CHECK(rgb->w == W && rgb->h == H && rgb->c == 3);
    g3d_raster_ws *ws;
    g3d_raster_ws_create(&ws);
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    memcpy(s.bg, c->bg, sizeof s.bg);
    float *ref = malloc(sizeof(float) * W * H * 3), *a = malloc(sizeof(float) * W * H),
          *z = malloc(sizeof(float) * W * H);
    CHECK_OK(g3d_raster_fwd(ws, c->g, cam, &s, ref, a, z, NULL));
    for (int k = 0; k < W * H * 3; k++) {
        double d = fabs(ref[k] - rgb->data[k]);
        if (d > c->max_rgb_diff) c->max_rgb_diff = d;
    }
    CHECK(depth != NULL);
    if (depth) {
        for (int k = 0; k < W * H; k++) {
            if (a[k] >= 0.5f) {
                double d = fabs(z[k] / a[k] - depth->data[k]);
                if (d > c->max_depth_diff) c->max_depth_diff = d;
            } else if (depth->data[k] != 0.0f) {
                c->depth_zero_ok = 0;
            }
        }
    }
    free(ref);
    free(a);
    free(z);
    g3d_raster_ws_free(ws);
    return G3D_OK;
}

TEST(frames_match_rasterizer)
{
    g3d_gaussians g;
    small_scene(&g, 60);
    g3d_camera cams[2];
    two_cameras(cams);
    g3d_render_params p;
    g3d_render_params_default(&p);
    p.depth = 1;
    p.background[0] = 0.2f;
    p.background[2] = 0.9f;
    capture c = {0, 0, 0, 1, &g, {0.2f, 0.0f, 0.9f}};
    CHECK_OK(g3d_render_path(&g, cams, 2, &p, compare_frame, &c));
    CHECK(c.calls == 2);
    printf("  max |rgb - raster| %.3g, max |depth - z/alpha| %.3g\n", c.max_rgb_diff, c.max_depth_diff);
    CHECK(c.max_rgb_diff == 0.0);
    CHECK(c.max_depth_diff < 1e-6);
    CHECK(c.depth_zero_ok);

    p.sh_degree = 2;
    CHECK_FAILS(g3d_render_path(&g, cams, 2, &p, compare_frame, &c));
    p.sh_degree = -1;
    CHECK_FAILS(g3d_render_path(&g, cams, 0, &p, compare_frame, &c));
    cams[1].K.width = 0;
    CHECK_FAILS(g3d_render_path(&g, cams, 2, &p, compare_frame, &c));
    cams[1].K.width = 27;
    cams[1].c2w.m[0][3] = NAN;
    CHECK_FAILS(g3d_render_path(&g, cams, 2, &p, compare_frame, &c));
    g3d_gaussians_free(&g);
}

static int count_files(const char *dir)
{
    char cmd[1200];
    snprintf(cmd, sizeof cmd, "ls '%s' 2>/dev/null | wc -l", dir);
    FILE *f = popen(cmd, "r");
    int n = -1;
    if (f) {
        if (fscanf(f, "%d", &n) != 1) n = -1;
        pclose(f);
    }
    return n;
}

TEST(output_folder)
{
    g3d_gaussians g;
    small_scene(&g, 60);
    g3d_camera input;
    input.K = g3d_intrinsics_from_fov(60, 41, 31);  /* odd sides: the video pads them */
    input.c2w = g3d_mat4_identity();
    g3d_camera *cams = NULL;
    int n = 0;
    CHECK_OK(g3d_render_flythrough("orbit_left", NULL, &g, &input, 0, 6, &cams, &n));
    CHECK(n == 6);
    g3d_render_params p;
    g3d_render_params_default(&p);
    p.depth = 1;
    g3d_render_output_params o;
    g3d_render_output_params_default(&o);

    char dir[1024];
    snprintf(dir, sizeof dir, "%s", test_tmp("render_out"));
    g3d_remove_tree(dir);
    g3d_mkdirs(dir);
    g3d_render_result res;
    CHECK_OK(g3d_render_to_dir(&g, cams, n, &p, &o, dir, &res));
    char sub[1100];
    snprintf(sub, sizeof sub, "%s/frames", dir);
    CHECK(count_files(sub) == 6);
    snprintf(sub, sizeof sub, "%s/depth", dir);
    CHECK(count_files(sub) == 6);
    CHECK(res.frames_written);

    /* the depth PNG holds the rendered depth in millimetres */
    snprintf(sub, sizeof sub, "%s/depth/00003.png", dir);
    g3d_image dimg;
    CHECK_OK(g3d_depth_load(sub, 0, &dimg));
    g3d_raster_ws *ws;
    g3d_raster_ws_create(&ws);
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    const int W = 41, H = 31;
    float *rgb = malloc(sizeof(float) * W * H * 3), *a = malloc(sizeof(float) * W * H), *z = malloc(sizeof(float) * W * H);
    CHECK_OK(g3d_raster_fwd(ws, &g, &cams[3], &s, rgb, a, z, NULL));
    double maxd = 0;
    int valid = 0;
    for (int k = 0; k < W * H; k++) {
        float want = a[k] >= 0.5f ? z[k] / a[k] : 0.0f;
        maxd = fmax(maxd, fabs(dimg.data[k] - want));
        valid += want > 0;
    }
    printf("  depth PNG vs render: max %.2g m over %d valid pixels\n", maxd, valid);
    CHECK(valid > W * H / 4);
    CHECK(maxd <= 0.0005 + 1e-6);  /* millimetre rounding */
    g3d_image_free(&dimg);

    /* cameras.json: the path with names pointing at the frames */
    snprintf(sub, sizeof sub, "%s/cameras.json", dir);
    g3d_camera_list l;
    CHECK_OK(g3d_cameras_json_read(sub, &l));
    CHECK(l.n == 6);
    if (l.n == 6) {
        CHECK(strcmp(l.names[5], "frames/00005.png") == 0);
        CHECK(g3d_mat4_max_abs_diff(l.cams[4].c2w, cams[4].c2w) < 1e-9);
        CHECK(l.cams[2].K.width == 41 && l.cams[2].K.height == 31);
    }
    g3d_camera_list_free(&l);

    snprintf(sub, sizeof sub, "%s/video.mp4", dir);
    char *ff = NULL;
    if (g3d_video_find_ffmpeg(&ff) == G3D_OK) {
        CHECK(res.video_written && res.note == NULL);
        CHECK(test_file_exists(sub));
    }
    free(ff);
    g3d_error_clear();

    /* no ffmpeg: frames are written even though only the video was asked for */
    g3d_remove_tree(dir);
    g3d_mkdirs(dir);
    setenv("G3D_FFMPEG", "/nonexistent/ffmpeg", 1);
    o.frames = 0;
    o.cameras = 0;
    p.depth = 0;
    CHECK_OK(g3d_render_to_dir(&g, cams, n, &p, &o, dir, &res));
    unsetenv("G3D_FFMPEG");
    CHECK(!res.video_written && res.frames_written && res.note && strstr(res.note, "ffmpeg"));
    CHECK(!test_file_exists(sub));
    snprintf(sub, sizeof sub, "%s/frames", dir);
    CHECK(count_files(sub) == 6);
    snprintf(sub, sizeof sub, "%s/depth", dir);
    CHECK(!test_file_exists(sub));

    /* mixed sizes: no video, frames of their own sizes */
    g3d_remove_tree(dir);
    g3d_mkdirs(dir);
    two_cameras(cams);
    CHECK_OK(g3d_render_to_dir(&g, cams, 2, &p, &o, dir, &res));
    CHECK(!res.video_written && res.frames_written && res.note && strstr(res.note, "size"));
    snprintf(sub, sizeof sub, "%s/frames/00001.png", dir);
    g3d_image f1;
    CHECK_OK(g3d_image_load(sub, 3, &f1));
    CHECK(f1.w == 27 && f1.h == 35);
    g3d_image_free(&f1);

    free(rgb);
    free(a);
    free(z);
    g3d_raster_ws_free(ws);
    free(cams);
    g3d_gaussians_free(&g);
}

TEST(resample_poses)
{
    g3d_mat4 key[5];
    for (int i = 0; i < 5; i++) key[i] = g3d_pose_yaw_pitch(25.0 * i, i == 2 ? 10 : 0, g3d_v3(0.3 * i, 0, 0.1 * i * i));
    g3d_mat4 *o = NULL;
    CHECK_OK(g3d_render_resample_poses(key, 5, 17, &o));
    /* 17 frames over 4 segments: every 4th frame is a keyframe */
    double worst = 0;
    for (int i = 0; i < 5; i++) worst = fmax(worst, g3d_mat4_max_abs_diff(o[4 * i], key[i]));
    printf("  keyframes reproduced to %.2g\n", worst);
    CHECK(worst < 1e-9);
    /* smooth through the keyframes: at the middle keyframe (frame 8, with real neighbours on
     * both sides) the second difference of the centres is well below the kink that
     * piecewise-linear motion has there */
    {
        const int j = 2;
        g3d_vec3 a = g3d_mat4_translation(o[4 * j - 1]), b = g3d_mat4_translation(o[4 * j]),
                 c = g3d_mat4_translation(o[4 * j + 1]);
        g3d_vec3 ka = g3d_mat4_translation(key[j - 1]), kb = g3d_mat4_translation(key[j]),
                 kc = g3d_mat4_translation(key[j + 1]);
        double spline = g3d_v3_norm(g3d_v3_add(g3d_v3_sub(c, b), g3d_v3_sub(a, b)));
        double linear = g3d_v3_norm(g3d_v3_add(g3d_v3_sub(kc, kb), g3d_v3_sub(ka, kb))) / 4;
        /* the centres' z = 0.1 i^2 makes the exact value 0.2 / 16 = 0.0125 */
        printf("  keyframe 2: second difference %.4f m (piecewise linear %.4f m)\n", spline, linear);
        CHECK_NEAR(spline, 0.0125, 1e-3);
        CHECK(spline < 0.5 * linear);
    }
    /* rotations stay orthonormal */
    for (int i = 0; i < 17; i++) {
        g3d_mat4 m = o[i];
        g3d_mat4 rt = g3d_mat4_mul(g3d_mat4_inverse_rigid(m), m);
        CHECK(g3d_mat4_max_abs_diff(rt, g3d_mat4_identity()) < 1e-9);
    }
    free(o);
    CHECK_OK(g3d_render_resample_poses(key, 1, 3, &o));
    CHECK(g3d_mat4_max_abs_diff(o[2], key[0]) == 0);
    free(o);
    CHECK_FAILS(g3d_render_resample_poses(key, 5, 0, &o));
}

TEST(flythrough)
{
    g3d_gaussians g;
    g3d_gaussians_create(&g, 5, 0);
    g.n = 5;
    const float zs[5] = {1, 3, 2, -4, 7};  /* one behind the camera */
    for (int i = 0; i < 5; i++) g.means[i * 3 + 2] = zs[i];
    g3d_camera input;
    input.K = g3d_intrinsics_from_fov(50, 64, 48);
    input.c2w = g3d_pose_yaw_pitch(30, 0, g3d_v3(1, 0, -1));
    double s;
    /* the Gaussians are at z = 1, 3, 2, -4, 7 in the world; seen from the identity camera the
     * median of those in front is 2.5 */
    g3d_camera id = input;
    id.c2w = g3d_mat4_identity();
    CHECK_OK(g3d_render_scene_scale(&g, &id, &s));
    CHECK_NEAR(s, 2.5, 1e-6);

    g3d_camera *cams = NULL;
    int n = 0;
    CHECK_OK(g3d_render_flythrough("rotate", NULL, NULL, &input, 2.0, 0, &cams, &n));
    CHECK(n == 9);  /* the input + 8 steps */
    CHECK(g3d_mat4_max_abs_diff(cams[0].c2w, input.c2w) < 1e-12);
    CHECK(cams[5].K.width == 64 && cams[5].K.fx == input.K.fx);
    free(cams);

    CHECK_OK(g3d_render_flythrough("swing", NULL, NULL, &input, 2.0, 40, &cams, &n));
    CHECK(n == 40);
    CHECK(g3d_mat4_max_abs_diff(cams[0].c2w, input.c2w) < 1e-12);
    /* every swing camera aims at the point 2 m ahead of the input camera */
    g3d_vec3 target = g3d_mat4_point(input.c2w, g3d_v3(0, 0, 2.0));
    double worst = 0;
    for (int i = 0; i < n; i++) {
        double u, v, z;
        CHECK(g3d_camera_project(&cams[i], target, &u, &v, &z));
        worst = fmax(worst, fmax(fabs(u - input.K.cx), fabs(v - input.K.cy)));
    }
    CHECK(worst < 1e-6);
    /* it moves, and the loop closes: the last frame is one step from the first */
    g3d_vec3 c10 = g3d_camera_center(&cams[10]), c0 = g3d_camera_center(&cams[0]), cl = g3d_camera_center(&cams[39]);
    CHECK(g3d_v3_norm(g3d_v3_sub(c10, c0)) > 0.2);
    CHECK(g3d_v3_norm(g3d_v3_sub(cl, c0)) < 0.05);
    free(cams);

    CHECK_FAILS(g3d_render_flythrough("sideways", NULL, NULL, &input, 2.0, 10, &cams, &n));
    CHECK(strstr(g3d_error_message(), "swing") && strstr(g3d_error_message(), "orbit_left"));
    /* no scale and nothing in front of the camera */
    g.n = 0;
    CHECK_FAILS(g3d_render_flythrough("push_in", NULL, &g, &input, 0, 10, &cams, &n));
    g3d_gaussians_free(&g);
}

int main(void)
{
    RUN(frames_match_rasterizer);
    RUN(output_folder);
    RUN(resample_poses);
    RUN(flythrough);
    return test_summary();
}
