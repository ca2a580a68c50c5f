/* Rasterizer speed: ms per forward+backward and forward-only frames/s on synthetic scenes, at the
 * sizes of OpenSplat's published CPU timings (same machine class), plus the same run on one
 * thread as the in-run baseline. */
#include "gen3d/raster.h"
#include "synthetic_scene.h"

#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* On one thread the process CPU time is the compute time even when the shared machine is
 * oversubscribed; with several threads it is wall time. */
static clockid_t g_clock = CLOCK_MONOTONIC;

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(g_clock, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

typedef struct result { double fb_ms, f_ms, layers; } result;

static result run(const g3d_gaussians *g, int W, int H, int reps)
{
    g3d_camera cam;
    cam.K = g3d_intrinsics_from_fov(60, W, H);
    cam.c2w = g3d_mat4_identity();
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    size_t np = (size_t)W * H;
    float *rgb = malloc(sizeof(float) * 3 * np), *al = malloc(sizeof(float) * np), *dep = malloc(sizeof(float) * np);
    float *d = malloc(sizeof(float) * 3 * np), *g2d = calloc((size_t)g->n, sizeof(float));
    int32_t *radii = malloc(sizeof(int32_t) * (size_t)g->n);
    for (size_t i = 0; i < 3 * np; i++) d[i] = (float)((i * 2654435761u) % 1000) / 1000.0f - 0.5f;
    g3d_gaussians gr;
    g3d_gaussians_create(&gr, g->n, g->sh_degree);
    g3d_raster_ws *ws;
    g3d_raster_ws_create(&ws);
    g3d_raster_fwd(ws, g, &cam, &s, rgb, al, dep, radii);   /* warm-up: buffers grow once */
    g3d_raster_bwd(ws, g, d, NULL, NULL, &gr, g2d);
    result r = {0, 0, 0};
    double t0 = now_ms();
    for (int i = 0; i < reps; i++) g3d_raster_fwd(ws, g, &cam, &s, rgb, al, dep, radii);
    r.f_ms = (now_ms() - t0) / reps;
    t0 = now_ms();
    for (int i = 0; i < reps; i++) {
        g3d_raster_fwd(ws, g, &cam, &s, rgb, al, dep, radii);
        g3d_raster_bwd(ws, g, d, NULL, NULL, &gr, g2d);
    }
    r.fb_ms = (now_ms() - t0) / reps;
    /* candidate layers: every visible Gaussian's 3-sigma square, as a multiple of the image */
    for (int64_t i = 0; i < g->n; i++) r.layers += radii[i] > 0 ? 4.0 * radii[i] * radii[i] : 0.0;
    r.layers /= (double)np;
    g3d_raster_ws_free(ws);
    g3d_gaussians_free(&gr);
    free(rgb); free(al); free(dep); free(d); free(g2d); free(radii);
    return r;
}

int main(void)
{
    const int sizes[2][2] = {{256, 192}, {512, 384}};
    const int counts[2] = {5000, 50000};
    /* OpenSplat CPU trainer, median ms per step (research/splatting.md section 3.4) */
    const double opensplat[2][2] = {{147, 311}, {677, 1035}};
    int threads = omp_get_max_threads();
    printf("threads: %d\n", threads);
    printf("fwd+bwd and fwd: wall ms on all threads; 1-thr cpu: CPU ms of the same on one thread\n");
    printf("%-9s %6s | %9s %9s %8s | %9s %7s | %s\n", "image", "N", "fwd+bwd", "1-thr cpu", "scaling",
           "fwd ms", "fwd fps", "layers | OpenSplat step / ours (1 thread)");
    for (int si = 0; si < 2; si++)
        for (int ci = 0; ci < 2; ci++) {
            g3d_gaussians g;
            synthetic_scene(&g, counts[ci]);
            int reps = si == 0 ? 10 : 4;
            omp_set_num_threads(1);
            g_clock = CLOCK_PROCESS_CPUTIME_ID;
            result r1 = run(&g, sizes[si][0], sizes[si][1], reps);
            omp_set_num_threads(threads);
            g_clock = CLOCK_MONOTONIC;
            result r = run(&g, sizes[si][0], sizes[si][1], reps);
            printf("%4dx%-4d %6d | %7.2fms %7.2fms %7.2fx | %7.2fms %7.1f | %6.1f | %.1fx\n", sizes[si][0],
                   sizes[si][1], counts[ci], r.fb_ms, r1.fb_ms, r1.fb_ms / r.fb_ms, r.f_ms, 1e3 / r.f_ms, r.layers,
                   opensplat[si][ci] / r1.fb_ms);
            g3d_gaussians_free(&g);
        }
    return 0;
}
