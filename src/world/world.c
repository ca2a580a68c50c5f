/* The world-generation loop, and the world folder: writer and reader. */
#include "gen3d/world.h"
#include "gen3d/dataset.h"
#include "gen3d/depthio.h"
#include "gen3d/imageio.h"
#include "gen3d/npy.h"
#include "gen3d/resize.h"
#include "gen3d/trajectory.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

void g3d_world_params_default(g3d_world_params *p)
{
    memset(p, 0, sizeof *p);
    p->extra_views = 10;
    p->extra_angle_deg = 5.0;
    p->hole_stride = 2;
    p->side_max_side = 384;
    p->side_carve = 0.02;
    g3d_cloud_render_params_default(&p->render);
    g3d_align_params_default(&p->align);
}

void g3d_world_free(g3d_world *w)
{
    if (!w) return;
    g3d_cloud_free(&w->cloud);
    for (int i = 0; i < w->n_views; i++) {
        if (w->rgb) g3d_image_free(&w->rgb[i]);
        if (w->depth) g3d_image_free(&w->depth[i]);
    }
    for (int i = 0; i < w->n_extra; i++) {
        if (w->extra_rgb) g3d_image_free(&w->extra_rgb[i]);
        if (w->extra_mask) g3d_image_free(&w->extra_mask[i]);
    }
    free(w->cams); free(w->rgb); free(w->depth); free(w->steps);
    free(w->extra_cams); free(w->extra_rgb); free(w->extra_mask);
    g3d_layers_free(&w->layers);
    memset(w, 0, sizeof *w);
}

double g3d_depth_median(const g3d_image *depth)
{
    size_t n = g3d_image_size(depth), k = 0;
    float *v = malloc(sizeof(float) * (n ? n : 1));
    if (!v) return 0;
    for (size_t i = 0; i < n; i++) if (depth->data[i] > 0) v[k++] = depth->data[i];
    double m = 0;
    if (k) { g3d_sort_f32(v, k); m = v[k / 2]; }
    free(v);
    return m;
}

/* The depth a view's estimator completes its holes from: the cloud's depth (depth, covered
 * where mask >= 0.5), with the near side of every depth edge that runs into a hole moved to the
 * far side (g3d_align_far_side, edge_ratio > 1), so that a disocclusion is completed from what
 * lies behind its occluder, not interpolated between the two. */
static g3d_status far_side_known(const g3d_image *depth, const g3d_image *mask, float edge_ratio, g3d_image *out)
{
    g3d_image far = {0};
    G3D_TRY(g3d_image_clone(out, depth));
    g3d_status rc = g3d_align_far_side(depth, mask, edge_ratio, &far, NULL);
    for (size_t k = 0; rc == G3D_OK && k < g3d_image_size(out); k++)
        if (far.data[k] > 0) out->data[k] = far.data[k];
    g3d_image_free(&far);
    if (rc != G3D_OK) g3d_image_free(out);
    return rc;
}

/* The input's depth with its gaps (a stereo matcher's occlusions, a sensor's dropouts) filled
 * as a new view's holes are: estimated, then aligned to the known depth around them. Left
 * unlifted, those pixels would be holes in the world from every camera, the input's too. */
