/* A whole CLIP model: OpenAI's ViT image tower and the text tower of clip_text.c, from the
 * Hugging Face CLIPModel names or OpenAI / OpenCLIP's, with the published preprocessing and
 * zero-shot classification. */
#include "gen3d/clip.h"

#include "clip_int.h"
#include "gen3d/nn.h"
#include "gen3d/resize.h"

#include <cjson/cJSON.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define HEAD_DIM 64 /* every published CLIP ViT: heads = width / 64 */

/* CLIP's normalisation (clip/clip.py _transform; Hugging Face's image_mean / image_std) */
static const float MEAN[3] = {0.48145466f, 0.4578275f, 0.40821073f};
static const float STD[3] = {0.26862954f, 0.26130258f, 0.27577711f};

struct g3d_clip {
    g3d_clip_config cfg;
    g3d_ckpt *ck;
    g3d_clip_text *text;
    g3d_nn_lin patch;            /* conv1 as a Linear over (channel, row, column) patches */
    g3d_nn_lin proj;             /* visual projection [embed, width] */
    float *cls, *pos;            /* [width], [grid^2 + 1, width] */
    float *lnpre_w, *lnpre_b, *lnpost_w, *lnpost_b;
    g3d_clip_block *blocks;      /* [layers] */
};

/* Tensor names of the two layouts; "%d" is the block. */
typedef struct vnames {
    const char *conv, *cls, *pos, *lnpre, *lnpost, *proj, *block;
} vnames;
static const vnames HF = {"vision_model.embeddings.patch_embedding.weight", "vision_model.embeddings.class_embedding",
                          "vision_model.embeddings.position_embedding.weight", "vision_model.pre_layrnorm.",
                          "vision_model.post_layernorm.", "visual_projection.weight", "vision_model.encoder.layers.%d."};
static const vnames OC = {"visual.conv1.weight", "visual.class_embedding", "visual.positional_embedding", "visual.ln_pre.",
                          "visual.ln_post.", "visual.proj", "visual.transformer.resblocks.%d."};

void g3d_clip_free(g3d_clip *m)
{
    if (!m) return;
    for (int i = 0; m->blocks && i < m->cfg.layers; i++) g3d_clip_block_free(&m->blocks[i]);
    free(m->blocks);
    g3d_nn_lin_free(&m->patch);
    g3d_nn_lin_free(&m->proj);
    free(m->cls); free(m->pos);
    free(m->lnpre_w); free(m->lnpre_b); free(m->lnpost_w); free(m->lnpost_b);
    g3d_clip_text_free(m->text);
    g3d_ckpt_free(m->ck);
    free(m);
}

/* The configuration from the tensors; act from the configuration files (cfg: config.json's
 * vision_config, or NULL; quick: open_clip_config.json's quick_gelu, -1 when not given). */
