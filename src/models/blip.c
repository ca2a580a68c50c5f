/* BLIP captioning: timm's ViT (pre-norm, the same block as CLIP's with GELU) and BLIP's BERT
 * decoder (post-norm layers with causal self-attention and cross-attention to the image),
 * WordPiece tokens, and transformers' greedy and beam search as BLIP calls them. */
#include "gen3d/blip.h"

#include "clip_int.h"
#include "gen3d/nn.h"

#include <cjson/cJSON.h>

#include <ctype.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define HEAD_DIM 64
#define WORD_MAX 100 /* BERT's max_input_chars_per_word: longer words become [UNK] */

typedef struct bert_layer {
    g3d_nn_lin qkv, out, cq, ckv, cout, inter, fout;
    float *ln1w, *ln1b, *ln2w, *ln2b, *ln3w, *ln3b;
} bert_layer;

struct g3d_blip {
    g3d_blip_config cfg;
    g3d_ckpt *ck;
    /* image encoder */
    g3d_nn_lin patch;
    float *cls, *pos, *normw, *normb;
    g3d_clip_block *vblocks;
    /* text decoder */
    const g3d_tensor_info *words;  /* word embeddings [vocab, width], read row by row */
    float *tpos, *elnw, *elnb;     /* positions [positions, width], embedding LayerNorm */
    bert_layer *layers;
    g3d_nn_lin head, lm;           /* prediction transform, decoder + bias */
    float *hlnw, *hlnb;
    /* vocabulary */
    char **tokens;                 /* [vocab] */
    int ntokens;
    int *sorted;                   /* token indices in strcmp order */
    int32_t unk, cls_id, mask_id, enc;
};

typedef struct names {
    const char *conv, *convb, *cls, *pos, *norm, *block, *ln1, *qkv, *proj, *ln2;
} names;
static const names SF = {"visual_encoder.patch_embed.proj.weight", "visual_encoder.patch_embed.proj.bias",
                         "visual_encoder.cls_token", "visual_encoder.pos_embed", "visual_encoder.norm.",
                         "visual_encoder.blocks.%d.", "norm1.", "attn.qkv", "attn.proj", "norm2."};
static const names HFN = {"vision_model.embeddings.patch_embedding.weight", "vision_model.embeddings.patch_embedding.bias",
                          "vision_model.embeddings.class_embedding", "vision_model.embeddings.position_embedding",
                          "vision_model.post_layernorm.", "vision_model.encoder.layers.%d.", "layer_norm1.",
                          "self_attn.qkv", "self_attn.projection", "layer_norm2."};
#define TD "text_decoder.bert."

static void free_layer(bert_layer *l)
{
    g3d_nn_lin *L[] = {&l->qkv, &l->out, &l->cq, &l->ckv, &l->cout, &l->inter, &l->fout};
    for (size_t i = 0; i < sizeof L / sizeof L[0]; i++) g3d_nn_lin_free(L[i]);
    free(l->ln1w); free(l->ln1b); free(l->ln2w); free(l->ln2b); free(l->ln3w); free(l->ln3b);
}

void g3d_blip_free(g3d_blip *m)
{
    if (!m) return;
    for (int i = 0; m->vblocks && i < m->cfg.vis_layers; i++) g3d_clip_block_free(&m->vblocks[i]);
    for (int i = 0; m->layers && i < m->cfg.layers; i++) free_layer(&m->layers[i]);
    free(m->vblocks);
    free(m->layers);
    g3d_nn_lin_free(&m->patch);
    g3d_nn_lin_free(&m->head);
    g3d_nn_lin_free(&m->lm);
    free(m->cls); free(m->pos); free(m->normw); free(m->normb);
    free(m->tpos); free(m->elnw); free(m->elnb); free(m->hlnw); free(m->hlnb);
    for (int i = 0; m->tokens && i < m->ntokens; i++) free(m->tokens[i]);
    free(m->tokens);
    free(m->sorted);
    g3d_ckpt_free(m->ck);
    free(m);
}

/* One Linear layer <base><name>.weight / .bias. */
static g3d_status lin1(const g3d_ckpt *ck, const char *base, const char *name, int out, int in, g3d_nn_lin *L)
{
    char w[256], b[256];
    snprintf(w, sizeof w, "%s.weight", name);
    snprintf(b, sizeof b, "%s.bias", name);
    const char *wp[1] = {w}, *bp[1] = {b};
    return g3d_clip_lin(ck, base, L, out, in, 1, wp, bp);
}

static g3d_status ln(const g3d_ckpt *ck, const char *base, const char *name, int D, float **w, float **b)
{
    G3D_TRY(g3d_clip_readf(ck, base, w, D, 0, "%sweight", name));
    return g3d_clip_readf(ck, base, b, D, 0, "%sbias", name);
}

