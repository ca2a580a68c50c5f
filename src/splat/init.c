/* Initial Gaussians: from a point cloud, the scale from a 3-nearest-neighbour search on a
 * uniform grid (cells of about 2 points each, searched in growing shells); or from random
 * points around the cameras. */
#include "gen3d/init.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct grid {
    double lo[3], cell;
    int64_t dim[3];
    int64_t *start;   /* (cells + 1) */
    int64_t *idx;     /* (n) point ids sorted by cell */
} grid;

static int64_t cell_coord(const grid *gr, double v, int a)
{
    int64_t c = (int64_t)floor((v - gr->lo[a]) / gr->cell);
    return c < 0 ? 0 : c >= gr->dim[a] ? gr->dim[a] - 1 : c;
}

/* Keeps the three smallest squared distances in best[0..2] (ascending). */
static void push_best(double best[3], double d2)
{
    if (d2 >= best[2]) return;
    best[2] = d2;
    if (best[2] < best[1]) { double t = best[1]; best[1] = best[2]; best[2] = t; }
    if (best[1] < best[0]) { double t = best[0]; best[0] = best[1]; best[1] = t; }
}

/* Mean of the squared distances to the (up to) 3 nearest other points of point i. */
static double knn3_mean_d2(const grid *gr, const float *xyz, int64_t n, int64_t i)
{
    double best[3] = {DBL_MAX, DBL_MAX, DBL_MAX};
    const float *p = xyz + 3 * i;
    int64_t c[3];
    for (int a = 0; a < 3; a++) c[a] = cell_coord(gr, p[a], a);
    int64_t maxr = gr->dim[0];
    if (gr->dim[1] > maxr) maxr = gr->dim[1];
    if (gr->dim[2] > maxr) maxr = gr->dim[2];
    const int want = n - 1 < 3 ? (int)(n - 1) : 3;
    for (int64_t r = 0; r <= maxr; r++) {
        /* visit the shell at Chebyshev distance r */
        for (int64_t z = c[2] - r; z <= c[2] + r; z++) {
            if (z < 0 || z >= gr->dim[2]) continue;
            for (int64_t y = c[1] - r; y <= c[1] + r; y++) {
                if (y < 0 || y >= gr->dim[1]) continue;
                int on_face = z == c[2] - r || z == c[2] + r || y == c[1] - r || y == c[1] + r;
                for (int64_t x = c[0] - r; x <= c[0] + r; x += (on_face || r == 0) ? 1 : 2 * r) {
                    if (x < 0 || x >= gr->dim[0]) continue;
                    int64_t cell = (z * gr->dim[1] + y) * gr->dim[0] + x;
                    for (int64_t k = gr->start[cell]; k < gr->start[cell + 1]; k++) {
                        int64_t j = gr->idx[k];
                        if (j == i) continue;
                        const float *q = xyz + 3 * j;
                        double dx = (double)q[0] - p[0], dy = (double)q[1] - p[1], dz = (double)q[2] - p[2];
                        push_best(best, dx * dx + dy * dy + dz * dz);
                    }
                }
            }
        }
        /* every point outside shells 0..r is farther than r cells from p */
        if (want == 0) break;
        if (best[want - 1] < DBL_MAX && sqrt(best[want - 1]) <= r * gr->cell) break;
    }
    if (want == 0) return 0.0;
    double s = 0;
    for (int k = 0; k < want; k++) s += best[k];
    return s / want;
}

