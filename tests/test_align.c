/* Depth completion and alignment on the procedural room, where the true depth is known. */
#include "testutil.h"
#include "gen3d/align.h"
#include "gen3d/cloud.h"
#include "gen3d/depth_complete.h"
#include "gen3d/procscene.h"
#include "gen3d/trajectory.h"

typedef struct setup {
    g3d_camera src, dst;
    g3d_image truth_d, cloud_d, mask;
} setup;

/* Source = default camera; target turned 25 degrees left and moved: its left part is new. */
static void make_setup(setup *s)
{
    s->src = g3d_procscene_default_camera(192, 144);
    s->dst = s->src;
    s->dst.c2w = g3d_pose_yaw_pitch(25, 5, g3d_v3(-0.2, -0.05, 0.3));
    g3d_image rgb, depth;
    g3d_cloud c;
    g3d_procscene_render(&s->src, &rgb, &depth, NULL);
    g3d_procscene_render(&s->dst, NULL, &s->truth_d, NULL);
    g3d_cloud_init(&c);
    g3d_cloud_lift(&c, &rgb, &depth, &s->src, NULL, 0, NULL);
    g3d_cloud_render(&c, &s->dst, NULL, NULL, &s->cloud_d, &s->mask);
    g3d_image_free(&rgb);
    g3d_image_free(&depth);
    g3d_cloud_free(&c);
}

static void free_setup(setup *s)
{
    g3d_image_free(&s->truth_d);
    g3d_image_free(&s->cloud_d);
    g3d_image_free(&s->mask);
}

/* Mean relative error over hole pixels (all, or only those touching covered pixels). */
static double hole_error(const g3d_image *d, const setup *s, int boundary_only)
{
    int w = d->w, h = d->h;
    double e = 0;
    size_t n = 0;
    for (int y = 1; y < h - 1; y++)
        for (int x = 1; x < w - 1; x++) {
            size_t i = (size_t)y * w + x;
            if (s->mask.data[i] > 0.5f) continue;
            int edge = s->mask.data[i - 1] > 0.5f || s->mask.data[i + 1] > 0.5f || s->mask.data[i - w] > 0.5f || s->mask.data[i + w] > 0.5f;
            if (boundary_only && !edge) continue;
            /* Skip pixels whose true surface differs from its covered neighbour's (the edge of
             * a disocclusion): a seam is measured where the new surface meets the old one. */
            if (boundary_only) {
                int same = 0;
                for (int k = 0; k < 4; k++) {
                    size_t j = k == 0 ? i - 1 : k == 1 ? i + 1 : k == 2 ? i - w : i + w;
                    if (s->mask.data[j] > 0.5f && fabsf(s->truth_d.data[j] - s->truth_d.data[i]) < 0.03f * s->truth_d.data[i]) same = 1;
                }
                if (!same) continue;
            }
            e += fabs(d->data[i] - s->truth_d.data[i]) / s->truth_d.data[i];
            n++;
        }
    return n ? e / n : NAN;
}

