/* Rasterizer tests: forward sanity, culling, determinism, and gradients of every parameter type
 * against central finite differences of an independent double-precision dense forward. */
#include "gen3d/init.h"
#include "gen3d/raster.h"
#include "testutil.h"

#include <omp.h>

#define SW 16
#define SH 16

static const double C1 = 0.4886025119029199;
static const double C2[5] = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
                             -1.0925484305920792, 0.5462742152960396};
static const double C3[7] = {-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
                             0.3731763325901154, -0.4570457994644658, 1.445305721320277,
                             -0.5900435899266435};

/* Parameters in double, same layout as g3d_gaussians. */
typedef struct dmodel { int n, deg; double *means, *ls, *rots, *ol, *sh; } dmodel;

/* Dense double forward: every Gaussian is tested at every pixel (the test scenes are one tile,
 * so tile binning cannot change the result), sorted by depth, same thresholds as Inria. Returns
 * sum(wr * rgb + wa * alpha + wd * depth). */
static double ref_loss(const dmodel *m, const g3d_camera *cam, const g3d_raster_params *s,
                       const double *wr, const double *wa, const double *wd)
{
    int n = m->n, K = G3D_SH_COEFFS(m->deg);
    double u[16], v[16], cA[16], cB[16], cC[16], op[16], z[16], col[16][3];
    int vis[16], order[16];
    g3d_mat4 w2c = g3d_mat4_inverse_rigid(cam->c2w);
    g3d_vec3 cp = g3d_camera_center(cam);
    const g3d_intrinsics *Kk = &cam->K;
    for (int i = 0; i < n; i++) {
        g3d_vec3 t = g3d_mat4_point(w2c, g3d_v3(m->means[3 * i], m->means[3 * i + 1], m->means[3 * i + 2]));
        vis[i] = t.z > s->near_plane;
        if (!vis[i]) continue;
        g3d_quat q = g3d_quat_normalize((g3d_quat){m->rots[4 * i], m->rots[4 * i + 1], m->rots[4 * i + 2], m->rots[4 * i + 3]});
        g3d_mat4 R = g3d_quat_to_mat4(q);
        double Sig[3][3], V[3][3], J[2][3], JV[2][3];
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) {
                Sig[a][b] = 0;
                for (int k = 0; k < 3; k++) Sig[a][b] += R.m[a][k] * exp(2 * m->ls[3 * i + k]) * R.m[b][k];
            }
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) V[a][b] = w2c.m[a][b];
        J[0][0] = Kk->fx / t.z; J[0][1] = 0; J[0][2] = -Kk->fx * t.x / (t.z * t.z);
        J[1][0] = 0; J[1][1] = Kk->fy / t.z; J[1][2] = -Kk->fy * t.y / (t.z * t.z);
        for (int a = 0; a < 2; a++)
            for (int b = 0; b < 3; b++) {
                JV[a][b] = 0;
                for (int k = 0; k < 3; k++) JV[a][b] += J[a][k] * V[k][b];
            }
        double c2[2][2];
        for (int a = 0; a < 2; a++)
            for (int b = 0; b < 2; b++) {
                c2[a][b] = 0;
                for (int k = 0; k < 3; k++)
                    for (int l = 0; l < 3; l++) c2[a][b] += JV[a][k] * Sig[k][l] * JV[b][l];
            }
        double det0 = c2[0][0] * c2[1][1] - c2[0][1] * c2[0][1];
        c2[0][0] += s->eps2d; c2[1][1] += s->eps2d;
        double det = c2[0][0] * c2[1][1] - c2[0][1] * c2[0][1];
        cA[i] = c2[1][1] / det; cB[i] = -c2[0][1] / det; cC[i] = c2[0][0] / det;
        u[i] = Kk->fx * t.x / t.z + Kk->cx; v[i] = Kk->fy * t.y / t.z + Kk->cy;
        z[i] = t.z;
        op[i] = 1 / (1 + exp(-m->ol[i])) * (s->antialiased ? sqrt(det0 / det) : 1.0);
        g3d_vec3 d = g3d_v3_normalize(g3d_v3_sub(g3d_v3(m->means[3 * i], m->means[3 * i + 1], m->means[3 * i + 2]), cp));
        double x = d.x, y = d.y, zz = d.z, xx = x * x, yy = y * y, z2 = zz * zz;
        double b[16] = {G3D_SH_C0, -C1 * y, C1 * zz, -C1 * x,
                        C2[0] * x * y, C2[1] * y * zz, C2[2] * (2 * z2 - xx - yy), C2[3] * x * zz, C2[4] * (xx - yy),
                        C3[0] * y * (3 * xx - yy), C3[1] * x * y * zz, C3[2] * y * (4 * z2 - xx - yy),
                        C3[3] * zz * (2 * z2 - 3 * xx - 3 * yy), C3[4] * x * (4 * z2 - xx - yy),
                        C3[5] * zz * (xx - yy), C3[6] * x * (xx - 3 * yy)};
        for (int ch = 0; ch < 3; ch++) {
            double c = 0.5;
            for (int k = 0; k < K; k++) c += b[k] * m->sh[(i * K + k) * 3 + ch];
            col[i][ch] = c < 0 ? 0 : c;
        }
    }
    int nv = 0;
    for (int i = 0; i < n; i++)
        if (vis[i]) order[nv++] = i;
    for (int a = 1; a < nv; a++)
        for (int b = a; b > 0 && z[order[b]] < z[order[b - 1]]; b--) {
            int tmp = order[b]; order[b] = order[b - 1]; order[b - 1] = tmp;
        }
    double L = 0;
    for (int py = 0; py < SH; py++)
        for (int px = 0; px < SW; px++) {
            double T = 1, C[3] = {0, 0, 0}, D = 0;
            for (int k = 0; k < nv; k++) {
                int i = order[k];
                double dx = u[i] - px, dy = v[i] - py;
                double pw = -0.5 * (cA[i] * dx * dx + cC[i] * dy * dy) - cB[i] * dx * dy;
                if (pw > 0) continue;
                double al = fmin(0.99, op[i] * exp(pw));
                if (al < 1.0 / 255) continue;
                double tn = T * (1 - al);
                if (tn < 1e-4) break;
                for (int ch = 0; ch < 3; ch++) C[ch] += al * T * col[i][ch];
                D += al * T * z[i];
                T = tn;
            }
            int p = py * SW + px;
            for (int ch = 0; ch < 3; ch++) L += wr[3 * p + ch] * (C[ch] + T * s->bg[ch]);
            L += wa[p] * (1 - T) + wd[p] * D;
        }
    return L;
}

