/* View sets for evaluation: camera files with ground-truth images, depth and masks, and
 * Middlebury stereo folders. Everything is loaded and checked before anything is scored. */
#include "gen3d/eval.h"

#include "gen3d/cameras_json.h"
#include "gen3d/depthio.h"
#include "gen3d/frame.h"
#include "gen3d/imageio.h"
#include "gen3d/resize.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

void g3d_eval_views_params_default(g3d_eval_views_params *p)
{
    p->input_view = -1;
    p->max_side = 0;
}

static void view_free(g3d_eval_view *v)
{
    free(v->name);
    g3d_image_free(&v->rgb);
    g3d_image_free(&v->depth);
    g3d_image_free(&v->mask);
    memset(v, 0, sizeof *v);
}

void g3d_eval_views_free(g3d_eval_views *v)
{
    if (!v) return;
    for (int i = 0; i < v->n; i++) view_free(&v->views[i]);
    free(v->views);
    view_free(&v->input);
    memset(v, 0, sizeof *v);
}

static int exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

static g3d_status set_name(g3d_eval_view *v, const char *name)
{
    size_t n = strlen(name) + 1;
    v->name = malloc(n);
    if (!v->name) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    memcpy(v->name, name, n);
    return G3D_OK;
}

/* A path from a camera file: relative to the file's folder unless absolute (malloc'd). */
static char *resolve(const char *dir, const char *rel)
{
    return rel[0] == '/' ? g3d_path_join("", rel) : g3d_path_join(dir, rel);
}

static g3d_status check_size(const g3d_image *img, const g3d_camera *cam, const char *path, const char *what)
{
    if (img->w != cam->K.width || img->h != cam->K.height)
        return G3D_ERR(G3D_ERR_MISMATCH, "%s: %s is %dx%d but its camera says %dx%d", path, what, img->w, img->h,
                       cam->K.width, cam->K.height);
    return G3D_OK;
}

/* Ground-truth depth: NaN and negative values are corrupt, not missing; then cleaned as every
 * reader does (0 and infinity mean unknown). */
static g3d_status check_gt_depth(g3d_image *d, const char *path)
{
    size_t nan = 0, neg = 0, n = g3d_image_size(d);
    for (size_t i = 0; i < n; i++) {
        nan += isnan(d->data[i]);
        neg += d->data[i] < 0;
    }
    if (nan || neg)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: ground-truth depth has %zu NaN and %zu negative values "
                       "(use 0 or infinity for unknown depth)", path, nan, neg);
    g3d_depth_sanitize(d);
    return G3D_OK;
}

static g3d_status load_gt_depth(const char *path, g3d_image *d)
{
    G3D_TRY(g3d_depth_load_raw(path, 0, d));
    g3d_status rc = check_gt_depth(d, path);
    if (rc != G3D_OK) g3d_image_free(d);
    return rc;
}

/* Shrinks a view so its longer side is at most max_side (colour by area, depth and masks
 * nearest, intrinsics along). */
static g3d_status limit_size(g3d_eval_view *v, int max_side)
{
    const int w = v->cam.K.width, h = v->cam.K.height;
    if (max_side <= 0 || (w <= max_side && h <= max_side)) return G3D_OK;
    int nw, nh;
    g3d_fit_size(w, h, max_side, &nw, &nh);
    g3d_image *imgs[3] = {&v->rgb, &v->depth, &v->mask};
    for (int k = 0; k < 3; k++) {
        if (!imgs[k]->data) continue;
        g3d_image out;
        G3D_TRY(g3d_image_resize(imgs[k], nw, nh, k == 0 ? G3D_RESIZE_AREA : G3D_RESIZE_NEAREST, &out));
        g3d_image_free(imgs[k]);
        *imgs[k] = out;
    }
    v->cam.K = g3d_intrinsics_resize(v->cam.K, nw, nh);
    return G3D_OK;
}

/* ---- camera files ------------------------------------------------------------------------ */

