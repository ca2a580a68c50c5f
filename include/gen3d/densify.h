/* gen3d/densify.h - adaptive density control of 3D Gaussian splatting (Kerbl et al. 2023).
 *
 * Every view the trainer adds, for each Gaussian visible in it (screen radius > 0), the norm of
 * the loss gradient w.r.t. its projected 2D mean (NDC units, raster.h grad2d) and one count.
 * Every `interval` iterations in [from, until):
 *   clone  avg grad >= grad_threshold and max scale <= percent_dense * extent: an exact copy
 *          is appended (Adam moments of the copy zero);
 *   split  avg grad >= grad_threshold and max scale > percent_dense * extent (originals only):
 *          2 children at mean + R (s * eps), eps ~ N(0, I), scale / 1.6, other parameters
 *          copied, zero moments; the parent is removed;
 *   prune  opacity < min_opacity; and, once past the first opacity reset, screen radius
 *          > max_screen_radius px or max scale > max_world_scale * extent.
 * Then the statistics restart. Every `opacity_reset_interval` iterations (while densifying),
 * opacities are clamped to at most 0.01 and their Adam moments zeroed.
 * Moments are kept in step with the model: every edit applies to adam->m and adam->v too.
 */
#ifndef G3D_DENSIFY_H
#define G3D_DENSIFY_H

#include "gen3d/adam.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_densify_params {
    int64_t from, until, interval;  /* iterations: densify when from < it < until, it % interval == 0 */
    int64_t opacity_reset_interval; /* 0 = never */
    double grad_threshold;          /* 0.0002 */
    double percent_dense;           /* 0.01 (of extent): clone/split boundary */
    double min_opacity;             /* 0.005 */
    double max_screen_radius;       /* 20 px */
    double max_world_scale;         /* 0.1 (of extent) */
    int64_t max_gaussians;          /* growth stops here (clones/splits skipped); 0 = no cap */
} g3d_densify_params;

/* Defaults for a schedule of `iterations` steps. At the reference 30000 the Inria values
 * (from 500, until 15000, every 100, opacity reset every 3000); shorter schedules keep the
 * interval of 100 (the statistic needs that many views) and scale the rest:
 * from = max(100, it/60), until = it/2, reset = max(1000, it/10). */
void g3d_densify_params_default(g3d_densify_params *p, int64_t iterations);

/* Per-Gaussian statistics, sized to the model's capacity. */
typedef struct g3d_densify_stats {
    float *grad_accum;   /* (capacity) sum of 2D gradient norms */
    int32_t *count;      /* (capacity) views that saw the Gaussian */
    float *max_radius;   /* (capacity) largest screen radius seen, px */
    int64_t capacity;
} g3d_densify_stats;

/* Allocates zero statistics for `capacity` Gaussians (st is overwritten). */
g3d_status g3d_densify_stats_init(g3d_densify_stats *st, int64_t capacity);
void g3d_densify_stats_free(g3d_densify_stats *st);  /* NULL/zeroed fine */

/* Adds one view: grad2d (n) and radii (n) as produced by g3d_raster_fwd/bwd for that view. */
void g3d_densify_accumulate(g3d_densify_stats *st, const float *grad2d, const int32_t *radii,
                            int64_t n);

typedef struct g3d_densify_result {
    int64_t cloned, split, pruned;
} g3d_densify_result;

/* Clone, split, prune as described above, on g and the moments in adam, then zero the
 * statistics (reallocated to the model's new capacity). prune_large: apply the screen/world
 * size tests. rng draws the split offsets. res may be NULL. On failure (NOMEM) the model
 * may have grown but stays consistent with the moments. */
g3d_status g3d_densify_step(g3d_gaussians *g, g3d_adam *adam, g3d_densify_stats *st,
                            const g3d_densify_params *p, double extent, int prune_large,
                            g3d_rng *rng, g3d_densify_result *res);

/* opacity := min(opacity, 0.01); the opacity moments are zeroed. */
void g3d_densify_reset_opacity(g3d_gaussians *g, g3d_adam *adam);

#ifdef __cplusplus
}
#endif
#endif /* G3D_DENSIFY_H */