static g3d_status probe(const g3d_ckpt *ck, const cJSON *cfg, g3d_blip_config *c)
{
    const char *path = g3d_ckpt_path(ck);
    memset(c, 0, sizeof *c);
    const names *n = NULL;
    if (g3d_ckpt_find(ck, SF.conv)) n = &SF;
    else if (g3d_ckpt_find(ck, HFN.conv) && g3d_ckpt_find(ck, HFN.convb)) n = &HFN, c->hf = 1;
    else if (g3d_ckpt_find(ck, "visual.conv1.weight") || g3d_ckpt_find(ck, "vision_model.embeddings.patch_embedding.weight"))
        return G3D_ERR(G3D_ERR_MODEL, "%s: a CLIP model, not a BLIP captioner (give it as the CLIP model)", path);
    else
        return G3D_ERR(G3D_ERR_MODEL, "%s: not a BLIP captioner (missing tensor %s)", path, SF.conv);
    if (!g3d_ckpt_find(ck, TD "embeddings.word_embeddings.weight"))
        return G3D_ERR(G3D_ERR_MODEL, "%s: no caption decoder (missing tensor " TD "embeddings.word_embeddings.weight; "
                       "a BLIP retrieval or VQA checkpoint?)", path);
    const g3d_tensor_info *cw = g3d_ckpt_find(ck, n->conv), *pe = g3d_ckpt_find(ck, n->pos);
    const g3d_tensor_info *we = g3d_ckpt_find(ck, TD "embeddings.word_embeddings.weight");
    const g3d_tensor_info *tp = g3d_ckpt_find(ck, TD "embeddings.position_embeddings.weight");
    const g3d_tensor_info *vf = g3d_clip_findf(ck, "", n == &SF ? "visual_encoder.blocks.0.mlp.fc1.weight"
                                                                 : "vision_model.encoder.layers.0.mlp.fc1.weight");
    const g3d_tensor_info *tf = g3d_ckpt_find(ck, TD "encoder.layer.0.intermediate.dense.weight");
    if (cw->ndim != 4 || cw->shape[1] != 3 || cw->shape[2] != cw->shape[3] || cw->shape[0] % HEAD_DIM)
        return G3D_ERR(G3D_ERR_MODEL, "%s: %s is not [width, 3, p, p] with a width in heads of %d", path, n->conv, HEAD_DIM);
    c->vis_width = (int)cw->shape[0];
    c->patch = (int)cw->shape[2];
    int grid = pe && pe->ndim == 3 ? (int)lround(sqrt((double)(pe->shape[1] - 1))) : 0;
    if (!pe || pe->ndim != 3 || pe->shape[2] != c->vis_width || grid < 1 || (int64_t)grid * grid + 1 != pe->shape[1])
        return G3D_ERR(G3D_ERR_MODEL, "%s: %s missing or not [1, grid^2 + 1, %d]", path, n->pos, c->vis_width);
    c->image_size = grid * c->patch;
    if (!we || we->ndim != 2 || we->shape[1] % HEAD_DIM || !tp || tp->ndim != 2 || tp->shape[1] != we->shape[1] || !vf ||
        vf->ndim != 2 || !tf || tf->ndim != 2)
        return G3D_ERR(G3D_ERR_MODEL, "%s: the decoder's embeddings or the first blocks are missing or misshapen", path);
    c->vocab = (int)we->shape[0];
    c->width = (int)we->shape[1];
    c->positions = (int)tp->shape[0];
    c->vis_mlp = (int)vf->shape[0];
    c->mlp = (int)tf->shape[0];
    while (g3d_clip_findf(ck, "", n == &SF ? "visual_encoder.blocks.%d.norm1.weight" : "vision_model.encoder.layers.%d.layer_norm1.weight",
                          c->vis_layers))
        c->vis_layers++;
    while (g3d_clip_findf(ck, TD, "encoder.layer.%d.attention.self.query.weight", c->layers)) c->layers++;
    c->vis_eps = n == &SF ? 1e-6f : 1e-5f;
    c->eps = 1e-12f;
    const cJSON *ve = cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(cfg, "vision_config"), "layer_norm_eps");
    const cJSON *te = cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(cfg, "text_config"), "layer_norm_eps");
    if (cJSON_IsNumber(ve) && ve->valuedouble > 0) c->vis_eps = (float)ve->valuedouble;
    if (cJSON_IsNumber(te) && te->valuedouble > 0) c->eps = (float)te->valuedouble;
    return G3D_OK;
}

static g3d_status load_vision(g3d_blip *m)
{
    const g3d_blip_config *c = &m->cfg;
    const names *n = c->hf ? &HFN : &SF;
    int W = c->vis_width, P = c->patch, np = (c->image_size / P) * (c->image_size / P);
    float *cw = NULL, *cb = NULL;
    int64_t cs[4] = {W, 3, P, P}, c3[3] = {1, 1, W}, p3[3] = {1, np + 1, W};
    g3d_status rc = g3d_ckpt_read_alloc(m->ck, n->conv, 4, cs, &cw);
    if (rc == G3D_OK) rc = g3d_clip_readf(m->ck, "", &cb, W, 0, "%s", n->convb);
    if (rc == G3D_OK) rc = g3d_nn_lin_init(&m->patch, cw, G3D_DT_F32, cb, W, 3 * P * P, G3D_DT_F32);
    free(cw);
    free(cb);
    if (rc == G3D_OK) rc = g3d_ckpt_read_alloc(m->ck, n->cls, 3, c3, &m->cls);
    if (rc == G3D_OK) rc = g3d_ckpt_read_alloc(m->ck, n->pos, 3, p3, &m->pos);
    if (rc == G3D_OK) rc = ln(m->ck, "", n->norm, W, &m->normw, &m->normb);
    if (rc == G3D_OK && !(m->vblocks = calloc((size_t)c->vis_layers, sizeof *m->vblocks)))
        rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory loading BLIP");
    for (int i = 0; rc == G3D_OK && i < c->vis_layers; i++) {
        char base[128];
        snprintf(base, sizeof base, n->block, i);
        g3d_clip_block *b = &m->vblocks[i];
        rc = lin1(m->ck, base, n->qkv, 3 * W, W, &b->qkv);
        if (rc == G3D_OK) rc = lin1(m->ck, base, n->proj, W, W, &b->out);
        if (rc == G3D_OK) rc = lin1(m->ck, base, "mlp.fc1", c->vis_mlp, W, &b->fc1);
        if (rc == G3D_OK) rc = lin1(m->ck, base, "mlp.fc2", W, c->vis_mlp, &b->fc2);
        if (rc == G3D_OK) rc = ln(m->ck, base, n->ln1, W, &b->ln1w, &b->ln1b);
        if (rc == G3D_OK) rc = ln(m->ck, base, n->ln2, W, &b->ln2w, &b->ln2b);
    }
    return rc;
}

