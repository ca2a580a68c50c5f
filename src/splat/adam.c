/* adam.c - Adam over the SoA Gaussian model with per-group learning rates. */
#include "gen3d/adam.h"

#include <math.h>
#include <string.h>

void g3d_adam_params_default(g3d_adam_params *p)
{
    memset(p, 0, sizeof *p);
    p->lr[G3D_PG_MEANS] = 1.6e-4;
    p->lr[G3D_PG_SH_DC] = 2.5e-3;
    p->lr[G3D_PG_SH_REST] = 2.5e-3 / 20.0;
    p->lr[G3D_PG_OPACITY] = 2.5e-2;
    p->lr[G3D_PG_SCALES] = 5e-3;
    p->lr[G3D_PG_ROTS] = 1e-3;
    p->means_lr_final = 1.6e-6;
    p->means_lr_steps = 30000;
    p->beta1 = 0.9;
    p->beta2 = 0.999;
    p->eps = 1e-15;
}

g3d_status g3d_adam_init(g3d_adam *a, const g3d_adam_params *p, const g3d_gaussians *model)
{
    memset(a, 0, sizeof *a);
    a->p = *p;
    g3d_status rc = g3d_gaussians_create(&a->m, model->capacity, model->sh_degree);
    if (rc == G3D_OK) rc = g3d_gaussians_create(&a->v, model->capacity, model->sh_degree);
    if (rc != G3D_OK) {
        g3d_adam_free(a);
        return rc;
    }
    a->m.n = a->v.n = model->n;
    return G3D_OK;
}

void g3d_adam_free(g3d_adam *a)
{
    if (!a) return;
    g3d_gaussians_free(&a->m);
    g3d_gaussians_free(&a->v);
    memset(a, 0, sizeof *a);
}

double g3d_adam_means_lr(const g3d_adam_params *p, int64_t step, double extent)
{
    double s = p->means_lr_steps > 0 ? (double)step / (double)p->means_lr_steps : 1.0;
    if (s < 0) s = 0;
    if (s > 1) s = 1;
    return extent * exp((1 - s) * log(p->lr[G3D_PG_MEANS]) + s * log(p->means_lr_final));
}

/* The update runs in single precision: the moments are stored as floats anyway, and at
 * 59 values per Gaussian the step is bound by memory traffic and, in double, by the vector
 * square roots and divisions (twice the lanes in float). */
typedef struct step_consts {
    float b1, b2, step_size, inv_sqrt_c2, eps;
} step_consts;

static inline void update(float *restrict x, float *restrict m, float *restrict v, const float *restrict g,
                          size_t n, const step_consts *k)
{
    const float b1 = k->b1, b2 = k->b2, ob1 = 1.0f - k->b1, ob2 = 1.0f - k->b2;
    const float ss = k->step_size, ic = k->inv_sqrt_c2, eps = k->eps;
    for (size_t i = 0; i < n; i++) {
        float gi = g[i];
        float mi = b1 * m[i] + ob1 * gi;
        float vi = b2 * v[i] + ob2 * gi * gi;
        m[i] = mi;
        v[i] = vi;
        x[i] -= ss * mi / (sqrtf(vi) * ic + eps);
    }
}

/* Gaussians [i0, i1): every group with its rate; the SH of consecutive Gaussians are one
 * contiguous run, the DC and the rest differing only in the step size. Built for AVX-512, AVX2
 * and SSE2 (the vector square roots and divisions are exact in every width, so the results
 * are the same). */
