/* The pipeline in the library (generate.h) on the procedural room: the result and the files
 * agree, a cancelled run stops with its own status and leaves nothing, a run can stop after
 * the world and a later one can train on that folder, a moving preset takes the steps it should,
 * bad parameters fail before any work. */
#include "testutil.h"
#include "gen3d/generate.h"
#include "gen3d/init.h"
#include "gen3d/ply.h"
#include "gen3d/procscene.h"

#include <dirent.h>

static void make_frame(g3d_frame *f, int w, int h)
{
    memset(f, 0, sizeof *f);
    f->cam = g3d_procscene_default_camera(w, h);
    g3d_procscene_render(&f->cam, &f->rgb, &f->depth, NULL);
    snprintf(f->name, sizeof f->name, "procedural room");
}

/* A small, fast run on an in-memory frame. */
static void small_params(g3d_generate_params *p, const g3d_frame *f, const char *out)
{
    g3d_generate_params_default(p);
    p->frame = f;
    p->steps = 2;
    p->trajectory_params.angle_deg = 20;
    p->world.extra_views = 2;
    p->explore_views = 0;  /* test_explore.c runs them */
    p->sh_degree = 1;
    g3d_train_params_default(&p->train, 40);
    p->video = 0;
    p->output_dir = out;
    p->seed = 3;
}

/* 1 when some entry of folder `dir` starts with `prefix` (a leftover temporary folder). */
static int has_entry_starting(const char *dir, const char *prefix)
{
    DIR *d = opendir(dir);
    int found = 0;
    for (struct dirent *e; d && (e = readdir(d));) found |= !strncmp(e->d_name, prefix, strlen(prefix));
    if (d) closedir(d);
    return found;
}

TEST(result_and_files_agree)
{
    g3d_frame f;
    make_frame(&f, 96, 72);
    const char *out = test_tmp("generate_lib");
    g3d_generate_params p;
    small_params(&p, &f, out);
    g3d_generate_result r;
    CHECK_OK(g3d_generate(&p, &r));
    printf("  %d views + %d extra, %lld points, %lld -> %lld Gaussians, PSNR %.1f dB, %.2f s\n", r.views, r.extra_views,
           (long long)r.points, (long long)r.initial_gaussians, (long long)r.gaussians, r.train_psnr, r.seconds_total);
    CHECK(r.views == 3 && r.extra_views == 2 && r.width == 96 && r.height == 72);
    CHECK(r.points > 0 && r.initial_gaussians == r.points && r.gaussians == r.scene.n && r.scene.n > 0);
    CHECK(r.train_psnr > 15.0);
    /* the exploration figures: the mean and worst of the per-camera fractions */
    double mean = 0, worst = 0;
    for (int i = 0; i < G3D_EXPLORE_CAMERAS; i++) {
        CHECK(r.explore_empty[i] >= 0 && r.explore_empty[i] <= 1);
        mean += r.explore_empty[i] / G3D_EXPLORE_CAMERAS;
        worst = fmax(worst, r.explore_empty[i]);
    }
    CHECK(r.explore_distance > 0 && r.explore_mean_empty == mean && r.explore_max_empty == worst);
    double sum = 0;
    for (int s = 0; s < G3D_STAGE_COUNT; s++) {
        CHECK(r.seconds[s] >= 0);
        sum += r.seconds[s];
    }
    CHECK(r.seconds[G3D_STAGE_SPLATS] > 0 && sum <= r.seconds_total + 1e-6);
    /* the scene on disk is the scene in the result */
    char path[1200];
    snprintf(path, sizeof path, "%s/scene.ply", out);
    g3d_gaussians g;
    CHECK_OK(g3d_ply_read_gaussians(path, &g));
    CHECK(g.n == r.scene.n && g.sh_degree == 1 && !memcmp(g.means, r.scene.means, sizeof(float) * 3 * (size_t)g.n));
    const char *files[] = {"scene.spz", "preview.png", "cameras.json", "transforms.json", "points.ply", "config.json",
                           "summary.json", "dataset/log.json", "dataset/views/view_002.png", "dataset/masks/extra_001.png",
                           "exploration.png", "exploration_cameras.json"};
    for (size_t k = 0; k < sizeof files / sizeof *files; k++) {
        snprintf(path, sizeof path, "%s/%s", out, files[k]);
        CHECK_MSG(test_file_exists(path), "%s is missing", files[k]);
    }
    g3d_gaussians_free(&g);
    g3d_generate_result_free(&r);
    CHECK(r.scene.n == 0);
    /* no output folder: the same scene in memory only, its exploration figures measured all the same */
    p.output_dir = NULL;
    double mean_on_disk = mean;
    CHECK_OK(g3d_generate(&p, &r));
    CHECK(r.scene.n > 0 && r.explore_mean_empty == mean_on_disk);
    g3d_generate_result_free(&r);
    g3d_frame_free(&f);
}