static g3d_status complete_input_depth(const g3d_frame *in, const g3d_depth_estimator *depth, const g3d_world_params *p,
                                       g3d_image *out)
{
    g3d_image holes = {0}, valid = {0}, est = {0};
    size_t n = g3d_image_size(&in->depth), nh = 0;
    /* From both sides, unlike a new view's holes (g3d_align_far_side): an input gap has its real
     * colour and is as often part of the near surface as of the far one (Middlebury's gaps on
     * the motorcycle itself), which depth completion cannot tell; completed from the far side
     * they cost 0.35 dB at the right view (docs/explore.md). */
    g3d_align_params ap = p->align;
    ap.edge_ratio = 0;
    G3D_TRY(g3d_image_clone(out, &in->depth));
    for (size_t k = 0; k < n; k++) nh += !(in->depth.data[k] > 0);
    if (!nh || nh == n) return G3D_OK;
    g3d_status rc = g3d_image_create(&holes, in->depth.w, in->depth.h, 1);
    if (rc == G3D_OK) rc = g3d_image_create(&valid, in->depth.w, in->depth.h, 1);
    for (size_t k = 0; rc == G3D_OK && k < n; k++) {
        holes.data[k] = !(in->depth.data[k] > 0);
        valid.data[k] = 1.0f - holes.data[k];
    }
    g3d_intrinsics K = in->cam.K;
    if (rc == G3D_OK) rc = depth->estimate(depth->ctx, &in->rgb, &in->depth, &holes, &est, &K);
    if (rc == G3D_OK) rc = g3d_align_depth(&est, &in->depth, &valid, &ap, NULL);
    for (size_t k = 0; rc == G3D_OK && k < n; k++)
        if (holes.data[k] > 0.5f) out->data[k] = est.data[k];
    g3d_image_free(&holes);
    g3d_image_free(&valid);
    g3d_image_free(&est);
    return rc;
}

/* Step 0: the input, and with layers the background hidden behind its foreground. */
static g3d_status lift_input(g3d_world *w, const g3d_frame *in, const g3d_depth_estimator *depth, const g3d_layers *layers,
                             const g3d_world_params *p)
{
    g3d_image full = {0};
    g3d_status rc = complete_input_depth(in, depth, p, &full);
    if (rc == G3D_OK) rc = g3d_cloud_lift(&w->cloud, &in->rgb, &full, &w->cams[0], NULL, 0, &w->steps[0].points_added);
    g3d_image_free(&full);
    G3D_TRY(rc);
    if (layers) {
        G3D_TRY(g3d_layers_clone(&w->layers, layers));
        if (w->layers.n_foreground) {
            int64_t added;
            G3D_TRY(g3d_cloud_lift(&w->cloud, &w->layers.bg_rgb, &w->layers.bg_depth, &w->cams[0], &w->layers.fg_mask, 0, &added));
            w->steps[0].points_added += added;
        }
    }
    G3D_TRY(g3d_image_clone(&w->rgb[0], &in->rgb));
    return g3d_image_clone(&w->depth[0], &in->depth);
}

/* A side step's hole pixels whose point (at `depth` in cam) one of the first n_path views sees
 * in front of its own surface, by more than tol of that view's depth, are cleared: that view
 * saw through the point, so it is an inpainted guess (mostly beside thin structures and object
 * borders, where the aligned depth of a hole bleeds between foreground and background) that
 * would hide what the path saw. */
static void carve_seen(const g3d_world *w, int n_path, const g3d_camera *cam, const g3d_image *depth, double tol,
                       g3d_image *holes)
{
    for (int j = 0; j < n_path; j++) {
        const g3d_image *dj = &w->depth[j];
        for (int y = 0; y < holes->h; y++)
            for (int x = 0; x < holes->w; x++) {
                size_t k = (size_t)y * holes->w + x;
                double u, v, z;
                if (!(holes->data[k] > 0.5f) || !(depth->data[k] > 0)) continue;
                if (!g3d_camera_project(&w->cams[j], g3d_camera_unproject(cam, x, y, depth->data[k]), &u, &v, &z)) continue;
                long iu = lround(u), iv = lround(v);
                if (iu < 0 || iv < 0 || iu >= dj->w || iv >= dj->h) continue;
                float dz = dj->data[(size_t)iv * dj->w + iu];
                if (dz > 0 && z < dz * (1 - tol)) holes->data[k] = 0;
            }
    }
}

/* The input's intrinsics, downscaled to a longer side of at most max_side. */
static g3d_intrinsics side_intrinsics(g3d_intrinsics K, int max_side)
{
    if (K.width <= max_side && K.height <= max_side) return K;
    int w, h;
    g3d_fit_size(K.width, K.height, max_side, &w, &h);
    return g3d_intrinsics_resize(K, w, h);
}

