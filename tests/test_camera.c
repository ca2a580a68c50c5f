/* Camera math: projection round trips, rigid inverses, quaternions, slerp, conventions. */
#include "testutil.h"
#include "gen3d/camera.h"

static g3d_mat4 random_pose(g3d_rng *r)
{
    g3d_vec3 axis = g3d_v3(g3d_rng_normal(r), g3d_rng_normal(r), g3d_rng_normal(r));
    g3d_quat q = g3d_quat_from_axis_angle(axis, 3.0 * g3d_rng_float(r));
    return g3d_mat4_from_rt(q, g3d_v3(g3d_rng_normal(r), g3d_rng_normal(r), g3d_rng_normal(r)));
}

TEST(project_unproject_identity)
{
    g3d_rng r;
    g3d_rng_seed(&r, 1, 0);
    g3d_camera cam = {g3d_intrinsics_make(500, 480, 255.5, 200.25, 512, 400), random_pose(&r)};
    double worst = 0;
    for (int i = 0; i < 1000; i++) {
        double u = 512 * g3d_rng_float(&r), v = 400 * g3d_rng_float(&r), z = 0.1 + 20 * g3d_rng_float(&r);
        g3d_vec3 p = g3d_camera_unproject(&cam, u, v, z);
        double u2, v2, z2;
        CHECK(g3d_camera_project(&cam, p, &u2, &v2, &z2));
        worst = fmax(worst, fmax(fabs(u - u2), fmax(fabs(v - v2), fabs(z - z2))));
        /* The ray through (u, v) passes through p. */
        g3d_vec3 d = g3d_camera_ray(&cam, u, v), c = g3d_camera_center(&cam);
        g3d_vec3 cp = g3d_v3_sub(p, c);
        g3d_vec3 x = g3d_v3_cross(d, cp);
        worst = fmax(worst, g3d_v3_norm(x) / g3d_v3_norm(cp));
    }
    CHECK_MSG(worst < 1e-9, "worst error %g", worst);
    /* Behind the camera is not projected. */
    g3d_camera id = {cam.K, g3d_mat4_identity()};
    double u, v, z;
    CHECK(!g3d_camera_project(&id, g3d_v3(0, 0, -1), &u, &v, &z));
    CHECK(g3d_camera_project(&id, g3d_v3(0, 0, 2), &u, &v, &z) && u == 255.5 && v == 200.25);
}

TEST(rigid_inverse_and_quaternions)
{
    g3d_rng r;
    g3d_rng_seed(&r, 2, 0);
    for (int i = 0; i < 100; i++) {
        g3d_mat4 a = random_pose(&r), inv, ginv;
        CHECK(g3d_mat4_max_abs_diff(g3d_mat4_mul(a, g3d_mat4_inverse_rigid(a)), g3d_mat4_identity()) < 1e-12);
        CHECK(g3d_mat4_inverse(a, &ginv));
        inv = g3d_mat4_inverse_rigid(a);
        CHECK(g3d_mat4_max_abs_diff(inv, ginv) < 1e-9);
        g3d_quat q = g3d_quat_from_mat4(a);
        g3d_mat4 b = g3d_mat4_from_rt(q, g3d_mat4_translation(a));
        CHECK(g3d_mat4_max_abs_diff(a, b) < 1e-12);
    }
    /* Hamilton product composes rotations like matrices do. */
    g3d_quat qa = g3d_quat_from_axis_angle(g3d_v3(0, 1, 0), 0.7), qb = g3d_quat_from_axis_angle(g3d_v3(1, 0, 1), -1.1);
    g3d_mat4 m1 = g3d_quat_to_mat4(g3d_quat_mul(qa, qb));
    g3d_mat4 m2 = g3d_mat4_mul(g3d_quat_to_mat4(qa), g3d_quat_to_mat4(qb));
    CHECK(g3d_mat4_max_abs_diff(m1, m2) < 1e-12);
}

TEST(slerp)
{
    g3d_quat a = g3d_quat_from_axis_angle(g3d_v3(0, 1, 0), 0.0);
    g3d_quat b = g3d_quat_from_axis_angle(g3d_v3(0, 1, 0), 1.2);
    g3d_quat h = g3d_quat_slerp(a, b, 0.25);
    g3d_quat e = g3d_quat_from_axis_angle(g3d_v3(0, 1, 0), 0.3);
    CHECK_NEAR(h.w, e.w, 1e-12);
    CHECK_NEAR(h.y, e.y, 1e-12);
    /* Shorter arc: b and -b give the same result. */
    g3d_quat nb = {-b.w, -b.x, -b.y, -b.z};
    g3d_quat h2 = g3d_quat_slerp(a, nb, 0.25);
    CHECK(g3d_mat4_max_abs_diff(g3d_quat_to_mat4(h), g3d_quat_to_mat4(h2)) < 1e-12);
    g3d_mat4 pa = g3d_mat4_from_rt(a, g3d_v3(0, 0, 0)), pb = g3d_mat4_from_rt(b, g3d_v3(2, 0, 4));
    g3d_mat4 pm = g3d_pose_interp(pa, pb, 0.5);
    CHECK_NEAR(pm.m[0][3], 1.0, 1e-12);
    CHECK_NEAR(pm.m[2][3], 2.0, 1e-12);
    CHECK(g3d_mat4_max_abs_diff(g3d_pose_interp(pa, pb, 1.0), pb) < 1e-9);
}

TEST(conventions)
{
    g3d_rng r;
    g3d_rng_seed(&r, 3, 0);
    g3d_mat4 a = random_pose(&r);
    CHECK(g3d_mat4_max_abs_diff(g3d_pose_opengl_to_opencv(g3d_pose_opencv_to_opengl(a)), a) == 0);
    /* An OpenGL camera looks along its -z: the forward vector is preserved by conversion. */
    g3d_mat4 gl = g3d_pose_opencv_to_opengl(a);
    g3d_vec3 f_cv = g3d_mat4_dir(a, g3d_v3(0, 0, 1)), f_gl = g3d_mat4_dir(gl, g3d_v3(0, 0, -1));
    CHECK(g3d_v3_norm(g3d_v3_sub(f_cv, f_gl)) < 1e-12);
    g3d_mat4 w = g3d_world_flip_yz();
    CHECK(g3d_mat4_max_abs_diff(g3d_mat4_mul(w, w), g3d_mat4_identity()) == 0);
    /* look_at: the camera's z points at the target and -y is up. */
    g3d_mat4 la = g3d_mat4_look_at(g3d_v3(1, -1, -2), g3d_v3(0, 0, 3), g3d_v3(0, -1, 0));
    g3d_camera cam = {g3d_intrinsics_from_fov(60, 640, 480), la};
    double u, v, z;
    CHECK(g3d_camera_project(&cam, g3d_v3(0, 0, 3), &u, &v, &z));
    CHECK_NEAR(u, 319.5, 1e-9);
    CHECK_NEAR(v, 239.5, 1e-9);
    g3d_vec3 up_cam = g3d_mat4_dir(la, g3d_v3(0, -1, 0));
    CHECK(up_cam.y < 0);
    CHECK_NEAR(g3d_intrinsics_fov_x_deg(cam.K), 60.0, 1e-9);
    g3d_intrinsics k2 = g3d_intrinsics_resize(cam.K, 320, 240);
    CHECK_NEAR(k2.cx, 159.5, 1e-12);
    CHECK_NEAR(k2.fx, cam.K.fx / 2, 1e-12);
}

int main(void)
{
    RUN(project_unproject_identity);
    RUN(rigid_inverse_and_quaternions);
    RUN(slerp);
    RUN(conventions);
    return test_summary();
}
