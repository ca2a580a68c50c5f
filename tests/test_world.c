/* The world loop on the procedural room: growth, consistency with the truth, determinism. */
#include "testutil.h"
#include "gen3d/depth_complete.h"
#include "gen3d/inpaint_classic.h"
#include "gen3d/procscene.h"
#include "gen3d/regions.h"
#include "gen3d/trajectory.h"
#include "gen3d/world.h"

static void make_frame(g3d_frame *f, int w, int h)
{
    memset(f, 0, sizeof *f);
    f->cam = g3d_procscene_default_camera(w, h);
    g3d_procscene_render(&f->cam, &f->rgb, &f->depth, NULL);
    snprintf(f->name, sizeof f->name, "procedural room");
}

static g3d_status run_world(const g3d_frame *f, uint64_t seed, g3d_world *w)
{
    g3d_mat4 *poses;
    int n;
    g3d_trajectory_params tp;
    g3d_trajectory_params_default(&tp);
    tp.steps = 3;
    tp.angle_deg = 30;
    g3d_trajectory_make("rotate", &tp, g3d_depth_median(&f->depth), &poses, &n);
    g3d_inpainter ip;
    g3d_mask_provider mp;
    g3d_depth_estimator de;
    g3d_depth_estimator_completion_create(&de);
    g3d_inpainter_classic_create(NULL, &ip);
    g3d_mask_provider_regions_create(NULL, f->cam.K, &mp);
    g3d_world_params wp;
    g3d_world_params_default(&wp);
    wp.extra_views = 5;
    g3d_layers L;
    g3d_status rc = g3d_layers_compute(&f->rgb, &f->depth, &mp, &ip, &de, NULL, seed, &L);
    if (rc == G3D_OK) rc = g3d_world_generate(f, poses, n, &ip, &de, &L, &wp, seed, w);
    g3d_layers_free(&L);
    g3d_inpainter_free(&ip);
    g3d_mask_provider_free(&mp);
    free(poses);
    return rc;
}

TEST(grows_the_scene_consistently)
{
    g3d_frame f;
    make_frame(&f, 160, 120);
    g3d_world w;
    CHECK_OK(run_world(&f, 5, &w));
    if (!w.n_views) return;
    CHECK(w.n_views == 4 && w.n_extra == 5);
    CHECK(w.layers.n_foreground >= 1);
    for (int i = 1; i < w.n_views; i++) {
        printf("  step %d: holes %.1f %%, %lld points added\n", i, 100 * w.steps[i].hole_fraction, (long long)w.steps[i].points_added);
        CHECK(w.steps[i].hole_fraction > 0.05 && w.steps[i].hole_fraction < 0.6);
        CHECK(w.steps[i].points_added > 0);
    }
    /* Where the generated views' depth comes from the cloud or its completion, it agrees with
     * the true room closely on the walls and floor the input saw. */
    g3d_image truth_d;
    CHECK_OK(g3d_procscene_render(&w.cams[3], NULL, &truth_d, NULL));
    double err = 0;
    size_t n = 0;
    for (size_t i = 0; i < g3d_image_size(&truth_d); i++)
        if (truth_d.data[i] < 10) { err += fabs(w.depth[3].data[i] - truth_d.data[i]) / truth_d.data[i]; n++; }
    printf("  view 3 depth vs truth: mean relative error %.1f %%\n", 100 * err / n);
    CHECK(err / n < 0.15);
    /* Extra views have valid pixels and holes (they are not inpainted). */
    double valid = 0;
    for (size_t i = 0; i < g3d_image_size(&w.extra_mask[0]); i++) valid += w.extra_mask[0].data[i];
    valid /= g3d_image_size(&w.extra_mask[0]);
    CHECK(valid > 0.5 && valid <= 1.0);
    g3d_image_free(&truth_d);
    g3d_world_free(&w);
    g3d_frame_free(&f);
}

