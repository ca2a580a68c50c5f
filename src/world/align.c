/* Ray-constrained alignment of new depth to the existing cloud. */
#include "gen3d/align.h"
#include "gen3d/membrane.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void g3d_align_params_default(g3d_align_params *p)
{
    *p = (g3d_align_params){3.0f, 3.0f, 1.1f};
}

/* How far a near-side value is carried into its occluder (g3d_align_far_side): the membrane
 * solves coarse to fine on 2 x 2 averages, so the values a few pixels behind the boundary
 * reach the hole through the coarser levels too. */
#define FAR_RING 4

g3d_status g3d_align_far_side(const g3d_image *depth_cloud, const g3d_image *mask, float edge_ratio, g3d_image *far,
                              int64_t *n_near)
{
    int w = depth_cloud->w, h = depth_cloud->h;
    int64_t count = 0;
    if (mask->w != w || mask->h != h)
        return G3D_ERR(G3D_ERR_MISMATCH, "align: cloud depth %dx%d and mask %dx%d differ", w, h, mask->w, mask->h);
    if (!(edge_ratio > 1)) return G3D_ERR(G3D_ERR_ARG, "align: depth edge ratio %g (need > 1)", edge_ratio);
    G3D_TRY(g3d_image_create(far, w, h, 1));
    const float *z = depth_cloud->data;
#define COVERED(xx, yy) (mask->data[(size_t)(yy) * w + (xx)] >= 0.5f)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            if (!COVERED(x, y) || !(z[i] > 0)) continue;
            float inv = 1.0f / z[i], best = 0;
            for (int d = 0; d < 9; d++) {
                int dx = d % 3 - 1, dy = d / 3 - 1;
                if (d == 4 || x + dx < 0 || y + dy < 0 || x + dx >= w || y + dy >= h || COVERED(x + dx, y + dy)) continue;
                /* Across the hole: the first covered pixel on the other side. */
                int k = 1, cx = x + dx, cy = y + dy;
                while (cx >= 0 && cy >= 0 && cx < w && cy < h && !COVERED(cx, cy)) { cx += dx; cy += dy; k++; }
                if (cx < 0 || cy < 0 || cx >= w || cy >= h) continue;
                float zc = z[(size_t)cy * w + cx];
                if (!(zc > 0)) continue;
                /* The near surface continued across the hole, when it recedes (a floor seen
                 * at a grazing angle is no depth edge): its slope in inverse depth over the
                 * covered pixels behind it, ignored when it is itself a jump (a thin
                 * structure); no verdict without pixels behind it. */
                int bx = x - 3 * dx, by = y - 3 * dy;
                if (bx < 0 || by < 0 || bx >= w || by >= h || !COVERED(bx, by) || !(z[(size_t)by * w + bx] > 0)) continue;
                float slope = (inv - 1.0f / z[(size_t)by * w + bx]) / 3;
                if (slope > 0 || slope < -0.02f * inv) slope = 0;
                float pred = inv + slope * k;
                if (pred > 0 && edge_ratio / zc < pred && (best == 0 || zc < best)) best = zc;
            }
            if (best > 0) { far->data[i] = best; count++; }
        }
#undef COVERED
    /* Carried into the occluder's fringe, to covered pixels still in front of the far side. */
    for (int r = 0; r < FAR_RING; r++) {
        g3d_image prev;
        g3d_status rc = g3d_image_clone(&prev, far);
        if (rc != G3D_OK) { g3d_image_free(far); return rc; }
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                size_t i = (size_t)y * w + x;
                if (prev.data[i] > 0 || mask->data[i] < 0.5f || !(z[i] > 0)) continue;
                float best = 0;
                for (int d = 0; d < 9; d++) {
                    int xx = x + d % 3 - 1, yy = y + d / 3 - 1;
                    if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
                    float f = prev.data[(size_t)yy * w + xx];
                    if (f > 0 && (best == 0 || f < best)) best = f;
                }
                if (best > 0 && z[i] * edge_ratio < best) far->data[i] = best;
            }
        g3d_image_free(&prev);
    }
    if (n_near) *n_near = count;
    return G3D_OK;
}

