/* test_eval.c - scoring scenes against ground-truth views: the SSIM against scikit-image's
 * definition (tests/fixtures/make_eval_ssim_fixture.py), a scene scored against its own exact
 * renders (PSNR infinite, SSIM 1, depth error 0) and against shifted cameras (worse with the
 * shift), co-visibility and the baselines on the ray-traced procedural room, a Middlebury-style
 * calibrated pair built from the room, the default input, and refusals of bad view sets. */
#include "gen3d/cameras_json.h"
#include "gen3d/depthio.h"
#include "gen3d/eval.h"
#include "gen3d/imageio.h"
#include "gen3d/init.h"
#include "gen3d/loss.h"
#include "gen3d/npy.h"
#include "gen3d/procscene.h"
#include "gen3d/raster.h"
#include "gen3d/render.h"
#include "testutil.h"

#include <stdlib.h>

#define W 128
#define H 96
#define NVIEWS 3  /* the default camera (the input) and two cameras on the room's arc */

static g3d_camera view_camera(int i)
{
    return i == 0 ? g3d_procscene_default_camera(W, H) : g3d_procscene_arc_camera(i == 1 ? 1 : 3, 5, W, H);
}

/* A room made of opaque Gaussians at the ground-truth surface points. */
static void room_scene(g3d_gaussians *g)
{
    g3d_points pts;
    CHECK_OK(g3d_procscene_points(3, W, H, 2, &pts));
    float *rgb = malloc(sizeof(float) * 3 * (size_t)pts.n);
    for (int64_t i = 0; i < 3 * pts.n; i++) rgb[i] = pts.rgb[i] / 255.0f;
    CHECK_OK(g3d_gaussians_init_from_points(g, pts.xyz, rgb, pts.n, 0));
    for (int64_t i = 0; i < g->n; i++) g->opacity_logits[i] = 4.0f;
    free(rgb);
    g3d_points_free(&pts);
}

typedef struct frame_out {
    const char *dir;
    g3d_camera_list *list;
} frame_out;

static g3d_status save_frame(void *user, int i, const g3d_camera *cam, const g3d_image *rgb, const g3d_image *depth)
{
    frame_out *o = user;
    char name[64], *p;
    snprintf(name, sizeof name, "rgb_%d.png", i);
    p = g3d_path_join(o->dir, name);
    G3D_TRY(g3d_image_save_png(p, rgb, 8));
    free(p);
    G3D_TRY(g3d_camera_list_set_name(o->list, i, name));
    snprintf(name, sizeof name, "depth_%d.npy", i);
    p = g3d_path_join(o->dir, name);
    G3D_TRY(g3d_depth_save(p, depth));
    free(p);
    o->list->cams[i] = *cam;
    return g3d_camera_list_set_depth(o->list, i, name);
}

/* dir/transforms.json with the scene's own renders (8-bit PNG, depth .npy) at the view
 * cameras; then the scored cameras moved sideways by `shift` metres in the file. */
static void write_renders(const g3d_gaussians *g, const char *dir, double shift)
{
    g3d_camera cams[NVIEWS];
    for (int i = 0; i < NVIEWS; i++) cams[i] = view_camera(i);
    g3d_camera_list l;
    CHECK_OK(g3d_camera_list_create(&l, NVIEWS));
    g3d_remove_tree(dir);
    CHECK_OK(g3d_mkdirs(dir));
    frame_out o = {dir, &l};
    g3d_render_params ro;
    g3d_render_params_default(&ro);
    ro.depth = 1;
    CHECK_OK(g3d_render_path(g, cams, NVIEWS, &ro, save_frame, &o));
    for (int i = 1; i < NVIEWS; i++) l.cams[i].c2w.m[0][3] += shift;
    char *p = g3d_path_join(dir, "transforms.json");
    CHECK_OK(g3d_transforms_json_write(p, &l));
    free(p);
    g3d_camera_list_free(&l);
}