static int same_file(const char *a, const char *b)
{
    unsigned char *x = NULL, *y = NULL;
    size_t nx = 0, ny = 0;
    int same = g3d_read_file(a, 1 << 28, &x, &nx) == G3D_OK && g3d_read_file(b, 1 << 28, &y, &ny) == G3D_OK && nx == ny &&
               !memcmp(x, y, nx);
    free(x);
    free(y);
    return same;
}

TEST(deterministic_dataset)
{
    g3d_frame f;
    make_frame(&f, 96, 72);
    g3d_world a, b;
    CHECK_OK(run_world(&f, 11, &a));
    CHECK_OK(run_world(&f, 11, &b));
    if (!a.n_views || !b.n_views) return;
    CHECK(a.cloud.n == b.cloud.n && !memcmp(a.cloud.xyz, b.cloud.xyz, sizeof(float) * 3 * a.cloud.n));
    CHECK_OK(g3d_world_save(&a, test_tmp("world_a"), 11));
    CHECK_OK(g3d_world_save(&b, test_tmp("world_b"), 11));
    const char *files[] = {"points.ply", "cameras.json", "transforms.json", "log.json", "views/view_003.png",
                           "depth/view_002.npy", "extra/extra_004.png", "masks/extra_001.png", "layers/fg_mask.png"};
    for (size_t k = 0; k < sizeof files / sizeof *files; k++) {
        char pa[1024], pb[1024];
        snprintf(pa, sizeof pa, "%s/%s", test_tmp("world_a"), files[k]);
        snprintf(pb, sizeof pb, "%s/%s", test_tmp("world_b"), files[k]);
        CHECK_MSG(same_file(pa, pb), "%s differs between two runs with the same seed", files[k]);
    }
    g3d_world_free(&a);
    g3d_world_free(&b);
    g3d_frame_free(&f);
}

static double max_abs_diff(const g3d_image *a, const g3d_image *b)
{
    if (a->w != b->w || a->h != b->h || a->c != b->c) return INFINITY;
    double m = 0;
    for (size_t i = 0; i < g3d_image_size(a); i++) m = fmax(m, fabs((double)a->data[i] - b->data[i]));
    return m;
}

TEST(world_folder_round_trip)
{
    g3d_frame f;
    make_frame(&f, 96, 72);
    g3d_world a, b;
    CHECK_OK(run_world(&f, 2, &a));
    if (!a.n_views) return;
    const char *dir = test_tmp("world_round_trip");
    CHECK_OK(g3d_world_save(&a, dir, 2));
    CHECK_OK(g3d_world_load(dir, &b));
    CHECK(b.n_views == a.n_views && b.n_extra == a.n_extra);
    if (b.n_views != a.n_views || b.n_extra != a.n_extra) return;
    /* what the folder keeps comes back: 8-bit colour, exact depth (.npy), cameras, masks */
    double cam = 0, rgb = 0, depth = 0, mask = 0;
    for (int i = 0; i < a.n_views; i++) {
        cam = fmax(cam, g3d_mat4_max_abs_diff(a.cams[i].c2w, b.cams[i].c2w) + fabs(a.cams[i].K.cx - b.cams[i].K.cx) +
                            fabs(a.cams[i].K.fx - b.cams[i].K.fx));
        rgb = fmax(rgb, max_abs_diff(&a.rgb[i], &b.rgb[i]));
        depth = fmax(depth, max_abs_diff(&a.depth[i], &b.depth[i]));
        CHECK(b.steps[i].points_added == a.steps[i].points_added && b.steps[i].hole_fraction == a.steps[i].hole_fraction &&
              b.steps[i].align.residual_after == a.steps[i].align.residual_after);
    }
    for (int k = 0; k < a.n_extra; k++) {
        cam = fmax(cam, g3d_mat4_max_abs_diff(a.extra_cams[k].c2w, b.extra_cams[k].c2w));
        rgb = fmax(rgb, max_abs_diff(&a.extra_rgb[k], &b.extra_rgb[k]));
        mask = fmax(mask, max_abs_diff(&a.extra_mask[k], &b.extra_mask[k]));
    }
    printf("  round trip: cameras %.1e, colour %.4f, depth %.1e m, masks %.1f\n", cam, rgb, depth, mask);
    CHECK(cam < 1e-9 && rgb <= 0.5 / 255 + 1e-6 && depth == 0 && mask == 0);
    CHECK(b.cloud.n == a.cloud.n && !memcmp(b.cloud.xyz, a.cloud.xyz, sizeof(float) * 3 * (size_t)a.cloud.n));
    CHECK(b.layers.n_foreground == a.layers.n_foreground && max_abs_diff(&b.layers.fg_mask, &a.layers.fg_mask) == 0 &&
          max_abs_diff(&b.layers.bg_depth, &a.layers.bg_depth) <= 0.0005 + 1e-6);
    /* saved again, the folder is the same bytes */
    const char *again = test_tmp("world_round_trip_again");
    CHECK_OK(g3d_world_save(&b, again, 2));
    const char *files[] = {"cameras.json", "transforms.json", "views/view_001.png", "depth/view_002.npy", "masks/extra_001.png",
                           "points.ply", "log.json"};
    for (size_t k = 0; k < sizeof files / sizeof *files; k++) {
        char pa[1024], pb[1024];
        snprintf(pa, sizeof pa, "%s/%s", dir, files[k]);
        snprintf(pb, sizeof pb, "%s/%s", again, files[k]);
        CHECK_MSG(same_file(pa, pb), "%s changed after loading and saving again", files[k]);
    }
    g3d_world_free(&a);
    g3d_world_free(&b);
    /* a folder that is not a world: no camera file */
    CHECK_FAILS(g3d_world_load(test_tmp("no_such_world"), &b));
    CHECK(strstr(g3d_error_message(), "no transforms.json or cameras.json") != NULL);
    g3d_frame_free(&f);
}

