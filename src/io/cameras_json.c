/* cameras.json and transforms.json through cJSON. */
#include "gen3d/cameras_json.h"

#include "io/json_int.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define MAX_JSON_BYTES ((size_t)256 << 20)

g3d_status g3d_camera_list_create(g3d_camera_list *l, int n)
{
    memset(l, 0, sizeof *l);
    if (n < 0) return G3D_ERR(G3D_ERR_ARG, "negative camera count");
    l->cams = g3d_calloc((size_t)(n ? n : 1), sizeof *l->cams, "cameras");
    l->names = g3d_calloc((size_t)(n ? n : 1), sizeof *l->names, "cameras");
    l->mask_paths = g3d_calloc((size_t)(n ? n : 1), sizeof *l->mask_paths, "cameras");
    l->depth_paths = g3d_calloc((size_t)(n ? n : 1), sizeof *l->depth_paths, "cameras");
    if (!l->cams || !l->names || !l->mask_paths || !l->depth_paths) { g3d_camera_list_free(l); return G3D_ERR_NOMEM; }
    l->n = n;
    return G3D_OK;
}

void g3d_camera_list_free(g3d_camera_list *l)
{
    if (!l) return;
    for (int i = 0; i < l->n; i++) {
        if (l->names) free(l->names[i]);
        if (l->mask_paths) free(l->mask_paths[i]);
        if (l->depth_paths) free(l->depth_paths[i]);
    }
    free(l->cams);
    free(l->names);
    free(l->mask_paths);
    free(l->depth_paths);
    memset(l, 0, sizeof *l);
}

static g3d_status set_str(char **slot, const char *s)
{
    free(*slot);
    *slot = NULL;
    if (!s) return G3D_OK;
    size_t n = strlen(s) + 1;
    *slot = malloc(n);
    if (!*slot) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    memcpy(*slot, s, n);
    return G3D_OK;
}

g3d_status g3d_camera_list_set_name(g3d_camera_list *l, int i, const char *name) { return set_str(&l->names[i], name); }
g3d_status g3d_camera_list_set_mask(g3d_camera_list *l, int i, const char *m) { return set_str(&l->mask_paths[i], m); }
g3d_status g3d_camera_list_set_depth(g3d_camera_list *l, int i, const char *d) { return set_str(&l->depth_paths[i], d); }

/* ---- shared helpers ----------------------------------------------------------------------- */

static g3d_status load_json(const char *path, cJSON **root)
{
    unsigned char *buf;
    size_t n;
    G3D_TRY(g3d_read_file(path, MAX_JSON_BYTES, &buf, &n));
    const char *end = NULL;
    *root = cJSON_ParseWithLengthOpts((const char *)buf, n, &end, 0);
    if (!*root) {
        size_t off = end ? (size_t)(end - (const char *)buf) : 0;
        free(buf);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: malformed JSON near byte %zu", path, off);
    }
    free(buf);
    return G3D_OK;
}

/* Reads a finite number field; `required` makes absence an error. */
static g3d_status get_num(const cJSON *obj, const char *key, double *out, int required, const char *path, int frame)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!v) {
        if (!required) return G3D_OK;
        return frame >= 0 ? G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d: missing \"%s\"", path, frame, key)
                          : G3D_ERR(G3D_ERR_FORMAT, "%s: missing \"%s\"", path, key);
    }
    if (!cJSON_IsNumber(v) || !isfinite(v->valuedouble))
        return G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d: \"%s\" is not a finite number", path, frame, key);
    *out = v->valuedouble;
    return G3D_OK;
}

