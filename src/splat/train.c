/* train.c - the 3DGS optimisation loop over a set of posed views. */
#include "gen3d/train.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "gen3d/loss.h"
#include "gen3d/raster.h"

void g3d_train_params_default(g3d_train_params *p, int64_t iterations)
{
    memset(p, 0, sizeof *p);
    p->iterations = iterations;
    p->seed = 42;
    p->lambda_ssim = G3D_LOSS_LAMBDA_SSIM;
    p->sh_degree_interval = 1000;
    p->densify = 1;
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

    g3d_raster_ws *ws = NULL;
    g3d_adam adam = {0};
    g3d_densify_stats st = {0};
    g3d_gaussians grads = {0};
    float *rgb = NULL, *drgb = NULL, *grad2d = NULL;
    int32_t *radii = NULL, *order = NULL;
    g3d_status rc = g3d_raster_ws_create(&ws);
    if (rc == G3D_OK) rc = g3d_adam_init(&adam, &p->adam, g);
    if (rc == G3D_OK) rc = g3d_densify_stats_init(&st, g->capacity);
    if (rc == G3D_OK) rc = g3d_gaussians_create(&grads, g->capacity, g->sh_degree);
    if (rc == G3D_OK) {
        rgb = g3d_calloc(npx, 3 * sizeof(float), "render buffer");
        drgb = g3d_calloc(npx, 3 * sizeof(float), "render gradient");
        order = g3d_calloc((size_t)nviews, sizeof(int32_t), "view order");
        if (!rgb || !drgb || !order) rc = G3D_ERR_NOMEM;
    }
    g3d_rng rng;
    g3d_rng_seed(&rng, p->seed, 7);
    g3d_raster_settings rs;
    g3d_raster_settings_default(&rs);
    memcpy(rs.bg, p->bg, sizeof rs.bg);
    int remaining = 0;
    double sum_loss = 0, sum_psnr = 0;
    int64_t nsum = 0;
    int64_t radii_cap = 0;

    for (int64_t it = 1; rc == G3D_OK && it <= p->iterations; it++) {
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
        if (remaining == 0) { /* a fresh seeded permutation every epoch */
            for (int i = 0; i < nviews; i++) order[i] = i;
            for (int i = nviews - 1; i > 0; i--) {
                int j = (int)g3d_rng_below(&rng, (uint32_t)i + 1);
                int32_t t = order[i]; order[i] = order[j]; order[j] = t;
            }
            remaining = nviews;
        }
        const g3d_train_view *v = &views[order[--remaining]];
        rs.sh_degree_active = (int)((it - 1) / (p->sh_degree_interval > 0 ? p->sh_degree_interval : 1));
        if (rs.sh_degree_active > g->sh_degree) rs.sh_degree_active = g->sh_degree;

        if ((rc = g3d_raster_fwd(ws, g, &v->cam, &rs, rgb, NULL, NULL, radii)) != G3D_OK) break;
        g3d_image pred = {v->cam.K.width, v->cam.K.height, 3, rgb};
        g3d_image dimg = {v->cam.K.width, v->cam.K.height, 3, drgb};
        double loss, psnr;
        if ((rc = g3d_loss_fwd_bwd(&pred, v->image, v->mask, p->lambda_ssim, &loss, NULL, &dimg)) != G3D_OK) break;
        if ((rc = g3d_psnr(&pred, v->image, v->mask, &psnr)) != G3D_OK) break;
        zero_grads(&grads, g->n);
        memset(grad2d, 0, (size_t)g->n * sizeof(float));
        if ((rc = g3d_raster_bwd(ws, g, drgb, NULL, NULL, &grads, grad2d)) != G3D_OK) break;
        const int dens_on = p->densify && it < p->dens.until;
        if (dens_on) g3d_densify_accumulate(&st, grad2d, radii, g->n);
        if ((rc = g3d_adam_step(&adam, g, &grads, extent)) != G3D_OK) break;
        if (dens_on) {
            if (it > p->dens.from && it % p->dens.interval == 0) {
                int large = p->dens.opacity_reset_interval > 0 && it > p->dens.opacity_reset_interval;
                if ((rc = g3d_densify_step(g, &adam, &st, &p->dens, extent, large, &rng, NULL)) != G3D_OK) break;
            }
            if (p->dens.opacity_reset_interval > 0 && it % p->dens.opacity_reset_interval == 0)
                g3d_densify_reset_opacity(g, &adam);
        }
        sum_loss += loss;
        sum_psnr += isfinite(psnr) ? psnr : 100.0;
        nsum++;
        int64_t every = p->report_every > 0 ? p->report_every : 50;
        if (it % every == 0 || it == p->iterations) {
            char info[128];
            snprintf(info, sizeof info, "loss %.4f psnr %.2f dB n %lld", sum_loss / nsum,
                     sum_psnr / nsum, (long long)g->n);
            if (res) {
                res->last_loss = sum_loss / nsum;
                res->last_psnr = sum_psnr / nsum;
            }
            sum_loss = sum_psnr = 0;
            nsum = 0;
            if (g3d_progress_report(&p->progress, "train", it, p->iterations, info))
                rc = G3D_ERR(G3D_ERR_ARG, "cancelled");
        }
    }
    if (res) res->seconds = g3d_time_now() - t0;
    g3d_raster_ws_free(ws);
    g3d_adam_free(&adam);
    g3d_densify_stats_free(&st);
    g3d_gaussians_free(&grads);
    free(rgb); free(drgb); free(grad2d); free(radii); free(order);
    return rc;
}