static g3d_camera test_camera(void)
{
    g3d_camera cam;
    cam.K = g3d_intrinsics_make(18, 17, 7.3, 7.8, SW, SH);
    cam.c2w = g3d_mat4_look_at(g3d_v3(0.3, -0.2, -0.1), g3d_v3(0, 0, 3), g3d_v3(0, -1, 0));
    return cam;
}

/* A few Gaussians in front of a camera looking down +z, sizes of a few pixels. */
static void random_scene(g3d_gaussians *g, int n, int deg, uint64_t seed, double scale)
{
    g3d_rng rng;
    g3d_rng_seed(&rng, seed, 1);
    CHECK_OK(g3d_gaussians_create(g, n, deg));
    g->n = n;
    int K = G3D_SH_COEFFS(deg);
    for (int i = 0; i < n; i++) {
        g->means[3 * i] = (float)(g3d_rng_float(&rng) * 1.2 - 0.6);
        g->means[3 * i + 1] = (float)(g3d_rng_float(&rng) * 1.2 - 0.6);
        g->means[3 * i + 2] = (float)(2.5 + g3d_rng_float(&rng));
        for (int k = 0; k < 3; k++) g->log_scales[3 * i + k] = (float)(log(0.25 * scale) + 0.5 * (g3d_rng_float(&rng) - 0.5));
        for (int k = 0; k < 4; k++) g->rots[4 * i + k] = (float)(g3d_rng_float(&rng) * 2 - 1);
        g->opacity_logits[i] = (float)(g3d_rng_float(&rng) * 2 - 1.5);
        for (int k = 0; k < K * 3; k++) g->sh[i * K * 3 + k] = (float)((g3d_rng_float(&rng) - 0.5) * (k < 3 ? 1.0 : 0.4));
    }
}

static dmodel to_double(const g3d_gaussians *g)
{
    int K = G3D_SH_COEFFS(g->sh_degree);
    dmodel m = {(int)g->n, g->sh_degree, NULL, NULL, NULL, NULL, NULL};
    m.means = malloc(sizeof(double) * 3 * m.n); m.ls = malloc(sizeof(double) * 3 * m.n);
    m.rots = malloc(sizeof(double) * 4 * m.n); m.ol = malloc(sizeof(double) * m.n);
    m.sh = malloc(sizeof(double) * 3 * K * m.n);
    for (int i = 0; i < 3 * m.n; i++) { m.means[i] = g->means[i]; m.ls[i] = g->log_scales[i]; }
    for (int i = 0; i < 4 * m.n; i++) m.rots[i] = g->rots[i];
    for (int i = 0; i < m.n; i++) m.ol[i] = g->opacity_logits[i];
    for (int i = 0; i < 3 * K * m.n; i++) m.sh[i] = g->sh[i];
    return m;
}