static g3d_status load_decoder(g3d_blip *m)
{
    const g3d_blip_config *c = &m->cfg;
    int D = c->width, Dv = c->vis_width;
    m->words = g3d_ckpt_find(m->ck, TD "embeddings.word_embeddings.weight");
    g3d_status rc = g3d_clip_readf(m->ck, TD, &m->tpos, c->positions, D, "embeddings.position_embeddings.weight");
    if (rc == G3D_OK) rc = ln(m->ck, TD, "embeddings.LayerNorm.", D, &m->elnw, &m->elnb);
    if (rc == G3D_OK && !(m->layers = calloc((size_t)c->layers, sizeof *m->layers)))
        rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory loading BLIP");
    for (int i = 0; rc == G3D_OK && i < c->layers; i++) {
        bert_layer *l = &m->layers[i];
        char base[128], w[3][64], b[3][64];
        snprintf(base, sizeof base, TD "encoder.layer.%d.", i);
        static const char *const qkv[3] = {"query", "key", "value"};
        const char *wp[3] = {w[0], w[1], w[2]}, *bp[3] = {b[0], b[1], b[2]};
        for (int k = 0; k < 3; k++) {
            snprintf(w[k], sizeof w[k], "attention.self.%s.weight", qkv[k]);
            snprintf(b[k], sizeof b[k], "attention.self.%s.bias", qkv[k]);
        }
        rc = g3d_clip_lin(m->ck, base, &l->qkv, 3 * D, D, 3, wp, bp);
        for (int k = 0; k < 2; k++) {
            snprintf(w[k], sizeof w[k], "crossattention.self.%s.weight", qkv[k + 1]);
            snprintf(b[k], sizeof b[k], "crossattention.self.%s.bias", qkv[k + 1]);
        }
        if (rc == G3D_OK) rc = g3d_clip_lin(m->ck, base, &l->ckv, 2 * D, Dv, 2, wp, bp);
        if (rc == G3D_OK) rc = lin1(m->ck, base, "attention.output.dense", D, D, &l->out);
        if (rc == G3D_OK) rc = lin1(m->ck, base, "crossattention.self.query", D, D, &l->cq);
        if (rc == G3D_OK) rc = lin1(m->ck, base, "crossattention.output.dense", D, D, &l->cout);
        if (rc == G3D_OK) rc = lin1(m->ck, base, "intermediate.dense", c->mlp, D, &l->inter);
        if (rc == G3D_OK) rc = lin1(m->ck, base, "output.dense", D, c->mlp, &l->fout);
        if (rc == G3D_OK) rc = ln(m->ck, base, "attention.output.LayerNorm.", D, &l->ln1w, &l->ln1b);
        if (rc == G3D_OK) rc = ln(m->ck, base, "crossattention.output.LayerNorm.", D, &l->ln2w, &l->ln2b);
        if (rc == G3D_OK) rc = ln(m->ck, base, "output.LayerNorm.", D, &l->ln3w, &l->ln3b);
    }
    const char *hw[1] = {"predictions.decoder.weight"}, *hb[1] = {"predictions.bias"};
    if (rc == G3D_OK) rc = lin1(m->ck, "text_decoder.cls.", "predictions.transform.dense", D, D, &m->head);
    if (rc == G3D_OK) rc = ln(m->ck, "text_decoder.cls.", "predictions.transform.LayerNorm.", D, &m->hlnw, &m->hlnb);
    if (rc == G3D_OK) rc = g3d_clip_lin(m->ck, "text_decoder.cls.", &m->lm, c->vocab, D, 1, hw, hb);
    return rc;
}

/* ---- vocabulary -------------------------------------------------------------------------- */

static int find_token(const g3d_blip *m, const char *s)
{
    int lo = 0, hi = m->ntokens - 1;
    while (lo <= hi) {
        int mid = (lo + hi) / 2, c = strcmp(m->tokens[m->sorted[mid]], s);
        if (!c) return m->sorted[mid];
        if (c < 0) lo = mid + 1;
        else hi = mid - 1;
    }
    return -1;
}

/* Sorts idx[n] by token string: a merge sort, since qsort's comparator could not reach the strings
 * without global state. */
static void sort_ids(char **tok, int *idx, int *tmp, int n)
{
    if (n < 2) return;
    int h = n / 2;
    sort_ids(tok, idx, tmp, h);
    sort_ids(tok, idx + h, tmp, n - h);
    int i = 0, j = h, k = 0;
    while (i < h || j < n) tmp[k++] = j >= n || (i < h && strcmp(tok[idx[i]], tok[idx[j]]) <= 0) ? idx[i++] : idx[j++];
    memcpy(idx, tmp, sizeof(int) * (size_t)n);
}

static g3d_status load_vocab(g3d_blip *m, const char *path)
{
    unsigned char *d = NULL;
    size_t len;
    G3D_TRY(g3d_read_file(path, 64 << 20, &d, &len));
    int cap = 2;
    for (size_t i = 0; i < len; i++) cap += d[i] == '\n';
    m->tokens = calloc((size_t)cap + 1, sizeof *m->tokens);
    g3d_status rc = m->tokens ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    for (size_t i = 0; rc == G3D_OK && i < len;) {
        size_t e = i;
        while (e < len && d[e] != '\n') e++;
        size_t b = e;
        if (b > i && d[b - 1] == '\r') b--;
        if (!(m->tokens[m->ntokens] = malloc(b - i + 1))) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        else {
            memcpy(m->tokens[m->ntokens], d + i, b - i);
            m->tokens[m->ntokens++][b - i] = 0;
        }
        i = e + 1;
    }
    free(d);
    /* BLIP's init_tokenizer adds [DEC] (bos) and [ENC] after the vocabulary */
    static const char *const added[2] = {"[DEC]", "[ENC]"};
    for (int k = 0; rc == G3D_OK && k < 2; k++) {
        int have = 0;
        for (int i = 0; i < m->ntokens; i++) have |= !strcmp(m->tokens[i], added[k]);
        if (!have && !(m->tokens[m->ntokens++] = strdup(added[k]))) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    int *tmp = rc == G3D_OK ? malloc(sizeof(int) * (size_t)m->ntokens) : NULL;
    if (rc == G3D_OK && (!tmp || !(m->sorted = malloc(sizeof(int) * (size_t)m->ntokens)))) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) {
        for (int i = 0; i < m->ntokens; i++) m->sorted[i] = i;
        sort_ids(m->tokens, m->sorted, tmp, m->ntokens);
    }
    free(tmp);
    if (rc != G3D_OK) return rc;
    const char *need[] = {"[PAD]", "[UNK]", "[CLS]", "[SEP]", "[MASK]"};
    int32_t *dst[] = {&m->cfg.pad, &m->unk, &m->cls_id, &m->cfg.eos, &m->mask_id};
    for (int k = 0; k < 5; k++)
        if ((*dst[k] = find_token(m, need[k])) < 0) return G3D_ERR(G3D_ERR_FORMAT, "%s: no %s token (a BERT vocab.txt expected)", path, need[k]);
    m->cfg.bos = find_token(m, "[DEC]");
    m->enc = find_token(m, "[ENC]");
    if (m->ntokens > m->cfg.vocab)
        return G3D_ERR(G3D_ERR_MODEL, "%s: %d tokens with [DEC] and [ENC], but the decoder has %d embeddings", path, m->ntokens,
                       m->cfg.vocab);
    return G3D_OK;
}

