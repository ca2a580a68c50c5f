/* Model recognition: one table of signatures, from checkpoint content only. */
#include "gen3d/recognize.h"

#include <cjson/cJSON.h>
#include <stdio.h>

g3d_model_kind g3d_model_recognize(const g3d_ckpt *ck)
{
    if (cJSON_IsObject(cJSON_GetObjectItemCaseSensitive(g3d_ckpt_meta(ck), "model_config"))) return G3D_MODEL_MOGE;
    if (g3d_ckpt_find(ck, "pretrained.blocks.0.attn.qkv.weight") && g3d_ckpt_find(ck, "depth_head.scratch.output_conv2.2.weight"))
        return G3D_MODEL_DEPTH_ANYTHING_V2;
    return G3D_MODEL_UNKNOWN;
}

g3d_model_kind g3d_model_recognize_file(const char *path)
{
    g3d_ckpt *ck = NULL;
    if (g3d_ckpt_open(path, &ck) != G3D_OK) {
        g3d_error_clear();
        return G3D_MODEL_UNKNOWN;
    }
    g3d_model_kind k = g3d_model_recognize(ck);
    g3d_ckpt_free(ck);
    return k;
}

/* Transformer blocks of a DINOv2 backbone stored under `prefix`. */
static int count_blocks(const g3d_ckpt *ck, const char *prefix)
{
    char name[128];
    int blocks = 0;
    for (;; blocks++) {
        snprintf(name, sizeof name, "%sblocks.%d.attn.qkv.weight", prefix, blocks);
        if (!g3d_ckpt_find(ck, name)) return blocks;
    }
}

const char *g3d_model_describe(const g3d_ckpt *ck, char *buf, size_t n)
{
    /* Depth Anything V2: DINOv2 under "pretrained.", DPT head under "depth_head."; the width
     * of the qkv projection names the ViT size. */
    const g3d_tensor_info *qkv = g3d_ckpt_find(ck, "pretrained.blocks.0.attn.qkv.weight");
    if (qkv && g3d_ckpt_find(ck, "depth_head.scratch.output_conv2.2.weight") && qkv->ndim == 2) {
        int blocks = count_blocks(ck, "pretrained.");
        int64_t d = qkv->shape[1];
        const char *size = d == 384 ? "vits: ViT-S/14" : d == 768 ? "vitb: ViT-B/14" : d == 1024 ? "vitl: ViT-L/14" : d == 1536 ? "vitg: ViT-g/14" : "unknown ViT size";
        snprintf(buf, n, "Depth Anything V2 (%s, %d blocks, width %lld)", size, blocks, (long long)d);
        return buf;
    }
    /* MoGe-2: DINOv2 under "encoder.backbone.", a ConvStack neck, the configuration beside the
     * state dict (model_config.encoder.backbone names the ViT). */
    const g3d_tensor_info *mq = g3d_ckpt_find(ck, "encoder.backbone.blocks.0.attn.qkv.weight");
    if (mq && mq->ndim == 2 && g3d_ckpt_find(ck, "neck.input_blocks.0.weight") &&
        g3d_ckpt_find(ck, "points_head.input_blocks.0.weight")) {
        const cJSON *cfg = cJSON_GetObjectItemCaseSensitive(g3d_ckpt_meta(ck), "model_config");
        const cJSON *enc = cJSON_GetObjectItemCaseSensitive(cfg, "encoder");
        const char *bb = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(enc, "backbone"));
        int blocks = count_blocks(ck, "encoder.backbone.");
        snprintf(buf, n, "MoGe-2 (%s, %d blocks, width %lld; heads: points%s%s%s)", bb ? bb : "DINOv2", blocks,
                 (long long)mq->shape[1], g3d_ckpt_find(ck, "normal_head.input_blocks.0.weight") ? ", normal" : "",
                 g3d_ckpt_find(ck, "mask_head.input_blocks.0.weight") ? ", mask" : "",
                 g3d_ckpt_find(ck, "scale_head.0.weight") ? ", metric scale" : "");
        return buf;
    }
    return NULL;
}