TEST(bad_trajectories)
{
    g3d_frame f;
    make_frame(&f, 64, 48);
    g3d_world w;
    g3d_inpainter ip;
    g3d_depth_estimator de;
    g3d_depth_estimator_completion_create(&de);
    g3d_inpainter_classic_create(NULL, &ip);
    /* A pose that turns round to look away from everything the input saw. */
    g3d_mat4 poses[2] = {g3d_mat4_identity(), g3d_pose_yaw_pitch(180, 0, g3d_v3(0, 0, -0.5))};
    CHECK_FAILS(g3d_world_generate(&f, poses, 2, &ip, &de, NULL, NULL, 1, &w));
    CHECK(strstr(g3d_error_message(), "pose 1") != NULL);
    CHECK_FAILS(g3d_world_generate(&f, poses, 0, &ip, &de, NULL, NULL, 1, &w));
    for (size_t i = 0; i < g3d_image_size(&f.depth); i++) f.depth.data[i] = 0;
    CHECK_FAILS(g3d_world_generate(&f, poses, 1, &ip, &de, NULL, NULL, 1, &w));
    g3d_inpainter_free(&ip);
    g3d_frame_free(&f);
}

/* Of the points that the views from `from` on lifted, how many lie in front of the depth of one
 * of the views before `from` (that view saw through them) by more than tol of that depth. */
static int64_t seen_through(const g3d_world *w, int from, double tol, int64_t *lifted)
{
    int64_t n = 0;
    *lifted = 0;
    for (int64_t k = 0; k < w->cloud.n; k++) {
        if (w->cloud.view[k] < from) continue;
        ++*lifted;
        g3d_vec3 x = g3d_v3(w->cloud.xyz[3 * k], w->cloud.xyz[3 * k + 1], w->cloud.xyz[3 * k + 2]);
        for (int j = 0; j < from; j++) {
            double u, v, z;
            if (!g3d_camera_project(&w->cams[j], x, &u, &v, &z)) continue;
            long iu = lround(u), iv = lround(v);
            if (iu < 0 || iv < 0 || iu >= w->depth[j].w || iv >= w->depth[j].h) continue;
            float dz = w->depth[j].data[iv * w->depth[j].w + iu];
            n += dz > 0 && z < dz * (1 - tol) - 1e-6;
        }
    }
    return n;
}

