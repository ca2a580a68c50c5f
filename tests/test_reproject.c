/* Lifting and z-buffered reprojection: self-consistency, real stereo (Middlebury), real
 * camera motion with ground-truth poses (ICL-NUIM), and parallax on the procedural room. */
#include "testutil.h"
#include "gen3d/cloud.h"
#include "gen3d/depthio.h"
#include "gen3d/frame.h"
#include "gen3d/imageio.h"
#include "gen3d/loss.h"
#include "gen3d/procscene.h"

static double grey(const float *p) { return 255.0 * (0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2]); }

/* Mean absolute grey difference over mask > 0.5; *n gets the pixel count. */
static double grey_error(const g3d_image *a, const g3d_image *b, const g3d_image *mask, size_t *n)
{
    double s = 0;
    *n = 0;
    for (size_t i = 0; i < (size_t)a->w * a->h; i++) {
        if (mask->data[i] < 0.5f) continue;
        s += fabs(grey(a->data + 3 * i) - grey(b->data + 3 * i));
        (*n)++;
    }
    return *n ? s / *n : 1e9;
}

static double hole_fraction(const g3d_image *mask)
{
    size_t holes = 0;
    for (size_t i = 0; i < g3d_image_size(mask); i++) holes += mask->data[i] < 0.5f;
    return (double)holes / g3d_image_size(mask);
}

TEST(self_reprojection)
{
    g3d_camera cam = g3d_procscene_default_camera(200, 150);
    g3d_image rgb, depth, out, outd, mask;
    g3d_cloud c;
    CHECK_OK(g3d_procscene_render(&cam, &rgb, &depth, NULL));
    CHECK_OK(g3d_cloud_init(&c));
    int64_t added;
    CHECK_OK(g3d_cloud_lift(&c, &rgb, &depth, &cam, NULL, 0, &added));
    CHECK(added == 200 * 150);
    CHECK_OK(g3d_cloud_render(&c, &cam, NULL, &out, &outd, &mask));
    double psnr;
    CHECK_OK(g3d_psnr(&out, &rgb, &mask, &psnr));
    printf("  self-reprojection PSNR %.1f dB, holes %.3f %%\n", psnr, 100 * hole_fraction(&mask));
    CHECK(psnr >= 40.0);
    CHECK(hole_fraction(&mask) == 0.0);
    double worst = 0;
    for (size_t i = 0; i < g3d_image_size(&depth); i++) worst = fmax(worst, fabs(outd.data[i] - depth.data[i]) / depth.data[i]);
    CHECK(worst < 1e-5);
    g3d_image_free(&rgb); g3d_image_free(&depth); g3d_image_free(&out); g3d_image_free(&outd); g3d_image_free(&mask);
    g3d_cloud_free(&c);
}

TEST(parallax_on_procedural_room)
{
    /* Move sideways and forward: the dense surfaces stay hole-free, the regions hidden behind
     * the near objects in the source view become holes, and what is filled matches the truth. */
    g3d_camera src = g3d_procscene_default_camera(256, 192);
    g3d_camera dst = src;
    dst.c2w = g3d_mat4_look_at(g3d_v3(0.45, -0.1, 0.6), g3d_v3(0.2, 0.4, 4.0), g3d_v3(0, -1, 0));
    g3d_image rgb, depth, truth, truth_d, truth_ids, out, outd, mask;
    g3d_cloud c;
    CHECK_OK(g3d_procscene_render(&src, &rgb, &depth, NULL));
    CHECK_OK(g3d_procscene_render(&dst, &truth, &truth_d, &truth_ids));
    CHECK_OK(g3d_cloud_init(&c));
    CHECK_OK(g3d_cloud_lift(&c, &rgb, &depth, &src, NULL, 0, NULL));
    CHECK_OK(g3d_cloud_render(&c, &dst, NULL, &out, &outd, &mask));
    /* Which target pixels are truly visible from the source camera? */
    size_t visible = 0, visible_filled = 0, hidden = 0, hidden_filled_wrong = 0;
    for (int y = 0; y < 192; y++)
        for (int x = 0; x < 256; x++) {
            size_t k = (size_t)y * 256 + x;
            float z = truth_d.data[k];
            g3d_vec3 p = g3d_camera_unproject(&dst, x, y, z);
            double u, v, zs;
            int seen = g3d_camera_project(&src, p, &u, &v, &zs) && u > 1 && v > 1 && u < 254 && v < 190 &&
                       fabs(*g3d_image_px(&depth, (int)lround(u), (int)lround(v)) - zs) < 0.02 * zs;
            if (seen) { visible++; visible_filled += mask.data[k] > 0.5f; }
            else { hidden++; hidden_filled_wrong += mask.data[k] > 0.5f && fabs(outd.data[k] - z) > 0.05 * z; }
        }
    size_t n;
    double err = grey_error(&out, &truth, &mask, &n);
    printf("  visible surfaces covered %.2f %%; hidden pixels filled with a wrong surface %.2f %%; grey error %.2f\n",
           100.0 * visible_filled / visible, 100.0 * hidden_filled_wrong / (hidden ? hidden : 1), err);
    CHECK(visible_filled > 0.985 * visible);
    CHECK(hidden > 500);
    CHECK(hidden_filled_wrong < 0.05 * hidden);
    CHECK(err < 6.0);
    g3d_image_free(&rgb); g3d_image_free(&depth); g3d_image_free(&truth); g3d_image_free(&truth_d);
    g3d_image_free(&truth_ids); g3d_image_free(&out); g3d_image_free(&outd); g3d_image_free(&mask);
    g3d_cloud_free(&c);
}

