/* Depth estimator tables on the depth networks (gen3d/depth_estimators.h). */
#include "gen3d/depth_estimators.h"

#include "gen3d/depthfit.h"
#include "gen3d/recognize.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct dav2_ctx {
    g3d_dav2 *model;
    int input_size;
} dav2_ctx;

static void dav2_free(void *ctx)
{
    dav2_ctx *c = ctx;
    if (!c) return;
    g3d_dav2_free(c->model);
    free(c);
}

static g3d_status dav2_estimate(void *ctx, const g3d_image *rgb, const g3d_image *known, const g3d_image *mask,
                                g3d_image *depth_out, g3d_intrinsics *K_io)
{
    const dav2_ctx *c = ctx;
    (void)mask;   /* the network predicts every pixel anyway */
    (void)K_io;
    if (!rgb || rgb->c != 3 || !rgb->data)
        return G3D_ERR(G3D_ERR_ARG, "depth-anything: the image must have 3 channels (got %d)", rgb ? rgb->c : 0);
    if (g3d_dav2_max_depth(c->model) > 0) { /* metric: metres already; the world loop aligns */
        g3d_image pred = {0};
        G3D_TRY(g3d_image_create(&pred, rgb->w, rgb->h, 1));
        g3d_status rc = g3d_dav2_predict(c->model, rgb->data, rgb->w, rgb->h, c->input_size, pred.data, NULL);
        if (rc != G3D_OK) {
            g3d_image_free(&pred);
            return rc;
        }
        *depth_out = pred;
        return G3D_OK;
    }
    if (!known || !known->data)
        return G3D_ERR(G3D_ERR_ARG, "depth-anything: relative depth needs known depth to align to metres "
                       "(a metric checkpoint does not)");
    if (known->c != 1 || known->w != rgb->w || known->h != rgb->h)
        return G3D_ERR(G3D_ERR_MISMATCH, "depth-anything: known depth is %dx%dx%d, image %dx%d", known->w,
                       known->h, known->c, rgb->w, rgb->h);
    g3d_image pred = {0};
    G3D_TRY(g3d_image_create(&pred, rgb->w, rgb->h, 1));
    size_t n = (size_t)rgb->w * rgb->h;
    double s = 0, t = 0;
    g3d_status rc = g3d_dav2_predict(c->model, rgb->data, rgb->w, rgb->h, c->input_size, pred.data, NULL);
    if (rc == G3D_OK) rc = g3d_depthfit_affine(pred.data, known->data, n, G3D_FIT_INVERSE, &s, &t);
    if (rc != G3D_OK) {
        g3d_image_free(&pred);
        return rc;
    }
    g3d_depthfit_apply(pred.data, n, G3D_FIT_INVERSE, s, t, pred.data);
    *depth_out = pred;
    return G3D_OK;
}

g3d_status g3d_depth_estimator_dav2_create(g3d_dav2 *model, int input_size, g3d_depth_estimator *out)
{
    if (input_size < 14) {
        g3d_dav2_free(model);
        return G3D_ERR(G3D_ERR_ARG, "depth-anything: input size %d is below one 14-pixel patch", input_size);
    }
    dav2_ctx *c = malloc(sizeof *c);
    if (!c) {
        g3d_dav2_free(model);
        return G3D_ERR(G3D_ERR_NOMEM, "depth-anything: out of memory");
    }
    c->model = model;
    c->input_size = input_size;
    out->name = "depth-anything-v2";
    out->ctx = c;
    out->estimate = dav2_estimate;
    out->free = dav2_free;
    return G3D_OK;
}

typedef struct moge_ctx {
    g3d_moge *model;
    int num_tokens;
} moge_ctx;

static void moge_free(void *ctx)
{
    moge_ctx *c = ctx;
    if (!c) return;
    g3d_moge_free(c->model);
    free(c);
}

static g3d_status moge_estimate(void *ctx, const g3d_image *rgb, const g3d_image *known, const g3d_image *mask,
                                g3d_image *depth_out, g3d_intrinsics *K_io)
{
    const moge_ctx *c = ctx;
    (void)known;  /* metric already; the caller aligns if it wants to */
    (void)mask;
    if (!rgb || rgb->c != 3 || !rgb->data)
        return G3D_ERR(G3D_ERR_ARG, "moge: the image must have 3 channels (got %d)", rgb ? rgb->c : 0);
    int known_camera = K_io && K_io->fx > 0;
    double fov_x = known_camera ? 2.0 * atan(0.5 * rgb->w / K_io->fx) * 180.0 / M_PI : 0;
    g3d_moge_result r;
    G3D_TRY(g3d_moge_infer(c->model, rgb->data, rgb->w, rgb->h, c->num_tokens, fov_x, &r));
    g3d_image d = {0};
    g3d_status rc = g3d_image_create(&d, rgb->w, rgb->h, 1);
    if (rc == G3D_OK) {
        for (size_t i = 0; i < (size_t)rgb->w * rgb->h; i++) d.data[i] = isfinite(r.depth[i]) ? r.depth[i] : 0.0f;
        if (K_io && !known_camera) *K_io = g3d_moge_intrinsics_pixels(&r);
        *depth_out = d;
    }
    g3d_moge_result_free(&r);
    return rc;
}

g3d_status g3d_depth_estimator_moge_create(g3d_moge *model, int num_tokens, g3d_depth_estimator *out)
{
    if (!g3d_moge_has_scale(model)) {
        g3d_moge_free(model);
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "moge: this checkpoint has no metric scale head, so it cannot give metres");
    }
    moge_ctx *c = malloc(sizeof *c);
    if (!c) {
        g3d_moge_free(model);
        return G3D_ERR(G3D_ERR_NOMEM, "moge: out of memory");
    }
    c->model = model;
    c->num_tokens = num_tokens;
    out->name = "moge-2";
    out->ctx = c;
    out->estimate = moge_estimate;
    out->free = moge_free;
    return G3D_OK;
}

void g3d_depth_model_params_default(g3d_depth_model_params *p)
{
    p->input_size = 518;
    p->num_tokens = 0;
    p->max_depth = -1;
}

g3d_status g3d_depth_estimator_model_create(const char *path, const g3d_depth_model_params *p, g3d_depth_estimator *out,
                                            int *metric)
{
    g3d_depth_model_params def;
    g3d_depth_model_params_default(&def);
    if (!p) p = &def;
    g3d_ckpt *ck;
    memset(out, 0, sizeof *out);
    G3D_TRY(g3d_ckpt_open(path, &ck));
    g3d_status rc;
    int is_metric = 1;
    if (g3d_model_recognize(ck) == G3D_MODEL_MOGE) {
        g3d_moge *m = NULL;
        rc = g3d_moge_load(ck, &m);
        if (rc == G3D_OK) rc = g3d_depth_estimator_moge_create(m, p->num_tokens, out);
    } else {
        g3d_dav2 *m = NULL;
        rc = g3d_dav2_load(ck, &m);
        if (rc == G3D_OK) {
            double md = p->max_depth < 0 ? g3d_dav2_metric_default(path) : p->max_depth;
            g3d_dav2_set_metric(m, (float)md);
            is_metric = md > 0;
            rc = g3d_depth_estimator_dav2_create(m, p->input_size, out);
        }
    }
    g3d_ckpt_free(ck);
    if (rc != G3D_OK) memset(out, 0, sizeof *out);
    else if (metric) *metric = is_metric;
    return rc;
}
