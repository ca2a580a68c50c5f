/* ckpt.c - the common checkpoint object: open/detect, index, lookup, dtype conversion. */
#include "ckpt_int.h"

#include <cjson/cJSON.h>
#include <fcntl.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

static const char *const k_dt_names[G3D_DT_COUNT] = {
    "F32", "F16", "BF16", "F64", "I64", "I32", "I16", "I8", "U8", "BOOL"};
static const size_t k_dt_sizes[G3D_DT_COUNT] = {4, 2, 2, 8, 8, 4, 2, 1, 1, 1};

const char *g3d_dtype_name(g3d_dtype t) { return (unsigned)t < G3D_DT_COUNT ? k_dt_names[t] : "?"; }
size_t g3d_dtype_size(g3d_dtype t) { return (unsigned)t < G3D_DT_COUNT ? k_dt_sizes[t] : 0; }

int g3d__dtype_parse(const char *s)
{
    for (int i = 0; i < G3D_DT_COUNT; i++)
        if (strcmp(s, k_dt_names[i]) == 0) return i;
    return -1;
}

int64_t g3d__ckpt_numel(int ndim, const int64_t *shape)
{
    int64_t n = 1;
    for (int i = 0; i < ndim; i++) {
        if (shape[i] < 0) return -1;
        if (shape[i] != 0 && n > INT64_MAX / shape[i]) return -1;
        n *= shape[i];
    }
    return n;
}

g3d_status g3d__ckpt_add(g3d_ckpt *ck, const char *name, g3d_dtype dt, int ndim, const int64_t *shape,
                         const void *data)
{
    if (ndim < 0 || ndim > G3D_MAX_DIMS)
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: tensor '%s' has %d dimensions (at most %d supported)",
                       ck->path, name, ndim, G3D_MAX_DIMS);
    int64_t numel = g3d__ckpt_numel(ndim, shape);
    if (numel < 0)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' has an invalid shape", ck->path, name);
    if (ck->n == ck->cap) {
        int64_t cap = ck->cap ? ck->cap * 2 : 64;
        g3d_tensor_info *t = realloc(ck->t, (size_t)cap * sizeof *t);
        if (!t) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory for the tensor index", ck->path);
        ck->t = t;
        ck->cap = cap;
    }
    char *nm = strdup(name);
    if (!nm) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory for the tensor index", ck->path);
    g3d_tensor_info *ti = &ck->t[ck->n++];
    memset(ti, 0, sizeof *ti);
    ti->name = nm;
    ti->dtype = dt;
    ti->ndim = ndim;
    for (int i = 0; i < ndim; i++) ti->shape[i] = shape[i];
    ti->numel = numel;
    ti->data = data;
    return G3D_OK;
}

static const g3d_ckpt *g_sort_ck; /* only used during open, before the object is shared */
static int cmp_name(const void *a, const void *b)
{
    return strcmp(g_sort_ck->t[*(const int64_t *)a].name, g_sort_ck->t[*(const int64_t *)b].name);
}

static g3d_status build_sorted(g3d_ckpt *ck)
{
    ck->sorted = g3d_calloc((size_t)(ck->n ? ck->n : 1), sizeof(int64_t), "tensor name index");
    if (!ck->sorted) return G3D_ERR_NOMEM;
    for (int64_t i = 0; i < ck->n; i++) ck->sorted[i] = i;
    g_sort_ck = ck;
    qsort(ck->sorted, (size_t)ck->n, sizeof(int64_t), cmp_name);
    g_sort_ck = NULL;
    for (int64_t i = 1; i < ck->n; i++)
        if (strcmp(ck->t[ck->sorted[i - 1]].name, ck->t[ck->sorted[i]].name) == 0)
            return G3D_ERR(G3D_ERR_FORMAT, "%s: duplicate tensor name '%s'", ck->path,
                           ck->t[ck->sorted[i]].name);
    return G3D_OK;
}