/* ---- loading ----------------------------------------------------------------------------- */
static int is_file(const char *p)
{
    struct stat st;
    return stat(p, &st) == 0 && S_ISREG(st.st_mode);
}

g3d_status g3d_blip_load(const char *path, g3d_blip **out)
{
    *out = NULL;
    struct stat st;
    if (stat(path, &st) != 0) return G3D_ERR(G3D_ERR_IO, "%s: no such file or folder", path);
    char *dir = NULL, *file = NULL;
    if (S_ISDIR(st.st_mode)) {
        static const char *const names[] = {"model_base_capfilt_large.pth", "model_base_caption_capfilt_large.pth",
                                            "model_large_caption.pth", "model.pth", "model.safetensors", "pytorch_model.bin"};
        for (size_t i = 0; i < sizeof names / sizeof names[0] && !file; i++) {
            char *f = g3d_path_join(path, names[i]);
            if (f && is_file(f)) file = f;
            else free(f);
        }
        if (!file)
            return G3D_ERR(G3D_ERR_IO, "%s: no BLIP weights here (model_base_capfilt_large.pth, model.safetensors or pytorch_model.bin expected)",
                           path);
        dir = strdup(path);
    } else {
        file = strdup(path);
        const char *slash = strrchr(path, '/');
        dir = slash ? strndup(path, (size_t)(slash - path + 1)) : strdup(".");
    }
    char *vocab = dir ? g3d_path_join(dir, "vocab.txt") : NULL, *cfgp = dir ? g3d_path_join(dir, "config.json") : NULL;
    g3d_blip *m = calloc(1, sizeof *m);
    g3d_status rc = file && dir && vocab && cfgp && m ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    cJSON *cfg = NULL;
    if (rc == G3D_OK && is_file(cfgp)) {
        unsigned char *d = NULL;
        size_t n;
        rc = g3d_read_file(cfgp, 1 << 20, &d, &n);
        if (rc == G3D_OK && !(cfg = cJSON_ParseWithLength((const char *)d, n))) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: not valid JSON", cfgp);
        free(d);
    }
    if (rc == G3D_OK) rc = g3d_ckpt_open(file, &m->ck);
    if (rc == G3D_OK) rc = probe(m->ck, cfg, &m->cfg);
    if (rc == G3D_OK && !is_file(vocab))
        rc = G3D_ERR(G3D_ERR_IO, "%s: no vocab.txt beside the weights (BERT base uncased's WordPiece vocabulary)", dir);
    if (rc == G3D_OK) rc = load_vocab(m, vocab);
    if (rc == G3D_OK) rc = load_vision(m);
    if (rc == G3D_OK) rc = load_decoder(m);
    cJSON_Delete(cfg);
    free(dir);
    free(file);
    free(vocab);
    free(cfgp);
    if (rc != G3D_OK) {
        if (m && !m->vblocks) m->cfg.vis_layers = 0;
        if (m && !m->layers) m->cfg.layers = 0;
        g3d_blip_free(m);
        return rc;
    }
    *out = m;
    return G3D_OK;
}

g3d_status g3d_blip_probe(const g3d_ckpt *ck, g3d_blip_config *c) { return probe(ck, NULL, c); }

const g3d_blip_config *g3d_blip_get_config(const g3d_blip *m) { return &m->cfg; }
int g3d_blip_image_tokens(const g3d_blip *m)
{
    int g = m->cfg.image_size / m->cfg.patch;
    return g * g + 1;
}

const char *g3d_blip_describe(const g3d_blip *m, char *buf, size_t n)
{
    const g3d_blip_config *c = &m->cfg;
    snprintf(buf, n, "BLIP captioner (%s layout: ViT %d px, patch %d, width %d, %d blocks; BERT decoder width %d, %d layers, "
             "vocabulary %d)", c->hf ? "Hugging Face" : "Salesforce", c->image_size, c->patch, c->vis_width, c->vis_layers,
             c->width, c->layers, c->vocab);
    return buf;
}

/* ---- image encoder ------------------------------------------------------------------------- */
g3d_status g3d_blip_preprocess(const g3d_image *img, int size, float *out)
{
    if (img->c != 3 && img->c != 1) return G3D_ERR(G3D_ERR_ARG, "BLIP needs an RGB or grey image (%d channels given)", img->c);
    if (img->w < G3D_BLIP_MIN_SIDE || img->h < G3D_BLIP_MIN_SIDE)
        return G3D_ERR(G3D_ERR_ARG, "the image is %dx%d: at least %d pixels on each side are needed", img->w, img->h, G3D_BLIP_MIN_SIDE);
    return g3d_clip_pixels(img, size, size, size, out);
}

