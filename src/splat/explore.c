/* The exploration set of cameras and the empty-pixel coverage of a scene seen from them. */
#include "gen3d/explore.h"
#include "gen3d/render.h"
#include "gen3d/trajectory.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void g3d_explore_params_default(g3d_explore_params *p)
{
    p->distance = 0.0;
    p->angle_deg = 15.0;
}

/* -1, 0, +1 for k mod 3 = 2, 0, 1. */
static int centred_mod3(int k)
{
    int m = ((k % 3) + 3) % 3;
    return m == 2 ? -1 : m;
}

g3d_status g3d_explore_cameras(const g3d_camera *input, double scene_scale, const g3d_explore_params *p,
                               g3d_camera **cams, double *distance)
{
    g3d_explore_params def;
    g3d_explore_params_default(&def);
    if (!p) p = &def;
    *cams = NULL;
    if (!(scene_scale > 0) || !isfinite(scene_scale))
        return G3D_ERR(G3D_ERR_ARG, "exploration: the scene scale must be positive, not %g m", scene_scale);
    if (!(p->distance >= 0) || !isfinite(p->distance))
        return G3D_ERR(G3D_ERR_ARG, "exploration: distance %g m must be zero (automatic) or positive", p->distance);
    if (p->distance > scene_scale)
        return G3D_ERR(G3D_ERR_ARG, "exploration: distance %g m is beyond the scene's median depth %g m (the cameras "
                       "would pass through the scene)", p->distance, scene_scale);
    if (!(p->angle_deg >= 0 && p->angle_deg < 90))
        return G3D_ERR(G3D_ERR_ARG, "exploration: angle %g degrees is not in [0, 90)", p->angle_deg);
    double d = p->distance > 0 ? p->distance : 0.25 * scene_scale, a = p->angle_deg;
    g3d_camera *c = malloc(sizeof *c * G3D_EXPLORE_CAMERAS);
    if (!c) return G3D_ERR(G3D_ERR_NOMEM, "exploration: out of memory");
    int k = 0;
    for (int oz = 0; oz <= 2; oz++)
        for (int oy = -1; oy <= 1; oy++)
            for (int ox = -1; ox <= 1; ox++) {
                /* (ox, oy, oz) -> (yaw, pitch) is linear over Z/3 with rank 2: each of the nine
                 * directions appears three times, and the origin keeps the input's direction */
                int yaw = centred_mod3(ox + oy + oz), pitch = centred_mod3(ox + 2 * oy);
                g3d_mat4 rel = g3d_pose_yaw_pitch(a * yaw, a * pitch, g3d_v3(d * ox, 0.5 * d * oy, d * oz));
                c[k].K = input->K;
                c[k].c2w = g3d_mat4_mul(input->c2w, rel);
                k++;
            }
    *cams = c;
    if (distance) *distance = d;
    return G3D_OK;
}

/* ---- coverage ---------------------------------------------------------------------------- */

typedef struct coverage_state {
    double *empty;
    g3d_image *sheet;
    int columns, tile_w, tile_h, shrink;
} coverage_state;

static const float MAGENTA[3] = {1.0f, 0.0f, 1.0f};

/* Draws frame `index` into its tile: box-averaged colour, magenta where any covered pixel is empty. */
static void draw_tile(const coverage_state *s, int index, const g3d_image *rgb, const g3d_image *depth)
{
    int f = s->shrink, x0 = 1 + (index % s->columns) * (s->tile_w + 1), y0 = 1 + (index / s->columns) * (s->tile_h + 1);
    int tw = (rgb->w + f - 1) / f, th = (rgb->h + f - 1) / f;
    for (int ty = 0; ty < th; ty++)
        for (int tx = 0; tx < tw; tx++) {
            float sum[3] = {0, 0, 0};
            int count = 0, hole = 0;
            for (int y = ty * f; y < (ty + 1) * f && y < rgb->h; y++)
                for (int x = tx * f; x < (tx + 1) * f && x < rgb->w; x++) {
                    const float *px = g3d_image_px(rgb, x, y);
                    for (int c = 0; c < 3; c++) sum[c] += px[c];
                    count++;
                    hole |= !(*g3d_image_px(depth, x, y) > 0);
                }
            float *out = g3d_image_px(s->sheet, x0 + tx, y0 + ty);
            for (int c = 0; c < 3; c++) out[c] = hole ? MAGENTA[c] : sum[c] / count;
        }
}

static g3d_status measure_frame(void *user, int index, const g3d_camera *cam, const g3d_image *rgb,
                                const g3d_image *depth)
{
    (void)cam;
    coverage_state *s = user;
    size_t n = g3d_image_size(depth), holes = 0;
    /* render.h: depth is 0 exactly where the accumulated opacity is below depth_min_alpha */
    for (size_t k = 0; k < n; k++) holes += !(depth->data[k] > 0);
    s->empty[index] = (double)holes / (double)n;
    if (s->sheet) draw_tile(s, index, rgb, depth);
    return G3D_OK;
}

g3d_status g3d_explore_coverage(const g3d_gaussians *g, const g3d_camera *cams, int n, double *empty,
                                g3d_image *sheet, int columns, int thumb_side)
{
    if (g->n < 1) return G3D_ERR(G3D_ERR_ARG, "coverage: the scene has no Gaussians");
    if (n < 1) return G3D_ERR(G3D_ERR_ARG, "coverage: no cameras");
    if (sheet && (columns < 1 || thumb_side < 1))
        return G3D_ERR(G3D_ERR_ARG, "coverage: a contact sheet needs columns and a thumbnail size >= 1");
    coverage_state s = {empty, sheet, columns, 0, 0, 1};
    if (sheet) {
        int side = 1;
        for (int i = 0; i < n; i++) {
            side = cams[i].K.width > side ? cams[i].K.width : side;
            side = cams[i].K.height > side ? cams[i].K.height : side;
        }
        s.shrink = (side + thumb_side - 1) / thumb_side;
        for (int i = 0; i < n; i++) {
            int tw = (cams[i].K.width + s.shrink - 1) / s.shrink, th = (cams[i].K.height + s.shrink - 1) / s.shrink;
            s.tile_w = tw > s.tile_w ? tw : s.tile_w;
            s.tile_h = th > s.tile_h ? th : s.tile_h;
        }
        int cols = n < columns ? n : columns, rows = (n + columns - 1) / columns;
        G3D_TRY(g3d_image_create(sheet, 1 + cols * (s.tile_w + 1), 1 + rows * (s.tile_h + 1), 3));
        for (size_t k = 0; k < g3d_image_size(sheet); k++) sheet->data[k] = 0.5f;
    }
    g3d_render_params rp;
    g3d_render_params_default(&rp);
    rp.depth = 1;
    g3d_status rc = g3d_render_path(g, cams, n, &rp, measure_frame, &s);
    if (rc != G3D_OK && sheet) g3d_image_free(sheet);
    return rc;
}
