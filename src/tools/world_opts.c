/* Running world generation from the shared world options. */
#include "world_opts.h"
#include "gen3d/cameras_json.h"
#include "gen3d/depth_complete.h"
#include "gen3d/inpaint_classic.h"
#include "gen3d/regions.h"
#include "gen3d/trajectory.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

void g3d_cli_world_init(g3d_cli_world *w)
{
    memset(w, 0, sizeof *w);
    w->trajectory = "rotate";
    w->extra = 10;
    w->max_side = 512;
}

int g3d_cli_world_check(const g3d_cli_world *w)
{
    if (w->steps < 0 || w->steps > 1000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--steps must be in 0..1000");
    if (w->extra < 0 || w->extra > 1000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--extra must be in 0..1000");
    if (w->max_side < 16 || w->max_side > G3D_MAX_IMAGE_SIDE)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--max-side must be in 16..%d", G3D_MAX_IMAGE_SIDE);
    if (w->distance < 0 || fabs(w->angle) > 360)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--distance must be >= 0 and --angle within a full turn");
    return 0;
}

int g3d_cli_world_help(char *buf, int k, int cap)
{
    k += snprintf(buf + k, k < cap ? cap - k : 0,
                  "Trajectories (--trajectory NAME, or a cameras.json / transforms.json file of poses in the\n"
                  "input camera's frame; moving presets scale with the median depth unless --distance is given):\n");
    for (const char *const *n = g3d_trajectory_names(); *n && k < cap; n++)
        k += snprintf(buf + k, cap - k, "  %-12s %s\n", *n, g3d_trajectory_describe(*n));
    return k;
}

/* Resamples poses to n_out evenly spaced ones (first and last kept). */
static g3d_mat4 *resample(const g3d_mat4 *p, int n, int n_out)
{
    g3d_mat4 *o = malloc(sizeof(g3d_mat4) * (size_t)n_out);
    if (!o) return NULL;
    for (int i = 0; i < n_out; i++) o[i] = p[n_out > 1 ? (int)lround((double)i * (n - 1) / (n_out - 1)) : 0];
    return o;
}

static g3d_status make_poses(const g3d_cli_world *w, const g3d_frame *f, g3d_mat4 **poses, int *n)
{
    struct stat st;
    g3d_status rc;
    *poses = NULL;
    *n = 0;
    if (stat(w->trajectory, &st) == 0) {
        g3d_camera_list l;
        rc = g3d_camera_list_load(w->trajectory, &l);
        if (rc == G3D_OK && l.n == 0) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: no poses", w->trajectory);
        if (rc == G3D_OK && !(*poses = malloc(sizeof(g3d_mat4) * (size_t)l.n))) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        if (rc == G3D_OK) {
            *n = l.n;
            for (int i = 0; i < l.n; i++) (*poses)[i] = l.cams[i].c2w;
        }
        g3d_camera_list_free(&l);
    } else {
        g3d_trajectory_params tp;
        g3d_trajectory_params_default(&tp);
        tp.steps = !strcmp(w->trajectory, "rotate") ? w->steps : 0;
        tp.angle_deg = w->angle;
        tp.distance = w->distance;
        rc = g3d_trajectory_make(w->trajectory, &tp, g3d_depth_median(&f->depth), poses, n);
    }
    if (rc == G3D_OK && w->steps > 0 && w->steps + 1 != *n) {
        g3d_mat4 *r = resample(*poses, *n, w->steps + 1);
        if (!r) {
            rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        } else {
            free(*poses);
            *poses = r;
            *n = w->steps + 1;
        }
    }
    return rc;
}

g3d_status g3d_cli_world_run(const g3d_cli_world *w, const g3d_frame *f, const g3d_depth_estimator *depth,
                             uint64_t seed, g3d_world *out)
{
    g3d_mat4 *poses;
    int n;
    g3d_status rc = make_poses(w, f, &poses, &n);
    g3d_inpainter ip = {0};
    g3d_mask_provider mp = {0};
    g3d_depth_estimator completion;
    g3d_depth_estimator_completion_create(&completion);
    g3d_world_params wp;
    g3d_world_params_default(&wp);
    wp.extra_views = w->extra;
    wp.progress = g3d_cli_progress();
    if (rc == G3D_OK) rc = g3d_inpainter_classic_create(NULL, &ip);
    if (rc == G3D_OK && !w->no_layers) rc = g3d_mask_provider_regions_create(NULL, f->cam.K, &mp);
    if (rc == G3D_OK) {
        g3d_log(G3D_LOG_INFO, "world: %s, %dx%d, %d poses (%s), %d extra views", f->name, f->rgb.w, f->rgb.h, n,
                w->trajectory, w->extra);
        double t0 = g3d_time_now();
        rc = g3d_world_generate(f, poses, n, &ip, depth ? depth : &completion, w->no_layers ? NULL : &mp, &wp, seed, out);
        if (rc == G3D_OK)
            g3d_log(G3D_LOG_INFO, "world: %lld points, %d views + %d extra, %d foreground objects, %.1f s",
                    (long long)out->cloud.n, out->n_views, out->n_extra, out->layers.n_foreground, g3d_time_now() - t0);
    }
    g3d_inpainter_free(&ip);
    g3d_mask_provider_free(&mp);
    free(poses);
    return rc;
}