g3d_status g3d_ckpt_open(const char *path, g3d_ckpt **out)
{
    *out = NULL;
    g3d_ckpt *ck = g3d_calloc(1, sizeof *ck, "checkpoint");
    if (!ck) return G3D_ERR_NOMEM;
    ck->path = strdup(path);
    if (!ck->path) { free(ck); return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", path); }
    g3d_status rc;
    int fd = open(path, O_RDONLY);
    if (fd < 0) { rc = G3D_ERR(G3D_ERR_IO, "%s: cannot open checkpoint", path); goto fail; }
    struct stat st;
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        close(fd);
        rc = G3D_ERR(G3D_ERR_IO, "%s: not a regular file", path);
        goto fail;
    }
    if (st.st_size < 8) {
        close(fd);
        rc = G3D_ERR(G3D_ERR_FORMAT, "%s: too small to be a checkpoint (%lld bytes)", path,
                     (long long)st.st_size);
        goto fail;
    }
    void *m = mmap(NULL, (size_t)st.st_size, PROT_READ, MAP_PRIVATE, fd, 0);
    close(fd);
    if (m == MAP_FAILED) { rc = G3D_ERR(G3D_ERR_IO, "%s: cannot map the file", path); goto fail; }
    ck->map = m;
    ck->map_size = (size_t)st.st_size;
    /* A zip starts with a local header "PK\3\4"; safetensors with a little-endian u64 length
     * followed by '{'. */
    if (memcmp(ck->map, "PK\x03\x04", 4) == 0)
        rc = g3d__torch_zip_parse(ck);
    else if (ck->map_size > 8 && ck->map[8] == '{')
        rc = g3d__safetensors_parse(ck);
    else
        rc = G3D_ERR(G3D_ERR_FORMAT, "%s: neither a safetensors file nor a PyTorch zip checkpoint", path);
    if (rc == G3D_OK) rc = build_sorted(ck);
    if (rc != G3D_OK) goto fail;
    *out = ck;
    return G3D_OK;
fail:
    g3d_ckpt_free(ck);
    return rc;
}

void g3d_ckpt_free(g3d_ckpt *ck)
{
    if (!ck) return;
    for (int64_t i = 0; i < ck->n; i++) free((char *)ck->t[i].name);
    free(ck->t);
    free(ck->sorted);
    for (int64_t i = 0; i < ck->n_bufs; i++) free(ck->bufs[i]);
    free(ck->bufs);
    cJSON_Delete(ck->meta);
    if (ck->map) munmap((void *)ck->map, ck->map_size);
    free(ck->path);
    free(ck);
}

const char *g3d_ckpt_path(const g3d_ckpt *ck) { return ck->path; }
int64_t g3d_ckpt_count(const g3d_ckpt *ck) { return ck->n; }
const struct cJSON *g3d_ckpt_meta(const g3d_ckpt *ck) { return ck->meta; }

const g3d_tensor_info *g3d_ckpt_tensor(const g3d_ckpt *ck, int64_t i)
{
    return (i >= 0 && i < ck->n) ? &ck->t[i] : NULL;
}

const g3d_tensor_info *g3d_ckpt_find(const g3d_ckpt *ck, const char *name)
{
    int64_t lo = 0, hi = ck->n;
    while (lo < hi) {
        int64_t mid = lo + (hi - lo) / 2;
        int c = strcmp(ck->t[ck->sorted[mid]].name, name);
        if (c == 0) return &ck->t[ck->sorted[mid]];
        if (c < 0) lo = mid + 1; else hi = mid;
    }
    return NULL;
}

/* IEEE half -> float, exact for normals, subnormals, infinities and NaN payloads. */
static float half_to_f32(uint16_t h)
{
    uint32_t sign = (uint32_t)(h & 0x8000u) << 16, exp = (h >> 10) & 0x1fu, man = h & 0x3ffu, bits;
    if (exp == 0x1f) {
        bits = sign | 0x7f800000u | (man << 13);
    } else if (exp != 0) {
        bits = sign | ((exp + 112u) << 23) | (man << 13);
    } else if (man == 0) {
        bits = sign;
    } else {
        float f = ldexpf((float)man, -24);
        return sign ? -f : f;
    }
    float f;
    memcpy(&f, &bits, 4);
    return f;
}