static g3d_status probe(const g3d_ckpt *ck, const cJSON *vcfg, int quick, g3d_clip_config *c)
{
    const char *path = g3d_ckpt_path(ck);
    memset(c, 0, sizeof *c);
    const vnames *n = NULL;
    if (g3d_ckpt_find(ck, HF.conv)) n = &HF, c->family = G3D_CLIP_HF;
    else if (g3d_ckpt_find(ck, OC.conv)) n = &OC, c->family = G3D_CLIP_OPENCLIP;
    else if (g3d_ckpt_find(ck, "visual_encoder.patch_embed.proj.weight") || g3d_ckpt_find(ck, "vision_model.embeddings.patch_embedding.bias"))
        return G3D_ERR(G3D_ERR_MODEL, "%s: a BLIP checkpoint, not a CLIP model (give it as the caption model)", path);
    else if (g3d_ckpt_find(ck, "visual.layer1.0.conv1.weight"))
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: CLIP with a ResNet image tower is not supported (ViT only)", path);
    else
        return G3D_ERR(G3D_ERR_MODEL, "%s: not a CLIP model (missing tensor %s or %s)", path, OC.conv, HF.conv);
    const g3d_tensor_info *cw = g3d_ckpt_find(ck, n->conv), *pe = g3d_ckpt_find(ck, n->pos);
    const g3d_tensor_info *pr = g3d_ckpt_find(ck, n->proj);
    if (cw->ndim != 4 || cw->shape[1] != 3 || cw->shape[2] != cw->shape[3] || cw->shape[2] < 1 || cw->shape[0] % HEAD_DIM)
        return G3D_ERR(G3D_ERR_MODEL, "%s: %s is not [width, 3, p, p] with a width in heads of %d", path, n->conv, HEAD_DIM);
    c->width = (int)cw->shape[0];
    c->patch = (int)cw->shape[2];
    if (!pe || pe->ndim != 2 || pe->shape[1] != c->width)
        return G3D_ERR(G3D_ERR_MODEL, "%s: %s missing or not [tokens, %d]", path, n->pos, c->width);
    int grid = (int)lround(sqrt((double)(pe->shape[0] - 1)));
    if ((int64_t)grid * grid + 1 != pe->shape[0] || grid < 1)
        return G3D_ERR(G3D_ERR_MODEL, "%s: %s has %lld rows: not a square grid plus the class token", path, n->pos,
                       (long long)pe->shape[0]);
    c->image_size = grid * c->patch;
    int hf = c->family == G3D_CLIP_HF;
    if (!pr || pr->ndim != 2 || pr->shape[hf ? 1 : 0] != c->width)
        return G3D_ERR(G3D_ERR_MODEL, "%s: %s missing or not a projection of width %d", path, n->proj, c->width);
    c->embed = (int)pr->shape[hf ? 0 : 1];
    while (g3d_clip_findf(ck, "", hf ? "vision_model.encoder.layers.%d.mlp.fc1.weight" : "visual.transformer.resblocks.%d.mlp.c_fc.weight",
                          c->layers))
        c->layers++;
    const g3d_tensor_info *fc = g3d_clip_findf(ck, "", hf ? "vision_model.encoder.layers.0.mlp.fc1.weight"
                                                          : "visual.transformer.resblocks.0.mlp.c_fc.weight");
    if (!c->layers || fc->ndim != 2)
        return G3D_ERR(G3D_ERR_MODEL, "%s: no image transformer blocks (missing tensor %s)", path,
                       hf ? "vision_model.encoder.layers.0.mlp.fc1.weight" : "visual.transformer.resblocks.0.mlp.c_fc.weight");
    c->mlp = (int)fc->shape[0];
    c->heads = c->width / HEAD_DIM;
    c->eps = 1e-5f;
    c->act = quick == 0 ? G3D_ACT_GELU : G3D_ACT_QUICK_GELU;
    if (vcfg) {
        const char *act = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(vcfg, "hidden_act"));
        const cJSON *nh = cJSON_GetObjectItemCaseSensitive(vcfg, "num_attention_heads");
        const cJSON *eps = cJSON_GetObjectItemCaseSensitive(vcfg, "layer_norm_eps");
        if (act && !strcmp(act, "gelu")) c->act = G3D_ACT_GELU;
        else if (act && strcmp(act, "quick_gelu"))
            return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: vision hidden_act \"%s\" (quick_gelu or gelu expected)", path, act);
        if (cJSON_IsNumber(nh) && nh->valueint >= 1 && c->width % nh->valueint == 0) c->heads = nh->valueint;
        if (cJSON_IsNumber(eps) && eps->valuedouble > 0) c->eps = (float)eps->valuedouble;
    }
    const g3d_tensor_info *ls = g3d_ckpt_find(ck, "logit_scale");
    if (!ls || ls->ndim > 1 || (ls->ndim == 1 && ls->shape[0] != 1))
        return G3D_ERR(G3D_ERR_MODEL, "%s: missing tensor logit_scale (a scalar)", path);
    float v;
    g3d_dtype_to_f32(ls->dtype, ls->data, &v, 1);
    c->logit_scale = expf(v);
    return G3D_OK;
}

