/* Vectors, rigid transforms, quaternions and the pinhole camera (see gen3d/camera.h). */
#include "gen3d/camera.h"

#include <math.h>
#include <string.h>

double g3d_v3_norm(g3d_vec3 a) { return sqrt(g3d_v3_dot(a, a)); }

g3d_vec3 g3d_v3_normalize(g3d_vec3 a)
{
    double n = g3d_v3_norm(a);
    return n > 0 ? g3d_v3_scale(a, 1.0 / n) : a;
}

g3d_mat4 g3d_mat4_identity(void)
{
    g3d_mat4 r;
    memset(&r, 0, sizeof r);
    for (int i = 0; i < 4; i++) r.m[i][i] = 1.0;
    return r;
}

g3d_mat4 g3d_mat4_mul(g3d_mat4 a, g3d_mat4 b)
{
    g3d_mat4 r;
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) {
            double s = 0;
            for (int k = 0; k < 4; k++) s += a.m[i][k] * b.m[k][j];
            r.m[i][j] = s;
        }
    return r;
}

g3d_mat4 g3d_mat4_inverse_rigid(g3d_mat4 a)
{
    g3d_mat4 r = g3d_mat4_identity();
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) r.m[i][j] = a.m[j][i];
    for (int i = 0; i < 3; i++)
        r.m[i][3] = -(r.m[i][0] * a.m[0][3] + r.m[i][1] * a.m[1][3] + r.m[i][2] * a.m[2][3]);
    return r;
}

int g3d_mat4_inverse(g3d_mat4 a, g3d_mat4 *out)
{
    /* Gauss-Jordan with partial pivoting on [a | I]. */
    double w[4][8];
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 8; j++) w[i][j] = j < 4 ? a.m[i][j] : (j - 4 == i);
    for (int c = 0; c < 4; c++) {
        int p = c;
        for (int r = c + 1; r < 4; r++)
            if (fabs(w[r][c]) > fabs(w[p][c])) p = r;
        if (fabs(w[p][c]) < 1e-300) return 0;
        if (p != c)
            for (int j = 0; j < 8; j++) { double t = w[c][j]; w[c][j] = w[p][j]; w[p][j] = t; }
        double inv = 1.0 / w[c][c];
        for (int j = 0; j < 8; j++) w[c][j] *= inv;
        for (int r = 0; r < 4; r++) {
            if (r == c) continue;
            double f = w[r][c];
            for (int j = 0; j < 8; j++) w[r][j] -= f * w[c][j];
        }
    }
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) out->m[i][j] = w[i][j + 4];
    return 1;
}

g3d_vec3 g3d_mat4_point(g3d_mat4 a, g3d_vec3 p)
{
    return g3d_v3(a.m[0][0] * p.x + a.m[0][1] * p.y + a.m[0][2] * p.z + a.m[0][3],
                  a.m[1][0] * p.x + a.m[1][1] * p.y + a.m[1][2] * p.z + a.m[1][3],
                  a.m[2][0] * p.x + a.m[2][1] * p.y + a.m[2][2] * p.z + a.m[2][3]);
}

g3d_vec3 g3d_mat4_dir(g3d_mat4 a, g3d_vec3 d)
{
    return g3d_v3(a.m[0][0] * d.x + a.m[0][1] * d.y + a.m[0][2] * d.z,
                  a.m[1][0] * d.x + a.m[1][1] * d.y + a.m[1][2] * d.z,
                  a.m[2][0] * d.x + a.m[2][1] * d.y + a.m[2][2] * d.z);
}

g3d_vec3 g3d_mat4_translation(g3d_mat4 a) { return g3d_v3(a.m[0][3], a.m[1][3], a.m[2][3]); }

g3d_mat4 g3d_mat4_from_rt(g3d_quat q, g3d_vec3 t)
{
    g3d_mat4 r = g3d_quat_to_mat4(q);
    r.m[0][3] = t.x;
    r.m[1][3] = t.y;
    r.m[2][3] = t.z;
    return r;
}

g3d_mat4 g3d_mat4_look_at(g3d_vec3 eye, g3d_vec3 target, g3d_vec3 up)
{
    g3d_vec3 z = g3d_v3_normalize(g3d_v3_sub(target, eye));
    g3d_vec3 x = g3d_v3_cross(g3d_v3_scale(up, -1.0), z); /* x = y * z with camera y = -up */
    if (g3d_v3_norm(x) < 1e-12) {
        /* Looking along `up`: any perpendicular x will do; pick a stable one. */
        g3d_vec3 alt = fabs(z.x) < 0.9 ? g3d_v3(1, 0, 0) : g3d_v3(0, 1, 0);
        x = g3d_v3_cross(alt, z);
    }
    x = g3d_v3_normalize(x);
    g3d_vec3 y = g3d_v3_cross(z, x);
    g3d_mat4 r = g3d_mat4_identity();
    r.m[0][0] = x.x; r.m[0][1] = y.x; r.m[0][2] = z.x; r.m[0][3] = eye.x;
    r.m[1][0] = x.y; r.m[1][1] = y.y; r.m[1][2] = z.y; r.m[1][3] = eye.y;
    r.m[2][0] = x.z; r.m[2][1] = y.z; r.m[2][2] = z.z; r.m[2][3] = eye.z;
    return r;
}