g3d_status g3d_blip_encode_pixels(const g3d_blip *m, const float *pixels, float *embeds)
{
    const g3d_blip_config *c = &m->cfg;
    int W = c->vis_width, P = c->patch, S = c->image_size, grid = S / P, np = grid * grid, n = np + 1, K = 3 * P * P;
    float *rows = malloc(sizeof(float) * (size_t)np * K);
    g3d_clip_scratch w = {0};
    g3d_status rc = rows ? g3d_clip_scratch_alloc(&w, n, W, c->vis_mlp) : G3D_ERR(G3D_ERR_NOMEM, "out of memory in BLIP");
    if (rc == G3D_OK) {
        for (int py = 0; py < grid; py++)
            for (int px = 0; px < grid; px++)
                for (int ch = 0; ch < 3; ch++)
                    for (int y = 0; y < P; y++)
                        memcpy(rows + (size_t)(py * grid + px) * K + (ch * P + y) * P,
                               pixels + ((size_t)ch * S + py * P + y) * S + px * P, sizeof(float) * P);
        rc = g3d_nn_lin_forward(&m->patch, rows, np, 0, embeds + W, 0, NULL);
    }
    if (rc == G3D_OK) {
        memcpy(embeds, m->cls, sizeof(float) * W);
        g3d_nn_add(embeds, m->pos, (size_t)n * W);
    }
    g3d_clip_block_shape sh = {.width = W, .heads = W / HEAD_DIM, .act = G3D_ACT_GELU, .eps = c->vis_eps, .causal = 0};
    for (int l = 0; rc == G3D_OK && l < c->vis_layers; l++) rc = g3d_clip_block_forward(&m->vblocks[l], &sh, embeds, n, &w);
    if (rc == G3D_OK) g3d_nn_layernorm(embeds, n, W, m->normw, m->normb, c->vis_eps, embeds);
    free(rows);
    g3d_clip_scratch_free(&w);
    return rc;
}

/* ---- text decoder -------------------------------------------------------------------------- */
/* The image side of every cross-attention, computed once per image: kv[layer] [tokens, 2 width]. */
typedef struct cross_kv {
    float **kv;
    int layers, tokens;
} cross_kv;

static void cross_free(cross_kv *x)
{
    for (int i = 0; x->kv && i < x->layers; i++) free(x->kv[i]);
    free(x->kv);
}

static g3d_status cross_make(const g3d_blip *m, const float *embeds, cross_kv *x)
{
    x->layers = m->cfg.layers;
    x->tokens = g3d_blip_image_tokens(m);
    x->kv = calloc((size_t)x->layers, sizeof *x->kv);
    g3d_status rc = x->kv ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory in BLIP");
    for (int l = 0; rc == G3D_OK && l < x->layers; l++) {
        x->kv[l] = malloc(sizeof(float) * (size_t)x->tokens * 2 * m->cfg.width);
        rc = x->kv[l] ? g3d_nn_lin_forward(&m->layers[l].ckv, embeds, x->tokens, 0, x->kv[l], 0, NULL)
                      : G3D_ERR(G3D_ERR_NOMEM, "out of memory in BLIP");
    }
    if (rc != G3D_OK) cross_free(x);
    return rc;
}

/* A sequence's self-attention keys and values so far (transformers' past_key_values):
 * kv + (layer * cap + i) * 2 width holds position i's key, then its value. */
typedef struct self_kv {
    float *kv;
    int len, cap, layers, width;
} self_kv;

static g3d_status self_make(const g3d_blip *m, int cap, self_kv *c)
{
    *c = (self_kv){.cap = cap, .layers = m->cfg.layers, .width = m->cfg.width};
    c->kv = malloc(sizeof(float) * (size_t)c->layers * cap * 2 * c->width);
    return c->kv ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory in BLIP");
}

/* dst = src (the first src->len positions). */
static void self_copy(self_kv *dst, const self_kv *src)
{
    size_t row = 2 * (size_t)src->width;
    for (int l = 0; l < src->layers; l++)
        memcpy(dst->kv + (size_t)l * dst->cap * row, src->kv + (size_t)l * src->cap * row, sizeof(float) * row * src->len);
    dst->len = src->len;
}

/* logits[vocab] for the token after ids[n]: the positions past cache->len run through the
 * decoder (appending their keys and values to the cache), attending to the cached ones. */
