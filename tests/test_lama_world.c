/* LaMa wired into the background layer and the world loop, on the procedural room and on the
 * Middlebury frame (toward its real held-out view): the plug-in is called with the holes the
 * loop finds, known pixels come back unchanged, and its output is what the views keep. The
 * fixture generator has random weights, so the hole PSNR of both inpainters against the truth
 * is printed for comparison, not judged. */
#include "testutil.h"
#include "inpaint_recorder.h"

#include "gen3d/depth_complete.h"
#include "gen3d/frame.h"
#include "gen3d/inpaint_classic.h"
#include "gen3d/lama.h"
#include "gen3d/procscene.h"
#include "gen3d/regions.h"
#include "gen3d/world.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* PSNR of a against truth over the pixels where mask > 0.5 (both (h, w, 3)). */
static double hole_psnr(const g3d_image *a, const g3d_image *truth, const g3d_image *mask)
{
    double se = 0;
    size_t n = 0;
    for (size_t i = 0; i < (size_t)a->w * a->h; i++)
        if (mask->data[i] > 0.5f)
            for (int k = 0; k < 3; k++, n++) se += pow((double)a->data[3 * i + k] - truth->data[3 * i + k], 2);
    return n && se > 0 ? 10 * log10((double)n / se) : 99;
}

typedef struct run_out {
    recorder rec;
    g3d_world world;
    int layer_calls; /* calls made by the background layer */
} run_out;

/* Layers (background inpainted) then the world loop along poses, through a recorder around
 * `ip`. */
static void run(const g3d_frame *f, const g3d_mat4 *poses, int n, const g3d_inpainter *ip, run_out *o)
{
    memset(o, 0, sizeof *o);
    o->rec.inner = ip;
    g3d_inpainter wrap = {"recorder", &o->rec, record, NULL};
    g3d_depth_estimator de = {0};
    g3d_mask_provider mp = {0};
    g3d_layers L = {0};
    CHECK_OK(g3d_depth_estimator_completion_create(&de));
    CHECK_OK(g3d_mask_provider_regions_create(NULL, f->cam.K, &mp));
    g3d_world_params wp;
    g3d_world_params_default(&wp);
    wp.extra_views = 0;
    CHECK_OK(g3d_layers_compute(&f->rgb, &f->depth, &mp, &wrap, &de, NULL, 7, &L));
    o->layer_calls = o->rec.calls;
    CHECK_OK(g3d_world_generate(f, poses, n, &wrap, &de, &L, &wp, 7, &o->world));
    g3d_layers_free(&L);
    g3d_mask_provider_free(&mp);
    g3d_depth_estimator_free(&de);
}

/* What both runs must show: every call checked clean, one call per view with holes (and one
 * for the background when there is a foreground), the views keep the plug-in's output. */
static void check_plumbing(const char *label, const run_out *o)
{
    const recorder *r = &o->rec;
    const g3d_world *w = &o->world;
    CHECK_MSG(r->known_changed == 0, "%s: %zu known pixels changed", label, r->known_changed);
    CHECK_MSG(r->bad_masks == 0, "%s: %zu masks not 0/1, empty or full", label, r->bad_masks);
    int with_holes = 0;
    for (int i = 1; i < w->n_views; i++) with_holes += w->steps[i].hole_fraction > 0;
    CHECK_MSG(r->calls == o->layer_calls + with_holes, "%s: %d calls for %d views with holes", label, r->calls, with_holes);
    CHECK_MSG(o->layer_calls == (w->layers.n_foreground > 0), "%s: %d background calls", label, o->layer_calls);
    for (int i = 1, k = o->layer_calls; i < w->n_views && k < MAX_CALLS; i++) {
        if (w->steps[i].hole_fraction <= 0) continue;
        const g3d_image *m = &r->mask[k];
        size_t holes = 0, n = (size_t)m->w * m->h;
        for (size_t j = 0; j < n; j++) holes += m->data[j] > 0.5f;
        CHECK_MSG(fabs((double)holes / n - w->steps[i].hole_fraction) < 1e-12, "%s: view %d mask is not its holes", label, i);
        CHECK_MSG(w->rgb[i].w == r->out[k].w && !memcmp(w->rgb[i].data, r->out[k].data, sizeof(float) * 3 * n),
                  "%s: view %d is not the inpainter's output", label, i);
        k++;
    }
}

/* classic and LaMa on one frame; prints the hole PSNR of the first new view against truth
 * (rendered for view 1 when truth is NULL: the procedural room). */