g3d_status g3d_gaussians_init_from_points(g3d_gaussians *g, const float *xyz, const float *rgb,
                                          int64_t n, int sh_degree)
{
    if (n < 1) return G3D_ERR(G3D_ERR_ARG, "init from points: empty point cloud");
    if (sh_degree < 0 || sh_degree > G3D_SH_MAX_DEGREE)
        return G3D_ERR(G3D_ERR_ARG, "init from points: SH degree %d out of range 0..%d", sh_degree, G3D_SH_MAX_DEGREE);
    grid gr;
    memset(&gr, 0, sizeof gr);
    double hi[3];
    for (int a = 0; a < 3; a++) { gr.lo[a] = DBL_MAX; hi[a] = -DBL_MAX; }
    for (int64_t i = 0; i < n; i++)
        for (int a = 0; a < 3; a++) {
            double v = xyz[3 * i + a];
            if (!isfinite(v) || !isfinite(rgb[3 * i + a]))
                return G3D_ERR(G3D_ERR_ARG, "init from points: point %lld is not finite", (long long)i);
            if (v < gr.lo[a]) gr.lo[a] = v;
            if (v > hi[a]) hi[a] = v;
        }
    /* cell size for ~2 points per cell of the bounding box, at most ~n cells in all */
    double vol = 1.0, ext[3];
    int flat = 0;
    for (int a = 0; a < 3; a++) {
        ext[a] = hi[a] - gr.lo[a];
        if (ext[a] > 0) vol *= ext[a]; else flat++;
    }
    double cell = flat == 3 ? 1.0 : pow(vol * 2.0 / (double)n, 1.0 / (3 - flat));
    double maxext = fmax(ext[0], fmax(ext[1], ext[2]));
    if (!(cell > 0) || cell < maxext * 1e-6) cell = maxext > 0 ? maxext * 1e-6 : 1.0;
    gr.cell = cell;
    int64_t cells = 1;
    for (int a = 0; a < 3; a++) {
        gr.dim[a] = (int64_t)(ext[a] / cell) + 1;
        cells *= gr.dim[a];
    }
    while (cells > 4 * n + 64) {   /* very flat or elongated clouds: coarsen */
        gr.cell *= 2;
        cells = 1;
        for (int a = 0; a < 3; a++) { gr.dim[a] = (int64_t)(ext[a] / gr.cell) + 1; cells *= gr.dim[a]; }
    }
    gr.start = calloc((size_t)cells + 1, sizeof(int64_t));
    gr.idx = malloc(sizeof(int64_t) * (size_t)n);
    int64_t *cellof = malloc(sizeof(int64_t) * (size_t)n);
    g3d_status rc = G3D_OK;
    if (!gr.start || !gr.idx || !cellof) { rc = G3D_ERR(G3D_ERR_NOMEM, "init from points: out of memory"); goto done; }
    for (int64_t i = 0; i < n; i++) {
        const float *p = xyz + 3 * i;
        cellof[i] = (cell_coord(&gr, p[2], 2) * gr.dim[1] + cell_coord(&gr, p[1], 1)) * gr.dim[0] + cell_coord(&gr, p[0], 0);
        gr.start[cellof[i] + 1]++;
    }
    for (int64_t c = 0; c < cells; c++) gr.start[c + 1] += gr.start[c];
    {
        int64_t *cur = malloc(sizeof(int64_t) * (size_t)cells);
        if (!cur) { rc = G3D_ERR(G3D_ERR_NOMEM, "init from points: out of memory"); goto done; }
        memcpy(cur, gr.start, sizeof(int64_t) * (size_t)cells);
        for (int64_t i = 0; i < n; i++) gr.idx[cur[cellof[i]]++] = i;
        free(cur);
    }
    rc = g3d_gaussians_create(g, n, sh_degree);
    if (rc != G3D_OK) goto done;
    g->n = n;
    const int K = G3D_SH_COEFFS(sh_degree);
    const float logit = logf(0.1f / 0.9f);
#pragma omp parallel for schedule(dynamic, 256)
    for (int64_t i = 0; i < n; i++) {
        double d2 = knn3_mean_d2(&gr, xyz, n, i);
        float ls = (float)log(sqrt(fmax(d2, 1e-7)));
        for (int a = 0; a < 3; a++) {
            g->means[3 * i + a] = xyz[3 * i + a];
            g->log_scales[3 * i + a] = ls;
            g->sh[(size_t)i * K * 3 + a] = (rgb[3 * i + a] - 0.5f) / G3D_SH_C0;
        }
        g->rots[4 * i] = 1.0f;
        g->opacity_logits[i] = logit;
    }
done:
    free(gr.start);
    free(gr.idx);
    free(cellof);
    return rc;
}

g3d_status g3d_gaussians_init_random(g3d_gaussians *g, const g3d_train_view *views, int nviews, int64_t n,
                                     int sh_degree, uint64_t seed)
{
    if (n < 1 || nviews < 1) return G3D_ERR(G3D_ERR_ARG, "random init: %lld points around %d cameras", (long long)n, nviews);
    g3d_vec3 c = g3d_v3(0, 0, 0);
    for (int i = 0; i < nviews; i++) c = g3d_v3_add(c, g3d_mat4_translation(views[i].cam.c2w));
    c = g3d_v3_scale(c, 1.0 / nviews);
    double half = 10.0 * g3d_train_scene_extent(views, nviews) / 1.1;
    float *xyz = g3d_calloc((size_t)n, 3 * sizeof(float), "random points");
    float *rgb = xyz ? g3d_calloc((size_t)n, 3 * sizeof(float), "random points") : NULL;
    if (!xyz || !rgb) {
        free(xyz);
        return G3D_ERR_NOMEM;
    }
    g3d_rng r;
    g3d_rng_seed(&r, seed, 11);
    const double cc[3] = {c.x, c.y, c.z};
    for (int64_t i = 0; i < 3 * n; i++) {
        xyz[i] = (float)(cc[i % 3] + half * (2.0 * g3d_rng_float(&r) - 1.0));
        rgb[i] = 0.5f;
    }
    g3d_status rc = g3d_gaussians_init_from_points(g, xyz, rgb, n, sh_degree);
    free(xyz);
    free(rgb);
    return rc;
}

/* One Gaussian from a pixel footprint: the covariance k^2 (sx sx^T + sy sy^T) in the plane the
 * two steps span (its principal axes from the 2x2 eigenproblem in an orthonormal basis of that
 * plane), and `thin` times the smaller in-plane axis along the normal. */
