/* gen3d/clip.h - a whole CLIP model (image tower, text tower, projections, logit scale) for
 * zero-shot classification, loaded from the files users have.
 *
 *   g3d_clip *m;  g3d_clip_tokenizer *tok;
 *   g3d_clip_load("clip-vit-base-patch32/", &m);        // Hugging Face CLIPModel folder
 *   g3d_clip_tokenizer_load("clip-vit-base-patch32/", &tok);
 *   float *img = malloc(sizeof(float) * g3d_clip_get_config(m)->embed), probs[2];
 *   g3d_clip_encode_image(m, &image, img, NULL);                 // preprocessing included
 *   const char *labels[] = {"kitchen", "beach"};
 *   g3d_clip_zero_shot(m, tok, img, labels, 2, "a photo of a {}.", NULL, probs);
 *
 * The image tower is OpenAI's ViT (B/32, B/16, L/14, L/14-336 and OpenCLIP's larger ones):
 * a patch convolution without bias, the class embedding, learned positions, ln_pre, pre-norm
 * blocks, ln_post on the class token, the visual projection. The text tower is the one of
 * gen3d/clip_text.h. Sizes come from the tensors; the activation from config.json
 * (vision_config.hidden_act), open_clip_config.json (model_cfg.quick_gelu), else quick_gelu,
 * as OpenAI's released weights use.
 *
 * A model is immutable after loading; several threads may use it at once.
 */
#ifndef G3D_CLIP_H
#define G3D_CLIP_H

#include "gen3d/clip_text.h"
#include "gen3d/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_clip g3d_clip;

/* The smallest short side an image may have (it is resized to the model's input, usually 224;
 * below this it holds too little to classify). */
#define G3D_CLIP_MIN_SIDE 32

typedef struct g3d_clip_config {
    g3d_clip_family family; /* G3D_CLIP_HF (vision_model.*) or G3D_CLIP_OPENCLIP (visual.*) */
    int image_size, patch;  /* input side (grid * patch) and patch side */
    int width, heads, layers, mlp;
    int embed;              /* joint embedding width */
    g3d_act act;
    float eps;
    float logit_scale;      /* exp of the stored logit_scale */
} g3d_clip_config;

/* Opens a CLIP model: a Hugging Face CLIPModel folder (model.safetensors or pytorch_model.bin
 * with config.json), an OpenCLIP folder (open_clip_pytorch_model.bin or
 * open_clip_model.safetensors with open_clip_config.json), or a single state-dict file of
 * either layout. A file without an image tower is refused naming the first missing tensor (a
 * BLIP captioning checkpoint is named as such). Free with g3d_clip_free. */
g3d_status g3d_clip_load(const char *path, g3d_clip **out);
/* The image tower's configuration read from an open checkpoint's tensors alone (activation
 * quick_gelu), without loading weights; the same refusals as loading. */
g3d_status g3d_clip_probe(const g3d_ckpt *ck, g3d_clip_config *c);
void g3d_clip_free(g3d_clip *m);
const g3d_clip_config *g3d_clip_get_config(const g3d_clip *m);
/* The text tower (owned by the model). */
const g3d_clip_text *g3d_clip_get_text(const g3d_clip *m);
/* A one-line description into buf. */
const char *g3d_clip_describe(const g3d_clip *m, char *buf, size_t n);

/* CLIP's published preprocessing of an RGB (or grey) image with values in [0, 1] into
 * out[3, size, size]: to 8 bits, the short side resized to `size` (the long one to
 * int(size * long / short)) with PIL's bicubic, the centre crop torchvision takes (offset
 * round((side - size) / 2), half to even), then (x / 255 - mean) / std with CLIP's mean and
 * std. G3D_ERR_ARG if the short side is below G3D_CLIP_MIN_SIDE. */
g3d_status g3d_clip_preprocess(const g3d_image *img, int size, float *out);

/* embed[config.embed] = encode_image of preprocessed pixels [3, image_size, image_size]
 * (unnormalised); class_token[width] (ln_post's output) when not NULL. */
g3d_status g3d_clip_encode_pixels(const g3d_clip *m, const float *pixels, float *embed, float *class_token);
/* Preprocessing and encode_image of an image. */
g3d_status g3d_clip_encode_image(const g3d_clip *m, const g3d_image *img, float *embed, float *class_token);
/* embed[config.embed] = encode_text of a prompt, tokenized as clip.tokenize frames it. */
g3d_status g3d_clip_encode_text(const g3d_clip *m, const g3d_clip_tokenizer *tok, const char *text, float *embed);

/* Zero-shot classification of an image embedding over labels[n]: each label put in place of
 * "{}" in tmpl (e.g. "a photo of a {}."), logits[i] = logit_scale * cosine(image, text_i),
 * probs = their softmax. logits or probs may be NULL. */
g3d_status g3d_clip_zero_shot(const g3d_clip *m, const g3d_clip_tokenizer *tok, const float *image_embed,
                              const char *const *labels, int n, const char *tmpl, float *logits, float *probs);

#ifdef __cplusplus
}
#endif
#endif /* G3D_CLIP_H */
