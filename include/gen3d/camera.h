/* gen3d/camera.h - vectors, rigid transforms, quaternions and pinhole cameras.
 *
 * CONVENTIONS (the one convention used everywhere inside gen3d)
 *   - Camera axes are OpenCV's: x right, y down, z forward (into the scene).
 *   - A pose is camera-to-world (c2w): p_world = R * p_cam + t, stored as a 4x4 matrix
 *     m[row][col] in double precision, last row (0 0 0 1). world-to-camera = inverse.
 *   - The world frame of a generated scene is the input camera's frame (pose = identity),
 *     in metres. So world "up" is -y and the input camera looks along +z.
 *   - Intrinsics are in pixels. Pixel (i, j) (column i, row j) has its centre at the
 *     continuous coordinate (u, v) = (i, j): OpenCV's convention. A symmetric camera of
 *     width w therefore has cx = (w - 1) / 2. (COLMAP/nerfstudio put centres at i + 0.5;
 *     the transforms.json reader/writer converts.)
 *   - Angles are radians unless a name says _deg.
 *   - Quaternions are (w, x, y, z), unit length, Hamilton product.
 *   - Projection: u = fx * x / z + cx, v = fy * y / z + cy for camera-space (x, y, z), z > 0.
 *
 * Other conventions are converted only at the edges with the functions at the end:
 *   OpenGL / Blender / nerfstudio cameras: x right, y up, z backward  (c2w_gl = c2w_cv * diag(1,-1,-1,1)).
 *
 * All functions are pure and thread-safe; small structs are passed by value.
 */
#ifndef G3D_CAMERA_H
#define G3D_CAMERA_H

#include "gen3d/base.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_vec3 { double x, y, z; } g3d_vec3;
typedef struct g3d_quat { double w, x, y, z; } g3d_quat;
typedef struct g3d_mat4 { double m[4][4]; } g3d_mat4;  /* row-major, m[row][col] */

typedef struct g3d_intrinsics {
    double fx, fy;   /* focal lengths, pixels */
    double cx, cy;   /* principal point, pixels (pixel centres at integers) */
    int width, height;
} g3d_intrinsics;

typedef struct g3d_camera {
    g3d_intrinsics K;
    g3d_mat4 c2w;    /* camera-to-world, OpenCV axes */
} g3d_camera;