static void footprint_shape(const float *span, double k, double thin, float *log_scales, float *rot)
{
    g3d_vec3 sx = g3d_v3(span[0], span[1], span[2]), sy = g3d_v3(span[3], span[4], span[5]);
    double a = g3d_v3_norm(sx);
    g3d_vec3 e1 = g3d_v3_scale(sx, 1.0 / a);
    double b1 = g3d_v3_dot(sy, e1);
    g3d_vec3 r = g3d_v3_sub(sy, g3d_v3_scale(e1, b1));
    double b2 = g3d_v3_norm(r);
    if (!(b2 > 1e-9 * a)) {  /* degenerate: the steps are parallel; any vector across */
        g3d_vec3 t = fabs(e1.x) < 0.9 ? g3d_v3(1, 0, 0) : g3d_v3(0, 1, 0);
        r = g3d_v3_sub(t, g3d_v3_scale(e1, g3d_v3_dot(t, e1)));
        b2 = 0;
    }
    g3d_vec3 e2 = g3d_v3_scale(r, 1.0 / g3d_v3_norm(r));
    /* [[a^2 + b1^2, b1 b2], [b1 b2, b2^2]] in (e1, e2) */
    double cxx = a * a + b1 * b1, cxy = b1 * b2, cyy = b2 * b2;
    double mean = 0.5 * (cxx + cyy), diff = 0.5 * (cxx - cyy), rad = sqrt(diff * diff + cxy * cxy);
    double l1 = mean + rad, l2 = fmax(mean - rad, 1e-4 * l1), th = 0.5 * atan2(2 * cxy, cxx - cyy);
    g3d_vec3 u1 = g3d_v3_add(g3d_v3_scale(e1, cos(th)), g3d_v3_scale(e2, sin(th)));
    g3d_vec3 u2 = g3d_v3_cross(g3d_v3_cross(e1, e2), u1), nrm = g3d_v3_cross(u1, u2);
    double s1 = k * sqrt(l1), s2 = k * sqrt(l2);
    log_scales[0] = (float)log(s1);
    log_scales[1] = (float)log(s2);
    log_scales[2] = (float)log(thin * s2);
    g3d_mat4 m = g3d_mat4_identity();
    const g3d_vec3 cols[3] = {u1, u2, nrm};
    for (int c = 0; c < 3; c++) {
        m.m[0][c] = cols[c].x;
        m.m[1][c] = cols[c].y;
        m.m[2][c] = cols[c].z;
    }
    g3d_quat q = g3d_quat_from_mat4(m);
    rot[0] = (float)q.w;
    rot[1] = (float)q.x;
    rot[2] = (float)q.y;
    rot[3] = (float)q.z;
}

g3d_status g3d_gaussians_init_from_footprints(g3d_gaussians *g, const float *xyz, const float *rgb, const float *span,
                                              int64_t n, int sh_degree, const g3d_footprint_init *p)
{
    if (n < 1) return G3D_ERR(G3D_ERR_ARG, "init from footprints: %lld points", (long long)n);
    if (!(p->scale > 0) || !(p->thin > 0) || !(p->opacity > 0 && p->opacity < 1))
        return G3D_ERR(G3D_ERR_ARG, "init from footprints: scale %g, thin %g, opacity %g (need > 0, > 0, in (0, 1))",
                       p->scale, p->thin, p->opacity);
    for (int64_t i = 0; i < n; i++) {
        const float *s = span + 6 * i;
        for (int a = 0; a < 6; a++)
            if (!isfinite(s[a]) || (a < 3 && (!isfinite(xyz[3 * i + a]) || !isfinite(rgb[3 * i + a]))))
                return G3D_ERR(G3D_ERR_ARG, "init from footprints: point %lld is not finite", (long long)i);
        if (!(s[0] * s[0] + s[1] * s[1] + s[2] * s[2] > 0))
            return G3D_ERR(G3D_ERR_ARG, "init from footprints: point %lld has no footprint", (long long)i);
    }
    G3D_TRY(g3d_gaussians_create(g, n, sh_degree));
    g->n = n;
    const int K = G3D_SH_COEFFS(sh_degree);
    const float logit = (float)log(p->opacity / (1 - p->opacity));
#pragma omp parallel for schedule(static)
    for (int64_t i = 0; i < n; i++) {
        footprint_shape(span + 6 * i, p->scale, p->thin, g->log_scales + 3 * i, g->rots + 4 * i);
        for (int a = 0; a < 3; a++) {
            g->means[3 * i + a] = xyz[3 * i + a];
            g->sh[(size_t)i * K * 3 + a] = (rgb[3 * i + a] - 0.5f) / G3D_SH_C0;
        }
        g->opacity_logits[i] = logit;
    }
    return G3D_OK;
}

void g3d_footprint_init_default(g3d_footprint_init *p)
{
    p->scale = 0.5;
    p->thin = 0.2;
    p->opacity = 0.5;
}
