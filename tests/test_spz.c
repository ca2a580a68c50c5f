/* test_spz.c - .spz v2 round trip within the quantisation bounds, axis flip, bad files. */
#include <zlib.h>

#include "gen3d/spz.h"
#include "testutil.h"

static void random_model(g3d_gaussians *g, int n, int deg)
{
    g3d_rng r;
    g3d_rng_seed(&r, 99, 3);
    g3d_gaussians_create(g, n, deg);
    g->n = n;
    int K = G3D_SH_COEFFS(deg);
    for (int i = 0; i < n; i++) {
        for (int a = 0; a < 3; a++) {
            g->means[i * 3 + a] = 20.0f * (g3d_rng_float(&r) - 0.5f);
            g->log_scales[i * 3 + a] = -6.0f + 5.0f * g3d_rng_float(&r);
        }
        for (int a = 0; a < 4; a++) g->rots[i * 4 + a] = g3d_rng_normal(&r);
        g->opacity_logits[i] = 6.0f * (g3d_rng_float(&r) - 0.5f);
        for (int k = 0; k < K * 3; k++)
            g->sh[i * K * 3 + k] = (k < 3 ? 1.5f : 0.9f) * (2 * g3d_rng_float(&r) - 1);
    }
}

TEST(round_trip)
{
    g3d_gaussians g, d;
    random_model(&g, 200, 3);
    const char *path = test_tmp("rt.spz");
    CHECK_OK(g3d_spz_save(path, &g));
    CHECK_OK(g3d_spz_load(path, &d));
    CHECK(d.n == 200 && d.sh_degree == 3);
    double e_pos = 0, e_col = 0, e_scl = 0, e_op = 0, e_rot = 0, e_sh1 = 0, e_shr = 0;
    for (int i = 0; i < 200 && d.n == 200; i++) {
        for (int a = 0; a < 3; a++) {
            e_pos = fmax(e_pos, fabs(d.means[i * 3 + a] - g.means[i * 3 + a]));
            e_scl = fmax(e_scl, fabs(d.log_scales[i * 3 + a] - g.log_scales[i * 3 + a]));
            e_col = fmax(e_col, fabs(d.sh[i * 48 + a] - g.sh[i * 48 + a]));
        }
        e_op = fmax(e_op, fabs(1 / (1 + exp(-d.opacity_logits[i])) - 1 / (1 + exp(-g.opacity_logits[i]))));
        const float *q = g.rots + i * 4;
        double len = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), dot = 0;
        for (int a = 0; a < 4; a++) dot += d.rots[i * 4 + a] * q[a] / len;
        e_rot = fmax(e_rot, 1 - fabs(dot)); /* q and -q are the same rotation */
        for (int k = 3; k < 48; k++) {
            double e = fabs(d.sh[i * 48 + k] - g.sh[i * 48 + k]);
            if (k < 12) e_sh1 = fmax(e_sh1, e); else e_shr = fmax(e_shr, e);
        }
    }
    printf("       max errors: pos %.2e  dc %.4f  log-scale %.4f  opacity %.4f  1-|q.q'| %.2e  sh1 %.4f  sh2+ %.4f\n",
           e_pos, e_col, e_scl, e_op, e_rot, e_sh1, e_shr);
    CHECK(e_pos <= 1.0 / 8192 + 1e-6);
    CHECK(e_col <= 1.0 / (2 * 0.15 * 255) + 1e-5);
    CHECK(e_scl <= 1.0 / 32 + 1e-6);
    CHECK(e_op <= 0.5 / 255 + 1e-6);
    CHECK(e_rot <= 5e-3); /* w is recovered from x, y, z: worst near w = 0 */
    CHECK(e_sh1 <= 4.5 / 128 + 1e-6);
    CHECK(e_shr <= 8.5 / 128 + 1e-6);
    g3d_gaussians_free(&g);
    g3d_gaussians_free(&d);
}

TEST(layout_and_flip)
{
    g3d_gaussians g;
    random_model(&g, 3, 1);
    g.means[0] = 1.0f; g.means[1] = 2.0f; g.means[2] = -3.0f;
    const char *path = test_tmp("flip.spz");
    CHECK_OK(g3d_spz_save(path, &g));
    gzFile f = gzopen(path, "rb");
    CHECK(f != NULL);
    uint8_t buf[16 + 9];
    CHECK(f && gzread(f, buf, sizeof buf) == (int)sizeof buf);
    if (f) gzclose(f);
    CHECK(buf[0] == 'N' && buf[1] == 'G' && buf[2] == 'S' && buf[3] == 'P');
    CHECK(buf[4] == 2 && buf[8] == 3 && buf[12] == 1 && buf[13] == 12 && buf[14] == 0 && buf[15] == 0);
    int32_t v[3];
    for (int a = 0; a < 3; a++) {
        const uint8_t *b = buf + 16 + 3 * a;
        v[a] = (int32_t)(b[0] | b[1] << 8 | b[2] << 16);
        if (v[a] & 0x800000) v[a] -= 0x1000000;
    }
    /* RDF (1, 2, -3) is RUB (1, -2, 3) */
    CHECK(v[0] == 4096 && v[1] == -8192 && v[2] == 12288);
    g3d_gaussians_free(&g);
}

/* The in-memory encoding is the file, byte for byte. */
TEST(encode_is_the_file)
{
    g3d_gaussians g;
    random_model(&g, 150, 2);
    const char *path = test_tmp("enc.spz");
    CHECK_OK(g3d_spz_save(path, &g));
    uint8_t *mem = NULL;
    size_t n = 0, fn = 0;
    unsigned char *file = NULL;
    CHECK_OK(g3d_spz_encode(&g, "enc", &mem, &n));
    CHECK_OK(g3d_read_file(path, 1 << 24, &file, &fn));
    CHECK(mem && file && n == fn && !memcmp(mem, file, n));
    free(mem);
    free(file);
    g.means[7] = 1e6f;  /* beyond the fixed-point range: refused, nothing returned */
    CHECK_FAILS(g3d_spz_encode(&g, "enc", &mem, &n));
    CHECK(mem == NULL && n == 0);
    g3d_gaussians_free(&g);
}

TEST(bad_files)
{
    g3d_gaussians g, d;
    random_model(&g, 50, 0);
    const char *path = test_tmp("bad.spz");
    CHECK_OK(g3d_spz_save(path, &g));
    unsigned char *data;
    size_t n;
    CHECK_OK(g3d_read_file(path, 1 << 20, &data, &n));
    CHECK_OK(g3d_write_file_atomic(path, data, n / 2));
    CHECK_FAILS(g3d_spz_load(path, &d));
    CHECK(d.n == 0 && d.means == NULL);
    CHECK_OK(g3d_write_file_atomic(path, "not gzip at all", 15));
    CHECK_FAILS(g3d_spz_load(path, &d));
    gzFile f = gzopen(path, "wb");
    gzwrite(f, "NGSQ", 4);
    gzclose(f);
    CHECK_FAILS(g3d_spz_load(path, &d));
    CHECK_FAILS(g3d_spz_load(test_tmp("missing.spz"), &d));
    g.means[4] = 5000.0f;
    CHECK_FAILS(g3d_spz_save(test_tmp("far.spz"), &g));
    CHECK(!test_file_exists(test_tmp("far.spz")));
    free(data);
    g3d_gaussians_free(&g);
}

int main(void)
{
    RUN(round_trip);
    RUN(layout_and_flip);
    RUN(encode_is_the_file);
    RUN(bad_files);
    return test_summary();
}
