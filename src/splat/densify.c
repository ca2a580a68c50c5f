/* Adaptive density control: clone, split, prune, opacity reset. */
#include "gen3d/densify.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

g3d_densify_params g3d_densify_params_default(void)
{
    g3d_densify_params p = {0.0002f, 0.01f, 0.005f, 20.0f, 0.1f, 2};
    return p;
}

g3d_status g3d_densify_stats_init(g3d_densify_stats *s, int64_t n)
{
    memset(s, 0, sizeof *s);
    s->grad_sum = g3d_calloc((size_t)(n ? n : 1), sizeof(double), "densify stats");
    s->count = g3d_calloc((size_t)(n ? n : 1), sizeof(int32_t), "densify stats");
    s->max_radius = g3d_calloc((size_t)(n ? n : 1), sizeof(float), "densify stats");
    if (!s->grad_sum || !s->count || !s->max_radius) { g3d_densify_stats_free(s); return G3D_ERR_NOMEM; }
    s->capacity = n;
    return G3D_OK;
}

void g3d_densify_stats_free(g3d_densify_stats *s)
{
    if (!s) return;
    free(s->grad_sum);
    free(s->count);
    free(s->max_radius);
    memset(s, 0, sizeof *s);
}

g3d_status g3d_densify_accumulate(g3d_densify_stats *s, int64_t n, const float *grad_norm, const float *radius)
{
    if (n > s->capacity) return G3D_ERR(G3D_ERR_MISMATCH, "densify: statistics for %lld Gaussians, got %lld", (long long)s->capacity, (long long)n);
    for (int64_t i = 0; i < n; i++) {
        if (!(radius[i] > 0)) continue;
        s->grad_sum[i] += grad_norm[i];
        s->count[i]++;
        if (radius[i] > s->max_radius[i]) s->max_radius[i] = radius[i];
    }
    return G3D_OK;
}

static double sigmoid(double x) { return 1.0 / (1.0 + exp(-x)); }

static float max_scale(const g3d_gaussians *g, int64_t i)
{
    const float *s = g->log_scales + 3 * i;
    return expf(fmaxf(s[0], fmaxf(s[1], s[2])));
}

g3d_status g3d_densify(g3d_gaussians *g, g3d_adam *opt, g3d_densify_stats *s, double extent, int prune_big,
                       const g3d_densify_params *p, g3d_rng *rng, g3d_densify_report *report)
{
    g3d_densify_params def = g3d_densify_params_default();
    if (!p) p = &def;
    memset(report, 0, sizeof *report);
    int64_t n0 = g->n;
    if (s->capacity < n0) return G3D_ERR(G3D_ERR_MISMATCH, "densify: statistics cover fewer Gaussians than the model");
    if (p->split_n < 2) return G3D_ERR(G3D_ERR_ARG, "densify: split_n must be at least 2");
    /* Count the new Gaussians first so that the model grows once. */
    int64_t add = 0;
    for (int64_t i = 0; i < n0; i++) {
        double gm = s->count[i] ? s->grad_sum[i] / s->count[i] : 0;
        if (gm >= p->grad_threshold) add += max_scale(g, i) <= p->percent_dense * extent ? 1 : p->split_n;
    }
    G3D_TRY(g3d_gaussians_reserve(g, n0 + add));
    uint8_t *keep = malloc((size_t)(n0 + add + 1));
    if (!keep) return G3D_ERR(G3D_ERR_NOMEM, "densify: out of memory");
    memset(keep, 1, (size_t)(n0 + add + 1));
    int64_t k = n0;
    for (int64_t i = 0; i < n0; i++) {
        double gm = s->count[i] ? s->grad_sum[i] / s->count[i] : 0;
        if (gm < p->grad_threshold) continue;
        if (max_scale(g, i) <= p->percent_dense * extent) {
            g3d_gaussians_copy_one(g, k++, g, i);
            report->cloned++;
            continue;
        }
        /* Split: samples from N(0, diag(scale^2)) rotated into the world, scales shrunk. */
        const float *q = g->rots + 4 * i;
        double qw = q[0], qx = q[1], qy = q[2], qz = q[3], qn = sqrt(qw * qw + qx * qx + qy * qy + qz * qz);
        if (qn > 0) { qw /= qn; qx /= qn; qy /= qn; qz /= qn; } else qw = 1;
        double Rm[3][3] = {{1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)},
                           {2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)},
                           {2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)}};
        for (int j = 0; j < p->split_n; j++, k++) {
            g3d_gaussians_copy_one(g, k, g, i);
            double z[3];
            for (int a = 0; a < 3; a++) z[a] = g3d_rng_normal(rng) * exp(g->log_scales[3 * i + a]);
            for (int a = 0; a < 3; a++) g->means[3 * k + a] += (float)(Rm[a][0] * z[0] + Rm[a][1] * z[1] + Rm[a][2] * z[2]);
            for (int a = 0; a < 3; a++) g->log_scales[3 * k + a] = (float)(g->log_scales[3 * i + a] - log(0.8 * p->split_n));
        }
        keep[i] = 0;
        report->split++;
    }
    g->n = k;
    if (opt) G3D_TRY(g3d_adam_grow(opt, g));
    /* Prune, over the old and the new Gaussians alike. */
    for (int64_t i = 0; i < g->n; i++) {
        if (!keep[i]) continue;
        int drop = sigmoid(g->opacity_logits[i]) < p->min_opacity;
        if (prune_big && i < n0) drop |= s->max_radius[i] > p->max_screen_px;
        if (prune_big) drop |= max_scale(g, i) > p->max_world_fraction * extent;
        if (drop) { keep[i] = 0; report->pruned++; }
    }
    g3d_gaussians_compact(g, keep);
    if (opt) g3d_adam_compact(opt, keep);
    free(keep);
    g3d_densify_stats_free(s);
    return g3d_densify_stats_init(s, g->capacity);
}

void g3d_opacity_reset(g3d_gaussians *g, g3d_adam *opt, float value)
{
    float cap = logf(value / (1.0f - value));
    for (int64_t i = 0; i < g->n; i++)
        if (g->opacity_logits[i] > cap) g->opacity_logits[i] = cap;
    if (opt)
        for (int64_t i = 0; i < opt->m.n; i++) opt->m.opacity_logits[i] = opt->v.opacity_logits[i] = 0;
}
