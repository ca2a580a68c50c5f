/* PLY: bit-identical round trips, the 3DGS f_rest channel grouping, foreign layouts, errors. */
#include "testutil.h"
#include "gen3d/ply.h"

static void write_text(const char *path, const char *s)
{
    FILE *f = fopen(path, "wb");
    fputs(s, f);
    fclose(f);
}

static void random_gaussians(g3d_gaussians *g, int64_t n, int deg, uint64_t seed)
{
    g3d_rng r;
    g3d_rng_seed(&r, seed, 0);
    g3d_gaussians_create(g, n, deg);
    g->n = n;
    int K = G3D_SH_COEFFS(deg);
    for (int64_t i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++) { g->means[3 * i + k] = g3d_rng_normal(&r); g->log_scales[3 * i + k] = g3d_rng_normal(&r) - 4; }
        for (int k = 0; k < 4; k++) g->rots[4 * i + k] = g3d_rng_normal(&r);
        g->opacity_logits[i] = g3d_rng_normal(&r);
        for (int k = 0; k < 3 * K; k++) g->sh[(size_t)i * 3 * K + k] = g3d_rng_normal(&r);
    }
}

TEST(gaussians_round_trip_all_degrees)
{
    for (int deg = 0; deg <= 3; deg++) {
        g3d_gaussians a, b;
        random_gaussians(&a, 257, deg, 10 + deg);
        CHECK_OK(g3d_ply_write_gaussians(test_tmp("g.ply"), &a));
        CHECK_OK(g3d_ply_read_gaussians(test_tmp("g.ply"), &b));
        CHECK(b.n == a.n && b.sh_degree == deg);
        int K = G3D_SH_COEFFS(deg);
        CHECK(!memcmp(a.means, b.means, sizeof(float) * 3 * a.n));
        CHECK(!memcmp(a.log_scales, b.log_scales, sizeof(float) * 3 * a.n));
        CHECK(!memcmp(a.rots, b.rots, sizeof(float) * 4 * a.n));
        CHECK(!memcmp(a.opacity_logits, b.opacity_logits, sizeof(float) * a.n));
        CHECK(!memcmp(a.sh, b.sh, sizeof(float) * 3 * K * a.n));
        g3d_ply_info info;
        CHECK_OK(g3d_ply_probe(test_tmp("g.ply"), &info));
        CHECK(info.is_gaussians && info.sh_degree == deg && info.n_vertices == 257 && info.n_properties == 17 + 3 * (K - 1));
        /* The file is 4 bytes per property per Gaussian after the header (Inria's layout). */
        FILE *f = fopen(test_tmp("g.ply"), "rb");
        fseek(f, 0, SEEK_END);
        long size = ftell(f);
        fclose(f);
        CHECK(size > 257L * 4 * info.n_properties && size < 257L * 4 * info.n_properties + 2000);
        g3d_gaussians_free(&a);
        g3d_gaussians_free(&b);
    }
}