static g3d_status load_frame(const char *file, const char *dir, const g3d_camera_list *l, int i, g3d_eval_view *v)
{
    g3d_status rc = G3D_OK;
    if (!l->names[i]) return G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d names no image", file, i);
    v->cam = l->cams[i];
    G3D_TRY(set_name(v, l->names[i]));
    const char *rel[3] = {l->names[i], l->mask_paths[i], l->depth_paths[i]};
    for (int k = 0; k < 3 && rc == G3D_OK; k++) {
        if (!rel[k]) continue;
        char *p = resolve(dir, rel[k]);
        if (!p) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        if (!exists(p)) rc = G3D_ERR(G3D_ERR_IO, "%s: frame %d: %s: no such file", file, i, p);
        else if (k == 0) rc = g3d_image_load(p, 3, &v->rgb);
        else if (k == 1) rc = g3d_image_load(p, 1, &v->mask);
        else rc = load_gt_depth(p, &v->depth);
        if (rc == G3D_OK) rc = check_size(k == 0 ? &v->rgb : k == 1 ? &v->mask : &v->depth, &v->cam, p,
                                          k == 0 ? "the image" : k == 1 ? "the mask" : "the depth map");
        free(p);
    }
    return rc;
}

/* The folder of a file path (malloc'd). */
static char *parent_dir(const char *file)
{
    const char *slash = strrchr(file, '/');
    if (!slash) return g3d_path_join(".", "");
    if (slash == file) return g3d_path_join("/", "");
    char *d = malloc((size_t)(slash - file) + 1);
    if (d) {
        memcpy(d, file, (size_t)(slash - file));
        d[slash - file] = '\0';
    }
    return d;
}

static int is_identity(const g3d_mat4 *m) { return g3d_mat4_max_abs_diff(*m, g3d_mat4_identity()) < 1e-9; }

static g3d_status load_camera_file(const char *file, const g3d_eval_views_params *p, g3d_eval_views *v)
{
    g3d_camera_list l;
    G3D_TRY(g3d_camera_list_load(file, &l));
    g3d_status rc = G3D_OK;
    int input = p->input_view;
    if (input == -1) {
        input = -2;
        for (int i = 0; i < l.n && input < 0; i++)
            if (is_identity(&l.cams[i].c2w)) input = i;
    }
    const int scored = l.n - (input >= 0);
    if (input >= l.n) rc = G3D_ERR(G3D_ERR_ARG, "%s: input view %d asked for, the file has %d frames", file, input, l.n);
    else if (scored < 1) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: no view to score", file);
    else if (!(v->views = g3d_calloc((size_t)scored, sizeof *v->views, "views"))) rc = G3D_ERR_NOMEM;
    char *dir = rc == G3D_OK ? parent_dir(file) : NULL;
    if (rc == G3D_OK && !dir) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    for (int i = 0; i < l.n && rc == G3D_OK; i++) {
        g3d_eval_view *dst = i == input ? &v->input : &v->views[v->n++];
        rc = load_frame(file, dir, &l, i, dst);
    }
    v->kind = "camera file";
    free(dir);
    g3d_camera_list_free(&l);
    return rc;
}

/* ---- Middlebury folders -------------------------------------------------------------------- */

typedef struct calib {
    double K[2][4];   /* fx fy cx cy of cam0, cam1 */
    double doffs, baseline_mm;
    int width, height;
} calib;

/* "[f 0 cx; 0 f cy; 0 0 1]" */
static int parse_matrix(const char *s, double *fx, double *fy, double *cx, double *cy)
{
    double m[9];
    const char *p = strchr(s, '[');
    if (!p) return 0;
    p++;
    for (int i = 0; i < 9; i++) {
        while (*p == ' ' || *p == ';' || *p == '\t') p++;
        char *end;
        m[i] = strtod(p, &end);
        if (end == p || !isfinite(m[i])) return 0;
        p = end;
    }
    *fx = m[0];
    *fy = m[4];
    *cx = m[2];
    *cy = m[5];
    return m[0] > 0 && m[4] > 0;
}

