/* generate_scene.c - a Gaussian-splat scene from one RGB-D frame, through the library alone.
 *
 *     generate_scene OUT_DIR [RGB DEPTH [FX]]
 *
 * With an RGB image and its depth map (16-bit PNG in millimetres, .pfm, .npy or .npz; FX the
 * focal length in pixels, else a 60 degree field of view) it uses them; without, it renders
 * the procedural test room as its input. A short schedule keeps it quick: for a real scene
 * leave the defaults of g3d_generate_params_default (3000 iterations, a video). The test
 * suite builds and runs it.
 */
#include "gen3d/gen3d.h"

#include <stdio.h>
#include <stdlib.h>

/* Prints each stage's last step; returning non-zero would cancel the run. */
static int show_progress(void *user, const char *stage, int64_t step, int64_t total, const char *info)
{
    (void)user;
    if (step == total) fprintf(stderr, "%-12s %lld/%lld %s\n", stage, (long long)step, (long long)total, info ? info : "");
    return 0;
}

int main(int argc, char **argv)
{
    g3d_process_setup(argv);   /* idle worker threads sleep instead of spinning */
    if (argc != 2 && argc != 4 && argc != 5) {
        fprintf(stderr, "usage: %s OUT_DIR [RGB DEPTH [FX]]\n", argv[0]);
        return 2;
    }
    g3d_generate_params p;
    g3d_generate_params_default(&p);
    g3d_frame room = {0};
    if (argc >= 4) {
        p.input.rgb_path = argv[2];
        p.input.depth_path = argv[3];
        if (argc == 5) p.input.K.fx = atof(argv[4]);
    } else {
        room.cam = g3d_procscene_default_camera(96, 72);
        if (g3d_procscene_render(&room.cam, &room.rgb, &room.depth, NULL) != G3D_OK) {
            fprintf(stderr, "%s\n", g3d_error_message());
            return 1;
        }
        p.frame = &room;
    }
    p.steps = 2;                                /* two new views beyond the input */
    p.world.extra_views = 2;
    g3d_train_params_default(&p.train, 60);     /* a short training schedule */
    p.video = 0;
    p.output_dir = argv[1];
    p.progress = (g3d_progress){show_progress, NULL};

    g3d_generate_result r;
    g3d_status rc = g3d_generate(&p, &r);
    g3d_frame_free(&room);
    if (rc != G3D_OK) {
        fprintf(stderr, "generate_scene: %s\n", g3d_error_message());
        return 1;
    }
    printf("%s: %d views, %lld points, %lld Gaussians, training PSNR %.1f dB\n", argv[1], r.views + r.extra_views,
           (long long)r.points, (long long)r.scene.n, r.train_psnr);
    for (int s = 0; s < G3D_STAGE_COUNT; s++) printf("  %-8s %6.2f s\n", g3d_stage_name((g3d_stage)s), r.seconds[s]);
    g3d_generate_result_free(&r);
    return 0;
}