TEST(middlebury_right_view)
{
    g3d_frame f;
    CHECK_OK(g3d_frame_load_middlebury(test_shared("testdata/middlebury2014_motorcycle_skimage"), &f));
    if (!f.rgb.data) return;
    g3d_cloud c;
    g3d_image out, mask;
    CHECK_OK(g3d_cloud_init(&c));
    CHECK_OK(g3d_cloud_lift(&c, &f.rgb, &f.depth, &f.cam, NULL, 0, NULL));
    CHECK_OK(g3d_cloud_render(&c, &f.heldout_cam, NULL, &out, NULL, &mask));
    size_t n;
    double err = grey_error(&out, &f.heldout, &mask, &n);
    double holes = hole_fraction(&mask);
    printf("  Middlebury right view: mean abs grey error %.2f on %zu pixels, holes %.1f %%\n", err, n, 100 * holes);
    CHECK(err < 10.0);
    /* 7.4 % of the left view has no ground truth; disocclusions at the right view's left
     * border and beside the motorcycle add to it. */
    CHECK(holes > 0.074 && holes < 0.25);
    /* The columns the left camera never saw (x_right = x_left - d: the right view's right border, at least 7 px wide) are holes. */
    size_t border = 0, border_holes = 0;
    for (int y = 0; y < out.h; y++)
        for (int x = out.w - 6; x < out.w; x++) { border++; border_holes += mask.data[(size_t)y * out.w + x] < 0.5f; }
    CHECK(border_holes > 0.9 * border);
    g3d_image_free(&out); g3d_image_free(&mask);
    g3d_cloud_free(&c);
    g3d_frame_free(&f);
}

static int read_icl_pose(int frame, g3d_mat4 *m)
{
    FILE *fp = fopen(test_shared("testdata/icl_nuim_livingroom1_open3d/trajectory.log"), "r");
    if (!fp) return 0;
    int ok = 0;
    for (int f = 0; f <= frame; f++) {
        int a, b, cc;
        if (fscanf(fp, "%d %d %d", &a, &b, &cc) != 3) break;
        for (int i = 0; i < 16; i++)
            if (fscanf(fp, "%lf", &m->m[i / 4][i % 4]) != 1) { fclose(fp); return 0; }
        ok = f == frame;
    }
    fclose(fp);
    return ok;
}

TEST(icl_nuim_frame0_to_frame4)
{
    g3d_frame f0, f4;
    g3d_intrinsics K = g3d_intrinsics_make(525, 525, 319.5, 239.5, 640, 480);
    CHECK_OK(g3d_frame_load_rgbd(test_shared("testdata/icl_nuim_livingroom1_open3d/color/00000.jpg"),
                                 test_shared("testdata/icl_nuim_livingroom1_open3d/depth/00000.png"), 1000, K, 0, &f0));
    CHECK_OK(g3d_frame_load_rgbd(test_shared("testdata/icl_nuim_livingroom1_open3d/color/00004.jpg"),
                                 test_shared("testdata/icl_nuim_livingroom1_open3d/depth/00004.png"), 1000, K, 0, &f4));
    g3d_mat4 T0, T4;
    CHECK(read_icl_pose(0, &T0) && read_icl_pose(4, &T4));
    if (!f0.rgb.data || !f4.rgb.data) return;
    /* World = frame 0's camera: frame 4's pose is inv(T0) * T4. */
    f0.cam.c2w = g3d_mat4_identity();
    g3d_camera cam4 = {K, g3d_mat4_mul(g3d_mat4_inverse_rigid(T0), T4)};
    g3d_cloud c;
    g3d_image out, mask, ident, imask;
    CHECK_OK(g3d_cloud_init(&c));
    CHECK_OK(g3d_cloud_lift(&c, &f0.rgb, &f0.depth, &f0.cam, NULL, 0, NULL));
    CHECK_OK(g3d_cloud_render(&c, &cam4, NULL, &out, NULL, &mask));
    size_t n, ni;
    double err = grey_error(&out, &f4.rgb, &mask, &n);
    g3d_camera wrong = {K, g3d_mat4_identity()};
    CHECK_OK(g3d_cloud_render(&c, &wrong, NULL, &ident, NULL, &imask));
    double err_ident = grey_error(&ident, &f4.rgb, &imask, &ni);
    printf("  ICL-NUIM frame 0 -> 4: mean abs grey error %.2f on %zu co-visible pixels (identity pose: %.2f)\n", err, n, err_ident);
    CHECK(err < 5.0);
    CHECK(err_ident > 2 * err);
    g3d_image_free(&out); g3d_image_free(&mask); g3d_image_free(&ident); g3d_image_free(&imask);
    g3d_cloud_free(&c);
    g3d_frame_free(&f0);
    g3d_frame_free(&f4);
}

TEST(errors)
{
    g3d_cloud c;
    g3d_image rgb, depth;
    g3d_camera cam = g3d_procscene_default_camera(10, 10);
    CHECK_OK(g3d_cloud_init(&c));
    g3d_image_create(&rgb, 10, 10, 3);
    g3d_image_create(&depth, 11, 10, 1);
    CHECK_FAILS(g3d_cloud_lift(&c, &rgb, &depth, &cam, NULL, 0, NULL));
    cam.K.fx = 0;
    CHECK_FAILS(g3d_cloud_render(&c, &cam, NULL, &rgb, NULL, NULL));
    g3d_image_free(&rgb);
    g3d_image_free(&depth);
    g3d_cloud_free(&c);
}

int main(void)
{
    RUN(self_reprojection);
    RUN(parallax_on_procedural_room);
    RUN(middlebury_right_view);
    RUN(icl_nuim_frame0_to_frame4);
    RUN(errors);
    return test_summary();
}
