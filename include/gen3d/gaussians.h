/* gen3d/gaussians.h - the 3D Gaussian model in structure-of-arrays form.
 *
 * Parameters are stored pre-activation, exactly as the standard 3DGS .ply holds them:
 *   scale   = exp(log_scales)           (metres, per local axis)
 *   opacity = sigmoid(opacity_logits)
 *   rotation= normalize(rots)           quaternion (w, x, y, z), rotates local -> world
 *   colour  = SH evaluation of `sh` + 0.5, clamped at 0 (Inria convention)
 * Coordinates are in the scene's world frame (OpenCV axes, see camera.h).
 *
 * SH layout: K = (sh_degree + 1)^2 coefficients per colour channel, coefficient-major:
 *   sh[(i * K + k) * 3 + ch]    k = 0 is the DC term (the PLY's f_dc_*), k >= 1 the rest.
 * (The PLY stores f_rest grouped by channel; the PLY reader/writer converts.)
 *
 * All arrays are sized for `capacity` Gaussians; the first `n` are live. One allocation
 * backs all arrays (g3d_gaussians_create / _reserve), so copying the model is one memcpy of
 * each array.
 */
#ifndef G3D_GAUSSIANS_H
#define G3D_GAUSSIANS_H

#include "gen3d/base.h"

#ifdef __cplusplus
extern "C" {
#endif

#define G3D_SH_MAX_DEGREE 3
#define G3D_SH_COEFFS(deg) (((deg) + 1) * ((deg) + 1))
#define G3D_SH_C0 0.28209479177387814f

typedef struct g3d_gaussians {
    int64_t n;              /* live Gaussians */
    int64_t capacity;       /* allocated */
    int sh_degree;          /* 0..3: coefficients stored per Gaussian = G3D_SH_COEFFS(sh_degree) */
    float *means;           /* (capacity, 3) world position */
    float *log_scales;      /* (capacity, 3) */
    float *rots;            /* (capacity, 4) w, x, y, z (not necessarily normalised) */
    float *opacity_logits;  /* (capacity) */
    float *sh;              /* (capacity, K, 3) */
    void *block_;           /* the single allocation behind all arrays */
} g3d_gaussians;

/* Allocates room for `capacity` Gaussians of SH degree `sh_degree`, n = 0, zero-filled. */
g3d_status g3d_gaussians_create(g3d_gaussians *g, int64_t capacity, int sh_degree);
/* Grows capacity to at least `capacity`, keeping the first n Gaussians. */
g3d_status g3d_gaussians_reserve(g3d_gaussians *g, int64_t capacity);
/* Frees all arrays and zeroes the struct; NULL/zeroed is fine. */
void g3d_gaussians_free(g3d_gaussians *g);
/* Deep copy (dst is overwritten, not freed first). */
g3d_status g3d_gaussians_clone(g3d_gaussians *dst, const g3d_gaussians *src);
/* Copies Gaussian j of src into slot i of dst (same sh_degree). */
void g3d_gaussians_copy_one(g3d_gaussians *dst, int64_t i, const g3d_gaussians *src, int64_t j);
/* Keeps the Gaussians with keep[i] != 0, in order; returns the new n. */
int64_t g3d_gaussians_compact(g3d_gaussians *g, const uint8_t *keep);
/* Checks every value is finite; G3D_ERR_FORMAT naming the first bad Gaussian otherwise. */
g3d_status g3d_gaussians_validate(const g3d_gaussians *g, const char *label);
/* Reads a scene file chosen by extension: .ply (standard 3DGS layout) or .spz. *g is created
 * by the call. Errors name the file: missing, unknown extension, the readers' own, and a scene
 * with no Gaussians (G3D_ERR_FORMAT). */
g3d_status g3d_gaussians_load(const char *path, g3d_gaussians *g);

#ifdef __cplusplus
}
#endif
#endif /* G3D_GAUSSIANS_H */
