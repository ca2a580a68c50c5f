/* heldout.h - the measure of the real held-out-view tests (test_generate_middlebury,
 * test_generate_aloe): `gen3d generate` runs on the left view of a stereo pair with ground
 * truth, and its scene is rendered at the real right camera and scored against the real right
 * image on the pixels the left view also sees. */
#ifndef G3D_TEST_HELDOUT_H
#define G3D_TEST_HELDOUT_H

#include "gen3d/eval.h"
#include "gen3d/frame.h"
#include "gen3d/loss.h"
#include "gen3d/ply.h"
#include "gen3d/raster.h"
#include "testutil.h"

#include <sys/wait.h>

/* What one scene scores at f's held-out camera, each on the co-visible pixels. */
typedef struct heldout_score {
    double scene;      /* the scene rendered there */
    double still;      /* the left image as if it were the right one: ignoring parallax */
    double warp;       /* the left image moved with its ground-truth depth, nearest pixel */
    double covisible;  /* the co-visible share of the right view's pixels */
} heldout_score;

/* Runs a shell command; a failed check unless it exits with status 0. */
static inline int heldout_system(const char *cmd)
{
    int st = system(cmd);
    int ok = st != -1 && WIFEXITED(st) && WEXITSTATUS(st) == 0;
    CHECK_MSG(ok, "failed: %s", cmd);
    return ok;
}

/* Scores the scene in `ply` at f's held-out view (f at the size the scene was made at). The
 * co-visible pixels are those the left view's ground-truth depth reaches (eval.h). */
static inline int heldout_score_scene(const g3d_frame *f, const char *ply, heldout_score *s)
{
    g3d_gaussians g;
    memset(s, 0, sizeof *s);
    CHECK_OK(g3d_ply_read_gaussians(ply, &g));
    if (!f->heldout.data || !g.n) return 0;
    g3d_eval_view left = {NULL, f->cam, f->rgb, f->depth, {0}}, right = {NULL, f->heldout_cam, f->heldout, {0}, {0}};
    g3d_image cov, img, warp = {0}, warp_depth = {0};
    g3d_covis_kind kind;
    CHECK_OK(g3d_eval_covisible(&left, &right, &cov, &kind));
    CHECK(kind == G3D_COVIS_INPUT_WARP);
    size_t n_cov = 0;
    for (size_t i = 0; i < g3d_image_size(&cov); i++) n_cov += cov.data[i] > 0.5f;
    s->covisible = (double)n_cov / g3d_image_size(&cov);
    g3d_image_create(&img, f->heldout.w, f->heldout.h, 3);
    g3d_raster_ws *ws;
    g3d_raster_params rp;
    g3d_raster_params_default(&rp);
    CHECK_OK(g3d_raster_ws_create(&ws));
    CHECK_OK(g3d_raster_fwd(ws, &g, &f->heldout_cam, &rp, img.data, NULL, NULL, NULL));
    CHECK_OK(g3d_psnr(&img, &f->heldout, &cov, &s->scene));
    CHECK_OK(g3d_psnr(&f->rgb, &f->heldout, &cov, &s->still));
    CHECK_OK(g3d_eval_forward_warp(&f->cam, &f->rgb, &f->depth, &f->heldout_cam, &warp, &warp_depth));
    CHECK_OK(g3d_psnr(&warp, &f->heldout, &cov, &s->warp));
    g3d_raster_ws_free(ws);
    g3d_image_free(&img);
    g3d_image_free(&warp);
    g3d_image_free(&warp_depth);
    g3d_image_free(&cov);
    g3d_gaussians_free(&g);
    return 1;
}

#endif /* G3D_TEST_HELDOUT_H */
