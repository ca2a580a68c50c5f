/* gen3d segment: Segment Anything's automatic masks of one picture. */
#include "cli.h"
#include "gen3d/image.h"
#include "gen3d/imageio.h"
#include "gen3d/sam.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *DESCRIPTION =
    "Segments a picture with Segment Anything (the official sam_vit_b_01ec64.pth, sam_vit_l_0b3195.pth\n"
    "or sam_vit_h_4b8939.pth) as its automatic mask generator does: a grid of points, three masks\n"
    "per point, kept when the predicted IoU and the stability pass their thresholds, duplicates\n"
    "removed by box non-maximum suppression. Writes into the output folder mask_NNN.png (one per\n"
    "mask, best first), masks.json (each mask's predicted IoU, stability, box x y w h, area and\n"
    "grid point; the prompt's point or the box centre with --point/--box) and overlay.png (the masks tinted over the picture).\n"
    "With --point and/or --box the predictor runs on that one prompt instead and writes its three\n"
    "masks (SamPredictor.predict with multimask output) the same way.";

/* A fixed colour per mask index (golden-ratio hues). */
static void colour(int i, float rgb[3])
{
    float h = (float)i * 0.618034f;
    h -= (float)(int)h;
    for (int c = 0; c < 3; c++) {
        float t = h * 6 - (float)(2 * c);
        t = t < 0 ? t + 6 : t;
        float v = t < 1 ? t : t < 3 ? 1 : t < 4 ? 4 - t : 0;
        rgb[c] = 0.2f + 0.8f * v;
    }
}

