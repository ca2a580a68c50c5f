/* CPU operators against direct loop definitions and hand-computed values. */
#include "testutil.h"

#include "gen3d/nn.h"

static void fill(float *v, size_t n, uint64_t seed)
{
    g3d_rng r;
    g3d_rng_seed(&r, seed, 1);
    for (size_t i = 0; i < n; i++) v[i] = g3d_rng_normal(&r);
}

static double max_abs_diff(const float *a, const float *b, size_t n)
{
    double m = 0;
    for (size_t i = 0; i < n; i++) m = fmax(m, fabs((double)a[i] - b[i]));
    return m;
}

TEST(linear_small)
{
    /* x = [[1,2],[3,4]], w = [[1,0],[1,1],[0,-1]], b = [0.5, 0, 1] */
    const float x[] = {1, 2, 3, 4}, w[] = {1, 0, 1, 1, 0, -1}, b[] = {0.5f, 0, 1};
    const float want[] = {1.5f, 3, -1, 3.5f, 7, -3};
    float y[6];
    g3d_nn_linear(x, 2, 2, w, b, 3, y);
    CHECK(max_abs_diff(y, want, 6) < 1e-6);
}

static void conv_ref(const float *x, int cin, int h, int w, const float *wt, const float *b, int cout, int k,
                     int s, int p, float *y)
{
    int ho = g3d_nn_conv_out(h, k, s, p), wo = g3d_nn_conv_out(w, k, s, p);
    for (int o = 0; o < cout; o++)
        for (int oy = 0; oy < ho; oy++)
            for (int ox = 0; ox < wo; ox++) {
                double acc = b ? b[o] : 0;
                for (int c = 0; c < cin; c++)
                    for (int ky = 0; ky < k; ky++)
                        for (int kx = 0; kx < k; kx++) {
                            int iy = oy * s - p + ky, ix = ox * s - p + kx;
                            if (iy < 0 || iy >= h || ix < 0 || ix >= w) continue;
                            acc += (double)wt[((o * cin + c) * k + ky) * k + kx] * x[(c * h + iy) * w + ix];
                        }
                y[(o * ho + oy) * wo + ox] = (float)acc;
            }
}

TEST(conv2d_matches_definition)
{
    const int cin = 3, cout = 5, h = 9, w = 7;
    const int cases[][3] = {{3, 1, 1}, {3, 2, 1}, {1, 1, 0}, {2, 2, 0}};
    float x[3 * 9 * 7], wt[5 * 3 * 3 * 3], b[5], y[5 * 9 * 7], ref[5 * 9 * 7];
    fill(x, sizeof x / sizeof *x, 1);
    fill(wt, sizeof wt / sizeof *wt, 2);
    fill(b, 5, 3);
    for (int i = 0; i < 4; i++) {
        int k = cases[i][0], s = cases[i][1], p = cases[i][2];
        size_t n = (size_t)cout * g3d_nn_conv_out(h, k, s, p) * g3d_nn_conv_out(w, k, s, p);
        for (int with_bias = 0; with_bias < 2; with_bias++) {
            CHECK_OK(g3d_nn_conv2d(x, cin, h, w, wt, with_bias ? b : NULL, cout, k, s, p, y));
            conv_ref(x, cin, h, w, wt, with_bias ? b : NULL, cout, k, s, p, ref);
            CHECK_MSG(max_abs_diff(y, ref, n) < 1e-5, "k %d s %d p %d bias %d", k, s, p, with_bias);
        }
    }
    CHECK_FAILS(g3d_nn_conv2d(x, cin, 1, 1, wt, b, cout, 3, 1, 0, y));
    /* inputs narrower than the kernel: most taps fall in the padding */
    for (int s = 1; s <= 2; s++) {
        CHECK_OK(g3d_nn_conv2d(x, cin, 1, 2, wt, b, cout, 3, s, 1, y));
        conv_ref(x, cin, 1, 2, wt, b, cout, 3, s, 1, ref);
        CHECK(max_abs_diff(y, ref, (size_t)cout * g3d_nn_conv_out(2, 3, s, 1)) < 1e-5);
    }
}