TEST(sh_channel_grouping_by_hand)
{
    /* One degree-1 Gaussian written by hand as ASCII with properties shuffled:
     * f_rest_0..2 = red coefficients 1..3, f_rest_3..5 = green, f_rest_6..8 = blue.
     * Value encodes 10*channel + coefficient. */
    write_text(test_tmp("hand.ply"),
               "ply\nformat ascii 1.0\nelement vertex 1\n"
               "property float opacity\nproperty double x\nproperty float y\nproperty float z\n"
               "property float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\n"
               "property float scale_0\nproperty float scale_1\nproperty float scale_2\n"
               "property float f_rest_0\nproperty float f_rest_1\nproperty float f_rest_2\nproperty float f_rest_3\n"
               "property float f_rest_4\nproperty float f_rest_5\nproperty float f_rest_6\nproperty float f_rest_7\n"
               "property float f_rest_8\nproperty float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\n"
               "property uchar extra\nend_header\n"
               "-0.5 1 2 3 1 0 0 0 -3 -4 -5 1 2 3 11 12 13 21 22 23 0 10 20 7\n");
    g3d_gaussians g;
    CHECK_OK(g3d_ply_read_gaussians(test_tmp("hand.ply"), &g));
    if (!g.n) return;
    CHECK(g.sh_degree == 1);
    for (int ch = 0; ch < 3; ch++)
        for (int j = 0; j < 4; j++) CHECK(g.sh[j * 3 + ch] == (float)(10 * ch + j));
    CHECK(g.means[0] == 1 && g.means[2] == 3 && g.opacity_logits[0] == -0.5f && g.log_scales[2] == -5 && g.rots[0] == 1);
    /* Written back in the standard order, f_rest_k must come out channel-grouped again. */
    CHECK_OK(g3d_ply_write_gaussians(test_tmp("hand2.ply"), &g));
    g3d_gaussians g2;
    CHECK_OK(g3d_ply_read_gaussians(test_tmp("hand2.ply"), &g2));
    CHECK(g2.n == 1 && !memcmp(g.sh, g2.sh, sizeof(float) * 12));
    FILE *f = fopen(test_tmp("hand2.ply"), "rb");
    char buf[4096] = {0};
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    fclose(f);
    CHECK(n > 104);
    char *data = strstr(buf, "end_header\n") + 11; /* the header holds no NUL byte */
    float row[26];
    memcpy(row, data, sizeof row);
    for (int k = 0; k < 9; k++) CHECK(row[9 + k] == (float)(10 * (k / 3) + k % 3 + 1));
    g3d_gaussians_free(&g);
    g3d_gaussians_free(&g2);
}

TEST(points_round_trip_and_foreign_files)
{
    g3d_points a, b;
    for (int normals = 0; normals <= 1; normals++) {
        CHECK_OK(g3d_points_create(&a, 100, normals));
        for (int i = 0; i < 300; i++) { a.xyz[i] = (float)i * 0.37f - 20; a.rgb[i] = (uint8_t)(i * 7); if (normals) a.normals[i] = (float)(i % 3); }
        CHECK_OK(g3d_ply_write_points(test_tmp("p.ply"), &a));
        CHECK_OK(g3d_ply_read_points(test_tmp("p.ply"), &b));
        CHECK(b.n == 100 && !memcmp(a.xyz, b.xyz, 1200) && !memcmp(a.rgb, b.rgb, 300));
        CHECK((b.normals != NULL) == normals);
        if (normals && b.normals) CHECK(!memcmp(a.normals, b.normals, 1200));
        g3d_points_free(&a);
        g3d_points_free(&b);
    }
    /* Big-endian with doubles, float colours, and a face element after the vertices. */
    FILE *f = fopen(test_tmp("be.ply"), "wb");
    fputs("ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\n"
          "property float red\nproperty float green\nproperty float blue\nelement face 1\n"
          "property list uchar int vertex_indices\nend_header\n", f);
    double xyz[2][3] = {{1.5, -2, 3}, {4, 5, 6.25}};
    float col[2][3] = {{1, 0, 0.5f}, {0, 1, 0}};
    for (int i = 0; i < 2; i++) {
        for (int k = 0; k < 3; k++) { unsigned char b8[8], r8[8]; memcpy(b8, &xyz[i][k], 8); for (int j = 0; j < 8; j++) r8[j] = b8[7 - j]; fwrite(r8, 1, 8, f); }
        for (int k = 0; k < 3; k++) { unsigned char b4[4], r4[4]; memcpy(b4, &col[i][k], 4); for (int j = 0; j < 4; j++) r4[j] = b4[3 - j]; fwrite(r4, 1, 4, f); }
    }
    fclose(f);
    CHECK_OK(g3d_ply_read_points(test_tmp("be.ply"), &b));
    CHECK(b.n == 2 && b.xyz[0] == 1.5f && b.xyz[5] == 6.25f && b.rgb[0] == 255 && b.rgb[2] == 128 && b.rgb[4] == 255);
    g3d_points_free(&b);
    /* A 3DGS file read as points takes its colours from the SH DC term. */
    g3d_gaussians g;
    random_gaussians(&g, 3, 0, 1);
    g.sh[0] = 0; g.sh[1] = 1.0f; g.sh[2] = -5;
    g3d_ply_write_gaussians(test_tmp("g0.ply"), &g);
    CHECK_OK(g3d_ply_read_points(test_tmp("g0.ply"), &b));
    CHECK(b.n == 3 && b.rgb[0] == 128 && b.rgb[1] == 199 && b.rgb[2] == 0); /* 255 * (0.5 + C0 * f_dc) */
    g3d_points_free(&b);
    g3d_gaussians_free(&g);
}

