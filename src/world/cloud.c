/* The aggregated point cloud: lifting and z-buffered splat rendering. */
#include "gen3d/cloud.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

g3d_status g3d_cloud_init(g3d_cloud *c)
{
    memset(c, 0, sizeof *c);
    return g3d_cloud_reserve(c, 1024);
}

void g3d_cloud_free(g3d_cloud *c)
{
    if (!c) return;
    free(c->xyz);
    free(c->rgb);
    free(c->size);
    free(c->span);
    free(c->view);
    memset(c, 0, sizeof *c);
}

g3d_status g3d_cloud_reserve(g3d_cloud *c, int64_t n)
{
    if (n <= c->capacity) return G3D_OK;
    int64_t cap = c->capacity ? c->capacity : 1024;
    while (cap < n) cap *= 2;
    float *xyz = realloc(c->xyz, sizeof(float) * 3 * (size_t)cap);
    if (xyz) c->xyz = xyz;
    float *rgb = realloc(c->rgb, sizeof(float) * 3 * (size_t)cap);
    if (rgb) c->rgb = rgb;
    float *size = realloc(c->size, sizeof(float) * (size_t)cap);
    if (size) c->size = size;
    float *span = realloc(c->span, sizeof(float) * 6 * (size_t)cap);
    if (span) c->span = span;
    int32_t *view = realloc(c->view, sizeof(int32_t) * (size_t)cap);
    if (view) c->view = view;
    if (!xyz || !rgb || !size || !span || !view) return G3D_ERR(G3D_ERR_NOMEM, "point cloud: out of memory for %lld points", (long long)cap);
    c->capacity = cap;
    return G3D_OK;
}

/* Neighbouring depths on one surface differ by less than this fraction. */
#define SAME_SURFACE 0.05f

/* World vector from pixel (x, y) to its neighbour one step along (dx, dy): from the
 * neighbour's lifted point when it lies on the same surface (either side), else the step at
 * constant depth (a surface facing the camera). */
static g3d_vec3 pixel_span(const g3d_camera *cam, const g3d_image *depth, int x, int y, int dx, int dy, g3d_vec3 p)
{
    float z = *g3d_image_px(depth, x, y);
    for (int side = 1; side >= -1; side -= 2) {
        int nx = x + side * dx, ny = y + side * dy;
        if (nx < 0 || ny < 0 || nx >= depth->w || ny >= depth->h) continue;
        float zn = *g3d_image_px(depth, nx, ny);
        if (zn > 0 && fabsf(zn - z) < SAME_SURFACE * z)
            return g3d_v3_scale(g3d_v3_sub(g3d_camera_unproject(cam, nx, ny, zn), p), (double)side);
    }
    return g3d_v3_sub(g3d_camera_unproject(cam, x + dx, y + dy, z), p);
}

/* 1 when pixel i is lifted: it has depth and, with a mask, is in it. */
static int liftable(const g3d_image *depth, const g3d_image *mask, size_t i)
{
    return depth->data[i] > 0 && (!mask || mask->data[i] > 0.5f);
}

/* The step (1 or `stride`) pixel (x, y) is lifted with, 0 when it is not lifted: the first
 * pixel of each stride x stride block stands for the block; the others are lifted on their
 * own only when it is not, so that narrow regions keep every pixel. */
static int lift_step(const g3d_image *depth, const g3d_image *mask, int x, int y, int stride)
{
    int w = depth->w;
    if (!liftable(depth, mask, (size_t)y * w + x)) return 0;
    if (stride == 1) return 1;
    int bx = x - x % stride, by = y - y % stride;
    if (bx == x && by == y) return stride;
    return liftable(depth, mask, (size_t)by * w + bx) ? 0 : 1;
}

g3d_status g3d_cloud_lift(g3d_cloud *c, const g3d_image *rgb, const g3d_image *depth, const g3d_camera *cam,
                          const g3d_image *lift_mask, int32_t view, int64_t *added)
{
    return g3d_cloud_lift_sparse(c, rgb, depth, cam, lift_mask, view, 1, added);
}