/* Cancels at the n-th poll. */
static int cancel_at(void *user)
{
    int *left = user;
    return --*left <= 0;
}

static int stop_training(void *user, const char *stage, int64_t step, int64_t total, const char *info)
{
    (void)user, (void)step, (void)total, (void)info;
    return !strcmp(stage, "train");
}

TEST(cancelling_leaves_nothing)
{
    g3d_frame f;
    make_frame(&f, 64, 48);
    const char *out = test_tmp("generate_cancel");
    g3d_generate_params p;
    small_params(&p, &f, out);
    g3d_generate_result r;
    /* cancelled from outside between the first stages, and later inside world generation */
    for (int at = 1; at <= 6; at += 5) {
        int left = at;
        p.cancel = (g3d_cancel){cancel_at, &left};
        CHECK(g3d_generate(&p, &r) == G3D_CANCELLED);
        CHECK(r.scene.n == 0 && r.views == 0);
        CHECK_MSG(!test_file_exists(out), "output after cancelling at poll %d", at);
    }
    /* a progress callback asking to stop cancels too, with the same status */
    p.cancel = (g3d_cancel){0};
    p.progress = (g3d_progress){stop_training, NULL};
    CHECK(g3d_generate(&p, &r) == G3D_CANCELLED);
    CHECK(!test_file_exists(out));
    CHECK(!has_entry_starting(test_tmp(""), "generate_cancel.tmp-"));
    g3d_frame_free(&f);
}

TEST(world_folder_then_splats)
{
    g3d_frame f;
    make_frame(&f, 80, 60);
    const char *world = test_tmp("generate_world"), *scene = test_tmp("generate_from_world");
    g3d_generate_params p;
    small_params(&p, &f, world);
    p.last_stage = G3D_STAGE_WORLD;
    g3d_generate_result r;
    CHECK_OK(g3d_generate(&p, &r));
    CHECK(r.views == 3 && r.scene.n == 0 && r.seconds[G3D_STAGE_SPLATS] == 0);
    char path[1200];
    snprintf(path, sizeof path, "%s/log.json", world);
    CHECK(test_file_exists(path));
    snprintf(path, sizeof path, "%s/scene.ply", world);
    CHECK(!test_file_exists(path));
    const int64_t points = r.points;
    g3d_generate_result_free(&r);

    /* training on the saved world: the cloud and views come back from the folder */
    g3d_generate_params q;
    small_params(&q, NULL, scene);
    q.world_dir = world;
    CHECK_OK(g3d_generate(&q, &r));
    CHECK(r.views == 3 && r.extra_views == 2 && r.points == points && r.initial_gaussians == points && r.gaussians > 0);
    CHECK(r.seconds[G3D_STAGE_INPUT] == 0 && r.seconds[G3D_STAGE_LAYERS] == 0);
    g3d_generate_result_free(&r);

    /* without points.ply the Gaussians start from random points around the cameras */
    snprintf(path, sizeof path, "%s/points.ply", world);
    CHECK(remove(path) == 0);
    q.output_dir = NULL;
    g3d_train_params_default(&q.train, 2);
    CHECK_OK(g3d_generate(&q, &r));
    CHECK(r.points == 0 && r.initial_gaussians == G3D_RANDOM_INIT_POINTS);
    g3d_generate_result_free(&r);
    g3d_frame_free(&f);
}