/* A side step that sees less of the cloud than this fraction of its pixels is left out: it
 * looks past the scene (a narrow input turned by the exploration set's yaw), and what it would
 * add has next to nothing to align its depth to. */
#define SIDE_MIN_COVERED 0.05

/* One generation step at pose i. A side step that sees too little of the cloud sets *skipped
 * and adds nothing. */
static g3d_status world_step(g3d_world *w, int i, const g3d_inpainter *inpaint, const g3d_depth_estimator *depth,
                             const g3d_world_params *p, uint64_t seed, int *skipped)
{
    g3d_world_step *st = &w->steps[i];
    const g3d_camera *cam = &w->cams[i];
    g3d_image rgb = {0}, cloud_d = {0}, mask = {0}, holes = {0}, est = {0}, known = {0};
    double t = g3d_time_now();
    g3d_status rc = g3d_cloud_render(&w->cloud, cam, &p->render, &rgb, &cloud_d, &mask);
    st->seconds_reproject = g3d_time_now() - t;
    if (rc != G3D_OK) goto done;
    size_t n = g3d_image_size(&mask), nh = 0;
    if ((rc = g3d_image_create(&holes, mask.w, mask.h, 1)) != G3D_OK) goto done;
    for (size_t k = 0; k < n; k++) { holes.data[k] = mask.data[k] < 0.5f; nh += mask.data[k] < 0.5f; }
    st->hole_fraction = (double)nh / n;
    const int side = p->side_from > 0 && i >= p->side_from;
    *skipped = side && (double)(n - nh) < SIDE_MIN_COVERED * (double)n;
    if (*skipped) goto done;
    if (nh == n) {
        rc = G3D_ERR(G3D_ERR_ARG, "trajectory pose %d sees none of the scene (it leaves the scene entirely); use a shorter path", i);
        goto done;
    }
    t = g3d_time_now();
    if (nh) rc = inpaint->inpaint(inpaint->ctx, &rgb, &holes, p->prompt, seed + (uint64_t)i * 7919u);
    st->seconds_inpaint = g3d_time_now() - t;
    if (rc != G3D_OK) goto done;
    t = g3d_time_now();
    g3d_intrinsics K = cam->K;
    /* Only the side steps complete from the far side: the path's turns uncover little behind
     * edges, and on the default input doing so there too cost 0.04 dB at the right view. */
    g3d_align_params ap = p->align;
    if (!side) ap.edge_ratio = 0;
    const int from_far = nh && ap.edge_ratio > 0;
    if (from_far) rc = far_side_known(&cloud_d, &mask, ap.edge_ratio, &known);
    if (rc == G3D_OK) rc = depth->estimate(depth->ctx, &rgb, from_far ? &known : &cloud_d, nh ? &holes : NULL, &est, &K);
    st->seconds_depth = g3d_time_now() - t;
    if (rc != G3D_OK) goto done;
    t = g3d_time_now();
    if (nh) rc = g3d_align_depth(&est, &cloud_d, &mask, &ap, &st->align);
    st->seconds_align = g3d_time_now() - t;
    if (rc != G3D_OK) goto done;
    /* The view keeps the cloud's depth where the cloud covered it: only the holes are new. */
    for (size_t k = 0; k < n; k++) if (mask.data[k] >= 0.5f) est.data[k] = cloud_d.data[k];
    t = g3d_time_now();
    if (nh && p->side_carve > 0 && side) carve_seen(w, p->side_from, cam, &est, p->side_carve, &holes);
    if (nh) rc = g3d_cloud_lift_sparse(&w->cloud, &rgb, &est, cam, &holes, i, p->hole_stride, &st->points_added);
    st->seconds_lift = g3d_time_now() - t;
    if (rc != G3D_OK) goto done;
    w->rgb[i] = rgb;
    w->depth[i] = est;
    rgb.data = est.data = NULL;
done:
    g3d_image_free(&rgb);
    g3d_image_free(&cloud_d);
    g3d_image_free(&mask);
    g3d_image_free(&holes);
    g3d_image_free(&est);
    g3d_image_free(&known);
    return rc;
}

