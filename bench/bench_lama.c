/* LaMa benchmark: seconds per 512x512 big-lama forward pass with 2 threads, against the
 * official PyTorch generator (bench/bench_lama_torch.py) in the same run: the twin builds the
 * generator with random weights and saves them, this program loads that file, and the two
 * then alternate one forward each per round (so a busy machine slows both alike). Wall time
 * and CPU time (all threads) are reported: on a shared machine the wall time of one pass moves
 * by tens of percent, its CPU time much less. The summary ratio is the median of the rounds'.
 * Run: cmake --build build --target bench && nice ./build/bench_lama LAMA_CHECKOUT [rounds=5] [size=512]
 * (LAMA_CHECKOUT: github.com/advimman/lama at 786f593; /usr/bin/python3 with torch). */
#include "gen3d/lama.h"
#include "bench_twin.h"
#include "gen3d/nn.h"

#include <omp.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: bench_lama LAMA_CHECKOUT [rounds=5] [size=512]\n");
        return 2;
    }
    g3d_process_setup(argv);
    const int threads = 2, rounds = argc > 2 ? atoi(argv[2]) : 5, size = argc > 3 ? atoi(argv[3]) : 512;
    omp_set_num_threads(threads);
    char sz[16], th[16], save[32];
    snprintf(sz, sizeof sz, "%d", size);
    snprintf(th, sizeof th, "%d", threads);
    const char *args[] = {sz, th, NULL};
    FILE *to = NULL, *from = NULL;
    pid_t py;
    if (twin_start(G3D_SOURCE_DIR "/bench/bench_lama_torch.py", argv[1], args, save, &to, &from, &py)) return 1;
    g3d_lama *m = NULL;
    double t0 = g3d_time_now();
    g3d_status rc = g3d_lama_load_file(save, &m);
    unlink(save);
    if (rc != G3D_OK) {
        fprintf(stderr, "load failed: %s\n", g3d_error_message());
        return 1;
    }
    char desc[256];
    printf("%s\nload (BatchNorm folding, kernel preparation): %.2f s\n", g3d_lama_describe(m, desc, sizeof desc),
           g3d_time_now() - t0);
    const size_t n = (size_t)size * size;
    float *x = malloc(sizeof(float) * 4 * n), *y = malloc(sizeof(float) * 3 * n);
    g3d_rng r;
    g3d_rng_seed(&r, 1, 1);
    for (size_t i = 0; i < 4 * n; i++) x[i] = g3d_rng_float(&r);
    for (size_t i = 3 * n; i < 4 * n; i++) x[i] = x[i] > 0.5f;
    /* a first pass of each plans the FFTs and fills the arena; not timed */
    rc = g3d_lama_forward(m, x, size, size, y, NULL, NULL);
    double tt = 0, ct = 0;
    if (rc != G3D_OK || twin_round(to, from, &tt, &ct)) {
        fprintf(stderr, "warm-up failed: %s\n", rc != G3D_OK ? g3d_error_message() : "no answer from the twin");
        return 1;
    }
    if (rounds < 1 || rounds > 100) return 2;
    double wall_ratio[100], cpu_ratio[100], sum_c = 0, sum_t = 0;
    const double load0 = load_average();
    for (int k = 0; k < rounds; k++) {
        t0 = g3d_time_now();
        const double c0 = cpu_seconds();
        if (g3d_lama_forward(m, x, size, size, y, NULL, NULL) != G3D_OK) return 1;
        double tc = g3d_time_now() - t0, cc = cpu_seconds() - c0;
        if (twin_round(to, from, &tt, &ct)) return 1;
        printf("round %d: gen3d %.3f s (CPU %.3f s), PyTorch %.3f s (CPU %.3f s): %.2fx (CPU %.2fx)\n", k + 1, tc, cc, tt,
               ct, tt / tc, ct / cc);
        fflush(stdout);
        wall_ratio[k] = tt / tc;
        cpu_ratio[k] = ct / cc;
        sum_c += tc;
        sum_t += tt;
    }
    const double load1 = load_average();
    printf("big-lama %dx%d, %d threads, %d rounds, load average %.1f -> %.1f: gen3d %.3f s, PyTorch %.3f s per forward "
           "(means); gen3d is %.2fx faster (median of the rounds; CPU time %.2fx)\n", size, size, threads, rounds, load0,
           load1, sum_c / rounds, sum_t / rounds, median(wall_ratio, rounds), median(cpu_ratio, rounds));
    fclose(to);
    fclose(from);
    waitpid(py, NULL, 0);
    free(x);
    free(y);
    g3d_lama_free(m);
    return 0;
}