/* A [rows, cols] weight as a packed Linear [out, in]: transposed when the file stores [in, out]. */
static g3d_status load_lin(const g3d_ckpt *ck, const char *name, int out, int in, int transposed, g3d_nn_lin *L)
{
    float *w = NULL, *t = NULL;
    g3d_status rc = g3d_clip_readf(ck, "", &w, transposed ? in : out, in == 0 ? 0 : (transposed ? out : in), "%s", name);
    if (rc == G3D_OK && transposed) {
        t = malloc(sizeof(float) * (size_t)out * in);
        if (!t) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory loading CLIP");
        for (int o = 0; t && o < out; o++)
            for (int i = 0; i < in; i++) t[(size_t)o * in + i] = w[(size_t)i * out + o];
    }
    if (rc == G3D_OK) rc = g3d_nn_lin_init(L, t ? t : w, G3D_DT_F32, NULL, out, in, G3D_DT_F32);
    free(w);
    free(t);
    return rc;
}

static g3d_status load_weights(g3d_clip *m)
{
    const g3d_clip_config *c = &m->cfg;
    const g3d_ckpt *ck = m->ck;
    const vnames *n = c->family == G3D_CLIP_HF ? &HF : &OC;
    int W = c->width, P = c->patch, grid = c->image_size / P;
    float *cw = NULL;
    int64_t cs[4] = {W, 3, P, P};
    g3d_status rc = g3d_ckpt_read_alloc(ck, n->conv, 4, cs, &cw);
    if (rc == G3D_OK) rc = g3d_nn_lin_init(&m->patch, cw, G3D_DT_F32, NULL, W, 3 * P * P, G3D_DT_F32);
    free(cw);
    if (rc == G3D_OK) rc = g3d_clip_readf(ck, "", &m->cls, W, 0, "%s", n->cls);
    if (rc == G3D_OK) rc = g3d_clip_readf(ck, "", &m->pos, grid * grid + 1, W, "%s", n->pos);
    if (rc == G3D_OK) rc = g3d_clip_readf(ck, "", &m->lnpre_w, W, 0, "%sweight", n->lnpre);
    if (rc == G3D_OK) rc = g3d_clip_readf(ck, "", &m->lnpre_b, W, 0, "%sbias", n->lnpre);
    if (rc == G3D_OK) rc = g3d_clip_readf(ck, "", &m->lnpost_w, W, 0, "%sweight", n->lnpost);
    if (rc == G3D_OK) rc = g3d_clip_readf(ck, "", &m->lnpost_b, W, 0, "%sbias", n->lnpost);
    if (rc == G3D_OK) rc = load_lin(ck, n->proj, c->embed, W, c->family != G3D_CLIP_HF, &m->proj);
    if (rc == G3D_OK && !(m->blocks = calloc((size_t)c->layers, sizeof *m->blocks)))
        rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory loading CLIP");
    for (int i = 0; rc == G3D_OK && i < c->layers; i++) {
        char base[128];
        snprintf(base, sizeof base, n->block, i);
        rc = g3d_clip_block_load(ck, c->family == G3D_CLIP_HF, base, W, c->mlp, &m->blocks[i]);
    }
    return rc;
}

static int is_file(const char *p)
{
    struct stat st;
    return stat(p, &st) == 0 && S_ISREG(st.st_mode);
}

