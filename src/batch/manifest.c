/* The batch manifest: JSON Lines of scenes, each line's keys checked against a key table. */
#include "gen3d/batch.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* A manifest of WorldScore's size (2,000 lines) is far below this. */
#define MANIFEST_MAX_BYTES ((size_t)256 << 20)

static char *dup_str(const char *s)
{
    size_t n = strlen(s) + 1;
    char *d = malloc(n);
    if (d) memcpy(d, s, n);
    return d;
}

/* Absolute form of an existing path (symlinks resolved), or NULL. */
static char *absolute(const char *path)
{
    char buf[PATH_MAX];
    return realpath(path, buf) ? dup_str(buf) : NULL;
}

static char *folder_of(const char *abs_path)
{
    char *d = dup_str(abs_path);
    char *slash = d ? strrchr(d, '/') : NULL;
    if (slash) slash == d ? (void)(slash[1] = 0) : (void)(*slash = 0);
    return d;
}

g3d_status g3d_batch_scene_set_error(g3d_batch_scene *s, const char *message)
{
    if (s->error) return G3D_OK;
    s->error = dup_str(message);
    return s->error ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
}

static void scene_errorf(g3d_batch_scene *s, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
static void scene_errorf(g3d_batch_scene *s, const char *fmt, ...)
{
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    g3d_batch_scene_set_error(s, msg);
}

const char *g3d_batch_scene_get(const g3d_batch_scene *s, const char *key)
{
    for (int i = 0; i < s->nopts; i++)
        if (!strcmp(s->opts[i].key, key)) return s->opts[i].value;
    return NULL;
}

int g3d_batch_manifest_bad(const g3d_batch_manifest *m)
{
    int n = 0;
    for (int i = 0; i < m->nscenes; i++) n += m->scenes[i].error != NULL;
    return n;
}

static const g3d_batch_key *find_key(const g3d_batch_key *keys, int nkeys, const char *name)
{
    for (int i = 0; i < nkeys; i++)
        if (!strcmp(keys[i].name, name)) return &keys[i];
    return NULL;
}

static int is_name(const g3d_batch_key *k, const char *v)
{
    for (const char *const *n = k->names; n && *n; n++)
        if (!strcmp(*n, v)) return 1;
    return 0;
}

/* The value of one key as text, or NULL after recording why it is bad. `base` is the folder
 * relative paths start from. */
static char *value_text(g3d_batch_scene *s, const g3d_batch_key *k, const cJSON *v, const char *base)
{
    char buf[64];
    switch (k->kind) {
    case G3D_BATCH_FLAG:
        if (!cJSON_IsBool(v)) break;
        return dup_str(cJSON_IsTrue(v) ? "1" : "0");
    case G3D_BATCH_INT: {
        double d = cJSON_IsNumber(v) ? v->valuedouble : NAN;
        if (!(fabs(d) < 9e15) || d != floor(d)) break;
        snprintf(buf, sizeof buf, "%.0f", d);
        return dup_str(buf);
    }
    case G3D_BATCH_NUMBER:
        if (!cJSON_IsNumber(v) || !isfinite(v->valuedouble)) break;
        snprintf(buf, sizeof buf, "%.17g", v->valuedouble);
        return dup_str(buf);
    case G3D_BATCH_STRING:
        if (!cJSON_IsString(v)) break;
        return dup_str(v->valuestring);
    case G3D_BATCH_PATH:
    case G3D_BATCH_NAME_OR_PATH: {
        if (!cJSON_IsString(v) || !v->valuestring[0]) break;
        const char *p = v->valuestring;
        if (k->kind == G3D_BATCH_NAME_OR_PATH && is_name(k, p)) return dup_str(p);
        char *joined = p[0] == '/' ? dup_str(p) : g3d_path_join(base, p);
        struct stat st;
        if (joined && stat(joined, &st) != 0) {
            scene_errorf(s, "%s: %s: %s", k->name, p, strerror(errno));
            free(joined);
            return NULL;
        }
        return joined;
    }
    }
    static const char *const want[] = {"true or false", "a whole number", "a number", "a string", "a path",
                                       "a name or a path"};
    scene_errorf(s, "%s: expected %s", k->name, want[k->kind]);
    return NULL;
}

/* Sets key = value in s, replacing an earlier value (a default). Takes value. */
static int scene_put(g3d_batch_scene *s, const char *key, char *value)
{
    for (int i = 0; i < s->nopts; i++)
        if (!strcmp(s->opts[i].key, key)) {
            free(s->opts[i].value);
            s->opts[i].value = value;
            return 0;
        }
    g3d_batch_option *o = realloc(s->opts, (size_t)(s->nopts + 1) * sizeof *o);
    char *k = dup_str(key);
    if (!o || !k) {
        if (o) s->opts = o;
        free(k);
        free(value);
        return -1;
    }
    s->opts = o;
    s->opts[s->nopts].key = k;
    s->opts[s->nopts].value = value;
    s->nopts++;
    return 0;
}

static int valid_id(const char *id)
{
    if (!id[0] || id[0] == '.' || strlen(id) > 128) return 0;
    for (const char *c = id; *c; c++)
        if (!((*c >= 'a' && *c <= 'z') || (*c >= 'A' && *c <= 'Z') || (*c >= '0' && *c <= '9') || *c == '.' ||
              *c == '_' || *c == '-'))
            return 0;
    return 1;
}

/* Reads the keys of object o into s (all but "id"); the first bad key is recorded. Returns -1
 * only when out of memory. */
static int read_keys(g3d_batch_scene *s, const cJSON *o, const g3d_batch_key *keys, int nkeys, const char *base)
{
    for (const cJSON *e = o->child; e; e = e->next) {
        if (!strcmp(e->string, "id")) continue;
        const g3d_batch_key *k = find_key(keys, nkeys, e->string);
        if (!k) {
            scene_errorf(s, "unknown key '%s'", e->string);
            continue;
        }
        char *v = value_text(s, k, e, base);
        if (v && scene_put(s, k->name, v)) return -1;
    }
    return 0;
}

/* Parses one line into s (index and line already set). Returns -1 when out of memory. */
static int read_line(g3d_batch_scene *s, const char *text, const g3d_batch_scene *defaults, const g3d_batch_key *keys,
                     int nkeys, const char *base)
{
    const char *end = NULL;
    cJSON *o = cJSON_ParseWithOpts(text, &end, 1);
    if (!o) {
        scene_errorf(s, "not JSON (near column %d)", end ? (int)(end - text) + 1 : 1);
        return 0;
    }
    int rc = 0;
    const cJSON *id = cJSON_GetObjectItemCaseSensitive(o, "id");
    if (!cJSON_IsObject(o)) {
        scene_errorf(s, "not a JSON object");
    } else if (!cJSON_IsString(id) || !valid_id(id->valuestring)) {
        scene_errorf(s, "%s", !id ? "no \"id\"" : "\"id\" must be a string of letters, digits, '.', '_' or '-' (not starting with '.')");
    } else if (!(s->id = dup_str(id->valuestring))) {
        rc = -1;
    }
    for (int i = 0; rc == 0 && defaults && i < defaults->nopts; i++) {
        char *v = dup_str(defaults->opts[i].value);
        rc = v ? scene_put(s, defaults->opts[i].key, v) : -1;
    }
    if (rc == 0 && cJSON_IsObject(o)) rc = read_keys(s, o, keys, nkeys, base);
    cJSON_Delete(o);
    return rc;
}

static void scene_free(g3d_batch_scene *s)
{
    for (int i = 0; i < s->nopts; i++) {
        free(s->opts[i].key);
        free(s->opts[i].value);
    }
    free(s->opts);
    free(s->id);
    free(s->error);
    memset(s, 0, sizeof *s);
}

void g3d_batch_manifest_free(g3d_batch_manifest *m)
{
    if (!m) return;
    for (int i = 0; i < m->nscenes; i++) scene_free(&m->scenes[i]);
    free(m->scenes);
    free(m->path);
    free(m->defaults);
    memset(m, 0, sizeof *m);
}

static g3d_status load_defaults(const char *path, const g3d_batch_key *keys, int nkeys, g3d_batch_scene *d)
{
    unsigned char *data;
    size_t n;
    G3D_TRY(g3d_read_file(path, MANIFEST_MAX_BYTES, &data, &n));
    cJSON *o = cJSON_ParseWithLength((const char *)data, n);
    free(data);
    if (!cJSON_IsObject(o)) {
        cJSON_Delete(o);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: not a JSON object of scene keys", path);
    }
    g3d_status rc = G3D_OK;
    char *base = folder_of(path);
    if (cJSON_GetObjectItemCaseSensitive(o, "id")) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: defaults have no \"id\"", path);
    else if (!base || read_keys(d, o, keys, nkeys, base)) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    else if (d->error) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: %s", path, d->error);
    free(base);
    cJSON_Delete(o);
    return rc;
}

