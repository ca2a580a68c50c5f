/* The evaluation folder: eval.json and the contact sheets, written atomically. */
#include "gen3d/eval.h"

#include "io/json_int.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* JSON has no infinity and no NaN: +inf becomes "inf" (only PSNR reaches it), NaN null. */
static void add_num(cJSON *o, const char *key, double v)
{
    if (isnan(v)) cJSON_AddNullToObject(o, key);
    else if (isinf(v)) cJSON_AddStringToObject(o, key, v > 0 ? "inf" : "-inf");
    else cJSON_AddNumberToObject(o, key, v);
}

static cJSON *metrics_json(const g3d_eval_metrics *m)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "pixels", (double)m->pixels);
    add_num(o, "psnr", m->psnr);
    add_num(o, "ssim", m->ssim);
    add_num(o, "mse", m->mse);
    add_num(o, "depth_abs_rel", m->depth_abs_rel);
    add_num(o, "depth_rmse", m->depth_rmse);
    add_num(o, "depth_coverage", m->depth_coverage);
    cJSON_AddNumberToObject(o, "depth_pixels", (double)m->depth_pixels);
    return o;
}

static cJSON *regions_json(const g3d_eval_metrics *all, const g3d_eval_metrics *covisible)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddItemToObject(o, "all", metrics_json(all));
    cJSON_AddItemToObject(o, "covisible", metrics_json(covisible));
    return o;
}

static void add_str_or_null(cJSON *o, const char *key, const char *s)
{
    if (s) cJSON_AddStringToObject(o, key, s);
    else cJSON_AddNullToObject(o, key);
}

static g3d_status write_json(const char *path, const g3d_eval_report *r, const g3d_eval_views *v,
                             const char *scene_label, const char *views_label)
{
    cJSON *root = cJSON_CreateObject();
    cJSON_AddNumberToObject(root, "version", 1);
    add_str_or_null(root, "scene", scene_label);
    add_str_or_null(root, "views", views_label);
    cJSON_AddStringToObject(root, "views_kind", v->kind ? v->kind : "");
    add_str_or_null(root, "input_view", v->input.rgb.data ? v->input.name : NULL);
    cJSON *proto = cJSON_CreateObject();
    cJSON_AddNumberToObject(proto, "prediction_bits", 8);
    cJSON_AddStringToObject(proto, "ssim", "11x11 Gaussian window, sigma 1.5, C1 = 0.01^2, C2 = 0.03^2, "
                                           "pixels within 5 of the border left out");
    cJSON_AddNumberToObject(proto, "covisible_depth_tolerance", G3D_EVAL_COVIS_DEPTH_TOL);
    cJSON_AddItemToObject(root, "protocol", proto);
    cJSON *methods = cJSON_CreateArray(), *mean = cJSON_CreateObject();
    for (int m = 0; m < G3D_EVAL_METHODS; m++) {
        if (!r->scored[m]) continue;
        cJSON_AddItemToArray(methods, cJSON_CreateString(g3d_eval_method_name(m)));
        cJSON_AddItemToObject(mean, g3d_eval_method_name(m), regions_json(&r->mean_all[m], &r->mean_covisible[m]));
    }
    cJSON_AddItemToObject(root, "methods", methods);
    cJSON_AddItemToObject(root, "mean", mean);
    cJSON *views = cJSON_CreateArray();
    for (int i = 0; i < r->n; i++) {
        const g3d_eval_view *view = &v->views[i];
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "name", view->name ? view->name : "");
        cJSON_AddNumberToObject(o, "width", view->cam.K.width);
        cJSON_AddNumberToObject(o, "height", view->cam.K.height);
        cJSON_AddStringToObject(o, "covisible_from", g3d_covis_kind_name(r->covis_kind[i]));
        add_num(o, "covisible_fraction", r->covis_fraction[i]);
        if (r->sheets[i]) {
            char *s = g3d_path_join("sheets", r->sheets[i]);
            add_str_or_null(o, "sheet", s);
            free(s);
        }
        for (int m = 0; m < G3D_EVAL_METHODS; m++)
            if (r->scored[m]) cJSON_AddItemToObject(o, g3d_eval_method_name(m), regions_json(&r->all[m][i], &r->covisible[m][i]));
        cJSON_AddItemToArray(views, o);
    }
    cJSON_AddItemToObject(root, "per_view", views);
    return g3d_json_save(path, root);
}

g3d_status g3d_eval_to_dir(const g3d_gaussians *scene, const g3d_eval_views *v, const g3d_eval_params *p,
                           const char *dir, const char *scene_label, const char *views_label, g3d_eval_report *out)
{
    char *tmp = NULL, *sheets = NULL, *json = NULL;
    g3d_eval_report r = {0};
    G3D_TRY(g3d_atomic_dir_begin(dir, &tmp));
    sheets = g3d_path_join(tmp, "sheets");
    json = g3d_path_join(tmp, "eval.json");
    g3d_status rc = sheets && json ? g3d_mkdirs(sheets) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_eval_params q = *p;
    q.sheets_dir = sheets;
    if (rc == G3D_OK) rc = g3d_eval_run(scene, v, &q, &r);
    if (rc == G3D_OK) rc = write_json(json, &r, v, scene_label, views_label);
    if (rc == G3D_OK) rc = g3d_atomic_dir_commit(tmp, dir);
    if (rc != G3D_OK) g3d_atomic_dir_abort(tmp);
    if (rc == G3D_OK && out) *out = r;
    else g3d_eval_report_free(&r);
    free(tmp);
    free(sheets);
    free(json);
    return rc;
}