/* The procedural room at 96 x 72 with the weight-free plug-ins; returns a step of a quarter of
 * the median depth, the exploration set's. */
static double side_step_setup(g3d_frame *f, g3d_inpainter *ip, g3d_depth_estimator *de)
{
    make_frame(f, 96, 72);
    g3d_depth_estimator_completion_create(de);
    g3d_inpainter_classic_create(NULL, ip);
    return 0.25 * g3d_depth_median(&f->depth);
}

/* Side steps (the exploration set's in g3d_generate): at most side_max_side pixels, no hole
 * point lifted where the input saw through it, extra views around the path only, and bad
 * side-step parameters refused. */
TEST(side_steps_fill_only_what_the_path_left)
{
    g3d_frame f;
    g3d_inpainter ip;
    g3d_depth_estimator de;
    double d = side_step_setup(&f, &ip, &de);
    /* the input, a turn (the path), then steps sideways and forward with turns */
    g3d_mat4 poses[5] = {g3d_mat4_identity(), g3d_pose_yaw_pitch(15, 0, g3d_v3(0, 0, 0)),
                         g3d_pose_yaw_pitch(-15, 0, g3d_v3(d, 0, 0)), g3d_pose_yaw_pitch(15, 10, g3d_v3(-d, 0, d)),
                         g3d_pose_yaw_pitch(0, -10, g3d_v3(0, 0.5 * d, 2 * d))};
    g3d_world_params wp;
    g3d_world_params_default(&wp);
    wp.extra_views = 3;
    wp.side_from = 2;
    wp.side_max_side = 48;
    wp.side_carve = 0.02;
    g3d_world w, path;
    CHECK_OK(g3d_world_generate(&f, poses, 5, &ip, &de, NULL, &wp, 3, &w));
    wp.side_from = 0;
    CHECK_OK(g3d_world_generate(&f, poses, 2, &ip, &de, NULL, &wp, 3, &path));
    if (w.n_views == 5 && path.n_views == 2) {
        for (int i = 0; i < 5; i++) {
            int side = i >= 2;
            CHECK(w.cams[i].K.width == (side ? 48 : 96) && w.cams[i].K.height == (side ? 36 : 72));
            CHECK(w.rgb[i].w == w.cams[i].K.width && w.depth[i].h == w.cams[i].K.height);
        }
        /* the extra views orbit the path's poses, as without the side steps */
        CHECK(w.n_extra == 3 && path.n_extra == 3);
        for (int k = 0; k < w.n_extra && k < path.n_extra; k++)
            CHECK(g3d_mat4_max_abs_diff(w.extra_cams[k].c2w, path.extra_cams[k].c2w) < 1e-12);
        /* every point a side step lifted lies behind the depth of the path views that see it */
        int64_t lifted, through = seen_through(&w, 2, wp.side_carve, &lifted);
        printf("  side steps: %lld points lifted, %lld seen through by the path\n", (long long)lifted, (long long)through);
        CHECK(lifted > 0);
        CHECK(through == 0);
    }
    g3d_world_free(&w);
    g3d_world_free(&path);
    wp.side_from = 2;
    wp.side_max_side = 8;
    CHECK_FAILS(g3d_world_generate(&f, poses, 5, &ip, &de, NULL, &wp, 3, &w));
    wp.side_max_side = 48;
    wp.side_carve = -0.1;
    CHECK_FAILS(g3d_world_generate(&f, poses, 5, &ip, &de, NULL, &wp, 3, &w));
    wp.side_carve = NAN;
    CHECK_FAILS(g3d_world_generate(&f, poses, 5, &ip, &de, NULL, &wp, 3, &w));
    wp.side_carve = 0.02;
    wp.align.edge_ratio = 1.0f;
    CHECK_FAILS(g3d_world_generate(&f, poses, 5, &ip, &de, NULL, &wp, 3, &w));
    g3d_inpainter_free(&ip);
    g3d_frame_free(&f);
}

/* A side step that looks away from the scene is left out (the views after it close the gap);
 * the same pose on the path is an error (bad_trajectories). */
