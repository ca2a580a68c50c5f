/* World generation benchmark: seconds per trajectory step split by stage, reprojection
 * throughput, final point count; on the default input (Middlebury) and the procedural room at
 * 512 px. Run: cmake --build build --target bench && ./build/bench_world [default-input-dir] */
#include "gen3d/depth_complete.h"
#include "gen3d/inpaint_classic.h"
#include "gen3d/procscene.h"
#include "gen3d/regions.h"
#include "gen3d/trajectory.h"
#include "gen3d/world.h"

#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void bench_frame(const char *label, const g3d_frame *f, const char *traj, int steps)
{
    g3d_mat4 *poses, *p2;
    int n;
    g3d_trajectory_params tp;
    g3d_trajectory_params_default(&tp);
    tp.steps = steps;
    tp.angle_deg = 20;
    if (g3d_trajectory_make(traj, &tp, g3d_depth_median(&f->depth), &poses, &n) != G3D_OK) return;
    if (n > steps + 1 && g3d_trajectory_pick(poses, n, steps + 1, &p2) == G3D_OK) {
        free(poses);
        poses = p2;
        n = steps + 1;
    }
    g3d_inpainter ip;
    g3d_mask_provider mp;
    g3d_depth_estimator de;
    g3d_depth_estimator_completion_create(&de);
    g3d_inpainter_classic_create(NULL, &ip);
    g3d_mask_provider_regions_create(NULL, f->cam.K, &mp);
    g3d_world_params wp;
    g3d_world_params_default(&wp);
    g3d_world w;
    g3d_layers L;
    double t0 = g3d_time_now();
    if (g3d_layers_compute(&f->rgb, &f->depth, &mp, &ip, &de, NULL, 1, &L) != G3D_OK ||
        g3d_world_generate(f, poses, n, &ip, &de, &L, &wp, 1, &w) != G3D_OK) {
        printf("%s: failed: %s\n", label, g3d_error_message());
        return;
    }
    double total = g3d_time_now() - t0, s[5] = {0};
    for (int i = 1; i < w.n_views; i++) {
        s[0] += w.steps[i].seconds_reproject; s[1] += w.steps[i].seconds_inpaint; s[2] += w.steps[i].seconds_depth;
        s[3] += w.steps[i].seconds_align; s[4] += w.steps[i].seconds_lift;
    }
    int k = w.n_views - 1;
    printf("%s, %dx%d, %s, %d steps, %d threads: %.2f s total (incl. layers and %d extra views)\n", label, f->rgb.w, f->rgb.h,
           traj, k, omp_get_max_threads(), total, w.n_extra);
    printf("  per step: reproject %.3f s, inpaint %.3f s, depth %.3f s, align %.3f s, lift %.3f s\n", s[0] / k, s[1] / k,
           s[2] / k, s[3] / k, s[4] / k);
    /* Reprojection throughput: render the final cloud into the last pose a few times. */
    g3d_image img, dep, msk;
    int reps = 5;
    double t1 = g3d_time_now();
    for (int r = 0; r < reps; r++) {
        g3d_cloud_render(&w.cloud, &w.cams[k], NULL, &img, &dep, &msk);
        g3d_image_free(&img); g3d_image_free(&dep); g3d_image_free(&msk);
    }
    double dt = (g3d_time_now() - t1) / reps;
    printf("  reprojection: %lld points in %.3f s = %.1f M points/s (one thread per render)\n", (long long)w.cloud.n, dt,
           w.cloud.n / dt / 1e6);
    printf("  final cloud: %lld points\n", (long long)w.cloud.n);
    g3d_world_free(&w);
    g3d_layers_free(&L);
    g3d_inpainter_free(&ip);
    g3d_mask_provider_free(&mp);
    free(poses);
}

int main(int argc, char **argv)
{
    const char *dir = argc > 1 ? argv[1] : G3D_DEFAULT_INPUT_DIR;
    g3d_frame f;
    if (g3d_frame_load_middlebury(dir, &f) == G3D_OK) {
        g3d_frame_limit_size(&f, 512);
        bench_frame("default input (Middlebury)", &f, "rotate", 6);
        g3d_frame_free(&f);
    } else {
        printf("default input not found (%s): %s\n", dir, g3d_error_message());
    }
    memset(&f, 0, sizeof f);
    f.cam = g3d_procscene_default_camera(512, 512);
    g3d_procscene_render(&f.cam, &f.rgb, &f.depth, NULL);
    snprintf(f.name, sizeof f.name, "procedural");
    bench_frame("procedural room", &f, "rotate", 6);
    g3d_frame_free(&f);
    return 0;
}