static g3d_status next_logits(const g3d_blip *m, const cross_kv *x, self_kv *cache, const int32_t *ids, int n, float *logits)
{
    const g3d_blip_config *c = &m->cfg;
    int D = c->width, hd = HEAD_DIM, heads = D / HEAD_DIM, p0 = cache->len, k = n - p0;
    if (n < 1 || n > c->positions || n > cache->cap || k < 1)
        return G3D_ERR(G3D_ERR_ARG, "%d tokens after %d: 1 to %d in all expected", k, p0, c->positions);
    for (int i = p0; i < n; i++)
        if (ids[i] < 0 || ids[i] >= c->vocab) return G3D_ERR(G3D_ERR_ARG, "token id %d outside the vocabulary (%d)", ids[i], c->vocab);
    size_t nd = (size_t)k * D;
    float *X = malloc(sizeof(float) * nd), *Q = malloc(sizeof(float) * 3 * nd), *A = malloc(sizeof(float) * nd);
    float *H = malloc(sizeof(float) * (size_t)k * c->mlp), *t = malloc(sizeof(float) * D);
    g3d_status rc = X && Q && A && H && t ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory in BLIP");
    if (rc == G3D_OK) {
        size_t es = g3d_dtype_size(m->words->dtype);
        for (int i = 0; i < k; i++) {
            g3d_dtype_to_f32(m->words->dtype, (const char *)m->words->data + (size_t)ids[p0 + i] * D * es, X + (size_t)i * D, D);
            g3d_nn_add(X + (size_t)i * D, m->tpos + (size_t)(p0 + i) * D, (size_t)D);
        }
        g3d_nn_layernorm(X, k, D, m->elnw, m->elnb, c->eps, X);
    }
    for (int l = 0; rc == G3D_OK && l < c->layers; l++) {
        const bert_layer *L = &m->layers[l];
        float *kv = cache->kv + (size_t)l * cache->cap * 2 * D;
        g3d_nn_epi res = {.res = X};
        /* post-norm: X = LN(X + sublayer(X)) */
        rc = g3d_nn_lin_forward(&L->qkv, X, k, 0, Q, 0, NULL);
        for (int i = 0; rc == G3D_OK && i < k; i++) memcpy(kv + (size_t)(p0 + i) * 2 * D, Q + (size_t)i * 3 * D + D, sizeof(float) * 2 * D);
        g3d_nn_attn a = {.nq = k, .nk = n, .heads = heads, .hd = hd, .q = Q, .k = kv, .v = kv + D, .ldq = 3 * D,
                         .ldk = 2 * D, .ldv = 2 * D, .out = A, .scale = 1.0f / sqrtf((float)hd), .causal = 1};
        if (rc == G3D_OK) rc = g3d_nn_attend(&a);
        if (rc == G3D_OK) rc = g3d_nn_lin_forward(&L->out, A, k, 0, X, 0, &res);
        if (rc == G3D_OK) g3d_nn_layernorm(X, k, D, L->ln1w, L->ln1b, c->eps, X);
        if (rc == G3D_OK) rc = g3d_nn_lin_forward(&L->cq, X, k, 0, Q, 0, NULL);
        g3d_nn_attn ca = {.nq = k, .nk = x->tokens, .heads = heads, .hd = hd, .q = Q, .k = x->kv[l], .v = x->kv[l] + D,
                          .ldk = 2 * D, .ldv = 2 * D, .out = A, .scale = 1.0f / sqrtf((float)hd)};
        if (rc == G3D_OK) rc = g3d_nn_attend(&ca);
        if (rc == G3D_OK) rc = g3d_nn_lin_forward(&L->cout, A, k, 0, X, 0, &res);
        if (rc == G3D_OK) g3d_nn_layernorm(X, k, D, L->ln2w, L->ln2b, c->eps, X);
        g3d_nn_epi act = {.act = G3D_ACT_GELU};
        if (rc == G3D_OK) rc = g3d_nn_lin_forward(&L->inter, X, k, 0, H, 0, &act);
        if (rc == G3D_OK) rc = g3d_nn_lin_forward(&L->fout, H, k, 0, X, 0, &res);
        if (rc == G3D_OK) g3d_nn_layernorm(X, k, D, L->ln3w, L->ln3b, c->eps, X);
    }
    if (rc == G3D_OK) cache->len = n;
    g3d_nn_epi act = {.act = G3D_ACT_GELU};
    if (rc == G3D_OK) rc = g3d_nn_lin_forward(&m->head, X + (size_t)(k - 1) * D, 1, 0, t, 0, &act);
    if (rc == G3D_OK) {
        g3d_nn_layernorm(t, 1, D, m->hlnw, m->hlnb, c->eps, t);
        rc = g3d_nn_lin_forward(&m->lm, t, 1, 0, logits, 0, NULL);
    }
    free(X);
    free(Q);
    free(A);
    free(H);
    free(t);
    return rc;
}

g3d_status g3d_blip_next_logits(const g3d_blip *m, const float *embeds, const int32_t *ids, int n, float *logits)
{
    cross_kv x = {0};
    self_kv cache = {0};
    G3D_TRY(cross_make(m, embeds, &x));
    g3d_status rc = self_make(m, n > 0 ? n : 1, &cache);
    if (rc == G3D_OK) rc = next_logits(m, &x, &cache, ids, n, logits);
    free(cache.kv);
    cross_free(&x);
    return rc;
}

/* ---- tokens -------------------------------------------------------------------------------- */
void g3d_blip_gen_default(g3d_blip_gen *g)
{
    g->num_beams = 3;
    g->max_length = 20;
    g->min_length = 5;
    g->repetition_penalty = 1.0f;
    g->prompt = "a picture of ";
}

static int is_punct(unsigned char ch) { return ch < 128 && ispunct(ch); }

/* Appends the WordPiece ids of one word (greedy longest match, "##" continuations). */
static g3d_status wordpiece(const g3d_blip *m, const char *w, size_t len, int32_t **ids, int *n, int *cap)
{
    int32_t pieces[WORD_MAX];
    int np = 0, bad = len > WORD_MAX;
    char buf[WORD_MAX + 3];
    for (size_t s = 0; !bad && s < len;) {
        int found = -1;
        size_t e = len;
        for (; e > s; e--) {
            snprintf(buf, sizeof buf, "%s%.*s", s ? "##" : "", (int)(e - s), w + s);
            if ((found = find_token(m, buf)) >= 0) break;
        }
        if (found < 0) bad = 1;
        else pieces[np++] = found, s = e;
    }
    if (bad) pieces[0] = m->unk, np = 1;
    if (*n + np > *cap) {
        *cap = 2 * (*n + np) + 16;
        int32_t *g = realloc(*ids, sizeof(int32_t) * (size_t)*cap);
        if (!g) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        *ids = g;
    }
    memcpy(*ids + *n, pieces, sizeof(int32_t) * (size_t)np);
    *n += np;
    return G3D_OK;
}

g3d_status g3d_blip_prompt_ids(const g3d_blip *m, const char *prompt, int32_t **ids, int *n)
{
    int cap = 16;
    *n = 0;
    *ids = malloc(sizeof(int32_t) * (size_t)cap);
    if (!*ids) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    (*ids)[(*n)++] = m->cfg.bos;
    /* BERT's basic tokenizer on ASCII text: lower case, split at white space and punctuation */
    size_t len = strlen(prompt);
    char *low = malloc(len + 1);
    if (!low) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    for (size_t i = 0; i <= len; i++) low[i] = (char)tolower((unsigned char)prompt[i]);
    g3d_status rc = G3D_OK;
    for (size_t i = 0; i < len && rc == G3D_OK;) {
        unsigned char ch = (unsigned char)low[i];
        if (isspace(ch)) { i++; continue; }
        size_t e = i + 1;
        if (!is_punct(ch))
            while (e < len && !isspace((unsigned char)low[e]) && !is_punct((unsigned char)low[e])) e++;
        rc = wordpiece(m, low + i, e - i, ids, n, &cap);
        i = e;
    }
    free(low);
    if (rc != G3D_OK) {
        free(*ids);
        *ids = NULL;
        *n = 0;
    }
    return rc;
}