__attribute__((target_clones("avx512f", "avx2", "default")))
static void update_range(g3d_adam *a, g3d_gaussians *x, const g3d_gaussians *g, size_t i0, size_t i1,
                         const step_consts k[G3D_PG_COUNT])
{
    const size_t c = i1 - i0, K3 = 3 * (size_t)G3D_SH_COEFFS(x->sh_degree);
    update(x->means + 3 * i0, a->m.means + 3 * i0, a->v.means + 3 * i0, g->means + 3 * i0, 3 * c, &k[G3D_PG_MEANS]);
    update(x->log_scales + 3 * i0, a->m.log_scales + 3 * i0, a->v.log_scales + 3 * i0, g->log_scales + 3 * i0,
           3 * c, &k[G3D_PG_SCALES]);
    update(x->rots + 4 * i0, a->m.rots + 4 * i0, a->v.rots + 4 * i0, g->rots + 4 * i0, 4 * c, &k[G3D_PG_ROTS]);
    update(x->opacity_logits + i0, a->m.opacity_logits + i0, a->v.opacity_logits + i0, g->opacity_logits + i0, c,
           &k[G3D_PG_OPACITY]);
    const step_consts *dc = &k[G3D_PG_SH_DC], *rest = &k[G3D_PG_SH_REST];
    const float b1 = dc->b1, b2 = dc->b2, ob1 = 1.0f - dc->b1, ob2 = 1.0f - dc->b2;
    const float ssd = dc->step_size, ssr = rest->step_size, ic = dc->inv_sqrt_c2, eps = dc->eps;
    float *restrict xs = x->sh + K3 * i0, *restrict ms = a->m.sh + K3 * i0, *restrict vs = a->v.sh + K3 * i0;
    const float *restrict gs = g->sh + K3 * i0;
    for (size_t i = 0; i < c; i++)
        for (size_t j = 0; j < K3; j++) {
            const size_t e = i * K3 + j;
            float gi = gs[e];
            float mi = b1 * ms[e] + ob1 * gi;
            float vi = b2 * vs[e] + ob2 * gi * gi;
            ms[e] = mi;
            vs[e] = vi;
            xs[e] -= (j < 3 ? ssd : ssr) * mi / (sqrtf(vi) * ic + eps);
        }
}

g3d_status g3d_adam_step(g3d_adam *a, g3d_gaussians *model, const g3d_gaussians *grad, double extent)
{
    return g3d_adam_step_visible(a, model, grad, extent, NULL);
}

g3d_status g3d_adam_step_visible(g3d_adam *a, g3d_gaussians *model, const g3d_gaussians *grad, double extent,
                                 const int32_t *radii)
{
    if (grad->n != model->n || grad->sh_degree != model->sh_degree || a->m.n != model->n ||
        a->v.n != model->n || a->m.sh_degree != model->sh_degree)
        return G3D_ERR(G3D_ERR_MISMATCH,
                       "adam: model has %lld Gaussians (SH %d), gradient %lld (SH %d), moments %lld",
                       (long long)model->n, model->sh_degree, (long long)grad->n,
                       grad->sh_degree, (long long)a->m.n);
    double means_lr = g3d_adam_means_lr(&a->p, a->step, extent);
    a->step++;
    /* bias corrections folded into the step size and the denominator:
     * lr m/c1 / (sqrt(v/c2) + eps) = (lr/c1) m / (sqrt(v) / sqrt(c2) + eps) */
    const double c1 = 1 - pow(a->p.beta1, (double)a->step), c2 = 1 - pow(a->p.beta2, (double)a->step);
    const size_t n = (size_t)model->n;
    const double *lr = a->p.lr;
    step_consts k[G3D_PG_COUNT];
    for (int gi = 0; gi < G3D_PG_COUNT; gi++)
        k[gi] = (step_consts){(float)a->p.beta1, (float)a->p.beta2,
                              (float)((gi == G3D_PG_MEANS ? means_lr : lr[gi]) / c1), (float)(1.0 / sqrt(c2)),
                              (float)a->p.eps};
    /* element-wise, so blocks of Gaussians can go to any thread: the result never depends on
     * the thread count. With radii, runs of visible Gaussians (consecutive ones are mostly
     * neighbours in the scene, so runs are long). */
#pragma omp parallel for schedule(static)
    for (size_t b = 0; b < n; b += 256) {
        const size_t e = b + 256 < n ? b + 256 : n;
        if (!radii) {
            update_range(a, model, grad, b, e, k);
            continue;
        }
        for (size_t i = b; i < e;) {
            while (i < e && radii[i] <= 0) i++;
            size_t j = i;
            while (j < e && radii[j] > 0) j++;
            if (j > i) update_range(a, model, grad, i, j, k);
            i = j;
        }
    }
    return G3D_OK;
}
