/* torch_zip.c - PyTorch zip checkpoints (torch.save since 1.6).
 *
 * Layout: <archive>/data.pkl (the pickled object), <archive>/data/<key> (one raw storage per
 * key, little-endian unless <archive>/byteorder says otherwise), <archive>/version.
 *
 * Tensor names: the dotted path of dict keys (list/tuple indices as numbers) from the top-level
 * object. When the top level is a dict without tensors of its own and exactly one of its values
 * holds tensors (torch.save({'model': state_dict, 'config': {...}})), that single wrapper key
 * is dropped, so tensors keep their state-dict names. The non-tensor content is the metadata
 * JSON, with each tensor replaced by its name.
 */
#include "ckpt_int.h"

#include <cjson/cJSON.h>
#include <stdlib.h>
#include <string.h>

#define TZ_MAX_PICKLE (512ull << 20)
#define TZ_MAX_DEPTH 64
/* Shared references can make a small pickle describe a huge tree; bound the nodes visited. */
#define TZ_MAX_VISITS (1 << 22)

typedef struct {
    g3d_ckpt *ck;
    g3d_zip zip;
    char prefix[512];          /* "<archive>/" */
    int64_t visits;
} tz_state;

static int has_tensor(tz_state *tz, const g3d__pv *v, int depth)
{
    if (!v || depth > TZ_MAX_DEPTH || ++tz->visits > TZ_MAX_VISITS) return 0;
    if (v->kind == G3D_PK_TENSOR) return 1;
    if (v->kind == G3D_PK_LIST || v->kind == G3D_PK_TUPLE || v->kind == G3D_PK_DICT)
        for (int64_t i = 0; i < v->n; i++)
            if (has_tensor(tz, v->items[i], depth + 1)) return 1;
    return 0;
}

/* Resolves a tensor's storage to bytes inside the file (or an extracted copy) and checks that
 * the tensor is contiguous and fits in the storage. */
static g3d_status add_tensor(tz_state *tz, const char *name, const g3d__pv *t)
{
    g3d_ckpt *ck = tz->ck;
    const g3d__pv *s = t->storage;
    int64_t expect = 1;
    for (int d = t->ndim - 1; d >= 0; d--) {
        if (t->shape[d] != 1 && t->stride[d] != expect)
            return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: tensor '%s' is not contiguous (save it with .contiguous())",
                           ck->path, name);
        if (t->shape[d] && expect > INT64_MAX / t->shape[d])
            return G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' has an absurd shape", ck->path, name);
        expect *= t->shape[d];
    }
    int64_t numel = expect;
    if (t->i > s->i || numel > s->i - t->i)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' (offset %lld, %lld elements) exceeds its storage of %lld elements",
                       ck->path, name, (long long)t->i, (long long)numel, (long long)s->i);
    char ename[1024];
    snprintf(ename, sizeof ename, "%sdata/%s", tz->prefix, s->s);
    int64_t e = g3d_zip_find(&tz->zip, ename);
    if (e < 0) return G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' refers to missing storage '%s'", ck->path, name, ename);
    size_t esz = g3d_dtype_size((g3d_dtype)s->dtype);
    if ((uint64_t)s->i > UINT64_MAX / esz || tz->zip.entries[e].size < (uint64_t)s->i * esz)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: storage '%s' holds %llu bytes, fewer than its %lld elements need", ck->path,
                       ename, (unsigned long long)tz->zip.entries[e].size, (long long)s->i);
    const unsigned char *base;
    if (tz->zip.entries[e].method == 0) {
        base = g3d_zip_stored_data(&tz->zip, e);
        if (!base) return G3D_ERR_FORMAT;
    } else {
        unsigned char *buf = NULL;
        uint64_t n = 0;
        G3D_TRY(g3d_zip_extract(&tz->zip, e, tz->zip.entries[e].size, &buf, &n));
        unsigned char **nb = realloc(ck->bufs, (size_t)(ck->n_bufs + 1) * sizeof *nb);
        if (!nb) { free(buf); return G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", ck->path); }
        ck->bufs = nb;
        ck->bufs[ck->n_bufs++] = buf;
        base = buf;
    }
    return g3d__ckpt_add(ck, name, (g3d_dtype)t->dtype, t->ndim, t->shape, base + (size_t)t->i * esz);
}

