/* A whole evaluation: every method on every view, means, contact sheets. */
#include "gen3d/eval.h"

#include "gen3d/imageio.h"
#include "gen3d/render.h"
#include "gen3d/resize.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define SHEET_PANEL_MAX 512   /* longer side of a contact-sheet panel, pixels */
#define SHEET_GAP 4
#define HEAT_MAX 0.25         /* mean absolute error shown as white */

const char *g3d_eval_method_name(int method)
{
    static const char *const names[G3D_EVAL_METHODS] = {"scene", "input_image", "forward_warp"};
    return method >= 0 && method < G3D_EVAL_METHODS ? names[method] : "?";
}

void g3d_eval_params_default(g3d_eval_params *p)
{
    memset(p, 0, sizeof *p);
    p->baselines = 1;
}

void g3d_eval_report_free(g3d_eval_report *r)
{
    if (!r) return;
    for (int m = 0; m < G3D_EVAL_METHODS; m++) {
        free(r->all[m]);
        free(r->covisible[m]);
    }
    if (r->sheets)
        for (int i = 0; i < r->n; i++) free(r->sheets[i]);
    free(r->sheets);
    free(r->covis_kind);
    free(r->covis_fraction);
    memset(r, 0, sizeof *r);
}

/* What a saved 8-bit frame holds: the PNG writer's rounding, read back as k / 255. */
static void quantize8(g3d_image *img)
{
    for (size_t i = 0; i < g3d_image_size(img); i++) {
        float v = img->data[i] * 255.0f;
        v = v != v ? 0.0f : (v < 0 ? 0.0f : (v > 255.0f ? 255.0f : v));
        img->data[i] = (float)lrintf(v) / 255.0f;
    }
}

/* ---- contact sheets -------------------------------------------------------------------- */

/* Error heat map: mean absolute error over the channels, black -> red -> yellow -> white at
 * HEAT_MAX on the co-visible region (everywhere when there is none), black -> blue outside it,
 * grey outside the view's mask. */
static g3d_status heat_map(const g3d_image *pred, const g3d_eval_view *gt, const g3d_image *covis, g3d_image *out)
{
    G3D_TRY(g3d_image_create(out, pred->w, pred->h, 3));
    for (size_t i = 0; i < (size_t)pred->w * pred->h; i++) {
        float *o = out->data + 3 * i;
        if (gt->mask.data && !(gt->mask.data[i] > 0.5f)) {
            o[0] = o[1] = o[2] = 0.5f;
            continue;
        }
        double e = 0;
        for (int c = 0; c < 3; c++) e += fabs((double)pred->data[3 * i + c] - gt->rgb.data[3 * i + c]) / 3.0;
        const double t = fmin(1.0, e / HEAT_MAX);
        if (covis && !(covis->data[i] > 0.5f)) {
            o[0] = 0.0f;
            o[1] = (float)(0.5 * t);
            o[2] = (float)t;
        } else {
            for (int c = 0; c < 3; c++) o[c] = (float)fmin(1.0, fmax(0.0, 3.0 * t - c));
        }
    }
    return G3D_OK;
}

typedef struct sheet {
    g3d_image img;
    int pw, ph, rows;
} sheet;

static g3d_status sheet_begin(sheet *s, int w, int h, int rows)
{
    s->pw = w, s->ph = h;
    if (w > SHEET_PANEL_MAX || h > SHEET_PANEL_MAX) g3d_fit_size(w, h, SHEET_PANEL_MAX, &s->pw, &s->ph);
    s->rows = 0;
    G3D_TRY(g3d_image_create(&s->img, 3 * s->pw + 2 * SHEET_GAP, rows * s->ph + (rows - 1) * SHEET_GAP, 3));
    for (size_t i = 0; i < g3d_image_size(&s->img); i++) s->img.data[i] = 1.0f;
    return G3D_OK;
}

static g3d_status sheet_panel(sheet *s, int col, const g3d_image *img)
{
    g3d_image small = {0};
    const g3d_image *src = img;
    if (img->w != s->pw || img->h != s->ph) {
        G3D_TRY(g3d_image_resize(img, s->pw, s->ph, G3D_RESIZE_AREA, &small));
        src = &small;
    }
    const int x0 = col * (s->pw + SHEET_GAP), y0 = s->rows * (s->ph + SHEET_GAP);
    for (int y = 0; y < s->ph; y++)
        memcpy(g3d_image_px(&s->img, x0, y0 + y), g3d_image_px(src, 0, y), sizeof(float) * 3 * (size_t)s->pw);
    g3d_image_free(&small);
    return G3D_OK;
}

/* "<index>_<image base name>.png" with anything unusual replaced by '_' (malloc'd). */
static char *sheet_name(int index, const char *view_name)
{
    const char *base = strrchr(view_name, '/');
    base = base ? base + 1 : view_name;
    char stem[80];
    size_t n = 0;
    for (; base[n] && base[n] != '.' && n < sizeof stem - 1; n++) {
        char c = base[n];
        stem[n] = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' ? c : '_';
    }
    stem[n] = '\0';
    char buf[128];
    snprintf(buf, sizeof buf, "%03d_%s.png", index, stem);
    return g3d_path_join("", buf);
}