g3d_status g3d_align_depth(g3d_image *depth_new, const g3d_image *depth_cloud, const g3d_image *mask,
                           const g3d_align_params *p, g3d_align_stats *stats)
{
    int w = depth_new->w, h = depth_new->h;
    size_t n = (size_t)w * h;
    g3d_align_params def;
    g3d_align_params_default(&def);
    g3d_align_stats st;
    memset(&st, 0, sizeof st);
    if (!p) p = &def;
    if (depth_cloud->w != w || depth_cloud->h != h || mask->w != w || mask->h != h)
        return G3D_ERR(G3D_ERR_MISMATCH, "align: depth %dx%d, cloud depth %dx%d and mask %dx%d differ", w, h, depth_cloud->w,
                       depth_cloud->h, mask->w, mask->h);
    if (!(p->edge_ratio == 0 || p->edge_ratio > 1))
        return G3D_ERR(G3D_ERR_ARG, "align: depth edge ratio %g (need 0 = off, or > 1)", p->edge_ratio);
    float *r = malloc(sizeof(float) * n), *tmp = malloc(sizeof(float) * n);
    uint8_t *known = calloc(n, 1);
    g3d_image far = {0};
    if (!r || !tmp || !known) { free(r); free(tmp); free(known); return G3D_ERR(G3D_ERR_NOMEM, "align: out of memory"); }
    g3d_status rc = p->edge_ratio > 0 ? g3d_align_far_side(depth_cloud, mask, p->edge_ratio, &far, &st.near_side) : G3D_OK;
    if (rc != G3D_OK) { free(r); free(tmp); free(known); return rc; }

    /* Correspondences: covered pixels with a hole among their 4 neighbours. */
    size_t m = 0, holes = 0;
    double before = 0;
    float lmax = logf(p->max_ratio);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            if (mask->data[i] < 0.5f) { holes++; continue; }
            int edge = (x > 0 && mask->data[i - 1] < 0.5f) || (x < w - 1 && mask->data[i + 1] < 0.5f) ||
                       (y > 0 && mask->data[i - w] < 0.5f) || (y < h - 1 && mask->data[i + w] < 0.5f);
            float zc = depth_cloud->data[i], zn = depth_new->data[i];
            if (!edge || !(zc > 0) || !(zn > 0) || (far.data && far.data[i] > 0)) continue;
            float lr = logf(zc / zn);
            if (fabsf(lr) > lmax) continue;
            r[i] = lr;
            known[i] = 1;
            tmp[m++] = lr;
            before += fabs(zn - zc) / zc;
        }
    st.correspondences = (int64_t)m;
    if (m > 0 && holes > 0) {
        st.residual_before = before / m;
        float med = g3d_median_f32(tmp, m);
        for (size_t k = 0; k < m; k++) tmp[k] = fabsf(tmp[k] - med);
        /* In a fresh pass, since tmp was reordered by the median. */
        float mad = g3d_median_f32(tmp, m);
        float lim = p->outlier_mads * 1.4826f * mad + 1e-3f;
        double after = 0;
        for (size_t i = 0; i < n; i++) {
            if (!known[i]) continue;
            if (fabsf(r[i] - med) > lim) { known[i] = 0; st.rejected++; after += fabs(expf(r[i]) - 1.0f); }
        }
        st.median_ratio = expf(med);
        st.residual_after = after / m;
        rc = g3d_membrane_fill_planar(r, known, NULL, w, h);
        if (rc == G3D_OK)
            for (size_t i = 0; i < n; i++)
                if (mask->data[i] < 0.5f && depth_new->data[i] > 0) /* no correction beyond what any match showed */
                    depth_new->data[i] *= expf(fminf(fmaxf(r[i], -lmax), lmax));
    }
    free(r);
    free(tmp);
    free(known);
    g3d_image_free(&far);
    if (stats) *stats = st;
    return rc;
}
