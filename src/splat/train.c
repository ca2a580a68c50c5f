/* train.c - the 3DGS optimisation loop over a set of posed views. */
#include "gen3d/train.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gen3d/ckpt.h"
#include "gen3d/loss.h"
#include "gen3d/raster.h"
#include "gen3d/resize.h"

void g3d_train_params_default(g3d_train_params *p, int64_t iterations)
{
    memset(p, 0, sizeof *p);
    p->iterations = iterations;
    p->seed = 42;
    p->lambda_ssim = G3D_LOSS_LAMBDA_SSIM;
    p->sh_degree_interval = 1000;
    p->densify = 1;
    p->visible_adam = 0;
    p->coarse_factor = 2;
    p->report_every = 50;
    g3d_adam_params_default(&p->adam);
    p->adam.means_lr_steps = iterations;
    g3d_densify_params_default(&p->dens, iterations);
}

double g3d_train_scene_extent(const g3d_train_view *views, int nviews)
{
    g3d_vec3 c = g3d_v3(0, 0, 0);
    for (int i = 0; i < nviews; i++)
        c = g3d_v3_add(c, g3d_mat4_translation(views[i].cam.c2w));
    c = g3d_v3_scale(c, 1.0 / (nviews > 0 ? nviews : 1));
    double r = 0;
    for (int i = 0; i < nviews; i++) {
        double d = g3d_v3_norm(g3d_v3_sub(g3d_mat4_translation(views[i].cam.c2w), c));
        if (d > r) r = d;
    }
    return 1.1 * (r > 0 ? r : 1.0);
}

static void zero_grads(g3d_gaussians *gr, int64_t n)
{
    size_t K3 = 3 * (size_t)G3D_SH_COEFFS(gr->sh_degree);
    memset(gr->means, 0, (size_t)n * 3 * sizeof(float));
    memset(gr->log_scales, 0, (size_t)n * 3 * sizeof(float));
    memset(gr->rots, 0, (size_t)n * 4 * sizeof(float));
    memset(gr->opacity_logits, 0, (size_t)n * sizeof(float));
    memset(gr->sh, 0, (size_t)n * K3 * sizeof(float));
    gr->n = n;
}

/* The views downscaled by f (area filter for the images and masks; a mask pixel stays valid
 * where most of what it covers was): the coarse part of the schedule trains on these. */
static g3d_status coarse_views(const g3d_train_view *views, int n, int f, g3d_train_view **out, g3d_image **imgs)
{
    g3d_train_view *v = g3d_calloc((size_t)n, sizeof *v, "coarse views");
    g3d_image *im = g3d_calloc(2 * (size_t)n, sizeof *im, "coarse images");
    g3d_status rc = v && im ? G3D_OK : G3D_ERR_NOMEM;
    for (int i = 0; rc == G3D_OK && i < n; i++) {
        int w = (views[i].cam.K.width + f / 2) / f, h = (views[i].cam.K.height + f / 2) / f;
        w = w > 0 ? w : 1;
        h = h > 0 ? h : 1;
        v[i].cam.c2w = views[i].cam.c2w;
        v[i].cam.K = g3d_intrinsics_resize(views[i].cam.K, w, h);
        rc = g3d_image_resize(views[i].image, w, h, G3D_RESIZE_AREA, &im[2 * i]);
        v[i].image = &im[2 * i];
        if (rc == G3D_OK && views[i].mask) {
            rc = g3d_image_resize(views[i].mask, w, h, G3D_RESIZE_AREA, &im[2 * i + 1]);
            v[i].mask = &im[2 * i + 1];
        }
    }
    if (rc != G3D_OK) {
        for (int i = 0; im && i < 2 * n; i++) g3d_image_free(&im[i]);
        free(im);
        free(v);
        v = NULL;
        im = NULL;
    }
    *out = v;
    *imgs = im;
    return rc;
}

/* The coverage term: weight x the mean of (1 - alpha) over the view's trained pixels (mask > 0.5,
 * as the photometric loss); its gradient with respect to alpha goes into dalpha. */
