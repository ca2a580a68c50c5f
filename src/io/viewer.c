/* viewer.c - viewer.html: the viewer template with a scene (.spz) and its cameras written in. */
#include "gen3d/viewer.h"

#include "gen3d/render.h"
#include "gen3d/spz.h"

#include <cjson/cJSON.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define CONFIG_MARK "@@G3D_CONFIG@@"
#define SCENE_MARK "@@G3D_SCENE@@"
#define MAX_TEMPLATE_BYTES ((size_t)64 << 20)

void g3d_viewer_params_default(g3d_viewer_params *o)
{
    memset(o, 0, sizeof *o);
    o->label = "scene";
    o->max_scene_bytes = G3D_VIEWER_MAX_SCENE_BYTES;
}

/* ---- finding the template ------------------------------------------------------------- */

static int readable(const char *path) { return access(path, R_OK) == 0; }

/* dir/name if readable: *found takes it. Returns 1 when found, -1 out of memory. */
static int try_path(const char *dir, const char *name, char **found)
{
    char *p = g3d_path_join(dir, name);
    if (!p) return -1;
    if (readable(p)) {
        *found = p;
        return 1;
    }
    free(p);
    return 0;
}

g3d_status g3d_viewer_find_template(char **path)
{
    *path = NULL;
    const char *env = getenv("G3D_VIEWER_TEMPLATE");
    if (env && *env) {
        if (!readable(env)) return G3D_ERR(G3D_ERR_IO, "G3D_VIEWER_TEMPLATE=%s: cannot read the viewer template", env);
        *path = strdup(env);
        return *path ? G3D_OK : G3D_ERR_NOMEM;
    }
    char exe[PATH_MAX];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    int r = 0;
    if (n > 0) {
        exe[n] = '\0';
        char *slash = strrchr(exe, '/');
        if (slash) *slash = '\0';
        r = try_path(exe, G3D_VIEWER_TEMPLATE_NAME, path);
        if (r == 0) r = try_path(exe, "../share/gen3d/" G3D_VIEWER_TEMPLATE_NAME, path);
    }
#ifdef G3D_VIEWER_DATADIR
    if (r == 0) r = try_path(G3D_VIEWER_DATADIR, G3D_VIEWER_TEMPLATE_NAME, path);
#endif
    if (r < 0) return G3D_ERR_NOMEM;
    if (r == 0)
        return G3D_ERR(G3D_ERR_UNSUPPORTED,
                       "no viewer template (" G3D_VIEWER_TEMPLATE_NAME ") next to the program or in its share/gen3d: "
                       "the viewer is built only when node and npm are installed at build time (docs/viewer.md)");
    return G3D_OK;
}

/* ---- the page's description ----------------------------------------------------------- */

static g3d_status check_camera(const g3d_camera *c, const char *what, int i)
{
    const g3d_intrinsics *K = &c->K;
    int ok = K->width > 0 && K->height > 0 && K->fx > 0 && K->fy > 0 && isfinite(K->fx) && isfinite(K->fy) &&
             isfinite(K->cx) && isfinite(K->cy);
    for (int r = 0; r < 4; r++)
        for (int k = 0; k < 4; k++) ok = ok && isfinite(c->c2w.m[r][k]);
    if (!ok) return G3D_ERR(G3D_ERR_ARG, "viewer: %s camera %d has a non-positive size or focal length, or a non-finite value", what, i);
    return G3D_OK;
}

/* {"w", "h", "fx", "fy", "cx", "cy", "c2w": 16 numbers, row-major, three.js axes} */
static cJSON *camera_json(const g3d_camera *c)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "w", c->K.width);
    cJSON_AddNumberToObject(o, "h", c->K.height);
    cJSON_AddNumberToObject(o, "fx", c->K.fx);
    cJSON_AddNumberToObject(o, "fy", c->K.fy);
    cJSON_AddNumberToObject(o, "cx", c->K.cx);
    cJSON_AddNumberToObject(o, "cy", c->K.cy);
    g3d_mat4 m = g3d_pose_opencv_to_opengl(g3d_mat4_mul(g3d_world_flip_yz(), c->c2w));
    double v[16];
    for (int r = 0; r < 4; r++)
        for (int k = 0; k < 4; k++) v[4 * r + k] = m.m[r][k];
    cJSON_AddItemToObject(o, "c2w", cJSON_CreateDoubleArray(v, 16));
    return o;
}

/* The description as ASCII JSON (numbers and fixed names only, so nothing in it can end the
 * script element it sits in). Caller frees. */