static g3d_status get_matrix(const cJSON *obj, const char *key, g3d_mat4 *m, const char *path, int frame)
{
    const cJSON *rows = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!cJSON_IsArray(rows) || (cJSON_GetArraySize(rows) != 4 && cJSON_GetArraySize(rows) != 3))
        return G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d: \"%s\" must be a 4x4 (or 3x4) matrix", path, frame, key);
    *m = g3d_mat4_identity();
    for (int r = 0; r < cJSON_GetArraySize(rows); r++) {
        const cJSON *row = cJSON_GetArrayItem(rows, r);
        if (!cJSON_IsArray(row) || cJSON_GetArraySize(row) != 4)
            return G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d: \"%s\" row %d must have 4 numbers", path, frame, key, r);
        for (int c = 0; c < 4; c++) {
            const cJSON *v = cJSON_GetArrayItem(row, c);
            if (!cJSON_IsNumber(v) || !isfinite(v->valuedouble))
                return G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d: \"%s\" has an entry that is not a finite number", path, frame, key);
            m->m[r][c] = v->valuedouble;
        }
    }
    /* A pose must be rigid: orthonormal rotation with determinant +1, last row (0 0 0 1).
     * Scaled poses would silently distort every reprojection. */
    double worst = 0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double d = 0;
            for (int k = 0; k < 3; k++) d += m->m[k][i] * m->m[k][j];
            worst = fmax(worst, fabs(d - (i == j)));
        }
    double det = m->m[0][0] * (m->m[1][1] * m->m[2][2] - m->m[1][2] * m->m[2][1]) -
                 m->m[0][1] * (m->m[1][0] * m->m[2][2] - m->m[1][2] * m->m[2][0]) +
                 m->m[0][2] * (m->m[1][0] * m->m[2][1] - m->m[1][1] * m->m[2][0]);
    if (worst > 1e-4 || det < 0 || fabs(m->m[3][0]) + fabs(m->m[3][1]) + fabs(m->m[3][2]) + fabs(m->m[3][3] - 1) > 1e-6)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d: \"%s\" is not a rigid transform", path, frame, key);
    return G3D_OK;
}

static cJSON *matrix_json(g3d_mat4 m)
{
    cJSON *rows = cJSON_CreateArray();
    for (int r = 0; r < 4; r++) {
        cJSON *row = cJSON_CreateArray();
        for (int c = 0; c < 4; c++) cJSON_AddItemToArray(row, cJSON_CreateNumber(m.m[r][c]));
        cJSON_AddItemToArray(rows, row);
    }
    return rows;
}

g3d_status g3d_json_save(const char *path, cJSON *root)
{
    char *text = cJSON_Print(root);
    cJSON_Delete(root);
    if (!text) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", path);
    g3d_status rc = g3d_write_file_atomic(path, text, strlen(text));
    free(text);
    return rc;
}

static const char *get_str(const cJSON *obj, const char *key)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(obj, key);
    return cJSON_IsString(v) ? v->valuestring : NULL;
}

static g3d_status check_size(double w, double h, const char *path, int frame)
{
    if (w < 1 || h < 1 || w > G3D_MAX_IMAGE_SIDE || h > G3D_MAX_IMAGE_SIDE || w != floor(w) || h != floor(h))
        return G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d: image size %gx%g out of range", path, frame, w, h);
    return G3D_OK;
}

/* ---- cameras.json -------------------------------------------------------------------------- */

g3d_status g3d_cameras_json_write(const char *path, const g3d_camera_list *l)
{
    cJSON *root = cJSON_CreateObject(), *frames = cJSON_CreateArray();
    cJSON_AddNumberToObject(root, "version", 1);
    cJSON_AddStringToObject(root, "convention", "opencv_c2w");
    for (int i = 0; i < l->n; i++) {
        const g3d_camera *c = &l->cams[i];
        cJSON *f = cJSON_CreateObject();
        if (l->names[i]) cJSON_AddStringToObject(f, "name", l->names[i]);
        if (l->mask_paths[i]) cJSON_AddStringToObject(f, "mask_path", l->mask_paths[i]);
        if (l->depth_paths[i]) cJSON_AddStringToObject(f, "depth_path", l->depth_paths[i]);
        cJSON_AddNumberToObject(f, "fx", c->K.fx);
        cJSON_AddNumberToObject(f, "fy", c->K.fy);
        cJSON_AddNumberToObject(f, "cx", c->K.cx);
        cJSON_AddNumberToObject(f, "cy", c->K.cy);
        cJSON_AddNumberToObject(f, "width", c->K.width);
        cJSON_AddNumberToObject(f, "height", c->K.height);
        cJSON_AddItemToObject(f, "c2w", matrix_json(c->c2w));
        cJSON_AddItemToArray(frames, f);
    }
    cJSON_AddItemToObject(root, "frames", frames);
    return g3d_json_save(path, root);
}

