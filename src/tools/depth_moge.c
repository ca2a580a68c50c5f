/* gen3d depth with a MoGe-2 checkpoint: metric depth plus the camera it implies. */
#include "depth_moge.h"

#include "cli.h"
#include "gen3d/depthio.h"
#include "gen3d/imageio.h"
#include "gen3d/moge.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* {"width", "height", "fx", "fy", "cx", "cy", "fov_x_deg", "fov_y_deg"}: pixels of the input
 * image, pixel centres at integer coordinates. NULL when out of memory. */
static char *intrinsics_json(g3d_intrinsics K)
{
    cJSON *j = cJSON_CreateObject();
    if (!j) return NULL;
    cJSON_AddNumberToObject(j, "width", K.width);
    cJSON_AddNumberToObject(j, "height", K.height);
    cJSON_AddNumberToObject(j, "fx", K.fx);
    cJSON_AddNumberToObject(j, "fy", K.fy);
    cJSON_AddNumberToObject(j, "cx", K.cx);
    cJSON_AddNumberToObject(j, "cy", K.cy);
    cJSON_AddNumberToObject(j, "fov_x_deg", g3d_intrinsics_fov_x_deg(K));
    cJSON_AddNumberToObject(j, "fov_y_deg", g3d_intrinsics_fov_y_deg(K));
    char *s = cJSON_Print(j), *line = s ? malloc(strlen(s) + 2) : NULL;
    if (line) sprintf(line, "%s\n", s);
    free(s);
    cJSON_Delete(j);
    return line;
}

int g3d_cli_depth_moge(const char *model, const char *input, const char *output, int num_tokens,
                       const char *intrinsics_out)
{
    g3d_image img = {0}, depth = {0};
    g3d_moge *m = NULL;
    g3d_moge_result r = {0};
    char *json = NULL;
    g3d_status rc = g3d_image_load(input, 3, &img);
    if (rc == G3D_OK) rc = g3d_moge_load_file(model, &m);
    if (rc == G3D_OK) {
        char desc[200];
        g3d_log(G3D_LOG_INFO, "%s", g3d_moge_describe(m, desc, sizeof desc));
        if (!g3d_moge_has_scale(m)) g3d_log(G3D_LOG_WARN, "%s: no metric scale head: depth is relative", model);
        rc = g3d_moge_infer(m, img.data, img.w, img.h, num_tokens, 0, &r);
    }
    if (rc == G3D_OK) rc = g3d_image_create(&depth, img.w, img.h, 1);
    if (rc == G3D_OK) {
        size_t valid = 0, n = (size_t)img.w * img.h;
        for (size_t i = 0; i < n; i++) {
            depth.data[i] = isfinite(r.depth[i]) ? r.depth[i] : 0.0f;
            valid += depth.data[i] > 0;
        }
        g3d_intrinsics K = g3d_moge_intrinsics_pixels(&r);
        g3d_log(G3D_LOG_INFO, "camera: fx %.1f px, horizontal fov %.1f deg; metric scale %.4g; valid pixels %.1f %%", K.fx,
                g3d_intrinsics_fov_x_deg(K), r.metric_scale, 100.0 * valid / n);
        if (intrinsics_out && !(json = intrinsics_json(K))) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    if (rc == G3D_OK) rc = g3d_depth_save(output, &depth);
    if (rc == G3D_OK && json) {
        rc = g3d_write_file_atomic(intrinsics_out, json, strlen(json));
        if (rc != G3D_OK) remove(output);   /* both files or neither */
    }
    free(json);
    g3d_moge_result_free(&r);
    g3d_moge_free(m);
    g3d_image_free(&img);
    g3d_image_free(&depth);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s\n", output);
    if (intrinsics_out) printf("%s\n", intrinsics_out);
    return G3D_EXIT_OK;
}