/* ---- one view -------------------------------------------------------------------------- */

typedef struct ctx {
    const g3d_eval_views *v;
    const g3d_eval_params *p;
    g3d_eval_report *r;
} ctx;

/* The prediction of a baseline for view i: *rgb and *depth are created. */
static g3d_status baseline(const ctx *x, int method, const g3d_eval_view *view, g3d_image *rgb, g3d_image *depth)
{
    const g3d_eval_view *in = &x->v->input;
    if (method == G3D_EVAL_FORWARD_WARP) return g3d_eval_forward_warp(&in->cam, &in->rgb, &in->depth, &view->cam, rgb, depth);
    const int w = view->cam.K.width, h = view->cam.K.height;
    if (in->rgb.w == w && in->rgb.h == h) G3D_TRY(g3d_image_clone(rgb, &in->rgb));
    else G3D_TRY(g3d_image_resize(&in->rgb, w, h, G3D_RESIZE_AREA, rgb));
    if (!in->depth.data) return G3D_OK;
    if (in->depth.w == w && in->depth.h == h) return g3d_image_clone(depth, &in->depth);
    return g3d_image_resize(&in->depth, w, h, G3D_RESIZE_NEAREST, depth);
}

static g3d_status score_view(ctx *x, int i, const g3d_image *scene_rgb, const g3d_image *scene_depth)
{
    const g3d_eval_view *view = &x->v->views[i];
    g3d_eval_report *r = x->r;
    const int w = view->cam.K.width, h = view->cam.K.height;
    g3d_image covis = {0};
    g3d_covis_kind kind;
    G3D_TRY(g3d_eval_covisible(x->v->input.depth.data ? &x->v->input : NULL, view, &covis, &kind));
    g3d_status rc = G3D_OK;
    if (kind == G3D_COVIS_NONE && scene_depth) {
        /* rendered depth is set exactly where the accumulated alpha reaches 0.5 */
        rc = g3d_image_create(&covis, w, h, 1);
        for (size_t k = 0; rc == G3D_OK && k < (size_t)w * h; k++) covis.data[k] = scene_depth->data[k] > 0;
        kind = G3D_COVIS_SCENE_ALPHA;
    }
    r->covis_kind[i] = kind;
    int64_t in_mask = 0, both = 0;
    for (size_t k = 0; k < (size_t)w * h; k++) {
        int m = !view->mask.data || view->mask.data[k] > 0.5f;
        in_mask += m;
        both += m && covis.data && covis.data[k] > 0.5f;
    }
    r->covis_fraction[i] = kind != G3D_COVIS_NONE && in_mask ? (double)both / in_mask : NAN;

    int rows = 0;
    for (int m = 0; m < G3D_EVAL_METHODS; m++) rows += r->scored[m];
    sheet sh = {0};
    if (rc == G3D_OK && x->p->sheets_dir) rc = sheet_begin(&sh, w, h, rows);
    for (int m = 0; m < G3D_EVAL_METHODS && rc == G3D_OK; m++) {
        if (!r->scored[m]) continue;
        g3d_image rgb = {0}, depth = {0};
        if (m == G3D_EVAL_SCENE) {
            rc = g3d_image_clone(&rgb, scene_rgb);
            if (rc == G3D_OK) rc = g3d_image_clone(&depth, scene_depth);
        } else {
            rc = baseline(x, m, view, &rgb, &depth);
        }
        if (rc == G3D_OK) {
            quantize8(&rgb);
            const g3d_image *d = depth.data ? &depth : NULL;
            rc = g3d_eval_score(&rgb, d, view, NULL, &r->all[m][i]);
            if (rc == G3D_OK && kind != G3D_COVIS_NONE) rc = g3d_eval_score(&rgb, d, view, &covis, &r->covisible[m][i]);
        }
        if (rc == G3D_OK && sh.img.data) {
            g3d_image heat = {0};
            rc = heat_map(&rgb, view, covis.data ? &covis : NULL, &heat);
            if (rc == G3D_OK) rc = sheet_panel(&sh, 0, &view->rgb);
            if (rc == G3D_OK) rc = sheet_panel(&sh, 1, &rgb);
            if (rc == G3D_OK) rc = sheet_panel(&sh, 2, &heat);
            sh.rows++;
            g3d_image_free(&heat);
        }
        g3d_image_free(&rgb);
        g3d_image_free(&depth);
    }
    if (rc == G3D_OK && sh.img.data) {
        r->sheets[i] = sheet_name(i, view->name ? view->name : "view");
        char *path = r->sheets[i] ? g3d_path_join(x->p->sheets_dir, r->sheets[i]) : NULL;
        rc = path ? g3d_image_save_png(path, &sh.img, 8) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        free(path);
    }
    g3d_image_free(&sh.img);
    g3d_image_free(&covis);
    if (rc == G3D_OK && g3d_progress_report(&x->p->progress, "eval", i + 1, x->v->n, NULL))
        rc = G3D_ERR(G3D_ERR_ARG, "eval: cancelled");
    return rc;
}