g3d_status g3d_cameras_json_read(const char *path, g3d_camera_list *l)
{
    cJSON *root;
    memset(l, 0, sizeof *l);
    G3D_TRY(load_json(path, &root));
    g3d_status rc = G3D_OK;
    const cJSON *frames = cJSON_GetObjectItemCaseSensitive(root, "frames");
    const char *conv = get_str(root, "convention");
    if (!cJSON_IsArray(frames)) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: no \"frames\" array", path);
    else if (conv && strcmp(conv, "opencv_c2w"))
        rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: convention \"%s\" is not supported (expected opencv_c2w)", path, conv);
    else rc = g3d_camera_list_create(l, cJSON_GetArraySize(frames));
    for (int i = 0; rc == G3D_OK && i < l->n; i++) {
        const cJSON *f = cJSON_GetArrayItem(frames, i);
        g3d_camera *c = &l->cams[i];
        double w = 0, h = 0;
        if ((rc = get_num(f, "fx", &c->K.fx, 1, path, i)) || (rc = get_num(f, "fy", &c->K.fy, 1, path, i)) ||
            (rc = get_num(f, "cx", &c->K.cx, 1, path, i)) || (rc = get_num(f, "cy", &c->K.cy, 1, path, i)) ||
            (rc = get_num(f, "width", &w, 1, path, i)) || (rc = get_num(f, "height", &h, 1, path, i)) ||
            (rc = check_size(w, h, path, i)) || (rc = get_matrix(f, "c2w", &c->c2w, path, i)))
            break;
        if (!(c->K.fx > 0 && c->K.fy > 0)) { rc = G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d: focal length must be positive", path, i); break; }
        c->K.width = (int)w;
        c->K.height = (int)h;
        const char *name = get_str(f, "name");
        if (!name) name = get_str(f, "file_path");
        if ((rc = g3d_camera_list_set_name(l, i, name)) || (rc = g3d_camera_list_set_mask(l, i, get_str(f, "mask_path"))) ||
            (rc = g3d_camera_list_set_depth(l, i, get_str(f, "depth_path"))))
            break;
    }
    cJSON_Delete(root);
    if (rc != G3D_OK) g3d_camera_list_free(l);
    return rc;
}

/* ---- transforms.json ---------------------------------------------------------------------- */

/* nerfstudio's intrinsics fields (pixel centres at +0.5, see the header). */
static void add_ns_intrinsics(cJSON *o, const g3d_intrinsics *K)
{
    cJSON_AddNumberToObject(o, "fl_x", K->fx);
    cJSON_AddNumberToObject(o, "fl_y", K->fy);
    cJSON_AddNumberToObject(o, "cx", K->cx + 0.5);
    cJSON_AddNumberToObject(o, "cy", K->cy + 0.5);
    cJSON_AddNumberToObject(o, "w", K->width);
    cJSON_AddNumberToObject(o, "h", K->height);
}

g3d_status g3d_transforms_json_write(const char *path, const g3d_camera_list *l)
{
    cJSON *root = cJSON_CreateObject(), *frames = cJSON_CreateArray();
    cJSON_AddStringToObject(root, "camera_model", "PINHOLE");
    if (l->n > 0) {
        /* Shared intrinsics at the top level (from the first frame); frames that differ
         * repeat theirs. */
        add_ns_intrinsics(root, &l->cams[0].K);
    }
    for (int i = 0; i < l->n; i++) {
        const g3d_camera *c = &l->cams[i];
        const g3d_intrinsics *K0 = &l->cams[0].K;
        cJSON *f = cJSON_CreateObject();
        char fallback[32];
        snprintf(fallback, sizeof fallback, "frame_%05d", i);
        cJSON_AddStringToObject(f, "file_path", l->names[i] ? l->names[i] : fallback);
        if (l->mask_paths[i]) cJSON_AddStringToObject(f, "mask_path", l->mask_paths[i]);
        if (l->depth_paths[i]) cJSON_AddStringToObject(f, "depth_file_path", l->depth_paths[i]);
        if (memcmp(&c->K, K0, sizeof *K0) != 0) add_ns_intrinsics(f, &c->K);
        cJSON_AddItemToObject(f, "transform_matrix", matrix_json(g3d_pose_opencv_to_opengl(c->c2w)));
        cJSON_AddItemToArray(frames, f);
    }
    cJSON_AddItemToObject(root, "frames", frames);
    return g3d_json_save(path, root);
}

