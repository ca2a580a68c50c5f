/* test_train.c - training fits a synthetic Gaussian scene from noisy points, and is
 * deterministic for a fixed seed. */
#include "gen3d/ckpt.h"
#include "gen3d/init.h"
#include "gen3d/loss.h"
#include "gen3d/ply.h"
#include "gen3d/raster.h"
#include "gen3d/train.h"
#include "testutil.h"

#define NGT 150
#define RES 64
#define NTRAIN 24
#define NTEST 4

static void gt_scene(g3d_gaussians *g)
{
    g3d_rng r;
    g3d_rng_seed(&r, 5, 0);
    g3d_gaussians_create(g, NGT, 0);
    g->n = NGT;
    for (int i = 0; i < NGT; i++) {
        for (int a = 0; a < 3; a++) {
            g->means[i * 3 + a] = 1.6f * (g3d_rng_float(&r) - 0.5f);
            g->log_scales[i * 3 + a] = logf(0.06f + 0.1f * g3d_rng_float(&r));
            g->sh[i * 3 + a] = (g3d_rng_float(&r) - 0.5f) / G3D_SH_C0;
        }
        for (int a = 0; a < 4; a++) g->rots[i * 4 + a] = g3d_rng_normal(&r);
        g->opacity_logits[i] = 1.5f;
    }
}

static g3d_camera ring_camera(double angle, double height)
{
    g3d_camera c;
    c.K = g3d_intrinsics_from_fov(55.0, RES, RES);
    c.c2w = g3d_mat4_look_at(g3d_v3(3.5 * cos(angle), height, 3.5 * sin(angle)), g3d_v3(0, 0, 0),
                             g3d_v3(0, -1, 0));
    return c;
}

static void render(const g3d_gaussians *g, const g3d_camera *c, g3d_image *img)
{
    g3d_raster_ws *ws;
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    g3d_image_create(img, RES, RES, 3);
    g3d_raster_ws_create(&ws);
    CHECK_OK(g3d_raster_fwd(ws, g, c, &s, img->data, NULL, NULL, NULL));
    g3d_raster_ws_free(ws);
}

/* The training views: the ring of cameras around the ground-truth scene, rendered. */
static void ring_views(const g3d_gaussians *gt, g3d_image imgs[NTRAIN], g3d_train_view views[NTRAIN])
{
    for (int i = 0; i < NTRAIN; i++) {
        views[i].cam = ring_camera(2 * M_PI * i / NTRAIN, (i % 3 - 1) * 1.0);
        render(gt, &views[i].cam, &imgs[i]);
        views[i].image = &imgs[i];
        views[i].mask = NULL;
    }
}

static void init_model(const g3d_gaussians *gt, g3d_gaussians *g)
{
    g3d_rng r;
    g3d_rng_seed(&r, 8, 0);
    float xyz[NGT * 3], rgb[NGT * 3];
    for (int i = 0; i < NGT * 3; i++) {
        xyz[i] = gt->means[i] + 0.03f * g3d_rng_normal(&r);
        rgb[i] = 0.5f;
    }
    CHECK_OK(g3d_gaussians_init_from_points(g, xyz, rgb, NGT, 0));
}

