/* Model recognition: one table of signatures, from checkpoint content only. */
#include "gen3d/recognize.h"

#include "gen3d/blip.h"
#include "gen3d/clip.h"
#include "gen3d/clip_text.h"
#include "gen3d/sd.h"

#include <cjson/cJSON.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Where LaMa's generator layers start ("generator.model." or "model."), or NULL. */
static const char *lama_prefix(const g3d_ckpt *ck)
{
    if (g3d_ckpt_find(ck, "generator.model.1.ffc.convl2l.weight")) return "generator.model.";
    if (g3d_ckpt_find(ck, "model.1.ffc.convl2l.weight")) return "model.";
    return NULL;
}

g3d_model_kind g3d_model_recognize(const g3d_ckpt *ck)
{
    if (cJSON_IsObject(cJSON_GetObjectItemCaseSensitive(g3d_ckpt_meta(ck), "model_config"))) return G3D_MODEL_MOGE;
    if (g3d_ckpt_find(ck, "pretrained.blocks.0.attn.qkv.weight") && g3d_ckpt_find(ck, "depth_head.scratch.output_conv2.2.weight"))
        return G3D_MODEL_DEPTH_ANYTHING_V2;
    g3d_sd_controlnet_config cn;
    if (g3d_sd_controlnet_probe(ck, NULL, &cn) == G3D_OK) return G3D_MODEL_CONTROLNET;
    g3d_sd_unet_config unet;
    if (g3d_sd_unet_probe(ck, NULL, &unet) == G3D_OK) return G3D_MODEL_STABLE_DIFFUSION;
    g3d_clip_text_config clip;
    if (g3d_clip_text_probe(ck, NULL, &clip) == G3D_OK) return G3D_MODEL_CLIP_TEXT;
    g3d_error_clear();
    if (lama_prefix(ck)) return G3D_MODEL_LAMA;
    if (g3d_ckpt_find(ck, "image_encoder.patch_embed.proj.weight") && g3d_ckpt_find(ck, "mask_decoder.iou_token.weight"))
        return G3D_MODEL_SAM;
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

/* The name of a published DINOv2 encoder of this width and depth ("ViT" otherwise): a label
 * only, every figure printed comes from the tensors. */
static const char *vit_name(int64_t width, int blocks)
{
    if (width == 384 && blocks == 12) return "vits: ViT-S";
    if (width == 768 && blocks == 12) return "vitb: ViT-B";
    if (width == 1024 && blocks == 24) return "vitl: ViT-L";
    if (width == 1536 && blocks == 40) return "vitg: ViT-g";
    return "ViT";
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

/* The first dimension of a tensor, or 0. */
static long long dim0(const g3d_ckpt *ck, const char *name)
{
    const g3d_tensor_info *t = g3d_ckpt_find(ck, name);
    return t && t->ndim > 0 ? (long long)t->shape[0] : 0;
}

static const char *vae_describe(const g3d_sd_vae_config *v, char *buf, size_t n)
{
    char mult[64] = "";
    for (int l = 0; l < v->levels; l++) snprintf(mult + strlen(mult), sizeof mult - strlen(mult), "%s%d", l ? "/" : "", v->mult[l]);
    snprintf(buf, n, "Stable Diffusion VAE (channels %d, multipliers %s, %d res blocks, %d latent channels, 1/%d scale)", v->ch,
             mult, v->nres, v->z_ch, v->factor);
    return buf;
}

const char *g3d_model_describe(const g3d_ckpt *ck, char *buf, size_t n)
{
    /* Depth Anything V2: DINOv2 under "pretrained.", DPT head under "depth_head."; sizes from
     * the shapes (heads of 64 channels, as in every published DINOv2). */
    const g3d_tensor_info *qkv = g3d_ckpt_find(ck, "pretrained.blocks.0.attn.qkv.weight");
    const g3d_tensor_info *pe = g3d_ckpt_find(ck, "pretrained.patch_embed.proj.weight");
    if (qkv && g3d_ckpt_find(ck, "depth_head.scratch.output_conv2.2.weight") && qkv->ndim == 2) {
        int blocks = count_blocks(ck, "pretrained.");
        int64_t d = qkv->shape[1];
        snprintf(buf, n, "Depth Anything V2 (%s/%lld, %d blocks, width %lld, %lld attention heads; DPT features %lld, out "
                 "channels %lld, %lld, %lld, %lld)", vit_name(d, blocks), pe && pe->ndim == 4 ? (long long)pe->shape[3] : 0,
                 blocks, (long long)d, (long long)d / 64, dim0(ck, "depth_head.scratch.layer1_rn.weight"),
                 dim0(ck, "depth_head.projects.0.weight"), dim0(ck, "depth_head.projects.1.weight"),
                 dim0(ck, "depth_head.projects.2.weight"), dim0(ck, "depth_head.projects.3.weight"));
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
        snprintf(buf, n, "MoGe-2 (%s, %d blocks, width %lld, %lld attention heads; heads: points%s%s%s)", bb ? bb : "DINOv2",
                 blocks, (long long)mq->shape[1], (long long)mq->shape[1] / 64, g3d_ckpt_find(ck, "normal_head.input_blocks.0.weight") ? ", normal" : "",
                 g3d_ckpt_find(ck, "mask_head.input_blocks.0.weight") ? ", mask" : "",
                 g3d_ckpt_find(ck, "scale_head.0.weight") ? ", metric scale" : "");
        return buf;
    }
    /* a whole CLIP model, a BLIP captioner */
    g3d_clip_config vc;
    g3d_blip_config bc;
    if (g3d_clip_probe(ck, &vc) == G3D_OK) {
        snprintf(buf, n, "CLIP model (image tower: %d px, patch %d, width %d, %d layers; embedding %d; gen3d describe --clip)",
                 vc.image_size, vc.patch, vc.width, vc.layers, vc.embed);
        return buf;
    }
    if (g3d_blip_probe(ck, &bc) == G3D_OK) {
        snprintf(buf, n, "BLIP captioner (%s layout: ViT %d px, patch %d, width %d, %d blocks; BERT decoder width %d, %d layers; "
                 "gen3d describe --caption-model)", bc.hf ? "Hugging Face" : "Salesforce", bc.image_size, bc.patch, bc.vis_width,
                 bc.vis_layers, bc.width, bc.layers);
        return buf;
    }
    /* a ControlNet (before the UNet: ControlNet 1.0 files carry a whole model beside it) */
    g3d_sd_controlnet_config cn;
    if (g3d_sd_controlnet_probe(ck, NULL, &cn) == G3D_OK) return g3d_sd_controlnet_describe(&cn, buf, n);
    g3d_error_clear();
    /* a Stable Diffusion UNet, with the VAE and the text encoder when the file holds them */
    g3d_sd_unet_config unet;
    g3d_clip_text_config clip;
    int has_clip = g3d_clip_text_probe(ck, NULL, &clip) == G3D_OK;
    char *yaml = g3d_sd_yaml_beside(g3d_ckpt_path(ck));
    g3d_status urc = g3d_sd_unet_probe(ck, yaml, &unet);
    free(yaml);
    if (urc == G3D_OK) {
        g3d_sd_vae_config vae;
        g3d_sd_unet_describe(&unet, buf, n);
        size_t k = strlen(buf);
        if (g3d_sd_vae_probe(ck, &vae) == G3D_OK && k + 2 < n) {
            snprintf(buf + k, n - k, "; ");
            k += 2 + strlen(vae_describe(&vae, buf + k + 2, n - k - 2));
        }
        if (has_clip && k < n) {
            snprintf(buf + k, n - k, "; ");
            g3d_clip_text_describe(&clip, buf + k + 2, n - k - 2 > 0 ? n - k - 2 : 0);
        }
        g3d_error_clear();
        return buf;
    }
    g3d_sd_vae_config vae;
    if (g3d_sd_vae_probe(ck, &vae) == G3D_OK) return vae_describe(&vae, buf, n);
    g3d_error_clear();
    if (has_clip) return g3d_clip_text_describe(&clip, buf, n);
    /* LaMa: residual blocks are the layers with a conv1; widths from their BatchNorms */
    const char *lp = lama_prefix(ck);
    if (lp) {
        char name[128];
        int blocks = 0;
        long long local = 0, global = 0;
        for (int i = 2; i < 256; i++) {
            snprintf(name, sizeof name, "%s%d.conv1.bn_l.weight", lp, i);
            long long l = dim0(ck, name);
            snprintf(name, sizeof name, "%s%d.conv1.bn_g.weight", lp, i);
            long long g = dim0(ck, name);
            if (!l && !g) continue;
            if (!blocks) local = l, global = g;
            blocks++;
        }
        snprintf(name, sizeof name, "%s1.bn_l.weight", lp);
        snprintf(buf, n, "LaMa (FFC ResNet generator, width %lld, %d residual blocks, %lld of %lld channels global)",
                 dim0(ck, name), blocks, global, local + global);
        return buf;
    }
    const g3d_tensor_info *sp = g3d_ckpt_find(ck, "image_encoder.pos_embed"),
                          *pw = g3d_ckpt_find(ck, "image_encoder.patch_embed.proj.weight");
    if (sp && sp->ndim == 4 && pw && pw->ndim == 4 && g3d_ckpt_find(ck, "mask_decoder.iou_token.weight")) {
        char name[64];
        int blocks = 0;
        do snprintf(name, sizeof name, "image_encoder.blocks.%d.norm1.weight", blocks);
        while (g3d_ckpt_find(ck, name) && ++blocks < 1000);
        snprintf(buf, n, "Segment Anything (ViT encoder width %lld, %d blocks, input %lld; prompt width %lld)",
                 (long long)sp->shape[3], blocks, (long long)(sp->shape[1] * pw->shape[2]),
                 dim0(ck, "image_encoder.neck.0.weight"));
        return buf;
    }
    return NULL;
}