static g3d_status read_calib(const char *path, calib *c)
{
    unsigned char *buf;
    size_t n;
    G3D_TRY(g3d_read_file(path, 1 << 16, &buf, &n));
    int have = 0;
    memset(c, 0, sizeof *c);
    for (char *line = (char *)buf; line && *line;) {
        char *next = strchr(line, '\n');
        if (next) *next++ = '\0';
        char *eq = strchr(line, '=');
        if (line[0] != '#' && eq) {
            *eq = '\0';
            const char *val = eq + 1;
            if (!strcmp(line, "cam0") || !strcmp(line, "cam1")) {
                double *k = c->K[line[3] - '0'];
                if (!parse_matrix(val, &k[0], &k[1], &k[2], &k[3])) {
                    free(buf);
                    return G3D_ERR(G3D_ERR_FORMAT, "%s: %s is not a camera matrix [f 0 cx; 0 f cy; 0 0 1]", path, line);
                }
                have |= line[3] == '0' ? 1 : 2;
            } else if (!strcmp(line, "doffs")) {
                c->doffs = strtod(val, NULL);
                have |= 4;
            } else if (!strcmp(line, "baseline")) {
                c->baseline_mm = strtod(val, NULL);
                have |= 8;
            } else if (!strcmp(line, "width")) {
                c->width = atoi(val);
            } else if (!strcmp(line, "height")) {
                c->height = atoi(val);
            }
        }
        line = next;
    }
    free(buf);
    if ((have & 15) != 15) return G3D_ERR(G3D_ERR_FORMAT, "%s: needs cam0, cam1, doffs and baseline", path);
    if (!isfinite(c->doffs) || !(c->baseline_mm > 0) || !isfinite(c->baseline_mm))
        return G3D_ERR(G3D_ERR_FORMAT, "%s: doffs and baseline must be finite, baseline positive", path);
    return G3D_OK;
}

/* One side of a calibrated pair: image, and depth from its disparity file when there is one. */
static g3d_status load_side(const char *dir, const calib *c, int side, g3d_eval_view *v)
{
    char img_name[16], disp_name[16];
    snprintf(img_name, sizeof img_name, "im%d.png", side);
    snprintf(disp_name, sizeof disp_name, "disp%d.pfm", side);
    char *img = g3d_path_join(dir, img_name), *disp = g3d_path_join(dir, disp_name);
    g3d_status rc = img && disp ? set_name(v, img_name) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK && !exists(img)) rc = G3D_ERR(G3D_ERR_IO, "%s: no such file", img);
    if (rc == G3D_OK) rc = g3d_image_load(img, 3, &v->rgb);
    if (rc == G3D_OK && c->width > 0 && (v->rgb.w != c->width || v->rgb.h != c->height))
        rc = G3D_ERR(G3D_ERR_MISMATCH, "%s: image is %dx%d but calib.txt says %dx%d", img, v->rgb.w, v->rgb.h,
                     c->width, c->height);
    if (rc == G3D_OK) {
        const double *k = c->K[side];
        v->cam.K = g3d_intrinsics_make(k[0], k[1], k[2], k[3], v->rgb.w, v->rgb.h);
        v->cam.c2w = g3d_mat4_identity();
        v->cam.c2w.m[0][3] = side ? c->baseline_mm / 1000.0 : 0.0;
    }
    if (rc == G3D_OK && exists(disp)) {
        rc = g3d_pfm_load(disp, &v->depth);
        if (rc == G3D_OK && v->depth.c != 1) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: disparity must have one channel", disp);
        if (rc == G3D_OK) rc = check_size(&v->depth, &v->cam, disp, "the disparity map");
        if (rc == G3D_OK) {
            size_t nan = 0;
            for (size_t i = 0; i < g3d_image_size(&v->depth); i++) nan += isnan(v->depth.data[i]);
            if (nan) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: %zu disparities are NaN (use infinity for unknown)", disp, nan);
        }
        if (rc == G3D_OK) g3d_disparity_to_depth(&v->depth, v->cam.K.fx, c->baseline_mm / 1000.0, c->doffs);
    }
    free(img);
    free(disp);
    return rc;
}