static g3d_status score(const g3d_gaussians *g, const char *path, g3d_eval_report *r)
{
    g3d_eval_views v;
    g3d_eval_params p;
    g3d_eval_params_default(&p);
    G3D_TRY(g3d_eval_views_load(path, NULL, &v));
    g3d_status rc = g3d_eval_run(g, &v, &p, r);
    g3d_eval_views_free(&v);
    return rc;
}

TEST(ssim_matches_reference)
{
    const char *fx = G3D_SOURCE_DIR "/tests/fixtures/eval_ssim_ref.npz";
    g3d_array a, b, m, ref;
    CHECK_OK(g3d_npz_load(fx, "a", &a));
    CHECK_OK(g3d_npz_load(fx, "b", &b));
    CHECK_OK(g3d_npz_load(fx, "mask", &m));
    CHECK_OK(g3d_npz_load(fx, "ssim", &ref));
    const int h = (int)a.shape[0], w = (int)a.shape[1];
    g3d_image ia = {w, h, 3, a.data}, ib = {w, h, 3, b.data}, im = {w, h, 1, m.data};
    double s, sm, self;
    CHECK_OK(g3d_ssim(&ia, &ib, NULL, &s));
    CHECK_OK(g3d_ssim(&ia, &ib, &im, &sm));
    CHECK_OK(g3d_ssim(&ia, &ia, NULL, &self));
    /* the fixture holds float64 values, the loader converts to float32 */
    printf("       SSIM %.9f (scikit-image %.9f), masked %.9f (%.9f)\n", s, (double)ref.data[0], sm, (double)ref.data[1]);
    CHECK_NEAR(s, ref.data[0], 1e-6);
    CHECK_NEAR(sm, ref.data[1], 1e-6);
    CHECK(self == 1.0);
    double s2;
    g3d_image tiny = {10, 10, 3, a.data};
    CHECK_FAILS(g3d_ssim(&tiny, &tiny, NULL, &s2));
    g3d_array_free(&a); g3d_array_free(&b); g3d_array_free(&m); g3d_array_free(&ref);
}

TEST(forward_warp_onto_itself_is_exact)
{
    g3d_camera cam = g3d_procscene_default_camera(W, H);
    g3d_image rgb, depth, wr, wd;
    CHECK_OK(g3d_procscene_render(&cam, &rgb, &depth, NULL));
    CHECK_OK(g3d_eval_forward_warp(&cam, &rgb, &depth, &cam, &wr, &wd));
    CHECK(memcmp(wr.data, rgb.data, g3d_image_size(&rgb) * sizeof(float)) == 0);
    CHECK(memcmp(wd.data, depth.data, g3d_image_size(&depth) * sizeof(float)) == 0);
    g3d_image_free(&rgb); g3d_image_free(&depth); g3d_image_free(&wr); g3d_image_free(&wd);
}

