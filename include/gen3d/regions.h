/* gen3d/regions.h - weight-free object proposals: a mask provider (providers.h) for the layers
 * (layers.h) when no segmentation model is given.
 *
 * The scene's large planes (floor, walls, ceiling, ground; each explaining at least
 * `min_plane` of the image) are found by RANSAC on the points lifted from depth and set aside
 * as structure; the remaining pixels split into 4-connected components across
 * depth-continuous neighbours, and each component is one proposal (score 1). An object
 * resting on the floor is thus cut from it where the floor plane ends, while its own faces
 * stay together. Deterministic (fixed RANSAC seed).
 */
#ifndef G3D_REGIONS_H
#define G3D_REGIONS_H

#include "gen3d/providers.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_regions_params {
    float min_plane;      /* a structure plane explains at least this fraction of the image (0.10) */
    float plane_tol;      /* inlier distance to a plane, relative to depth (0.012) */
    float jump;           /* neighbours further apart than this fraction of depth are disconnected (0.03) */
    int max_planes;       /* structure planes to remove at most (6) */
    int ransac_iters;     /* plane hypotheses per plane (300) */
    int min_size;         /* smallest proposal in pixels (7) */
} g3d_regions_params;

/* Fills the defaults above. */
void g3d_regions_params_default(g3d_regions_params *p);

/* Region proposals as a mask provider. Needs the camera intrinsics (to lift pixels to points;
 * images of another size rescale them); K and params are copied, params NULL = defaults. Release with
 * g3d_mask_provider_free. */
g3d_status g3d_mask_provider_regions_create(const g3d_regions_params *params, g3d_intrinsics K, g3d_mask_provider *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_REGIONS_H */
