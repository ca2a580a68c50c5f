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
    g3d_status rc = g3d_world_generate(f, poses, n, &ip, &de, &mp, &wp, seed, w);
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

int main(void)
{
    RUN(grows_the_scene_consistently);
    RUN(deterministic_dataset);
    RUN(bad_trajectories);
    return test_summary();
}
