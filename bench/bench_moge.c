/* MoGe-2 benchmark: seconds per forward pass and per full inference (forward + focal/shift
 * fit + re-projection) on a 640x480 image at several token counts, with 2 threads, next to the
 * DINOv2 backbone alone on the same token grid measured in the same run (the part the neck and
 * heads add is the ratio minus one).
 * With --twin, instead: the forward pass against the official MoGe-2 code in PyTorch built from
 * the same checkpoint (bench/bench_moge_torch.py), alternating one forward each per round, 2
 * threads each; wall and CPU time of each, the medians of the rounds' ratios, the load average.
 * Run: cmake --build build --target bench && ./build/bench_moge [model.pt]
 *      ./build/bench_moge --twin MOGE_CHECKOUT UTILS3D_CHECKOUT [rounds=5] [tokens=2500] [model.pt]
 * (default model: the seeded ViT-S-sized golden checkpoint; timing does not depend on the values). */
#include "gen3d/dinov2.h"
#include "gen3d/moge.h"
#include "bench_twin.h"

#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define DEFAULT_MODEL G3D_SHARED_DIR "/golden/moge2_vits_config/model.pt"

static int twin(int argc, char **argv)
{
    if (argc < 4) {
        fprintf(stderr, "usage: bench_moge --twin MOGE_CHECKOUT UTILS3D_CHECKOUT [rounds=5] [tokens=2500] [model.pt]\n");
        return 2;
    }
    const int rounds = argc > 4 ? atoi(argv[4]) : 5, tokens = argc > 5 ? atoi(argv[5]) : 2500, w = 640, h = 480;
    const char *path = argc > 6 ? argv[6] : DEFAULT_MODEL;
    if (rounds < 1 || rounds > 100 || tokens < 1) {
        fprintf(stderr, "bench_moge: rounds must be 1..100 and tokens positive\n");
        return 2;
    }
    char tok[16];
    snprintf(tok, sizeof tok, "%d", tokens);
    char *targv[] = {"/usr/bin/python3", G3D_SOURCE_DIR "/bench/bench_moge_torch.py", argv[2], argv[3], (char *)path,
                     tok, "2", "640", "480", NULL};
    FILE *to = NULL, *from = NULL;
    pid_t py;
    if (twin_spawn(targv, &to, &from, &py)) return 1;
    omp_set_num_threads(2);
    g3d_ckpt *ck = NULL;
    g3d_moge *m = NULL;
    if (g3d_ckpt_open(path, &ck) != G3D_OK || g3d_moge_load(ck, &m) != G3D_OK) {
        fprintf(stderr, "load failed: %s\n", g3d_error_message());
        return 1;
    }
    float *rgb = malloc(sizeof(float) * (size_t)w * h * 3);
    g3d_rng r;
    g3d_rng_seed(&r, 1, 1);
    for (long i = 0; i < (long)w * h * 3; i++) rgb[i] = g3d_rng_float(&r);
    double walls[100], cpus[100], wr[100], cr[100], tt, ct;
    g3d_moge_output o;
    /* one untimed pass of each: first-touch page faults, PyTorch's lazy set-up */
    if (g3d_moge_forward(m, rgb, w, h, tokens, &o, NULL) != G3D_OK || twin_round(to, from, &tt, &ct)) {
        fprintf(stderr, "warm-up failed: %s\n", g3d_error_message());
        return 1;
    }
    g3d_moge_output_free(&o);
    const double load0 = load_average();
    for (int i = 0; i < rounds; i++) {
        const double t0 = g3d_time_now(), c0 = cpu_seconds();
        if (g3d_moge_forward(m, rgb, w, h, tokens, &o, NULL) != G3D_OK) {
            fprintf(stderr, "forward failed: %s\n", g3d_error_message());
            return 1;
        }
        walls[i] = g3d_time_now() - t0, cpus[i] = cpu_seconds() - c0;
        g3d_moge_output_free(&o);
        if (twin_round(to, from, &tt, &ct)) return 1;
        wr[i] = tt / walls[i], cr[i] = ct / cpus[i];
        printf("round %d: gen3d %.3f s (CPU %.3f s), PyTorch %.3f s (CPU %.3f s): %.2fx (CPU %.2fx)\n", i + 1, walls[i],
               cpus[i], tt, ct, wr[i], cr[i]);
        fflush(stdout);
    }
    const double load1 = load_average();
    printf("MoGe-2 forward, %dx%d at %d tokens, 2 threads, %d rounds, load average %.1f -> %.1f:\n"
           "  gen3d %.3f s (CPU %.3f s) per forward (medians)\n"
           "  gen3d is %.2fx faster than PyTorch in wall time, %.2fx in CPU time (medians of the rounds' ratios)\n",
           w, h, tokens, rounds, load0, load1, median(walls, rounds), median(cpus, rounds), median(wr, rounds),
           median(cr, rounds));
    twin_stop(to, from, py);
    free(rgb);
    g3d_moge_free(m);
    g3d_ckpt_free(ck);
    return 0;
}

