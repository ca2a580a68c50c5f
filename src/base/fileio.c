/* Whole-file reads, atomic file and folder output, small path helpers. */
#include "gen3d/base.h"

#include <ctype.h>
#include <dirent.h>
#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

char *g3d_path_join(const char *dir, const char *name)
{
    size_t a = strlen(dir), b = strlen(name);
    char *s = malloc(a + b + 2);
    if (!s) return NULL;
    memcpy(s, dir, a);
    if (a && dir[a - 1] != '/') s[a++] = '/';
    memcpy(s + a, name, b + 1);
    return s;
}

const char *g3d_path_ext(const char *path, char *buf, size_t bufsize)
{
    const char *slash = strrchr(path, '/');
    const char *dot = strrchr(path, '.');
    size_t i = 0;
    if (bufsize == 0) return buf;
    if (dot && (!slash || dot > slash)) {
        for (dot++; *dot && i + 1 < bufsize; dot++) buf[i++] = (char)tolower((unsigned char)*dot);
    }
    buf[i] = 0;
    return buf;
}

g3d_status g3d_read_file(const char *path, size_t max_bytes, unsigned char **data, size_t *n)
{
    FILE *fp = fopen(path, "rb");
    unsigned char *buf;
    long len;
    if (!fp) return G3D_ERR(G3D_ERR_IO, "%s: cannot open (%s)", path, strerror(errno));
    if (fseek(fp, 0, SEEK_END) != 0 || (len = ftell(fp)) < 0 || fseek(fp, 0, SEEK_SET) != 0) {
        fclose(fp);
        return G3D_ERR(G3D_ERR_IO, "%s: cannot determine size (not a regular file?)", path);
    }
    if ((size_t)len > max_bytes) {
        fclose(fp);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: file too large (%ld bytes, limit %zu)", path, len, max_bytes);
    }
    buf = malloc((size_t)len + 1);
    if (!buf) { fclose(fp); return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", path); }
    if (len > 0 && fread(buf, 1, (size_t)len, fp) != (size_t)len) {
        free(buf);
        fclose(fp);
        return G3D_ERR(G3D_ERR_IO, "%s: read error", path);
    }
    fclose(fp);
    buf[len] = 0;
    *data = buf;
    *n = (size_t)len;
    return G3D_OK;
}

static char *dup_str(const char *s)
{
    size_t n = strlen(s) + 1;
    char *d = malloc(n);
    if (d) memcpy(d, s, n);
    return d;
}

g3d_status g3d_atomic_open(g3d_atomic_file *af, const char *path)
{
    char suffix[64];
    int fd;
    memset(af, 0, sizeof *af);
    snprintf(suffix, sizeof suffix, ".tmp-%ld-XXXXXX", (long)getpid());
    af->path = dup_str(path);
    af->tmp_path = malloc(strlen(path) + sizeof suffix);
    if (!af->path || !af->tmp_path) {
        g3d_atomic_abort(af);
        return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", path);
    }
    strcpy(af->tmp_path, path);
    strcat(af->tmp_path, suffix);
    fd = mkstemp(af->tmp_path);
    if (fd < 0) {
        g3d_status rc = G3D_ERR(G3D_ERR_IO, "%s: cannot create file (%s)", path, strerror(errno));
        free(af->tmp_path);
        af->tmp_path = NULL;
        g3d_atomic_abort(af);
        return rc;
    }
    fchmod(fd, 0644);
    af->fp = fdopen(fd, "wb");
    if (!af->fp) {
        close(fd);
        g3d_atomic_abort(af);
        return G3D_ERR(G3D_ERR_IO, "%s: cannot open for writing", path);
    }
    return G3D_OK;
}

g3d_status g3d_atomic_commit(g3d_atomic_file *af)
{
    g3d_status rc = G3D_OK;
    int bad = ferror(af->fp) != 0;
    if (fclose(af->fp) != 0) bad = 1;
    af->fp = NULL;
    if (bad) rc = G3D_ERR(G3D_ERR_IO, "%s: write failed (disk full?)", af->path);
    else if (rename(af->tmp_path, af->path) != 0)
        rc = G3D_ERR(G3D_ERR_IO, "%s: cannot rename into place (%s)", af->path, strerror(errno));
    g3d_atomic_abort(af);
    return rc;
}

void g3d_atomic_abort(g3d_atomic_file *af)
{
    if (af->fp) fclose(af->fp);
    if (af->tmp_path) remove(af->tmp_path);
    free(af->tmp_path);
    free(af->path);
    memset(af, 0, sizeof *af);
}

g3d_status g3d_write_file_atomic(const char *path, const void *data, size_t n)
{
    g3d_atomic_file af;
    G3D_TRY(g3d_atomic_open(&af, path));
    if (n && fwrite(data, 1, n, af.fp) != n) {
        g3d_atomic_abort(&af);
        return G3D_ERR(G3D_ERR_IO, "%s: write failed", path);
    }
    return g3d_atomic_commit(&af);
}

g3d_status g3d_mkdirs(const char *path)
{
    char buf[4096];
    size_t n = strlen(path);
    if (n == 0 || n >= sizeof buf) return G3D_ERR(G3D_ERR_ARG, "%s: bad folder name", path);
    memcpy(buf, path, n + 1);
    for (size_t i = 1; i <= n; i++) {
        if (buf[i] == '/' || buf[i] == 0) {
            char c = buf[i];
            buf[i] = 0;
            if (mkdir(buf, 0755) != 0 && errno != EEXIST)
                return G3D_ERR(G3D_ERR_IO, "%s: cannot create folder (%s)", buf, strerror(errno));
            buf[i] = c;
        }
    }
    struct stat st;
    if (stat(path, &st) != 0 || !S_ISDIR(st.st_mode))
        return G3D_ERR(G3D_ERR_IO, "%s: exists and is not a folder", path);
    return G3D_OK;
}

g3d_status g3d_remove_tree(const char *path)
{
    struct stat st;
    DIR *d;
    struct dirent *e;
    if (lstat(path, &st) != 0) return G3D_OK;
    if (!S_ISDIR(st.st_mode)) {
        if (remove(path) != 0) return G3D_ERR(G3D_ERR_IO, "%s: cannot remove (%s)", path, strerror(errno));
        return G3D_OK;
    }
    d = opendir(path);
    if (!d) return G3D_ERR(G3D_ERR_IO, "%s: cannot open folder (%s)", path, strerror(errno));
    while ((e = readdir(d)) != NULL) {
        char *child;
        g3d_status rc;
        if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
        child = g3d_path_join(path, e->d_name);
        if (!child) { closedir(d); return G3D_ERR(G3D_ERR_NOMEM, "out of memory"); }
        rc = g3d_remove_tree(child);
        free(child);
        if (rc != G3D_OK) { closedir(d); return rc; }
    }
    closedir(d);
    if (rmdir(path) != 0) return G3D_ERR(G3D_ERR_IO, "%s: cannot remove folder (%s)", path, strerror(errno));
    return G3D_OK;
}

g3d_status g3d_atomic_dir_begin(const char *path, char **tmp_out)
{
    char suffix[48];
    char *tmp;
    size_t n = strlen(path);
    while (n > 1 && path[n - 1] == '/') n--;
    snprintf(suffix, sizeof suffix, ".tmp-%ld", (long)getpid());
    tmp = malloc(n + strlen(suffix) + 1);
    if (!tmp) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    memcpy(tmp, path, n);
    strcpy(tmp + n, suffix);
    g3d_remove_tree(tmp);
    if (g3d_mkdirs(tmp) != G3D_OK) {
        free(tmp);
        return G3D_ERR(G3D_ERR_IO, "%s: cannot create output folder next to it", path);
    }
    /* The marker lets a later run replace this folder without risking a user's own folder. */
    char *marker = g3d_path_join(tmp, G3D_OUTPUT_MARKER);
    g3d_status rc = marker ? g3d_write_file_atomic(marker, "gen3d output\n", 13) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    free(marker);
    if (rc != G3D_OK) {
        g3d_remove_tree(tmp);
        free(tmp);
        return rc;
    }
    *tmp_out = tmp;
    return G3D_OK;
}

/* An existing folder may be replaced if it is empty or carries our marker. */
static int replaceable_dir(const char *path)
{
    struct stat st;
    char *marker = g3d_path_join(path, G3D_OUTPUT_MARKER);
    int ok = marker && stat(marker, &st) == 0;
    free(marker);
    if (ok) return 1;
    DIR *d = opendir(path);
    struct dirent *e;
    if (!d) return 0;
    ok = 1;
    while ((e = readdir(d)) != NULL)
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) ok = 0;
    closedir(d);
    return ok;
}

g3d_status g3d_atomic_dir_commit(const char *tmp, const char *path)
{
    struct stat st;
    if (lstat(path, &st) == 0) {
        if (!S_ISDIR(st.st_mode))
            return G3D_ERR(G3D_ERR_IO, "%s: exists and is not a folder", path);
        if (!replaceable_dir(path))
            return G3D_ERR(G3D_ERR_IO, "%s: folder exists and is not an earlier gen3d output; choose another name", path);
        G3D_TRY(g3d_remove_tree(path));
    }
    if (rename(tmp, path) != 0)
        return G3D_ERR(G3D_ERR_IO, "%s: cannot move output folder into place (%s)", path, strerror(errno));
    return G3D_OK;
}

void g3d_atomic_dir_abort(const char *tmp)
{
    if (tmp) g3d_remove_tree(tmp);
}