static void free_dmodel(dmodel *m) { free(m->means); free(m->ls); free(m->rots); free(m->ol); free(m->sh); }

/* Analytic gradients vs central differences (h = 1e-5, double). Per parameter type the error
 * must satisfy |ana - fd| <= 1e-3 * max(|fd|, 1e-2 * max_type |fd|): relative 1e-3, with an
 * absolute floor at 1e-5 of the type's largest gradient for entries near zero. */
static void grad_check(int deg, int antialiased, uint64_t seed, double scale)
{
    g3d_gaussians g, gr;
    random_scene(&g, 5, deg, seed, scale);
    CHECK_OK(g3d_gaussians_create(&gr, g.n, deg));
    g3d_camera cam = test_camera();
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    s.antialiased = antialiased;
    s.bg[0] = 0.2f; s.bg[1] = 0.5f; s.bg[2] = 0.9f;
    int np = SW * SH;
    float *rgb = malloc(sizeof(float) * 3 * np), *al = malloc(sizeof(float) * np), *dep = malloc(sizeof(float) * np);
    float *fwr = malloc(sizeof(float) * 3 * np), *fwa = malloc(sizeof(float) * np), *fwd = malloc(sizeof(float) * np);
    double *wr = malloc(sizeof(double) * 3 * np), *wa = malloc(sizeof(double) * np), *wd = malloc(sizeof(double) * np);
    g3d_rng rng;
    g3d_rng_seed(&rng, seed + 100, 2);
    for (int i = 0; i < 3 * np; i++) wr[i] = fwr[i] = g3d_rng_float(&rng) - 0.5f;
    for (int i = 0; i < np; i++) { wa[i] = fwa[i] = g3d_rng_float(&rng) - 0.5f; wd[i] = fwd[i] = 0.2f * (g3d_rng_float(&rng) - 0.5f); }
    g3d_raster_ws *ws;
    CHECK_OK(g3d_raster_ws_create(&ws));
    CHECK_OK(g3d_raster_fwd(ws, &g, &cam, &s, rgb, al, dep, NULL));
    CHECK_OK(g3d_raster_bwd(ws, &g, fwr, fwa, fwd, &gr, NULL));

    dmodel m = to_double(&g);
    int K = G3D_SH_COEFFS(deg);
    struct { const char *name; double *p; float *ana; int count; } types[5] = {
        {"means", m.means, gr.means, 3 * m.n}, {"log_scales", m.ls, gr.log_scales, 3 * m.n},
        {"rots", m.rots, gr.rots, 4 * m.n}, {"opacity_logits", m.ol, gr.opacity_logits, m.n},
        {"sh", m.sh, gr.sh, 3 * K * m.n}};
    const double h = 1e-5;
    for (int t = 0; t < 5; t++) {
        double *fd = malloc(sizeof(double) * types[t].count), maxfd = 0, worst = 0;
        for (int k = 0; k < types[t].count; k++) {
            double keep = types[t].p[k];
            types[t].p[k] = keep + h;
            double lp = ref_loss(&m, &cam, &s, wr, wa, wd);
            types[t].p[k] = keep - h;
            double lm = ref_loss(&m, &cam, &s, wr, wa, wd);
            types[t].p[k] = keep;
            fd[k] = (lp - lm) / (2 * h);
            if (fabs(fd[k]) > maxfd) maxfd = fabs(fd[k]);
        }
        CHECK_MSG(maxfd > 1e-3, "%s: gradients all near zero, scene does not exercise them", types[t].name);
        for (int k = 0; k < types[t].count; k++) {
            double err = fabs(types[t].ana[k] - fd[k]) / fmax(fabs(fd[k]), 1e-2 * maxfd);
            if (err > worst) worst = err;
            CHECK_MSG(err <= 1e-3, "deg %d aa %d %s[%d]: analytic %.8g fd %.8g", deg, antialiased,
                      types[t].name, k, types[t].ana[k], fd[k]);
        }
        printf("  deg %d aa %d %-15s max rel err %.2e (max |g| %.3g)\n", deg, antialiased, types[t].name, worst, maxfd);
        free(fd);
    }
    free_dmodel(&m);
    g3d_raster_ws_free(ws);
    g3d_gaussians_free(&g);
    g3d_gaussians_free(&gr);
    free(rgb); free(al); free(dep); free(fwr); free(fwa); free(fwd); free(wr); free(wa); free(wd);
}

