/* Depth Anything V2 ViT-S benchmark: seconds per 518x518 prediction with 2 threads against the
 * same architecture in PyTorch (bench/bench_depth_torch.py, random weights) in the same run: the
 * two alternate one forward each per round, so a busy machine slows both alike. Per round: wall
 * and CPU time (all threads) of each, and gen3d's arithmetic rate as a fraction of a plain sgemm
 * of the backbone's MLP shape (OpenBLAS, the same threads) timed in that round. The summary gives
 * the medians of the rounds' ratios and the load average around the run.
 * Run: cmake --build build --target bench && nice ./build/bench_depth [rounds=5] [checkpoint]
 * (default: the seeded ViT-S weights of the golden reference; timing does not depend on values). */
#include "gen3d/depth_anything.h"
#include "bench_twin.h"

#include <cblas.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/wait.h>

static double conv_flops(int cout, int cin, int k, int ho, int wo) { return 2.0 * cout * cin * k * k * ho * wo; }

/* Multiply-adds x 2 of the ViT-S model on an s x s token grid (s = 37 at 518). */
static double vits_flops(int s)
{
    const double D = 384, M = 1536, n = (double)s * s + 1, np = (double)s * s;
    double f = 2 * np * 588 * D;
    f += 12 * (2 * n * D * 3 * D + 4 * n * n * D + 2 * n * D * D + 4 * n * D * M);
    const int oc[4] = {48, 96, 192, 384}, hs[4] = {4 * s, 2 * s, s, (s + 1) / 2};
    for (int i = 0; i < 4; i++) {
        f += 2 * np * D * oc[i] + conv_flops(64, oc[i], 3, hs[i], hs[i]);
        f += conv_flops(64, 64, 3, hs[i], hs[i]) * (i == 3 ? 2 : 4); /* residual units */
        int out = i ? hs[i - 1] : 2 * hs[0];
        f += conv_flops(64, 64, 1, out, out);
    }
    f += 2 * np * 48 * 48 * 16 + 2 * np * 96 * 96 * 4 + conv_flops(384, 384, 3, hs[3], hs[3]);
    f += conv_flops(32, 64, 3, 8 * s, 8 * s) + conv_flops(32, 32, 3, 14 * s, 14 * s) + conv_flops(1, 32, 1, 14 * s, 14 * s);
    return f;
}

/* OpenBLAS's rate (GFLOP/s) on one block's MLP product, [1370 x 384] x [384 x 1536], best of 3
 * (the library runs OpenBLAS single-threaded inside its own OpenMP team; here it has its threads). */
static double sgemm_rate(const float *a, const float *b, float *c)
{
    const int n = 1370, k = 384, mm = 1536;
    double tb = 1e30;
    for (int i = 0; i < 3; i++) {
        double t0 = g3d_time_now();
        cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, n, mm, k, 1.0f, a, k, b, mm, 0.0f, c, mm);
        double t = g3d_time_now() - t0;
        tb = t < tb ? t : tb;
    }
    return 2.0 * n * k * mm * 1e-9 / tb;
}

int main(int argc, char **argv)
{
    const int rounds = argc > 1 ? atoi(argv[1]) : 5;
    const char *path = argc > 2 ? argv[2] : G3D_SHARED_DIR "/golden/depth_anything_v2_vits/weights.safetensors";
    if (rounds < 1 || rounds > 100) {
        fprintf(stderr, "usage: bench_depth [rounds=5 (1..100)] [checkpoint]\n");
        return 2;
    }
    g3d_process_setup(argv);
    const int threads = 2, size = 518;
    omp_set_num_threads(threads);
    openblas_set_num_threads(threads);
    char *targv[] = {"/usr/bin/python3", G3D_SOURCE_DIR "/bench/bench_depth_torch.py", "518", "2", NULL};
    FILE *to = NULL, *from = NULL;
    pid_t py;
    if (twin_spawn(targv, &to, &from, &py)) return 1;
    g3d_dav2 *m;
    double t0 = g3d_time_now();
    if (g3d_dav2_load_file(path, &m) != G3D_OK) {
        fprintf(stderr, "load failed: %s\n", g3d_error_message());
        return 1;
    }
    printf("load: %.3f s\n", g3d_time_now() - t0);
    const size_t npx = (size_t)size * size;
    float *rgb = malloc(sizeof(float) * npx * 3), *depth = malloc(sizeof(float) * npx);
    g3d_rng r;
    g3d_rng_seed(&r, 1, 1);
    for (size_t i = 0; i < npx * 3; i++) rgb[i] = g3d_rng_float(&r);
    const int n = 1370, k = 384, mm = 1536;
    float *a = calloc((size_t)n * k, sizeof(float)), *b = calloc((size_t)k * mm, sizeof(float)), *c = malloc(sizeof(float) * (size_t)n * mm);
    const double gflop = vits_flops(size / 14) * 1e-9;
    /* one untimed pass of each: first-touch page faults, PyTorch's lazy set-up */
    double tt, ct;
    if (g3d_dav2_predict(m, rgb, size, size, size, depth, NULL) != G3D_OK || twin_round(to, from, &tt, &ct)) {
        fprintf(stderr, "warm-up failed: %s\n", g3d_error_message());
        return 1;
    }
    const double load0 = load_average();
    double wall_ratio[100], cpu_ratio[100], frac[100], walls[100], cpus[100];
    for (int i = 0; i < rounds; i++) {
        t0 = g3d_time_now();
        const double c0 = cpu_seconds();
        if (g3d_dav2_predict(m, rgb, size, size, size, depth, NULL) != G3D_OK) {
            fprintf(stderr, "predict failed: %s\n", g3d_error_message());
            return 1;
        }
        const double tg = g3d_time_now() - t0, cg = cpu_seconds() - c0, base = sgemm_rate(a, b, c);
        if (twin_round(to, from, &tt, &ct)) return 1;
        wall_ratio[i] = tt / tg, cpu_ratio[i] = ct / cg, frac[i] = gflop / tg / base, walls[i] = tg, cpus[i] = cg;
        printf("round %d: gen3d %.3f s (CPU %.3f s, %.1f GFLOP/s = %.2f of sgemm's %.1f), PyTorch %.3f s (CPU %.3f s): "
               "%.2fx (CPU %.2fx)\n", i + 1, tg, cg, gflop / tg, frac[i], base, tt, ct, wall_ratio[i], cpu_ratio[i]);
        fflush(stdout);
    }
    const double load1 = load_average();
    printf("Depth Anything V2 ViT-S %dx%d (%.1f GFLOP), %d threads, %d rounds, load average %.1f -> %.1f:\n"
           "  gen3d %.3f s (CPU %.3f s) per prediction (medians), %.2f of the same-round sgemm rate\n"
           "  gen3d is %.2fx faster than PyTorch in wall time, %.2fx in CPU time (medians of the rounds' ratios)\n",
           size, size, gflop, threads, rounds, load0, load1, median(walls, rounds), median(cpus, rounds),
           median(frac, rounds), median(wall_ratio, rounds), median(cpu_ratio, rounds));
    fclose(to);
    fclose(from);
    waitpid(py, NULL, 0);
    free(a); free(b); free(c); free(rgb); free(depth);
    g3d_dav2_free(m);
    return 0;
}