static double coverage_term(const g3d_train_view *v, const float *alpha, double weight, float *dalpha)
{
    size_t n = (size_t)v->cam.K.width * v->cam.K.height, valid = 0;
    double open = 0;
    for (size_t k = 0; k < n; k++)
        if (!v->mask || v->mask->data[k] > 0.5f) {
            valid++;
            open += 1.0 - alpha[k];
        }
    float d = valid ? (float)(-weight / (double)valid) : 0.0f;
    for (size_t k = 0; k < n; k++) dalpha[k] = !v->mask || v->mask->data[k] > 0.5f ? d : 0.0f;
    return valid ? weight * open / (double)valid : 0.0;
}

/* Everything the loop carries from one iteration to the next: saving it and loading it back
 * continues a run exactly as if it had not stopped. */
typedef struct train_state {
    int64_t it;              /* iterations done */
    g3d_adam adam;
    g3d_densify_stats st;
    g3d_rng rng;
    int32_t *order;          /* (nviews) this epoch's view permutation */
    int remaining;           /* views of `order` not yet used */
    double sum_loss, sum_psnr;
    int64_t nsum;
} train_state;

#define CKPT_FORMAT "gen3d-train-checkpoint"

/* The five arrays of a model (or of its Adam moments) as named 2-D tensors. */
static int model_arrays(const g3d_gaussians *g, const char *prefix, g3d_tensor_out *t, char names[5][48])
{
    const char *nm[5] = {"means", "log_scales", "rots", "opacity_logits", "sh"};
    float *ptr[5] = {g->means, g->log_scales, g->rots, g->opacity_logits, g->sh};
    int64_t width[5] = {3, 3, 4, 1, 3 * (int64_t)G3D_SH_COEFFS(g->sh_degree)};
    for (int k = 0; k < 5; k++) {
        snprintf(names[k], 48, "%s.%s", prefix, nm[k]);
        t[k] = (g3d_tensor_out){names[k], G3D_DT_F32, 2, {g->n, width[k]}, ptr[k]};
    }
    return 5;
}

static void meta_i64(cJSON *m, const char *key, int64_t v)
{
    char b[32];
    snprintf(b, sizeof b, "%" PRId64, v);
    cJSON_AddStringToObject(m, key, b);
}

static void meta_u64(cJSON *m, const char *key, uint64_t v)
{
    char b[32];
    snprintf(b, sizeof b, "%" PRIu64, v);
    cJSON_AddStringToObject(m, key, b);
}

static void meta_f64(cJSON *m, const char *key, double v)
{
    char b[40];
    snprintf(b, sizeof b, "%.17g", v);
    cJSON_AddStringToObject(m, key, b);
}

static g3d_status save_checkpoint(const char *path, const g3d_gaussians *g, const train_state *s, int nviews,
                                  const g3d_train_params *p)
{
    g3d_tensor_out t[19];
    char names[3][5][48];
    int n = 0;
    n += model_arrays(g, "model", t + n, names[0]);
    n += model_arrays(&s->adam.m, "adam.m", t + n, names[1]);
    n += model_arrays(&s->adam.v, "adam.v", t + n, names[2]);
    t[n++] = (g3d_tensor_out){"densify.grad_accum", G3D_DT_F32, 1, {g->n}, s->st.grad_accum};
    t[n++] = (g3d_tensor_out){"densify.count", G3D_DT_I32, 1, {g->n}, s->st.count};
    t[n++] = (g3d_tensor_out){"densify.max_radius", G3D_DT_F32, 1, {g->n}, s->st.max_radius};
    t[n++] = (g3d_tensor_out){"view_order", G3D_DT_I32, 1, {nviews}, s->order};
    cJSON *m = cJSON_CreateObject();
    if (!m) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    cJSON_AddStringToObject(m, "format", CKPT_FORMAT);
    meta_i64(m, "iteration", s->it);
    meta_i64(m, "iterations", p->iterations);
    meta_i64(m, "views", nviews);
    meta_i64(m, "sh_degree", g->sh_degree);
    meta_u64(m, "seed", p->seed);
    meta_u64(m, "rng_state", s->rng.state);
    meta_u64(m, "rng_inc", s->rng.inc);
    meta_i64(m, "remaining", s->remaining);
    meta_i64(m, "adam_step", s->adam.step);
    meta_f64(m, "sum_loss", s->sum_loss);
    meta_f64(m, "sum_psnr", s->sum_psnr);
    meta_i64(m, "nsum", s->nsum);
    g3d_status rc = g3d_safetensors_write(path, t, n, m);
    cJSON_Delete(m);
    return rc;
}

