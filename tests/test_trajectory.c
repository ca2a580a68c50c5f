/* Trajectory presets: counts, directions, interpolation, orbits about their pivot. */
#include "testutil.h"
#include "gen3d/trajectory.h"

static g3d_vec3 forward(g3d_mat4 m) { return g3d_mat4_dir(m, g3d_v3(0, 0, 1)); }

TEST(counts_and_first_pose)
{
    struct { const char *name; int n; } want[] = {{"rotate", 9}, {"lookdown", 14}, {"lookaround", 21}, {"rotate360", 10},
                                                 {"push_in", 50}, {"pull_out", 50}, {"move_left", 50}, {"move_right", 50},
                                                 {"orbit_left", 50}, {"orbit_right", 50}, {"pan_left", 50}, {"pan_right", 50}};
    for (size_t i = 0; i < sizeof want / sizeof *want; i++) {
        g3d_mat4 *p;
        int n;
        CHECK_OK(g3d_trajectory_make(want[i].name, NULL, 2.0, &p, &n));
        CHECK_MSG(n == want[i].n, "%s: %d poses", want[i].name, n);
        if (n) CHECK(g3d_mat4_max_abs_diff(p[0], g3d_mat4_identity()) < 1e-12);
        for (int k = 0; k < n; k++) CHECK(g3d_mat4_max_abs_diff(g3d_mat4_mul(p[k], g3d_mat4_inverse_rigid(p[k])), g3d_mat4_identity()) < 1e-9);
        CHECK(g3d_trajectory_describe(want[i].name) != NULL);
        free(p);
    }
}

TEST(directions)
{
    g3d_mat4 *p;
    int n;
    /* rotate: counter-clockwise seen from above = turning left (-x) by the full angle. */
    g3d_trajectory_params tp;
    g3d_trajectory_params_default(&tp);
    tp.steps = 4;
    tp.angle_deg = 40;
    CHECK_OK(g3d_trajectory_make("rotate", &tp, 3.0, &p, &n));
    g3d_vec3 f = forward(p[n - 1]);
    CHECK(n == 5 && f.x < 0);
    CHECK_NEAR(atan2(-f.x, f.z) * 180 / M_PI, 40.0, 1e-9);
    free(p);
    /* lookdown: second row looks down (+y). */
    CHECK_OK(g3d_trajectory_make("lookdown", NULL, 3.0, &p, &n));
    CHECK(forward(p[7]).y > 0.38 && forward(p[7]).y < 0.39);
    free(p);
    /* push_in moves along +z by a quarter of the scene scale, interpolated linearly. */
    CHECK_OK(g3d_trajectory_make("push_in", NULL, 4.0, &p, &n));
    CHECK_NEAR(p[n - 1].m[2][3], 1.0, 1e-12);
    CHECK_NEAR(p[n / 2].m[2][3], 1.0 * (n / 2) / (n - 1), 1e-9);
    free(p);
    g3d_trajectory_params_default(&tp);
    tp.distance = 0.8;
    tp.interp = 0;
    CHECK_OK(g3d_trajectory_make("move_right", &tp, 4.0, &p, &n));
    CHECK(n == 2);
    CHECK_NEAR(p[1].m[0][3], 0.4, 1e-12);
    free(p);
    /* orbit_left: the camera moves left and keeps looking at the pivot s ahead. */
    CHECK_OK(g3d_trajectory_make("orbit_left", &tp, 4.0, &p, &n));
    g3d_vec3 c = g3d_mat4_translation(p[1]), fw = forward(p[1]);
    CHECK(c.x < 0);
    g3d_vec3 to_pivot = g3d_v3_normalize(g3d_v3_sub(g3d_v3(0, 0, 0.8), c));
    CHECK(g3d_v3_norm(g3d_v3_sub(to_pivot, fw)) < 1e-9);
    free(p);
    CHECK_OK(g3d_trajectory_make("pan_right", &tp, 4.0, &p, &n));
    CHECK(forward(p[1]).x > 0.49 && g3d_v3_norm(g3d_mat4_translation(p[1])) == 0);
    free(p);
}

TEST(orbits_and_errors)
{
    g3d_mat4 base[2] = {g3d_mat4_identity(), g3d_pose_yaw_pitch(30, 0, g3d_v3(1, 0, 0))}, *o;
    int n;
    CHECK_OK(g3d_trajectory_orbits(base, 2, 4, 2.0, 5.0, &o, &n));
    CHECK(n == 8);
    /* Every orbit view still looks at its pivot. */
    for (int i = 0; i < 8; i++) {
        g3d_vec3 pivot = g3d_mat4_point(base[i / 4], g3d_v3(0, 0, 2.0));
        g3d_vec3 d = g3d_v3_normalize(g3d_v3_sub(pivot, g3d_mat4_translation(o[i])));
        CHECK(g3d_v3_norm(g3d_v3_sub(d, forward(o[i]))) < 1e-9);
    }
    free(o);
    g3d_mat4 *p;
    CHECK_FAILS(g3d_trajectory_make("spiral", NULL, 1.0, &p, &n));
    CHECK(strstr(g3d_error_message(), "orbit_left") != NULL);
    CHECK_FAILS(g3d_trajectory_make("rotate", NULL, 0.0, &p, &n));
    g3d_trajectory_params tp;
    g3d_trajectory_params_default(&tp);
    tp.steps = 100000;
    CHECK_FAILS(g3d_trajectory_make("rotate", &tp, 1.0, &p, &n));
    CHECK_FAILS(g3d_trajectory_orbits(base, 2, 9, 2.0, 5.0, &o, &n));
}

int main(void)
{
    RUN(counts_and_first_pose);
    RUN(directions);
    RUN(orbits_and_errors);
    return test_summary();
}