TEST(fits_and_is_deterministic)
{
    g3d_gaussians gt, g, g2;
    gt_scene(&gt);
    g3d_image imgs[NTRAIN];
    g3d_train_view views[NTRAIN];
    ring_views(&gt, imgs, views);
    init_model(&gt, &g);
    init_model(&gt, &g2);
    g3d_train_params p;
    g3d_train_params_default(&p, 500);
    g3d_train_result res;
    CHECK_OK(g3d_train(&g, views, NTRAIN, &p, &res));
    double mean_psnr = 0;
    for (int i = 0; i < NTEST; i++) {
        g3d_camera c = ring_camera(2 * M_PI * (i + 0.5) / NTEST + 0.1, 0.5);
        g3d_image want, got;
        render(&gt, &c, &want);
        render(&g, &c, &got);
        double psnr;
        CHECK_OK(g3d_psnr(&got, &want, NULL, &psnr));
        mean_psnr += psnr / NTEST;
        g3d_image_free(&want);
        g3d_image_free(&got);
    }
    printf("       500 its, %lld Gaussians, %.1f s: train PSNR %.2f dB, held-out PSNR %.2f dB\n",
           (long long)g.n, res.seconds, res.last_psnr, mean_psnr);
    CHECK(mean_psnr >= 25.0);

    /* same seed, same result, bit for bit (a short run that includes a densification) */
    g3d_gaussians g1;
    init_model(&gt, &g1);
    g3d_train_params_default(&p, 250);
    const char *ckpt = test_tmp("train.ckpt.safetensors");
    remove(ckpt);
    p.checkpoint_path = ckpt;
    p.checkpoint_every = 150;
    CHECK_OK(g3d_train(&g1, views, NTRAIN, &p, NULL));
    p.checkpoint_path = NULL;
    g3d_gaussians_free(&g);
    g = g1;
    CHECK_OK(g3d_train(&g2, views, NTRAIN, &p, NULL));
    CHECK(g2.n == g.n);
    CHECK(g2.n == g.n && memcmp(g2.means, g.means, (size_t)g.n * 3 * sizeof(float)) == 0 &&
          memcmp(g2.sh, g.sh, (size_t)g.n * 3 * sizeof(float)) == 0);

    /* resuming from the checkpoint written at iteration 150 ends where the whole run ended */
    g3d_gaussians r = {0};
    p.resume_path = ckpt;
    CHECK_OK(g3d_train(&r, views, NTRAIN, &p, NULL));
    CHECK(r.n == g.n && memcmp(r.means, g.means, (size_t)g.n * 3 * sizeof(float)) == 0 &&
          memcmp(r.log_scales, g.log_scales, (size_t)g.n * 3 * sizeof(float)) == 0 &&
          memcmp(r.rots, g.rots, (size_t)g.n * 4 * sizeof(float)) == 0 &&
          memcmp(r.opacity_logits, g.opacity_logits, (size_t)g.n * sizeof(float)) == 0 &&
          memcmp(r.sh, g.sh, (size_t)g.n * 3 * sizeof(float)) == 0);
    /* ... and refuses another view set, another seed, a finished schedule, or a foreign file */
    CHECK_FAILS(g3d_train(&r, views, NTRAIN - 1, &p, NULL));
    p.seed = 43;
    CHECK_FAILS(g3d_train(&r, views, NTRAIN, &p, NULL));
    p.seed = 42;
    p.iterations = 150;
    CHECK_FAILS(g3d_train(&r, views, NTRAIN, &p, NULL));
    p.iterations = 250;
    const char *foreign = test_tmp("foreign.safetensors");
    g3d_tensor_out t = {"model.means", G3D_DT_F32, 2, {1, 3}, r.means};
    CHECK_OK(g3d_safetensors_write(foreign, &t, 1, NULL));
    p.resume_path = foreign;
    CHECK_FAILS(g3d_train(&r, views, NTRAIN, &p, NULL));
    CHECK(strstr(g3d_error_message(), "not a gen3d training checkpoint") != NULL);
    p.resume_path = NULL;
    g3d_gaussians_free(&r);

    /* the trained model survives the standard 3DGS PLY exactly */
    g3d_gaussians back;
    const char *ply = test_tmp("trained.ply");
    CHECK_OK(g3d_ply_write_gaussians(ply, &g));
    CHECK_OK(g3d_ply_read_gaussians(ply, &back));
    CHECK(back.n == g.n && back.sh_degree == g.sh_degree);
    if (back.n == g.n) {
        CHECK(memcmp(back.means, g.means, (size_t)g.n * 3 * sizeof(float)) == 0);
        CHECK(memcmp(back.log_scales, g.log_scales, (size_t)g.n * 3 * sizeof(float)) == 0);
        CHECK(memcmp(back.rots, g.rots, (size_t)g.n * 4 * sizeof(float)) == 0);
        CHECK(memcmp(back.opacity_logits, g.opacity_logits, (size_t)g.n * sizeof(float)) == 0);
        CHECK(memcmp(back.sh, g.sh, (size_t)g.n * 3 * sizeof(float)) == 0);
    }
    g3d_gaussians_free(&back);

    /* a view whose image does not match its camera is refused */
    g3d_image small;
    g3d_image_create(&small, RES / 2, RES, 3);
    views[3].image = &small;
    CHECK_FAILS(g3d_train(&g2, views, NTRAIN, &p, NULL));
    g3d_image_free(&small);
    for (int i = 0; i < NTRAIN; i++) g3d_image_free(&imgs[i]);
    g3d_gaussians_free(&gt);
    g3d_gaussians_free(&g);
    g3d_gaussians_free(&g2);
}