static int meta_get(const cJSON *m, const char *key, int is_unsigned, void *out)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(m, key);
    if (!cJSON_IsString(v) || !v->valuestring[0]) return 0;
    char *end;
    errno = 0;
    if (is_unsigned) *(uint64_t *)out = strtoull(v->valuestring, &end, 10);
    else *(int64_t *)out = strtoll(v->valuestring, &end, 10);
    return errno == 0 && *end == 0;
}

static int meta_get_f64(const cJSON *m, const char *key, double *out)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(m, key);
    if (!cJSON_IsString(v)) return 0;
    char *end;
    *out = strtod(v->valuestring, &end);
    return end != v->valuestring && *end == 0 && isfinite(*out);
}

static g3d_status read_model(const g3d_ckpt *ck, const char *prefix, g3d_gaussians *g)
{
    g3d_tensor_out t[5];
    char names[5][48];
    model_arrays(g, prefix, t, names);
    for (int k = 0; k < 5; k++) {
        g3d_status rc = g3d_ckpt_read(ck, t[k].name, 2, t[k].shape, (float *)t[k].data);
        if (rc != G3D_OK) return rc;
    }
    return G3D_OK;
}

static g3d_status read_i32(const g3d_ckpt *ck, const char *name, int64_t n, int32_t *dst)
{
    const g3d_tensor_info *ti = g3d_ckpt_find(ck, name);
    if (!ti || ti->dtype != G3D_DT_I32 || ti->ndim != 1 || ti->shape[0] != n)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: tensor '%s' is missing or is not I32 [%" PRId64 "]", g3d_ckpt_path(ck), name, n);
    memcpy(dst, ti->data, (size_t)n * sizeof *dst);
    return G3D_OK;
}