g3d_status g3d_world_generate(const g3d_frame *input, const g3d_mat4 *poses, int n_poses, const g3d_inpainter *inpaint,
                              const g3d_depth_estimator *depth, const g3d_layers *layers,
                              const g3d_world_params *p, uint64_t seed, g3d_world *out)
{
    g3d_world_params def;
    g3d_world_params_default(&def);
    if (!p) p = &def;
    memset(out, 0, sizeof *out);
    if (n_poses < 1 || n_poses > 10000) return G3D_ERR(G3D_ERR_ARG, "world: %d poses (need 1..10000)", n_poses);
    if (p->hole_stride < 1 || p->hole_stride > 16) return G3D_ERR(G3D_ERR_ARG, "world: hole stride %d (need 1..16)", p->hole_stride);
    if (p->extra_views < 0 || p->extra_views > 10000) return G3D_ERR(G3D_ERR_ARG, "world: %d extra views (need 0..10000)", p->extra_views);
    if (p->side_max_side < 16) return G3D_ERR(G3D_ERR_ARG, "world: side steps' longer side %d (need >= 16)", p->side_max_side);
    if (!(p->align.edge_ratio == 0 || p->align.edge_ratio > 1))
        return G3D_ERR(G3D_ERR_ARG, "world: depth edge ratio %g (need 0 = off, or > 1)", p->align.edge_ratio);
    if (!(p->side_carve >= 0 && p->side_carve <= 1))
        return G3D_ERR(G3D_ERR_ARG, "world: side-step carving tolerance %g (need 0..1)", p->side_carve);
    /* the path: the poses before the side steps */
    const int n_path = p->side_from > 0 && p->side_from < n_poses ? p->side_from : n_poses;
    G3D_TRY(g3d_frame_validate(input, input->name[0] ? input->name : "input"));
    g3d_status rc = g3d_cloud_init(&out->cloud);
    out->cams = calloc((size_t)n_poses, sizeof *out->cams);
    out->rgb = calloc((size_t)n_poses, sizeof *out->rgb);
    out->depth = calloc((size_t)n_poses, sizeof *out->depth);
    out->steps = calloc((size_t)n_poses, sizeof *out->steps);
    if (rc == G3D_OK && (!out->cams || !out->rgb || !out->depth || !out->steps)) rc = G3D_ERR(G3D_ERR_NOMEM, "world: out of memory");
    out->n_views = n_poses;
    for (int i = 0; i < n_poses && rc == G3D_OK; i++) {
        out->cams[i].K = i < n_path ? input->cam.K : side_intrinsics(input->cam.K, p->side_max_side);
        out->cams[i].c2w = g3d_mat4_mul(input->cam.c2w, poses[i]);
    }
    if (rc == G3D_OK) rc = lift_input(out, input, depth, layers, p);
    if (rc == G3D_OK && g3d_progress_report(&p->progress, "world", 1, n_poses, NULL))
        rc = G3D_ERR(G3D_CANCELLED, "world generation cancelled");
    /* v: the view the step at pose i becomes (side steps left out close the gap) */
    int v = 1;
    for (int i = 1; i < n_poses && rc == G3D_OK; i++) {
        int skipped = 0;
        out->cams[v] = out->cams[i];
        memset(&out->steps[v], 0, sizeof out->steps[v]);
        rc = world_step(out, v, inpaint, depth, p, seed, &skipped);
        char info[96];
        if (skipped)
            snprintf(info, sizeof info, "side step left out: it sees %.1f %% of the scene", 100.0 * (1.0 - out->steps[v].hole_fraction));
        else
            snprintf(info, sizeof info, "holes %.1f %%, %lld points", 100.0 * out->steps[v].hole_fraction, (long long)out->cloud.n);
        if (rc == G3D_OK && !skipped) v++;
        if (rc == G3D_OK && g3d_progress_report(&p->progress, "world", i + 1, n_poses, info))
            rc = G3D_ERR(G3D_CANCELLED, "world generation cancelled");
    }
    if (rc == G3D_OK) out->n_views = v;
    /* Extra views: orbits around the path's poses, rendered from the final cloud, not inpainted. */
    if (rc == G3D_OK && p->extra_views > 0) {
        int per = (p->extra_views + n_path - 1) / n_path;
        if (per > 5) per = 5;
        g3d_mat4 *orb = NULL;
        int norb = 0;
        double pivot = g3d_depth_median(&input->depth);
        rc = g3d_trajectory_orbits(poses, n_path, per, pivot > 0 ? pivot : 1.0, p->extra_angle_deg, &orb, &norb);
        int m = p->extra_views < norb ? p->extra_views : norb;
        if (rc == G3D_OK) {
            out->extra_cams = calloc((size_t)(m ? m : 1), sizeof *out->extra_cams);
            out->extra_rgb = calloc((size_t)(m ? m : 1), sizeof *out->extra_rgb);
            out->extra_mask = calloc((size_t)(m ? m : 1), sizeof *out->extra_mask);
            if (!out->extra_cams || !out->extra_rgb || !out->extra_mask) rc = G3D_ERR(G3D_ERR_NOMEM, "world: out of memory");
        }
        for (int k = 0; k < m && rc == G3D_OK; k++) {
            /* Spread the views over the poses: pose k % n, orbit k / n. */
            int pose = k % n_path, j = k / n_path;
            out->extra_cams[k].K = input->cam.K;
            out->extra_cams[k].c2w = g3d_mat4_mul(input->cam.c2w, orb[pose * per + j]);
            rc = g3d_cloud_render(&out->cloud, &out->extra_cams[k], &p->render, &out->extra_rgb[k], NULL, &out->extra_mask[k]);
            if (rc == G3D_OK) out->n_extra = k + 1;
            if (rc == G3D_OK && g3d_progress_report(&p->progress, "extra views", k + 1, m, NULL))
                rc = G3D_ERR(G3D_CANCELLED, "world generation cancelled");
        }
        free(orb);
    }
    if (rc != G3D_OK) g3d_world_free(out);
    return rc;
}

