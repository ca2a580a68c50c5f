/* Training speed: milliseconds per full iteration (rasterizer forward, masked L1 + SSIM loss
 * forward and backward, rasterizer backward, Adam) on synthetic scenes at the sizes of
 * OpenSplat's published CPU trainer timings on this class of 2-core machine, with a per-stage
 * breakdown and the ratio to those figures; render frames/s for the same scenes.
 * `bench_train WxH N` runs one row (any size; the ratio column only for the table's sizes). */
#include "gen3d/adam.h"
#include "gen3d/loss.h"
#include "gen3d/raster.h"
#include "synthetic_scene.h"

#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

enum { ST_FWD, ST_LOSS, ST_ZERO, ST_BWD, ST_ADAM, ST_COUNT };
static const char *STAGE[ST_COUNT] = {"fwd", "loss", "zero", "bwd", "adam"};

typedef struct result { double iter_ms, cpu_ms, stage_ms[ST_COUNT], render_fps; } result;

/* CPU seconds of the whole process: with OMP_WAIT_POLICY=passive (no spinning threads) the work
 * done, which other people's load on a shared machine does not inflate as it does wall time */
static double cpu_now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static result run(int n, int W, int H, int reps)
{
    g3d_gaussians g, grads;
    synthetic_scene(&g, n);
    g3d_gaussians_create(&grads, n, 3);
    grads.n = n;
    g3d_camera cam;
    cam.K = g3d_intrinsics_from_fov(60, W, H);
    cam.c2w = g3d_mat4_identity();
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    size_t np = (size_t)W * H;
    g3d_image target, pred, dpred;
    g3d_image_create(&target, W, H, 3);
    g3d_image_create(&pred, W, H, 3);
    g3d_image_create(&dpred, W, H, 3);
    for (size_t i = 0; i < 3 * np; i++) target.data[i] = (float)((i * 2654435761u) % 1000) / 1000.0f;
    float *g2d = calloc((size_t)n, sizeof(float));
    int32_t *radii = malloc(sizeof(int32_t) * (size_t)n);
    g3d_adam adam;
    g3d_adam_params ap;
    g3d_adam_params_default(&ap);
    g3d_adam_init(&adam, &ap, &g);
    g3d_raster_ws *ws;
    g3d_raster_ws_create(&ws);
    result r;
    memset(&r, 0, sizeof r);
    double cpu0 = 0;
    for (int it = -1; it < reps; it++) {   /* iteration -1 warms the buffers up */
        if (it == 0) cpu0 = cpu_now();
        double t[ST_COUNT + 1];
        t[0] = g3d_time_now();
        g3d_raster_fwd(ws, &g, &cam, &s, pred.data, NULL, NULL, radii);
        t[1] = g3d_time_now();
        double loss;
        g3d_loss_fwd_bwd(&pred, &target, NULL, 0.2, &loss, NULL, &dpred);
        t[2] = g3d_time_now();
        size_t K3 = 48;
        memset(grads.means, 0, sizeof(float) * 3 * (size_t)n);
        memset(grads.log_scales, 0, sizeof(float) * 3 * (size_t)n);
        memset(grads.rots, 0, sizeof(float) * 4 * (size_t)n);
        memset(grads.opacity_logits, 0, sizeof(float) * (size_t)n);
        memset(grads.sh, 0, sizeof(float) * K3 * (size_t)n);
        memset(g2d, 0, sizeof(float) * (size_t)n);
        t[3] = g3d_time_now();
        g3d_raster_bwd(ws, &g, dpred.data, NULL, NULL, &grads, g2d);
        t[4] = g3d_time_now();
        g3d_adam_step(&adam, &g, &grads, 5.0);
        t[5] = g3d_time_now();
        if (it < 0) continue;
        for (int k = 0; k < ST_COUNT; k++) r.stage_ms[k] += (t[k + 1] - t[k]) * 1e3 / reps;
        r.iter_ms += (t[ST_COUNT] - t[0]) * 1e3 / reps;
    }
    r.cpu_ms = (cpu_now() - cpu0) * 1e3 / reps;
    double t0 = g3d_time_now();
    for (int i = 0; i < reps; i++) g3d_raster_fwd(ws, &g, &cam, &s, pred.data, NULL, NULL, NULL);
    r.render_fps = reps / (g3d_time_now() - t0);
    g3d_raster_ws_free(ws);
    g3d_adam_free(&adam);
    g3d_gaussians_free(&g);
    g3d_gaussians_free(&grads);
    g3d_image_free(&target);
    g3d_image_free(&pred);
    g3d_image_free(&dpred);
    free(g2d);
    free(radii);
    return r;
}

int main(int argc, char **argv)
{
    g3d_process_setup(argv);
    const int sizes[2][2] = {{256, 192}, {512, 384}};
    const int counts[2] = {5000, 50000};
    /* OpenSplat's CPU trainer (libtorch), ms per iteration on this class of 2-core machine */
    const double opensplat[2][2] = {{147, 311}, {677, 1035}};
    int only_w = 0, only_h = 0, only_n = 0;
    if ((argc != 1 && argc != 3) ||
        (argc == 3 && (sscanf(argv[1], "%dx%d", &only_w, &only_h) != 2 || sscanf(argv[2], "%d", &only_n) != 1 ||
                       only_w < 16 || only_h < 16 || only_n < 1))) {
        fprintf(stderr, "usage: bench_train [WxH N]\n");
        return 2;
    }
    printf("threads: %d; SH degree 3; mean of 20 iterations after a warm-up\n", omp_get_max_threads());
    printf("%-9s %6s | %9s | %9s | %-44s | %9s | %s\n", "image", "N", "ms/iter", "cpu ms", "fwd / loss / zero / bwd / adam (ms)",
           "render", "OpenSplat ms/iter / ours");
    for (int si = 0; si < 3; si++)
        for (int ci = 0; ci < 2; ci++) {
            const int W = si < 2 ? sizes[si][0] : only_w, H = si < 2 ? sizes[si][1] : only_h;
            const int N = si < 2 ? counts[ci] : only_n;
            if (only_n ? si < 2 || ci > 0 : si == 2) continue;
            int known = -1;
            for (int k = 0; k < 4; k++)
                if (W == sizes[k / 2][0] && H == sizes[k / 2][1] && N == counts[k % 2]) known = k;
            result r = run(N, W, H, 20);
            char st[128], ratio[16] = "-";
            int k = 0;
            for (int s = 0; s < ST_COUNT; s++)
                k += snprintf(st + k, sizeof st - k, "%s%.1f", s ? " / " : "", r.stage_ms[s]);
            if (known >= 0) snprintf(ratio, sizeof ratio, "%.1fx", opensplat[known / 2][known % 2] / r.iter_ms);
            printf("%4dx%-4d %6d | %7.1fms | %7.1fms | %-44s | %5.1f fps | %s\n", W, H, N, r.iter_ms, r.cpu_ms, st,
                   r.render_fps, ratio);
        }
    printf("stages: %s", STAGE[0]);
    for (int s = 1; s < ST_COUNT; s++) printf(", %s", STAGE[s]);
    printf(" (zero = clearing the gradient buffers); cpu ms: CPU time of all threads per iteration\n");
    return 0;
}
