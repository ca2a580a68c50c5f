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

/* A two-depth hole: an occluder at 1 m (x < 30), the background at 3 m behind it, which the
 * cloud covers from x = 50 on; the hole between is background that the occluder hid. */
#define TW 80
#define TH 40
static void two_depth_hole(g3d_image *truth, g3d_image *cloud, g3d_image *mask)
{
    g3d_image_create(truth, TW, TH, 1);
    g3d_image_create(cloud, TW, TH, 1);
    g3d_image_create(mask, TW, TH, 1);
    for (int y = 0; y < TH; y++)
        for (int x = 0; x < TW; x++) {
            size_t i = (size_t)y * TW + x;
            truth->data[i] = x < 30 ? 1.0f : 3.0f;
            mask->data[i] = x < 30 || x >= 50;
            cloud->data[i] = mask->data[i] > 0.5f ? truth->data[i] : 0;
        }
}

/* Mean relative error of d over the hole of two_depth_hole. */
static double two_depth_error(const g3d_image *d, const g3d_image *truth, const g3d_image *mask)
{
    double e = 0;
    size_t n = 0;
    for (size_t i = 0; i < g3d_image_size(d); i++)
        if (mask->data[i] < 0.5f) { e += fabs(d->data[i] - truth->data[i]) / truth->data[i]; n++; }
    return e / n;
}

TEST(the_near_side_of_a_depth_edge_is_found)
{
    g3d_image truth, cloud, mask, far;
    two_depth_hole(&truth, &cloud, &mask);
    int64_t n_near = 0;
    CHECK_OK(g3d_align_far_side(&cloud, &mask, 1.1f, &far, &n_near));
    CHECK(n_near == TH); /* the occluder's column next to the hole */
    int wrong = 0;
    for (int y = 0; y < TH; y++)
        for (int x = 0; x < TW; x++) {
            float f = far.data[(size_t)y * TW + x];
            /* the occluder's last 5 columns carry the far side's depth, nothing else does */
            wrong += x >= 25 && x < 30 ? fabsf(f - 3.0f) > 1e-6f : f != 0;
        }
    CHECK(wrong == 0);
    g3d_image_free(&far);
    /* A floor receding at a grazing angle (inverse depth falling linearly across the view, from
     * 2 m to 5.4 m) has a hole as deep across as the edge above, but no depth edge. */
    for (int y = 0; y < TH; y++)
        for (int x = 0; x < TW; x++)
            if (mask.data[(size_t)y * TW + x] > 0.5f) cloud.data[(size_t)y * TW + x] = 1.0f / (0.5f - 0.004f * x);
    CHECK_OK(g3d_align_far_side(&cloud, &mask, 1.1f, &far, &n_near));
    CHECK(n_near == 0);
    g3d_image_free(&far);
    CHECK_FAILS(g3d_align_far_side(&cloud, &mask, 1.0f, &far, NULL));
    g3d_image_free(&truth);
    g3d_image_free(&cloud);
    g3d_image_free(&mask);
}

TEST(a_disocclusion_follows_its_far_side)
{
    g3d_image truth, cloud, mask, est, known, far;
    two_depth_hole(&truth, &cloud, &mask);
    /* Alignment: the estimated depth is right on the occluder and 20 % short behind it. */
    g3d_align_params ap;
    g3d_align_params_default(&ap);
    double err[2];
    for (int edges = 0; edges < 2; edges++) {
        g3d_image_clone(&est, &truth);
        for (size_t i = 0; i < g3d_image_size(&est); i++) if (truth.data[i] > 2) est.data[i] *= 0.8f;
        ap.edge_ratio = edges ? 1.1f : 0.0f;
        g3d_align_stats st;
        CHECK_OK(g3d_align_depth(&est, &cloud, &mask, &ap, &st));
        CHECK(st.near_side == (edges ? TH : 0));
        err[edges] = two_depth_error(&est, &truth, &mask);
        g3d_image_free(&est);
    }
    ap.edge_ratio = 0.9f;
    g3d_image_clone(&est, &truth);
    CHECK_FAILS(g3d_align_depth(&est, &cloud, &mask, &ap, NULL));
    g3d_image_free(&est);
    printf("  alignment: hole error %.2f %% from both sides, %.3f %% from the far side\n", 100 * err[0], 100 * err[1]);
    CHECK(err[0] > 0.05);
    CHECK(err[1] < 0.005);
    /* Completion from the cloud's depth with the far side written over the near side. */
    g3d_image holes;
    g3d_image_create(&holes, TW, TH, 1);
    for (size_t i = 0; i < g3d_image_size(&holes); i++) holes.data[i] = mask.data[i] < 0.5f;
    g3d_image_clone(&known, &cloud);
    CHECK_OK(g3d_depth_complete(&known, &holes));
    err[0] = two_depth_error(&known, &truth, &mask);
    g3d_image_free(&known);
    g3d_image_clone(&known, &cloud);
    CHECK_OK(g3d_align_far_side(&cloud, &mask, 1.1f, &far, NULL));
    for (size_t i = 0; i < g3d_image_size(&known); i++) if (far.data[i] > 0) known.data[i] = far.data[i];
    CHECK_OK(g3d_depth_complete(&known, &holes));
    err[1] = two_depth_error(&known, &truth, &mask);
    printf("  completion: hole error %.2f %% from both sides, %.3f %% from the far side\n", 100 * err[0], 100 * err[1]);
    CHECK(err[0] > 0.1);
    CHECK(err[1] < 0.005);
    g3d_image_free(&known);
    g3d_image_free(&far);
    g3d_image_free(&holes);
    g3d_image_free(&truth);
    g3d_image_free(&cloud);
    g3d_image_free(&mask);
}

int main(void)
{
    RUN(alignment_removes_smooth_depth_error);
    RUN(outliers_are_rejected);
    RUN(completion);
    RUN(the_near_side_of_a_depth_edge_is_found);
    RUN(a_disocclusion_follows_its_far_side);
    return test_summary();
}