TEST(conv2d_wide_image)
{
    /* 8000 output pixels: many column tiles, output rows crossing the packed panels */
    const int cin = 64, cout = 2, h = 8, w = 1000;
    size_t nx = (size_t)cin * h * w, ny = (size_t)cout * h * w;
    float *x = malloc(sizeof(float) * nx), *wt = malloc(sizeof(float) * cout * cin * 9), *y = malloc(sizeof(float) * ny),
          *ref = malloc(sizeof(float) * ny), b[2] = {0.5f, -1};
    fill(x, nx, 8);
    fill(wt, (size_t)cout * cin * 9, 9);
    CHECK_OK(g3d_nn_conv2d(x, cin, h, w, wt, b, cout, 3, 1, 1, y));
    conv_ref(x, cin, h, w, wt, b, cout, 3, 1, 1, ref);
    CHECK(max_abs_diff(y, ref, ny) < 1e-4);
    free(x); free(wt); free(y); free(ref);
}

TEST(conv_transpose_matches_definition)
{
    const int cin = 4, cout = 3, h = 3, w = 5, k = 2;
    float x[4 * 3 * 5], wt[4 * 3 * 2 * 2], b[3], y[3 * 6 * 10];
    fill(x, sizeof x / sizeof *x, 4);
    fill(wt, sizeof wt / sizeof *wt, 5);
    fill(b, 3, 6);
    CHECK_OK(g3d_nn_conv_transpose2d(x, cin, h, w, wt, b, cout, k, y));
    double err = 0;
    for (int o = 0; o < cout; o++)
        for (int oy = 0; oy < h * k; oy++)
            for (int ox = 0; ox < w * k; ox++) {
                double acc = b[o];
                for (int c = 0; c < cin; c++)
                    acc += (double)x[(c * h + oy / k) * w + ox / k] * wt[((c * cout + o) * k + oy % k) * k + ox % k];
                err = fmax(err, fabs(acc - y[(o * h * k + oy) * w * k + ox]));
            }
    CHECK(err < 1e-5);
}

TEST(layernorm_gelu_relu)
{
    /* row [1,2,3,4]: mean 2.5, var 1.25 */
    const float x[] = {1, 2, 3, 4}, g[] = {1, 2, 1, 1}, b[] = {0, 0, 1, 0};
    float y[4];
    g3d_nn_layernorm(x, 1, 4, g, b, 1e-6f, y);
    double s = 1 / sqrt(1.25 + 1e-6);
    CHECK_NEAR(y[0], -1.5 * s, 1e-6);
    CHECK_NEAR(y[1], -1.0 * s, 1e-6);
    CHECK_NEAR(y[2], 0.5 * s + 1, 1e-6);
    CHECK_NEAR(y[3], 1.5 * s, 1e-6);
    float v[] = {-1, 0, 1, 2};
    g3d_nn_gelu(v, 4);
    CHECK_NEAR(v[0], -0.15865525, 1e-6);
    CHECK_NEAR(v[1], 0, 1e-7);
    CHECK_NEAR(v[2], 0.84134475, 1e-6);
    CHECK_NEAR(v[3], 1.95449974, 1e-6);
    float r[] = {-2, 3};
    g3d_nn_relu(r, 2);
    CHECK(r[0] == 0 && r[1] == 3);
}

TEST(attention_matches_definition)
{
    enum { N = 7, H = 2, HD = 3, D = H * HD };
    float qkv[N * 3 * D], out[N * D];
    fill(qkv, sizeof qkv / sizeof *qkv, 7);
    const float scale = 0.6f;
    CHECK_OK(g3d_nn_attention(qkv, N, H, HD, scale, out));
    double err = 0;
    for (int h = 0; h < H; h++)
        for (int i = 0; i < N; i++) {
            double p[N], sum = 0;
            for (int j = 0; j < N; j++) {
                double d = 0;
                for (int c = 0; c < HD; c++) d += (double)qkv[i * 3 * D + h * HD + c] * qkv[j * 3 * D + D + h * HD + c];
                p[j] = exp(d * scale);
                sum += p[j];
            }
            for (int c = 0; c < HD; c++) {
                double o = 0;
                for (int j = 0; j < N; j++) o += p[j] / sum * qkv[j * 3 * D + 2 * D + h * HD + c];
                err = fmax(err, fabs(o - out[i * D + h * HD + c]));
            }
        }
    CHECK(err < 1e-5);
}

int main(void)
{
    RUN(linear_small);
    RUN(conv2d_matches_definition);
    RUN(conv2d_wide_image);
    RUN(conv_transpose_matches_definition);
    RUN(layernorm_gelu_relu);
    RUN(attention_matches_definition);
    return test_summary();
}
