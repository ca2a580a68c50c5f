/* safetensors.c - index of a memory-mapped .safetensors file.
 *
 * Layout: u64 little-endian header length N, N bytes of JSON
 * {"name": {"dtype": "F16", "shape": [..], "data_offsets": [begin, end]}, "__metadata__": {..}},
 * then the data section; offsets are relative to its start. Everything is validated here,
 * before any tensor byte is used: lengths, dtypes, shape x dtype size == byte length, bounds,
 * and that no two tensors overlap.
 */
#include "ckpt_int.h"

#include <cjson/cJSON.h>
#include <stdlib.h>
#include <string.h>

/* Headers beyond this are absurd (the format's own reference reader uses the same bound). */
#define G3D_ST_MAX_HEADER (100u * 1024u * 1024u)

typedef struct { uint64_t begin, end; int64_t idx; } st_range;

static int cmp_range(const void *a, const void *b)
{
    const st_range *x = a, *y = b;
    return x->begin < y->begin ? -1 : x->begin > y->begin ? 1 : (x->end < y->end ? -1 : x->end > y->end);
}

/* A JSON number that is a non-negative integer representable exactly. */
static int json_u64(const cJSON *j, uint64_t *out)
{
    if (!cJSON_IsNumber(j)) return 0;
    double v = j->valuedouble;
    if (!(v >= 0 && v <= 9007199254740992.0) || v != (double)(uint64_t)v) return 0;
    *out = (uint64_t)v;
    return 1;
}

g3d_status g3d__safetensors_parse(g3d_ckpt *ck)
{
    const char *p = ck->path;
    uint64_t hlen = 0;
    for (int i = 7; i >= 0; i--) hlen = (hlen << 8) | ck->map[i];
    if (hlen > ck->map_size - 8)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: safetensors header length %llu runs past the end of the file (%zu bytes)",
                       p, (unsigned long long)hlen, ck->map_size);
    if (hlen > G3D_ST_MAX_HEADER)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: safetensors header of %llu bytes is absurdly large", p,
                       (unsigned long long)hlen);
    const char *hdr = (const char *)ck->map + 8;
    const char *end = NULL;
    cJSON *root = cJSON_ParseWithLengthOpts(hdr, (size_t)hlen, &end, 0);
    /* Writers pad the header with spaces to align the data; anything else after it is corrupt. */
    while (root && end && end < hdr + hlen && (*end == ' ' || *end == '\n' || *end == '\r' || *end == '\t'))
        end++;
    if (!root || !cJSON_IsObject(root) || end != hdr + hlen) {
        cJSON_Delete(root);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: safetensors header is not a JSON object", p);
    }
    const unsigned char *data = ck->map + 8 + hlen;
    uint64_t data_size = ck->map_size - 8 - hlen;
    g3d_status rc = G3D_OK;
    st_range *rg = NULL;
    int n_items = cJSON_GetArraySize(root);
    rg = g3d_calloc((size_t)(n_items ? n_items : 1), sizeof *rg, "safetensors ranges");
    if (!rg) { cJSON_Delete(root); return G3D_ERR_NOMEM; }
    int64_t nr = 0;
    for (cJSON *e = root->child; e; e = e->next) {
        const char *name = e->string;
        if (strcmp(name, "__metadata__") == 0) {
            if (!cJSON_IsObject(e)) {
                rc = G3D_ERR(G3D_ERR_FORMAT, "%s: __metadata__ is not a JSON object", p);
                goto done;
            }
            continue;
        }
        const cJSON *jd = cJSON_GetObjectItemCaseSensitive(e, "dtype");
        const cJSON *js = cJSON_GetObjectItemCaseSensitive(e, "shape");
        const cJSON *jo = cJSON_GetObjectItemCaseSensitive(e, "data_offsets");
        if (!cJSON_IsObject(e) || !cJSON_IsString(jd) || !cJSON_IsArray(js) || !cJSON_IsArray(jo) ||
            cJSON_GetArraySize(jo) != 2) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' needs dtype, shape and data_offsets [begin, end]", p, name);
            goto done;
        }
        int dt = g3d__dtype_parse(jd->valuestring);
        if (dt < 0) {
            rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: tensor '%s' has unsupported dtype '%s'", p, name, jd->valuestring);
            goto done;
        }
        int ndim = cJSON_GetArraySize(js);
        if (ndim > G3D_MAX_DIMS) {
            rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: tensor '%s' has %d dimensions (at most %d supported)", p, name,
                         ndim, G3D_MAX_DIMS);
            goto done;
        }
        int64_t shape[G3D_MAX_DIMS];
        int k = 0;
        for (const cJSON *d = js->child; d; d = d->next, k++) {
            uint64_t v;
            if (!json_u64(d, &v)) {
                rc = G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' has a non-integer or negative dimension", p, name);
                goto done;
            }
            shape[k] = (int64_t)v;
        }
        uint64_t b, en;
        if (!json_u64(jo->child, &b) || !json_u64(jo->child->next, &en) || en < b || en > data_size) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' data_offsets lie outside the data section (%llu bytes)", p,
                         name, (unsigned long long)data_size);
            goto done;
        }
        int64_t numel = g3d__ckpt_numel(ndim, shape);
        if (numel < 0 || (uint64_t)numel > UINT64_MAX / 8 ||
            (uint64_t)numel * g3d_dtype_size((g3d_dtype)dt) != en - b) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' (%s, %lld elements) does not match its %llu data bytes", p,
                         name, jd->valuestring, (long long)numel, (unsigned long long)(en - b));
            goto done;
        }
        rc = g3d__ckpt_add(ck, name, (g3d_dtype)dt, ndim, shape, data + b);
        if (rc != G3D_OK) goto done;
        rg[nr].begin = b;
        rg[nr].end = en;
        rg[nr].idx = ck->n - 1;
        nr++;
    }
    qsort(rg, (size_t)nr, sizeof *rg, cmp_range);
    /* After sorting by start, a non-empty range overlaps an earlier one iff it starts before
     * the furthest end seen so far. */
    int64_t far = -1;
    for (int64_t i = 0; i < nr; i++) {
        if (rg[i].end == rg[i].begin) continue;
        if (far >= 0 && rg[i].begin < rg[far].end) {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: tensors '%s' and '%s' overlap in the data section", p,
                         ck->t[rg[far].idx].name, ck->t[rg[i].idx].name);
            goto done;
        }
        if (far < 0 || rg[i].end > rg[far].end) far = i;
    }
    cJSON *meta = cJSON_DetachItemFromObjectCaseSensitive(root, "__metadata__");
    ck->meta = meta;
done:
    free(rg);
    cJSON_Delete(root);
    return rc;
}