char *g3d_blip_decode(const g3d_blip *m, const int32_t *ids, int n)
{
    size_t len = 1;
    for (int i = 0; i < n; i++) len += ids[i] >= 0 && ids[i] < m->ntokens ? strlen(m->tokens[ids[i]]) + 1 : 0;
    char *s = malloc(len), *p = s;
    if (!s) return NULL;
    *p = 0;
    for (int i = 0; i < n; i++) {
        int32_t id = ids[i];
        if (id < 0 || id >= m->ntokens || id == m->cfg.pad || id == m->unk || id == m->cls_id || id == m->cfg.eos ||
            id == m->mask_id || id == m->cfg.bos || id == m->enc)
            continue;
        const char *t = m->tokens[id];
        if (!strncmp(t, "##", 2) && p > s) p += sprintf(p, "%s", t + 2);
        else p += sprintf(p, "%s%s", p > s ? " " : "", t);
    }
    /* transformers' clean_up_tokenization */
    static const char *const fix[][2] = {{" .", "."}, {" ?", "?"}, {" !", "!"}, {" ,", ","}, {" ' ", "'"}, {" n't", "n't"},
                                         {" 'm", "'m"}, {" 's", "'s"}, {" 've", "'ve"}, {" 're", "'re"}};
    for (size_t f = 0; f < sizeof fix / sizeof fix[0]; f++) {
        size_t a = strlen(fix[f][0]), b = strlen(fix[f][1]);
        char *r = s, *w = s;
        while (*r) {
            if (!strncmp(r, fix[f][0], a)) {
                memmove(w, fix[f][1], b);
                w += b;
                r += a;
            } else {
                *w++ = *r++;
            }
        }
        *w = 0;
    }
    return s;
}

/* ---- search -------------------------------------------------------------------------------- */
static void log_softmax(float *x, int n)
{
    float mx = -FLT_MAX;
    for (int i = 0; i < n; i++) mx = x[i] > mx ? x[i] : mx;
    double s = 0;
    for (int i = 0; i < n; i++) s += exp((double)x[i] - mx);
    float lse = mx + (float)log(s);
    for (int i = 0; i < n; i++) x[i] -= lse;
}

/* transformers' logits processors: MinLength (end token barred while the sequence is short) and
 * RepetitionPenalty (scores of tokens already in the sequence divided, or multiplied when
 * negative, by the penalty). */
static void process(const g3d_blip *m, const g3d_blip_gen *g, const int32_t *seq, int n, float *s)
{
    if (n < g->min_length) s[m->cfg.eos] = -INFINITY;
    if (g->repetition_penalty != 1.0f)
        for (int i = 0; i < n; i++) {
            float *v = &s[seq[i]];
            int seen = 0;
            for (int j = 0; j < i; j++) seen |= seq[j] == seq[i];
            if (!seen) *v = *v < 0 ? *v * g->repetition_penalty : *v / g->repetition_penalty;
        }
}

typedef struct hyp {
    double score;
    int32_t *ids;
    int n;
} hyp;

/* BeamHypotheses.add: keeps the num_beams best finished sequences scored sum_logprobs / length. */
static g3d_status hyp_add(hyp *h, int *nh, int beams, double *worst, const int32_t *ids, int n, double sum)
{
    double score = sum / n;
    if (*nh == beams && score <= *worst) return G3D_OK;
    int32_t *c = malloc(sizeof(int32_t) * (size_t)n);
    if (!c) return G3D_ERR(G3D_ERR_NOMEM, "out of memory in BLIP");
    memcpy(c, ids, sizeof(int32_t) * (size_t)n);
    h[(*nh)++] = (hyp){score, c, n};
    if (*nh > beams) {
        int wi = 0;
        for (int i = 1; i < *nh; i++) wi = h[i].score < h[wi].score ? i : wi;
        free(h[wi].ids);
        h[wi] = h[--*nh];
        *worst = h[0].score;
        for (int i = 1; i < *nh; i++) *worst = h[i].score < *worst ? h[i].score : *worst;
    } else {
        *worst = *nh == 1 || score < *worst ? score : *worst;
    }
    return G3D_OK;
}

static g3d_status greedy(const g3d_blip *m, const cross_kv *x, const g3d_blip_gen *g, int32_t *seq, int *n, float *s)
{
    self_kv cache;
    g3d_status rc = self_make(m, g->max_length, &cache);
    while (rc == G3D_OK && *n < g->max_length) {
        rc = next_logits(m, x, &cache, seq, *n, s);
        if (rc != G3D_OK) break;
        process(m, g, seq, *n, s);
        int best = 0;
        for (int v = 1; v < m->cfg.vocab; v++) best = s[v] > s[best] ? v : best;
        seq[(*n)++] = best;
        if (best == m->cfg.eos) break;
    }
    free(cache.kv);
    return rc;
}