int main(int argc, char **argv)
{
    g3d_process_setup(argv);
    if (argc > 1 && !strcmp(argv[1], "--twin")) return twin(argc, argv);
    const char *path = argc > 1 ? argv[1] : DEFAULT_MODEL;
    const int threads = 2, w = 640, h = 480, reps = 2;
    static const int tokens[] = {600, 1200, 2500, 3600};
    omp_set_num_threads(threads);
    g3d_ckpt *ck = NULL;
    g3d_moge *m = NULL;
    g3d_dinov2 *bb = NULL;
    double t0 = g3d_time_now();
    if (g3d_ckpt_open(path, &ck) != G3D_OK || g3d_moge_load(ck, &m) != G3D_OK ||
        g3d_dinov2_load(ck, "encoder.backbone.", &bb) != G3D_OK) {
        printf("load failed: %s\n", g3d_error_message());
        return 1;
    }
    char desc[200];
    printf("%s\nload: %.3f s\n", g3d_moge_describe(m, desc, sizeof desc), g3d_time_now() - t0);
    size_t npx = (size_t)w * h;
    float *rgb = malloc(sizeof(float) * npx * 3);
    g3d_rng r;
    g3d_rng_seed(&r, 1, 1);
    for (size_t i = 0; i < npx * 3; i++) rgb[i] = g3d_rng_float(&r);
    for (int k = 0; k < 4; k++) {
        double tf = 1e30, ti = 1e30, tb = 1e30;
        int rows = (int)nearbyint(sqrt(tokens[k] / ((double)w / h))), cols = (int)nearbyint(sqrt(tokens[k] * ((double)w / h)));
        float *x = calloc((size_t)3 * 14 * rows * 14 * cols, sizeof(float));
        for (int i = 0; i < reps; i++) {
            g3d_moge_output o;
            g3d_moge_result res;
            t0 = g3d_time_now();
            if (g3d_moge_forward(m, rgb, w, h, tokens[k], &o, NULL) != G3D_OK) return printf("%s\n", g3d_error_message()), 1;
            tf = fmin(tf, g3d_time_now() - t0);
            g3d_moge_output_free(&o);
            t0 = g3d_time_now();
            if (g3d_moge_infer(m, rgb, w, h, tokens[k], 0, &res) != G3D_OK) return printf("%s\n", g3d_error_message()), 1;
            ti = fmin(ti, g3d_time_now() - t0);
            g3d_moge_result_free(&res);
            /* baseline: the backbone alone, blocks 2, 5, 8, 11 out (the encoder's own request) */
            static const int layers[4] = {2, 5, 8, 11};
            float *f[4], *c[4];
            t0 = g3d_time_now();
            if (g3d_dinov2_forward(bb, x, 14 * rows, 14 * cols, layers, 4, f, c, NULL) != G3D_OK)
                return printf("%s\n", g3d_error_message()), 1;
            tb = fmin(tb, g3d_time_now() - t0);
            for (int j = 0; j < 4; j++) free(f[j]), free(c[j]);
        }
        free(x);
        printf("%4d tokens (%2dx%2d): forward %.3f s, infer %.3f s; backbone alone %.3f s -> forward/backbone %.2f\n",
               tokens[k], cols, rows, tf, ti, tb, tf / tb);
    }
    free(rgb);
    g3d_dinov2_free(bb);
    g3d_moge_free(m);
    g3d_ckpt_free(ck);
    return 0;
}
