/* Adam over the Gaussian model's parameter arrays. */
#include "gen3d/adam.h"

#include <math.h>
#include <string.h>

g3d_status g3d_adam_init(g3d_adam *a, const g3d_gaussians *g, double scene_extent)
{
    memset(a, 0, sizeof *a);
    a->lr[G3D_GROUP_MEANS] = 1.6e-4 * scene_extent;
    a->lr[G3D_GROUP_SCALES] = 5e-3;
    a->lr[G3D_GROUP_ROTS] = 1e-3;
    a->lr[G3D_GROUP_OPACITY] = 2.5e-2;
    a->lr[G3D_GROUP_SH_DC] = 2.5e-3;
    a->lr[G3D_GROUP_SH_REST] = 2.5e-3 / 20.0;
    a->beta1 = 0.9;
    a->beta2 = 0.999;
    a->eps = 1e-15;
    G3D_TRY(g3d_gaussians_create(&a->m, g->capacity, g->sh_degree));
    g3d_status rc = g3d_gaussians_create(&a->v, g->capacity, g->sh_degree);
    if (rc != G3D_OK) { g3d_gaussians_free(&a->m); return rc; }
    a->m.n = a->v.n = g->n;
    return G3D_OK;
}

void g3d_adam_free(g3d_adam *a)
{
    if (!a) return;
    g3d_gaussians_free(&a->m);
    g3d_gaussians_free(&a->v);
}

/* n elements of one array. */
g3d_status g3d_adam_grow(g3d_adam *a, const g3d_gaussians *p)
{
    if (a->m.capacity < p->n) {
        G3D_TRY(g3d_gaussians_reserve(&a->m, p->capacity));
        G3D_TRY(g3d_gaussians_reserve(&a->v, p->capacity));
    }
    /* Gaussians added since the moments were last sized start from zero moments. */
    int64_t K3 = 3 * G3D_SH_COEFFS(p->sh_degree);
    for (int64_t i = a->m.n; i < p->n; i++)
        for (int which = 0; which < 2; which++) {
            g3d_gaussians *s = which ? &a->v : &a->m;
            memset(s->means + 3 * i, 0, 3 * sizeof(float));
            memset(s->log_scales + 3 * i, 0, 3 * sizeof(float));
            memset(s->rots + 4 * i, 0, 4 * sizeof(float));
            s->opacity_logits[i] = 0;
            memset(s->sh + K3 * i, 0, sizeof(float) * (size_t)K3);
        }
    a->m.n = a->v.n = p->n;
    return G3D_OK;
}

static void update(float *p, const float *g, float *m, float *v, int64_t n, double lr, const g3d_adam *a, double bc1, double bc2)
{
    for (int64_t i = 0; i < n; i++) {
        double gi = g[i];
        double mi = a->beta1 * m[i] + (1 - a->beta1) * gi, vi = a->beta2 * v[i] + (1 - a->beta2) * gi * gi;
        m[i] = (float)mi;
        v[i] = (float)vi;
        p[i] -= (float)(lr * (mi / bc1) / (sqrt(vi / bc2) + a->eps));
    }
}

g3d_status g3d_adam_step(g3d_adam *a, g3d_gaussians *p, const g3d_gaussians *g)
{
    if (g->n != p->n || g->sh_degree != p->sh_degree || a->m.sh_degree != p->sh_degree)
        return G3D_ERR(G3D_ERR_MISMATCH, "adam: gradients for %lld Gaussians (SH %d), model has %lld (SH %d)", (long long)g->n,
                       g->sh_degree, (long long)p->n, p->sh_degree);
    G3D_TRY(g3d_adam_grow(a, p));
    a->step++;
    double bc1 = 1 - pow(a->beta1, (double)a->step), bc2 = 1 - pow(a->beta2, (double)a->step);
    int64_t n = p->n, K = G3D_SH_COEFFS(p->sh_degree);
    update(p->means, g->means, a->m.means, a->v.means, 3 * n, a->lr[G3D_GROUP_MEANS], a, bc1, bc2);
    update(p->log_scales, g->log_scales, a->m.log_scales, a->v.log_scales, 3 * n, a->lr[G3D_GROUP_SCALES], a, bc1, bc2);
    update(p->rots, g->rots, a->m.rots, a->v.rots, 4 * n, a->lr[G3D_GROUP_ROTS], a, bc1, bc2);
    update(p->opacity_logits, g->opacity_logits, a->m.opacity_logits, a->v.opacity_logits, n, a->lr[G3D_GROUP_OPACITY], a, bc1, bc2);
    for (int64_t i = 0; i < n; i++) {
        size_t o = (size_t)(3 * K * i);
        update(p->sh + o, g->sh + o, a->m.sh + o, a->v.sh + o, 3, a->lr[G3D_GROUP_SH_DC], a, bc1, bc2);
        if (K > 1) update(p->sh + o + 3, g->sh + o + 3, a->m.sh + o + 3, a->v.sh + o + 3, 3 * (K - 1), a->lr[G3D_GROUP_SH_REST], a, bc1, bc2);
    }
    return G3D_OK;
}

void g3d_adam_compact(g3d_adam *a, const uint8_t *keep)
{
    g3d_gaussians_compact(&a->m, keep);
    g3d_gaussians_compact(&a->v, keep);
}
