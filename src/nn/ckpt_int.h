/* ckpt_int.h - what the checkpoint readers share: the g3d_ckpt object they fill. */
#ifndef G3D_CKPT_INT_H
#define G3D_CKPT_INT_H

#include "gen3d/ckpt.h"

#include <cjson/cJSON.h>

struct g3d_ckpt {
    char *path;                 /* for messages (owned) */
    void *map;                  /* mmap of the file, or NULL for a borrowed buffer */
    size_t map_size;
    const unsigned char *data;  /* the bytes (the mapping or the borrowed buffer) */
    size_t size;
    g3d_tensor_info *tensors;   /* (n) in file order; names owned */
    int64_t n;
    int64_t *by_name;           /* (n) indices sorted by name, for lookup */
    cJSON *meta;                /* owned, may be NULL */
};

/* Parse the buffer (ck->data, ck->size) into ck's index: safetensors, and PyTorch zip files. */
g3d_status g3d__safetensors_index(g3d_ckpt *ck);
g3d_status g3d__torch_index(g3d_ckpt *ck);

#endif
