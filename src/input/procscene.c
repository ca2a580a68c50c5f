/* The procedural room: geometry, textures, and a one-ray-per-pixel tracer. */
#include "gen3d/procscene.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define ROOM_X 3.0
#define ROOM_Y 1.5
#define ROOM_Z0 -1.0
#define ROOM_Z1 7.0
#define FAR_Z 25.0
/* Window in the back wall. */
#define WIN_X0 -1.2
#define WIN_X1 1.2
#define WIN_Y0 -1.0
#define WIN_Y1 0.3

typedef struct box { g3d_vec3 lo, hi; int id; float color[3]; } box;
typedef struct sphere { g3d_vec3 c; double r; int id; float color[3]; } sphere;

static const box g_boxes[] = {
    {{-1.5, 0.45, 2.1}, {-0.7, 1.5, 2.8}, G3D_PROC_NEAR_BOX, {0.80, 0.30, 0.20}},
    {{1.0, 0.3, 4.4}, {2.1, 1.5, 5.3}, G3D_PROC_BACK_BOX, {0.25, 0.45, 0.75}},
};
static const sphere g_spheres[] = {
    {{0.75, 1.05, 2.3}, 0.45, G3D_PROC_NEAR_SPHERE, {0.90, 0.80, 0.25}},
    {{-1.9, 1.0, 5.6}, 0.5, G3D_PROC_BACK_SPHERE, {0.35, 0.70, 0.35}},
};
static const g3d_vec3 g_light = {0.5, -1.2, 2.5};

int g3d_procscene_is_near_object(int id) { return id >= 10 && id < 20; }

g3d_camera g3d_procscene_default_camera(int w, int h)
{
    g3d_camera c = {g3d_intrinsics_from_fov(70.0, w, h), g3d_mat4_identity()};
    return c;
}

g3d_camera g3d_procscene_arc_camera(int i, int n, int w, int h)
{
    double t = n > 1 ? (double)i / (n - 1) * 2.0 - 1.0 : 0.0;
    g3d_vec3 eye = g3d_v3(0.6 * t, -0.15 * sin(3.0 * t), 0.25 * (1.0 - t * t));
    g3d_camera c = {g3d_intrinsics_from_fov(70.0, w, h),
                    g3d_mat4_look_at(eye, g3d_v3(0.15 * t, 0.4, 4.0), g3d_v3(0, -1, 0))};
    return c;
}

/* ---- textures ------------------------------------------------------------------------------ */

static double hash2(int x, int y, int s)
{
    uint32_t h = (uint32_t)x * 374761393u + (uint32_t)y * 668265263u + (uint32_t)s * 2246822519u;
    h = (h ^ (h >> 13)) * 1274126177u;
    return (double)((h ^ (h >> 16)) & 0xffffff) / 16777215.0;
}

/* Smooth value noise in [0, 1]. */
static double vnoise(double x, double y, int s)
{
    int xi = (int)floor(x), yi = (int)floor(y);
    double fx = x - xi, fy = y - yi;
    fx = fx * fx * (3 - 2 * fx);
    fy = fy * fy * (3 - 2 * fy);
    double a = hash2(xi, yi, s), b = hash2(xi + 1, yi, s), c = hash2(xi, yi + 1, s), d = hash2(xi + 1, yi + 1, s);
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy;
}

static double fbm(double x, double y, int s)
{
    return 0.5 * vnoise(x, y, s) + 0.3 * vnoise(2.1 * x, 2.1 * y, s + 1) + 0.2 * vnoise(4.3 * x, 4.3 * y, s + 2);
}

static void set3(float *c, double r, double g, double b) { c[0] = (float)r; c[1] = (float)g; c[2] = (float)b; }

