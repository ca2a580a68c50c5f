/* Rendering along camera paths: per-frame callback, output folders, fly-through paths. */
#include "gen3d/render.h"

#include "gen3d/cameras_json.h"
#include "gen3d/depthio.h"
#include "gen3d/imageio.h"
#include "gen3d/raster.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void g3d_render_params_default(g3d_render_params *p)
{
    memset(p, 0, sizeof *p);
    p->sh_degree = -1;
    p->depth_min_alpha = 0.5f;
}

void g3d_render_output_params_default(g3d_render_output_params *o)
{
    o->frames = 1;
    o->video = 1;
    o->cameras = 1;
    g3d_video_params_default(&o->video_params);
}

static g3d_status check_camera(const g3d_camera *c, int i)
{
    const g3d_intrinsics *K = &c->K;
    if (K->width < 1 || K->height < 1 || K->width > G3D_MAX_IMAGE_SIDE || K->height > G3D_MAX_IMAGE_SIDE)
        return G3D_ERR(G3D_ERR_ARG, "camera %d: image size %dx%d out of range 1..%d", i, K->width, K->height,
                       G3D_MAX_IMAGE_SIDE);
    if (!(isfinite(K->fx) && isfinite(K->fy) && isfinite(K->cx) && isfinite(K->cy) && K->fx > 0 && K->fy > 0))
        return G3D_ERR(G3D_ERR_ARG, "camera %d: focal lengths must be finite and positive, principal point finite", i);
    for (int r = 0; r < 4; r++)
        for (int k = 0; k < 4; k++)
            if (!isfinite(c->c2w.m[r][k])) return G3D_ERR(G3D_ERR_ARG, "camera %d: pose is not finite", i);
    return G3D_OK;
}

g3d_status g3d_render_path(const g3d_gaussians *g, const g3d_camera *cams, int n,
                           const g3d_render_params *p, g3d_render_frame_fn fn, void *user)
{
    if (n < 1) return G3D_ERR(G3D_ERR_ARG, "render: no cameras");
    if (p->sh_degree > g->sh_degree)
        return G3D_ERR(G3D_ERR_ARG, "render: SH degree %d asked for, the scene has degree %d", p->sh_degree,
                       g->sh_degree);
    for (int i = 0; i < n; i++) G3D_TRY(check_camera(&cams[i], i));

    g3d_raster_params s;
    g3d_raster_params_default(&s);
    memcpy(s.bg, p->background, sizeof s.bg);
    s.sh_degree_active = p->sh_degree;

    g3d_raster_ws *ws = NULL;
    g3d_image rgb = {0}, depth = {0}, alpha = {0};
    g3d_status rc = g3d_raster_ws_create(&ws);
    for (int i = 0; i < n && rc == G3D_OK; i++) {
        const g3d_camera *c = &cams[i];
        const int W = c->K.width, H = c->K.height;
        if (rgb.w != W || rgb.h != H) {
            g3d_image_free(&rgb);
            g3d_image_free(&depth);
            g3d_image_free(&alpha);
            rc = g3d_image_create(&rgb, W, H, 3);
            if (rc == G3D_OK && p->depth) rc = g3d_image_create(&depth, W, H, 1);
            if (rc == G3D_OK && p->depth) rc = g3d_image_create(&alpha, W, H, 1);
            if (rc != G3D_OK) break;
        }
        rc = g3d_raster_fwd(ws, g, c, &s, rgb.data, p->depth ? alpha.data : NULL, p->depth ? depth.data : NULL, NULL);
        if (rc != G3D_OK) break;
        if (p->depth) {
            const size_t np = (size_t)W * (size_t)H;
            for (size_t k = 0; k < np; k++) {
                float a = alpha.data[k];
                depth.data[k] = a >= p->depth_min_alpha && a > 0.0f ? depth.data[k] / a : 0.0f;
            }
        }
        rc = fn(user, i, c, &rgb, p->depth ? &depth : NULL);
        if (rc == G3D_OK && g3d_progress_report(&p->progress, "render", i + 1, n, NULL))
            rc = G3D_ERR(G3D_CANCELLED, "render: cancelled");
    }
    g3d_image_free(&rgb);
    g3d_image_free(&depth);
    g3d_image_free(&alpha);
    g3d_raster_ws_free(ws);
    return rc;
}