/* A keyframed preset takes 2 generation steps by default, not its video's 50 frames, and
 * --steps N makes exactly N + 1 evenly spaced poses of it. */
TEST(moving_preset_steps)
{
    g3d_frame f;
    make_frame(&f, 64, 48);
    const char *world = test_tmp("generate_move_right");
    const int steps[2] = {0, 8}, views[2] = {3, 9};
    for (int k = 0; k < 2; k++) {
        g3d_generate_params p;
        small_params(&p, &f, world);
        p.trajectory = "move_right";
        p.trajectory_params.distance = 0.4;  /* the preset moves half of it: 0.2 m */
        p.steps = steps[k];
        p.world.extra_views = 0;
        p.last_stage = G3D_STAGE_WORLD;
        g3d_generate_result r;
        CHECK_OK(g3d_generate(&p, &r));
        CHECK(r.views == views[k]);
        g3d_generate_result_free(&r);
        char path[1200];
        snprintf(path, sizeof path, "%s/cameras.json", world);
        g3d_camera_list l;
        CHECK_OK(g3d_camera_list_load(path, &l));
        CHECK(l.n == views[k]);
        for (int i = 0; i < l.n && l.n == views[k]; i++)
            CHECK_NEAR(g3d_v3_norm(g3d_v3_sub(g3d_mat4_translation(l.cams[i].c2w), g3d_mat4_translation(l.cams[0].c2w))),
                       0.2 * i / (views[k] - 1), 1e-6);
        g3d_camera_list_free(&l);
    }
    g3d_frame_free(&f);
}

TEST(refusals_before_work)
{
    g3d_frame f;
    make_frame(&f, 64, 48);
    const char *out = test_tmp("generate_never");
    g3d_generate_params p;
    small_params(&p, &f, out);
    p.trajectory = "spiral";
    CHECK(g3d_generate(&p, NULL) == G3D_ERR_ARG);
    CHECK(strstr(g3d_error_message(), "spiral") != NULL);
    small_params(&p, &f, out);
    p.video = 1;
    p.video_trajectory = "elsewhere";
    CHECK(g3d_generate(&p, NULL) == G3D_ERR_ARG);
    small_params(&p, &f, out);
    p.last_stage = G3D_STAGE_LAYERS;
    CHECK(g3d_generate(&p, NULL) == G3D_ERR_ARG);
    small_params(&p, &f, out);
    p.sh_degree = 4;
    CHECK(g3d_generate(&p, NULL) == G3D_ERR_ARG);
    small_params(&p, &f, out);
    p.coverage_weight = NAN;
    CHECK(g3d_generate(&p, NULL) == G3D_ERR_ARG);
    CHECK(strstr(g3d_error_message(), "coverage weight") != NULL);
    small_params(&p, NULL, out);
    p.input.rgb_path = test_tmp("no-such-image.png");
    p.input.depth_path = test_tmp("no-such-depth.png");
    CHECK_FAILS(g3d_generate(&p, NULL));
    CHECK(strstr(g3d_error_message(), "no-such-image.png") != NULL);
    CHECK(!test_file_exists(out));
    CHECK(!has_entry_starting(test_tmp(""), "generate_never.tmp-"));
    g3d_frame_free(&f);
}

int main(int argc, char **argv)
{
    (void)argc;
    g3d_process_setup(argv);   /* idle OpenMP threads sleep: on a busy machine spinning ones cost 10x */
    RUN(result_and_files_agree);
    RUN(cancelling_leaves_nothing);
    RUN(world_folder_then_splats);
    RUN(moving_preset_steps);
    RUN(refusals_before_work);
    return test_summary();
}
