/* Segment Anything benchmark: seconds per ViT-B image encoding at 1024x1024 with 2 threads,
 * against the official PyTorch encoder (bench/bench_sam_torch.py) in the same run: the twin
 * builds the model with random weights and saves them, this program loads that file, and the two
 * then alternate one forward each per round (so a busy machine slows both alike). Wall time and
 * CPU time (all threads) are reported; the summary ratio is the median of the rounds'. gen3d's
 * time includes the preprocessing of a 1024x1024 picture (resize, normalisation).
 * Run: cmake --build build --target bench && nice ./build/bench_sam SAM_CHECKOUT [rounds=3]
 * (SAM_CHECKOUT: github.com/facebookresearch/segment-anything at dca509f; /usr/bin/python3 with torch). */
#include "bench_twin.h"
#include "gen3d/nn.h"
#include "gen3d/sam.h"

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
        fprintf(stderr, "usage: bench_sam SAM_CHECKOUT [rounds=3]\n");
        return 2;
    }
    g3d_process_setup(argv);
    const int threads = 2, rounds = argc > 2 ? atoi(argv[2]) : 3, size = 1024;
    if (rounds < 1 || rounds > 100) return 2;
    omp_set_num_threads(threads);
    char th[16], save[32];
    snprintf(th, sizeof th, "%d", threads);
    const char *args[] = {th, NULL};
    FILE *to = NULL, *from = NULL;
    pid_t py;
    if (twin_start(G3D_SOURCE_DIR "/bench/bench_sam_torch.py", argv[1], args, save, &to, &from, &py)) return 1;
    g3d_sam *m = NULL;
    double t0 = g3d_time_now();
    g3d_status rc = g3d_sam_load_file(save, &m);
    unlink(save);
    if (rc != G3D_OK) {
        fprintf(stderr, "load failed: %s\n", g3d_error_message());
        return 1;
    }
    char desc[256];
    printf("%s\nload: %.2f s\n", g3d_sam_describe(m, desc, sizeof desc), g3d_time_now() - t0);
    const size_t n = (size_t)size * size * 3;
    uint8_t *px = malloc(n);
    g3d_rng r;
    g3d_rng_seed(&r, 1, 1);
    for (size_t i = 0; i < n; i++) px[i] = (uint8_t)(g3d_rng_float(&r) * 255.0f);
    double wall_ratio[100], cpu_ratio[100], sum_c = 0, sum_t = 0;
    for (int k = 0; k < rounds; k++) {
        g3d_sam_image img;
        t0 = g3d_time_now();
        const double c0 = cpu_seconds();
        if (g3d_sam_set_image(m, px, size, size, &img, NULL) != G3D_OK) {
            fprintf(stderr, "encoding failed: %s\n", g3d_error_message());
            return 1;
        }
        double tc = g3d_time_now() - t0, cc = cpu_seconds() - c0, tt = 0, ct = 0;
        g3d_sam_image_free(&img);
        if (twin_round(to, from, &tt, &ct)) return 1;
        printf("round %d: gen3d %.3f s (CPU %.3f s), PyTorch %.3f s (CPU %.3f s): %.2fx (CPU %.2fx)\n", k + 1, tc, cc, tt,
               ct, tt / tc, ct / cc);
        fflush(stdout);
        wall_ratio[k] = tt / tc;
        cpu_ratio[k] = ct / cc;
        sum_c += tc;
        sum_t += tt;
    }
    printf("SAM ViT-B image encoder %dx%d, %d threads, %d rounds: gen3d %.3f s, PyTorch %.3f s per image (means); "
           "gen3d is %.2fx faster (median of the rounds; CPU time %.2fx)\n", size, size, threads, rounds, sum_c / rounds,
           sum_t / rounds, median(wall_ratio, rounds), median(cpu_ratio, rounds));
    fclose(to);
    fclose(from);
    waitpid(py, NULL, 0);
    free(px);
    g3d_sam_free(m);
    return 0;
}
