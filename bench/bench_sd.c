/* Stable Diffusion 1.5 benchmark: seconds per denoising step at 512 x 512 (the UNet on the 64 x 64
 * latent twice: unconditional and conditional, as a guided step runs it) and for the VAE decoding
 * to 512 x 512, with full-size random weights; the same with the official PyTorch modules
 * (bench/bench_sd_torch.py), alternating, same threads; the arithmetic rates against a plain
 * sgemm of the UNet's first feed-forward shape measured in the same run; peak memory.
 * Run: cmake --build build --target bench_sd && nice ./build/bench_sd STABLEDIFFUSION_CHECKOUT
 *      [weights.safetensors (written by the PyTorch script when missing)] [rounds=1] [threads=2] */
#include "gen3d/nn.h"
#include "gen3d/sd.h"

#include <cblas.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>

static double peak_gb(void)
{
    struct rusage u;
    getrusage(RUSAGE_SELF, &u);
    return u.ru_maxrss / 1048576.0;
}

/* Runs the PyTorch twin and reads its figures. */
static int torch_run(const char *checkout, int threads, const char *write, double *unet, double *vae, double *gu, double *gv, double *peak)
{
    char cmd[2048];
    snprintf(cmd, sizeof cmd, "/usr/bin/python3 %s/bench/bench_sd_torch.py %s %d 1 %s%s 2>/dev/null", G3D_SOURCE_DIR, checkout, threads,
             write ? "--write " : "", write ? write : "");
    FILE *py = popen(cmd, "r");
    if (!py) return 0;
    char line[256];
    int got = 0;
    while (fgets(line, sizeof line, py)) {
        got += sscanf(line, "torch_unet_seconds %lf", unet) + sscanf(line, "torch_vae_seconds %lf", vae);
        got += sscanf(line, "unet_gflop %lf", gu) + sscanf(line, "vae_gflop %lf", gv) + sscanf(line, "torch_peak_gb %lf", peak);
    }
    return pclose(py) == 0 && got == 5;
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: bench_sd STABLEDIFFUSION_CHECKOUT [weights.safetensors] [rounds] [threads]\n");
        return 2;
    }
    g3d_process_setup(argv);
    const char *checkout = argv[1], *weights = argc > 2 ? argv[2] : "/tmp/gen3d_bench_sd15.safetensors";
    int rounds = argc > 3 ? atoi(argv[3]) : 1, threads = argc > 4 ? atoi(argv[4]) : 2;
    omp_set_num_threads(threads);
    double tu = 0, tv = 0, gu = 0, gv = 0, tpeak = 0;
    struct stat st;
    int have_torch = 1;
    if (stat(weights, &st) != 0) {
        printf("writing %s with the PyTorch script (random SD 1.5 weights)...\n", weights);
        fflush(stdout);
        have_torch = torch_run(checkout, threads, weights, &tu, &tv, &gu, &gv, &tpeak);
    }
    g3d_ckpt *ck = NULL;
    g3d_sd_unet *unet = NULL;
    g3d_sd_vae *vae = NULL;
    double t0 = g3d_time_now();
    if (g3d_ckpt_open(weights, &ck) != G3D_OK || g3d_sd_unet_load(ck, NULL, &unet) != G3D_OK || g3d_sd_vae_load(ck, &vae) != G3D_OK) {
        printf("load failed: %s\n", g3d_error_message());
        return 1;
    }
    char d[512];
    printf("%s\nload: %.2f s\n", g3d_sd_unet_describe(g3d_sd_unet_get_config(unet), d, sizeof d), g3d_time_now() - t0);

    const int h = 64, w = 64, n = 4 * h * w;
    float *x = malloc(sizeof(float) * n), *ctx = malloc(sizeof(float) * 2 * 77 * 768), *out = malloc(sizeof(float) * n);
    float *rgb = malloc(sizeof(float) * 3 * 512 * 512);
    g3d_rng r;
    g3d_rng_seed(&r, 1, 1);
    for (int i = 0; i < n; i++) x[i] = g3d_rng_normal(&r);
    for (int i = 0; i < 2 * 77 * 768; i++) ctx[i] = g3d_rng_normal(&r);

    /* the baseline: [4096 x 320] x [320 x 2560], level 0's GEGLU projection, on OpenBLAS's threads */
    openblas_set_num_threads(threads);
    const int bm = 4096, bk = 320, bn = 2560;
    float *a = calloc((size_t)bm * bk, sizeof(float)), *b = calloc((size_t)bk * bn, sizeof(float)), *c = malloc(sizeof(float) * (size_t)bm * bn);
    double tb = 1e30;
    for (int i = 0; i < 5; i++) {
        t0 = g3d_time_now();
        cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, bm, bn, bk, 1.0f, a, bk, b, bn, 0.0f, c, bn);
        double t = g3d_time_now() - t0;
        tb = t < tb ? t : tb;
    }
    double sgemm = 2.0 * bm * bk * bn * 1e-9 / tb;
    printf("sgemm %dx%dx%d, %d threads: %.1f GFLOP/s\n", bm, bk, bn, threads, sgemm);

    double best_step = 1e30, best_vae = 1e30;
    for (int round = 0; round < rounds; round++) {
        t0 = g3d_time_now();
        for (int k = 0; k < 2; k++)
            if (g3d_sd_unet_forward(unet, x, h, w, 981.0f, ctx + k * 77 * 768, 77, out, NULL, NULL) != G3D_OK) {
                printf("UNet failed: %s\n", g3d_error_message());
                return 1;
            }
        double ts = g3d_time_now() - t0;
        t0 = g3d_time_now();
        if (g3d_sd_vae_decode(vae, x, h, w, rgb, NULL, NULL) != G3D_OK) {
            printf("VAE failed: %s\n", g3d_error_message());
            return 1;
        }
        double tvae = g3d_time_now() - t0;
        best_step = ts < best_step ? ts : best_step;
        best_vae = tvae < best_vae ? tvae : best_vae;
        printf("round %d: gen3d step %.2f s, VAE decode %.2f s\n", round + 1, ts, tvae);
        fflush(stdout);
        double u, v;
        if (have_torch && torch_run(checkout, threads, NULL, &u, &v, &gu, &gv, &tpeak)) {
            tu = tu > 0 && tu < u ? tu : u;
            tv = tv > 0 && tv < v ? tv : v;
            printf("round %d: PyTorch step %.2f s, VAE decode %.2f s\n", round + 1, u, v);
        } else {
            have_torch = 0;
        }
        fflush(stdout);
    }
    printf("\nSD 1.5 at 512x512, %d threads (%s kernels), best of %d:\n", threads, g3d_nn_isa_name(), rounds);
    if (gu > 0) {
        printf("  denoising step (UNet x2): gen3d %.2f s = %.1f GFLOP/s (%.2f of sgemm)", best_step, gu / best_step, gu / best_step / sgemm);
        if (tu > 0) printf("; PyTorch %.2f s = %.1f GFLOP/s; gen3d %.2fx faster", tu, gu / tu, tu / best_step);
        printf("\n  VAE decode: gen3d %.2f s = %.1f GFLOP/s (%.2f of sgemm)", best_vae, gv / best_vae, gv / best_vae / sgemm);
        if (tv > 0) printf("; PyTorch %.2f s; gen3d %.2fx faster", tv, tv / best_vae);
        printf("\n  work: UNet %.0f GFLOP per step, VAE %.0f GFLOP\n", gu, gv);
    } else {
        printf("  denoising step %.2f s, VAE decode %.2f s (no PyTorch figures)\n", best_step, best_vae);
    }
    printf("  peak memory: gen3d %.2f GB (the weights' mapping included)%s", peak_gb(), tpeak > 0 ? "" : "\n");
    if (tpeak > 0) printf(", PyTorch %.2f GB\n", tpeak);
    free(x); free(ctx); free(out); free(rgb); free(a); free(b); free(c);
    g3d_sd_unet_free(unet);
    g3d_sd_vae_free(vae);
    g3d_ckpt_free(ck);
    return 0;
}
