/* gen3d/init.h - the Gaussians training starts from: one per point of a coloured point cloud
 * (the Inria recipe), or random points around the cameras when a dataset has no cloud.
 */
#ifndef G3D_INIT_H
#define G3D_INIT_H

#include "gen3d/gaussians.h"
#include "gen3d/train.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Initial Gaussians from a point cloud (the Inria recipe):
 *   xyz (n, 3) world positions, rgb (n, 3) colours in [0, 1].
 *   mean = xyz; sh DC = (rgb - 0.5) / C0, higher SH = 0; rotation = identity;
 *   opacity = 0.1 (logit stored); log_scale (all three axes) = log(sqrt(max(d2, 1e-7))) with d2 the
 *   mean squared distance to the 3 nearest other points (uniform-grid search, not O(n^2)).
 * `g` is created here (capacity n, degree sh_degree) and owned by the caller (g3d_gaussians_free).
 * n must be >= 1; with fewer than 4 points the available neighbours are used (scale 1e-7 floor
 * when alone). Errors: G3D_ERR_ARG (n < 1, non-finite input), G3D_ERR_NOMEM. */
g3d_status g3d_gaussians_init_from_points(g3d_gaussians *g, const float *xyz, const float *rgb,
                                          int64_t n, int sh_degree);

/* The shape of Gaussians started from pixel footprints (g3d_gaussians_init_from_footprints). */
typedef struct g3d_footprint_init {
    double scale;    /* in-plane standard deviation per footprint step (0.5: neighbours at one
                        pixel's spacing overlap like a pixel grid, not a blur) */
    double thin;     /* extent along the surface normal, relative to the smaller in-plane one (0.2) */
    double opacity;  /* starting opacity (0.5) */
} g3d_footprint_init;
/* Fills the defaults above. */
void g3d_footprint_init_default(g3d_footprint_init *p);

/* Initial Gaussians from a lifted point cloud whose points keep their pixel footprints
 * (cloud.h: span (n, 6), the world steps to the next pixel right and down): each Gaussian is a
 * flat ellipse on the surface, its covariance scale^2 (sx sx^T + sy sy^T) in the plane of the
 * steps and thin x the smaller axis along the normal, so that at the input's resolution the
 * Gaussians tile the image like its pixels and, seen from another camera, foreshorten like the
 * surface. Colour as g3d_gaussians_init_from_points, opacity p->opacity. `g` is created here.
 * Errors: G3D_ERR_ARG (n < 1, non-finite input, a zero footprint, parameters out of range),
 * G3D_ERR_NOMEM. */
g3d_status g3d_gaussians_init_from_footprints(g3d_gaussians *g, const float *xyz, const float *rgb, const float *span,
                                              int64_t n, int sh_degree, const g3d_footprint_init *p);

/* How many random points a dataset without a cloud starts from (nerfstudio's splatfacto). */
#define G3D_RANDOM_INIT_POINTS 50000

/* Initial Gaussians from n random points, as nerfstudio's splatfacto does without a cloud:
 * uniform in a cube around the mean camera centre of `views` with half-side 10 x their spread
 * (g3d_train_scene_extent / 1.1), grey (rgb 0.5), seeded by `seed`; then as
 * g3d_gaussians_init_from_points. `g` is created here. Errors: G3D_ERR_ARG (n < 1, nviews < 1),
 * G3D_ERR_NOMEM. */
g3d_status g3d_gaussians_init_random(g3d_gaussians *g, const g3d_train_view *views, int nviews, int64_t n,
                                     int sh_degree, uint64_t seed);

#ifdef __cplusplus
}
#endif
#endif /* G3D_INIT_H */
