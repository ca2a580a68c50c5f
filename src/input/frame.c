/* Building the input frame from files: RGB-D pairs and the Middlebury default input. */
#include "gen3d/frame.h"
#include "gen3d/depthio.h"
#include "gen3d/npy.h"
#include "gen3d/imageio.h"
#include "gen3d/cameras_json.h"
#include "gen3d/ply.h"
#include "gen3d/providers.h"
#include "gen3d/resize.h"
#include <math.h>

#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* The calibration of Middlebury 2014 "Motorcycle" (calib.txt of the perfect-rectification
 * pair): focal length, principal points, disparity offset, baseline. */
#define MIDDLEBURY_F 994.978
#define MIDDLEBURY_CX0 311.193
#define MIDDLEBURY_CY 254.877
#define MIDDLEBURY_DOFFS 31.086
#define MIDDLEBURY_BASELINE_M 0.193001

void g3d_frame_free(g3d_frame *f)
{
    if (!f) return;
    g3d_image_free(&f->rgb);
    g3d_image_free(&f->depth);
    g3d_image_free(&f->heldout);
    memset(f, 0, sizeof *f);
}

g3d_status g3d_frame_validate(const g3d_frame *f, const char *label)
{
    if (f->rgb.c != 3) return G3D_ERR(G3D_ERR_FORMAT, "%s: colour image must have 3 channels", label);
    if (f->depth.w != f->rgb.w || f->depth.h != f->rgb.h)
        return G3D_ERR(G3D_ERR_MISMATCH, "%s: depth is %dx%d but the image is %dx%d", label, f->depth.w, f->depth.h,
                       f->rgb.w, f->rgb.h);
    if (f->cam.K.width != f->rgb.w || f->cam.K.height != f->rgb.h || !(f->cam.K.fx > 0) || !(f->cam.K.fy > 0))
        return G3D_ERR(G3D_ERR_ARG, "%s: intrinsics do not describe the %dx%d image", label, f->rgb.w, f->rgb.h);
    size_t valid = 0, n = g3d_image_size(&f->depth);
    for (size_t i = 0; i < n; i++) valid += f->depth.data[i] > 0;
    if (valid == 0) return G3D_ERR(G3D_ERR_FORMAT, "%s: depth has no valid pixel (all zero, NaN or infinite)", label);
    return G3D_OK;
}

/* The camera from the caller's K (fx > 0), else a field of view (60 degrees when none). */
static g3d_intrinsics given_camera(g3d_intrinsics K, double fov_deg, int w, int h)
{
    g3d_intrinsics d = g3d_intrinsics_from_fov(fov_deg > 0 ? fov_deg : 60.0, w, h);
    if (K.fx > 0) {
        d.fx = K.fx;
        d.fy = K.fy > 0 ? K.fy : K.fx;
        if (K.cx >= 0) d.cx = K.cx;
        if (K.cy >= 0) d.cy = K.cy;
    } else if (!(fov_deg > 0)) {
        g3d_log(G3D_LOG_INFO, "no intrinsics given: assuming a 60 degree horizontal field of view (fx = %.1f px)", d.fx);
    }
    return d;
}

static g3d_status resize_in_place(g3d_image *img, int w, int h, g3d_resize_mode mode);
g3d_status g3d_frame_load_rgb(const char *rgb_path, const g3d_depth_estimator *model, g3d_intrinsics K, double fov_deg,
                              int max_side, g3d_frame *f)
{
    g3d_image rgb;
    memset(f, 0, sizeof *f);
    G3D_TRY(g3d_image_load(rgb_path, 3, &rgb));
    g3d_status rc = g3d_frame_from_image(&rgb, rgb_path, model, K, fov_deg, max_side, f);
    if (rc == G3D_OK) snprintf(f->name, sizeof f->name, "rgb+model");
    return rc;
}

