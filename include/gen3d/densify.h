/* gen3d/densify.h - adaptive density control of the Gaussian model (the reference 3DGS
 * rules), keeping the optimiser state in step with the model.
 *
 *   - statistics: the view-space positional gradient norm of each Gaussian, accumulated over
 *     the views in which it was visible (g3d_densify_accumulate);
 *   - clone: mean gradient >= grad_threshold and largest scale <= percent_dense * extent:
 *     an identical copy is added (both then move apart under the optimiser);
 *   - split: mean gradient >= grad_threshold and largest scale > percent_dense * extent:
 *     replaced by `split_n` Gaussians drawn from it (means sampled from the Gaussian itself,
 *     scales divided by 0.8 * split_n);
 *   - prune: opacity below min_opacity, and when `prune_big` is set also Gaussians whose
 *     largest screen radius exceeded max_screen_px or whose largest scale exceeds
 *     max_world_fraction * extent;
 *   - opacity reset: every opacity clamped to at most `value`.
 * New Gaussians get zero optimiser moments; removed ones take theirs with them.
 */
#ifndef G3D_DENSIFY_H
#define G3D_DENSIFY_H

#include "gen3d/adam.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_densify_params {
    float grad_threshold;      /* 0.0002 */
    float percent_dense;       /* 0.01 */
    float min_opacity;         /* 0.005 */
    float max_screen_px;       /* 20 */
    float max_world_fraction;  /* 0.1 */
    int split_n;               /* 2 */
} g3d_densify_params;
g3d_densify_params g3d_densify_params_default(void);

/* Per-Gaussian statistics between two densification steps. */
typedef struct g3d_densify_stats {
    int64_t capacity;
    double *grad_sum;     /* (capacity) accumulated view-space gradient norms */
    int32_t *count;       /* (capacity) views in which the Gaussian was visible */
    float *max_radius;    /* (capacity) largest screen radius seen, pixels */
} g3d_densify_stats;
g3d_status g3d_densify_stats_init(g3d_densify_stats *s, int64_t n);
void g3d_densify_stats_free(g3d_densify_stats *s);

/* Adds one view: grad_norm (n) and radius (n, 0 = not visible). */
g3d_status g3d_densify_accumulate(g3d_densify_stats *s, int64_t n, const float *grad_norm, const float *radius);

typedef struct g3d_densify_report { int64_t cloned, split, pruned; } g3d_densify_report;

/* Clones, splits and prunes g (and the moments in opt, which may be NULL), then resets the
 * statistics for the new count. rng draws the split samples. */
g3d_status g3d_densify(g3d_gaussians *g, g3d_adam *opt, g3d_densify_stats *s, double extent, int prune_big,
                       const g3d_densify_params *p, g3d_rng *rng, g3d_densify_report *report);

/* Clamps every opacity to at most `value` (0.01 in the reference) and zeroes the opacity
 * moments of opt (may be NULL). */
void g3d_opacity_reset(g3d_gaussians *g, g3d_adam *opt, float value);

#ifdef __cplusplus
}
#endif
#endif /* G3D_DENSIFY_H */
