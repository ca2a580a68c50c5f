/* gen3d/raster.h - differentiable tile rasterizer for 3D Gaussian splats (CPU, OpenMP).
 *
 * Pipeline (the same stages a GPU implementation would run, same per-frame buffers):
 *   1. project   one pass per Gaussian: view transform, near/guard-band culling, EWA 2D covariance
 *                with +eps2d dilation, conic, 3-sigma radius, SH colour, tile rectangle.
 *   2. bin/sort  one (tile, depth) key per touched tile, stable sort -> per-tile front-to-back lists.
 *   3. blend     one 16x16 tile per task, front to back: alpha = min(0.99, o * exp(power)),
 *                skip alpha < 1/255, stop when T would drop below 1e-4.
 *   backward     blend backward per tile (back to front, from the saved final T and last contributor),
 *                per-(instance) gradient records reduced per Gaussian in a fixed order, then
 *                projection/covariance/SH backward per Gaussian. Deterministic for a fixed thread
 *                count (actually independent of it: no float atomics, fixed reduction order).
 *
 * Conventions: camera.h (OpenCV axes, c2w pose, pixel centres at integer coordinates), gaussians.h
 * (pre-activation parameters, SH layout). Images are row-major, channels-last float:
 * rgb (H, W, 3), alpha (H, W), depth (H, W). Depth is the alpha-weighted view-space z
 * (sum_i w_i z_i, NOT divided by alpha; divide by alpha yourself for a normalised depth).
 */
#ifndef G3D_RASTER_H
#define G3D_RASTER_H

#include "gen3d/base.h"
#include "gen3d/camera.h"
#include "gen3d/gaussians.h"

#ifdef __cplusplus
extern "C" {
#endif

#define G3D_RASTER_TILE 16

typedef struct g3d_raster_params {
    float bg[3];           /* background colour added as T_final * bg; default black */
    int sh_degree_active;  /* SH degree evaluated, clamped to the model's; -1 = the model's (default) */
    int antialiased;       /* 1: multiply opacity by sqrt(det(S)/det(S + eps2d I)) (gsplat/Mip-Splatting) */
    float near_plane;      /* view z <= near_plane is culled; default 0.01 m */
    float eps2d;           /* screen-space dilation added to the 2D covariance diagonal; default 0.3 px^2 */
    float guard_band;      /* x/z and y/z clamped to guard_band * tan(fov/2) for the Jacobian; default 1.3 */
} g3d_raster_params;

/* Fills the defaults listed above. */
void g3d_raster_params_default(g3d_raster_params *s);

/* Per-frame buffers kept between calls (projected Gaussians, sort keys, tile ranges, final T and
 * last contributor per pixel, gradient scratch). Grows on demand, never shrinks; steady-state
 * calls do not allocate. Not thread-safe: one workspace per concurrent frame. */
typedef struct g3d_raster_ws g3d_raster_ws;

g3d_status g3d_raster_ws_create(g3d_raster_ws **out);
void g3d_raster_ws_free(g3d_raster_ws *ws);   /* NULL is fine */

/* Renders Gaussians `g` (the first g->n) seen by `cam` into caller-owned buffers of
 * cam->K.width x cam->K.height pixels:
 *   rgb   (H, W, 3)  required; colour + T_final * bg
 *   alpha (H, W)     optional (NULL); 1 - T_final
 *   depth (H, W)     optional; alpha-weighted view z, metres
 *   radii (N)        optional; screen radius in pixels, 0 = not visible in this view
 * Saves everything the backward pass needs in `ws`; a following g3d_raster_bwd must use the same
 * g, cam and params unchanged. Errors: G3D_ERR_ARG for bad sizes (W or H < 1 or > 32768),
 * G3D_ERR_NOMEM. On failure the outputs are unspecified and the workspace holds no valid frame. */
g3d_status g3d_raster_fwd(g3d_raster_ws *ws, const g3d_gaussians *g, const g3d_camera *cam,
                          const g3d_raster_params *s, float *rgb, float *alpha, float *depth,
                          int32_t *radii);

/* Backward of the last g3d_raster_fwd on this workspace.
 *   d_rgb   (H, W, 3) dL/d rgb, required
 *   d_alpha (H, W)    dL/d alpha, optional (NULL = 0)
 *   d_depth (H, W)    dL/d depth, optional (NULL = 0)
 *   grads   a model-shaped gradient holder (same sh_degree as g, capacity >= g->n), e.g. made with
 *           g3d_gaussians_create. Gradients w.r.t. the stored pre-activation parameters (means,
 *           log_scales, rots (through the normalisation), opacity_logits, sh) are ADDED to
 *           grads' arrays: zero them yourself before the first view of a batch. grads->n untouched.
 *   grad2d  (N) optional; ADDED: |dL/d mean2d| with the pixel gradient scaled by (0.5 W, 0.5 H)
 *           (Inria's NDC units, the densification statistic), for Gaussians with radius > 0.
 * Visibility counts for densification are radii > 0 from the forward.
 * Errors: G3D_ERR_ARG if no forward was run, G3D_ERR_MISMATCH if grads does not fit g. */
g3d_status g3d_raster_bwd(g3d_raster_ws *ws, const g3d_gaussians *g, const float *d_rgb,
                          const float *d_alpha, const float *d_depth, g3d_gaussians *grads,
                          float *grad2d);

#ifdef __cplusplus
}
#endif
#endif /* G3D_RASTER_H */
