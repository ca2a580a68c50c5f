/* ckpt_int.h - internals shared by the checkpoint readers (ckpt.c, safetensors.c, torch_zip.c). */
#ifndef G3D_CKPT_INT_H
#define G3D_CKPT_INT_H

#include "gen3d/ckpt.h"
#include "gen3d/zip.h"

struct g3d_ckpt {
    char *path;
    const unsigned char *map;      /* the whole file, memory-mapped */
    size_t map_size;
    g3d_tensor_info *t;            /* (n) in file order; names owned */
    int64_t n, cap;
    int64_t *sorted;               /* (n) indices into t sorted by name */
    struct cJSON *meta;
    unsigned char **bufs;          /* storages extracted from compressed zip entries (owned) */
    int64_t n_bufs;
};

/* Appends a tensor (name copied); data may be NULL until resolved. */
g3d_status g3d__ckpt_add(g3d_ckpt *ck, const char *name, g3d_dtype dt, int ndim, const int64_t *shape,
                         const void *data);
/* numel of a shape, or -1 on a negative dim / overflow of int64. */
int64_t g3d__ckpt_numel(int ndim, const int64_t *shape);
/* Parses "F32", "F16", ...; returns -1 if unknown. */
int g3d__dtype_parse(const char *s);

g3d_status g3d__safetensors_parse(g3d_ckpt *ck);
g3d_status g3d__torch_zip_parse(g3d_ckpt *ck);

#endif
