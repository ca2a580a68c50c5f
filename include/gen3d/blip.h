/* gen3d/blip.h - BLIP image captioning (Salesforce's BLIP_Decoder, the model LAVIS's
 * "blip_caption" runs): a ViT image encoder, a BERT text decoder with cross-attention to the
 * image tokens, greedy or beam search after the prompt "a picture of ".
 *
 *   g3d_blip *m;  char *caption;  g3d_blip_gen g;
 *   g3d_blip_load("blip-caption/", &m);        // model_base_capfilt_large.pth + vocab.txt
 *   g3d_blip_gen_default(&g);                   // 3 beams, max_length 20, min_length 5
 *   g3d_blip_caption(m, &image, &g, &caption);  // "a living room with a couch and a table"
 *
 * Layouts read as published: Salesforce's checkpoints ({"model": state dict}: visual_encoder.*,
 * text_decoder.bert.*, text_decoder.cls.*) and Hugging Face's BlipForConditionalGeneration
 * (vision_model.*, text_decoder.*; config.json gives the vision LayerNorm epsilon). Sizes come
 * from the tensors (heads of 64 channels, as BLIP base and large have). The WordPiece
 * vocabulary is vocab.txt beside the weights (bert-base-uncased's), with [DEC] and [ENC]
 * appended when it lacks them, as BLIP's init_tokenizer adds them.
 *
 * A model is immutable after loading; several threads may use it at once.
 */
#ifndef G3D_BLIP_H
#define G3D_BLIP_H

#include "gen3d/base.h"
#include "gen3d/ckpt.h"
#include "gen3d/image.h"

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_blip g3d_blip;

typedef struct g3d_blip_config {
    int hf;                                 /* 1: Hugging Face's names */
    int image_size, patch;                  /* input side (grid * patch), patch side */
    int vis_width, vis_layers, vis_mlp;
    float vis_eps;                          /* 1e-6 (Salesforce), config.json's for Hugging Face */
    int width, layers, mlp, positions;      /* text decoder */
    int vocab;                              /* rows of the word embedding */
    float eps;                              /* 1e-12 */
    int32_t bos, eos, pad;                  /* [DEC], [SEP], [PAD] */
} g3d_blip_config;

/* Opens a BLIP captioner: a folder holding the weights (model_base_capfilt_large.pth,
 * model_base_caption_capfilt_large.pth, model.pth, model.safetensors or pytorch_model.bin)
 * and vocab.txt, or a weights file with vocab.txt beside it. A CLIP model is refused as such;
 * other files name the first missing tensor. */
g3d_status g3d_blip_load(const char *path, g3d_blip **out);
/* The configuration read from an open checkpoint's tensors alone (no vocabulary: bos, eos and
 * pad are 0), without loading weights; the same refusals as loading. */
g3d_status g3d_blip_probe(const g3d_ckpt *ck, g3d_blip_config *c);
void g3d_blip_free(g3d_blip *m);
const g3d_blip_config *g3d_blip_get_config(const g3d_blip *m);
/* A one-line description into buf. */
const char *g3d_blip_describe(const g3d_blip *m, char *buf, size_t n);

/* BLIP's preprocessing: the image resized to size x size (PIL's bicubic, aspect not kept),
 * CLIP's mean and std, into out[3, size, size]. Refuses images under G3D_BLIP_MIN_SIDE. */
#define G3D_BLIP_MIN_SIDE 32
g3d_status g3d_blip_preprocess(const g3d_image *img, int size, float *out);
/* Image tokens of the encoder's output: (image_size / patch)^2 + 1. */
int g3d_blip_image_tokens(const g3d_blip *m);
/* embeds[tokens, vis_width] = the ViT's output (after its final LayerNorm) for pixels. */
g3d_status g3d_blip_encode_pixels(const g3d_blip *m, const float *pixels, float *embeds);
/* logits[vocab] = the decoder's scores for the token after ids[n] (n <= positions). */
g3d_status g3d_blip_next_logits(const g3d_blip *m, const float *embeds, const int32_t *ids, int n, float *logits);

/* The generation settings of BLIP_Decoder.generate (beam search) as the official captioning
 * runs call it (predict.py, configs/caption_coco.yaml). */
typedef struct g3d_blip_gen {
    int num_beams;            /* 3; 1 = greedy */
    int max_length;           /* 20 tokens, prompt included */
    int min_length;           /* 5: the end token is barred until the sequence is this long */
    float repetition_penalty; /* 1.0 (none); above 1 scores of tokens already present shrink */
    const char *prompt;       /* "a picture of " */
} g3d_blip_gen;
void g3d_blip_gen_default(g3d_blip_gen *g);

/* The prompt's ids as BLIP frames it: [DEC], then its WordPiece tokens. *ids malloc'd. */
g3d_status g3d_blip_prompt_ids(const g3d_blip *m, const char *prompt, int32_t **ids, int *n);
/* The ids generated from embeds (transformers' greedy or beam search with BLIP's settings),
 * prompt first, the end token last when one was produced. *ids malloc'd. */
g3d_status g3d_blip_generate(const g3d_blip *m, const float *embeds, const g3d_blip_gen *g, int32_t **ids, int *n);
/* The text of ids as BertTokenizer.decode(skip_special_tokens=True) gives it (WordPiece
 * pieces joined, spaces before punctuation removed), malloc'd. */
char *g3d_blip_decode(const g3d_blip *m, const int32_t *ids, int n);
/* Preprocessing, encoding, generation and decoding, the prompt cut off: *caption malloc'd. */
g3d_status g3d_blip_caption(const g3d_blip *m, const g3d_image *img, const g3d_blip_gen *g, char **caption);

#ifdef __cplusplus
}
#endif
#endif /* G3D_BLIP_H */