g3d_status g3d_cloud_lift_sparse(g3d_cloud *c, const g3d_image *rgb, const g3d_image *depth, const g3d_camera *cam,
                                 const g3d_image *lift_mask, int32_t view, int stride, int64_t *added)
{
    int w = cam->K.width, h = cam->K.height;
    if (rgb->w != w || rgb->h != h || rgb->c != 3 || depth->w != w || depth->h != h || depth->c != 1 ||
        (lift_mask && (lift_mask->w != w || lift_mask->h != h)))
        return G3D_ERR(G3D_ERR_MISMATCH, "lift: image %dx%d / depth %dx%d do not match the %dx%d camera", rgb->w, rgb->h,
                       depth->w, depth->h, w, h);
    if (stride < 1 || stride > 16) return G3D_ERR(G3D_ERR_ARG, "lift: stride %d is not in 1..16", stride);
    int64_t n = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) n += lift_step(depth, lift_mask, x, y, stride) > 0;
    G3D_TRY(g3d_cloud_reserve(c, c->n + n));
    double inv_f = 2.0 / (cam->K.fx + cam->K.fy);
    int64_t k = c->n;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            int step = lift_step(depth, lift_mask, x, y, stride);
            if (!step) continue;
            size_t i = (size_t)y * w + x;
            float z = depth->data[i];
            g3d_vec3 p = g3d_camera_unproject(cam, x, y, z);
            g3d_vec3 sx = pixel_span(cam, depth, x, y, step, 0, p), sy = pixel_span(cam, depth, x, y, 0, step, p);
            float *sp = c->span + 6 * k;
            sp[0] = (float)sx.x; sp[1] = (float)sx.y; sp[2] = (float)sx.z;
            sp[3] = (float)sy.x; sp[4] = (float)sy.y; sp[5] = (float)sy.z;
            c->xyz[3 * k] = (float)p.x;
            c->xyz[3 * k + 1] = (float)p.y;
            c->xyz[3 * k + 2] = (float)p.z;
            memcpy(c->rgb + 3 * k, rgb->data + 3 * i, 3 * sizeof(float));
            c->size[k] = (float)(z * inv_f * step);
            c->view[k] = view;
            k++;
        }
    c->n = k;
    if (added) *added = n;
    return G3D_OK;
}

void g3d_cloud_render_params_default(g3d_cloud_render_params *p)
{
    *p = (g3d_cloud_render_params){0.02f, 1.0f, 1};
}

/* The projected footprint of a point: centre (u, v), depth z, and the parallelogram
 * {centre + alpha * a + beta * b : |alpha|, |beta| <= 1} given by the inverse map (m) from
 * pixel offsets to (alpha, beta). x0..y1 bound it in whole pixels. */
typedef struct splat {
    float u, v, z;
    double m[2][2];
    int x0, x1, y0, y1;
} splat;

static int transform(const double R[3][3], const double t[3], const g3d_intrinsics *K, double px, double py, double pz,
                     double *u, double *v, double *z)
{
    double x = R[0][0] * px + R[0][1] * py + R[0][2] * pz + t[0];
    double y = R[1][0] * px + R[1][1] * py + R[1][2] * pz + t[1];
    *z = R[2][0] * px + R[2][1] * py + R[2][2] * pz + t[2];
    if (*z <= 1e-6) return 0;
    *u = K->fx * x / *z + K->cx;
    *v = K->fy * y / *z + K->cy;
    return 1;
}

