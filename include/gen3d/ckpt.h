/* gen3d/ckpt.h - model checkpoints: safetensors and PyTorch zip files (.pth/.pt/.ckpt),
 * read in two phases.
 *
 *   1. g3d_ckpt_open builds an index (name, dtype, shape, byte location) and checks every
 *      entry against the file before any tensor data is touched. safetensors files are
 *      memory-mapped; PyTorch files are parsed with a restricted unpickler that only rebuilds
 *      tensors and plain containers and never executes anything.
 *   2. g3d_ckpt_read copies one tensor into a caller buffer as float32 (all dtype conversion
 *      lives in one place), after checking the expected shape. Tensors are found by their
 *      official names; messages name the tensor and print got vs expected.
 *
 * Non-tensor content (safetensors __metadata__, or the rest of a pickled dict such as
 * {'model_config': {...}}) is available as a cJSON tree.
 *
 * A g3d_ckpt is immutable after opening: concurrent reads from several threads are fine.
 */
#ifndef G3D_CKPT_H
#define G3D_CKPT_H

#include "gen3d/base.h"

#ifdef __cplusplus
extern "C" {
#endif

struct cJSON;

typedef enum g3d_dtype {
    G3D_DT_F32, G3D_DT_F16, G3D_DT_BF16, G3D_DT_F64,
    G3D_DT_I64, G3D_DT_I32, G3D_DT_I16, G3D_DT_I8, G3D_DT_U8, G3D_DT_BOOL,
    G3D_DT_COUNT
} g3d_dtype;

/* "F32", "F16", ... (safetensors spelling). */
const char *g3d_dtype_name(g3d_dtype t);
/* Bytes per element. */
size_t g3d_dtype_size(g3d_dtype t);

#define G3D_MAX_DIMS 8

typedef struct g3d_tensor_info {
    const char *name;               /* official name, e.g. "pretrained.blocks.0.attn.qkv.weight" */
    g3d_dtype dtype;
    int ndim;
    int64_t shape[G3D_MAX_DIMS];    /* outermost first (PyTorch order) */
    int64_t numel;
    const void *data;               /* first element, contiguous row-major (PyTorch strides
                                       are checked to be contiguous at open time) */
} g3d_tensor_info;

typedef struct g3d_ckpt g3d_ckpt;   /* opaque */

/* Opens a checkpoint file, detected from its content (not its name): safetensors, or a PyTorch
 * zip checkpoint (.pth/.pt/.ckpt). The file is memory-mapped; tensors point into it. PyTorch
 * naming rule: tensors are named by their dotted path in the saved object; when exactly one
 * top-level dict entry holds tensors and it is a dict (e.g. {'model': state_dict,
 * 'model_config': {...}}), that key is left out, so tensors keep their state-dict names.
 * Only contiguous tensors in uncompressed little-endian storages are accepted. On success
 * *out owns the mapping and the index; free with g3d_ckpt_free. */
g3d_status g3d_ckpt_open(const char *path, g3d_ckpt **out);
/* The same over a caller-owned buffer of n bytes that must outlive the checkpoint; `label`
 * names it in messages. */
g3d_status g3d_ckpt_open_memory(const void *data, size_t n, const char *label, g3d_ckpt **out);
void g3d_ckpt_free(g3d_ckpt *ck);

/* The path given to open (for messages). */
const char *g3d_ckpt_path(const g3d_ckpt *ck);
int64_t g3d_ckpt_count(const g3d_ckpt *ck);
/* i-th tensor in file order, 0 <= i < count. */
const g3d_tensor_info *g3d_ckpt_tensor(const g3d_ckpt *ck, int64_t i);
/* Tensor by exact name, or NULL. */
const g3d_tensor_info *g3d_ckpt_find(const g3d_ckpt *ck, const char *name);

/* Copies tensor `name` into dst as float32. If ndim > 0 the shape must equal shape[0..ndim);
 * a missing tensor or a shape mismatch is G3D_ERR_MODEL with a message naming the tensor
 * and both shapes. dst holds numel floats. */
g3d_status g3d_ckpt_read(const g3d_ckpt *ck, const char *name, int ndim, const int64_t *shape, float *dst);
/* The same, allocating dst (caller frees). */
g3d_status g3d_ckpt_read_alloc(const g3d_ckpt *ck, const char *name, int ndim, const int64_t *shape, float **dst);

/* Converts n elements of type t at src to float32. */
void g3d_dtype_to_f32(g3d_dtype t, const void *src, float *dst, int64_t n);

/* Total number of elements over all tensors (the parameter count of a state dict). */
int64_t g3d_ckpt_numel(const g3d_ckpt *ck);

/* Non-tensor content as JSON (safetensors: the __metadata__ object; PyTorch: the unpickled
 * top-level object with every tensor replaced by its name). NULL if there is none. Owned by
 * the checkpoint. */
const struct cJSON *g3d_ckpt_meta(const g3d_ckpt *ck);

/* One tensor to write: `data` holds numel(shape) contiguous little-endian values of dtype. */
typedef struct g3d_tensor_out {
    const char *name;
    g3d_dtype dtype;
    int ndim;
    int64_t shape[G3D_MAX_DIMS];
    const void *data;
} g3d_tensor_out;

/* Writes n tensors, in order, as a safetensors file at `path` (atomically: a temporary name,
 * then rename). meta, if not NULL, is a JSON object of string values stored as __metadata__.
 * The file reads back with g3d_ckpt_open. */
g3d_status g3d_safetensors_write(const char *path, const g3d_tensor_out *t, int n, const struct cJSON *meta);

#ifdef __cplusplus
}
#endif
#endif /* G3D_CKPT_H */
