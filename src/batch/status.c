/* The batch output folder: which manifest it belongs to, scene locks, status files, the
 * summary, and moving finished scenes into place. */
#include "gen3d/batch.h"

#include <cjson/cJSON.h>
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#define JSON_MAX_BYTES ((size_t)64 << 20)

const char *g3d_batch_state_name(g3d_batch_state s)
{
    static const char *const names[] = {"pending", "running", "done", "failed"};
    return (unsigned)s < 4 ? names[s] : "unknown";
}

static char *path3(const char *a, const char *b, const char *c)
{
    char *ab = g3d_path_join(a, b);
    char *abc = ab && c ? g3d_path_join(ab, c) : NULL;
    if (!c) return ab;
    free(ab);
    return abc;
}

static cJSON *read_json(const char *path)
{
    unsigned char *data;
    size_t n;
    if (g3d_read_file(path, JSON_MAX_BYTES, &data, &n) != G3D_OK) return NULL;
    cJSON *j = cJSON_ParseWithLength((const char *)data, n);
    free(data);
    return j;
}

static g3d_status write_json(const char *path, const cJSON *j)
{
    char *text = cJSON_Print(j);
    if (!text) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    size_t n = strlen(text);
    text[n] = '\n';   /* replaces the NUL: the file ends with a newline */
    g3d_status rc = g3d_write_file_atomic(path, text, n + 1);
    free(text);
    return rc;
}

static const char *json_str(const cJSON *o, const char *key)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, key);
    return cJSON_IsString(v) ? v->valuestring : NULL;
}

static int same(const char *a, const char *b) { return (!a && !b) || (a && b && !strcmp(a, b)); }

static int empty_dir(const char *path)
{
    DIR *d = opendir(path);
    struct dirent *e;
    int empty = 1;
    if (!d) return 0;
    while (empty && (e = readdir(d)) != NULL) empty = !strcmp(e->d_name, ".") || !strcmp(e->d_name, "..");
    closedir(d);
    return empty;
}

g3d_status g3d_batch_folder_manifest(const char *dir, char **manifest, char **defaults)
{
    *manifest = *defaults = NULL;
    char *p = g3d_path_join(dir, "batch.json");
    cJSON *j = p ? read_json(p) : NULL;
    const char *m = json_str(j, "manifest"), *d = json_str(j, "defaults");
    g3d_status rc = G3D_OK;
    if (!m) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: not a batch output folder (no readable batch.json)", dir);
    else if (!(*manifest = strdup(m)) || (d && !(*defaults = strdup(d)))) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc != G3D_OK) {
        free(*manifest);
        *manifest = NULL;
    }
    cJSON_Delete(j);
    free(p);
    return rc;
}

/* An existing non-empty folder must be this manifest's batch folder. */
static g3d_status check_owner(const char *dir, const g3d_batch_manifest *m)
{
    char *old_m = NULL, *old_d = NULL;
    if (g3d_batch_folder_manifest(dir, &old_m, &old_d) != G3D_OK)
        return G3D_ERR(G3D_ERR_ARG, "%s: folder exists and is not a batch output folder; choose another", dir);
    g3d_status rc = G3D_OK;
    if (strcmp(old_m, m->path))
        rc = G3D_ERR(G3D_ERR_ARG, "%s: holds the scenes of another manifest (%s); choose another output folder", dir, old_m);
    else if (!same(old_d, m->defaults))
        rc = G3D_ERR(G3D_ERR_ARG, "%s: was run with %s%s; give the same --defaults or another output folder", dir,
                     old_d ? "--defaults " : "no --defaults", old_d ? old_d : "");
    free(old_m);
    free(old_d);
    return rc;
}

g3d_status g3d_batch_folder_claim(const char *dir, const g3d_batch_manifest *m)
{
    struct stat st;
    if (stat(dir, &st) == 0 && !S_ISDIR(st.st_mode)) return G3D_ERR(G3D_ERR_IO, "%s: exists and is not a folder", dir);
    char *locks = path3(dir, ".batch", "locks"), *work = path3(dir, ".batch", "work"), *bj = g3d_path_join(dir, "batch.json");
    cJSON *j = cJSON_CreateObject();
    g3d_status rc = locks && work && bj && j ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK && stat(dir, &st) == 0 && !empty_dir(dir)) {
        rc = check_owner(dir, m);
    } else if (rc == G3D_OK) {
        /* batch.json first: array tasks starting together on a new folder either find it
         * empty (and write the same file) or find the file */
        cJSON_AddStringToObject(j, "manifest", m->path);
        if (m->defaults) cJSON_AddStringToObject(j, "defaults", m->defaults);
        rc = g3d_mkdirs(dir);
        if (rc == G3D_OK) rc = write_json(bj, j);
    }
    if (rc == G3D_OK) rc = g3d_mkdirs(locks);
    if (rc == G3D_OK) rc = g3d_mkdirs(work);
    cJSON_Delete(j);
    free(locks);
    free(work);
    free(bj);
    return rc;
}

