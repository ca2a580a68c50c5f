/* The checkpoint object: opening and mapping files, lookup by name, dtype conversion. */
#include "ckpt_int.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

static const char *const g_dtype_names[G3D_DT_COUNT] = {"F32", "F16", "BF16", "F64", "I64", "I32", "I16", "I8", "U8", "BOOL"};
static const size_t g_dtype_sizes[G3D_DT_COUNT] = {4, 2, 2, 8, 8, 4, 2, 1, 1, 1};

const char *g3d_dtype_name(g3d_dtype t) { return (int)t >= 0 && t < G3D_DT_COUNT ? g_dtype_names[t] : "?"; }
size_t g3d_dtype_size(g3d_dtype t) { return (int)t >= 0 && t < G3D_DT_COUNT ? g_dtype_sizes[t] : 0; }

static float half_to_float(uint16_t h)
{
    uint32_t sign = (uint32_t)(h >> 15) << 31, e = (h >> 10) & 31, m = h & 1023, bits;
    if (e == 0) {
        if (m == 0) bits = sign;
        else { /* subnormal: normalise the mantissa */
            int shift = 0;
            while (!(m & 1024)) { m <<= 1; shift++; }
            m &= 1023;
            bits = sign | ((uint32_t)(127 - 15 + 1 - shift) << 23) | (m << 13);
        }
    } else if (e == 31) bits = sign | 0x7f800000u | (m << 13); /* inf / nan keep their payload */
    else bits = sign | ((e + 127 - 15) << 23) | (m << 13);
    float f;
    memcpy(&f, &bits, 4);
    return f;
}

void g3d_dtype_to_f32(g3d_dtype t, const void *src, float *dst, int64_t n)
{
    const unsigned char *s = src;
    /* Element by element through memcpy: tensor data in a file need not be aligned. */
    for (int64_t i = 0; i < n; i++) {
        const unsigned char *p = s + (size_t)i * g_dtype_sizes[t];
        switch (t) {
        case G3D_DT_F32: memcpy(&dst[i], p, 4); break;
        case G3D_DT_F16: { uint16_t h; memcpy(&h, p, 2); dst[i] = half_to_float(h); break; }
        case G3D_DT_BF16: { uint16_t h; memcpy(&h, p, 2); uint32_t b = (uint32_t)h << 16; memcpy(&dst[i], &b, 4); break; }
        case G3D_DT_F64: { double d; memcpy(&d, p, 8); dst[i] = (float)d; break; }
        case G3D_DT_I64: { int64_t v; memcpy(&v, p, 8); dst[i] = (float)v; break; }
        case G3D_DT_I32: { int32_t v; memcpy(&v, p, 4); dst[i] = (float)v; break; }
        case G3D_DT_I16: { int16_t v; memcpy(&v, p, 2); dst[i] = (float)v; break; }
        case G3D_DT_I8: dst[i] = (float)(int8_t)p[0]; break;
        case G3D_DT_U8: dst[i] = (float)p[0]; break;
        case G3D_DT_BOOL: dst[i] = p[0] ? 1.0f : 0.0f; break;
        default: dst[i] = NAN; break;
        }
    }
}

void g3d_ckpt_free(g3d_ckpt *ck)
{
    if (!ck) return;
    for (int64_t i = 0; i < ck->n; i++) free((char *)ck->tensors[i].name);
    free(ck->tensors);
    free(ck->by_name);
    cJSON_Delete(ck->meta);
    if (ck->map) munmap(ck->map, ck->map_size);
    free(ck->path);
    free(ck);
}

static const g3d_ckpt *g_sort_ck;
static int cmp_by_name(const void *a, const void *b)
{
    return strcmp(g_sort_ck->tensors[*(const int64_t *)a].name, g_sort_ck->tensors[*(const int64_t *)b].name);
}

/* Detects the format, builds the index and the name lookup. ck->data/size/path are set. */
static g3d_status index_checkpoint(g3d_ckpt *ck)
{
    if (ck->size >= 4 && !memcmp(ck->data, "PK\x03\x04", 4)) G3D_TRY(g3d__torch_index(ck));
    else G3D_TRY(g3d__safetensors_index(ck));
    ck->by_name = malloc(sizeof(int64_t) * (size_t)(ck->n ? ck->n : 1));
    if (!ck->by_name) return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", ck->path);
    for (int64_t i = 0; i < ck->n; i++) ck->by_name[i] = i;
    g_sort_ck = ck; /* qsort has no context argument; the sort runs before the object is shared */
    qsort(ck->by_name, (size_t)ck->n, sizeof(int64_t), cmp_by_name);
    for (int64_t i = 1; i < ck->n; i++)
        if (!strcmp(ck->tensors[ck->by_name[i]].name, ck->tensors[ck->by_name[i - 1]].name))
            return G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' appears twice", ck->path, ck->tensors[ck->by_name[i]].name);
    return G3D_OK;
}

static g3d_ckpt *new_ckpt(const char *label)
{
    g3d_ckpt *ck = calloc(1, sizeof *ck);
    if (!ck) return NULL;
    ck->path = malloc(strlen(label) + 1);
    if (!ck->path) { free(ck); return NULL; }
    strcpy(ck->path, label);
    return ck;
}