g3d_mat4 g3d_mat4_rotation(g3d_vec3 axis, double angle)
{
    return g3d_quat_to_mat4(g3d_quat_from_axis_angle(axis, angle));
}

double g3d_mat4_max_abs_diff(g3d_mat4 a, g3d_mat4 b)
{
    double d = 0;
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) d = fmax(d, fabs(a.m[i][j] - b.m[i][j]));
    return d;
}

g3d_quat g3d_quat_normalize(g3d_quat q)
{
    double n = sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
    if (n <= 0) { g3d_quat id = {1, 0, 0, 0}; return id; }
    g3d_quat r = {q.w / n, q.x / n, q.y / n, q.z / n};
    return r;
}

g3d_quat g3d_quat_mul(g3d_quat a, g3d_quat b)
{
    g3d_quat r = {
        a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z,
        a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
        a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
        a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w,
    };
    return r;
}

g3d_quat g3d_quat_from_axis_angle(g3d_vec3 axis, double angle)
{
    g3d_vec3 a = g3d_v3_normalize(axis);
    double s = sin(0.5 * angle);
    g3d_quat q = {cos(0.5 * angle), a.x * s, a.y * s, a.z * s};
    return q;
}

g3d_quat g3d_quat_from_mat4(g3d_mat4 m)
{
    /* Shepperd's method: pick the largest diagonal term for numerical stability. */
    double tr = m.m[0][0] + m.m[1][1] + m.m[2][2];
    g3d_quat q;
    if (tr > 0) {
        double s = sqrt(tr + 1.0) * 2;
        q.w = 0.25 * s;
        q.x = (m.m[2][1] - m.m[1][2]) / s;
        q.y = (m.m[0][2] - m.m[2][0]) / s;
        q.z = (m.m[1][0] - m.m[0][1]) / s;
    } else if (m.m[0][0] > m.m[1][1] && m.m[0][0] > m.m[2][2]) {
        double s = sqrt(1.0 + m.m[0][0] - m.m[1][1] - m.m[2][2]) * 2;
        q.w = (m.m[2][1] - m.m[1][2]) / s;
        q.x = 0.25 * s;
        q.y = (m.m[0][1] + m.m[1][0]) / s;
        q.z = (m.m[0][2] + m.m[2][0]) / s;
    } else if (m.m[1][1] > m.m[2][2]) {
        double s = sqrt(1.0 + m.m[1][1] - m.m[0][0] - m.m[2][2]) * 2;
        q.w = (m.m[0][2] - m.m[2][0]) / s;
        q.x = (m.m[0][1] + m.m[1][0]) / s;
        q.y = 0.25 * s;
        q.z = (m.m[1][2] + m.m[2][1]) / s;
    } else {
        double s = sqrt(1.0 + m.m[2][2] - m.m[0][0] - m.m[1][1]) * 2;
        q.w = (m.m[1][0] - m.m[0][1]) / s;
        q.x = (m.m[0][2] + m.m[2][0]) / s;
        q.y = (m.m[1][2] + m.m[2][1]) / s;
        q.z = 0.25 * s;
    }
    q = g3d_quat_normalize(q);
    if (q.w < 0) { q.w = -q.w; q.x = -q.x; q.y = -q.y; q.z = -q.z; }
    return q;
}

g3d_mat4 g3d_quat_to_mat4(g3d_quat q)
{
    g3d_mat4 r = g3d_mat4_identity();
    double w = q.w, x = q.x, y = q.y, z = q.z;
    r.m[0][0] = 1 - 2 * (y * y + z * z); r.m[0][1] = 2 * (x * y - w * z);     r.m[0][2] = 2 * (x * z + w * y);
    r.m[1][0] = 2 * (x * y + w * z);     r.m[1][1] = 1 - 2 * (x * x + z * z); r.m[1][2] = 2 * (y * z - w * x);
    r.m[2][0] = 2 * (x * z - w * y);     r.m[2][1] = 2 * (y * z + w * x);     r.m[2][2] = 1 - 2 * (x * x + y * y);
    return r;
}