static int same_model(const g3d_gaussians *a, const g3d_gaussians *b)
{
    return a->n == b->n && memcmp(a->means, b->means, (size_t)a->n * 3 * sizeof(float)) == 0 &&
           memcmp(a->log_scales, b->log_scales, (size_t)a->n * 3 * sizeof(float)) == 0 &&
           memcmp(a->sh, b->sh, (size_t)a->n * 3 * sizeof(float)) == 0 &&
           memcmp(a->opacity_logits, b->opacity_logits, (size_t)a->n * sizeof(float)) == 0;
}

/* Trains `whole` with a checkpoint every `every` iterations, then `resumed` from the last one. */
static void run_and_resume(g3d_gaussians *whole, g3d_gaussians *resumed, const g3d_train_view *views, g3d_train_params p,
                           const char *name, int64_t every)
{
    const char *ckpt = test_tmp(name);
    remove(ckpt);
    p.checkpoint_path = ckpt;
    p.checkpoint_every = every;
    CHECK_OK(g3d_train(whole, views, NTRAIN, &p, NULL));
    p.checkpoint_path = NULL;
    p.resume_path = ckpt;
    memset(resumed, 0, sizeof *resumed);
    CHECK_OK(g3d_train(resumed, views, NTRAIN, &p, NULL));
}

/* Coarse to fine: the first iterations see every view at half size; a run resumed from a
 * checkpoint taken in the coarse part crosses into the fine part exactly as the whole run. */
TEST(coarse_to_fine)
{
    g3d_gaussians gt, a, b, fine;
    gt_scene(&gt);
    g3d_image imgs[NTRAIN];
    g3d_train_view views[NTRAIN];
    ring_views(&gt, imgs, views);
    init_model(&gt, &a);
    init_model(&gt, &fine);
    g3d_train_params p;
    g3d_train_params_default(&p, 160);
    p.coarse_until = 0;
    CHECK_OK(g3d_train(&fine, views, NTRAIN, &p, NULL));
    p.coarse_until = 100;
    run_and_resume(&a, &b, views, p, "coarse.ckpt.safetensors", 60);
    CHECK(same_model(&a, &b));
    /* the coarse part did train on other images than the plain run */
    CHECK(!same_model(&a, &fine));
    /* and the model still fits a held-out view */
    g3d_camera c = ring_camera(0.3, 0.5);
    g3d_image want, got;
    render(&gt, &c, &want);
    render(&a, &c, &got);
    double psnr;
    CHECK_OK(g3d_psnr(&got, &want, NULL, &psnr));
    printf("       160 its, coarse until 100: held-out PSNR %.2f dB\n", psnr);
    CHECK(psnr >= 20.0);
    g3d_image_free(&want);
    g3d_image_free(&got);
    for (int i = 0; i < NTRAIN; i++) g3d_image_free(&imgs[i]);
    g3d_gaussians_free(&gt);
    g3d_gaussians_free(&a);
    g3d_gaussians_free(&b);
    g3d_gaussians_free(&fine);
}

/* The first view on its own beat: with a beat of 1 training sees only the first view, exactly
 * as a run on that view alone; with a beat of 3 a run resumed from a checkpoint ends where the
 * whole run does, and differs from the run without the beat. */
TEST(first_view_beat)
{
    g3d_gaussians gt, a, b, c;
    gt_scene(&gt);
    g3d_image imgs[NTRAIN];
    g3d_train_view views[NTRAIN];
    ring_views(&gt, imgs, views);
    g3d_train_params p;
    g3d_train_params_default(&p, 90);
    p.extent = 4.0;
    init_model(&gt, &a);
    init_model(&gt, &b);
    p.first_view_every = 1;
    CHECK_OK(g3d_train(&a, views, NTRAIN, &p, NULL));
    p.first_view_every = 0;
    CHECK_OK(g3d_train(&b, views, 1, &p, NULL));
    CHECK(same_model(&a, &b));
    g3d_gaussians_free(&a);
    g3d_gaussians_free(&b);

    init_model(&gt, &a);
    init_model(&gt, &c);
    CHECK_OK(g3d_train(&c, views, NTRAIN, &p, NULL));
    p.first_view_every = 3;
    run_and_resume(&a, &b, views, p, "beat.ckpt.safetensors", 40);
    CHECK(same_model(&a, &b));
    CHECK(!same_model(&a, &c));
    for (int i = 0; i < NTRAIN; i++) g3d_image_free(&imgs[i]);
    g3d_gaussians_free(&gt);
    g3d_gaussians_free(&a);
    g3d_gaussians_free(&b);
    g3d_gaussians_free(&c);
}

