/* Foreground/background layers from candidate masks and depth. */
#include "gen3d/layers.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void g3d_layers_params_default(g3d_layers_params *p)
{
    *p = (g3d_layers_params){0.85f, 0.005f, 0.60f, 0.35f, 0.3f, 2, NULL};
}

void g3d_layers_free(g3d_layers *l)
{
    if (!l) return;
    g3d_image_free(&l->fg_mask);
    g3d_image_free(&l->bg_rgb);
    g3d_image_free(&l->bg_depth);
    free(l->bg_prompt);
    free(l->view_prompt);
    memset(l, 0, sizeof *l);
}

g3d_status g3d_layers_clone(g3d_layers *dst, const g3d_layers *src)
{
    *dst = *src;
    dst->fg_mask = dst->bg_rgb = dst->bg_depth = (g3d_image){0};
    dst->bg_prompt = src->bg_prompt ? strdup(src->bg_prompt) : NULL;
    dst->view_prompt = src->view_prompt ? strdup(src->view_prompt) : NULL;
    g3d_status rc = (src->bg_prompt && !dst->bg_prompt) || (src->view_prompt && !dst->view_prompt)
                        ? G3D_ERR(G3D_ERR_NOMEM, "layers: out of memory")
                        : G3D_OK;
    if (src->fg_mask.data) rc = g3d_image_clone(&dst->fg_mask, &src->fg_mask);
    if (rc == G3D_OK && src->bg_rgb.data) rc = g3d_image_clone(&dst->bg_rgb, &src->bg_rgb);
    if (rc == G3D_OK && src->bg_depth.data) rc = g3d_image_clone(&dst->bg_depth, &src->bg_depth);
    if (rc != G3D_OK) g3d_layers_free(dst);
    return rc;
}

/* Fraction of the mask's boundary pixels with an outside 4-neighbour more than 5 % deeper. */
static double occluding_fraction(const uint8_t *mk, const g3d_image *depth)
{
    int w = depth->w, h = depth->h;
    size_t boundary = 0, occluding = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            if (!mk[i]) continue;
            int is_b = 0, is_o = 0;
            for (int k = 0; k < 4; k++) {
                int xx = x + (k == 0) - (k == 1), yy = y + (k == 2) - (k == 3);
                if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
                size_t j = (size_t)yy * w + xx;
                if (mk[j]) continue;
                is_b = 1;
                float zi = depth->data[i], zj = depth->data[j];
                if (zi > 0 && (zj <= 0 || zj > 1.05f * zi)) is_o = 1;
            }
            boundary += is_b;
            occluding += is_o;
        }
    return boundary ? (double)occluding / boundary : 0.0;
}

g3d_status g3d_layers_compute(const g3d_image *rgb, const g3d_image *depth, const g3d_mask_provider *masks,
                              const g3d_inpainter *inpaint, const g3d_depth_estimator *depth_fill,
                              const g3d_layers_params *p, uint64_t seed, g3d_layers *out)
{
    g3d_layers_params def;
    g3d_layers_params_default(&def);
    int w = rgb->w, h = rgb->h;
    size_t n = (size_t)w * h;
    memset(out, 0, sizeof *out);
    if (!p) p = &def;
    if (depth->w != w || depth->h != h) return G3D_ERR(G3D_ERR_MISMATCH, "layers: depth %dx%d vs image %dx%d", depth->w, depth->h, w, h);

    /* theta_d: the percentile of the valid depth. */
    float *vals = malloc(sizeof(float) * n), *inside = malloc(sizeof(float) * n);
    if (!vals || !inside) { free(vals); free(inside); return G3D_ERR(G3D_ERR_NOMEM, "layers: out of memory"); }
    size_t nv = 0;
    for (size_t i = 0; i < n; i++) if (depth->data[i] > 0) vals[nv++] = depth->data[i];
    if (nv == 0) { free(vals); free(inside); return G3D_ERR(G3D_ERR_ARG, "layers: depth has no valid pixel"); }
    g3d_sort_f32(vals, nv);
    out->theta_d = vals[(size_t)(p->percentile * (nv - 1))];

    g3d_mask_set set;
    g3d_status rc = masks->propose(masks->ctx, rgb, depth, &set);
    if (rc != G3D_OK) { free(vals); free(inside); return rc; }
    if ((rc = g3d_image_create(&out->fg_mask, w, h, 1)) != G3D_OK) goto done;
    out->n_candidates = set.n;
    for (int m = 0; m < set.n; m++) {
        const uint8_t *mk = set.masks + (size_t)m * n;
        size_t area = 0, k = 0;
        for (size_t i = 0; i < n; i++) {
            if (!mk[i]) continue;
            area++;
            if (depth->data[i] > 0) inside[k++] = depth->data[i];
        }
        if (set.scores[m] <= p->min_score && set.scores[m] < 1.0f) continue;
        if (area < p->min_area * n || area > p->max_area * n || k == 0) continue;
        out->n_kept++;
        float med = g3d_median_f32(inside, k);
        double occ = occluding_fraction(mk, depth);
        g3d_log(G3D_LOG_DEBUG, "layers: candidate %d: area %.2f %%, median depth %.2f m, occluding boundary %.0f %%", m,
                100.0 * area / n, med, 100 * occ);
        if (med >= out->theta_d || occ < p->min_occluding) continue;
        out->n_foreground++;
        for (size_t i = 0; i < n; i++) if (mk[i]) out->fg_mask.data[i] = 1;
    }

    /* Background: remove the (slightly grown) foreground, inpaint colour, complete depth. */
    g3d_image grown = {0}, known = {0};
    if ((rc = g3d_image_clone(&grown, &out->fg_mask)) != G3D_OK) goto done;
    for (int it = 0; it < p->dilate; it++) {
        g3d_image prev;
        if ((rc = g3d_image_clone(&prev, &grown)) != G3D_OK) break;
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++)
                if ((x > 0 && prev.data[(size_t)y * w + x - 1] > 0.5f) || (x < w - 1 && prev.data[(size_t)y * w + x + 1] > 0.5f) ||
                    (y > 0 && prev.data[(size_t)(y - 1) * w + x] > 0.5f) || (y < h - 1 && prev.data[(size_t)(y + 1) * w + x] > 0.5f))
                    grown.data[(size_t)y * w + x] = 1;
        g3d_image_free(&prev);
    }
    if (rc == G3D_OK) rc = g3d_image_clone(&out->bg_rgb, rgb);
    if (rc == G3D_OK && p->prompts) rc = p->prompts->prompt(p->prompts->ctx, rgb, &out->fg_mask, &out->bg_prompt, &out->view_prompt);
    if (rc == G3D_OK && out->n_foreground) rc = inpaint->inpaint(inpaint->ctx, &out->bg_rgb, &grown, out->bg_prompt, seed);
    if (rc == G3D_OK) rc = g3d_image_clone(&known, depth);
    if (rc == G3D_OK) {
        for (size_t i = 0; i < n; i++) if (grown.data[i] > 0.5f) known.data[i] = 0;
        if (out->n_foreground) rc = depth_fill->estimate(depth_fill->ctx, &out->bg_rgb, &known, &grown, &out->bg_depth, NULL);
        else rc = g3d_image_clone(&out->bg_depth, depth);
    }
    g3d_image_free(&grown);
    g3d_image_free(&known);
done:
    g3d_mask_set_free(&set);
    free(vals);
    free(inside);
    if (rc != G3D_OK) g3d_layers_free(out);
    return rc;
}