/* ---- output folder ------------------------------------------------------------------- */

typedef struct dir_writer {
    const char *dir;
    int frames, depth;
    g3d_video *video;
} dir_writer;

static g3d_status save_numbered(const char *dir, const char *sub, int index, const g3d_image *img, int is_depth)
{
    char name[64];
    snprintf(name, sizeof name, "%s/%05d.png", sub, index);
    char *path = g3d_path_join(dir, name);
    if (!path) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_status rc = is_depth ? g3d_depth_save(path, img) : g3d_image_save_png(path, img, 8);
    free(path);
    return rc;
}

static g3d_status write_frame(void *user, int index, const g3d_camera *cam, const g3d_image *rgb,
                              const g3d_image *depth)
{
    (void)cam;
    dir_writer *w = user;
    if (w->video) G3D_TRY(g3d_video_write_image(w->video, rgb));
    if (w->frames) G3D_TRY(save_numbered(w->dir, "frames", index, rgb, 0));
    if (depth) G3D_TRY(save_numbered(w->dir, "depth", index, depth, 1));
    return G3D_OK;
}

static g3d_status make_subdir(const char *dir, const char *sub)
{
    char *path = g3d_path_join(dir, sub);
    if (!path) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_status rc = g3d_mkdirs(path);
    free(path);
    return rc;
}

static g3d_status write_cameras(const char *dir, const g3d_camera *cams, int n, int depth)
{
    g3d_camera_list l;
    G3D_TRY(g3d_camera_list_create(&l, n));
    g3d_status rc = G3D_OK;
    char name[64];
    for (int i = 0; i < n && rc == G3D_OK; i++) {
        l.cams[i] = cams[i];
        snprintf(name, sizeof name, "frames/%05d.png", i);
        rc = g3d_camera_list_set_name(&l, i, name);
        snprintf(name, sizeof name, "depth/%05d.png", i);
        if (rc == G3D_OK && depth) rc = g3d_camera_list_set_depth(&l, i, name);
    }
    char *path = g3d_path_join(dir, "cameras.json");
    if (rc == G3D_OK) rc = path ? g3d_cameras_json_write(path, &l) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    free(path);
    g3d_camera_list_free(&l);
    return rc;
}

g3d_status g3d_render_to_dir(const g3d_gaussians *g, const g3d_camera *cams, int n,
                             const g3d_render_params *p, const g3d_render_output_params *o,
                             const char *dir, g3d_render_result *res)
{
    g3d_render_result r = {0, 0, NULL};
    dir_writer w = {dir, o->frames, p->depth, NULL};
    g3d_status rc = G3D_OK;
    if (n < 1) return G3D_ERR(G3D_ERR_ARG, "render: no cameras");
    if (o->video) {
        int same = 1;
        for (int i = 1; i < n; i++)
            same &= cams[i].K.width == cams[0].K.width && cams[i].K.height == cams[0].K.height;
        if (!same) {
            r.note = "the cameras differ in image size, so no video was made";
        } else {
            char *path = g3d_path_join(dir, "video.mp4");
            if (!path) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
            rc = check_camera(&cams[0], 0);
            if (rc == G3D_OK) rc = g3d_video_open(&w.video, path, cams[0].K.width, cams[0].K.height, &o->video_params);
            free(path);
            if (rc == G3D_ERR_UNSUPPORTED) {
                r.note = "ffmpeg is not installed, so no video was made";
                g3d_error_clear();
                rc = G3D_OK;
            }
            if (rc != G3D_OK) return rc;
        }
        if (r.note) {
            g3d_log(G3D_LOG_WARN, "%s; writing PNG frames to %s/frames instead", r.note, dir);
            w.frames = 1;
        }
    }
    if (w.frames) rc = make_subdir(dir, "frames");
    if (rc == G3D_OK && w.depth) rc = make_subdir(dir, "depth");
    if (rc == G3D_OK) rc = g3d_render_path(g, cams, n, p, write_frame, &w);
    if (w.video) {
        if (rc == G3D_OK) {
            rc = g3d_video_close(w.video);
            r.video_written = rc == G3D_OK;
        } else {
            g3d_video_abort(w.video);
        }
    }
    if (rc == G3D_OK && o->cameras) rc = write_cameras(dir, cams, n, w.depth);
    r.frames_written = rc == G3D_OK && w.frames;
    if (res) *res = r;
    return rc;
}