void g3d_dtype_to_f32(g3d_dtype t, const void *src, float *dst, int64_t n)
{
    /* memcpy per element: the source may be unaligned inside a mapped file. */
    const unsigned char *s = src;
    for (int64_t i = 0; i < n; i++) {
        switch (t) {
        case G3D_DT_F32: { float v; memcpy(&v, s + 4 * i, 4); dst[i] = v; break; }
        case G3D_DT_F16: { uint16_t v; memcpy(&v, s + 2 * i, 2); dst[i] = half_to_f32(v); break; }
        case G3D_DT_BF16: {
            uint16_t v; memcpy(&v, s + 2 * i, 2);
            uint32_t b = (uint32_t)v << 16; float f; memcpy(&f, &b, 4); dst[i] = f; break;
        }
        case G3D_DT_F64: { double v; memcpy(&v, s + 8 * i, 8); dst[i] = (float)v; break; }
        case G3D_DT_I64: { int64_t v; memcpy(&v, s + 8 * i, 8); dst[i] = (float)v; break; }
        case G3D_DT_I32: { int32_t v; memcpy(&v, s + 4 * i, 4); dst[i] = (float)v; break; }
        case G3D_DT_I16: { int16_t v; memcpy(&v, s + 2 * i, 2); dst[i] = (float)v; break; }
        case G3D_DT_I8: dst[i] = (float)(int8_t)s[i]; break;
        case G3D_DT_U8: dst[i] = (float)s[i]; break;
        case G3D_DT_BOOL: dst[i] = s[i] ? 1.0f : 0.0f; break;
        default: dst[i] = NAN; break;
        }
    }
}

static void shape_str(char *buf, size_t n, int ndim, const int64_t *shape)
{
    size_t k = (size_t)snprintf(buf, n, "[");
    for (int i = 0; i < ndim && k < n; i++)
        k += (size_t)snprintf(buf + k, n - k, "%s%lld", i ? ", " : "", (long long)shape[i]);
    if (k < n) snprintf(buf + k, n - k, "]");
}

static g3d_status lookup(const g3d_ckpt *ck, const char *name, int ndim, const int64_t *shape,
                         const g3d_tensor_info **out)
{
    const g3d_tensor_info *ti = g3d_ckpt_find(ck, name);
    if (!ti) return G3D_ERR(G3D_ERR_MODEL, "%s: tensor '%s' not found", ck->path, name);
    if (ndim > 0) {
        int same = ndim == ti->ndim;
        for (int i = 0; same && i < ndim; i++) same = shape[i] == ti->shape[i];
        if (!same) {
            char got[160], want[160];
            shape_str(got, sizeof got, ti->ndim, ti->shape);
            shape_str(want, sizeof want, ndim, shape);
            return G3D_ERR(G3D_ERR_MODEL, "%s: tensor '%s' has shape %s, expected %s", ck->path, name,
                           got, want);
        }
    }
    *out = ti;
    return G3D_OK;
}

g3d_status g3d_ckpt_read(const g3d_ckpt *ck, const char *name, int ndim, const int64_t *shape, float *dst)
{
    const g3d_tensor_info *ti;
    G3D_TRY(lookup(ck, name, ndim, shape, &ti));
    g3d_dtype_to_f32(ti->dtype, ti->data, dst, ti->numel);
    return G3D_OK;
}

g3d_status g3d_ckpt_read_alloc(const g3d_ckpt *ck, const char *name, int ndim, const int64_t *shape, float **dst)
{
    const g3d_tensor_info *ti;
    G3D_TRY(lookup(ck, name, ndim, shape, &ti));
    float *buf = g3d_calloc((size_t)(ti->numel ? ti->numel : 1), sizeof(float), name);
    if (!buf) return G3D_ERR_NOMEM;
    g3d_dtype_to_f32(ti->dtype, ti->data, buf, ti->numel);
    *dst = buf;
    return G3D_OK;
}