/* ---- the world folder ---------------------------------------------------------------------- */

static g3d_status save_in(const char *dir, const char *name, g3d_status (*fn)(const char *, const g3d_image *), const g3d_image *img)
{
    char *p = g3d_path_join(dir, name);
    if (!p) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_status rc = fn(p, img);
    free(p);
    return rc;
}

static g3d_status save_png8(const char *path, const g3d_image *img) { return g3d_image_save_png(path, img, 8); }

static cJSON *step_json(int i, const g3d_world_step *s)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "step", i);
    cJSON_AddNumberToObject(o, "hole_fraction", s->hole_fraction);
    cJSON_AddNumberToObject(o, "points_added", (double)s->points_added);
    cJSON_AddNumberToObject(o, "correspondences", (double)s->align.correspondences);
    cJSON_AddNumberToObject(o, "outliers", (double)s->align.rejected);
    cJSON_AddNumberToObject(o, "near_side", (double)s->align.near_side);
    cJSON_AddNumberToObject(o, "residual_before", s->align.residual_before);
    cJSON_AddNumberToObject(o, "residual_after", s->align.residual_after);
    cJSON_AddNumberToObject(o, "median_depth_ratio", s->align.median_ratio);
    return o;
}

g3d_status g3d_world_cameras(const g3d_world *w, const char *prefix, g3d_camera_list *out)
{
    char name[4096];
    if (!prefix) prefix = "";
    G3D_TRY(g3d_camera_list_create(out, w->n_views + w->n_extra));
    g3d_status rc = G3D_OK;
    for (int i = 0; i < w->n_views && rc == G3D_OK; i++) {
        out->cams[i] = w->cams[i];
        snprintf(name, sizeof name, "%sviews/view_%03d.png", prefix, i);
        rc = g3d_camera_list_set_name(out, i, name);
    }
    for (int k = 0; k < w->n_extra && rc == G3D_OK; k++) {
        int i = w->n_views + k;
        out->cams[i] = w->extra_cams[k];
        snprintf(name, sizeof name, "%sextra/extra_%03d.png", prefix, k);
        rc = g3d_camera_list_set_name(out, i, name);
        snprintf(name, sizeof name, "%smasks/extra_%03d.png", prefix, k);
        if (rc == G3D_OK) rc = g3d_camera_list_set_mask(out, i, name);
    }
    if (rc != G3D_OK) g3d_camera_list_free(out);
    return rc;
}

