/* gen3d/depth_estimators.h - g3d_depth_estimator tables (gen3d/providers.h) built on the
 * depth networks.
 *
 * Depth Anything V2 (relative) predicts inverse depth up to an unknown scale and shift, so its
 * estimator needs known metric depth: it fits scale and shift in inverse depth on the pixels
 * where `known` is valid (gen3d/depthfit.h, least squares) and returns the aligned prediction
 * in metres for every pixel. Without known depth it fails with G3D_ERR_ARG rather than guess a
 * scale. A metric Depth Anything V2 (g3d_dav2_set_metric) returns its depth in metres as is,
 * with or without known depth. Intrinsics are not predicted: K_io is left as given.
 *
 * MoGe-2 predicts metric depth and the camera itself: its estimator returns the metric depth
 * of every pixel it finds valid (0 elsewhere: sky, beyond the predicted mask) without needing
 * `known` (which it ignores, as the contract lets the caller align). A known camera
 * (K_io->fx > 0) fixes the horizontal field of view of the fit; otherwise the predicted
 * intrinsics are written to K_io (pixels of the input image).
 */
#ifndef G3D_DEPTH_ESTIMATORS_H
#define G3D_DEPTH_ESTIMATORS_H

#include "gen3d/depth_anything.h"
#include "gen3d/moge.h"
#include "gen3d/providers.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Fills *out with an estimator running `model` at `input_size` (518 as trained; must be at
 * least 14). The estimator takes ownership of model: g3d_depth_estimator_free releases it
 * (also on failure of this call, model is freed). Concurrent estimate() calls on one table
 * are safe (the model is immutable). */
g3d_status g3d_depth_estimator_dav2_create(g3d_dav2 *model, int input_size, g3d_depth_estimator *out);

/* Fills *out with a MoGe-2 estimator running `model` with num_tokens tokens (<= 0: the model's
 * default). The model must have a metric scale head (G3D_ERR_UNSUPPORTED otherwise). Ownership
 * of model passes to the estimator exactly as for g3d_depth_estimator_dav2_create. */
g3d_status g3d_depth_estimator_moge_create(g3d_moge *model, int num_tokens, g3d_depth_estimator *out);

/* How g3d_depth_estimator_model_create runs the model it finds. */
typedef struct g3d_depth_model_params {
    int input_size;     /* Depth Anything V2 network input size; 518 */
    int num_tokens;     /* MoGe-2 encoder tokens; <= 0: the model's default */
    double max_depth;   /* Depth Anything V2: > 0 metric with this maximum depth (metres), 0
                           relative, < 0 (default) from the file name (g3d_dav2_metric_default) */
} g3d_depth_model_params;

/* Fills the defaults above. */
void g3d_depth_model_params_default(g3d_depth_model_params *p);

/* Opens a depth checkpoint and wraps it as an estimator, the architecture recognised from the
 * content (recognize.h): MoGe-2, or Depth Anything V2 (any other file, refused with the
 * loader's message naming the tensor when it is not one). p NULL = defaults. *metric (may be
 * NULL) is 1 when the estimator gives metres without known depth (MoGe-2, metric Depth
 * Anything V2). Release with g3d_depth_estimator_free; *out is zeroed on failure. */
g3d_status g3d_depth_estimator_model_create(const char *path, const g3d_depth_model_params *p, g3d_depth_estimator *out,
                                            int *metric);

#ifdef __cplusplus
}
#endif
#endif /* G3D_DEPTH_ESTIMATORS_H */
