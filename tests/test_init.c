/* Gaussians started from pixel footprints (init.h): their covariance against the footprint
 * formula, a surface lifted from the procedural room rendered back at its own camera (closer to
 * the image, and with no empty pixels, than the Inria start), and the refusals. */
#include "gen3d/cloud.h"
#include "gen3d/init.h"
#include "gen3d/loss.h"
#include "gen3d/procscene.h"
#include "gen3d/raster.h"
#include "testutil.h"

/* The covariance R diag(s^2) R^T of Gaussian i. */
static void covariance(const g3d_gaussians *g, int64_t i, double cov[3][3])
{
    const float *q = g->rots + 4 * i;
    double n = sqrt((double)q[0] * q[0] + (double)q[1] * q[1] + (double)q[2] * q[2] + (double)q[3] * q[3]);
    g3d_mat4 R = g3d_quat_to_mat4((g3d_quat){q[0] / n, q[1] / n, q[2] / n, q[3] / n});
    double s2[3];
    for (int a = 0; a < 3; a++) s2[a] = exp(2.0 * g->log_scales[3 * i + a]);
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) {
            cov[r][c] = 0;
            for (int a = 0; a < 3; a++) cov[r][c] += R.m[r][a] * s2[a] * R.m[c][a];
        }
}

TEST(covariance_spans_the_footprint)
{
    enum { N = 300 };
    float xyz[3 * N], rgb[3 * N], span[6 * N];
    g3d_rng r;
    g3d_rng_seed(&r, 5, 1);
    for (int i = 0; i < N; i++) {
        for (int a = 0; a < 3; a++) {
            xyz[3 * i + a] = 4.0f * g3d_rng_float(&r) - 2.0f;
            rgb[3 * i + a] = g3d_rng_float(&r);
        }
        /* steps of a few millimetres, at any angle to each other (oblique surfaces) */
        for (int a = 0; a < 6; a++) span[6 * i + a] = 0.01f * (2.0f * g3d_rng_float(&r) - 1.0f);
    }
    g3d_footprint_init p;
    g3d_footprint_init_default(&p);
    g3d_gaussians g;
    CHECK_OK(g3d_gaussians_init_from_footprints(&g, xyz, rgb, span, N, 2, &p));
    double worst = 0;
    for (int i = 0; i < N; i++) {
        const float *s = span + 6 * i;
        g3d_vec3 sx = g3d_v3(s[0], s[1], s[2]), sy = g3d_v3(s[3], s[4], s[5]);
        g3d_vec3 nrm = g3d_v3_cross(sx, sy);
        nrm = g3d_v3_scale(nrm, 1.0 / g3d_v3_norm(nrm));
        const float *ls = g.log_scales + 3 * i;
        /* the normal axis is `thin` times the smaller in-plane one */
        CHECK_NEAR(exp(ls[2]), p.thin * fmin(exp(ls[0]), exp(ls[1])), 1e-6 * exp(ls[0]));
        double want[3][3], got[3][3], sv[2][3] = {{sx.x, sx.y, sx.z}, {sy.x, sy.y, sy.z}}, nv[3] = {nrm.x, nrm.y, nrm.z};
        covariance(&g, i, got);
        double scale2 = 0;
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) {
                want[a][b] = p.scale * p.scale * (sv[0][a] * sv[0][b] + sv[1][a] * sv[1][b]) + exp(2.0 * ls[2]) * nv[a] * nv[b];
                scale2 = fmax(scale2, fabs(want[a][b]));
            }
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) worst = fmax(worst, fabs(got[a][b] - want[a][b]) / scale2);
        CHECK_NEAR(g.opacity_logits[i], log(0.5 / 0.5), 1e-6);
        for (int a = 0; a < 3; a++) {
            CHECK(g.means[3 * i + a] == xyz[3 * i + a]);
            CHECK_NEAR(g.sh[(size_t)i * 9 * 3 + a], (rgb[3 * i + a] - 0.5f) / G3D_SH_C0, 1e-6);
        }
    }
    printf("       %d footprints: covariance relative error %.2g at worst\n", N, worst);
    CHECK(worst < 1e-4);
    g3d_gaussians_free(&g);
}