TEST(perfect_scene_and_shifted_cameras)
{
    g3d_gaussians g;
    room_scene(&g);
    const double shifts[3] = {0.0, 0.03, 0.08};
    double prev_psnr = INFINITY, prev_ssim = 1.0;
    for (int k = 0; k < 3; k++) {
        char name[64];
        snprintf(name, sizeof name, "eval_room_%d", k);
        const char *dir = test_tmp(name);
        write_renders(&g, dir, shifts[k]);
        char *path = g3d_path_join(dir, "transforms.json");
        g3d_eval_report r;
        CHECK_OK(score(&g, path, &r));
        free(path);
        if (!r.n) continue;
        CHECK(r.n == NVIEWS - 1);
        CHECK(r.scored[G3D_EVAL_SCENE] && r.scored[G3D_EVAL_INPUT_IMAGE] && r.scored[G3D_EVAL_FORWARD_WARP]);
        const g3d_eval_metrics *a = &r.mean_all[G3D_EVAL_SCENE], *c = &r.mean_covisible[G3D_EVAL_SCENE];
        printf("       shift %.2f m: scene PSNR %.2f dB SSIM %.4f depth abs rel %.2e RMSE %.4f m coverage %.3f; "
               "co-visible (%.0f%%) PSNR %.2f dB\n", shifts[k], a->psnr, a->ssim, a->depth_abs_rel, a->depth_rmse,
               a->depth_coverage, 100 * r.covis_fraction[0], c->psnr);
        for (int i = 0; i < r.n; i++) CHECK(r.covis_kind[i] == G3D_COVIS_VIEW_DEPTH);
        if (k == 0) {
            /* the scene's own renders: exact */
            for (int i = 0; i < r.n; i++) {
                const g3d_eval_metrics *m = &r.all[G3D_EVAL_SCENE][i], *mc = &r.covisible[G3D_EVAL_SCENE][i];
                CHECK(m->pixels == W * H && isinf(m->psnr) && m->psnr > 0 && m->mse == 0);
                CHECK(m->ssim == 1.0 && m->depth_abs_rel == 0 && m->depth_rmse == 0 && m->depth_coverage == 1.0);
                CHECK(mc->pixels > 0 && mc->pixels < W * H && isinf(mc->psnr) && mc->ssim == 1.0 && mc->depth_rmse == 0);
                /* the baselines are not exact */
                CHECK(isfinite(r.all[G3D_EVAL_INPUT_IMAGE][i].psnr) && isfinite(r.all[G3D_EVAL_FORWARD_WARP][i].psnr));
            }
            CHECK(isinf(a->psnr) && a->ssim == 1.0);
        } else {
            CHECK(isfinite(a->psnr) && a->psnr < prev_psnr - 1.0);
            CHECK(a->ssim < prev_ssim);
            CHECK(a->depth_rmse > 0 && isfinite(c->psnr));
        }
        prev_psnr = a->psnr;
        prev_ssim = a->ssim;
        g3d_eval_report_free(&r);
    }
    g3d_gaussians_free(&g);
}

/* The ray-traced room with exact depth: where co-visibility comes from, what the baselines
 * score, and that the depth test agrees with the forward warp of the input. */