static int project_splat(const double R[3][3], const double t[3], const g3d_intrinsics *K, const float *p,
                         const float *span, float scale, int w, int h, splat *s)
{
    double u, v, z, u1, v1, z1, u2, v2, z2;
    if (!transform(R, t, K, p[0], p[1], p[2], &u, &v, &z)) return 0;
    /* Half a source pixel in each direction, scaled. */
    double hs = 0.5 * scale;
    double a[2], b[2];
    if (transform(R, t, K, p[0] + hs * span[0], p[1] + hs * span[1], p[2] + hs * span[2], &u1, &v1, &z1) &&
        transform(R, t, K, p[0] + hs * span[3], p[1] + hs * span[4], p[2] + hs * span[5], &u2, &v2, &z2)) {
        a[0] = u1 - u; a[1] = v1 - v;
        b[0] = u2 - u; b[1] = v2 - v;
    } else {
        a[0] = 0.5; a[1] = 0; b[0] = 0; b[1] = 0.5;
    }
    /* A parallelogram seen nearly edge-on would vanish between pixel centres: use its
     * axis-aligned bounding box instead, at least half a pixel each way, so a point always
     * reaches the pixel it falls in. */
    double det = a[0] * b[1] - a[1] * b[0];
    if (fabs(det) < 0.25) {
        double ex = fmax(0.5, fabs(a[0]) + fabs(b[0])), ey = fmax(0.5, fabs(a[1]) + fabs(b[1]));
        a[0] = ex; a[1] = 0;
        b[0] = 0; b[1] = ey;
        det = ex * ey;
    }
    s->m[0][0] = b[1] / det; s->m[0][1] = -b[0] / det;
    s->m[1][0] = -a[1] / det; s->m[1][1] = a[0] / det;
    double ex = fabs(a[0]) + fabs(b[0]), ey = fabs(a[1]) + fabs(b[1]);
    /* A footprint that would cover a large part of the image belongs to a point right in
     * front of the camera: drop it rather than paint over the view. */
    if (ex > 0.25 * w + 8 || ey > 0.25 * h + 8) return 0;
    s->u = (float)u;
    s->v = (float)v;
    s->z = (float)z;
    s->x0 = (int)ceil(u - ex); s->x1 = (int)floor(u + ex);
    s->y0 = (int)ceil(v - ey); s->y1 = (int)floor(v + ey);
    if (s->x1 < 0 || s->y1 < 0 || s->x0 >= w || s->y0 >= h) return 0;
    if (s->x0 < 0) s->x0 = 0;
    if (s->y0 < 0) s->y0 = 0;
    if (s->x1 >= w) s->x1 = w - 1;
    if (s->y1 >= h) s->y1 = h - 1;
    return 1;
}

/* Parallelogram coordinates of pixel (x, y); inside when both are within [-1, 1]. */
static int splat_covers(const splat *s, int x, int y, double *r2)
{
    double dx = x - s->u, dy = y - s->v;
    double al = s->m[0][0] * dx + s->m[0][1] * dy, be = s->m[1][0] * dx + s->m[1][1] * dy;
    *r2 = al * al + be * be;
    return fabs(al) <= 1.0 && fabs(be) <= 1.0;
}