/* Albedo of the room surfaces at point p with outward normal axis `axis` (0 x, 1 y, 2 z). */
static void room_albedo(g3d_vec3 p, int axis, double side, float *c)
{
    if (axis == 1 && side > 0) { /* floor: wooden checker */
        int k = ((int)floor(p.x / 0.5) + (int)floor(p.z / 0.5)) & 1;
        double n = fbm(p.x * 3, p.z * 12, 3);
        if (k) set3(c, 0.55 + 0.2 * n, 0.38 + 0.15 * n, 0.22 + 0.1 * n);
        else set3(c, 0.35 + 0.2 * n, 0.22 + 0.12 * n, 0.12 + 0.08 * n);
    } else if (axis == 1) { /* ceiling: light grid */
        double gx = fabs(p.x / 0.75 - floor(p.x / 0.75 + 0.5)), gz = fabs(p.z / 0.75 - floor(p.z / 0.75 + 0.5));
        double line = gx < 0.03 || gz < 0.03 ? 0.7 : 0.92;
        set3(c, line, line, line * 0.97);
    } else { /* walls: vertical stripes with noise, a different tint per wall */
        double u = axis == 0 ? p.z : p.x;
        double stripe = 0.5 + 0.5 * sin(u * 2 * M_PI / 0.4);
        double n = fbm(u * 4, p.y * 4, axis * 7 + (side > 0));
        double base[3] = {0.75, 0.70, 0.60};
        if (axis == 0 && side < 0) { base[0] = 0.55; base[1] = 0.68; base[2] = 0.75; }
        if (axis == 0 && side > 0) { base[0] = 0.78; base[1] = 0.62; base[2] = 0.62; }
        double m = 0.8 + 0.12 * stripe + 0.15 * (n - 0.5);
        set3(c, base[0] * m, base[1] * m, base[2] * m);
    }
}

static void far_albedo(g3d_vec3 p, float *c)
{
    double hills = -2.0 + 3.0 * fbm(p.x * 0.15, 0.0, 11);
    if (p.y < hills) { /* sky above the hills (y down) */
        double t = fmin(1.0, fmax(0.0, (-p.y - 2) / 12));
        double cl = fbm(p.x * 0.2, p.y * 0.5, 13);
        set3(c, 0.55 + 0.25 * cl - 0.2 * t, 0.70 + 0.15 * cl - 0.1 * t, 0.95);
    } else {
        double n = fbm(p.x * 0.8, p.y * 0.8, 17);
        set3(c, 0.20 + 0.25 * n, 0.45 + 0.25 * n, 0.15 + 0.1 * n);
    }
}

/* ---- tracing ------------------------------------------------------------------------------- */

typedef struct hit { double t; g3d_vec3 n; int id; int kind; int index; int axis; double side; } hit;

static void try_box(const box *b, g3d_vec3 o, g3d_vec3 d, hit *h)
{
    double t0 = -1e30, t1 = 1e30;
    int axis = 0;
    double sgn = 0;
    double oo[3] = {o.x, o.y, o.z}, dd[3] = {d.x, d.y, d.z}, lo[3] = {b->lo.x, b->lo.y, b->lo.z}, hi[3] = {b->hi.x, b->hi.y, b->hi.z};
    for (int k = 0; k < 3; k++) {
        if (fabs(dd[k]) < 1e-15) {
            if (oo[k] < lo[k] || oo[k] > hi[k]) return;
            continue;
        }
        double a = (lo[k] - oo[k]) / dd[k], c = (hi[k] - oo[k]) / dd[k];
        double s = -1;
        if (a > c) { double tmp = a; a = c; c = tmp; s = 1; }
        if (a > t0) { t0 = a; axis = k; sgn = s; }
        if (c < t1) t1 = c;
    }
    if (t0 > t1 || t0 <= 1e-6 || t0 >= h->t) return;
    h->t = t0;
    h->n = g3d_v3(axis == 0 ? sgn : 0, axis == 1 ? sgn : 0, axis == 2 ? sgn : 0);
    h->id = b->id;
    h->kind = 1;
    h->index = (int)(b - g_boxes);
    h->axis = axis;
}