/* Loads a checkpoint written by save_checkpoint into a fresh model and state. */
static g3d_status load_checkpoint(const char *path, int nviews, const g3d_train_params *p, g3d_gaussians *g,
                                  train_state *s)
{
    g3d_ckpt *ck;
    g3d_status rc = g3d_ckpt_open(path, &ck);
    if (rc != G3D_OK) return rc;
    const cJSON *m = g3d_ckpt_meta(ck);
    const cJSON *fmt = cJSON_GetObjectItemCaseSensitive(m, "format");
    int64_t it = 0, iters = 0, views = 0, deg = 0, remaining = 0, step = 0, nsum = 0;
    uint64_t seed = 0, state = 0, inc = 0;
    double sl = 0, sp = 0;
    const g3d_tensor_info *means = g3d_ckpt_find(ck, "model.means");
    if (!cJSON_IsString(fmt) || strcmp(fmt->valuestring, CKPT_FORMAT) != 0 || !means || means->ndim != 2) {
        rc = G3D_ERR(G3D_ERR_FORMAT, "%s: not a gen3d training checkpoint", path);
    } else if (!meta_get(m, "iteration", 0, &it) || !meta_get(m, "iterations", 0, &iters) ||
               !meta_get(m, "views", 0, &views) || !meta_get(m, "sh_degree", 0, &deg) ||
               !meta_get(m, "seed", 1, &seed) || !meta_get(m, "rng_state", 1, &state) ||
               !meta_get(m, "rng_inc", 1, &inc) || !meta_get(m, "remaining", 0, &remaining) ||
               !meta_get(m, "adam_step", 0, &step) || !meta_get(m, "nsum", 0, &nsum) ||
               !meta_get_f64(m, "sum_loss", &sl) || !meta_get_f64(m, "sum_psnr", &sp) ||
               deg < 0 || deg > G3D_SH_MAX_DEGREE || remaining < 0 || remaining > views || it < 0) {
        rc = G3D_ERR(G3D_ERR_FORMAT, "%s: checkpoint metadata is incomplete or out of range", path);
    } else if (views != nviews) {
        rc = G3D_ERR(G3D_ERR_MISMATCH, "%s: the checkpoint was trained on %" PRId64 " views, the dataset has %d", path, views, nviews);
    } else if (seed != p->seed) {
        rc = G3D_ERR(G3D_ERR_MISMATCH, "%s: the checkpoint used seed %" PRIu64 ", not %" PRIu64, path, seed, p->seed);
    } else if (it >= p->iterations) {
        rc = G3D_ERR(G3D_ERR_ARG, "%s: the checkpoint is at iteration %" PRId64 ", nothing left of %" PRId64, path, it, p->iterations);
    }
    int64_t n = rc == G3D_OK ? means->shape[0] : 0;
    if (rc == G3D_OK) rc = g3d_gaussians_create(g, n > 0 ? n : 1, (int)deg);
    if (rc == G3D_OK) rc = g3d_adam_init(&s->adam, &p->adam, g);
    if (rc == G3D_OK) rc = g3d_densify_stats_init(&s->st, g->capacity);
    s->order = rc == G3D_OK ? g3d_calloc((size_t)nviews, sizeof(int32_t), "view order") : NULL;
    if (rc == G3D_OK && !s->order) rc = G3D_ERR_NOMEM;
    if (rc == G3D_OK) {
        g->n = s->adam.m.n = s->adam.v.n = n;
        rc = read_model(ck, "model", g);
        if (rc == G3D_OK) rc = read_model(ck, "adam.m", &s->adam.m);
        if (rc == G3D_OK) rc = read_model(ck, "adam.v", &s->adam.v);
        if (rc == G3D_OK) rc = g3d_ckpt_read(ck, "densify.grad_accum", 1, &n, s->st.grad_accum);
        if (rc == G3D_OK) rc = g3d_ckpt_read(ck, "densify.max_radius", 1, &n, s->st.max_radius);
        if (rc == G3D_OK) rc = read_i32(ck, "densify.count", n, s->st.count);
        if (rc == G3D_OK) rc = read_i32(ck, "view_order", nviews, s->order);
        for (int i = 0; rc == G3D_OK && i < nviews; i++)
            if (s->order[i] < 0 || s->order[i] >= nviews)
                rc = G3D_ERR(G3D_ERR_FORMAT, "%s: view_order holds %d, outside 0..%d", path, (int)s->order[i], nviews - 1);
        if (rc == G3D_OK) rc = g3d_gaussians_validate(g, path);
    }
    if (rc == G3D_OK) {
        s->it = it;
        s->adam.step = step;
        s->rng.state = state;
        s->rng.inc = inc;
        s->remaining = (int)remaining;
        s->sum_loss = sl;
        s->sum_psnr = sp;
        s->nsum = nsum;
    }
    g3d_ckpt_free(ck);
    return rc;
}

