/* densify.c - clone / split / prune of Gaussians with the optimiser moments kept in step. */
#include "gen3d/densify.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "gen3d/camera.h"

void g3d_densify_params_default(g3d_densify_params *p, int64_t iterations)
{
    memset(p, 0, sizeof *p);
    p->interval = 100;
    p->from = iterations >= 30000 ? 500 : (iterations / 60 > 100 ? iterations / 60 : 100);
    p->until = iterations / 2;
    p->opacity_reset_interval = iterations >= 30000 ? 3000 : (iterations / 10 > 1000 ? iterations / 10 : 1000);
    p->grad_threshold = 0.0002;
    p->percent_dense = 0.01;
    p->min_opacity = 0.005;
    p->max_screen_radius = 20;
    p->max_world_scale = 0.1;
    p->max_gaussians = 0;
}

g3d_status g3d_densify_stats_init(g3d_densify_stats *st, int64_t capacity)
{
    memset(st, 0, sizeof *st);
    if (capacity < 1) capacity = 1;
    st->grad_accum = g3d_calloc((size_t)capacity, sizeof(float), "densify statistics");
    st->count = g3d_calloc((size_t)capacity, sizeof(int32_t), "densify statistics");
    st->max_radius = g3d_calloc((size_t)capacity, sizeof(float), "densify statistics");
    if (!st->grad_accum || !st->count || !st->max_radius) {
        g3d_densify_stats_free(st);
        return G3D_ERR_NOMEM;
    }
    st->capacity = capacity;
    return G3D_OK;
}

void g3d_densify_stats_free(g3d_densify_stats *st)
{
    if (!st) return;
    free(st->grad_accum);
    free(st->count);
    free(st->max_radius);
    memset(st, 0, sizeof *st);
}

void g3d_densify_accumulate(g3d_densify_stats *st, const float *grad2d, const int32_t *radii,
                            int64_t n)
{
    for (int64_t i = 0; i < n && i < st->capacity; i++) {
        if (radii[i] <= 0) continue;
        st->grad_accum[i] += grad2d[i];
        st->count[i] += 1;
        if ((float)radii[i] > st->max_radius[i]) st->max_radius[i] = (float)radii[i];
    }
}

static float max_scale(const g3d_gaussians *g, int64_t i)
{
    const float *s = g->log_scales + i * 3;
    float m = s[0] > s[1] ? s[0] : s[1];
    return expf(m > s[2] ? m : s[2]);
}

static float sigmoidf(float x) { return 1.0f / (1.0f + expf(-x)); }

/* Zeroes slot i of a moment buffer (a newly created Gaussian starts with fresh moments). */
static void zero_slot(g3d_gaussians *m, int64_t i)
{
    size_t K3 = 3 * (size_t)G3D_SH_COEFFS(m->sh_degree);
    memset(m->means + i * 3, 0, 3 * sizeof(float));
    memset(m->log_scales + i * 3, 0, 3 * sizeof(float));
    memset(m->rots + i * 4, 0, 4 * sizeof(float));
    m->opacity_logits[i] = 0;
    memset(m->sh + (size_t)i * K3, 0, K3 * sizeof(float));
}

/* Appends a copy of Gaussian j (parameters) with zero moments; capacity is reserved. */
static int64_t append_copy(g3d_gaussians *g, g3d_adam *a, int64_t j)
{
    int64_t i = g->n++;
    g3d_gaussians_copy_one(g, i, g, j);
    zero_slot(&a->m, i);
    zero_slot(&a->v, i);
    a->m.n = a->v.n = g->n;
    return i;
}

