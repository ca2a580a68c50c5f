/* Weight-free object proposals: remove the scene's large planes, split the rest into
 * depth-continuous components. */
#include "gen3d/regions.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void g3d_regions_params_default(g3d_regions_params *p)
{
    *p = (g3d_regions_params){0.10f, 0.012f, 0.03f, 6, 300, 7};
}

typedef struct regions_ctx { g3d_regions_params p; g3d_intrinsics K; } regions_ctx;

/* Distance of camera-space point P from plane n.P + d = 0 (n unit), relative to its depth. */
static double rel_dist(const double n[4], const double P[3]) { return fabs(n[0] * P[0] + n[1] * P[1] + n[2] * P[2] + n[3]) / P[2]; }

static int plane_from_3(const double a[3], const double b[3], const double c[3], double n[4])
{
    double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    n[0] = u[1] * v[2] - u[2] * v[1];
    n[1] = u[2] * v[0] - u[0] * v[2];
    n[2] = u[0] * v[1] - u[1] * v[0];
    double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (len < 1e-12) return 0;
    for (int k = 0; k < 3; k++) n[k] /= len;
    n[3] = -(n[0] * a[0] + n[1] * a[1] + n[2] * a[2]);
    return 1;
}

static g3d_status regions_propose(void *vctx, const g3d_image *rgb, const g3d_image *depth, g3d_mask_set *out)
{
    regions_ctx *ctx = vctx;
    const g3d_regions_params *p = &ctx->p;
    int w = rgb->w, h = rgb->h;
    size_t n = (size_t)w * h;
    memset(out, 0, sizeof *out);
    if (depth->w != w || depth->h != h) return G3D_ERR(G3D_ERR_MISMATCH, "regions: depth %dx%d vs image %dx%d", depth->w, depth->h, w, h);
    g3d_intrinsics K = ctx->K;
    if (K.width != w || K.height != h) K = g3d_intrinsics_resize(K, w, h);

    double *P = malloc(sizeof(double) * 3 * n);
    int32_t *label = malloc(sizeof(int32_t) * n), *stack = malloc(sizeof(int32_t) * n), *sample = malloc(sizeof(int32_t) * n);
    g3d_status rc = G3D_OK;
    if (!P || !label || !stack || !sample) { rc = G3D_ERR(G3D_ERR_NOMEM, "regions: out of memory"); goto done; }
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            double z = depth->data[i];
            P[3 * i] = (x - K.cx) / K.fx * z;
            P[3 * i + 1] = (y - K.cy) / K.fy * z;
            P[3 * i + 2] = z;
            label[i] = z > 0 ? -1 : -2; /* -1 unassigned, -2 invalid, -3 structure plane */
        }

    /* Structure: repeatedly take the plane with the most inliers (RANSAC on a pixel sample,
     * seeded) while it explains at least min_plane of the image. */
    g3d_rng rng;
    g3d_rng_seed(&rng, 0x9e3779b9u, 3);
    for (int plane = 0; plane < p->max_planes; plane++) {
        int ns = 0;
        for (size_t i = 0; i < n; i += 7) if (label[i] == -1) sample[ns++] = (int32_t)i;
        if (ns < 30) break;
        double best[4] = {0}, cand[4];
        int best_count = 0;
        for (int it = 0; it < p->ransac_iters; it++) {
            int32_t a = sample[g3d_rng_below(&rng, (uint32_t)ns)], b = sample[g3d_rng_below(&rng, (uint32_t)ns)],
                    c = sample[g3d_rng_below(&rng, (uint32_t)ns)];
            if (!plane_from_3(P + 3 * a, P + 3 * b, P + 3 * c, cand)) continue;
            int count = 0;
            for (int k = 0; k < ns; k++) count += rel_dist(cand, P + 3 * (size_t)sample[k]) < p->plane_tol;
            if (count > best_count) { best_count = count; memcpy(best, cand, sizeof best); }
        }
        size_t inl = 0;
        for (size_t i = 0; i < n; i++) inl += label[i] == -1 && rel_dist(best, P + 3 * i) < p->plane_tol;
        if (best_count == 0 || inl < p->min_plane * n) break;
        for (size_t i = 0; i < n; i++) if (label[i] == -1 && rel_dist(best, P + 3 * i) < p->plane_tol) label[i] = -3;
    }

    /* Objects: 4-connected components of what is left, across depth-continuous neighbours. */
    int ncomp = 0;
    for (size_t s = 0; s < n; s++) {
        if (label[s] != -1) continue;
        int top = 0;
        stack[top++] = (int32_t)s;
        label[s] = ncomp;
        while (top) {
            int32_t i = stack[--top];
            int x = i % w, y = i / w;
            float zi = depth->data[i];
            for (int k = 0; k < 4; k++) {
                int xx = x + (k == 0) - (k == 1), yy = y + (k == 2) - (k == 3);
                if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
                int32_t j = yy * w + xx;
                if (label[j] != -1 || fabsf(depth->data[j] - zi) > p->jump * zi) continue;
                label[j] = ncomp;
                stack[top++] = j;
            }
        }
        ncomp++;
    }
    int *size = calloc((size_t)(ncomp ? ncomp : 1), sizeof(int)), *id = malloc(sizeof(int) * (size_t)(ncomp ? ncomp : 1));
    if (!size || !id) { free(size); free(id); rc = G3D_ERR(G3D_ERR_NOMEM, "regions: out of memory"); goto done; }
    for (size_t i = 0; i < n; i++) if (label[i] >= 0) size[label[i]]++;
    int nprop = 0;
    for (int c = 0; c < ncomp; c++) id[c] = size[c] >= p->min_size ? nprop++ : -1;
    out->masks = calloc((size_t)(nprop ? nprop : 1) * n, 1);
    out->scores = malloc(sizeof(float) * (size_t)(nprop ? nprop : 1));
    if (!out->masks || !out->scores) { free(size); free(id); g3d_mask_set_free(out); rc = G3D_ERR(G3D_ERR_NOMEM, "regions: out of memory"); goto done; }
    for (size_t i = 0; i < n; i++) if (label[i] >= 0 && id[label[i]] >= 0) out->masks[(size_t)id[label[i]] * n + i] = 1;
    for (int r = 0; r < nprop; r++) out->scores[r] = 1.0f; /* no confidence model: every proposal counts */
    out->n = nprop;
    out->w = w;
    out->h = h;
    free(size);
    free(id);
done:
    free(P);
    free(label);
    free(stack);
    free(sample);
    return rc;
}

static void regions_free(void *ctx) { free(ctx); }

g3d_status g3d_mask_provider_regions_create(const g3d_regions_params *params, g3d_intrinsics K, g3d_mask_provider *out)
{
    regions_ctx *c = malloc(sizeof *c);
    if (!c) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (params) c->p = *params;
    else g3d_regions_params_default(&c->p);
    c->K = K;
    out->name = "regions";
    out->ctx = c;
    out->propose = regions_propose;
    out->free = regions_free;
    return G3D_OK;
}