/* ---- vectors --------------------------------------------------------------------------- */
static inline g3d_vec3 g3d_v3(double x, double y, double z) { g3d_vec3 v = {x, y, z}; return v; }
static inline g3d_vec3 g3d_v3_add(g3d_vec3 a, g3d_vec3 b) { return g3d_v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline g3d_vec3 g3d_v3_sub(g3d_vec3 a, g3d_vec3 b) { return g3d_v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline g3d_vec3 g3d_v3_scale(g3d_vec3 a, double s) { return g3d_v3(a.x * s, a.y * s, a.z * s); }
static inline double   g3d_v3_dot(g3d_vec3 a, g3d_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline g3d_vec3 g3d_v3_cross(g3d_vec3 a, g3d_vec3 b)
{
    return g3d_v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
double   g3d_v3_norm(g3d_vec3 a);
/* a / |a|; returns a unchanged if |a| == 0. */
g3d_vec3 g3d_v3_normalize(g3d_vec3 a);

/* ---- rigid transforms ------------------------------------------------------------------ */
g3d_mat4 g3d_mat4_identity(void);
g3d_mat4 g3d_mat4_mul(g3d_mat4 a, g3d_mat4 b);                /* a * b */
/* Inverse of a rigid transform [R t; 0 1] (R orthonormal): [R^T -R^T t; 0 1]. */
g3d_mat4 g3d_mat4_inverse_rigid(g3d_mat4 a);
/* General 4x4 inverse; returns 0 if singular (out untouched). */
int      g3d_mat4_inverse(g3d_mat4 a, g3d_mat4 *out);
g3d_vec3 g3d_mat4_point(g3d_mat4 a, g3d_vec3 p);              /* R p + t */
g3d_vec3 g3d_mat4_dir(g3d_mat4 a, g3d_vec3 d);                /* R d */
g3d_vec3 g3d_mat4_translation(g3d_mat4 a);
/* Builds [R(q) t; 0 1]. */
g3d_mat4 g3d_mat4_from_rt(g3d_quat q, g3d_vec3 t);
/* Camera-to-world pose at `eye` looking at `target`, image "up" along `up` (OpenCV camera:
 * the camera's -y axis is aligned as closely as possible with `up`). */
g3d_mat4 g3d_mat4_look_at(g3d_vec3 eye, g3d_vec3 target, g3d_vec3 up);
/* Rotation by `angle` about unit `axis`, no translation. */
g3d_mat4 g3d_mat4_rotation(g3d_vec3 axis, double angle);
/* Largest |a_ij - b_ij|. */
double   g3d_mat4_max_abs_diff(g3d_mat4 a, g3d_mat4 b);

/* ---- quaternions ----------------------------------------------------------------------- */
g3d_quat g3d_quat_normalize(g3d_quat q);
g3d_quat g3d_quat_mul(g3d_quat a, g3d_quat b);
g3d_quat g3d_quat_from_axis_angle(g3d_vec3 axis, double angle);
/* Rotation part of m (assumed orthonormal) as a unit quaternion with w >= 0. */
g3d_quat g3d_quat_from_mat4(g3d_mat4 m);
/* 3x3 rotation of a unit quaternion, written into the rotation block of an identity 4x4. */
g3d_mat4 g3d_quat_to_mat4(g3d_quat q);
/* Spherical interpolation along the shorter arc, t in [0, 1]. */
g3d_quat g3d_quat_slerp(g3d_quat a, g3d_quat b, double t);
/* Pose interpolation: slerp of rotations, linear interpolation of camera centres. */
g3d_mat4 g3d_pose_interp(g3d_mat4 a, g3d_mat4 b, double t);

/* ---- intrinsics ------------------------------------------------------------------------ */
g3d_intrinsics g3d_intrinsics_make(double fx, double fy, double cx, double cy, int width, int height);
/* Square pixels, principal point at the image centre ((w-1)/2, (h-1)/2), horizontal field of
 * view `fov_x_deg` degrees. */
g3d_intrinsics g3d_intrinsics_from_fov(double fov_x_deg, int width, int height);
double g3d_intrinsics_fov_x_deg(g3d_intrinsics K);
double g3d_intrinsics_fov_y_deg(g3d_intrinsics K);
/* Intrinsics for the same camera resampled to new_w x new_h (scale fx, fy, and the pixel
 * grid, keeping the continuous image rectangle: c' = (c + 0.5) * s - 0.5). */
g3d_intrinsics g3d_intrinsics_resize(g3d_intrinsics K, int new_w, int new_h);

/* ---- projection ------------------------------------------------------------------------ */
/* World point -> pixel (u, v) and camera depth z. Returns 1 if z > 0, else 0 (u, v untouched). */
int      g3d_camera_project(const g3d_camera *cam, g3d_vec3 p_world, double *u, double *v, double *z);
/* Pixel (u, v) at camera depth z -> world point. */
g3d_vec3 g3d_camera_unproject(const g3d_camera *cam, double u, double v, double z);
/* Unit ray direction in world space through pixel (u, v). */
g3d_vec3 g3d_camera_ray(const g3d_camera *cam, double u, double v);
g3d_vec3 g3d_camera_center(const g3d_camera *cam);

/* ---- conventions at the edges ---------------------------------------------------------- */
/* OpenCV c2w <-> OpenGL/Blender/nerfstudio c2w (flip the camera's y and z axes). Each is its
 * own inverse; both names exist so call sites say which way they go. */
g3d_mat4 g3d_pose_opencv_to_opengl(g3d_mat4 c2w_cv);
g3d_mat4 g3d_pose_opengl_to_opencv(g3d_mat4 c2w_gl);
/* A world-frame change that maps our y-down scene frame to a y-up frame (rotate 180 degrees
 * about x: (x, y, z) -> (x, -y, -z)); applied to poses as W * c2w. Its own inverse. */
g3d_mat4 g3d_world_flip_yz(void);

#ifdef __cplusplus
}
#endif
#endif /* G3D_CAMERA_H */