g3d_status g3d_transforms_json_read(const char *path, g3d_camera_list *l)
{
    cJSON *root;
    memset(l, 0, sizeof *l);
    G3D_TRY(load_json(path, &root));
    g3d_status rc = G3D_OK;
    const cJSON *frames = cJSON_GetObjectItemCaseSensitive(root, "frames");
    const char *model = get_str(root, "camera_model");
    double g[6] = {0, 0, 0, 0, 0, 0}; /* fl_x fl_y cx cy w h at the top level */
    static const char *const keys[6] = {"fl_x", "fl_y", "cx", "cy", "w", "h"};
    static const char *const dist[] = {"k1", "k2", "k3", "k4", "p1", "p2"};
    if (!cJSON_IsArray(frames)) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: no \"frames\" array", path);
    else if (model && strcmp(model, "PINHOLE") && strcmp(model, "OPENCV"))
        rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: camera_model \"%s\" is not supported (PINHOLE or OPENCV)", path, model);
    for (int k = 0; rc == G3D_OK && k < 6; k++) rc = get_num(root, keys[k], &g[k], 0, path, -1);
    for (int k = 0; rc == G3D_OK && k < 6; k++) {
        double d = 0;
        rc = get_num(root, dist[k], &d, 0, path, -1);
        if (rc == G3D_OK && d != 0)
            rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: lens distortion (%s = %g) is not supported; undistort the images first", path, dist[k], d);
    }
    if (rc == G3D_OK) {
        /* fl_y defaults to fl_x (square pixels), as nerfstudio does. */
        if (g[1] == 0) g[1] = g[0];
        rc = g3d_camera_list_create(l, cJSON_GetArraySize(frames));
    }
    for (int i = 0; rc == G3D_OK && i < l->n; i++) {
        const cJSON *f = cJSON_GetArrayItem(frames, i);
        double v[6];
        memcpy(v, g, sizeof v);
        for (int k = 0; rc == G3D_OK && k < 6; k++) rc = get_num(f, keys[k], &v[k], 0, path, i);
        if (rc) break;
        if (!cJSON_GetObjectItemCaseSensitive(f, "fl_y") && cJSON_GetObjectItemCaseSensitive(f, "fl_x")) v[1] = v[0];
        if (!(v[0] > 0 && v[1] > 0)) { rc = G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d: missing or non-positive fl_x/fl_y", path, i); break; }
        if ((rc = check_size(v[4], v[5], path, i))) break;
        g3d_camera *c = &l->cams[i];
        c->K = g3d_intrinsics_make(v[0], v[1], v[2] - 0.5, v[3] - 0.5, (int)v[4], (int)v[5]);
        g3d_mat4 gl;
        if ((rc = get_matrix(f, "transform_matrix", &gl, path, i))) break;
        c->c2w = g3d_pose_opengl_to_opencv(gl);
        if ((rc = g3d_camera_list_set_name(l, i, get_str(f, "file_path"))) ||
            (rc = g3d_camera_list_set_mask(l, i, get_str(f, "mask_path"))) ||
            (rc = g3d_camera_list_set_depth(l, i, get_str(f, "depth_file_path"))))
            break;
    }
    cJSON_Delete(root);
    if (rc != G3D_OK) g3d_camera_list_free(l);
    return rc;
}

g3d_status g3d_camera_list_load(const char *path, g3d_camera_list *l)
{
    cJSON *root;
    memset(l, 0, sizeof *l);
    G3D_TRY(load_json(path, &root));
    const cJSON *frames = cJSON_GetObjectItemCaseSensitive(root, "frames");
    const cJSON *first = cJSON_IsArray(frames) ? cJSON_GetArrayItem(frames, 0) : NULL;
    int nerfstudio = first && cJSON_GetObjectItemCaseSensitive(first, "transform_matrix");
    cJSON_Delete(root);
    return nerfstudio ? g3d_transforms_json_read(path, l) : g3d_cameras_json_read(path, l);
}