g3d_status g3d_frame_from_image(g3d_image *rgb, const char *label, const g3d_depth_estimator *model, g3d_intrinsics K,
                                double fov_deg, int max_side, g3d_frame *f)
{
    g3d_status rc;
    memset(f, 0, sizeof *f);
    f->rgb = *rgb;
    memset(rgb, 0, sizeof *rgb);
    /* the model sees the image at the size the pipeline will use: given pixel intrinsics
     * scale with it */
    int w0 = f->rgb.w, h0 = f->rgb.h;
    if (max_side > 0 && (w0 > max_side || h0 > max_side)) {
        int w, h;
        g3d_fit_size(w0, h0, max_side, &w, &h);
        if ((rc = resize_in_place(&f->rgb, w, h, G3D_RESIZE_AREA)) != G3D_OK) { g3d_frame_free(f); return rc; }
        if (K.fx > 0) {
            double sx = (double)w / w0, sy = (double)h / h0;
            K.fx *= sx;
            K.fy *= sy;
            if (K.cx >= 0) K.cx = (K.cx + 0.5) * sx - 0.5;
            if (K.cy >= 0) K.cy = (K.cy + 0.5) * sy - 0.5;
        }
    }
    /* a camera the user gave is passed on (it fixes the model's fit); otherwise the model
     * may predict one */
    int given = K.fx > 0 || fov_deg > 0;
    g3d_intrinsics io = {0};
    if (given) io = given_camera(K, fov_deg, f->rgb.w, f->rgb.h);
    rc = model->estimate(model->ctx, &f->rgb, NULL, NULL, &f->depth, &io);
    if (rc != G3D_OK) {
        g3d_error_prefix(label);
        g3d_frame_free(f);
        return rc;
    }
    if (!given && io.fx > 0) {
        io.width = f->rgb.w;
        io.height = f->rgb.h;
        g3d_log(G3D_LOG_INFO, "camera from the depth model: fx %.1f fy %.1f cx %.1f cy %.1f px", io.fx, io.fy, io.cx, io.cy);
    } else if (!given) {
        io = given_camera(K, fov_deg, f->rgb.w, f->rgb.h);
    }
    f->cam.K = io;
    f->cam.c2w = g3d_mat4_identity();
    snprintf(f->name, sizeof f->name, "%s", label);
    if ((rc = g3d_frame_validate(f, label)) != G3D_OK) g3d_frame_free(f);
    return rc;
}

g3d_status g3d_frame_load_rgbd(const char *rgb_path, const char *depth_path, double depth_scale, g3d_intrinsics K,
                               double fov_deg, g3d_frame *f)
{
    g3d_status rc;
    memset(f, 0, sizeof *f);
    if ((rc = g3d_image_load(rgb_path, 3, &f->rgb)) != G3D_OK) return rc;
    if ((rc = g3d_depth_load(depth_path, depth_scale, &f->depth)) != G3D_OK) { g3d_frame_free(f); return rc; }
    if (f->depth.w != f->rgb.w || f->depth.h != f->rgb.h) {
        rc = G3D_ERR(G3D_ERR_MISMATCH, "%s: depth is %dx%d but %s is %dx%d", depth_path, f->depth.w, f->depth.h,
                     rgb_path, f->rgb.w, f->rgb.h);
        g3d_frame_free(f);
        return rc;
    }
    f->cam.K = given_camera(K, fov_deg, f->rgb.w, f->rgb.h);
    f->cam.c2w = g3d_mat4_identity();
    snprintf(f->name, sizeof f->name, "rgbd");
    if ((rc = g3d_frame_validate(f, depth_path)) != G3D_OK) g3d_frame_free(f);
    return rc;
}

/* Picks the first of two candidate names that exists in dir (malloc'd path). */
static char *pick(const char *dir, const char *a, const char *b)
{
    struct stat st;
    char *p = g3d_path_join(dir, a);
    if (p && stat(p, &st) == 0) return p;
    free(p);
    return g3d_path_join(dir, b);
}