g3d_status g3d_ckpt_open_memory(const void *data, size_t n, const char *label, g3d_ckpt **out)
{
    *out = NULL;
    g3d_ckpt *ck = new_ckpt(label);
    if (!ck) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    ck->data = data;
    ck->size = n;
    g3d_status rc = index_checkpoint(ck);
    if (rc != G3D_OK) { g3d_ckpt_free(ck); return rc; }
    *out = ck;
    return G3D_OK;
}

g3d_status g3d_ckpt_open(const char *path, g3d_ckpt **out)
{
    struct stat st;
    *out = NULL;
    int fd = open(path, O_RDONLY);
    if (fd < 0) return G3D_ERR(G3D_ERR_IO, "%s: cannot open (%s)", path, strerror(errno));
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) { close(fd); return G3D_ERR(G3D_ERR_IO, "%s: not a regular file", path); }
    if (st.st_size == 0) { close(fd); return G3D_ERR(G3D_ERR_FORMAT, "%s: empty file", path); }
    void *map = mmap(NULL, (size_t)st.st_size, PROT_READ, MAP_PRIVATE, fd, 0);
    close(fd);
    if (map == MAP_FAILED) return G3D_ERR(G3D_ERR_IO, "%s: cannot map the file (%s)", path, strerror(errno));
    g3d_ckpt *ck = new_ckpt(path);
    if (!ck) { munmap(map, (size_t)st.st_size); return G3D_ERR(G3D_ERR_NOMEM, "out of memory"); }
    ck->map = map;
    ck->map_size = (size_t)st.st_size;
    ck->data = map;
    ck->size = (size_t)st.st_size;
    g3d_status rc = index_checkpoint(ck);
    if (rc != G3D_OK) { g3d_ckpt_free(ck); return rc; }
    *out = ck;
    return G3D_OK;
}

const char *g3d_ckpt_path(const g3d_ckpt *ck) { return ck->path; }
int64_t g3d_ckpt_count(const g3d_ckpt *ck) { return ck->n; }
const g3d_tensor_info *g3d_ckpt_tensor(const g3d_ckpt *ck, int64_t i) { return i >= 0 && i < ck->n ? &ck->tensors[i] : NULL; }
const struct cJSON *g3d_ckpt_meta(const g3d_ckpt *ck) { return ck->meta; }

int64_t g3d_ckpt_numel(const g3d_ckpt *ck)
{
    int64_t s = 0;
    for (int64_t i = 0; i < ck->n; i++) s += ck->tensors[i].numel;
    return s;
}

const g3d_tensor_info *g3d_ckpt_find(const g3d_ckpt *ck, const char *name)
{
    int64_t lo = 0, hi = ck->n - 1;
    while (lo <= hi) {
        int64_t mid = (lo + hi) / 2;
        int c = strcmp(ck->tensors[ck->by_name[mid]].name, name);
        if (c == 0) return &ck->tensors[ck->by_name[mid]];
        if (c < 0) lo = mid + 1;
        else hi = mid - 1;
    }
    return NULL;
}

static void shape_str(char *buf, size_t n, int ndim, const int64_t *shape)
{
    size_t k = (size_t)snprintf(buf, n, "[");
    for (int i = 0; i < ndim && k < n; i++) k += (size_t)snprintf(buf + k, n - k, "%s%lld", i ? ", " : "", (long long)shape[i]);
    if (k < n) snprintf(buf + k, n - k, "]");
}

g3d_status g3d_ckpt_read(const g3d_ckpt *ck, const char *name, int ndim, const int64_t *shape, float *dst)
{
    const g3d_tensor_info *t = g3d_ckpt_find(ck, name);
    if (!t) return G3D_ERR(G3D_ERR_MODEL, "%s: tensor '%s' is missing", ck->path, name);
    if (ndim > 0 && (t->ndim != ndim || memcmp(t->shape, shape, sizeof(int64_t) * (size_t)ndim) != 0)) {
        char got[160], want[160];
        shape_str(got, sizeof got, t->ndim, t->shape);
        shape_str(want, sizeof want, ndim, shape);
        return G3D_ERR(G3D_ERR_MODEL, "%s: tensor '%s' has shape %s, expected %s", ck->path, name, got, want);
    }
    g3d_dtype_to_f32(t->dtype, t->data, dst, t->numel);
    return G3D_OK;
}

g3d_status g3d_ckpt_read_alloc(const g3d_ckpt *ck, const char *name, int ndim, const int64_t *shape, float **dst)
{
    const g3d_tensor_info *t = g3d_ckpt_find(ck, name);
    *dst = NULL;
    if (!t) return G3D_ERR(G3D_ERR_MODEL, "%s: tensor '%s' is missing", ck->path, name);
    float *buf = g3d_calloc((size_t)(t->numel ? t->numel : 1), sizeof(float), name);
    if (!buf) return G3D_ERR_NOMEM;
    g3d_status rc = g3d_ckpt_read(ck, name, ndim, shape, buf);
    if (rc != G3D_OK) { free(buf); return rc; }
    *dst = buf;
    return G3D_OK;
}