/* Mean accumulated opacity of g seen from c, over the columns x0..x1-1. */
static double mean_alpha(const g3d_gaussians *g, const g3d_camera *c, int x0, int x1)
{
    g3d_raster_ws *ws;
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    float *rgb = malloc(sizeof(float) * 3 * RES * RES), *alpha = malloc(sizeof(float) * RES * RES);
    g3d_raster_ws_create(&ws);
    CHECK_OK(g3d_raster_fwd(ws, g, c, &s, rgb, alpha, NULL, NULL));
    g3d_raster_ws_free(ws);
    double m = 0;
    for (int y = 0; y < RES; y++)
        for (int x = x0; x < x1; x++) m += alpha[y * RES + x] / ((double)RES * (x1 - x0));
    free(rgb);
    free(alpha);
    return m;
}

/* A dark wall seen by one view, against the black background: the photometric loss alone is
 * as well served by a transparent wall as by a dark one, and lowers the opacity; the coverage
 * term keeps it opaque. With the right half of the view masked out, the term pulls where the
 * view is trained, not where it is masked. */
TEST(coverage_term_keeps_dark_surfaces_opaque)
{
    g3d_gaussians wall;
    const int side = 24;
    CHECK_OK(g3d_gaussians_create(&wall, side * side, 0));
    wall.n = side * side;
    for (int i = 0; i < side * side; i++) {
        float xyz[3] = {2.0f * ((i % side) + 0.5f) / side - 1.0f, 2.0f * ((i / side) + 0.5f) / side - 1.0f, 0.0f};
        for (int a = 0; a < 3; a++) {
            wall.means[3 * i + a] = xyz[a];
            wall.log_scales[3 * i + a] = logf(a < 2 ? 0.06f : 0.01f);
            wall.sh[3 * i + a] = (0.5f - 0.5f) / G3D_SH_C0;
        }
        wall.rots[4 * i] = 1.0f;
        wall.opacity_logits[i] = 0.0f;   /* 0.5 */
    }
    g3d_camera cam;
    cam.K = g3d_intrinsics_from_fov(40.0, RES, RES);
    cam.c2w = g3d_mat4_look_at(g3d_v3(0, 0, -2.2), g3d_v3(0, 0, 0), g3d_v3(0, -1, 0));
    g3d_image dark, mask;
    g3d_image_create(&dark, RES, RES, 3);
    g3d_image_create(&mask, RES, RES, 1);
    for (size_t k = 0; k < g3d_image_size(&dark); k++) dark.data[k] = 0.03f;
    for (int k = 0; k < RES * RES; k++) mask.data[k] = (k % RES) < RES / 2;
    const g3d_train_view whole = {cam, &dark, NULL}, half = {cam, &dark, &mask};
    g3d_train_params p;
    g3d_train_params_default(&p, 150);
    p.extent = 2.0;
    p.densify = 0;
    double a[3], right[3];
    for (int run = 0; run < 3; run++) {
        g3d_gaussians g;
        CHECK_OK(g3d_gaussians_clone(&g, &wall));
        p.coverage_weight = run == 0 ? 0.0 : 0.5;
        CHECK_OK(g3d_train(&g, run == 2 ? &half : &whole, 1, &p, NULL));
        a[run] = mean_alpha(&g, &cam, 0, RES / 2);
        right[run] = mean_alpha(&g, &cam, 3 * RES / 4, RES);
        g3d_gaussians_free(&g);
    }
    double start = mean_alpha(&wall, &cam, 3 * RES / 4, RES);
    /* the masked quarter still moves a little: SSIM windows and growing neighbours reach it */
    printf("       mean opacity of the dark wall's left half: %.3f without the coverage term, %.3f with it, %.3f with "
           "the right half masked; right quarter %.3f, %.3f, %.3f (started at %.3f)\n", a[0], a[1], a[2], right[0],
           right[1], right[2], start);
    CHECK(a[0] < 0.5 && right[0] < 0.5);
    CHECK(a[1] > 0.9 && right[1] > 0.9);
    CHECK(a[2] > 0.9);
    CHECK(right[2] < right[1] - 0.04);
    g3d_image_free(&dark);
    g3d_image_free(&mask);
    g3d_gaussians_free(&wall);
}

int main(void)
{
    RUN(fits_and_is_deterministic);
    RUN(coarse_to_fine);
    RUN(first_view_beat);
    RUN(coverage_term_keeps_dark_surfaces_opaque);
    return test_summary();
}
