/* The procedural room: analytic depths, two-view consistency, determinism. */
#include "testutil.h"
#include "gen3d/imageio.h"
#include "gen3d/procscene.h"

TEST(analytic_depth)
{
    g3d_camera cam = g3d_procscene_default_camera(160, 120);
    g3d_image rgb, depth, ids;
    CHECK_OK(g3d_procscene_render(&cam, &rgb, &depth, &ids));
    if (!depth.data) return;
    /* Bottom-left corner pixels see the floor (y = 1.5), unless an object is in the way. */
    int checked = 0;
    for (int y = 100; y < 120; y++)
        for (int x = 0; x < 160; x += 7) {
            if (*g3d_image_px(&ids, x, y) != G3D_PROC_ROOM) continue;
            double dy = (y - cam.K.cy) / cam.K.fy; /* ray (dx, dy, 1) */
            double z_floor = 1.5 / dy;
            double dx = (x - cam.K.cx) / cam.K.fx, xw = dx * z_floor;
            if (fabs(xw) >= 3.0 || z_floor > 7.0) continue; /* hits a wall instead */
            CHECK_NEAR(*g3d_image_px(&depth, x, y), z_floor, 1e-4 * z_floor);
            checked++;
        }
    CHECK(checked > 10);
    /* The ray through the near sphere's centre hits at distance |c| - r; depth is its z. */
    g3d_vec3 c = g3d_v3(0.75, 1.05, 2.3);
    double u, v, z;
    CHECK(g3d_camera_project(&cam, c, &u, &v, &z));
    g3d_vec3 d = g3d_camera_ray(&cam, u, v);
    double t = g3d_v3_norm(c) - 0.45;
    CHECK(*g3d_image_px(&ids, (int)lround(u), (int)lround(v)) == G3D_PROC_NEAR_SPHERE);
    /* Pixel centres are at integers: evaluate at the nearest pixel and re-derive the hit. */
    int iu = (int)lround(u), iv = (int)lround(v);
    d = g3d_camera_ray(&cam, iu, iv);
    double b = g3d_v3_dot(d, c), disc = b * b - (g3d_v3_dot(c, c) - 0.45 * 0.45);
    t = b - sqrt(disc);
    CHECK_NEAR(*g3d_image_px(&depth, iu, iv), t * d.z, 1e-4);
    /* Through the window the far landscape is at z = 25. */
    int far = 0;
    for (size_t i = 0; i < g3d_image_size(&ids); i++)
        if (ids.data[i] == G3D_PROC_FAR) { far++; CHECK_NEAR(depth.data[i], 25.0, 1e-3); }
    CHECK(far > 100);
    g3d_image_save_png(test_tmp("procscene_default.png"), &rgb, 8);
    g3d_image_free(&rgb);
    g3d_image_free(&depth);
    g3d_image_free(&ids);
}

TEST(two_view_consistency)
{
    g3d_camera a = g3d_procscene_arc_camera(0, 5, 128, 96), b = g3d_procscene_arc_camera(3, 5, 128, 96);
    g3d_image ra, da, rb, db;
    CHECK_OK(g3d_procscene_render(&a, &ra, &da, NULL));
    CHECK_OK(g3d_procscene_render(&b, &rb, &db, NULL));
    if (!da.data || !db.data) return;
    /* A point lifted from view a lands on view b at the depth b sees (when not occluded). */
    int n = 0, agree = 0;
    double colour_err = 0;
    for (int y = 0; y < 96; y += 3)
        for (int x = 0; x < 128; x += 3) {
            float z = *g3d_image_px(&da, x, y);
            if (z <= 0 || z > 20) continue;
            g3d_vec3 p = g3d_camera_unproject(&a, x, y, z);
            double u, v, zb;
            if (!g3d_camera_project(&b, p, &u, &v, &zb)) continue;
            int iu = (int)lround(u), iv = (int)lround(v);
            if (iu < 0 || iv < 0 || iu >= 128 || iv >= 96) continue;
            n++;
            if (fabs(*g3d_image_px(&db, iu, iv) - zb) < 0.03 * zb) {
                agree++;
                for (int k = 0; k < 3; k++) colour_err += fabs(g3d_image_px(&ra, x, y)[k] - g3d_image_px(&rb, iu, iv)[k]);
            }
        }
    printf("  %d of %d reprojected points agree in depth, mean colour error %.3f\n", agree, n, colour_err / (3.0 * agree));
    CHECK(agree > 0.85 * n);
    CHECK(colour_err / (3.0 * agree) < 0.06);
    g3d_image_free(&ra); g3d_image_free(&da); g3d_image_free(&rb); g3d_image_free(&db);
}

TEST(deterministic_and_points)
{
    g3d_camera c = g3d_procscene_arc_camera(1, 4, 64, 48);
    g3d_image r1, r2;
    CHECK_OK(g3d_procscene_render(&c, &r1, NULL, NULL));
    CHECK_OK(g3d_procscene_render(&c, &r2, NULL, NULL));
    CHECK(!memcmp(r1.data, r2.data, g3d_image_size(&r1) * sizeof(float)));
    g3d_image_free(&r1);
    g3d_image_free(&r2);
    g3d_points pts;
    CHECK_OK(g3d_procscene_points(3, 64, 48, 2, &pts));
    CHECK(pts.n > 1500 && pts.n <= 3 * 32 * 24);
    for (int64_t i = 0; i < pts.n; i++) {
        CHECK(pts.xyz[3 * i] >= -3.001f && pts.xyz[3 * i] <= 3.001f);
        if (!(pts.xyz[3 * i] >= -3.001f && pts.xyz[3 * i] <= 3.001f)) break;
    }
    g3d_points_free(&pts);
}

int main(void)
{
    RUN(analytic_depth);
    RUN(two_view_consistency);
    RUN(deterministic_and_points);
    return test_summary();
}
