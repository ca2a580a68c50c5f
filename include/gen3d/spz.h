/* gen3d/spz.h - .spz export/import (Niantic's compressed splat format, legacy version 2).
 *
 * Version 2 is the one every web viewer that reads .spz accepts (Spark reads 1-3,
 * GaussianSplats3D only 1-2). The file is a gzip stream of a 16-byte little-endian header
 *   u32 magic 0x5053474e ("NGSP"), u32 version 2, u32 numPoints,
 *   u8 shDegree, u8 fractionalBits (12), u8 flags (0), u8 reserved (0)
 * followed by per-attribute arrays, in this order:
 *   positions  3 x 24-bit signed fixed point, round(v * 2^fractionalBits)   (resolution 0.24 mm,
 *              range +-2048 m: farther Gaussians are rejected with G3D_ERR_ARG)
 *   alphas     u8 round(sigmoid(logit) * 255)
 *   colours    u8 round(f_dc * 0.15 * 255 + 127.5)
 *   scales     u8 round((log scale + 10) * 16)
 *   rotations  3 x u8 round(q * 127.5 + 127.5) of the unit quaternion's x, y, z with w >= 0
 *   SH rest    u8 per coefficient, coefficient-major with colour fastest (our own layout):
 *              round(v * 128 + 128) rounded to a multiple of 8 (degree 1, 5 bits) or 16 (higher)
 *
 * AXES: .spz is defined in RUB (x right, y up, z back, as OpenGL/three.js); gen3d works in
 * OpenCV RDF. Writing and reading both apply the flip (x, y, z) -> (x, -y, -z): positions,
 * the quaternion's y and z, and the SH coefficients whose basis function is odd in y or z
 * (band 1: indices 1, 2; band 2: 4, 7; band 3: 9, 11, 12, 14) change sign. Reading a file
 * written here therefore gives back the model in gen3d's frame.
 *
 * Round-trip error bounds (decode(encode(g)) vs g, see tests/test_spz.c): position 2^-13 m;
 * colour DC 1/(2*0.15*255) = 0.0131; log scale 1/32; SH rest 4.5/128 (band 1) or 8.5/128 (higher)
 * for values in [-1, 1]; opacity 0.5/255 after the sigmoid; quaternion components about 0.01
 * (w is recomputed from x, y, z, so precision drops for rotations near 180 degrees:
 * |q.q'| >= 0.995 in the worst case, the known weakness of version 2). Values outside a
 * field's range are clamped.
 */
#ifndef G3D_SPZ_H
#define G3D_SPZ_H

#include "gen3d/gaussians.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Writes the first g->n Gaussians to `path` atomically (nothing left behind on failure).
 * Errors: G3D_ERR_ARG (a position beyond the fixed-point range, more than 2^32-1 Gaussians),
 * G3D_ERR_IO, G3D_ERR_NOMEM. */
g3d_status g3d_spz_save(const char *path, const g3d_gaussians *g);

/* The same file in memory: *data (malloc'd, caller frees) holds *size bytes. `label` names
 * the scene in error messages. Errors as g3d_spz_save, less G3D_ERR_IO. */
g3d_status g3d_spz_encode(const g3d_gaussians *g, const char *label, uint8_t **data, size_t *size);

/* Reads a version-2 .spz (versions 1 and 3 give G3D_ERR_UNSUPPORTED).
 * `g` is created here (caller frees with g3d_gaussians_free) and left zeroed on failure.
 * Errors name the file: G3D_ERR_FORMAT (not gzip, bad magic, truncated, absurd count),
 * G3D_ERR_UNSUPPORTED (other versions, SH degree > 3), G3D_ERR_IO. */
g3d_status g3d_spz_load(const char *path, g3d_gaussians *g);

#ifdef __cplusplus
}
#endif
#endif /* G3D_SPZ_H */