g3d_status g3d_train(g3d_gaussians *g, const g3d_train_view *views, int nviews,
                     const g3d_train_params *p, g3d_train_result *res)
{
    if (nviews < 1) return G3D_ERR(G3D_ERR_ARG, "train: no views");
    if (p->iterations < 1) return G3D_ERR(G3D_ERR_ARG, "train: %lld iterations", (long long)p->iterations);
    int maxw = 0, maxh = 0;
    for (int i = 0; i < nviews; i++) {
        const g3d_train_view *v = &views[i];
        if (!v->image || v->image->c != 3 || v->image->w != v->cam.K.width || v->image->h != v->cam.K.height)
            return G3D_ERR(G3D_ERR_MISMATCH, "train: view %d: image %dx%dx%d does not match its %dx%d camera (RGB expected)",
                           i, v->image ? v->image->w : 0, v->image ? v->image->h : 0,
                           v->image ? v->image->c : 0, v->cam.K.width, v->cam.K.height);
        if (v->mask && (v->mask->w != v->image->w || v->mask->h != v->image->h || v->mask->c != 1))
            return G3D_ERR(G3D_ERR_MISMATCH, "train: view %d: mask %dx%dx%d vs image %dx%d",
                           i, v->mask->w, v->mask->h, v->mask->c, v->image->w, v->image->h);
        if (v->cam.K.width > maxw) maxw = v->cam.K.width;
        if (v->cam.K.height > maxh) maxh = v->cam.K.height;
    }
    const double extent = p->extent > 0 ? p->extent : g3d_train_scene_extent(views, nviews);
    const double t0 = g3d_time_now();
    size_t npx = (size_t)maxw * maxh;

    train_state s = {0};
    g3d_train_view *coarse = NULL;
    g3d_image *coarse_img = NULL;
    g3d_raster_ws *ws = NULL;
    g3d_gaussians grads = {0};
    float *rgb = NULL, *drgb = NULL, *grad2d = NULL, *alpha = NULL, *dalpha = NULL;
    int32_t *radii = NULL;
    g3d_status rc;
    if (p->resume_path) {
        g3d_gaussians loaded = {0};
        rc = load_checkpoint(p->resume_path, nviews, p, &loaded, &s);
        if (rc == G3D_OK) {
            g3d_gaussians_free(g);
            *g = loaded;
        } else {
            g3d_gaussians_free(&loaded);
        }
    } else {
        g3d_rng_seed(&s.rng, p->seed, 7);
        rc = g3d_adam_init(&s.adam, &p->adam, g);
        if (rc == G3D_OK) rc = g3d_densify_stats_init(&s.st, g->capacity);
        s.order = rc == G3D_OK ? g3d_calloc((size_t)nviews, sizeof(int32_t), "view order") : NULL;
        if (rc == G3D_OK && !s.order) rc = G3D_ERR_NOMEM;
    }
    const int coarse_on = p->coarse_until > s.it && p->coarse_factor > 1;
    if (rc == G3D_OK && coarse_on) rc = coarse_views(views, nviews, p->coarse_factor, &coarse, &coarse_img);
    if (rc == G3D_OK) rc = g3d_raster_ws_create(&ws);
    if (rc == G3D_OK) rc = g3d_gaussians_create(&grads, g->capacity, g->sh_degree);
    if (rc == G3D_OK) {
        rgb = g3d_calloc(npx, 3 * sizeof(float), "render buffer");
        drgb = g3d_calloc(npx, 3 * sizeof(float), "render gradient");
        if (!rgb || !drgb) rc = G3D_ERR_NOMEM;
    }
    if (rc == G3D_OK && p->coverage_weight > 0) {
        alpha = g3d_calloc(npx, sizeof(float), "opacity buffer");
        dalpha = g3d_calloc(npx, sizeof(float), "opacity gradient");
        if (!alpha || !dalpha) rc = G3D_ERR_NOMEM;
    }
    g3d_raster_params rs;
    g3d_raster_params_default(&rs);
    memcpy(rs.bg, p->bg, sizeof rs.bg);
    int64_t radii_cap = 0;

    for (int64_t it = s.it + 1; rc == G3D_OK && it <= p->iterations; it++) {
        if (g->capacity > radii_cap) {
            free(radii);
            free(grad2d);
            radii = g3d_calloc((size_t)g->capacity, sizeof(int32_t), "radii");
            grad2d = g3d_calloc((size_t)g->capacity, sizeof(float), "2D gradients");
            radii_cap = g->capacity;
            if (!radii || !grad2d) { rc = G3D_ERR_NOMEM; break; }
        }
        if (grads.capacity < g->capacity) {
            g3d_gaussians_free(&grads);
            if ((rc = g3d_gaussians_create(&grads, g->capacity, g->sh_degree)) != G3D_OK) break;
        }
        /* the first view on its own beat, outside the permutation (so the epochs stay whole) */
        const int first = p->first_view_every > 0 && it % p->first_view_every == 0;
        if (!first && s.remaining == 0) { /* a fresh seeded permutation every epoch */
            for (int i = 0; i < nviews; i++) s.order[i] = i;
            for (int i = nviews - 1; i > 0; i--) {
                int j = (int)g3d_rng_below(&s.rng, (uint32_t)i + 1);
                int32_t t = s.order[i]; s.order[i] = s.order[j]; s.order[j] = t;
            }
            s.remaining = nviews;
        }
        const int vi = first ? 0 : s.order[--s.remaining];
        const g3d_train_view *v = coarse_on && it <= p->coarse_until ? &coarse[vi] : &views[vi];
        rs.sh_degree_active = (int)((it - 1) / (p->sh_degree_interval > 0 ? p->sh_degree_interval : 1));
        if (rs.sh_degree_active > g->sh_degree) rs.sh_degree_active = g->sh_degree;

        if ((rc = g3d_raster_fwd(ws, g, &v->cam, &rs, rgb, alpha, NULL, radii)) != G3D_OK) break;
        g3d_image pred = {v->cam.K.width, v->cam.K.height, 3, rgb};
        g3d_image dimg = {v->cam.K.width, v->cam.K.height, 3, drgb};
        double loss, psnr;
        if ((rc = g3d_loss_fwd_bwd(&pred, v->image, v->mask, p->lambda_ssim, &loss, NULL, &dimg)) != G3D_OK) break;
        if ((rc = g3d_psnr(&pred, v->image, v->mask, &psnr)) != G3D_OK) break;
        if (alpha) loss += coverage_term(v, alpha, p->coverage_weight, dalpha);
        zero_grads(&grads, g->n);
        memset(grad2d, 0, (size_t)g->n * sizeof(float));
        if ((rc = g3d_raster_bwd(ws, g, drgb, dalpha, NULL, &grads, grad2d)) != G3D_OK) break;
        const int dens_on = p->densify && it < p->dens.until;
        if (dens_on) g3d_densify_accumulate(&s.st, grad2d, radii, g->n);
        if ((rc = g3d_adam_step_visible(&s.adam, g, &grads, extent, p->visible_adam ? radii : NULL)) != G3D_OK) break;
        if (dens_on) {
            if (it > p->dens.from && it % p->dens.interval == 0) {
                int large = p->dens.opacity_reset_interval > 0 && it > p->dens.opacity_reset_interval;
                if ((rc = g3d_densify_step(g, &s.adam, &s.st, &p->dens, extent, large, &s.rng, NULL)) != G3D_OK) break;
            }
            if (p->dens.opacity_reset_interval > 0 && it % p->dens.opacity_reset_interval == 0)
                g3d_densify_reset_opacity(g, &s.adam);
        }
        s.sum_loss += loss;
        s.sum_psnr += isfinite(psnr) ? psnr : 100.0;
        s.nsum++;
        s.it = it;
        int64_t every = p->report_every > 0 ? p->report_every : 50;
        if (it % every == 0 || it == p->iterations) {
            char info[128];
            snprintf(info, sizeof info, "loss %.4f psnr %.2f dB n %lld", s.sum_loss / s.nsum,
                     s.sum_psnr / s.nsum, (long long)g->n);
            if (res) {
                res->last_loss = s.sum_loss / s.nsum;
                res->last_psnr = s.sum_psnr / s.nsum;
            }
            s.sum_loss = s.sum_psnr = 0;
            s.nsum = 0;
            if (g3d_progress_report(&p->progress, "train", it, p->iterations, info))
                rc = G3D_ERR(G3D_CANCELLED, "training cancelled");
        }
        if (p->checkpoint_path && p->checkpoint_every > 0 && it % p->checkpoint_every == 0 && it < p->iterations) {
            g3d_status crc = save_checkpoint(p->checkpoint_path, g, &s, nviews, p);
            if (crc != G3D_OK) rc = crc;
        }
    }
    if (res) res->seconds = g3d_time_now() - t0;
    g3d_raster_ws_free(ws);
    g3d_adam_free(&s.adam);
    g3d_densify_stats_free(&s.st);
    g3d_gaussians_free(&grads);
    free(rgb); free(drgb); free(grad2d); free(radii); free(s.order); free(alpha); free(dalpha);
    for (int i = 0; coarse_img && i < 2 * nviews; i++) g3d_image_free(&coarse_img[i]);
    free(coarse_img);
    free(coarse);
    return rc;
}