TEST(alignment_removes_smooth_depth_error)
{
    setup s;
    make_setup(&s);
    size_t holes = 0;
    for (size_t i = 0; i < g3d_image_size(&s.mask); i++) holes += s.mask.data[i] < 0.5f;
    CHECK(holes > 0.15 * g3d_image_size(&s.mask));
    /* "Estimated" depth: the truth with a smooth scale error (12-30 %, varying across the
     * view) and an offset of 2 cm, the kind of error a monocular depth model makes. */
    g3d_image est;
    g3d_image_clone(&est, &s.truth_d);
    for (int y = 0; y < est.h; y++)
        for (int x = 0; x < est.w; x++) {
            float *z = g3d_image_px(&est, x, y);
            *z = *z * (1.2f + 0.1f * x / est.w - 0.08f * y / est.h) + 0.02f;
        }
    double seam_before = hole_error(&est, &s, 1), err_before = hole_error(&est, &s, 0);
    g3d_align_stats st;
    CHECK_OK(g3d_align_depth(&est, &s.cloud_d, &s.mask, NULL, &st));
    double seam_after = hole_error(&est, &s, 1), err_after = hole_error(&est, &s, 0);
    printf("  %lld correspondences (%lld rejected), median ratio %.3f\n", (long long)st.correspondences, (long long)st.rejected, st.median_ratio);
    printf("  seam: %.2f %% -> %.3f %% of depth; hole interior: %.2f %% -> %.3f %% (%.0fx)\n", 100 * seam_before,
           100 * seam_after, 100 * err_before, 100 * err_after, err_before / err_after);
    CHECK(st.correspondences > 100);
    CHECK(seam_after < 0.01);
    CHECK(err_after * 10 <= err_before);
    g3d_image_free(&est);

    /* An error with structure the boundary cannot reveal (a wave across the view) is still
     * reduced, by less. */
    g3d_image_clone(&est, &s.truth_d);
    for (int y = 0; y < est.h; y++)
        for (int x = 0; x < est.w; x++) *g3d_image_px(&est, x, y) *= 1.2f + 0.05f * sinf(x * 0.02f);
    err_before = hole_error(&est, &s, 0);
    CHECK_OK(g3d_align_depth(&est, &s.cloud_d, &s.mask, NULL, &st));
    err_after = hole_error(&est, &s, 0);
    printf("  wavy scale error: hole interior %.2f %% -> %.2f %%\n", 100 * err_before, 100 * err_after);
    CHECK(err_after * 4 <= err_before);
    g3d_image_free(&est);
    free_setup(&s);
}

TEST(outliers_are_rejected)
{
    setup s;
    make_setup(&s);
    g3d_image est;
    g3d_image_clone(&est, &s.truth_d);
    for (size_t i = 0; i < g3d_image_size(&est); i++) est.data[i] *= 1.25f;
    /* Corrupt a few boundary correspondences in the cloud depth (e.g. stray far points). */
    int corrupted = 0;
    for (size_t i = 1; i + 1 < g3d_image_size(&s.mask) && corrupted < 40; i += 7)
        if (s.mask.data[i] > 0.5f && s.mask.data[i + 1] < 0.5f) { s.cloud_d.data[i] *= 1.8f; corrupted++; }
    g3d_align_stats st;
    CHECK_OK(g3d_align_depth(&est, &s.cloud_d, &s.mask, NULL, &st));
    CHECK(st.rejected >= corrupted * 3 / 4);
    double err = hole_error(&est, &s, 0);
    printf("  %d corrupted, %lld rejected; interior error %.3f %%\n", corrupted, (long long)st.rejected, 100 * err);
    CHECK(err < 0.01);
    g3d_image_free(&est);
    free_setup(&s);
}

TEST(completion)
{
    setup s;
    make_setup(&s);
    /* Completing the target's holes from the rendered cloud depth alone: smooth surfaces
     * (walls, floor) continue; the error is far below a constant fill. */
    g3d_image d;
    g3d_image_clone(&d, &s.cloud_d);
    CHECK_OK(g3d_depth_complete(&d, NULL)); /* the holes are the zero-depth pixels */
    double err = hole_error(&d, &s, 0);
    double mean = 0;
    size_t n = 0;
    for (size_t i = 0; i < g3d_image_size(&d); i++) if (s.mask.data[i] > 0.5f) { mean += s.cloud_d.data[i]; n++; }
    mean /= n;
    g3d_image c;
    g3d_image_clone(&c, &s.cloud_d);
    for (size_t i = 0; i < g3d_image_size(&c); i++) if (s.mask.data[i] < 0.5f) c.data[i] = (float)mean;
    double err_const = hole_error(&c, &s, 0);
    printf("  completion error in holes %.1f %% (constant fill %.1f %%)\n", 100 * err, 100 * err_const);
    CHECK(err < 0.5 * err_const);
    for (size_t i = 0; i < g3d_image_size(&d); i++) CHECK(d.data[i] > 0 && isfinite(d.data[i]));
    g3d_image empty;
    g3d_image_create(&empty, 8, 8, 1);
    CHECK_FAILS(g3d_depth_complete(&empty, NULL));
    g3d_image_free(&empty);
    g3d_image_free(&c);
    g3d_image_free(&d);
    free_setup(&s);
}

int main(void)
{
    RUN(alignment_removes_smooth_depth_error);
    RUN(outliers_are_rejected);
    RUN(completion);
    return test_summary();
}