static void try_sphere(const sphere *s, g3d_vec3 o, g3d_vec3 d, hit *h)
{
    g3d_vec3 oc = g3d_v3_sub(o, s->c);
    double b = g3d_v3_dot(oc, d), c = g3d_v3_dot(oc, oc) - s->r * s->r, disc = b * b - c;
    if (disc < 0) return;
    double t = -b - sqrt(disc);
    if (t <= 1e-6 || t >= h->t) return;
    h->t = t;
    h->n = g3d_v3_scale(g3d_v3_sub(g3d_v3_add(o, g3d_v3_scale(d, t)), s->c), 1.0 / s->r);
    h->id = s->id;
    h->kind = 2;
    h->index = (int)(s - g_spheres);
}

/* Room walls are one-sided planes facing inwards; the back wall has the window. */
static void try_room(g3d_vec3 o, g3d_vec3 d, hit *h)
{
    static const double pos[6] = {-ROOM_X, ROOM_X, -ROOM_Y, ROOM_Y, ROOM_Z0, ROOM_Z1};
    double oo[3] = {o.x, o.y, o.z}, dd[3] = {d.x, d.y, d.z};
    for (int f = 0; f < 6; f++) {
        int axis = f / 2;
        double side = f % 2 ? 1.0 : -1.0;
        if (dd[axis] * side <= 0) continue; /* moving away from this wall, or seeing its back */
        double t = (pos[f] - oo[axis]) / dd[axis];
        if (t <= 1e-6 || t >= h->t) continue;
        g3d_vec3 p = g3d_v3_add(o, g3d_v3_scale(d, t));
        double pp[3] = {p.x, p.y, p.z};
        int inside = 1;
        for (int k = 0; k < 3; k++)
            if (k != axis && (pp[k] < pos[2 * k] - 1e-9 || pp[k] > pos[2 * k + 1] + 1e-9)) inside = 0;
        if (!inside) continue;
        if (f == 5 && p.x > WIN_X0 && p.x < WIN_X1 && p.y > WIN_Y0 && p.y < WIN_Y1) continue; /* the window */
        h->t = t;
        h->n = g3d_v3(axis == 0 ? -side : 0, axis == 1 ? -side : 0, axis == 2 ? -side : 0);
        h->id = G3D_PROC_ROOM;
        h->kind = 0;
        h->axis = axis;
        h->side = side;
    }
    if (d.z > 0) {
        double t = (FAR_Z - o.z) / d.z;
        if (t > 1e-6 && t < h->t) {
            h->t = t;
            h->n = g3d_v3(0, 0, -1);
            h->id = G3D_PROC_FAR;
            h->kind = 3;
        }
    }
}

static void shade(g3d_vec3 o, g3d_vec3 d, float *rgb, double *t_out, int *id_out)
{
    hit h;
    memset(&h, 0, sizeof h);
    h.t = 1e30;
    try_room(o, d, &h);
    for (size_t i = 0; i < sizeof g_boxes / sizeof *g_boxes; i++) try_box(&g_boxes[i], o, d, &h);
    for (size_t i = 0; i < sizeof g_spheres / sizeof *g_spheres; i++) try_sphere(&g_spheres[i], o, d, &h);
    *id_out = h.t < 1e29 ? h.id : G3D_PROC_NONE;
    *t_out = h.t < 1e29 ? h.t : 0;
    if (h.t >= 1e29) { set3(rgb, 0, 0, 0); return; }
    g3d_vec3 p = g3d_v3_add(o, g3d_v3_scale(d, h.t));
    float alb[3];
    if (h.kind == 0) room_albedo(p, h.axis, h.side, alb);
    else if (h.kind == 3) { far_albedo(p, alb); memcpy(rgb, alb, sizeof alb); return; } /* lit by daylight */
    else if (h.kind == 1) {
        const box *b = &g_boxes[h.index];
        double u = h.axis == 0 ? p.z : p.x, v = h.axis == 1 ? p.z : p.y;
        int k = ((int)floor(u / 0.1) + (int)floor(v / 0.1)) & 1;
        double m = (k ? 1.0 : 0.75) * (0.85 + 0.3 * fbm(u * 6, v * 6, 21));
        set3(alb, b->color[0] * m, b->color[1] * m, b->color[2] * m);
    } else {
        const sphere *s = &g_spheres[h.index];
        g3d_vec3 q = g3d_v3_sub(p, s->c);
        double lat = asin(fmax(-1.0, fmin(1.0, q.y / s->r))), lon = atan2(q.z, q.x);
        double stripe = 0.5 + 0.5 * sin(lat * 10) * cos(lon * 6);
        double m = 0.7 + 0.3 * stripe;
        set3(alb, s->color[0] * m, s->color[1] * m, s->color[2] * m);
    }
    g3d_vec3 l = g3d_v3_sub(g_light, p);
    double dist = g3d_v3_norm(l);
    l = g3d_v3_scale(l, 1.0 / dist);
    double diff = fmax(0.0, g3d_v3_dot(h.n, l)) * 6.0 / (1.0 + dist * dist);
    double light = 0.35 + 0.65 * fmin(diff, 1.2);
    for (int k = 0; k < 3; k++) rgb[k] = (float)fmin(1.0, alb[k] * light);
}