static g3d_status rendered(void *user, int index, const g3d_camera *cam, const g3d_image *rgb, const g3d_image *depth)
{
    (void)cam;
    return score_view(user, index, rgb, depth);
}

/* ---- means ----------------------------------------------------------------------------- */

static void mean_of(const g3d_eval_metrics *per, int n, g3d_eval_metrics *out)
{
    double sum[6] = {0};
    int cnt[6] = {0};
    memset(out, 0, sizeof *out);
    for (int i = 0; i < n; i++) {
        const g3d_eval_metrics *m = &per[i];
        const double v[6] = {m->mse, m->psnr, m->ssim, m->depth_abs_rel, m->depth_rmse, m->depth_coverage};
        for (int k = 0; k < 6; k++)
            if (!isnan(v[k])) {
                sum[k] += v[k];
                cnt[k]++;
            }
        out->pixels += m->pixels;
        out->depth_pixels += m->depth_pixels;
    }
    double mean[6];
    for (int k = 0; k < 6; k++) mean[k] = cnt[k] ? sum[k] / cnt[k] : NAN;
    out->mse = mean[0];
    out->psnr = mean[1];
    out->ssim = mean[2];
    out->depth_abs_rel = mean[3];
    out->depth_rmse = mean[4];
    out->depth_coverage = mean[5];
}

g3d_status g3d_eval_run(const g3d_gaussians *scene, const g3d_eval_views *v, const g3d_eval_params *p,
                        g3d_eval_report *r)
{
    memset(r, 0, sizeof *r);
    if (v->n < 1) return G3D_ERR(G3D_ERR_ARG, "eval: no views to score");
    const int have_input = v->input.rgb.data != NULL;
    r->scored[G3D_EVAL_SCENE] = scene != NULL;
    r->scored[G3D_EVAL_INPUT_IMAGE] = p->baselines && have_input;
    r->scored[G3D_EVAL_FORWARD_WARP] = p->baselines && have_input && v->input.depth.data;
    if (!r->scored[0] && !r->scored[1])
        return G3D_ERR(G3D_ERR_ARG, "eval: nothing to score (no scene, and no input view for the baselines)");
    r->n = v->n;
    const double nan = NAN;
    const g3d_eval_metrics none = {0, nan, nan, nan, 0, nan, nan, nan};
    g3d_status rc = G3D_OK;
    for (int m = 0; m < G3D_EVAL_METHODS && rc == G3D_OK; m++) {
        if (!r->scored[m]) continue;
        r->all[m] = g3d_calloc((size_t)v->n, sizeof(g3d_eval_metrics), "eval metrics");
        r->covisible[m] = g3d_calloc((size_t)v->n, sizeof(g3d_eval_metrics), "eval metrics");
        if (!r->all[m] || !r->covisible[m]) rc = G3D_ERR_NOMEM;
        for (int i = 0; rc == G3D_OK && i < v->n; i++) r->all[m][i] = r->covisible[m][i] = none;
    }
    r->covis_kind = g3d_calloc((size_t)v->n, sizeof *r->covis_kind, "eval");
    r->covis_fraction = g3d_calloc((size_t)v->n, sizeof *r->covis_fraction, "eval");
    r->sheets = g3d_calloc((size_t)v->n, sizeof *r->sheets, "eval");
    if (rc == G3D_OK && (!r->covis_kind || !r->covis_fraction || !r->sheets)) rc = G3D_ERR_NOMEM;

    ctx x = {v, p, r};
    if (rc == G3D_OK && scene) {
        g3d_camera *cams = g3d_calloc((size_t)v->n, sizeof *cams, "cameras");
        if (!cams) rc = G3D_ERR_NOMEM;
        for (int i = 0; rc == G3D_OK && i < v->n; i++) cams[i] = v->views[i].cam;
        g3d_render_params ro;
        g3d_render_params_default(&ro);
        ro.depth = 1;
        if (rc == G3D_OK) rc = g3d_render_path(scene, cams, v->n, &ro, rendered, &x);
        free(cams);
    } else {
        for (int i = 0; rc == G3D_OK && i < v->n; i++) rc = score_view(&x, i, NULL, NULL);
    }
    for (int m = 0; m < G3D_EVAL_METHODS && rc == G3D_OK; m++) {
        if (!r->scored[m]) continue;
        mean_of(r->all[m], v->n, &r->mean_all[m]);
        mean_of(r->covisible[m], v->n, &r->mean_covisible[m]);
    }
    if (rc != G3D_OK) g3d_eval_report_free(r);
    return rc;
}
