/* Storage of the Gaussian model: one block split into the parameter arrays. */
#include "gen3d/gaussians.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Floats per Gaussian in each array, in block order. */
static void array_widths(int sh_degree, size_t w[5])
{
    w[0] = 3;                                 /* means */
    w[1] = 3;                                 /* log_scales */
    w[2] = 4;                                 /* rots */
    w[3] = 1;                                 /* opacity_logits */
    w[4] = 3 * (size_t)G3D_SH_COEFFS(sh_degree); /* sh */
}

static g3d_status alloc_block(g3d_gaussians *g, int64_t capacity, int sh_degree)
{
    size_t w[5], per = 0;
    array_widths(sh_degree, w);
    for (int i = 0; i < 5; i++) per += w[i];
    if (capacity < 1) capacity = 1;
    float *block = g3d_calloc((size_t)capacity, per * sizeof(float), "gaussians");
    if (!block) return G3D_ERR_NOMEM;
    float *p = block;
    g->means = p;          p += w[0] * (size_t)capacity;
    g->log_scales = p;     p += w[1] * (size_t)capacity;
    g->rots = p;           p += w[2] * (size_t)capacity;
    g->opacity_logits = p; p += w[3] * (size_t)capacity;
    g->sh = p;
    g->block_ = block;
    g->capacity = capacity;
    g->sh_degree = sh_degree;
    return G3D_OK;
}

g3d_status g3d_gaussians_create(g3d_gaussians *g, int64_t capacity, int sh_degree)
{
    memset(g, 0, sizeof *g);
    if (sh_degree < 0 || sh_degree > G3D_SH_MAX_DEGREE)
        return G3D_ERR(G3D_ERR_ARG, "SH degree %d out of range 0..%d", sh_degree, G3D_SH_MAX_DEGREE);
    if (capacity < 0) return G3D_ERR(G3D_ERR_ARG, "negative Gaussian count");
    return alloc_block(g, capacity, sh_degree);
}

g3d_status g3d_gaussians_reserve(g3d_gaussians *g, int64_t capacity)
{
    g3d_gaussians bigger;
    if (capacity <= g->capacity) return G3D_OK;
    memset(&bigger, 0, sizeof bigger);
    G3D_TRY(alloc_block(&bigger, capacity, g->sh_degree));
    bigger.n = g->n;
    size_t K3 = 3 * (size_t)G3D_SH_COEFFS(g->sh_degree), n = (size_t)g->n;
    memcpy(bigger.means, g->means, n * 3 * sizeof(float));
    memcpy(bigger.log_scales, g->log_scales, n * 3 * sizeof(float));
    memcpy(bigger.rots, g->rots, n * 4 * sizeof(float));
    memcpy(bigger.opacity_logits, g->opacity_logits, n * sizeof(float));
    memcpy(bigger.sh, g->sh, n * K3 * sizeof(float));
    g3d_gaussians_free(g);
    *g = bigger;
    return G3D_OK;
}

void g3d_gaussians_free(g3d_gaussians *g)
{
    if (!g) return;
    free(g->block_);
    memset(g, 0, sizeof *g);
}

g3d_status g3d_gaussians_clone(g3d_gaussians *dst, const g3d_gaussians *src)
{
    G3D_TRY(g3d_gaussians_create(dst, src->n, src->sh_degree));
    dst->n = 0;
    for (int64_t i = 0; i < src->n; i++) g3d_gaussians_copy_one(dst, i, src, i);
    dst->n = src->n;
    return G3D_OK;
}

void g3d_gaussians_copy_one(g3d_gaussians *dst, int64_t i, const g3d_gaussians *src, int64_t j)
{
    size_t K3 = 3 * (size_t)G3D_SH_COEFFS(src->sh_degree);
    memcpy(dst->means + 3 * i, src->means + 3 * j, 3 * sizeof(float));
    memcpy(dst->log_scales + 3 * i, src->log_scales + 3 * j, 3 * sizeof(float));
    memcpy(dst->rots + 4 * i, src->rots + 4 * j, 4 * sizeof(float));
    dst->opacity_logits[i] = src->opacity_logits[j];
    memcpy(dst->sh + K3 * (size_t)i, src->sh + K3 * (size_t)j, K3 * sizeof(float));
}

int64_t g3d_gaussians_compact(g3d_gaussians *g, const uint8_t *keep)
{
    int64_t k = 0;
    for (int64_t i = 0; i < g->n; i++) {
        if (!keep[i]) continue;
        if (k != i) g3d_gaussians_copy_one(g, k, g, i);
        k++;
    }
    g->n = k;
    return k;
}

g3d_status g3d_gaussians_validate(const g3d_gaussians *g, const char *label)
{
    size_t K3 = 3 * (size_t)G3D_SH_COEFFS(g->sh_degree);
    for (int64_t i = 0; i < g->n; i++) {
        int ok = isfinite(g->opacity_logits[i]);
        for (int k = 0; k < 3; k++) ok &= isfinite(g->means[3 * i + k]) && isfinite(g->log_scales[3 * i + k]);
        for (int k = 0; k < 4; k++) ok &= isfinite(g->rots[4 * i + k]);
        for (size_t k = 0; k < K3; k++) ok &= isfinite(g->sh[K3 * (size_t)i + k]);
        if (!ok) return G3D_ERR(G3D_ERR_FORMAT, "%s: Gaussian %lld has a NaN or infinite parameter", label, (long long)i);
    }
    return G3D_OK;
}