g3d_status g3d_frame_load_middlebury(const char *dir, g3d_frame *f)
{
    g3d_status rc;
    g3d_array disp = {0};
    char *left = pick(dir, "motorcycle_left.png", "im0.png");
    char *right = pick(dir, "motorcycle_right.png", "im1.png");
    char *npz = g3d_path_join(dir, "motorcycle_disp.npz");
    memset(f, 0, sizeof *f);
    if (!left || !right || !npz) { rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory"); goto done; }
    if ((rc = g3d_image_load(left, 3, &f->rgb)) != G3D_OK) goto done;
    if ((rc = g3d_image_load(right, 3, &f->heldout)) != G3D_OK) goto done;
    if ((rc = g3d_npz_load(npz, NULL, &disp)) != G3D_OK) goto done;
    if (disp.ndim != 2 || disp.shape[0] != f->rgb.h || disp.shape[1] != f->rgb.w) {
        rc = G3D_ERR(G3D_ERR_MISMATCH, "%s: disparity shape does not match the %dx%d image", npz, f->rgb.w, f->rgb.h);
        goto done;
    }
    if ((rc = g3d_image_create(&f->depth, f->rgb.w, f->rgb.h, 1)) != G3D_OK) goto done;
    memcpy(f->depth.data, disp.data, g3d_image_size(&f->depth) * sizeof(float));
    g3d_disparity_to_depth(&f->depth, MIDDLEBURY_F, MIDDLEBURY_BASELINE_M, MIDDLEBURY_DOFFS);

    f->cam.K = g3d_intrinsics_make(MIDDLEBURY_F, MIDDLEBURY_F, MIDDLEBURY_CX0, MIDDLEBURY_CY, f->rgb.w, f->rgb.h);
    f->cam.c2w = g3d_mat4_identity();
    f->heldout_cam.K = g3d_intrinsics_make(MIDDLEBURY_F, MIDDLEBURY_F, MIDDLEBURY_CX0 + MIDDLEBURY_DOFFS,
                                           MIDDLEBURY_CY, f->heldout.w, f->heldout.h);
    f->heldout_cam.c2w = g3d_mat4_identity();
    f->heldout_cam.c2w.m[0][3] = MIDDLEBURY_BASELINE_M;
    snprintf(f->name, sizeof f->name, "middlebury-motorcycle");
    rc = g3d_frame_validate(f, dir);
done:
    if (rc != G3D_OK) g3d_frame_free(f);
    g3d_array_free(&disp);
    free(left);
    free(right);
    free(npz);
    return rc;
}

g3d_status g3d_frame_to_points(const g3d_frame *f, int stride, g3d_points *out)
{
    int64_t n = 0;
    if (stride < 1) return G3D_ERR(G3D_ERR_ARG, "lifting stride must be >= 1");
    for (int y = 0; y < f->depth.h; y += stride)
        for (int x = 0; x < f->depth.w; x += stride) n += *g3d_image_px(&f->depth, x, y) > 0;
    G3D_TRY(g3d_points_create(out, n, 0));
    n = 0;
    for (int y = 0; y < f->depth.h; y += stride)
        for (int x = 0; x < f->depth.w; x += stride) {
            float z = *g3d_image_px(&f->depth, x, y);
            if (z <= 0) continue;
            g3d_vec3 p = g3d_camera_unproject(&f->cam, x, y, z);
            const float *c = g3d_image_px(&f->rgb, x, y);
            out->xyz[3 * n] = (float)p.x;
            out->xyz[3 * n + 1] = (float)p.y;
            out->xyz[3 * n + 2] = (float)p.z;
            for (int k = 0; k < 3; k++) out->rgb[3 * n + k] = (uint8_t)lrintf(255.0f * fminf(1.0f, fmaxf(0.0f, c[k])));
            n++;
        }
    return G3D_OK;
}

g3d_status g3d_frame_save(const g3d_frame *f, const char *dir)
{
    char *tmp = NULL, *p = NULL;
    g3d_camera_list cams = {0};
    g3d_points pts = {0};
    g3d_status rc = g3d_atomic_dir_begin(dir, &tmp);
    if (rc != G3D_OK) return rc;
#define SAVE(name, call) \
    if (rc == G3D_OK) { p = g3d_path_join(tmp, name); rc = p ? (call) : G3D_ERR(G3D_ERR_NOMEM, "out of memory"); free(p); }
    SAVE("rgb.png", g3d_image_save_png(p, &f->rgb, 8));
    SAVE("depth.png", g3d_depth_save(p, &f->depth));
    SAVE("depth.npy", g3d_depth_save(p, &f->depth));
    if (f->heldout.data) SAVE("heldout.png", g3d_image_save_png(p, &f->heldout, 8));
    if (rc == G3D_OK && (rc = g3d_camera_list_create(&cams, f->heldout.data ? 2 : 1)) == G3D_OK) {
        cams.cams[0] = f->cam;
        rc = g3d_camera_list_set_name(&cams, 0, "rgb.png");
        if (rc == G3D_OK && f->heldout.data) {
            cams.cams[1] = f->heldout_cam;
            rc = g3d_camera_list_set_name(&cams, 1, "heldout.png");
        }
    }
    SAVE("cameras.json", g3d_cameras_json_write(p, &cams));
    if (rc == G3D_OK) rc = g3d_frame_to_points(f, 1, &pts);
    SAVE("points.ply", g3d_ply_write_points(p, &pts));
#undef SAVE
    if (rc == G3D_OK) rc = g3d_atomic_dir_commit(tmp, dir);
    if (rc != G3D_OK) g3d_atomic_dir_abort(tmp);
    free(tmp);
    g3d_camera_list_free(&cams);
    g3d_points_free(&pts);
    return rc;
}

void g3d_frame_params_default(g3d_frame_params *p)
{
    memset(p, 0, sizeof *p);
    p->depth_scale = 1000;
    p->K.cx = p->K.cy = -1;
    p->default_dir = "cache/default-input";
}

g3d_status g3d_frame_load(const g3d_frame_params *p, const g3d_depth_estimator *model, g3d_frame *f)
{
    g3d_status rc;
    memset(f, 0, sizeof *f);
    if (p->max_side < 0) return G3D_ERR(G3D_ERR_ARG, "maximum image side %d is negative", p->max_side);
    if (p->rgb_path && p->depth_path) {
        rc = g3d_frame_load_rgbd(p->rgb_path, p->depth_path, p->depth_scale, p->K, p->fov_deg, f);
    } else if (p->rgb_path) {
        if (!model) return G3D_ERR(G3D_ERR_ARG, "%s: no depth map, and no depth model to predict one", p->rgb_path);
        rc = g3d_frame_load_rgb(p->rgb_path, model, p->K, p->fov_deg, p->max_side, f);
    } else if (p->depth_path) {
        return G3D_ERR(G3D_ERR_ARG, "%s: a depth map needs its colour image", p->depth_path);
    } else {
        rc = g3d_frame_load_middlebury(p->default_dir, f);
        if (rc != G3D_OK) g3d_error_prefix("default input (run scripts/fetch-default-input.sh)");
    }
    if (rc == G3D_OK && p->max_side > 0) rc = g3d_frame_limit_size(f, p->max_side);
    if (rc != G3D_OK) g3d_frame_free(f);
    return rc;
}

/* Resizes img in place to w x h with the given mode. */
static g3d_status resize_in_place(g3d_image *img, int w, int h, g3d_resize_mode mode)
{
    g3d_image out;
    G3D_TRY(g3d_image_resize(img, w, h, mode, &out));
    g3d_image_free(img);
    *img = out;
    return G3D_OK;
}

g3d_status g3d_frame_limit_size(g3d_frame *f, int max_side)
{
    int w, h;
    if (max_side < 16) return G3D_ERR(G3D_ERR_ARG, "maximum image side %d is too small (at least 16)", max_side);
    if (f->rgb.w > max_side || f->rgb.h > max_side) {
        g3d_fit_size(f->rgb.w, f->rgb.h, max_side, &w, &h);
        G3D_TRY(resize_in_place(&f->rgb, w, h, G3D_RESIZE_AREA));
        G3D_TRY(resize_in_place(&f->depth, w, h, G3D_RESIZE_NEAREST));
        f->cam.K = g3d_intrinsics_resize(f->cam.K, w, h);
    }
    if (f->heldout.data && (f->heldout.w > max_side || f->heldout.h > max_side)) {
        g3d_fit_size(f->heldout.w, f->heldout.h, max_side, &w, &h);
        G3D_TRY(resize_in_place(&f->heldout, w, h, G3D_RESIZE_AREA));
        f->heldout_cam.K = g3d_intrinsics_resize(f->heldout_cam.K, w, h);
    }
    return G3D_OK;
}