/* The weights file and the configuration file of a folder or a file. */
static g3d_status find_files(const char *path, char **file, char **cfg, char **occfg)
{
    struct stat st;
    *file = *cfg = *occfg = NULL;
    if (stat(path, &st) != 0) return G3D_ERR(G3D_ERR_IO, "%s: no such file or folder", path);
    if (!S_ISDIR(st.st_mode)) {
        *file = strdup(path);
        return *file ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    static const char *const names[] = {"model.safetensors", "pytorch_model.bin", "open_clip_model.safetensors",
                                        "open_clip_pytorch_model.bin"};
    for (size_t i = 0; i < sizeof names / sizeof names[0] && !*file; i++) {
        char *f = g3d_path_join(path, names[i]);
        if (f && is_file(f)) *file = f;
        else free(f);
    }
    if (!*file)
        return G3D_ERR(G3D_ERR_IO, "%s: no CLIP weights here (model.safetensors, pytorch_model.bin or open_clip_pytorch_model.bin expected)",
                       path);
    *cfg = g3d_path_join(path, "config.json");
    *occfg = g3d_path_join(path, "open_clip_config.json");
    return G3D_OK;
}

static cJSON *read_json(const char *path, g3d_status *rc)
{
    unsigned char *d = NULL;
    size_t n;
    if (!path || !is_file(path)) return NULL;
    *rc = g3d_read_file(path, 1 << 20, &d, &n);
    cJSON *j = *rc == G3D_OK ? cJSON_ParseWithLength((const char *)d, n) : NULL;
    if (*rc == G3D_OK && !j) *rc = G3D_ERR(G3D_ERR_FORMAT, "%s: not valid JSON", path);
    free(d);
    return j;
}

g3d_status g3d_clip_load(const char *path, g3d_clip **out)
{
    *out = NULL;
    char *file, *cfgp, *occfgp;
    G3D_TRY(find_files(path, &file, &cfgp, &occfgp));
    g3d_status rc = G3D_OK;
    cJSON *cfg = read_json(cfgp, &rc), *occ = rc == G3D_OK ? read_json(occfgp, &rc) : NULL;
    g3d_clip *m = rc == G3D_OK ? calloc(1, sizeof *m) : NULL;
    if (rc == G3D_OK && !m) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory loading CLIP");
    if (rc == G3D_OK) rc = g3d_ckpt_open(file, &m->ck);
    int quick = -1;
    const cJSON *q = cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(occ, "model_cfg"), "quick_gelu");
    if (cJSON_IsBool(q)) quick = cJSON_IsTrue(q);
    if (rc == G3D_OK) rc = probe(m->ck, cJSON_GetObjectItemCaseSensitive(cfg, "vision_config"), quick, &m->cfg);
    if (rc == G3D_OK) rc = load_weights(m);
    /* the text tower reads the activation as a text config states it */
    char *tcfg = NULL;
    const cJSON *tc = cJSON_GetObjectItemCaseSensitive(cfg, "text_config");
    if (rc == G3D_OK) {
        tcfg = tc ? cJSON_PrintUnformatted(tc) : strdup(m->cfg.act == G3D_ACT_GELU ? "{\"hidden_act\": \"gelu\"}"
                                                                                    : "{\"hidden_act\": \"quick_gelu\"}");
        if (!tcfg) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory loading CLIP");
    }
    if (rc == G3D_OK) rc = g3d_clip_text_load_ckpt(m->ck, tcfg, &m->text);
    if (rc == G3D_OK && g3d_clip_text_embed_dim(m->text) != m->cfg.embed)
        rc = G3D_ERR(G3D_ERR_MODEL, "%s: text_projection gives %d values, the image projection %d", file,
                     g3d_clip_text_embed_dim(m->text), m->cfg.embed);
    free(tcfg);
    cJSON_Delete(cfg);
    cJSON_Delete(occ);
    free(file);
    free(cfgp);
    free(occfgp);
    if (rc != G3D_OK) {
        if (m && !m->blocks) m->cfg.layers = 0;
        g3d_clip_free(m);
        return rc;
    }
    *out = m;
    return G3D_OK;
}

g3d_status g3d_clip_probe(const g3d_ckpt *ck, g3d_clip_config *c) { return probe(ck, NULL, -1, c); }

const g3d_clip_config *g3d_clip_get_config(const g3d_clip *m) { return &m->cfg; }
const g3d_clip_text *g3d_clip_get_text(const g3d_clip *m) { return m->text; }

const char *g3d_clip_describe(const g3d_clip *m, char *buf, size_t n)
{
    const g3d_clip_config *c = &m->cfg;
    const g3d_clip_text_config *t = g3d_clip_text_get_config(m->text);
    snprintf(buf, n, "CLIP ViT-%s/%d (%s layout: image %d px, width %d, %d layers, %d heads, %s; text width %d, %d layers; "
             "embedding %d, logit scale %.4g)",
             c->width >= 1280 ? "H" : c->width >= 1024 ? "L" : c->width >= 768 ? "B" : "tiny", c->patch,
             c->family == G3D_CLIP_HF ? "Hugging Face" : "OpenAI / OpenCLIP", c->image_size, c->width, c->layers, c->heads,
             c->act == G3D_ACT_GELU ? "gelu" : "quick_gelu", t->width, t->layers, c->embed, c->logit_scale);
    return buf;
}