TEST(grad_deg0) { grad_check(0, 0, 1, 1.0); }
TEST(grad_deg1) { grad_check(1, 0, 2, 1.0); }
TEST(grad_deg3) { grad_check(3, 0, 3, 1.0); }
TEST(grad_deg2_antialiased) { grad_check(2, 1, 4, 1.0); }
/* footprints under 8 pixels wide: the blend's half-row path */
TEST(grad_small_footprints) { grad_check(3, 0, 5, 0.4); }

/* One isotropic Gaussian on the optical axis renders o * exp(-r^2 / (2 (s^2 + eps2d))) with
 * s = f sigma / z pixels, wherever that alpha is at least 1/255. */
TEST(single_isotropic)
{
    g3d_gaussians g;
    CHECK_OK(g3d_gaussians_create(&g, 1, 0));
    g.n = 1;
    const double z = 4.0, sigma = 0.3, f = 20.0;
    g.means[2] = (float)z;
    for (int k = 0; k < 3; k++) g.log_scales[k] = (float)log(sigma);
    g.rots[0] = 2.0f;                 /* unnormalised identity */
    g.opacity_logits[0] = 0.0f;       /* o = 0.5 */
    g.sh[0] = 0.7f; g.sh[1] = -0.2f; g.sh[2] = 0.1f;
    g3d_camera cam;
    cam.K = g3d_intrinsics_make(f, f, 20, 15, 41, 31);
    cam.c2w = g3d_mat4_identity();
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    s.bg[0] = 0.25f; s.bg[1] = 0.5f; s.bg[2] = 1.0f;
    float rgb[41 * 31 * 3], al[41 * 31], dep[41 * 31];
    int32_t radius;
    g3d_raster_ws *ws;
    CHECK_OK(g3d_raster_ws_create(&ws));
    CHECK_OK(g3d_raster_fwd(ws, &g, &cam, &s, rgb, al, dep, &radius));
    double sp = f * sigma / z, var = sp * sp + s.eps2d;
    CHECK(radius == (int)ceil(3 * sqrt(var + sqrt(0.1))));   /* Inria floors the eigen gap at 0.1 */
    double col[3];
    for (int ch = 0; ch < 3; ch++) col[ch] = fmax(0.0, 0.5 + G3D_SH_C0 * g.sh[ch]);
    double maxerr = 0;
    for (int y = 0; y < 31; y++)
        for (int x = 0; x < 41; x++) {
            double dx = x - 20.0, dy = y - 15.0;
            double a = 0.5 * exp(-(dx * dx + dy * dy) / (2 * var));
            if (a < 1.0 / 255 || fmax(fabs(dx), fabs(dy)) > radius) a = 0;   /* skipped / outside tiles */
            int p = y * 41 + x;
            if (a > 0 && a < 1.1 / 255) continue;   /* float rounding at the cut-off */
            maxerr = fmax(maxerr, fabs(al[p] - a));
            maxerr = fmax(maxerr, fabs(dep[p] - a * z));
            for (int ch = 0; ch < 3; ch++) maxerr = fmax(maxerr, fabs(rgb[3 * p + ch] - (a * col[ch] + (1 - a) * s.bg[ch])));
        }
    CHECK_NEAR(maxerr, 0, 2e-6);
    g3d_raster_ws_free(ws);
    g3d_gaussians_free(&g);
}

/* rgb(bg) - rgb(0) = (1 - alpha) bg per pixel; alpha in [0, 1); Gaussians behind the camera or
 * nearer than the near plane get radius 0 and leave the image untouched. */
