/* Ray-constrained alignment of new depth to the existing cloud. */
#include "gen3d/align.h"
#include "gen3d/membrane.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void g3d_align_params_default(g3d_align_params *p)
{
    *p = (g3d_align_params){3.0f, 3.0f};
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
    float *r = malloc(sizeof(float) * n), *tmp = malloc(sizeof(float) * n);
    uint8_t *known = calloc(n, 1);
    if (!r || !tmp || !known) { free(r); free(tmp); free(known); return G3D_ERR(G3D_ERR_NOMEM, "align: out of memory"); }

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
            if (!edge || !(zc > 0) || !(zn > 0)) continue;
            float lr = logf(zc / zn);
            if (fabsf(lr) > lmax) continue;
            r[i] = lr;
            known[i] = 1;
            tmp[m++] = lr;
            before += fabs(zn - zc) / zc;
        }
    st.correspondences = (int64_t)m;
    g3d_status rc = G3D_OK;
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
    if (stats) *stats = st;
    return rc;
}