g3d_status g3d_procscene_render(const g3d_camera *cam, g3d_image *rgb, g3d_image *depth, g3d_image *ids)
{
    int w = cam->K.width, h = cam->K.height;
    g3d_image tmp_rgb = {0};
    if (rgb) G3D_TRY(g3d_image_create(rgb, w, h, 3));
    else G3D_TRY(g3d_image_create(&tmp_rgb, w, h, 3));
    if (depth && g3d_image_create(depth, w, h, 1) != G3D_OK) goto fail;
    if (ids && g3d_image_create(ids, w, h, 1) != G3D_OK) goto fail;
    g3d_image *out = rgb ? rgb : &tmp_rgb;
    g3d_vec3 o = g3d_camera_center(cam), fwd = g3d_mat4_dir(cam->c2w, g3d_v3(0, 0, 1));
#pragma omp parallel for schedule(dynamic, 4)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            g3d_vec3 d = g3d_camera_ray(cam, x, y);
            double t;
            int id;
            shade(o, d, g3d_image_px(out, x, y), &t, &id);
            if (depth) *g3d_image_px(depth, x, y) = (float)(t * g3d_v3_dot(d, fwd));
            if (ids) *g3d_image_px(ids, x, y) = (float)id;
        }
    g3d_image_free(&tmp_rgb);
    return G3D_OK;
fail:
    g3d_image_free(rgb);
    g3d_image_free(depth);
    g3d_image_free(&tmp_rgb);
    return G3D_ERR_NOMEM;
}

g3d_status g3d_procscene_points(int n_views, int w, int h, int stride, g3d_points *out)
{
    int64_t per = (int64_t)((w + stride - 1) / stride) * ((h + stride - 1) / stride), n = 0;
    memset(out, 0, sizeof *out);
    if (n_views < 1 || stride < 1) return G3D_ERR(G3D_ERR_ARG, "procscene points: need >= 1 view and stride >= 1");
    G3D_TRY(g3d_points_create(out, per * n_views, 0));
    for (int v = 0; v < n_views; v++) {
        g3d_camera cam = g3d_procscene_arc_camera(v, n_views, w, h);
        g3d_image rgb, depth;
        g3d_status rc = g3d_procscene_render(&cam, &rgb, &depth, NULL);
        if (rc != G3D_OK) { g3d_points_free(out); return rc; }
        for (int y = stride / 2; y < h; y += stride)
            for (int x = stride / 2; x < w; x += stride) {
                float z = *g3d_image_px(&depth, x, y);
                if (z <= 0 || z > ROOM_Z1 + 1) continue; /* the far landscape is left to the background */
                g3d_vec3 p = g3d_camera_unproject(&cam, x, y, z);
                const float *c = g3d_image_px(&rgb, x, y);
                out->xyz[3 * n] = (float)p.x;
                out->xyz[3 * n + 1] = (float)p.y;
                out->xyz[3 * n + 2] = (float)p.z;
                for (int k = 0; k < 3; k++) out->rgb[3 * n + k] = (uint8_t)lrintf(255.0f * c[k]);
                n++;
            }
        g3d_image_free(&rgb);
        g3d_image_free(&depth);
    }
    out->n = n;
    return G3D_OK;
}