static void compare(const char *label, const g3d_frame *f, const g3d_mat4 *poses, int n, const g3d_image *truth)
{
    g3d_inpainter classic = {0}, lama = {0};
    CHECK_OK(g3d_inpainter_classic_create(NULL, &classic));
    CHECK_OK(g3d_inpainter_lama_create(test_fixture("lama_tiny.ckpt"), &lama));
    if (!lama.inpaint) return;
    run_out a, b;
    run(f, poses, n, &classic, &a);
    run(f, poses, n, &lama, &b);
    char name[96];
    snprintf(name, sizeof name, "%s, classic", label);
    check_plumbing(name, &a);
    snprintf(name, sizeof name, "%s, LaMa", label);
    check_plumbing(name, &b);
    CHECK_MSG(b.rec.holes_unchanged < b.rec.calls * 16u, "%s: LaMa left %zu hole pixels as they were", label, b.rec.holes_unchanged);
    /* Both runs see the same masks: the layers' foreground and the first new view's holes
     * come from the input alone. */
    CHECK(a.layer_calls == b.layer_calls && a.rec.calls > a.layer_calls);
    for (int k = 0; k <= a.layer_calls && k < a.rec.calls && k < b.rec.calls; k++)
        CHECK_MSG(!memcmp(a.rec.mask[k].data, b.rec.mask[k].data, sizeof(float) * a.rec.mask[k].w * a.rec.mask[k].h),
                  "%s: call %d had another mask", label, k);
    /* The plug-in returns exactly what the model does on that image and mask. */
    g3d_image again = {0};
    int k = b.layer_calls;
    CHECK_OK(g3d_image_clone(&again, &b.rec.in[k]));
    CHECK_OK(g3d_lama_inpaint(lama.ctx, &again, &b.rec.mask[k], NULL));
    CHECK(again.data && !memcmp(again.data, b.rec.out[k].data, sizeof(float) * 3 * again.w * again.h));
    g3d_image_free(&again);
    g3d_image gt = {0};
    if (!truth) {
        CHECK_OK(g3d_procscene_render(&a.world.cams[1], &gt, NULL, NULL));
        truth = &gt;
    }
    if (truth->w == a.rec.out[k].w && truth->h == a.rec.out[k].h)
        printf("  %s, view 1: %.1f %% holes; hole PSNR classic %.2f dB, LaMa (random fixture) %.2f dB\n", label,
               100 * a.world.steps[1].hole_fraction, hole_psnr(&a.rec.out[k], truth, &a.rec.mask[k]),
               hole_psnr(&b.rec.out[k], truth, &b.rec.mask[k]));
    g3d_image_free(&gt);
    recorder_free(&a.rec);
    recorder_free(&b.rec);
    g3d_world_free(&a.world);
    g3d_world_free(&b.world);
    g3d_inpainter_free(&classic);
    g3d_inpainter_free(&lama);
}

TEST(procedural_room)
{
    g3d_frame f;
    memset(&f, 0, sizeof f);
    f.cam = g3d_procscene_default_camera(96, 72);
    CHECK_OK(g3d_procscene_render(&f.cam, &f.rgb, &f.depth, NULL));
    g3d_mat4 poses[3] = {g3d_mat4_identity(), g3d_mat4_identity(), g3d_mat4_identity()};
    /* a step sideways and a turn: new pixels at the borders and behind the furniture */
    poses[1].m[0][3] = 0.25;
    const double a = 0.2;
    poses[2].m[0][0] = cos(a), poses[2].m[0][2] = sin(a), poses[2].m[2][0] = -sin(a), poses[2].m[2][2] = cos(a);
    compare("procedural room", &f, poses, 3, NULL);
    g3d_frame_free(&f);
}

TEST(middlebury_toward_heldout_view)
{
    g3d_frame f;
    CHECK_OK(g3d_frame_load_middlebury(test_default_input(), &f));
    if (!f.rgb.data) return;
    CHECK_OK(g3d_frame_limit_size(&f, 128));
    g3d_mat4 poses[2] = {g3d_mat4_identity(), f.heldout_cam.c2w};
    compare("Middlebury", &f, poses, 2, f.heldout.w == f.rgb.w ? &f.heldout : NULL);
    g3d_frame_free(&f);
}

int main(void)
{
    RUN(procedural_room);
    RUN(middlebury_toward_heldout_view);
    return test_summary();
}