g3d_status g3d_cloud_render(const g3d_cloud *c, const g3d_camera *cam, const g3d_cloud_render_params *p,
                            g3d_image *rgb, g3d_image *depth, g3d_image *mask)
{
    const g3d_intrinsics *K = &cam->K;
    int w = K->width, h = K->height;
    size_t npx = (size_t)w * h;
    g3d_cloud_render_params def;
    g3d_cloud_render_params_default(&def);
    if (!p) p = &def;
    if (w < 1 || h < 1 || w > G3D_MAX_IMAGE_SIDE || h > G3D_MAX_IMAGE_SIDE || !(K->fx > 0) || !(K->fy > 0))
        return G3D_ERR(G3D_ERR_ARG, "render: bad camera (%dx%d, fx %g)", w, h, K->fx);

    float *zmin = malloc(sizeof(float) * npx);
    double *acc = calloc(npx * 5, sizeof(double)); /* r g b z weight */
    if (!zmin || !acc) { free(zmin); free(acc); return G3D_ERR(G3D_ERR_NOMEM, "render: out of memory"); }
    for (size_t i = 0; i < npx; i++) zmin[i] = INFINITY;

    g3d_mat4 w2c = g3d_mat4_inverse_rigid(cam->c2w);
    double R[3][3], t[3];
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) R[i][j] = w2c.m[i][j];
        t[i] = w2c.m[i][3];
    }
    /* Pass 1: nearest depth per pixel. */
    for (int64_t i = 0; i < c->n; i++) {
        splat s;
        double r2;
        if (!project_splat(R, t, K, c->xyz + 3 * i, c->span + 6 * i, p->footprint_scale, w, h, &s)) continue;
        for (int y = s.y0; y <= s.y1; y++)
            for (int x = s.x0; x <= s.x1; x++)
                if (splat_covers(&s, x, y, &r2) && s.z < zmin[(size_t)y * w + x]) zmin[(size_t)y * w + x] = s.z;
    }
    /* Pass 2: blend the points on the front surface, nearer-to-centre points weigh more. */
    float tol = 1.0f + p->depth_tolerance;
    for (int64_t i = 0; i < c->n; i++) {
        splat s;
        double r2;
        if (!project_splat(R, t, K, c->xyz + 3 * i, c->span + 6 * i, p->footprint_scale, w, h, &s)) continue;
        const float *col = c->rgb + 3 * i;
        for (int y = s.y0; y <= s.y1; y++)
            for (int x = s.x0; x <= s.x1; x++) {
                size_t k = (size_t)y * w + x;
                if (!splat_covers(&s, x, y, &r2) || s.z > zmin[k] * tol) continue;
                double wt = 1.0 / (0.05 + r2);
                double *a = acc + 5 * k;
                a[0] += wt * col[0];
                a[1] += wt * col[1];
                a[2] += wt * col[2];
                a[3] += wt * s.z;
                a[4] += wt;
            }
    }
    free(zmin);

    /* Cracks: a hole whose 8 neighbours are all filled at nearly the same depth lies inside
     * one surface (a disocclusion always has a depth step around it). */
    unsigned char *fill = NULL;
    if (p->fill_cracks && (fill = calloc(npx, 1)) != NULL) {
        for (int y = 1; y < h - 1; y++)
            for (int x = 1; x < w - 1; x++) {
                size_t k = (size_t)y * w + x;
                if (acc[5 * k + 4] > 0) continue;
                double lo = INFINITY, hi = 0;
                int ok = 1;
                for (int dy = -1; dy <= 1 && ok; dy++)
                    for (int dx = -1; dx <= 1; dx++) {
                        if (!dx && !dy) continue;
                        const double *a = acc + 5 * (k + (ptrdiff_t)dy * w + dx);
                        if (a[4] <= 0) { ok = 0; break; }
                        double z = a[3] / a[4];
                        lo = fmin(lo, z);
                        hi = fmax(hi, z);
                    }
                if (ok && hi <= lo * tol) fill[k] = 1;
            }
    }

    g3d_status rc = G3D_OK;
    if (rgb && (rc = g3d_image_create(rgb, w, h, 3)) != G3D_OK) goto done;
    if (depth && (rc = g3d_image_create(depth, w, h, 1)) != G3D_OK) goto done;
    if (mask && (rc = g3d_image_create(mask, w, h, 1)) != G3D_OK) goto done;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t k = (size_t)y * w + x;
            double v[4] = {0, 0, 0, 0}, wsum = acc[5 * k + 4];
            int filled = wsum > 0;
            if (filled) {
                for (int j = 0; j < 4; j++) v[j] = acc[5 * k + j] / wsum;
            } else if (fill && fill[k]) {
                /* Average of the 8 neighbours. */
                for (int dy = -1; dy <= 1; dy++)
                    for (int dx = -1; dx <= 1; dx++) {
                        if (!dx && !dy) continue;
                        const double *a = acc + 5 * (k + (ptrdiff_t)dy * w + dx);
                        for (int j = 0; j < 4; j++) v[j] += a[j] / a[4] / 8.0;
                    }
                filled = 1;
            }
            if (rgb) for (int j = 0; j < 3; j++) rgb->data[3 * k + j] = (float)v[j];
            if (depth) depth->data[k] = (float)v[3];
            if (mask) mask->data[k] = (float)filled;
        }
done:
    if (rc != G3D_OK) { g3d_image_free(rgb); g3d_image_free(depth); g3d_image_free(mask); }
    free(fill);
    free(acc);
    return rc;
}

g3d_status g3d_cloud_to_points(const g3d_cloud *c, g3d_points *out)
{
    G3D_TRY(g3d_points_create(out, c->n, 0));
    memcpy(out->xyz, c->xyz, sizeof(float) * 3 * (size_t)c->n);
    for (int64_t i = 0; i < 3 * c->n; i++) out->rgb[i] = (uint8_t)lrintf(255.0f * fminf(1.0f, fmaxf(0.0f, c->rgb[i])));
    return G3D_OK;
}