g3d_status g3d_world_save(const g3d_world *w, const char *dir, uint64_t seed)
{
    char *tmp = NULL, *sub = NULL, name[96];
    g3d_camera_list cams = {0};
    g3d_points pts = {0};
    g3d_status rc = g3d_atomic_dir_begin(dir, &tmp);
    if (rc != G3D_OK) return rc;
    static const char *const folders[] = {"views", "depth", "extra", "masks", "layers"};
    for (int f = 0; f < 5 && rc == G3D_OK; f++) {
        sub = g3d_path_join(tmp, folders[f]);
        rc = sub ? g3d_mkdirs(sub) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        free(sub);
    }
    if (rc == G3D_OK) rc = g3d_world_cameras(w, NULL, &cams);
    for (int i = 0; i < w->n_views && rc == G3D_OK; i++) {
        rc = save_in(tmp, cams.names[i], save_png8, &w->rgb[i]);
        snprintf(name, sizeof name, "depth/view_%03d.png", i);
        if (rc == G3D_OK) rc = save_in(tmp, name, g3d_depth_save, &w->depth[i]);
        snprintf(name, sizeof name, "depth/view_%03d.npy", i);
        if (rc == G3D_OK) rc = save_in(tmp, name, g3d_depth_save, &w->depth[i]);
    }
    for (int k = 0; k < w->n_extra && rc == G3D_OK; k++) {
        int i = w->n_views + k;
        rc = save_in(tmp, cams.names[i], save_png8, &w->extra_rgb[k]);
        if (rc == G3D_OK) rc = save_in(tmp, cams.mask_paths[i], save_png8, &w->extra_mask[k]);
    }
    if (rc == G3D_OK && w->layers.fg_mask.data) {
        rc = save_in(tmp, "layers/fg_mask.png", save_png8, &w->layers.fg_mask);
        if (rc == G3D_OK) rc = save_in(tmp, "layers/bg_rgb.png", save_png8, &w->layers.bg_rgb);
        if (rc == G3D_OK) rc = save_in(tmp, "layers/bg_depth.png", g3d_depth_save, &w->layers.bg_depth);
    }
    char *p;
    if (rc == G3D_OK) { p = g3d_path_join(tmp, "cameras.json"); rc = g3d_cameras_json_write(p, &cams); free(p); }
    if (rc == G3D_OK) { p = g3d_path_join(tmp, "transforms.json"); rc = g3d_transforms_json_write(p, &cams); free(p); }
    if (rc == G3D_OK) rc = g3d_cloud_to_points(&w->cloud, &pts);
    if (rc == G3D_OK) { p = g3d_path_join(tmp, "points.ply"); rc = g3d_ply_write_points(p, &pts); free(p); }
    if (rc == G3D_OK) {
        cJSON *root = cJSON_CreateObject(), *steps = cJSON_AddArrayToObject(root, "steps");
        cJSON_AddNumberToObject(root, "seed", (double)seed);
        cJSON_AddNumberToObject(root, "views", w->n_views);
        cJSON_AddNumberToObject(root, "extra_views", w->n_extra);
        cJSON_AddNumberToObject(root, "points", (double)w->cloud.n);
        cJSON_AddNumberToObject(root, "foreground_objects", w->layers.n_foreground);
        for (int i = 0; i < w->n_views; i++) cJSON_AddItemToArray(steps, step_json(i, &w->steps[i]));
        char *text = cJSON_Print(root);
        cJSON_Delete(root);
        p = g3d_path_join(tmp, "log.json");
        rc = text && p ? g3d_write_file_atomic(p, text, strlen(text)) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        free(p);
        free(text);
    }
    if (rc == G3D_OK) rc = g3d_atomic_dir_commit(tmp, dir);
    if (rc != G3D_OK) g3d_atomic_dir_abort(tmp);
    free(tmp);
    g3d_camera_list_free(&cams);
    g3d_points_free(&pts);
    return rc;
}