static g3d_status beam(const g3d_blip *m, const cross_kv *x, const g3d_blip_gen *g, int32_t *seq, int *n, float *s)
{
    int B = g->num_beams, V = m->cfg.vocab, L = g->max_length, cur = *n, nh = 0, done = 0;
    int32_t *beams = malloc(sizeof(int32_t) * (size_t)B * L), *next = malloc(sizeof(int32_t) * (size_t)B * L);
    double *bs = malloc(sizeof(double) * B), *nbs = malloc(sizeof(double) * B), worst = 0;
    double *all = malloc(sizeof(double) * (size_t)B * V);
    hyp *h = calloc((size_t)B + 1, sizeof *h);
    int *top = malloc(sizeof(int) * 2 * (size_t)B);
    self_kv *cache = calloc(2 * (size_t)B, sizeof *cache), *ncache = cache ? cache + B : NULL;
    g3d_status rc = beams && next && bs && nbs && all && h && top && cache ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory in BLIP");
    for (int b = 0; rc == G3D_OK && b < 2 * B; b++) rc = self_make(m, L, &cache[b]);
    for (int b = 0; rc == G3D_OK && b < B; b++) {
        memcpy(beams + (size_t)b * L, seq, sizeof(int32_t) * (size_t)cur);
        bs[b] = b ? -1e9 : 0.0; /* only the first beam is live at the start */
    }
    while (rc == G3D_OK) {
        for (int b = 0; rc == G3D_OK && b < B; b++) {
            rc = next_logits(m, x, &cache[b], beams + (size_t)b * L, cur, s);
            log_softmax(s, V);
            process(m, g, beams + (size_t)b * L, cur, s);
            for (int v = 0; v < V; v++) all[(size_t)b * V + v] = (double)s[v] + bs[b];
        }
        if (rc != G3D_OK) break;
        /* the 2B best (beam, token) pairs, highest first; ties to the lower index, as topk */
        int K = 2 * B;
        for (int k = 0; k < K; k++) {
            int best = -1;
            for (size_t i = 0; i < (size_t)B * V; i++) {
                int used = 0;
                for (int j = 0; j < k; j++) used |= top[j] == (int)i;
                if (!used && (best < 0 || all[i] > all[best])) best = (int)i;
            }
            top[k] = best;
        }
        int nb = 0;
        for (int k = 0; k < K && nb < B && rc == G3D_OK; k++) {
            int b = top[k] / V, t = top[k] % V;
            if (t == m->cfg.eos) {
                if (k < B) rc = hyp_add(h, &nh, B, &worst, beams + (size_t)b * L, cur, all[top[k]]);
            } else {
                memcpy(next + (size_t)nb * L, beams + (size_t)b * L, sizeof(int32_t) * (size_t)cur);
                next[(size_t)nb * L + cur] = t;
                self_copy(&ncache[nb], &cache[b]);
                nbs[nb++] = all[top[k]];
            }
        }
        if (rc != G3D_OK) break;
        done = done || (nh >= B && worst >= all[top[0]] / cur);
        int32_t *tmp = beams;
        beams = next;
        next = tmp;
        self_kv *ctmp = cache;
        cache = ncache;
        ncache = ctmp;
        memcpy(bs, nbs, sizeof(double) * B);
        cur++;
        if (done || cur >= L) break;
    }
    for (int b = 0; rc == G3D_OK && !done && b < B; b++) rc = hyp_add(h, &nh, B, &worst, beams + (size_t)b * L, cur, bs[b]);
    if (rc == G3D_OK) {
        int best = 0;
        for (int i = 1; i < nh; i++) best = h[i].score > h[best].score ? i : best;
        memcpy(seq, h[best].ids, sizeof(int32_t) * (size_t)h[best].n);
        *n = h[best].n;
        if (*n < L) seq[(*n)++] = m->cfg.eos;
    }
    for (int i = 0; h && i < nh; i++) free(h[i].ids);
    /* cache and ncache are the two halves of one block, in either order */
    self_kv *block = cache && ncache && ncache < cache ? ncache : cache;
    for (int b = 0; block && b < 2 * B; b++) free(block[b].kv);
    free(block);
    free(h);
    free(beams);
    free(next);
    free(bs);
    free(nbs);
    free(all);
    free(top);
    return rc;
}

g3d_status g3d_blip_generate(const g3d_blip *m, const float *embeds, const g3d_blip_gen *g, int32_t **ids, int *n)
{
    *ids = NULL;
    *n = 0;
    if (g->num_beams < 1 || g->max_length < 1 || g->max_length > m->cfg.positions)
        return G3D_ERR(G3D_ERR_ARG, "generation: %d beams, max_length %d (1 to %d)", g->num_beams, g->max_length, m->cfg.positions);
    int32_t *prompt = NULL, *seq = malloc(sizeof(int32_t) * (size_t)g->max_length);
    float *s = malloc(sizeof(float) * (size_t)m->cfg.vocab);
    int np = 0;
    cross_kv x = {0};
    g3d_status rc = seq && s ? g3d_blip_prompt_ids(m, g->prompt ? g->prompt : "", &prompt, &np)
                             : G3D_ERR(G3D_ERR_NOMEM, "out of memory in BLIP");
    if (rc == G3D_OK && np >= g->max_length)
        rc = G3D_ERR(G3D_ERR_ARG, "the prompt has %d tokens: no room below max_length %d", np, g->max_length);
    if (rc == G3D_OK) rc = cross_make(m, embeds, &x);
    if (rc == G3D_OK) {
        memcpy(seq, prompt, sizeof(int32_t) * (size_t)np);
        *n = np;
        rc = g->num_beams == 1 ? greedy(m, &x, g, seq, n, s) : beam(m, &x, g, seq, n, s);
    }
    cross_free(&x);
    free(prompt);
    free(s);
    if (rc != G3D_OK) {
        free(seq);
        *n = 0;
        return rc;
    }
    *ids = seq;
    return G3D_OK;
}

g3d_status g3d_blip_caption(const g3d_blip *m, const g3d_image *img, const g3d_blip_gen *g, char **caption)
{
    *caption = NULL;
    int S = m->cfg.image_size, T = g3d_blip_image_tokens(m);
    float *px = malloc(sizeof(float) * 3 * (size_t)S * S), *emb = malloc(sizeof(float) * (size_t)T * m->cfg.vis_width);
    int32_t *ids = NULL;
    int n = 0;
    g3d_status rc = px && emb ? g3d_blip_preprocess(img, S, px) : G3D_ERR(G3D_ERR_NOMEM, "out of memory in BLIP");
    if (rc == G3D_OK) rc = g3d_blip_encode_pixels(m, px, emb);
    if (rc == G3D_OK) rc = g3d_blip_generate(m, emb, g, &ids, &n);
    char *text = rc == G3D_OK ? g3d_blip_decode(m, ids, n) : NULL;
    if (rc == G3D_OK && !text) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory in BLIP");
    if (rc == G3D_OK) {
        /* BLIP_Decoder.generate cuts len(prompt) characters off the decoded text */
        size_t cut = g->prompt ? strlen(g->prompt) : 0, len = strlen(text);
        *caption = strdup(cut < len ? text + cut : "");
        if (!*caption) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory in BLIP");
    }
    free(text);
    free(ids);
    free(px);
    free(emb);
    return rc;
}