static g3d_status write_outputs(const char *dir, const g3d_image *img, const g3d_sam_masks *mk)
{
    char path[4096];
    size_t npx = (size_t)mk->w * mk->h;
    g3d_image m = {0}, over = {0};
    cJSON *root = cJSON_CreateObject(), *arr = cJSON_AddArrayToObject(root, "masks");
    g3d_status rc = g3d_image_create(&m, mk->w, mk->h, 1);
    if (rc == G3D_OK) rc = g3d_image_clone(&over, img);
    cJSON_AddNumberToObject(root, "width", mk->w);
    cJSON_AddNumberToObject(root, "height", mk->h);
    for (int i = 0; i < mk->n && rc == G3D_OK; i++) {
        const uint8_t *src = mk->masks + npx * i;
        float col[3];
        colour(i, col);
        for (size_t j = 0; j < npx; j++) {
            m.data[j] = src[j] ? 1.0f : 0.0f;
            if (src[j])
                for (int c = 0; c < 3; c++) over.data[3 * j + c] = 0.5f * over.data[3 * j + c] + 0.5f * col[c];
        }
        snprintf(path, sizeof path, "%s/mask_%03d.png", dir, i);
        rc = g3d_image_save_png(path, &m, 8);
        cJSON *o = cJSON_CreateObject();
        cJSON_AddItemToArray(arr, o);
        snprintf(path, sizeof path, "mask_%03d.png", i);
        cJSON_AddStringToObject(o, "file", path);
        cJSON_AddNumberToObject(o, "predicted_iou", mk->iou[i]);
        cJSON_AddNumberToObject(o, "stability_score", mk->stability[i]);
        cJSON_AddItemToObject(o, "bbox", cJSON_CreateIntArray(mk->boxes + 4 * i, 4));
        cJSON_AddNumberToObject(o, "area", mk->area[i]);
        double pt[2] = {mk->points[2 * i], mk->points[2 * i + 1]};
        cJSON_AddItemToObject(o, "point_coords", cJSON_CreateDoubleArray(pt, 2));
    }
    if (rc == G3D_OK) {
        snprintf(path, sizeof path, "%s/overlay.png", dir);
        rc = g3d_image_save_png(path, &over, 8);
    }
    char *text = rc == G3D_OK ? cJSON_Print(root) : NULL;
    if (rc == G3D_OK && !text) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) {
        snprintf(path, sizeof path, "%s/masks.json", dir);
        rc = g3d_write_file_atomic(path, text, strlen(text));
    }
    free(text);
    cJSON_Delete(root);
    g3d_image_free(&m);
    g3d_image_free(&over);
    return rc;
}

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    const char *input = NULL, *model_path = NULL, *point = NULL, *box = NULL;
    g3d_sam_amg_params p;
    g3d_sam_amg_params_default(&p);
    double iou = p.pred_iou_thresh, stab = p.stability_score_thresh, off = p.stability_score_offset,
           nms = p.box_nms_thresh;
    g3d_cli_common_init(&common);
    common.output = NULL;
    g3d_opt opts[] = {
        {'m', "model", G3D_OPT_PATH, &model_path, "CKPT", "Segment Anything checkpoint (sam_vit_*.pth)"},
        {'i', "input", G3D_OPT_PATH, &input, "IMAGE", "picture (.png, .jpg)"},
        {0, "points-per-side", G3D_OPT_INT, &p.points_per_side, "N", "grid of N x N prompt points"},
        {0, "pred-iou-thresh", G3D_OPT_DOUBLE, &iou, "T", "keep masks with predicted IoU above T (0: all)"},
        {0, "stability-thresh", G3D_OPT_DOUBLE, &stab, "T", "keep masks with stability at least T (0: all)"},
        {0, "stability-offset", G3D_OPT_DOUBLE, &off, "D", "logit offset of the stability score"},
        {0, "nms-thresh", G3D_OPT_DOUBLE, &nms, "T", "box IoU above which the lower-scored mask goes"},
        {0, "min-region-area", G3D_OPT_INT, &p.min_mask_region_area, "PX",
         "fill holes and drop islands smaller than this in every mask (0: off)"},
        {0, "point", G3D_OPT_STRING, &point, "X,Y[,L]", "one prompt point in pixels, label L 1 (default) or 0"},
        {0, "box", G3D_OPT_STRING, &box, "X0,Y0,X1,Y1", "one prompt box in pixels"},
        G3D_COMMON_OPTS(&common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts), "gen3d segment -m CKPT -i IMAGE -o DIR",
                                  DESCRIPTION, pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if (!input || !model_path || !common.output) return g3d_cli_errorf(G3D_EXIT_USAGE, "-m, -i and -o are required");
    p.pred_iou_thresh = (float)iou;
    p.stability_score_thresh = (float)stab;
    p.stability_score_offset = (float)off;
    p.box_nms_thresh = (float)nms;
    if (p.points_per_side < 1 || p.points_per_side > 256 || !(off >= 0) || !(nms >= 0 && nms <= 1) ||
        p.min_mask_region_area < 0)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--points-per-side must be 1..256, --stability-offset and "
                                              "--min-region-area >= 0, --nms-thresh in [0, 1]");
    float pt[2], bx[4];
    int label = 1, np = 0;
    if (point) {
        char end = 0;
        int k = sscanf(point, "%f,%f,%d%c", &pt[0], &pt[1], &label, &end);
        if ((k != 2 && k != 3) || (label != 0 && label != 1) || !isfinite(pt[0]) || !isfinite(pt[1]))
            return g3d_cli_errorf(G3D_EXIT_USAGE, "--point must be X,Y or X,Y,LABEL with LABEL 0 or 1, not '%s'", point);
        np = 1;
    }
    if (box) {
        char end = 0;
        if (sscanf(box, "%f,%f,%f,%f%c", &bx[0], &bx[1], &bx[2], &bx[3], &end) != 4 || !isfinite(bx[0] + bx[1] + bx[2] + bx[3]))
            return g3d_cli_errorf(G3D_EXIT_USAGE, "--box must be X0,Y0,X1,Y1, not '%s'", box);
    }
    g3d_cli_common_apply(&common);

    g3d_image img = {0};
    g3d_sam *model = NULL;
    g3d_sam_image emb = {0};
    g3d_sam_masks mk = {0};
    uint8_t *px = NULL;
    char *tmp = NULL, desc[256];
    g3d_progress_term term;
    g3d_progress prog = g3d_progress_term_init(&term, stderr, common.quiet);
    g3d_status rc = g3d_image_load(input, 3, &img);
    if (rc == G3D_OK) rc = g3d_sam_load_file(model_path, &model);
    if (rc == G3D_OK) {
        g3d_log(G3D_LOG_INFO, "%s", g3d_sam_describe(model, desc, sizeof desc));
        rc = (px = g3d_sam_rgb8(&img)) ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    double t0 = g3d_time_now();
    if (rc == G3D_OK) rc = g3d_sam_set_image(model, px, img.w, img.h, &emb, NULL);
    if (rc == G3D_OK) g3d_log(G3D_LOG_INFO, "image encoder: %.2f s", g3d_time_now() - t0);
    if (rc == G3D_OK && (point || box)) {
        g3d_sam_prompt prompt = {np, np ? pt : NULL, np ? &label : NULL, box ? bx : NULL, NULL};
        g3d_sam_prediction pr;
        rc = g3d_sam_predict(model, &emb, &prompt, 1, &pr, NULL);
        if (rc == G3D_OK)
            rc = g3d_sam_prediction_masks(&pr, p.stability_score_offset, np ? pt[0] : 0.5f * (bx[0] + bx[2]),
                                          np ? pt[1] : 0.5f * (bx[1] + bx[3]), &mk);
        g3d_sam_prediction_free(&pr);
    } else if (rc == G3D_OK)
        rc = g3d_sam_generate(model, &emb, &p, &prog, &mk);
    if (rc == G3D_OK) rc = g3d_atomic_dir_begin(common.output, &tmp);
    if (rc == G3D_OK) rc = write_outputs(tmp, &img, &mk);
    if (rc == G3D_OK) rc = g3d_atomic_dir_commit(tmp, common.output);
    else if (tmp) g3d_atomic_dir_abort(tmp);
    int code = G3D_EXIT_OK;
    if (rc != G3D_OK)
        code = g3d_cli_fail(rc);
    else {
        g3d_log(G3D_LOG_INFO, "%d masks in %.2f s", mk.n, g3d_time_now() - t0);
        printf("%s\n", common.output);
    }
    free(tmp);
    free(px);
    g3d_sam_masks_free(&mk);
    g3d_sam_image_free(&emb);
    g3d_sam_free(model);
    g3d_image_free(&img);
    return code;
}

const g3d_command g3d_cmd_segment = {"segment", "Segment Anything's automatic masks of a picture", run};
