/* Stable Diffusion 1.5 benchmark: seconds per denoising step at 512 x 512 (the UNet on the 64 x 64
 * latent twice: unconditional and conditional, as a guided step runs it) and for the VAE decoding
 * to 512 x 512, with full-size random weights; the same with the official PyTorch modules
 * (bench/bench_sd_torch.py), alternating round by round, same threads: wall and CPU time (all
 * threads) of each, the medians of the rounds' ratios, the load average around the run; the
 * arithmetic rates against a plain sgemm of the UNet's first feed-forward shape measured in the
 * same run; peak memory. --vae times only the VAE decoding (the twin then builds only the VAE).
 * Run: cmake --build build --target bench_sd && nice ./build/bench_sd STABLEDIFFUSION_CHECKOUT
 *      [weights.safetensors (written by the PyTorch script when missing)] [rounds=1] [threads=2] [--vae] */
#include "gen3d/nn.h"
#include "gen3d/sd.h"
#include "bench_twin.h"

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

/* Figures of one run of the PyTorch twin: wall and CPU seconds, work, peak memory. */
typedef struct twin_figures {
    double unet, unet_cpu, vae, vae_cpu, gu, gv, peak;
} twin_figures;

/* Runs the PyTorch twin and reads its figures; 1 on success. */
static int torch_run(const char *checkout, int threads, const char *write, int vae_only, twin_figures *f)
{
    char cmd[2048];
    snprintf(cmd, sizeof cmd, "/usr/bin/python3 %s/bench/bench_sd_torch.py %s %d 1 %s%s%s 2>/dev/null", G3D_SOURCE_DIR,
             checkout, threads, write ? "--write " : "", write ? write : "", vae_only ? " --vae-only" : "");
    FILE *py = popen(cmd, "r");
    if (!py) return 0;
    char line[256];
    int got = 0;
    while (fgets(line, sizeof line, py)) {
        got += sscanf(line, "torch_unet_seconds %lf %lf", &f->unet, &f->unet_cpu) == 2;
        got += sscanf(line, "torch_vae_seconds %lf %lf", &f->vae, &f->vae_cpu) == 2;
        got += sscanf(line, "unet_gflop %lf", &f->gu) + sscanf(line, "vae_gflop %lf", &f->gv);
        got += sscanf(line, "torch_peak_gb %lf", &f->peak);
    }
    return pclose(py) == 0 && got == (vae_only && !write ? 3 : 5);
}

