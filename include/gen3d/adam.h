/* gen3d/adam.h - Adam optimiser over the Gaussian model, with per-group learning rates.
 *
 * Gradients and both moment estimates are stored as g3d_gaussians structs (gaussians.h), so
 * they share the model's SoA layout: grad->means[i*3+k] is dL/d g->means[i*3+k], and the
 * moments follow densification through the same g3d_gaussians_* calls (reserve, copy_one,
 * compact) that edit the model. One global step count drives bias correction, as in the
 * reference implementation (moments of newly created Gaussians start at zero).
 *
 * Learning rates (3DGS defaults, g3d_adam_params_default):
 *   means    1.6e-4 * extent, decaying log-linearly to 1.6e-6 * extent over `means_lr_steps`
 *   SH DC    2.5e-3, SH rest 2.5e-3 / 20
 *   opacity  2.5e-2 (the Oct-2024 reference value; the 2023 release used 5e-2 - the lower
 *            value is gentler on short schedules that reset opacity)
 *   scales   5e-3,  rotations 1e-3;  beta = (0.9, 0.999), eps = 1e-15.
 */
#ifndef G3D_ADAM_H
#define G3D_ADAM_H

#include "gen3d/gaussians.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum g3d_param_group {
    G3D_PG_MEANS = 0,
    G3D_PG_SH_DC,
    G3D_PG_SH_REST,
    G3D_PG_OPACITY,
    G3D_PG_SCALES,
    G3D_PG_ROTS,
    G3D_PG_COUNT
} g3d_param_group;

typedef struct g3d_adam_params {
    double lr[G3D_PG_COUNT];  /* lr[G3D_PG_MEANS] is the initial rate per unit of extent */
    double means_lr_final;    /* final means rate per unit of extent */
    int64_t means_lr_steps;   /* steps over which the means rate decays (then stays final) */
    double beta1, beta2, eps;
} g3d_adam_params;

typedef struct g3d_adam {
    g3d_adam_params p;
    int64_t step;       /* steps taken so far */
    g3d_gaussians m, v; /* first and second moments, same degree and capacity as the model */
} g3d_adam;

/* Fills the 3DGS defaults above; means_lr_steps = 30000 (set it to the schedule length). */
void g3d_adam_params_default(g3d_adam_params *p);

/* Creates zero moments shaped like `model` (its capacity, n and sh_degree). a is overwritten. */
g3d_status g3d_adam_init(g3d_adam *a, const g3d_adam_params *p, const g3d_gaussians *model);
/* Frees the moments; NULL or zeroed is fine. */
void g3d_adam_free(g3d_adam *a);

/* The means learning rate (world units) at `step` for a scene of size `extent`. */
double g3d_adam_means_lr(const g3d_adam_params *p, int64_t step, double extent);

/* One Adam step on the first model->n Gaussians: increments a->step, then for every value
 *   m = b1 m + (1-b1) g;  v = b2 v + (1-b2) g^2;
 *   x -= lr * (m / (1 - b1^t)) / (sqrt(v / (1 - b2^t)) + eps)
 * with lr from the value's group (means scheduled by g3d_adam_means_lr at the step before
 * the increment). grad must have the model's sh_degree and n; the moments must have the
 * model's n (keep them in sync when densifying). G3D_ERR_MISMATCH otherwise. */
g3d_status g3d_adam_step(g3d_adam *a, g3d_gaussians *model, const g3d_gaussians *grad,
                         double extent);

/* The same step on the visible Gaussians only (radii[i] > 0, the rasterizer's output for the
 * view the gradient came from): the others keep their parameters and moments, as if that
 * step had not happened for them ("visible Adam"). radii NULL = every Gaussian (g3d_adam_step).
 * The step count still rises once. Computed in single precision. */
g3d_status g3d_adam_step_visible(g3d_adam *a, g3d_gaussians *model, const g3d_gaussians *grad, double extent,
                                 const int32_t *radii);

#ifdef __cplusplus
}
#endif
#endif /* G3D_ADAM_H */