/* ---- camera paths -------------------------------------------------------------------- */

g3d_status g3d_render_scene_scale(const g3d_gaussians *g, const g3d_camera *cam, double *scale)
{
    float *z = g->n > 0 ? malloc((size_t)g->n * sizeof *z) : NULL;
    if (g->n > 0 && !z) return G3D_ERR(G3D_ERR_NOMEM, "out of memory for %lld depths", (long long)g->n);
    const g3d_mat4 w2c = g3d_mat4_inverse_rigid(cam->c2w);
    size_t m = 0;
    for (int64_t i = 0; i < g->n; i++) {
        g3d_vec3 pc = g3d_mat4_point(w2c, g3d_v3(g->means[i * 3], g->means[i * 3 + 1], g->means[i * 3 + 2]));
        if (pc.z > 0.01 && isfinite(pc.z)) z[m++] = (float)pc.z;
    }
    if (m == 0) {
        free(z);
        return G3D_ERR(G3D_ERR_ARG, "scene scale: none of the %lld Gaussians is in front of the camera",
                       (long long)g->n);
    }
    *scale = g3d_median_f32(z, m);
    free(z);
    return G3D_OK;
}

static double catmull_rom(double p0, double p1, double p2, double p3, double t)
{
    const double t2 = t * t, t3 = t2 * t;
    return 0.5 * (2 * p1 + (p2 - p0) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t2 + (3 * p1 - p0 - 3 * p2 + p3) * t3);
}

g3d_status g3d_render_resample_poses(const g3d_mat4 *poses, int n, int frames, g3d_mat4 **out)
{
    if (n < 1 || frames < 1) return G3D_ERR(G3D_ERR_ARG, "resample poses: %d poses to %d frames", n, frames);
    /* (n, 7): centre xyz, quaternion wxyz, each quaternion on the same side as the previous one */
    double *k = g3d_calloc((size_t)n * 7, sizeof *k, "keyframes");
    g3d_mat4 *o = g3d_calloc((size_t)frames, sizeof *o, "poses");
    if (!k || !o) {
        free(k);
        free(o);
        return G3D_ERR_NOMEM;
    }
    for (int i = 0; i < n; i++) {
        g3d_vec3 t = g3d_mat4_translation(poses[i]);
        g3d_quat q = g3d_quat_from_mat4(poses[i]);
        double *r = k + (size_t)i * 7;
        r[0] = t.x; r[1] = t.y; r[2] = t.z;
        r[3] = q.w; r[4] = q.x; r[5] = q.y; r[6] = q.z;
        if (i > 0) {
            const double *prev = r - 7;
            double d = r[3] * prev[3] + r[4] * prev[4] + r[5] * prev[5] + r[6] * prev[6];
            if (d < 0)
                for (int a = 3; a < 7; a++) r[a] = -r[a];
        }
    }
    for (int f = 0; f < frames; f++) {
        double u = frames > 1 ? (double)f * (n - 1) / (frames - 1) : 0.0;
        int i = (int)floor(u);
        if (i >= n - 1) i = n > 1 ? n - 2 : 0;
        double t = n > 1 ? u - i : 0.0;
        const int i0 = i > 0 ? i - 1 : 0, i2 = i + 1 < n ? i + 1 : n - 1, i3 = i + 2 < n ? i + 2 : n - 1;
        double v[7];
        for (int a = 0; a < 7; a++)
            v[a] = catmull_rom(k[i0 * 7 + a], k[i * 7 + a], k[i2 * 7 + a], k[i3 * 7 + a], t);
        g3d_quat q = g3d_quat_normalize((g3d_quat){v[3], v[4], v[5], v[6]});
        o[f] = g3d_mat4_from_rt(q, g3d_v3(v[0], v[1], v[2]));
    }
    /* the spline passes through the keyframes; make the ends bit-exact */
    o[0] = poses[0];
    if (frames > 1) o[frames - 1] = poses[n - 1];
    free(k);
    *out = o;
    return G3D_OK;
}