TEST(side_steps_that_see_nothing_are_left_out)
{
    g3d_frame f;
    g3d_inpainter ip;
    g3d_depth_estimator de;
    double d = side_step_setup(&f, &ip, &de);
    g3d_mat4 poses[4] = {g3d_mat4_identity(), g3d_pose_yaw_pitch(15, 0, g3d_v3(0, 0, 0)),
                         g3d_pose_yaw_pitch(180, 0, g3d_v3(0, 0, -0.5)), g3d_pose_yaw_pitch(-15, 0, g3d_v3(d, 0, 0))};
    g3d_world_params wp;
    g3d_world_params_default(&wp);
    wp.extra_views = 0;
    wp.side_from = 2;
    wp.side_max_side = 48;
    g3d_world w;
    CHECK_OK(g3d_world_generate(&f, poses, 4, &ip, &de, NULL, &wp, 3, &w));
    CHECK(w.n_views == 3);
    if (w.n_views == 3) {
        g3d_mat4 want = g3d_mat4_mul(f.cam.c2w, poses[3]);
        CHECK(g3d_mat4_max_abs_diff(w.cams[2].c2w, want) < 1e-12);
        CHECK(w.rgb[2].w == 48 && w.steps[2].hole_fraction < 1.0);
        int64_t from_last = 0;
        for (int64_t k = 0; k < w.cloud.n; k++) from_last += w.cloud.view[k] == 2;
        CHECK(from_last > 0);
    }
    g3d_world_free(&w);
    wp.side_from = 3;
    CHECK_FAILS(g3d_world_generate(&f, poses, 4, &ip, &de, NULL, &wp, 3, &w));
    CHECK(strstr(g3d_error_message(), "pose 2") != NULL);
    g3d_inpainter_free(&ip);
    g3d_frame_free(&f);
}

/* Side steps sideways past the box: what they uncover beside it is completed from the far side
 * of its edges, so without carving far fewer of their points float in front of what the path
 * saw than when the holes are completed from both sides. */
TEST(disocclusions_are_completed_from_behind)
{
    g3d_frame f;
    g3d_inpainter ip;
    g3d_depth_estimator de;
    double d = side_step_setup(&f, &ip, &de);
    g3d_mat4 poses[4] = {g3d_mat4_identity(), g3d_pose_yaw_pitch(0, 0, g3d_v3(d, 0, 0)), g3d_pose_yaw_pitch(0, 0, g3d_v3(-d, 0, 0)),
                         g3d_pose_yaw_pitch(0, 0, g3d_v3(0, -0.5 * d, d))};
    g3d_world_params wp;
    g3d_world_params_default(&wp);
    wp.extra_views = 0;
    wp.side_from = 1;
    wp.side_carve = 0;
    int64_t through[2], lifted[2];
    for (int edges = 0; edges < 2; edges++) {
        g3d_world w;
        wp.align.edge_ratio = edges ? 1.1f : 0.0f;
        CHECK_OK(g3d_world_generate(&f, poses, 4, &ip, &de, NULL, &wp, 3, &w));
        through[edges] = w.n_views == 4 ? seen_through(&w, 1, 0.02, &lifted[edges]) : -1;
        g3d_world_free(&w);
    }
    printf("  side-step points in front of the input's surfaces: %lld of %lld from both sides, %lld of %lld from the "
           "far side\n", (long long)through[0], (long long)lifted[0], (long long)through[1], (long long)lifted[1]);
    CHECK(through[0] > 20);
    CHECK(through[1] >= 0 && through[1] * 4 < through[0]);
    g3d_inpainter_free(&ip);
    g3d_frame_free(&f);
}

int main(void)
{
    RUN(grows_the_scene_consistently);
    RUN(deterministic_dataset);
    RUN(world_folder_round_trip);
    RUN(bad_trajectories);
    RUN(side_steps_fill_only_what_the_path_left);
    RUN(side_steps_that_see_nothing_are_left_out);
    RUN(disocclusions_are_completed_from_behind);
    return test_summary();
}