/* Converts v to JSON, registering tensors under `path`; returns NULL with the error set. */
static cJSON *walk(tz_state *tz, const g3d__pv *v, const char *path, int depth, g3d_status *rc)
{
    g3d_ckpt *ck = tz->ck;
    if (depth > TZ_MAX_DEPTH || ++tz->visits > TZ_MAX_VISITS) {
        *rc = G3D_ERR(G3D_ERR_FORMAT, "%s: data.pkl nests deeper than %d levels or is too large", ck->path,
                      TZ_MAX_DEPTH);
        return NULL;
    }
    switch (v->kind) {
    case G3D_PK_NONE: return cJSON_CreateNull();
    case G3D_PK_BOOL: return cJSON_CreateBool((int)v->i);
    case G3D_PK_INT: return cJSON_CreateNumber((double)v->i);
    case G3D_PK_FLOAT: return cJSON_CreateNumber(v->f);
    case G3D_PK_STR: return cJSON_CreateString(v->s);
    case G3D_PK_TENSOR:
        if ((*rc = add_tensor(tz, path, v)) != G3D_OK) return NULL;
        return cJSON_CreateString(path);
    case G3D_PK_LIST: case G3D_PK_TUPLE: case G3D_PK_DICT: break;
    default:
        *rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: data.pkl holds a bare %s at '%s'", ck->path,
                      v->kind == G3D_PK_STORAGE ? "storage" : "global", path);
        return NULL;
    }
    int dict = v->kind == G3D_PK_DICT;
    cJSON *out = dict ? cJSON_CreateObject() : cJSON_CreateArray();
    if (!out) { *rc = G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", ck->path); return NULL; }
    /* The wrapper rule (see the file comment) applies at the top level only. */
    int64_t strip = -1;
    if (dict && depth == 0) {
        int64_t holders = 0, direct = 0;
        for (int64_t i = 0; i < v->n; i += 2) {
            if (v->items[i + 1]->kind == G3D_PK_TENSOR) direct++;
            else if (has_tensor(tz, v->items[i + 1], 1)) { holders++; strip = i; }
        }
        if (direct || holders != 1) strip = -1;
    }
    for (int64_t i = 0; i < v->n; i += dict ? 2 : 1) {
        char key[256], sub[1024];
        const g3d__pv *val = dict ? v->items[i + 1] : v->items[i];
        if (dict) {
            const g3d__pv *k = v->items[i];
            if (k->kind == G3D_PK_STR) snprintf(key, sizeof key, "%s", k->s);
            else if (k->kind == G3D_PK_INT) snprintf(key, sizeof key, "%lld", (long long)k->i);
            else {
                cJSON_Delete(out);
                *rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: dict key of unsupported type under '%s'", ck->path, path);
                return NULL;
            }
        } else {
            snprintf(key, sizeof key, "%lld", (long long)i);
        }
        if (i == strip) snprintf(sub, sizeof sub, "%s", path);
        else snprintf(sub, sizeof sub, "%s%s%s", path, path[0] ? "." : "", key);
        cJSON *c = walk(tz, val, sub, depth + 1, rc);
        if (!c) { cJSON_Delete(out); return NULL; }
        if (dict) cJSON_AddItemToObject(out, key, c); else cJSON_AddItemToArray(out, c);
    }
    return out;
}

g3d_status g3d__torch_zip_parse(g3d_ckpt *ck)
{
    tz_state tz;
    memset(&tz, 0, sizeof tz);
    tz.ck = ck;
    G3D_TRY(g3d_zip_open(&tz.zip, ck->map, ck->map_size, ck->path));
    g3d_status rc = G3D_OK;
    g3d__pickle pk;
    memset(&pk, 0, sizeof pk);
    unsigned char *pkl = NULL;
    uint64_t pkl_n = 0;
    int64_t ipkl = -1;
    for (int64_t i = 0; i < tz.zip.n_entries && ipkl < 0; i++) {
        const char *nm = tz.zip.entries[i].name, *sl = strchr(nm, '/');
        if (sl && strcmp(sl, "/data.pkl") == 0 && (size_t)(sl - nm) + 2 < sizeof tz.prefix) {
            ipkl = i;
            memcpy(tz.prefix, nm, (size_t)(sl - nm) + 1);
            tz.prefix[sl - nm + 1] = 0;
        }
    }
    if (ipkl < 0) {
        rc = G3D_ERR(G3D_ERR_FORMAT, "%s: zip file without <archive>/data.pkl, not a PyTorch checkpoint", ck->path);
        goto done;
    }
    char bo[600];
    snprintf(bo, sizeof bo, "%sbyteorder", tz.prefix);
    int64_t ibo = g3d_zip_find(&tz.zip, bo);
    if (ibo >= 0) {
        unsigned char *b = NULL;
        uint64_t bn = 0;
        if ((rc = g3d_zip_extract(&tz.zip, ibo, 64, &b, &bn)) != G3D_OK) goto done;
        int little = bn == 6 && memcmp(b, "little", 6) == 0;
        free(b);
        if (!little) {
            rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: big-endian checkpoint", ck->path);
            goto done;
        }
    }
    if ((rc = g3d_zip_extract(&tz.zip, ipkl, TZ_MAX_PICKLE, &pkl, &pkl_n)) != G3D_OK) goto done;
    char label[1100];
    snprintf(label, sizeof label, "%s: %sdata.pkl", ck->path, tz.prefix);
    if ((rc = g3d__pickle_load(&pk, pkl, (size_t)pkl_n, label)) != G3D_OK) goto done;
    ck->meta = walk(&tz, pk.root, "", 0, &rc);
done:
    g3d__pickle_free(&pk);
    free(pkl);
    g3d_zip_close(&tz.zip);
    return rc;
}
