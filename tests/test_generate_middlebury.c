/* test_generate_middlebury.c - `gen3d generate` end to end on the default input (Middlebury
 * 2014 Motorcycle, left view + ground-truth depth), judged where ground truth exists: the
 * trained scene rendered at the real right camera, against the real right image, on the pixels
 * the left view also sees. The floor below is our regression bound: the figure reached when it
 * was set, less a margin for thread-count and platform differences. */
#include "gen3d/frame.h"
#include "gen3d/loss.h"
#include "gen3d/ply.h"
#include "gen3d/raster.h"
#include "testutil.h"

#include <stdlib.h>
#include <sys/wait.h>

#define MAX_SIDE 256
#define PSNR_FLOOR 25.0  /* 27.1 dB when set */

/* Pixels of the right view that the left view's ground-truth depth reaches first (z-buffered
 * nearest-pixel forward warp): the co-visible region, where the right image is predictable. */
static void covisible(const g3d_frame *f, g3d_image *m, size_t *count)
{
    int w = f->heldout.w, h = f->heldout.h;
    float *zbuf = malloc(sizeof(float) * (size_t)w * h);
    g3d_image_create(m, w, h, 1);
    for (size_t i = 0; i < (size_t)w * h; i++) zbuf[i] = INFINITY;
    for (int y = 0; y < f->rgb.h; y++)
        for (int x = 0; x < f->rgb.w; x++) {
            float z = *g3d_image_px(&f->depth, x, y);
            if (!(z > 0)) continue;
            double u, v, zz;
            if (!g3d_camera_project(&f->heldout_cam, g3d_camera_unproject(&f->cam, x, y, z), &u, &v, &zz)) continue;
            int iu = (int)lround(u), iv = (int)lround(v);
            if (iu < 0 || iv < 0 || iu >= w || iv >= h) continue;
            size_t k = (size_t)iv * w + iu;
            if (zz < zbuf[k]) zbuf[k] = (float)zz;
        }
    *count = 0;
    for (size_t i = 0; i < (size_t)w * h; i++) *count += m->data[i] = isfinite(zbuf[i]);
    free(zbuf);
}

TEST(generate_at_the_real_right_view)
{
    const char *gen3d = getenv("GEN3D");
    const char *mb = test_shared("testdata/middlebury2014_motorcycle_skimage");
    const char *out = test_tmp("generate_middlebury");
    CHECK(gen3d != NULL);
    if (!gen3d) return;
    char cmd[4096];
    snprintf(cmd, sizeof cmd,
             "'%s' generate --default-input '%s' --max-side %d --steps 4 --extra 4 --iters 400 --sh-degree 1 "
             "--no-video -t 2 -q -o '%s' > '%s.log' 2>&1", gen3d, mb, MAX_SIDE, out, out);
    int st = system(cmd);
    CHECK(st != -1 && WIFEXITED(st) && WEXITSTATUS(st) == 0);

    g3d_frame f;
    CHECK_OK(g3d_frame_load_middlebury(mb, &f));
    CHECK_OK(g3d_frame_limit_size(&f, MAX_SIDE));
    char ply[4096];
    snprintf(ply, sizeof ply, "%s/scene.ply", out);
    g3d_gaussians g;
    CHECK_OK(g3d_ply_read_gaussians(ply, &g));
    if (!f.heldout.data || !g.n) return;

    size_t n_cov;
    g3d_image cov;
    covisible(&f, &cov, &n_cov);
    g3d_image img;
    g3d_image_create(&img, f.heldout.w, f.heldout.h, 3);
    g3d_raster_ws *ws;
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    CHECK_OK(g3d_raster_ws_create(&ws));
    CHECK_OK(g3d_raster_fwd(ws, &g, &f.heldout_cam, &s, img.data, NULL, NULL, NULL));
    double psnr, still;
    CHECK_OK(g3d_psnr(&img, &f.heldout, &cov, &psnr));
    /* the left image itself, shown as if it were the right one: what ignoring parallax gives */
    CHECK_OK(g3d_psnr(&f.rgb, &f.heldout, &cov, &still));
    printf("       Middlebury right view, %dx%d, %.0f%% co-visible: generate %.2f dB (left image as is: %.2f dB)\n",
           img.w, img.h, 100.0 * n_cov / ((double)img.w * img.h), psnr, still);
    CHECK(psnr >= PSNR_FLOOR);
    CHECK(psnr > still + 2.0);
    g3d_raster_ws_free(ws);
    g3d_image_free(&img);
    g3d_image_free(&cov);
    g3d_gaussians_free(&g);
    g3d_frame_free(&f);
}

int main(void)
{
    RUN(generate_at_the_real_right_view);
    return test_summary();
}