g3d_status g3d_clip_pixels(const g3d_image *img, int rw, int rh, int size, float *out)
{
    int w = img->w, h = img->h;
    unsigned char *u = malloc((size_t)w * h * 3), *r = malloc((size_t)rw * rh * 3);
    g3d_status rc = u && r ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory preprocessing an image");
    for (size_t i = 0; rc == G3D_OK && i < (size_t)w * h; i++)
        for (int ch = 0; ch < 3; ch++) {
            float v = img->data[i * img->c + (img->c == 3 ? ch : 0)] * 255.0f;
            u[i * 3 + ch] = (unsigned char)(v <= 0 ? 0 : v >= 255 ? 255 : lrintf(v));
        }
    if (rc == G3D_OK) rc = g3d_resize_u8_pil_bicubic(u, w, h, 3, r, rw, rh);
    if (rc == G3D_OK) {
        /* torchvision's CenterCrop: int(round((side - size) / 2.0)), Python rounding half to even */
        int top = (int)nearbyint((rh - size) / 2.0), left = (int)nearbyint((rw - size) / 2.0);
        for (int ch = 0; ch < 3; ch++)
            for (int y = 0; y < size; y++)
                for (int x = 0; x < size; x++)
                    out[((size_t)ch * size + y) * size + x] =
                        ((float)r[((size_t)(y + top) * rw + x + left) * 3 + ch] / 255.0f - MEAN[ch]) / STD[ch];
    }
    free(u);
    free(r);
    return rc;
}

g3d_status g3d_clip_preprocess(const g3d_image *img, int size, float *out)
{
    if (img->c != 3 && img->c != 1) return G3D_ERR(G3D_ERR_ARG, "CLIP needs an RGB or grey image (%d channels given)", img->c);
    int w = img->w, h = img->h, shortside = w < h ? w : h, longside = w < h ? h : w;
    if (shortside < G3D_CLIP_MIN_SIDE)
        return G3D_ERR(G3D_ERR_ARG, "the image is %dx%d: at least %d pixels on the short side are needed", w, h, G3D_CLIP_MIN_SIDE);
    int nl = (int)((double)size * longside / shortside);
    return g3d_clip_pixels(img, w <= h ? size : nl, w <= h ? nl : size, size, out);
}

g3d_status g3d_clip_encode_pixels(const g3d_clip *m, const float *pixels, float *embed, float *class_token)
{
    const g3d_clip_config *c = &m->cfg;
    int W = c->width, P = c->patch, S = c->image_size, grid = S / P, np = grid * grid, n = np + 1, K = 3 * P * P;
    float *rows = malloc(sizeof(float) * (size_t)np * K), *X = malloc(sizeof(float) * (size_t)n * W);
    float *cls = malloc(sizeof(float) * (size_t)W);
    g3d_clip_scratch w = {0};
    g3d_status rc = rows && X && cls ? g3d_clip_scratch_alloc(&w, n, W, c->mlp) : G3D_ERR(G3D_ERR_NOMEM, "out of memory in CLIP");
    if (rc == G3D_OK) {
        /* the stride-P convolution as a product: one row per patch in the weight's (c, y, x) order */
        for (int py = 0; py < grid; py++)
            for (int px = 0; px < grid; px++) {
                float *row = rows + (size_t)(py * grid + px) * K;
                for (int ch = 0; ch < 3; ch++)
                    for (int y = 0; y < P; y++)
                        memcpy(row + (ch * P + y) * P, pixels + ((size_t)ch * S + py * P + y) * S + px * P, sizeof(float) * P);
            }
        rc = g3d_nn_lin_forward(&m->patch, rows, np, 0, X + W, 0, NULL);
    }
    if (rc == G3D_OK) {
        memcpy(X, m->cls, sizeof(float) * W);
        g3d_nn_add(X, m->pos, (size_t)n * W);
        g3d_nn_layernorm(X, n, W, m->lnpre_w, m->lnpre_b, c->eps, X);
    }
    g3d_clip_block_shape sh = {.width = W, .heads = c->heads, .act = c->act, .eps = c->eps, .causal = 0};
    for (int l = 0; rc == G3D_OK && l < c->layers; l++) rc = g3d_clip_block_forward(&m->blocks[l], &sh, X, n, &w);
    if (rc == G3D_OK) {
        g3d_nn_layernorm(X, 1, W, m->lnpost_w, m->lnpost_b, c->eps, cls);
        if (class_token) memcpy(class_token, cls, sizeof(float) * W);
        rc = g3d_nn_lin_forward(&m->proj, cls, 1, 0, embed, 0, NULL);
    }
    free(rows);
    free(X);
    free(cls);
    g3d_clip_scratch_free(&w);
    return rc;
}