g3d_quat g3d_quat_slerp(g3d_quat a, g3d_quat b, double t)
{
    double d = a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z;
    g3d_quat r;
    if (d < 0) { d = -d; b.w = -b.w; b.x = -b.x; b.y = -b.y; b.z = -b.z; }
    if (d > 0.9995) {
        /* Nearly parallel: linear interpolation avoids dividing by sin(~0). */
        r.w = a.w + t * (b.w - a.w); r.x = a.x + t * (b.x - a.x);
        r.y = a.y + t * (b.y - a.y); r.z = a.z + t * (b.z - a.z);
        return g3d_quat_normalize(r);
    }
    double th = acos(d), s = sin(th);
    double wa = sin((1 - t) * th) / s, wb = sin(t * th) / s;
    r.w = wa * a.w + wb * b.w; r.x = wa * a.x + wb * b.x;
    r.y = wa * a.y + wb * b.y; r.z = wa * a.z + wb * b.z;
    return g3d_quat_normalize(r);
}

g3d_mat4 g3d_pose_interp(g3d_mat4 a, g3d_mat4 b, double t)
{
    g3d_quat q = g3d_quat_slerp(g3d_quat_from_mat4(a), g3d_quat_from_mat4(b), t);
    g3d_vec3 ta = g3d_mat4_translation(a), tb = g3d_mat4_translation(b);
    return g3d_mat4_from_rt(q, g3d_v3_add(ta, g3d_v3_scale(g3d_v3_sub(tb, ta), t)));
}

g3d_intrinsics g3d_intrinsics_make(double fx, double fy, double cx, double cy, int width, int height)
{
    g3d_intrinsics K = {fx, fy, cx, cy, width, height};
    return K;
}

g3d_intrinsics g3d_intrinsics_from_fov(double fov_x_deg, int width, int height)
{
    double f = 0.5 * width / tan(0.5 * fov_x_deg * M_PI / 180.0);
    return g3d_intrinsics_make(f, f, 0.5 * (width - 1), 0.5 * (height - 1), width, height);
}

double g3d_intrinsics_fov_x_deg(g3d_intrinsics K) { return 2.0 * atan(0.5 * K.width / K.fx) * 180.0 / M_PI; }
double g3d_intrinsics_fov_y_deg(g3d_intrinsics K) { return 2.0 * atan(0.5 * K.height / K.fy) * 180.0 / M_PI; }

g3d_intrinsics g3d_intrinsics_resize(g3d_intrinsics K, int new_w, int new_h)
{
    double sx = (double)new_w / K.width, sy = (double)new_h / K.height;
    return g3d_intrinsics_make(K.fx * sx, K.fy * sy, (K.cx + 0.5) * sx - 0.5, (K.cy + 0.5) * sy - 0.5, new_w, new_h);
}

int g3d_camera_project(const g3d_camera *cam, g3d_vec3 p_world, double *u, double *v, double *z)
{
    g3d_vec3 pc = g3d_mat4_point(g3d_mat4_inverse_rigid(cam->c2w), p_world);
    *z = pc.z;
    if (pc.z <= 0) return 0;
    *u = cam->K.fx * pc.x / pc.z + cam->K.cx;
    *v = cam->K.fy * pc.y / pc.z + cam->K.cy;
    return 1;
}

g3d_vec3 g3d_camera_unproject(const g3d_camera *cam, double u, double v, double z)
{
    g3d_vec3 pc = g3d_v3((u - cam->K.cx) / cam->K.fx * z, (v - cam->K.cy) / cam->K.fy * z, z);
    return g3d_mat4_point(cam->c2w, pc);
}

g3d_vec3 g3d_camera_ray(const g3d_camera *cam, double u, double v)
{
    g3d_vec3 d = g3d_v3((u - cam->K.cx) / cam->K.fx, (v - cam->K.cy) / cam->K.fy, 1.0);
    return g3d_v3_normalize(g3d_mat4_dir(cam->c2w, d));
}

g3d_vec3 g3d_camera_center(const g3d_camera *cam) { return g3d_mat4_translation(cam->c2w); }

g3d_mat4 g3d_pose_opencv_to_opengl(g3d_mat4 c2w)
{
    for (int i = 0; i < 3; i++) { c2w.m[i][1] = -c2w.m[i][1]; c2w.m[i][2] = -c2w.m[i][2]; }
    return c2w;
}

g3d_mat4 g3d_pose_opengl_to_opencv(g3d_mat4 c2w) { return g3d_pose_opencv_to_opengl(c2w); }

g3d_mat4 g3d_world_flip_yz(void)
{
    g3d_mat4 w = g3d_mat4_identity();
    w.m[1][1] = -1;
    w.m[2][2] = -1;
    return w;
}