g3d_status g3d_densify_step(g3d_gaussians *g, g3d_adam *adam, g3d_densify_stats *st,
                            const g3d_densify_params *p, double extent, int prune_large,
                            g3d_rng *rng, g3d_densify_result *res)
{
    const int64_t n0 = g->n;
    if (adam->m.n != n0 || adam->v.n != n0 || st->capacity < n0)
        return G3D_ERR(G3D_ERR_MISMATCH, "densify: model has %lld Gaussians, moments %lld, statistics %lld",
                       (long long)n0, (long long)adam->m.n, (long long)st->capacity);
    const double dense = p->percent_dense * extent;
    int64_t nclone = 0, nsplit = 0;
    uint8_t *sel = g3d_calloc((size_t)(n0 > 0 ? n0 : 1), 1, "densify selection");
    if (!sel) return G3D_ERR_NOMEM;
    for (int64_t i = 0; i < n0; i++) {
        float avg = st->count[i] > 0 ? st->grad_accum[i] / (float)st->count[i] : 0.0f;
        if (!(avg >= p->grad_threshold)) continue;
        if (max_scale(g, i) <= dense) { sel[i] = 1; nclone++; }
        else { sel[i] = 2; nsplit++; }
    }
    if (p->max_gaussians > 0 && n0 + nclone + nsplit > p->max_gaussians) {
        memset(sel, 0, (size_t)n0);
        nclone = nsplit = 0;
    }
    int64_t need = n0 + nclone + 2 * nsplit;
    g3d_status rc = g3d_gaussians_reserve(g, need);
    if (rc == G3D_OK) rc = g3d_gaussians_reserve(&adam->m, need);
    if (rc == G3D_OK) rc = g3d_gaussians_reserve(&adam->v, need);
    if (rc != G3D_OK) { free(sel); return rc; }

    /* clones first, then split children (Inria order) */
    for (int64_t i = 0; i < n0; i++)
        if (sel[i] == 1) append_copy(g, adam, i);
    for (int64_t i = 0; i < n0; i++) {
        if (sel[i] != 2) continue;
        const float *q = g->rots + i * 4;
        g3d_mat4 R = g3d_quat_to_mat4(g3d_quat_normalize((g3d_quat){q[0], q[1], q[2], q[3]}));
        for (int c = 0; c < 2; c++) {
            int64_t k = append_copy(g, adam, i);
            g3d_vec3 e = g3d_v3(expf(g->log_scales[i * 3 + 0]) * g3d_rng_normal(rng),
                                expf(g->log_scales[i * 3 + 1]) * g3d_rng_normal(rng),
                                expf(g->log_scales[i * 3 + 2]) * g3d_rng_normal(rng));
            g3d_vec3 d = g3d_mat4_dir(R, e);
            g->means[k * 3 + 0] += (float)d.x;
            g->means[k * 3 + 1] += (float)d.y;
            g->means[k * 3 + 2] += (float)d.z;
            for (int a = 0; a < 3; a++) g->log_scales[k * 3 + a] -= logf(1.6f);
        }
    }

    uint8_t *keep = g3d_calloc((size_t)g->n, 1, "densify keep mask");
    if (!keep) { free(sel); return G3D_ERR_NOMEM; }
    int64_t pruned = 0;
    for (int64_t i = 0; i < g->n; i++) {
        int drop = (i < n0 && sel[i] == 2) || sigmoidf(g->opacity_logits[i]) < p->min_opacity;
        if (!drop && prune_large)
            drop = (i < n0 && st->max_radius[i] > p->max_screen_radius) ||
                   max_scale(g, i) > p->max_world_scale * extent;
        keep[i] = !drop;
        pruned += drop && !(i < n0 && sel[i] == 2);
    }
    g3d_gaussians_compact(g, keep);
    g3d_gaussians_compact(&adam->m, keep);
    g3d_gaussians_compact(&adam->v, keep);
    free(keep);
    free(sel);

    g3d_densify_stats_free(st);
    G3D_TRY(g3d_densify_stats_init(st, g->capacity));
    if (res) { res->cloned = nclone; res->split = nsplit; res->pruned = pruned; }
    return G3D_OK;
}

void g3d_densify_reset_opacity(g3d_gaussians *g, g3d_adam *adam)
{
    const float cap = logf(0.01f / 0.99f);
    for (int64_t i = 0; i < g->n; i++) {
        if (g->opacity_logits[i] > cap) g->opacity_logits[i] = cap;
        adam->m.opacity_logits[i] = 0;
        adam->v.opacity_logits[i] = 0;
    }
}