static char *lock_path(const char *dir, const char *id)
{
    char *locks = path3(dir, ".batch", "locks");
    char *p = locks ? g3d_path_join(locks, id) : NULL;
    free(locks);
    return p;
}

g3d_status g3d_batch_lock(const char *dir, const char *id, int *fd)
{
    *fd = -1;
    char *p = lock_path(dir, id);
    if (!p) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    int f = open(p, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    g3d_status rc = G3D_OK;
    if (f < 0) rc = G3D_ERR(G3D_ERR_IO, "%s: cannot create lock (%s)", p, strerror(errno));
    else if (flock(f, LOCK_EX | LOCK_NB) == 0) *fd = f;
    else if (errno == EWOULDBLOCK) close(f);
    else {
        rc = G3D_ERR(G3D_ERR_IO, "%s: cannot lock (%s)", p, strerror(errno));
        close(f);
    }
    free(p);
    return rc;
}

void g3d_batch_unlock(int fd)
{
    if (fd >= 0) close(fd);
}

/* 1 when another process holds the scene's lock. */
static int locked(const char *dir, const char *id)
{
    char *p = lock_path(dir, id);
    int f = p ? open(p, O_RDONLY | O_CLOEXEC) : -1;
    int held = f >= 0 && flock(f, LOCK_SH | LOCK_NB) != 0 && errno == EWOULDBLOCK;
    if (f >= 0) close(f);
    free(p);
    return held;
}

void g3d_batch_status_free(g3d_batch_status *st)
{
    if (!st) return;
    free(st->error);
    memset(st, 0, sizeof *st);
}

g3d_batch_state g3d_batch_scene_state(const char *dir, const char *id, g3d_batch_status *st)
{
    g3d_batch_status s;
    memset(&s, 0, sizeof s);
    char *p = path3(dir, id, "status.json");
    cJSON *j = p ? read_json(p) : NULL;
    const char *state = json_str(j, "state"), *err = json_str(j, "error");
    if (state && !strcmp(state, "done")) s.state = G3D_BATCH_DONE;
    if (state && !strcmp(state, "failed")) {
        s.state = G3D_BATCH_FAILED;
        s.error = strdup(err ? err : "failed");
    }
    const cJSON *sec = cJSON_GetObjectItemCaseSensitive(j, "seconds");
    for (int i = 0; i < G3D_STAGE_COUNT; i++) {
        const cJSON *v = cJSON_GetObjectItemCaseSensitive(sec, g3d_stage_name((g3d_stage)i));
        s.seconds[i] = cJSON_IsNumber(v) ? v->valuedouble : 0;
    }
    const cJSON *tot = cJSON_GetObjectItemCaseSensitive(sec, "total");
    s.seconds_total = cJSON_IsNumber(tot) ? tot->valuedouble : 0;
    if (locked(dir, id)) s.state = G3D_BATCH_RUNNING;
    cJSON_Delete(j);
    free(p);
    g3d_batch_state result = s.state;
    if (st) *st = s;
    else g3d_batch_status_free(&s);
    return result;
}

char *g3d_batch_work_dir(const char *dir, const char *id)
{
    char *work = path3(dir, ".batch", "work");
    char *p = work ? g3d_path_join(work, id) : NULL;
    DIR *d = p ? opendir(work) : NULL;
    struct dirent *e;
    size_t n = strlen(id);
    /* what an attempt that died left: the folder, and generate's "<id>.tmp-<pid>" beside it */
    while (d && (e = readdir(d)) != NULL)
        if (!strncmp(e->d_name, id, n) && (!e->d_name[n] || !strncmp(e->d_name + n, ".tmp-", 5))) {
            char *old = g3d_path_join(work, e->d_name);
            if (old) g3d_remove_tree(old);
            free(old);
        }
    if (d) closedir(d);
    free(work);
    return p;
}

static void add_time(cJSON *o, const char *key)
{
    char buf[32];
    time_t t = time(NULL);
    struct tm tm;
    gmtime_r(&t, &tm);
    strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    cJSON_AddStringToObject(o, key, buf);
}

g3d_status g3d_batch_status_write(const char *folder, const g3d_batch_scene *s, const char *error,
                                  const double seconds[G3D_STAGE_COUNT], double seconds_total, int threads)
{
    cJSON *j = cJSON_CreateObject(), *sec = cJSON_CreateObject(), *opts = cJSON_CreateObject();
    char host[256] = "";
    gethostname(host, sizeof host - 1);
    cJSON_AddStringToObject(j, "id", s->id);
    cJSON_AddStringToObject(j, "state", error ? "failed" : "done");
    if (error) cJSON_AddStringToObject(j, "error", error);
    for (int i = 0; seconds && i < G3D_STAGE_COUNT; i++) cJSON_AddNumberToObject(sec, g3d_stage_name((g3d_stage)i), seconds[i]);
    cJSON_AddNumberToObject(sec, "total", seconds_total);
    cJSON_AddItemToObject(j, "seconds", sec);
    for (int i = 0; i < s->nopts; i++) cJSON_AddStringToObject(opts, s->opts[i].key, s->opts[i].value);
    cJSON_AddItemToObject(j, "options", opts);
    cJSON_AddNumberToObject(j, "threads", threads);
    cJSON_AddNumberToObject(j, "manifest_line", s->line);
    cJSON_AddStringToObject(j, "host", host);
    add_time(j, "finished");
    char *p = g3d_path_join(folder, "status.json");
    g3d_status rc = p ? write_json(p, j) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    free(p);
    cJSON_Delete(j);
    return rc;
}

g3d_status g3d_batch_commit(const char *dir, const char *id, const char *work)
{
    char *dst = g3d_path_join(dir, id), *old = path3(dir, ".batch", "work");
    char *old_id = NULL;
    g3d_status rc = dst && old ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    struct stat st;
    /* an earlier result moves aside first: rename cannot replace a folder that has files */
    if (rc == G3D_OK && lstat(dst, &st) == 0) {
        size_t n = strlen(old) + strlen(id) + 16;
        old_id = malloc(n);
        if (!old_id) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        else snprintf(old_id, n, "%s/%s.old", old, id);
        if (rc == G3D_OK) g3d_remove_tree(old_id);
        if (rc == G3D_OK && rename(dst, old_id) != 0)
            rc = G3D_ERR(G3D_ERR_IO, "%s: cannot move the earlier result aside (%s)", dst, strerror(errno));
    }
    if (rc == G3D_OK && rename(work, dst) != 0)
        rc = G3D_ERR(G3D_ERR_IO, "%s: cannot move the scene into place (%s)", dst, strerror(errno));
    if (old_id) g3d_remove_tree(old_id);
    free(old_id);
    free(old);
    free(dst);
    return rc;
}

g3d_status g3d_batch_summary_write(const char *dir, const g3d_batch_manifest *m, const g3d_batch_state *states,
                                   char *const *errors, double seconds)
{
    cJSON *j = cJSON_CreateObject(), *counts = cJSON_CreateObject(), *scenes = cJSON_CreateArray(),
          *bad = cJSON_CreateArray();
    int count[4] = {0, 0, 0, 0};
    for (int i = 0; i < m->nscenes; i++) {
        const g3d_batch_scene *s = &m->scenes[i];
        cJSON *o = cJSON_CreateObject();
        if (!s->id || (s->error && !errors[i])) {
            /* a line without a usable id has no folder: only the manifest line names it */
            cJSON_AddNumberToObject(o, "line", s->line);
            cJSON_AddStringToObject(o, "error", s->error ? s->error : "bad line");
            cJSON_AddItemToArray(bad, o);
            continue;
        }
        count[states[i]]++;
        cJSON_AddStringToObject(o, "id", s->id);
        cJSON_AddNumberToObject(o, "line", s->line);
        cJSON_AddStringToObject(o, "state", g3d_batch_state_name(states[i]));
        if (errors[i]) cJSON_AddStringToObject(o, "error", errors[i]);
        cJSON_AddItemToArray(scenes, o);
    }
    cJSON_AddStringToObject(j, "manifest", m->path);
    for (int i = 0; i < 4; i++) cJSON_AddNumberToObject(counts, g3d_batch_state_name((g3d_batch_state)i), count[i]);
    cJSON_AddNumberToObject(counts, "bad_lines", cJSON_GetArraySize(bad));
    cJSON_AddItemToObject(j, "counts", counts);
    cJSON_AddNumberToObject(j, "seconds", seconds);
    add_time(j, "written");
    cJSON_AddItemToObject(j, "scenes", scenes);
    cJSON_AddItemToObject(j, "bad_lines", bad);
    char *p = g3d_path_join(dir, "summary.json");
    g3d_status rc = p ? write_json(p, j) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    free(p);
    cJSON_Delete(j);
    return rc;
}