g3d_status g3d_clip_encode_image(const g3d_clip *m, const g3d_image *img, float *embed, float *class_token)
{
    int S = m->cfg.image_size;
    float *px = malloc(sizeof(float) * 3 * (size_t)S * S);
    g3d_status rc = px ? g3d_clip_preprocess(img, S, px) : G3D_ERR(G3D_ERR_NOMEM, "out of memory in CLIP");
    if (rc == G3D_OK) rc = g3d_clip_encode_pixels(m, px, embed, class_token);
    free(px);
    return rc;
}

g3d_status g3d_clip_encode_text(const g3d_clip *m, const g3d_clip_tokenizer *tok, const char *text, float *embed)
{
    int context = g3d_clip_text_get_config(m->text)->context;
    int32_t *ids = malloc(sizeof(int32_t) * (size_t)context);
    g3d_clip_tokens info;
    /* clip.tokenize pads with 0; the end token is the highest id either way */
    g3d_status rc = ids ? g3d_clip_tokenize(tok, text, context, 0, ids, &info) : G3D_ERR(G3D_ERR_NOMEM, "out of memory in CLIP");
    if (rc == G3D_OK) rc = g3d_clip_text_pooled(m->text, ids, info.length, embed);
    free(ids);
    return rc;
}

static void normalise(float *v, int n)
{
    double s = 0;
    for (int i = 0; i < n; i++) s += (double)v[i] * v[i];
    float inv = s > 0 ? (float)(1.0 / sqrt(s)) : 0.0f;
    for (int i = 0; i < n; i++) v[i] *= inv;
}

g3d_status g3d_clip_zero_shot(const g3d_clip *m, const g3d_clip_tokenizer *tok, const float *image_embed,
                              const char *const *labels, int n, const char *tmpl, float *logits, float *probs)
{
    int E = m->cfg.embed;
    if (n < 1) return G3D_ERR(G3D_ERR_ARG, "zero-shot classification needs at least one label");
    const char *slot = strstr(tmpl, "{}");
    if (!slot) return G3D_ERR(G3D_ERR_ARG, "prompt template \"%s\" has no {} for the label", tmpl);
    float *img = malloc(sizeof(float) * E), *txt = malloc(sizeof(float) * E), *lg = malloc(sizeof(float) * n);
    g3d_status rc = img && txt && lg ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory in CLIP");
    if (rc == G3D_OK) {
        memcpy(img, image_embed, sizeof(float) * E);
        normalise(img, E);
    }
    for (int i = 0; rc == G3D_OK && i < n; i++) {
        size_t len = strlen(tmpl) + strlen(labels[i]);
        char *text = malloc(len);
        if (!text) {
            rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory in CLIP");
            break;
        }
        snprintf(text, len, "%.*s%s%s", (int)(slot - tmpl), tmpl, labels[i], slot + 2);
        rc = g3d_clip_encode_text(m, tok, text, txt);
        free(text);
        if (rc != G3D_OK) break;
        normalise(txt, E);
        double dot = 0;
        for (int k = 0; k < E; k++) dot += (double)img[k] * txt[k];
        lg[i] = m->cfg.logit_scale * (float)dot;
    }
    if (rc == G3D_OK) {
        if (logits) memcpy(logits, lg, sizeof(float) * n);
        if (probs) {
            memcpy(probs, lg, sizeof(float) * n);
            g3d_nn_softmax(probs, 1, n);
        }
    }
    free(img);
    free(txt);
    free(lg);
    return rc;
}