static char *config_text(const g3d_gaussians *g, double scale, const g3d_camera *input,
                         const g3d_viewer_path *paths, int npaths)
{
    cJSON *root = cJSON_CreateObject();
    cJSON_AddNumberToObject(root, "version", 1);
    cJSON *scene = cJSON_AddObjectToObject(root, "scene");
    cJSON_AddNumberToObject(scene, "gaussians", (double)g->n);
    cJSON_AddNumberToObject(scene, "sh_degree", g->sh_degree);
    cJSON_AddNumberToObject(scene, "scale", scale);
    cJSON_AddItemToObject(root, "input", camera_json(input));
    cJSON *list = cJSON_AddArrayToObject(root, "paths");
    for (int p = 0; p < npaths; p++) {
        cJSON *path = cJSON_CreateObject();
        cJSON_AddStringToObject(path, "name", paths[p].name);
        cJSON_AddNumberToObject(path, "fps", paths[p].fps);
        cJSON *cams = cJSON_AddArrayToObject(path, "cameras");
        for (int i = 0; i < paths[p].n; i++) cJSON_AddItemToArray(cams, camera_json(&paths[p].cams[i]));
        cJSON_AddItemToArray(list, path);
    }
    char *text = cJSON_PrintUnformatted(root);
    cJSON_Delete(root);
    return text;
}

/* ---- writing the page ------------------------------------------------------------------ */

/* The one place `mark` occurs in the template, or NULL (absent or repeated). */
static const unsigned char *find_once(const unsigned char *t, size_t n, const char *mark)
{
    const size_t m = strlen(mark);
    const unsigned char *first = NULL;
    for (const unsigned char *p = t; p + m <= t + n; p++) {
        p = memchr(p, mark[0], (size_t)(t + n - p));
        if (!p || p + m > t + n) break;
        if (!memcmp(p, mark, m)) {
            if (first) return NULL;
            first = p;
        }
    }
    return first;
}

/* The binary-block encoding of docs/viewer.md (decoded by web/src/boot.js). */
static void put_block(FILE *f, const uint8_t *b, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        const int c = b[i], next = i + 1 < n ? b[i + 1] : -1;
        if (c == 0x00 || c == 0x0d || c == '=' || (c == '<' && (next == '/' || next == '!'))) {
            putc('=', f);
            putc((c + 64) & 0xff, f);
        } else {
            putc(c, f);
        }
    }
}

static g3d_status write_page(const char *path, const unsigned char *t, size_t tn, const char *config,
                             const uint8_t *spz, size_t spz_n, const char *template_path)
{
    const unsigned char *cm = find_once(t, tn, CONFIG_MARK), *sm = find_once(t, tn, SCENE_MARK);
    if (!cm || !sm || cm > sm || tn < 15 || memcmp(t, "<!doctype html", 14))
        return G3D_ERR(G3D_ERR_FORMAT, "%s: not a gen3d viewer template (damaged or from another version)", template_path);
    g3d_atomic_file af;
    G3D_TRY(g3d_atomic_open(&af, path));
    const unsigned char *after_c = cm + strlen(CONFIG_MARK), *after_s = sm + strlen(SCENE_MARK);
    fwrite(t, 1, (size_t)(cm - t), af.fp);
    fputs(config, af.fp);
    fwrite(after_c, 1, (size_t)(sm - after_c), af.fp);
    put_block(af.fp, spz, spz_n);
    fwrite(after_s, 1, (size_t)(t + tn - after_s), af.fp);
    return g3d_atomic_commit(&af);
}

static double megabytes(size_t n) { return (double)n / (1 << 20); }

g3d_status g3d_viewer_write(const char *path, const g3d_gaussians *g, const g3d_camera *input,
                            const g3d_viewer_path *paths, int npaths, const g3d_viewer_params *opts)
{
    g3d_viewer_params o;
    if (opts) o = *opts;
    else g3d_viewer_params_default(&o);
    const char *label = o.label ? o.label : "scene";
    if (g->n < 1) return G3D_ERR(G3D_ERR_ARG, "%s: the scene holds no Gaussians, so there is nothing to view", label);
    G3D_TRY(check_camera(input, "input", 0));
    for (int p = 0; p < npaths; p++)
        for (int i = 0; i < paths[p].n; i++) G3D_TRY(check_camera(&paths[p].cams[i], paths[p].name, i));

    double scale = o.scene_scale;
    if (!(scale > 0)) {
        if (g3d_render_scene_scale(g, input, &scale) != G3D_OK) scale = 1.0;
        g3d_error_clear();
    }

    char *tpath = NULL;
    if (o.template_path) {
        tpath = strdup(o.template_path);
        if (!tpath) return G3D_ERR_NOMEM;
    } else {
        G3D_TRY(g3d_viewer_find_template(&tpath));
    }
    uint8_t *spz = NULL;
    size_t spz_n = 0;
    unsigned char *tmpl = NULL;
    size_t tmpl_n = 0;
    char *config = NULL;
    g3d_status rc = g3d_spz_encode(g, label, &spz, &spz_n);
    if (rc == G3D_OK && spz_n > o.max_scene_bytes)
        rc = G3D_ERR(G3D_ERR_UNSUPPORTED,
                     "%s: %lld Gaussians at SH degree %d make a %.3g MB .spz, more than the %.3g MB a viewer page "
                     "can hold; keep fewer Gaussians (--max-gaussians N) or drop SH bands (--sh-degree 0)",
                     label, (long long)g->n, g->sh_degree, megabytes(spz_n), megabytes(o.max_scene_bytes));
    if (rc == G3D_OK) rc = g3d_read_file(tpath, MAX_TEMPLATE_BYTES, &tmpl, &tmpl_n);
    if (rc == G3D_OK) {
        config = config_text(g, scale, input, paths, npaths);
        if (!config) rc = G3D_ERR(G3D_ERR_NOMEM, "viewer: out of memory");
    }
    if (rc == G3D_OK) rc = write_page(path, tmpl, tmpl_n, config, spz, spz_n, tpath);
    free(config);
    free(tmpl);
    free(spz);
    free(tpath);
    return rc;
}