static g3d_status load_calibrated_pair(const char *dir, const char *calib_path, g3d_eval_views *v)
{
    calib c;
    G3D_TRY(read_calib(calib_path, &c));
    if (!(v->views = g3d_calloc(1, sizeof *v->views, "views"))) return G3D_ERR_NOMEM;
    v->n = 1;
    G3D_TRY(load_side(dir, &c, 0, &v->input));
    return load_side(dir, &c, 1, &v->views[0]);
}

/* The default input's layout (motorcycle_*.png + disparity .npz, calibration built in). */
static g3d_status load_default_input(const char *dir, g3d_eval_views *v)
{
    g3d_frame f;
    G3D_TRY(g3d_frame_load_middlebury(dir, &f));
    g3d_status rc = G3D_OK;
    if (!(v->views = g3d_calloc(1, sizeof *v->views, "views"))) rc = G3D_ERR_NOMEM;
    if (rc == G3D_OK) {
        char *l = g3d_path_join(dir, "motorcycle_left.png");
        int skimage_names = l && exists(l);
        free(l);
        v->n = 1;
        v->input.cam = f.cam;
        v->input.rgb = f.rgb;
        v->input.depth = f.depth;
        v->views[0].cam = f.heldout_cam;
        v->views[0].rgb = f.heldout;
        memset(&f.rgb, 0, sizeof f.rgb);
        memset(&f.depth, 0, sizeof f.depth);
        memset(&f.heldout, 0, sizeof f.heldout);
        rc = set_name(&v->input, skimage_names ? "motorcycle_left.png" : "im0.png");
        if (rc == G3D_OK) rc = set_name(&v->views[0], skimage_names ? "motorcycle_right.png" : "im1.png");
    }
    g3d_frame_free(&f);
    return rc;
}

/* ---- entry point --------------------------------------------------------------------------- */

g3d_status g3d_eval_views_load(const char *path, const g3d_eval_views_params *p, g3d_eval_views *v)
{
    g3d_eval_views_params def;
    g3d_eval_views_params_default(&def);
    if (!p) p = &def;
    memset(v, 0, sizeof *v);
    struct stat st;
    if (stat(path, &st) != 0) return G3D_ERR(G3D_ERR_IO, "%s: no such file or folder", path);
    g3d_status rc;
    if (!S_ISDIR(st.st_mode)) {
        rc = load_camera_file(path, p, v);
    } else {
        const char *files[4] = {"transforms.json", "cameras.json", "calib.txt", "motorcycle_disp.npz"};
        int found = -1;
        char *f = NULL;
        for (int k = 0; k < 4 && found < 0; k++) {
            free(f);
            f = g3d_path_join(path, files[k]);
            if (!f) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
            if (exists(f)) found = k;
        }
        if (found < 0) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: no transforms.json, cameras.json or Middlebury pair (calib.txt) here", path);
        else if (found < 2) rc = load_camera_file(f, p, v);
        else if (found == 2) rc = load_calibrated_pair(path, f, v);
        else rc = load_default_input(path, v);
        if (found >= 2) v->kind = "middlebury";
        free(f);
        /* the left view is the input unless the caller says there is none */
        if (rc == G3D_OK && found >= 2 && p->input_view == -2) {
            view_free(&v->input);
        } else if (rc == G3D_OK && found >= 2 && p->input_view > 0) {
            rc = G3D_ERR(G3D_ERR_ARG, "%s: a stereo pair's input view is its left image (0)", path);
        }
    }
    for (int i = -1; i < v->n && rc == G3D_OK; i++) {
        g3d_eval_view *w = i < 0 ? &v->input : &v->views[i];
        if (w->rgb.data) rc = limit_size(w, p->max_side);
    }
    if (rc != G3D_OK) g3d_eval_views_free(v);
    return rc;
}