TEST(alpha_and_culling)
{
    g3d_gaussians g;
    random_scene(&g, 5, 1, 7, 1.0);
    g3d_camera cam = test_camera();
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    float rgb0[SW * SH * 3], rgb1[SW * SH * 3], al[SW * SH];
    int32_t radii[5];
    g3d_raster_ws *ws;
    CHECK_OK(g3d_raster_ws_create(&ws));
    CHECK_OK(g3d_raster_fwd(ws, &g, &cam, &s, rgb0, al, NULL, radii));
    s.bg[0] = 1; s.bg[1] = 0.5f; s.bg[2] = 0.25f;
    CHECK_OK(g3d_raster_fwd(ws, &g, &cam, &s, rgb1, NULL, NULL, NULL));
    double maxerr = 0, maxal = 0;
    for (int p = 0; p < SW * SH; p++) {
        CHECK(al[p] >= 0 && al[p] < 1);
        maxal = fmax(maxal, al[p]);
        for (int ch = 0; ch < 3; ch++) maxerr = fmax(maxerr, fabs(rgb1[3 * p + ch] - rgb0[3 * p + ch] - (1 - al[p]) * s.bg[ch]));
    }
    CHECK_NEAR(maxerr, 0, 1e-6);
    CHECK(maxal > 0.3);
    for (int i = 0; i < 5; i++) CHECK(radii[i] > 0);
    /* move every Gaussian behind the camera (mirror through its centre) or inside the near plane */
    g3d_vec3 c = g3d_camera_center(&cam);
    for (int i = 0; i < 5; i++) {
        g3d_vec3 p = g3d_v3(g.means[3 * i], g.means[3 * i + 1], g.means[3 * i + 2]);
        g3d_vec3 q = i == 0 ? g3d_v3_add(c, g3d_v3_scale(g3d_v3_normalize(g3d_v3_sub(p, c)), 0.005))
                            : g3d_v3_sub(g3d_v3_scale(c, 2), p);
        g.means[3 * i] = (float)q.x; g.means[3 * i + 1] = (float)q.y; g.means[3 * i + 2] = (float)q.z;
    }
    CHECK_OK(g3d_raster_fwd(ws, &g, &cam, &s, rgb1, al, NULL, radii));
    for (int i = 0; i < 5; i++) CHECK(radii[i] == 0);
    for (int p = 0; p < SW * SH; p++) {
        CHECK(al[p] == 0);
        for (int ch = 0; ch < 3; ch++) CHECK(rgb1[3 * p + ch] == s.bg[ch]);
    }
    g3d_raster_ws_free(ws);
    g3d_gaussians_free(&g);
}

/* Forward and backward are bit-identical across runs and across thread counts. */
TEST(deterministic)
{
    g3d_gaussians g, g1, g2;
    g3d_rng rng;
    g3d_rng_seed(&rng, 11, 3);
    const int n = 3000, W = 96, H = 72;
    CHECK_OK(g3d_gaussians_create(&g, n, 2));
    g.n = n;
    for (int i = 0; i < n; i++) {
        g.means[3 * i] = g3d_rng_float(&rng) * 4 - 2;
        g.means[3 * i + 1] = g3d_rng_float(&rng) * 3 - 1.5f;
        g.means[3 * i + 2] = g3d_rng_float(&rng) * 4 + 2;
        for (int k = 0; k < 3; k++) g.log_scales[3 * i + k] = logf(0.03f + 0.05f * g3d_rng_float(&rng));
        for (int k = 0; k < 4; k++) g.rots[4 * i + k] = g3d_rng_normal(&rng);
        g.opacity_logits[i] = g3d_rng_normal(&rng);
        for (int k = 0; k < 27; k++) g.sh[27 * i + k] = 0.3f * g3d_rng_normal(&rng);
    }
    g3d_camera cam;
    cam.K = g3d_intrinsics_from_fov(60, W, H);
    cam.c2w = g3d_mat4_identity();
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    size_t np = (size_t)W * H;
    float *rgb[2], *d = malloc(sizeof(float) * 3 * np), *g2d[2];
    for (size_t i = 0; i < 3 * np; i++) d[i] = g3d_rng_float(&rng) - 0.5f;
    g3d_gaussians *grs[2] = {&g1, &g2};
    g3d_raster_ws *ws;
    CHECK_OK(g3d_raster_ws_create(&ws));
    for (int r = 0; r < 2; r++) {
        omp_set_num_threads(r == 0 ? 1 : 3);
        rgb[r] = malloc(sizeof(float) * 3 * np);
        g2d[r] = calloc(n, sizeof(float));
        CHECK_OK(g3d_gaussians_create(grs[r], n, 2));
        CHECK_OK(g3d_raster_fwd(ws, &g, &cam, &s, rgb[r], NULL, NULL, NULL));
        CHECK_OK(g3d_raster_bwd(ws, &g, d, NULL, NULL, grs[r], g2d[r]));
    }
    CHECK(memcmp(rgb[0], rgb[1], sizeof(float) * 3 * np) == 0);
    CHECK(memcmp(g2d[0], g2d[1], sizeof(float) * n) == 0);
    CHECK(memcmp(g1.block_, g2.block_, sizeof(float) * (size_t)n * (3 + 3 + 4 + 1 + 27)) == 0);
    double sum = 0;
    for (int i = 0; i < n; i++) sum += g2d[0][i];
    CHECK(sum > 0);
    g3d_raster_ws_free(ws);
    for (int r = 0; r < 2; r++) { free(rgb[r]); free(g2d[r]); g3d_gaussians_free(grs[r]); }
    g3d_gaussians_free(&g);
    free(d);
}