/* ---- reading a world folder back ------------------------------------------------------------- */

static double json_num(const cJSON *o, const char *key)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, key);
    return cJSON_IsNumber(v) ? v->valuedouble : 0.0;
}

/* log.json, when present: its parsed tree (*root, NULL without a log; caller deletes) and the
 * number of generated views (*views, -1 without a log). */
static g3d_status read_log(const char *dir, int *views, cJSON **root)
{
    char *p = g3d_path_join(dir, "log.json");
    unsigned char *text = NULL;
    size_t n = 0;
    struct stat st;
    *views = -1;
    *root = NULL;
    if (!p) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_status rc = stat(p, &st) == 0 ? g3d_read_file(p, (size_t)1 << 26, &text, &n) : G3D_OK;
    if (rc == G3D_OK && text) {
        *root = cJSON_Parse((const char *)text);
        const cJSON *v = cJSON_GetObjectItemCaseSensitive(*root, "views");
        if (!cJSON_IsObject(*root) || !cJSON_IsNumber(v) || v->valuedouble < 0 || v->valuedouble > 1e6)
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: not a world log (no \"views\" count)", p);
        else
            *views = (int)v->valuedouble;
    }
    free(text);
    free(p);
    if (rc != G3D_OK) {
        cJSON_Delete(*root);
        *root = NULL;
    }
    return rc;
}

static void steps_from_log(const cJSON *root, g3d_world *w)
{
    const cJSON *steps = cJSON_GetObjectItemCaseSensitive(root, "steps"), *s;
    cJSON_ArrayForEach(s, steps)
    {
        int i = (int)json_num(s, "step");
        if (i < 0 || i >= w->n_views) continue;
        g3d_world_step *st = &w->steps[i];
        st->hole_fraction = json_num(s, "hole_fraction");
        st->points_added = (int64_t)json_num(s, "points_added");
        st->align.correspondences = (int64_t)json_num(s, "correspondences");
        st->align.rejected = (int64_t)json_num(s, "outliers");
        st->align.near_side = (int64_t)json_num(s, "near_side");
        st->align.residual_before = json_num(s, "residual_before");
        st->align.residual_after = json_num(s, "residual_after");
        st->align.median_ratio = json_num(s, "median_depth_ratio");
    }
}

/* Loads dir/name into *img when the file exists, leaving it empty otherwise: as an image of
 * `channels` channels, or as depth when channels is 0. */
static g3d_status load_if_present(const char *dir, const char *name, int channels, g3d_image *img)
{
    struct stat st;
    char *p = g3d_path_join(dir, name);
    if (!p) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_status rc = stat(p, &st) != 0 ? G3D_OK : channels ? g3d_image_load(p, channels, img) : g3d_depth_load(p, 0, img);
    free(p);
    return rc;
}