TEST(room_covisibility_and_baselines)
{
    g3d_eval_views v = {0};
    v.n = NVIEWS - 1;
    v.views = calloc((size_t)v.n, sizeof *v.views);
    v.kind = "camera file";
    for (int i = 0; i < NVIEWS; i++) {
        g3d_eval_view *d = i == 0 ? &v.input : &v.views[i - 1];
        d->cam = view_camera(i);
        d->name = g3d_path_join("", i == 0 ? "input" : "view");
        CHECK_OK(g3d_procscene_render(&d->cam, &d->rgb, &d->depth, NULL));
    }
    g3d_eval_params p;
    g3d_eval_params_default(&p);
    p.sheets_dir = test_tmp("eval_sheets");
    g3d_remove_tree(p.sheets_dir);
    CHECK_OK(g3d_mkdirs(p.sheets_dir));
    g3d_gaussians g;
    room_scene(&g);
    g3d_eval_report r;
    CHECK_OK(g3d_eval_run(&g, &v, &p, &r));
    for (int i = 0; i < r.n; i++) {
        const double fw = r.covisible[G3D_EVAL_FORWARD_WARP][i].psnr, ii = r.covisible[G3D_EVAL_INPUT_IMAGE][i].psnr;
        const double sc = r.covisible[G3D_EVAL_SCENE][i].psnr, sa = r.all[G3D_EVAL_SCENE][i].psnr;
        printf("       view %d: %.0f%% co-visible; co-visible PSNR: scene %.2f dB, forward warp %.2f dB, input image "
               "%.2f dB; scene on all pixels %.2f dB\n", i, 100 * r.covis_fraction[i], sc, fw, ii, sa);
        CHECK(r.covis_kind[i] == G3D_COVIS_VIEW_DEPTH);
        CHECK(r.covis_fraction[i] > 0.4 && r.covis_fraction[i] < 0.99);
        CHECK(fw > ii + 3.0);      /* moving the pixels with their depth beats not moving them */
        CHECK(sc > ii);
        CHECK(r.all[G3D_EVAL_FORWARD_WARP][i].depth_coverage < 1.0);
        CHECK(r.covisible[G3D_EVAL_FORWARD_WARP][i].depth_abs_rel < 0.01);
        char *sheet = r.sheets[i] ? g3d_path_join(p.sheets_dir, r.sheets[i]) : NULL;
        g3d_image img = {0};
        CHECK(sheet && g3d_image_load(sheet, 3, &img) == G3D_OK && img.w == 3 * W + 8 && img.h == 3 * H + 8);
        g3d_image_free(&img);
        free(sheet);

        /* the two depth rules agree: the forward warp of the input depth reaches nearly the
         * same pixels as the depth test of the view's own depth */
        g3d_image m1, m2;
        g3d_covis_kind k1, k2;
        CHECK_OK(g3d_eval_covisible(&v.input, &v.views[i], &m1, &k1));
        g3d_image keep = v.views[i].depth;
        v.views[i].depth = (g3d_image){0};
        CHECK_OK(g3d_eval_covisible(&v.input, &v.views[i], &m2, &k2));
        v.views[i].depth = keep;
        CHECK(k1 == G3D_COVIS_VIEW_DEPTH && k2 == G3D_COVIS_INPUT_WARP);
        int64_t both = 0, either = 0;
        for (size_t k = 0; k < g3d_image_size(&m1); k++) {
            both += m1.data[k] > 0.5f && m2.data[k] > 0.5f;
            either += m1.data[k] > 0.5f || m2.data[k] > 0.5f;
        }
        printf("       depth test vs forward warp: IoU %.3f\n", (double)both / either);
        CHECK((double)both / either > 0.85);
        g3d_image_free(&m1);
        g3d_image_free(&m2);
    }
    g3d_eval_report_free(&r);

    /* without input depth, co-visibility comes from the scene's alpha */
    g3d_image_free(&v.input.depth);
    CHECK_OK(g3d_eval_run(&g, &v, &p, &r));
    CHECK(r.scored[G3D_EVAL_INPUT_IMAGE] && !r.scored[G3D_EVAL_FORWARD_WARP]);
    for (int i = 0; i < r.n; i++) CHECK(r.covis_kind[i] == G3D_COVIS_SCENE_ALPHA && r.covis_fraction[i] > 0.5);
    g3d_eval_report_free(&r);
    /* and without a scene there is nothing to find it from */
    CHECK_OK(g3d_eval_run(NULL, &v, &p, &r));
    for (int i = 0; i < r.n; i++) CHECK(r.covis_kind[i] == G3D_COVIS_NONE && r.covisible[G3D_EVAL_INPUT_IMAGE][i].pixels == 0);
    g3d_eval_report_free(&r);
    g3d_eval_views_free(&v);
    g3d_gaussians_free(&g);
}

/* Writes a one-channel PFM (rows bottom-to-top, little-endian). */
static void write_pfm(const char *path, const g3d_image *img)
{
    FILE *f = fopen(path, "wb");
    fprintf(f, "Pf\n%d %d\n-1.0\n", img->w, img->h);
    for (int y = img->h - 1; y >= 0; y--) fwrite(g3d_image_px(img, 0, y), sizeof(float), (size_t)img->w, f);
    fclose(f);
}