g3d_status g3d_viewer_write_generated(const char *dir, const g3d_gaussians *g, const g3d_camera *views,
                                      int n_views, const char *video_trajectory, int video_frames,
                                      double video_fps, int *written)
{
    if (written) *written = 0;
    g3d_camera *video = NULL;
    int n_video = 0;
    g3d_status rc = G3D_OK;
    if (video_trajectory)
        rc = g3d_render_flythrough(video_trajectory, NULL, g, &views[0], 0, video_frames, &video, &n_video);
    const g3d_viewer_path paths[2] = {{"generation", views, n_views, 1.0}, {"video", video, n_video, video_fps}};
    char *path = g3d_path_join(dir, "viewer.html");
    if (rc == G3D_OK && !path) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) rc = g3d_viewer_write(path, g, &views[0], paths, video ? 2 : 1, NULL);
    if (rc == G3D_ERR_UNSUPPORTED) {  /* no viewer installed, or too large: the rest of the output stands */
        g3d_log(G3D_LOG_WARN, "no viewer.html: %s", g3d_error_message());
        g3d_error_clear();
        rc = G3D_OK;
    } else if (rc == G3D_OK && written) {
        *written = 1;
    }
    free(path);
    free(video);
    return rc;
}

/* ---- fitting a scene into a page ------------------------------------------------------- */

typedef struct scored { float score; int64_t index; } scored;

static int by_score_desc(const void *a, const void *b)
{
    const scored *x = a, *y = b;
    if (x->score != y->score) return x->score < y->score ? 1 : -1;
    return x->index < y->index ? -1 : x->index > y->index;
}

g3d_status g3d_viewer_reduce(const g3d_gaussians *g, int64_t max_gaussians, int sh_degree, g3d_gaussians *out)
{
    const int deg = sh_degree < 0 || sh_degree > g->sh_degree ? g->sh_degree : sh_degree;
    const int64_t n = max_gaussians > 0 && max_gaussians < g->n ? max_gaussians : g->n;
    uint8_t *keep = g3d_calloc((size_t)(g->n > 0 ? g->n : 1), 1, "Gaussian selection");
    if (!keep) return G3D_ERR_NOMEM;
    if (n == g->n) {
        memset(keep, 1, (size_t)g->n);
    } else {
        scored *s = g3d_calloc((size_t)g->n, sizeof *s, "Gaussian scores");
        if (!s) {
            free(keep);
            return G3D_ERR_NOMEM;
        }
        for (int64_t i = 0; i < g->n; i++) {
            const float *ls = g->log_scales + 3 * i;
            s[i].score = (ls[0] + ls[1] + ls[2]) - log1pf(expf(-g->opacity_logits[i]));  /* log of the score */
            s[i].index = i;
        }
        qsort(s, (size_t)g->n, sizeof *s, by_score_desc);
        for (int64_t i = 0; i < n; i++) keep[s[i].index] = 1;
        free(s);
    }
    g3d_status rc = g3d_gaussians_create(out, n, deg);
    if (rc != G3D_OK) {
        free(keep);
        return rc;
    }
    const int K = G3D_SH_COEFFS(g->sh_degree), Ko = G3D_SH_COEFFS(deg);
    int64_t o = 0;
    for (int64_t i = 0; i < g->n; i++) {
        if (!keep[i]) continue;
        memcpy(out->means + 3 * o, g->means + 3 * i, 3 * sizeof(float));
        memcpy(out->log_scales + 3 * o, g->log_scales + 3 * i, 3 * sizeof(float));
        memcpy(out->rots + 4 * o, g->rots + 4 * i, 4 * sizeof(float));
        out->opacity_logits[o] = g->opacity_logits[i];
        memcpy(out->sh + (size_t)o * Ko * 3, g->sh + (size_t)i * K * 3, (size_t)Ko * 3 * sizeof(float));
        o++;
    }
    out->n = n;
    free(keep);
    return G3D_OK;
}