static g3d_status cloud_from_points(const g3d_points *pts, g3d_cloud *c)
{
    G3D_TRY(g3d_cloud_init(c));
    G3D_TRY(g3d_cloud_reserve(c, pts->n));
    for (int64_t i = 0; i < pts->n; i++) {
        for (int k = 0; k < 3; k++) {
            c->xyz[3 * i + k] = pts->xyz[3 * i + k];
            c->rgb[3 * i + k] = pts->rgb[3 * i + k] / 255.0f;
        }
        c->size[i] = 0;
        memset(c->span + 6 * i, 0, sizeof(float) * 6);
        c->view[i] = -1;
    }
    c->n = pts->n;
    return G3D_OK;
}

g3d_status g3d_world_load(const char *dir, g3d_world *w)
{
    g3d_dataset d;
    cJSON *log = NULL;
    int nv;
    memset(w, 0, sizeof *w);
    G3D_TRY(g3d_dataset_load(dir, 1, &d));
    g3d_status rc = read_log(dir, &nv, &log);
    if (rc == G3D_OK && nv > d.n) rc = G3D_ERR(G3D_ERR_FORMAT, "%s/log.json: %d views, the camera file lists %d frames", dir, nv, d.n);
    /* which frames are generated views: the log's first nv, else those without a mask */
    for (int i = 0; i < d.n && rc == G3D_OK; i++) {
        int is_view = nv >= 0 ? i < nv : !d.masks[i].data;
        if (!is_view && !d.masks[i].data)
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: extra view %d has no mask_path", dir, i - nv);
        if (is_view) w->n_views++;
        else w->n_extra++;
    }
    if (rc == G3D_OK) {
        size_t v = (size_t)(w->n_views ? w->n_views : 1), e = (size_t)(w->n_extra ? w->n_extra : 1);
        w->cams = calloc(v, sizeof *w->cams);
        w->rgb = calloc(v, sizeof *w->rgb);
        w->depth = calloc(v, sizeof *w->depth);
        w->steps = calloc(v, sizeof *w->steps);
        w->extra_cams = calloc(e, sizeof *w->extra_cams);
        w->extra_rgb = calloc(e, sizeof *w->extra_rgb);
        w->extra_mask = calloc(e, sizeof *w->extra_mask);
        if (!w->cams || !w->rgb || !w->depth || !w->steps || !w->extra_cams || !w->extra_rgb || !w->extra_mask)
            rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    /* the images move from the dataset into the world */
    int iv = 0, ie = 0;
    char name[64];
    for (int i = 0; i < d.n && rc == G3D_OK; i++) {
        if (nv >= 0 ? i < nv : !d.masks[i].data) {
            w->cams[iv] = d.cams.cams[i];
            w->rgb[iv] = d.images[i];
            g3d_image_free(&d.masks[i]);
            snprintf(name, sizeof name, "depth/view_%03d.npy", iv);
            rc = load_if_present(dir, name, 0, &w->depth[iv]);
            iv++;
        } else {
            w->extra_cams[ie] = d.cams.cams[i];
            w->extra_rgb[ie] = d.images[i];
            w->extra_mask[ie] = d.masks[i];
            ie++;
        }
        memset(&d.images[i], 0, sizeof d.images[i]);
        memset(&d.masks[i], 0, sizeof d.masks[i]);
    }
    if (rc == G3D_OK && log) steps_from_log(log, w);
    if (rc == G3D_OK) rc = load_if_present(dir, "layers/fg_mask.png", 1, &w->layers.fg_mask);
    if (rc == G3D_OK && w->layers.fg_mask.data) {
        rc = load_if_present(dir, "layers/bg_rgb.png", 3, &w->layers.bg_rgb);
        if (rc == G3D_OK) rc = load_if_present(dir, "layers/bg_depth.png", 0, &w->layers.bg_depth);
        w->layers.n_foreground = (int)json_num(log, "foreground_objects");
    }
    if (rc == G3D_OK) rc = cloud_from_points(&d.points, &w->cloud);
    cJSON_Delete(log);
    g3d_dataset_free(&d);
    if (rc != G3D_OK) g3d_world_free(w);
    return rc;
}