/* A Middlebury-style calibrated pair (calib.txt, im0/im1, disp0/disp1 .pfm) made from the room. */
TEST(calibrated_pair)
{
    const char *dir = test_tmp("eval_pair");
    g3d_remove_tree(dir);
    CHECK_OK(g3d_mkdirs(dir));
    const double f = 110, cx0 = 60.5, cy = 47.5, doffs = 7.25, base_mm = 150;
    g3d_camera cam[2];
    g3d_image rgb[2], depth[2];
    for (int s = 0; s < 2; s++) {
        cam[s].K = g3d_intrinsics_make(f, f, cx0 + s * doffs, cy, W, H);
        cam[s].c2w = g3d_mat4_identity();
        cam[s].c2w.m[0][3] = s * base_mm / 1000;
        CHECK_OK(g3d_procscene_render(&cam[s], &rgb[s], &depth[s], NULL));
        char name[32], *p;
        snprintf(name, sizeof name, "im%d.png", s);
        CHECK_OK(g3d_image_save_png(p = g3d_path_join(dir, name), &rgb[s], 8));
        free(p);
        g3d_image disp;
        g3d_image_clone(&disp, &depth[s]);
        for (size_t i = 0; i < g3d_image_size(&disp); i++)
            disp.data[i] = disp.data[i] > 0 ? (float)(base_mm / 1000 * f / disp.data[i] - doffs) : INFINITY;
        snprintf(name, sizeof name, "disp%d.pfm", s);
        write_pfm(p = g3d_path_join(dir, name), &disp);
        free(p);
        g3d_image_free(&disp);
    }
    char text[512], *calib = g3d_path_join(dir, "calib.txt");
    snprintf(text, sizeof text, "cam0=[%g 0 %g; 0 %g %g; 0 0 1]\ncam1=[%g 0 %g; 0 %g %g; 0 0 1]\ndoffs=%g\nbaseline=%g\n"
             "width=%d\nheight=%d\nndisp=64\n", f, cx0, f, cy, f, cx0 + doffs, f, cy, doffs, base_mm, W, H);
    CHECK_OK(g3d_write_file_atomic(calib, text, strlen(text)));
    g3d_eval_views v;
    CHECK_OK(g3d_eval_views_load(dir, NULL, &v));
    if (v.n == 1) {
        CHECK(!strcmp(v.kind, "middlebury") && !strcmp(v.input.name, "im0.png") && !strcmp(v.views[0].name, "im1.png"));
        CHECK(v.views[0].cam.K.cx == cx0 + doffs && v.views[0].cam.c2w.m[0][3] == base_mm / 1000);
        double worst = 0;
        for (size_t i = 0; i < g3d_image_size(&depth[1]); i++)
            worst = fmax(worst, fabs(v.views[0].depth.data[i] - depth[1].data[i]) / depth[1].data[i]);
        printf("       depth from disparity: worst relative error %.1e\n", worst);
        CHECK(worst < 1e-5);
        g3d_eval_report r;
        g3d_eval_params p;
        g3d_eval_params_default(&p);
        CHECK_OK(g3d_eval_run(NULL, &v, &p, &r));
        CHECK(r.n == 1 && r.covis_kind[0] == G3D_COVIS_VIEW_DEPTH && r.covis_fraction[0] > 0.8);
        g3d_eval_report_free(&r);
        g3d_eval_views_free(&v);
    }
    /* a NaN disparity is corrupt ground truth */
    g3d_image bad;
    g3d_image_clone(&bad, &depth[1]);
    bad.data[17] = NAN;
    char *p = g3d_path_join(dir, "disp1.pfm");
    write_pfm(p, &bad);
    CHECK_FAILS(g3d_eval_views_load(dir, NULL, &v));
    free(p);
    free(calib);
    g3d_image_free(&bad);
    for (int s = 0; s < 2; s++) { g3d_image_free(&rgb[s]); g3d_image_free(&depth[s]); }
}

