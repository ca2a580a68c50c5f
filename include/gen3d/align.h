/* gen3d/align.h - aligning the depth of a newly generated view to the existing cloud
 * (the Gen3d paper, section 3.2).
 *
 * The new view's depth (from a depth model or completion) is consistent within itself but
 * not with the cloud. Where the rendered cloud covers the view (mask M = 1) and touches a
 * hole (|grad M| > 0), the cloud's depth along the pixel's ray and the new depth describe the
 * same surface: their ratio is the correction needed there. New points may only move along
 * their camera rays (so the inpainted colours stay where they are drawn), so the correction
 * is a per-pixel depth factor. Outlier correspondences (median/MAD test on the log ratio) are
 * dropped; the log-ratio is then interpolated over the holes with the boundary values held
 * fixed: a plane fitted to the boundary values plus a harmonic residual (membrane.h), so a
 * correction that varies across the view keeps its trend into wide holes at the image border
 * instead of being forced to zero there (LucidDreamer pins zero correction at the image
 * corners). The existing side is not changed.
 *
 * A hole that a depth edge runs into is a disocclusion: what fills it lies behind the occluder.
 * The pixels on the near side of such an edge (g3d_align_far_side) are therefore no
 * correspondences: the correction follows the far side alone, so the hole's depth is not pulled
 * in front of what lies behind it.
 */
#ifndef G3D_ALIGN_H
#define G3D_ALIGN_H

#include "gen3d/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_align_params {
    float outlier_mads;     /* reject |r - median| > this x 1.4826 MAD (3.0) */
    float max_ratio;        /* ignore correspondences whose depths differ by more than this factor (3.0) */
    float edge_ratio;       /* > 1: drop the near side of depth edges (g3d_align_far_side with this
                               ratio); 0 = every boundary pixel is a correspondence (1.1) */
} g3d_align_params;
/* Fills the defaults above. */
void g3d_align_params_default(g3d_align_params *p);

typedef struct g3d_align_stats {
    int64_t correspondences;     /* boundary pixels used */
    int64_t rejected;            /* dropped as outliers */
    double residual_before;      /* mean |new - cloud| / cloud over the correspondences */
    double residual_after;       /* the same after alignment (0 when all are kept: they are pinned) */
    double median_ratio;         /* median cloud/new depth ratio */
    int64_t near_side;           /* boundary pixels on the near side of a depth edge (edge_ratio),
                                    not used as correspondences */
} g3d_align_stats;

/* depth_new (h, w, 1): the new view's full depth, corrected in place at the hole pixels
 * (mask < 0.5). depth_cloud, mask (h, w, 1): the cloud rendered into the view. If there is no
 * usable correspondence, the median-free fallback is to leave depth_new unchanged (stats say
 * so). stats may be NULL. */
g3d_status g3d_align_depth(g3d_image *depth_new, const g3d_image *depth_cloud, const g3d_image *mask,
                           const g3d_align_params *p, g3d_align_stats *stats);

/* The near side of the depth edges that run into holes. depth_cloud, mask (h, w, 1): the cloud
 * rendered into a view (covered where mask >= 0.5). A covered pixel next to a hole is on the near
 * side when, looking across the hole in one of the 8 directions, the first covered pixel on the
 * other side is more than edge_ratio (> 1) times deeper than the pixel's surface continued
 * there (continued along its slope over the 3 pixels behind it when it recedes, so that a floor
 * at a grazing angle is not an edge; no verdict in a direction without a covered pixel there).
 * *far (created by the call, free with g3d_image_free) gets, at those pixels, the depth of that
 * far side (the nearest of the far sides found), carried 4 pixels into the covered
 * pixels behind them that are still in front of it, and 0 everywhere else; *n_near (may be
 * NULL) counts the boundary pixels found. A depth estimator given the cloud's depth with *far
 * written over it completes a hole from its far side. */
g3d_status g3d_align_far_side(const g3d_image *depth_cloud, const g3d_image *mask, float edge_ratio, g3d_image *far,
                              int64_t *n_near);

#ifdef __cplusplus
}
#endif
#endif /* G3D_ALIGN_H */