int main(int argc, char **argv)
{
    int vae_only = 0, na = 0;
    char *args[8];
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--vae")) vae_only = 1;
        else if (na < 8) args[na++] = argv[i];
    }
    if (na < 1) {
        fprintf(stderr, "usage: bench_sd STABLEDIFFUSION_CHECKOUT [weights.safetensors] [rounds] [threads] [--vae]\n");
        return 2;
    }
    g3d_process_setup(argv);
    const char *checkout = args[0], *weights = na > 1 ? args[1] : "/tmp/gen3d_bench_sd15.safetensors";
    int rounds = na > 2 ? atoi(args[2]) : 1, threads = na > 3 ? atoi(args[3]) : 2;
    if (rounds < 1 || rounds > 100) return 2;
    omp_set_num_threads(threads);
    twin_figures tf = {0};
    struct stat st;
    int have_torch = 1;
    if (stat(weights, &st) != 0) {
        printf("writing %s with the PyTorch script (random SD 1.5 weights)...\n", weights);
        fflush(stdout);
        have_torch = torch_run(checkout, threads, weights, 0, &tf);
    }
    g3d_ckpt *ck = NULL;
    g3d_sd_unet *unet = NULL;
    g3d_sd_vae *vae = NULL;
    double t0 = g3d_time_now();
    if (g3d_ckpt_open(weights, &ck) != G3D_OK || (!vae_only && g3d_sd_unet_load(ck, NULL, &unet) != G3D_OK) ||
        g3d_sd_vae_load(ck, &vae) != G3D_OK) {
        printf("load failed: %s\n", g3d_error_message());
        return 1;
    }
    char d[512];
    if (unet) printf("%s\n", g3d_sd_unet_describe(g3d_sd_unet_get_config(unet), d, sizeof d));
    printf("load: %.2f s\n", g3d_time_now() - t0);

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

    const double load0 = load_average();
    double step[100], step_cpu[100], dec[100], dec_cpu[100], rs[100], rsc[100], rv[100], rvc[100];
    for (int round = 0; round < rounds; round++) {
        if (!vae_only) {
            t0 = g3d_time_now();
            double c0 = cpu_seconds();
            for (int k = 0; k < 2; k++)
                if (g3d_sd_unet_forward(unet, x, h, w, 981.0f, ctx + k * 77 * 768, 77, out, NULL, NULL) != G3D_OK) {
                    printf("UNet failed: %s\n", g3d_error_message());
                    return 1;
                }
            step[round] = g3d_time_now() - t0, step_cpu[round] = cpu_seconds() - c0;
        }
        t0 = g3d_time_now();
        double c0 = cpu_seconds();
        if (g3d_sd_vae_decode(vae, x, h, w, rgb, NULL, NULL) != G3D_OK) {
            printf("VAE failed: %s\n", g3d_error_message());
            return 1;
        }
        dec[round] = g3d_time_now() - t0, dec_cpu[round] = cpu_seconds() - c0;
        if (!vae_only) printf("round %d: gen3d step %.2f s (CPU %.2f s)", round + 1, step[round], step_cpu[round]);
        else printf("round %d: gen3d", round + 1);
        printf(", VAE decode %.2f s (CPU %.2f s)\n", dec[round], dec_cpu[round]);
        fflush(stdout);
        if (have_torch && torch_run(checkout, threads, NULL, vae_only, &tf)) {
            if (!vae_only) {
                rs[round] = tf.unet / step[round], rsc[round] = tf.unet_cpu / step_cpu[round];
                printf("round %d: PyTorch step %.2f s (CPU %.2f s): %.2fx (CPU %.2fx)", round + 1, tf.unet, tf.unet_cpu,
                       rs[round], rsc[round]);
            } else {
                printf("round %d: PyTorch", round + 1);
            }
            rv[round] = tf.vae / dec[round], rvc[round] = tf.vae_cpu / dec_cpu[round];
            printf(", VAE decode %.2f s (CPU %.2f s): %.2fx (CPU %.2fx)\n", tf.vae, tf.vae_cpu, rv[round], rvc[round]);
        } else {
            have_torch = 0;
        }
        fflush(stdout);
    }
    const double load1 = load_average();
    printf("\nSD 1.5 at 512x512, %d threads (%s kernels), %d rounds, load average %.1f -> %.1f, medians:\n", threads,
           g3d_nn_isa_name(), rounds, load0, load1);
    const double ms = vae_only ? 0 : median(step, rounds), mv = median(dec, rounds);
    if (!vae_only) {
        printf("  denoising step (UNet x2): gen3d %.2f s (CPU %.2f s)", ms, median(step_cpu, rounds));
        if (tf.gu > 0) printf(" = %.1f GFLOP/s (%.2f of sgemm)", tf.gu / ms, tf.gu / ms / sgemm);
        if (have_torch) printf("; gen3d %.2fx faster than PyTorch (CPU %.2fx)", median(rs, rounds), median(rsc, rounds));
        printf("\n");
    }
    printf("  VAE decode: gen3d %.2f s (CPU %.2f s)", mv, median(dec_cpu, rounds));
    if (tf.gv > 0) printf(" = %.1f GFLOP/s (%.2f of sgemm)", tf.gv / mv, tf.gv / mv / sgemm);
    if (have_torch) printf("; gen3d %.2fx faster than PyTorch (CPU %.2fx)", median(rv, rounds), median(rvc, rounds));
    printf("\n");
    if (tf.gv > 0) printf("  work: UNet %.0f GFLOP per step, VAE %.0f GFLOP\n", tf.gu, tf.gv);
    printf("  peak memory: gen3d %.2f GB (the weights' mapping included)%s", peak_gb(), tf.peak > 0 ? "" : "\n");
    if (tf.peak > 0) printf(", PyTorch %.2f GB\n", tf.peak);
    free(x); free(ctx); free(out); free(rgb); free(a); free(b); free(c);
    g3d_sd_unet_free(unet);
    g3d_sd_vae_free(vae);
    g3d_ckpt_free(ck);
    return 0;
}