/* Bad view sets: one line naming the file, nothing returned. */
TEST(refusals)
{
    g3d_gaussians g;
    room_scene(&g);
    const char *dir = test_tmp("eval_bad");
    write_renders(&g, dir, 0.0);
    char *json = g3d_path_join(dir, "transforms.json"), *img = g3d_path_join(dir, "rgb_1.png");
    char *dep = g3d_path_join(dir, "depth_2.npy");
    g3d_eval_views v;
    g3d_eval_views_params vp;
    g3d_eval_views_params_default(&vp);
    vp.input_view = 7;
    CHECK_FAILS(g3d_eval_views_load(json, &vp, &v));
    /* an image of another size than its camera */
    g3d_image small;
    g3d_image_create(&small, W / 2, H / 2, 3);
    CHECK_OK(g3d_image_save_png(img, &small, 8));
    CHECK_FAILS(g3d_eval_views_load(json, NULL, &v));
    CHECK(strstr(g3d_error_message(), "rgb_1.png") && strstr(g3d_error_message(), "64x48"));
    /* a missing image */
    remove(img);
    CHECK_FAILS(g3d_eval_views_load(json, NULL, &v));
    CHECK(strstr(g3d_error_message(), "rgb_1.png") != NULL);
    write_renders(&g, dir, 0.0);
    /* NaN in ground-truth depth */
    g3d_image d;
    CHECK_OK(g3d_depth_load(dep, 0, &d));
    d.data[100] = NAN;
    CHECK_OK(g3d_depth_save(dep, &d));
    CHECK_FAILS(g3d_eval_views_load(json, NULL, &v));
    CHECK(strstr(g3d_error_message(), "depth_2.npy") && strstr(g3d_error_message(), "NaN"));
    CHECK(v.n == 0 && v.views == NULL);
    /* no scene and no input view: nothing to score */
    write_renders(&g, dir, 0.0);
    vp.input_view = -2;
    CHECK_OK(g3d_eval_views_load(json, &vp, &v));
    g3d_eval_report r;
    g3d_eval_params p;
    g3d_eval_params_default(&p);
    CHECK_FAILS(g3d_eval_run(NULL, &v, &p, &r));
    g3d_eval_views_free(&v);
    CHECK_FAILS(g3d_eval_views_load(test_tmp("no-such-views"), NULL, &v));
    g3d_gaussians none;
    CHECK_FAILS(g3d_gaussians_load(test_tmp("no-such-scene.ply"), &none));
    g3d_image_free(&d);
    g3d_image_free(&small);
    free(json);
    free(img);
    free(dep);
    g3d_gaussians_free(&g);
}

/* The default input (scripts/fetch-default-input.sh): left view = input, right view scored. */
TEST(default_input_views)
{
    const char *dir = test_default_input();
    g3d_eval_views v;
    g3d_eval_views_params vp;
    g3d_eval_views_params_default(&vp);
    vp.max_side = 256;
    CHECK_OK(g3d_eval_views_load(dir, &vp, &v));
    if (v.n != 1) return;
    CHECK(!strcmp(v.input.name, "motorcycle_left.png") && !strcmp(v.views[0].name, "motorcycle_right.png"));
    CHECK(v.views[0].cam.K.width == 256 && v.views[0].cam.K.height == 173 && v.input.depth.w == 256);
    CHECK_NEAR(v.views[0].cam.c2w.m[0][3], 0.193001, 1e-12);
    g3d_eval_report r;
    g3d_eval_params p;
    g3d_eval_params_default(&p);
    CHECK_OK(g3d_eval_run(NULL, &v, &p, &r));
    if (r.n == 1) {
        printf("       Middlebury right view at 256 px: %.1f%% co-visible; co-visible PSNR: forward warp %.2f dB, "
               "input image %.2f dB\n", 100 * r.covis_fraction[0], r.covisible[G3D_EVAL_FORWARD_WARP][0].psnr,
               r.covisible[G3D_EVAL_INPUT_IMAGE][0].psnr);
        CHECK(r.covis_kind[0] == G3D_COVIS_INPUT_WARP && r.covis_fraction[0] > 0.7);
        CHECK(r.covisible[G3D_EVAL_FORWARD_WARP][0].psnr > r.covisible[G3D_EVAL_INPUT_IMAGE][0].psnr + 5.0);
    }
    g3d_eval_report_free(&r);
    g3d_eval_views_free(&v);
}

int main(void)
{
    RUN(ssim_matches_reference);
    RUN(forward_warp_onto_itself_is_exact);
    RUN(perfect_scene_and_shifted_cameras);
    RUN(room_covisibility_and_baselines);
    RUN(calibrated_pair);
    RUN(refusals);
    RUN(default_input_views);
    return test_summary();
}
