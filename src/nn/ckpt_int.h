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

/* ---- restricted unpickler (pickle.c) -------------------------------------------------- */
typedef enum g3d__pk_kind {
    G3D_PK_NONE, G3D_PK_BOOL, G3D_PK_INT, G3D_PK_FLOAT, G3D_PK_STR, G3D_PK_LIST, G3D_PK_TUPLE,
    G3D_PK_DICT, G3D_PK_GLOBAL, G3D_PK_STORAGE, G3D_PK_TENSOR
} g3d__pk_kind;

typedef struct g3d__pv g3d__pv;
struct g3d__pv {
    g3d__pk_kind kind;
    int64_t i;                 /* INT, BOOL; STORAGE: numel; TENSOR: storage offset (elements) */
    double f;                  /* FLOAT */
    char *s;                   /* STR; GLOBAL "module.name"; STORAGE: key */
    g3d__pv **items;           /* LIST/TUPLE elements; DICT alternating key, value (n counts both) */
    int64_t n, cap;
    int dtype;                 /* STORAGE, TENSOR: g3d_dtype */
    g3d__pv *storage;          /* TENSOR */
    int ndim;                  /* TENSOR */
    int64_t shape[G3D_MAX_DIMS], stride[G3D_MAX_DIMS];
};

typedef struct g3d__pickle {
    g3d__pv **pool;            /* every value allocated, freed together */
    int64_t n_pool, cap_pool;
    g3d__pv *root;
} g3d__pickle;

/* Unpickles `n` bytes (protocols 2-4 as written by torch.save); only plain containers,
 * OrderedDict, torch storages (persistent ids) and _rebuild_tensor_v2/_rebuild_parameter are
 * allowed; any other global fails with its name. `label` names the stream in messages.
 * Free with g3d__pickle_free even on failure. */
g3d_status g3d__pickle_load(g3d__pickle *pk, const unsigned char *buf, size_t n, const char *label);
void g3d__pickle_free(g3d__pickle *pk);