/* The swing loop in the input camera's frame, t in [0, 1). */
static g3d_mat4 swing_pose(double s, double t)
{
    const double a = 2.0 * M_PI * t;
    g3d_vec3 eye = g3d_v3(0.15 * s * sin(a), 0.0, 0.05 * s * (1.0 - cos(a)));
    return g3d_mat4_look_at(eye, g3d_v3(0, 0, s), g3d_v3(0, -1, 0));
}

g3d_status g3d_render_flythrough(const char *name, const g3d_trajectory_params *tp,
                                 const g3d_gaussians *g, const g3d_camera *input,
                                 double scene_scale, int frames, g3d_camera **cams, int *n)
{
    const int swing = strcmp(name, "swing") == 0;
    if (!swing && !g3d_trajectory_describe(name)) {
        char known[1024] = "swing";
        for (const char *const *nm = g3d_trajectory_names(); *nm; nm++) {
            size_t len = strlen(known);
            snprintf(known + len, sizeof known - len, ", %s", *nm);
        }
        return G3D_ERR(G3D_ERR_ARG, "unknown trajectory '%s' (known: %s)", name, known);
    }
    if (!(scene_scale > 0)) {
        if (!g) return G3D_ERR(G3D_ERR_ARG, "fly-through: no scene scale and no scene to measure it");
        G3D_TRY(g3d_render_scene_scale(g, input, &scene_scale));
    }
    g3d_mat4 *rel = NULL;
    int m = 0;
    g3d_status rc = G3D_OK;
    if (swing) {
        m = frames > 0 ? frames : 120;
        rel = g3d_calloc((size_t)m, sizeof *rel, "poses");
        if (!rel) return G3D_ERR_NOMEM;
        /* a closed loop: frame m would equal frame 0, so t stops one step short */
        for (int i = 0; i < m; i++) rel[i] = swing_pose(scene_scale, (double)i / m);
        rel[0] = g3d_mat4_identity();
    } else {
        g3d_trajectory_params def;
        g3d_trajectory_params_default(&def);
        rc = g3d_trajectory_make(name, tp ? tp : &def, scene_scale, &rel, &m);
        if (rc == G3D_OK && frames > 0) {
            g3d_mat4 *re = NULL;
            rc = g3d_render_resample_poses(rel, m, frames, &re);
            free(rel);
            rel = re;
            m = frames;
        }
        if (rc != G3D_OK) {
            free(rel);
            return rc;
        }
    }
    g3d_camera *c = g3d_calloc((size_t)m, sizeof *c, "cameras");
    if (!c) {
        free(rel);
        return G3D_ERR_NOMEM;
    }
    for (int i = 0; i < m; i++) {
        c[i].K = input->K;
        c[i].c2w = g3d_mat4_mul(input->c2w, rel[i]);
    }
    free(rel);
    *cams = c;
    *n = m;
    return G3D_OK;
}
