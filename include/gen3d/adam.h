/* gen3d/adam.h - Adam for the Gaussian model, with one learning rate per parameter group.
 *
 * The optimiser state mirrors g3d_gaussians: first and second moments for every parameter,
 * in arrays of the same shapes, so that densification can copy, append and drop Gaussians in
 * the state exactly as in the model (new Gaussians start with zero moments, as in the
 * reference implementation). Update, per element: m = b1 m + (1-b1) g, v = b2 v + (1-b2) g^2,
 * p -= lr * (m / (1 - b1^t)) / (sqrt(v / (1 - b2^t)) + eps), with eps = 1e-15 as in 3DGS.
 */
#ifndef G3D_ADAM_H
#define G3D_ADAM_H

#include "gen3d/gaussians.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum g3d_param_group {
    G3D_GROUP_MEANS, G3D_GROUP_SCALES, G3D_GROUP_ROTS, G3D_GROUP_OPACITY, G3D_GROUP_SH_DC, G3D_GROUP_SH_REST,
    G3D_GROUP_COUNT
} g3d_param_group;

typedef struct g3d_adam {
    double lr[G3D_GROUP_COUNT];  /* learning rate per group */
    double beta1, beta2, eps;
    int64_t step;                /* updates done (for bias correction) */
    g3d_gaussians m, v;          /* moments, same layout and capacity as the model */
} g3d_adam;

/* Zeroed moments sized like g, the reference 3DGS learning rates (means 1.6e-4 x
 * scene_extent, scales 5e-3, rotations 1e-3, opacity 2.5e-2, SH DC 2.5e-3, SH rest 2.5e-3/20),
 * betas (0.9, 0.999), eps 1e-15. */
g3d_status g3d_adam_init(g3d_adam *a, const g3d_gaussians *g, double scene_extent);
void g3d_adam_free(g3d_adam *a);

/* One step: params -= update(grads). grads has the model's layout (a g3d_gaussians holding
 * gradients). Moments grow with the model if it grew (new Gaussians get zero moments). */
g3d_status g3d_adam_step(g3d_adam *a, g3d_gaussians *params, const g3d_gaussians *grads);

/* Extends the moments with zeros up to the model's current count (after Gaussians were
 * appended to it). */
g3d_status g3d_adam_grow(g3d_adam *a, const g3d_gaussians *params);

/* Keeps the moments of the Gaussians with keep[i] != 0 (call with the same mask as
 * g3d_gaussians_compact on the model). */
void g3d_adam_compact(g3d_adam *a, const uint8_t *keep);

#ifdef __cplusplus
}
#endif
#endif /* G3D_ADAM_H */