/* Marks the later of two lines with the same id. */
static void mark_duplicates(g3d_batch_manifest *m)
{
    for (int i = 0; i < m->nscenes; i++) {
        g3d_batch_scene *s = &m->scenes[i];
        for (int j = 0; s->id && j < i; j++)
            if (m->scenes[j].id && !strcmp(m->scenes[j].id, s->id)) {
                scene_errorf(s, "duplicate id '%s' (first on line %d)", s->id, m->scenes[j].line);
                /* the folder of that id is the first line's */
                free(s->id);
                s->id = NULL;
                break;
            }
    }
}

g3d_status g3d_batch_manifest_load(const char *path, const char *defaults, const g3d_batch_key *keys, int nkeys,
                                   g3d_batch_manifest *m)
{
    memset(m, 0, sizeof *m);
    g3d_batch_scene d;
    memset(&d, 0, sizeof d);
    unsigned char *data = NULL;
    size_t n = 0;
    m->path = absolute(path);
    if (!m->path) return G3D_ERR(G3D_ERR_IO, "%s: %s", path, strerror(errno));
    if (defaults && !(m->defaults = absolute(defaults))) {
        g3d_status rc = G3D_ERR(G3D_ERR_IO, "%s: %s", defaults, strerror(errno));
        g3d_batch_manifest_free(m);
        return rc;
    }
    g3d_status rc = m->defaults ? load_defaults(m->defaults, keys, nkeys, &d) : G3D_OK;
    if (rc == G3D_OK) rc = g3d_read_file(m->path, MANIFEST_MAX_BYTES, &data, &n);
    char *base = rc == G3D_OK ? folder_of(m->path) : NULL;
    if (rc == G3D_OK && !base) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    char *text = (char *)data;
    int line = 0;
    for (char *p = text; rc == G3D_OK && p && p < text + n; line++) {
        char *nl = memchr(p, '\n', (size_t)(text + n - p));
        if (nl) *nl = 0;
        const char *q = p;
        while (*q == ' ' || *q == '\t' || *q == '\r') q++;
        if (*q) {
            g3d_batch_scene *grown = realloc(m->scenes, (size_t)(m->nscenes + 1) * sizeof *grown);
            if (!grown) {
                rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
                break;
            }
            m->scenes = grown;
            g3d_batch_scene *s = &m->scenes[m->nscenes++];
            memset(s, 0, sizeof *s);
            s->index = m->nscenes - 1;
            s->line = line + 1;
            if (strlen(p) != (size_t)((nl ? nl : text + n) - p)) scene_errorf(s, "not JSON (a NUL byte)");
            else if (read_line(s, p, m->defaults ? &d : NULL, keys, nkeys, base))
                rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        }
        p = nl ? nl + 1 : NULL;
    }
    if (rc == G3D_OK && m->nscenes == 0) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: no scenes (one JSON object per line)", path);
    if (rc == G3D_OK) mark_duplicates(m);
    free(base);
    free(data);
    scene_free(&d);
    if (rc != G3D_OK) g3d_batch_manifest_free(m);
    return rc;
}
