/* Layers on the procedural room: the depth-found foreground covers the near objects. */
#include "testutil.h"
#include "gen3d/depth_complete.h"
#include "gen3d/imageio.h"
#include "gen3d/inpaint_classic.h"
#include "gen3d/layers.h"
#include "gen3d/procscene.h"
#include "gen3d/regions.h"

TEST(foreground_matches_near_objects)
{
    g3d_camera cam = g3d_procscene_default_camera(256, 192);
    g3d_image rgb, depth, ids;
    CHECK_OK(g3d_procscene_render(&cam, &rgb, &depth, &ids));
    g3d_mask_provider mp;
    g3d_inpainter ip;
    g3d_depth_estimator de;
    g3d_depth_estimator_completion_create(&de);
    CHECK_OK(g3d_mask_provider_regions_create(NULL, cam.K, &mp));
    CHECK_OK(g3d_inpainter_classic_create(NULL, &ip));
    g3d_layers L;
    CHECK_OK(g3d_layers_compute(&rgb, &depth, &mp, &ip, &de, NULL, 1, &L));
    if (!L.fg_mask.data) return;
    size_t inter = 0, uni = 0;
    for (size_t i = 0; i < g3d_image_size(&ids); i++) {
        int a = L.fg_mask.data[i] > 0.5f, b = g3d_procscene_is_near_object((int)ids.data[i]);
        inter += a && b;
        uni += a || b;
    }
    double iou = (double)inter / uni;
    printf("  %d regions, %d kept, %d foreground, theta_d %.2f m; IoU with the near objects %.3f\n", L.n_candidates,
           L.n_kept, L.n_foreground, L.theta_d, iou);
    CHECK(iou >= 0.8);
    /* The background behind the foreground is completed: deeper than the objects were. */
    double deeper = 0;
    size_t nf = 0;
    for (size_t i = 0; i < g3d_image_size(&ids); i++)
        if (L.fg_mask.data[i] > 0.5f) { deeper += L.bg_depth.data[i] > depth.data[i] * 1.05f; nf++; }
    printf("  background depth behind the foreground is deeper on %.1f %% of it\n", 100 * deeper / nf);
    CHECK(deeper > 0.8 * nf);
    g3d_image_save_png(test_tmp("layers_fg.png"), &L.fg_mask, 8);
    g3d_image_save_png(test_tmp("layers_bg.png"), &L.bg_rgb, 8);
    g3d_layers_free(&L);
    g3d_mask_provider_free(&mp);
    g3d_inpainter_free(&ip);
    g3d_image_free(&rgb); g3d_image_free(&depth); g3d_image_free(&ids);
}

int main(void)
{
    RUN(foreground_matches_near_objects);
    return test_summary();
}