TEST(hostile_ply)
{
    g3d_points p;
    g3d_gaussians g;
    const char *hdr3 = "ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    write_text(test_tmp("trunc.ply"), hdr3); /* declares 10 vertices, holds none */
    CHECK_FAILS(g3d_ply_read_points(test_tmp("trunc.ply"), &p));
    write_text(test_tmp("absurd.ply"), "ply\nformat binary_little_endian 1.0\nelement vertex 99999999999\nproperty float x\nproperty float y\nproperty float z\nend_header\n");
    CHECK_FAILS(g3d_ply_read_points(test_tmp("absurd.ply"), &p));
    write_text(test_tmp("noz.ply"), "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n");
    CHECK_FAILS(g3d_ply_read_points(test_tmp("noz.ply"), &p));
    write_text(test_tmp("list.ply"), "ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\nend_header\n1 2\n");
    CHECK_FAILS(g3d_ply_read_points(test_tmp("list.ply"), &p));
    write_text(test_tmp("noend.ply"), "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n");
    CHECK_FAILS(g3d_ply_read_points(test_tmp("noend.ply"), &p));
    write_text(test_tmp("notply.ply"), "solid cube\nfacet normal 0 0 1\n");
    CHECK_FAILS(g3d_ply_read_points(test_tmp("notply.ply"), &p));
    write_text(test_tmp("asciishort.ply"), "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 5 6\n7 8\n");
    CHECK_FAILS(g3d_ply_read_points(test_tmp("asciishort.ply"), &p));
    /* Points are not Gaussians. */
    CHECK_OK(g3d_points_create(&p, 2, 0));
    g3d_ply_write_points(test_tmp("pts.ply"), &p);
    g3d_points_free(&p);
    CHECK_FAILS(g3d_ply_read_gaussians(test_tmp("pts.ply"), &g));
    /* Wrong number of f_rest properties (4 matches no degree). */
    write_text(test_tmp("rest4.ply"),
               "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
               "property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\nproperty float f_rest_0\nproperty float f_rest_1\n"
               "property float f_rest_2\nproperty float f_rest_3\nproperty float opacity\nproperty float scale_0\nproperty float scale_1\n"
               "property float scale_2\nproperty float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\n"
               "end_header\n0 0 0 0 0 0 0 0 0 0 0 0 0 0 1 0 0 0\n");
    CHECK_FAILS(g3d_ply_read_gaussians(test_tmp("rest4.ply"), &g));
    /* NaN in a Gaussian parameter. */
    write_text(test_tmp("nan.ply"),
               "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
               "property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\nproperty float opacity\nproperty float scale_0\n"
               "property float scale_1\nproperty float scale_2\nproperty float rot_0\nproperty float rot_1\nproperty float rot_2\n"
               "property float rot_3\nend_header\n0 0 0 0 0 0 nan 0 0 0 1 0 0 0\n");
    CHECK_FAILS(g3d_ply_read_gaussians(test_tmp("nan.ply"), &g));
    CHECK_FAILS(g3d_ply_read_points(test_tmp("missing.ply"), &p));
}

int main(void)
{
    RUN(gaussians_round_trip_all_degrees);
    RUN(sh_channel_grouping_by_hand);
    RUN(points_round_trip_and_foreign_files);
    RUN(hostile_ply);
    return test_summary();
}
