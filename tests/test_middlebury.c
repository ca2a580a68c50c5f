/* Real data proves the camera conventions: lift the Middlebury left view with its ground-truth
 * depth, project it into the real right camera and compare with the real right image. */
#include "testutil.h"
#include "gen3d/frame.h"

static double grey(const g3d_image *img, int x, int y)
{
    const float *p = g3d_image_px(img, x, y);
    return 255.0 * (0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2]);
}

/* Forward-warps src (with depth) into cam_dst with a z-buffer (nearest pixel) and returns the
 * mean absolute grey error against dst over the co-visible pixels; *covered gets their count. */
static double warp_error(const g3d_frame *f, const g3d_camera *cam_dst, size_t *covered)
{
    int w = f->heldout.w, h = f->heldout.h;
    float *zbuf = malloc(sizeof(float) * (size_t)w * h);
    double *val = malloc(sizeof(double) * (size_t)w * h);
    for (size_t i = 0; i < (size_t)w * h; i++) zbuf[i] = INFINITY;
    for (int y = 0; y < f->rgb.h; y++)
        for (int x = 0; x < f->rgb.w; x++) {
            float z = *g3d_image_px(&f->depth, x, y);
            if (z <= 0) continue;
            g3d_vec3 p = g3d_camera_unproject(&f->cam, x, y, z);
            double u, v, zz;
            if (!g3d_camera_project(cam_dst, p, &u, &v, &zz)) continue;
            int iu = (int)lround(u), iv = (int)lround(v);
            if (iu < 0 || iv < 0 || iu >= w || iv >= h) continue;
            size_t k = (size_t)iv * w + iu;
            if (zz < zbuf[k]) { zbuf[k] = (float)zz; val[k] = grey(&f->rgb, x, y); }
        }
    double sum = 0;
    size_t n = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t k = (size_t)y * w + x;
            if (!isfinite(zbuf[k])) continue;
            sum += fabs(val[k] - grey(&f->heldout, x, y));
            n++;
        }
    free(zbuf);
    free(val);
    *covered = n;
    return n ? sum / n : 1e9;
}

TEST(reproject_into_real_right_view)
{
    g3d_frame f;
    CHECK_OK(g3d_frame_load_middlebury(test_default_input(), &f));
    if (!f.rgb.data) return;
    CHECK(f.rgb.w == 741 && f.rgb.h == 500 && f.heldout.w == 741);
    /* Depth range from the README: 2.11 .. 5.02 m. */
    float lo = 1e9f, hi = 0;
    for (size_t i = 0; i < g3d_image_size(&f.depth); i++)
        if (f.depth.data[i] > 0) { lo = fminf(lo, f.depth.data[i]); hi = fmaxf(hi, f.depth.data[i]); }
    CHECK(lo > 2.0f && lo < 2.2f && hi > 4.9f && hi < 5.1f);

    size_t covered;
    double err = warp_error(&f, &f.heldout_cam, &covered);
    printf("  mean abs grey error at the real right view: %.2f over %zu pixels\n", err, covered);
    CHECK(err < 10.0);
    CHECK(covered > (size_t)(0.7 * 741 * 500));

    /* The same with the baseline's sign flipped must be far worse: the test can fail. */
    g3d_camera wrong = f.heldout_cam;
    wrong.c2w.m[0][3] = -wrong.c2w.m[0][3];
    double err_wrong = warp_error(&f, &wrong, &covered);
    printf("  with the wrong sign: %.2f\n", err_wrong);
    CHECK(err_wrong > 3 * err);
    g3d_frame_free(&f);
}

int main(void)
{
    RUN(reproject_into_real_right_view);
    return test_summary();
}