/* Init from points: scales against a brute-force 3-NN on clustered points, DC colour, identity
 * rotation, opacity 0.1. */
TEST(init_from_points)
{
    const int n = 3000;
    float *xyz = malloc(sizeof(float) * 3 * n), *rgb = malloc(sizeof(float) * 3 * n);
    g3d_rng rng;
    g3d_rng_seed(&rng, 5, 5);
    for (int i = 0; i < n; i++) {
        /* a dense cluster, a sparse shell and a flat sheet: uneven densities */
        int kind = i % 3;
        for (int a = 0; a < 3; a++) {
            xyz[3 * i + a] = kind == 0 ? 0.2f * g3d_rng_normal(&rng) : 5.0f * g3d_rng_float(&rng) - 2.5f;
            rgb[3 * i + a] = g3d_rng_float(&rng);
        }
        if (kind == 2) xyz[3 * i + 2] = 3.0f;
    }
    xyz[3] = xyz[0]; xyz[4] = xyz[1]; xyz[5] = xyz[2];   /* a duplicate point */
    g3d_gaussians g;
    CHECK_OK(g3d_gaussians_init_from_points(&g, xyz, rgb, n, 2));
    CHECK(g.n == n && g.sh_degree == 2);
    double maxerr = 0;
    for (int i = 0; i < n; i++) {
        double best[3] = {1e300, 1e300, 1e300};
        for (int j = 0; j < n; j++) {
            if (j == i) continue;
            double d2 = 0;
            for (int a = 0; a < 3; a++) d2 += ((double)xyz[3 * j + a] - xyz[3 * i + a]) * ((double)xyz[3 * j + a] - xyz[3 * i + a]);
            if (d2 < best[2]) {
                best[2] = d2;
                for (int k = 2; k > 0 && best[k] < best[k - 1]; k--) { double t = best[k]; best[k] = best[k - 1]; best[k - 1] = t; }
            }
        }
        double want = log(sqrt(fmax((best[0] + best[1] + best[2]) / 3, 1e-7)));
        for (int a = 0; a < 3; a++) maxerr = fmax(maxerr, fabs(g.log_scales[3 * i + a] - want));
        CHECK(g.rots[4 * i] == 1 && g.rots[4 * i + 1] == 0 && g.rots[4 * i + 2] == 0 && g.rots[4 * i + 3] == 0);
        CHECK_NEAR(1 / (1 + exp(-g.opacity_logits[i])), 0.1, 1e-6);
        for (int a = 0; a < 3; a++) CHECK_NEAR(0.5 + G3D_SH_C0 * g.sh[i * 27 + a], rgb[3 * i + a], 1e-6);
        CHECK(g.sh[i * 27 + 3] == 0);
    }
    CHECK_NEAR(maxerr, 0, 1e-5);
    g3d_gaussians_free(&g);
    CHECK_FAILS(g3d_gaussians_init_from_points(&g, xyz, rgb, 0, 0));
    xyz[7] = NAN;
    CHECK_FAILS(g3d_gaussians_init_from_points(&g, xyz, rgb, n, 0));
    /* tiny clouds use the neighbours that exist */
    CHECK_OK(g3d_gaussians_init_from_points(&g, xyz, rgb, 2, 0));
    double d2 = 0;
    for (int a = 0; a < 3; a++) d2 += ((double)xyz[a] - xyz[3 + a]) * ((double)xyz[a] - xyz[3 + a]);
    CHECK_NEAR(g.log_scales[0], log(sqrt(fmax(d2, 1e-7))), 1e-6);
    g3d_gaussians_free(&g);
    free(xyz);
    free(rgb);
}

int main(void)
{
    RUN(single_isotropic);
    RUN(alpha_and_culling);
    RUN(deterministic);
    RUN(init_from_points);
    RUN(grad_deg0);
    RUN(grad_deg1);
    RUN(grad_deg3);
    RUN(grad_deg2_antialiased);
    RUN(grad_small_footprints);
    return test_summary();
}
