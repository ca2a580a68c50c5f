/* gen3d/npy.h - NumPy arrays on disk: .npy files and .npz archives of them.
 *
 * Readers accept float32, float16, float64, uint8, uint16 and bool arrays of up to 8
 * dimensions in either byte order, C order only, and convert them to float32; headers and
 * sizes are checked against the file before any data is read (a fuzz target runs on them).
 * .npz members are read through the zip reader (zip.h), stored or deflated.
 */
#ifndef G3D_NPY_H
#define G3D_NPY_H

#include "gen3d/base.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A numeric array read from .npy/.npz, converted to float32. */
typedef struct g3d_array {
    int ndim;
    int64_t shape[8];
    float *data;  /* (prod(shape)) row-major; free with g3d_array_free */
    int integer;  /* 1 if the file stored integers (uint8/uint16/bool) */
} g3d_array;
void g3d_array_free(g3d_array *a);

/* Parses an .npy file image held in memory (`label` names it in messages). */
g3d_status g3d_npy_parse(const unsigned char *buf, size_t n, const char *label, g3d_array *out);
g3d_status g3d_npy_load(const char *path, g3d_array *out);
/* Reads one member of an .npz (member NULL: "arr_0", else the first member). The ".npy"
 * suffix of member names is optional. */
g3d_status g3d_npz_load(const char *path, const char *member, g3d_array *out);
/* Writes a float32 array of the given shape as .npy (atomically). */
g3d_status g3d_npy_save(const char *path, const float *data, int ndim, const int64_t *shape);

#ifdef __cplusplus
}
#endif
#endif /* G3D_NPY_H */