/* Renders g at cam: PSNR against want and the share of pixels with alpha below 0.5. */
static void render_back(const g3d_gaussians *g, const g3d_camera *cam, const g3d_image *want, double *psnr, double *empty)
{
    g3d_image img, alpha;
    g3d_image_create(&img, cam->K.width, cam->K.height, 3);
    g3d_image_create(&alpha, cam->K.width, cam->K.height, 1);
    g3d_raster_ws *ws;
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    CHECK_OK(g3d_raster_ws_create(&ws));
    CHECK_OK(g3d_raster_fwd(ws, g, cam, &s, img.data, alpha.data, NULL, NULL));
    CHECK_OK(g3d_psnr(&img, want, NULL, psnr));
    size_t n = 0;
    for (size_t i = 0; i < g3d_image_size(&alpha); i++) n += alpha.data[i] < 0.5f;
    *empty = (double)n / g3d_image_size(&alpha);
    g3d_raster_ws_free(ws);
    g3d_image_free(&img);
    g3d_image_free(&alpha);
}

TEST(a_lifted_view_renders_back)
{
    g3d_camera cam = g3d_procscene_default_camera(128, 96);
    g3d_image rgb, depth;
    CHECK_OK(g3d_procscene_render(&cam, &rgb, &depth, NULL));
    g3d_cloud c;
    CHECK_OK(g3d_cloud_init(&c));
    CHECK_OK(g3d_cloud_lift(&c, &rgb, &depth, &cam, NULL, 0, NULL));
    g3d_footprint_init p;
    g3d_footprint_init_default(&p);
    g3d_gaussians fp, knn;
    CHECK_OK(g3d_gaussians_init_from_footprints(&fp, c.xyz, c.rgb, c.span, c.n, 0, &p));
    CHECK_OK(g3d_gaussians_init_from_points(&knn, c.xyz, c.rgb, c.n, 0));
    double psnr_fp, psnr_knn, empty_fp, empty_knn;
    render_back(&fp, &cam, &rgb, &psnr_fp, &empty_fp);
    render_back(&knn, &cam, &rgb, &psnr_knn, &empty_knn);
    printf("       room 128x96 at its own camera, before training: footprints %.2f dB (%.2f %% empty), "
           "3-NN %.2f dB (%.2f %% empty)\n", psnr_fp, 100 * empty_fp, psnr_knn, 100 * empty_knn);
    CHECK(empty_fp == 0);
    CHECK(psnr_fp > psnr_knn + 3.0);
    g3d_gaussians_free(&fp);
    g3d_gaussians_free(&knn);
    g3d_cloud_free(&c);
    g3d_image_free(&rgb);
    g3d_image_free(&depth);
}

TEST(refusals)
{
    float xyz[6] = {0, 0, 1, 0, 0, 2}, rgb[6] = {0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f};
    float span[12] = {0.01f, 0, 0, 0, 0.01f, 0, 0.01f, 0, 0, 0, 0.01f, 0};
    g3d_footprint_init p;
    g3d_footprint_init_default(&p);
    g3d_gaussians g = {0};
    CHECK_FAILS(g3d_gaussians_init_from_footprints(&g, xyz, rgb, span, 0, 0, &p));
    g3d_footprint_init bad[] = {{0, 0.2, 0.5}, {0.5, 0, 0.5}, {0.5, 0.2, 0}, {0.5, 0.2, 1}, {NAN, 0.2, 0.5}};
    for (size_t k = 0; k < sizeof bad / sizeof *bad; k++) CHECK_FAILS(g3d_gaussians_init_from_footprints(&g, xyz, rgb, span, 2, 0, &bad[k]));
    float zero[12] = {0.01f, 0, 0, 0, 0.01f, 0};
    CHECK_FAILS(g3d_gaussians_init_from_footprints(&g, xyz, rgb, zero, 2, 0, &p));
    span[7] = NAN;
    CHECK_FAILS(g3d_gaussians_init_from_footprints(&g, xyz, rgb, span, 2, 0, &p));
    span[7] = 0;
    xyz[4] = INFINITY;
    CHECK_FAILS(g3d_gaussians_init_from_footprints(&g, xyz, rgb, span, 2, 0, &p));
    CHECK(g.n == 0);
}

int main(void)
{
    RUN(covariance_spans_the_footprint);
    RUN(a_lifted_view_renders_back);
    RUN(refusals);
    return test_summary();
}
