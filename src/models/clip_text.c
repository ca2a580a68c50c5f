/* CLIP's text transformer (pre-norm blocks, causal self-attention, learned positions, final
 * LayerNorm) from the Hugging Face CLIPTextModel names or OpenAI / OpenCLIP's, as Stable
 * Diffusion 1.x and 2.x publish them. Sizes come from the tensors. */
#include "gen3d/clip_text.h"

#include "clip_int.h"
#include "gen3d/nn.h"

#include <cjson/cJSON.h>

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define HEAD_DIM 64   /* every published CLIP text tower: heads = width / 64 */

struct g3d_clip_text {
    g3d_clip_text_config cfg;
    g3d_ckpt *own;                    /* the checkpoint when the encoder opened it */
    const g3d_tensor_info *tok;       /* token embedding [vocab, width], read row by row */
    float *pos, *lnfw, *lnfb;         /* [context, width], final LayerNorm */
    g3d_clip_block *blocks;           /* [run_layers] */
    g3d_nn_lin proj;                  /* text_projection as a Linear [embed, width]; in = 0 when absent */
};

/* <prefix> followed by the formatted name, into full[n]. */
static void vname(char *full, size_t n, const char *prefix, const char *fmt, va_list ap)
{
    char name[256];
    vsnprintf(name, sizeof name, fmt, ap);
    snprintf(full, n, "%s%s", prefix, name);
}

/* The tensor <prefix><name>, or NULL. */
const g3d_tensor_info *g3d_clip_findf(const g3d_ckpt *ck, const char *prefix, const char *fmt, ...)
{
    char full[384];
    va_list ap;
    va_start(ap, fmt);
    vname(full, sizeof full, prefix, fmt, ap);
    va_end(ap);
    return g3d_ckpt_find(ck, full);
}

/* Reads <prefix><name> with the given shape ([d0], or [d0, d1] when d1 > 0) as float32 (malloc'd). */
g3d_status g3d_clip_readf(const g3d_ckpt *ck, const char *prefix, float **dst, int64_t d0, int64_t d1, const char *fmt, ...)
{
    char full[384];
    va_list ap;
    va_start(ap, fmt);
    vname(full, sizeof full, prefix, fmt, ap);
    va_end(ap);
    int64_t shape[2] = {d0, d1};
    return g3d_ckpt_read_alloc(ck, full, d1 ? 2 : 1, shape, dst);
}

g3d_status g3d_clip_lin(const g3d_ckpt *ck, const char *prefix, g3d_nn_lin *L, int out, int in, int parts, const char *const *w,
                      const char *const *b)
{
    float *W = NULL, *B = NULL;
    g3d_status rc = G3D_OK;
    g3d_dtype store = G3D_DT_F32;
    size_t n = (size_t)out / (size_t)parts * (size_t)in;
    W = malloc(sizeof(float) * (size_t)out * (size_t)in);
    B = malloc(sizeof(float) * (size_t)out);
    if (!W || !B) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the text encoder");
    for (int p = 0; p < parts && rc == G3D_OK; p++) {
        char full[384];
        int64_t sw[2] = {out / parts, in}, sb[1] = {out / parts};
        snprintf(full, sizeof full, "%s%s", prefix, w[p]);
        const g3d_tensor_info *t = g3d_ckpt_find(ck, full);
        if (t && (t->dtype == G3D_DT_F16 || t->dtype == G3D_DT_BF16)) store = t->dtype;
        rc = g3d_ckpt_read(ck, full, 2, sw, W + p * n);
        snprintf(full, sizeof full, "%s%s", prefix, b[p]);
        if (rc == G3D_OK) rc = g3d_ckpt_read(ck, full, 1, sb, B + p * (out / parts));
    }
    /* 16-bit weights stay 16-bit in the packed panels (the same values: exact) */
    if (rc == G3D_OK) rc = g3d_nn_lin_init(L, W, G3D_DT_F32, B, out, in, store);
    free(W);
    free(B);
    return rc;
}

void g3d_clip_text_free(g3d_clip_text *m)
{
    if (!m) return;
    for (int i = 0; m->blocks && i < m->cfg.run_layers; i++) g3d_clip_block_free(&m->blocks[i]);
    free(m->blocks);
    g3d_nn_lin_free(&m->proj);
    free(m->pos);
    free(m->lnfw);
    free(m->lnfb);
    g3d_ckpt_free(m->own);
    free(m);
}

/* Where the text tower sits in a checkpoint: the family and the key prefix, or -1. */
static int locate(const g3d_ckpt *ck, const char **prefix)
{
    static const char *const hf[] = {"cond_stage_model.transformer.", "", "text_encoder."};
    static const char *const oc[] = {"cond_stage_model.model.", ""};
    for (size_t i = 0; i < sizeof hf / sizeof hf[0]; i++)
        if (g3d_clip_findf(ck, hf[i], "text_model.embeddings.token_embedding.weight")) {
            *prefix = hf[i];
            return G3D_CLIP_HF;
        }
    for (size_t i = 0; i < sizeof oc / sizeof oc[0]; i++)
        if (g3d_clip_findf(ck, oc[i], "token_embedding.weight") && g3d_clip_findf(ck, oc[i], "positional_embedding")) {
            *prefix = oc[i];
            return G3D_CLIP_OPENCLIP;
        }
    return -1;
}

g3d_status g3d_clip_text_probe(const g3d_ckpt *ck, const char *cfg_json, g3d_clip_text_config *c)
{
    const char *p = NULL;
    int fam = locate(ck, &p);
    memset(c, 0, sizeof *c);
    if (fam < 0) {
        /* say what is missing under the prefix a Stable Diffusion file would use */
        const char *want = g3d_ckpt_find(ck, "model.diffusion_model.input_blocks.0.0.weight") &&
                                   g3d_clip_findf(ck, "cond_stage_model.", "model.ln_final.weight") == NULL
                               ? "cond_stage_model.transformer.text_model.embeddings.token_embedding.weight"
                               : "text_model.embeddings.token_embedding.weight";
        return G3D_ERR(G3D_ERR_MODEL, "%s: no CLIP text encoder (missing tensor %s, or token_embedding.weight of "
                       "an OpenCLIP layout)", g3d_ckpt_path(ck), want);
    }
    c->family = (g3d_clip_family)fam;
    c->prefix = p;
    c->eps = 1e-5f;
    int hf = fam == G3D_CLIP_HF;
    const g3d_tensor_info *te = g3d_clip_findf(ck, p, hf ? "text_model.embeddings.token_embedding.weight" : "token_embedding.weight");
    const g3d_tensor_info *pe = g3d_clip_findf(ck, p, hf ? "text_model.embeddings.position_embedding.weight" : "positional_embedding");
    if (!te || te->ndim != 2 || !pe || pe->ndim != 2 || pe->shape[1] != te->shape[1])
        return G3D_ERR(G3D_ERR_MODEL, "%s: %sposition embedding missing or not [context, %lld]", g3d_ckpt_path(ck), p,
                       te && te->ndim == 2 ? (long long)te->shape[1] : 0LL);
    c->vocab = (int)te->shape[0];
    c->width = (int)te->shape[1];
    c->context = (int)pe->shape[0];
    while (g3d_clip_findf(ck, p, hf ? "text_model.encoder.layers.%d.self_attn.q_proj.weight" : "transformer.resblocks.%d.attn.in_proj_weight",
                 c->layers))
        c->layers++;
    const g3d_tensor_info *fc = g3d_clip_findf(ck, p, hf ? "text_model.encoder.layers.0.mlp.fc1.weight" : "transformer.resblocks.0.mlp.c_fc.weight");
    if (!c->layers || !fc || fc->ndim != 2)
        return G3D_ERR(G3D_ERR_MODEL, "%s: missing tensor %s%s", g3d_ckpt_path(ck), p,
                       !c->layers ? (hf ? "text_model.encoder.layers.0.self_attn.q_proj.weight" : "transformer.resblocks.0.attn.in_proj_weight")
                                  : (hf ? "text_model.encoder.layers.0.mlp.fc1.weight" : "transformer.resblocks.0.mlp.c_fc.weight"));
    c->mlp = (int)fc->shape[0];
    c->heads = c->width / HEAD_DIM;
    c->run_layers = c->layers;
    /* SD 1.x is OpenAI's CLIP (quick_gelu, last layer, end-token padding); SD 2.x's
     * FrozenOpenCLIPEmbedder (layer "penultimate") stops one block early, pads with 0, and its
     * ViT-H uses exact GELU */
    c->act = hf ? G3D_ACT_QUICK_GELU : G3D_ACT_GELU;
    c->pad_id = hf ? -1 : 0;
    if (!strcmp(p, "cond_stage_model.model.") && c->layers > 1) c->run_layers = c->layers - 1;
    cJSON *j = cfg_json ? cJSON_Parse(cfg_json) : NULL;
    if (j) {
        const char *act = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(j, "hidden_act"));
        const cJSON *nl = cJSON_GetObjectItemCaseSensitive(j, "num_hidden_layers");
        const cJSON *nh = cJSON_GetObjectItemCaseSensitive(j, "num_attention_heads");
        const cJSON *eps = cJSON_GetObjectItemCaseSensitive(j, "layer_norm_eps");
        if (act && !strcmp(act, "gelu")) c->act = G3D_ACT_GELU;
        else if (act && !strcmp(act, "quick_gelu")) c->act = G3D_ACT_QUICK_GELU;
        else if (act) {
            g3d_status rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: hidden_act \"%s\" (quick_gelu or gelu expected)", g3d_ckpt_path(ck), act);
            cJSON_Delete(j);
            return rc;
        }
        if (cJSON_IsNumber(nl) && nl->valueint >= 1 && nl->valueint < c->layers) c->run_layers = nl->valueint;
        if (cJSON_IsNumber(nh) && nh->valueint >= 1) c->heads = nh->valueint;
        if (cJSON_IsNumber(eps) && eps->valuedouble > 0) c->eps = (float)eps->valuedouble;
        cJSON_Delete(j);
    }
    if (c->heads < 1 || c->width % c->heads)
        return G3D_ERR(G3D_ERR_MODEL, "%s: width %d does not split into heads of %d", g3d_ckpt_path(ck), c->width, HEAD_DIM);
    return G3D_OK;
}

g3d_status g3d_clip_block_load(const g3d_ckpt *ck, int hf, const char *base, int D, int M, g3d_clip_block *b)
{
    char w[3][384], bs[3][384], ln[2][384];
    const char *wp[3] = {w[0], w[1], w[2]}, *bp[3] = {bs[0], bs[1], bs[2]};
    if (hf) {
        static const char *const qkv[] = {"q", "k", "v"};
        for (int k = 0; k < 3; k++) {
            snprintf(w[k], sizeof w[k], "%sself_attn.%s_proj.weight", base, qkv[k]);
            snprintf(bs[k], sizeof bs[k], "%sself_attn.%s_proj.bias", base, qkv[k]);
        }
        snprintf(ln[0], sizeof ln[0], "%slayer_norm1.", base);
        snprintf(ln[1], sizeof ln[1], "%slayer_norm2.", base);
    } else {
        snprintf(w[0], sizeof w[0], "%sattn.in_proj_weight", base);
        snprintf(bs[0], sizeof bs[0], "%sattn.in_proj_bias", base);
        snprintf(ln[0], sizeof ln[0], "%sln_1.", base);
        snprintf(ln[1], sizeof ln[1], "%sln_2.", base);
    }
    G3D_TRY(g3d_clip_lin(ck, "", &b->qkv, 3 * D, D, hf ? 3 : 1, wp, bp));
    G3D_TRY(g3d_clip_readf(ck, "", &b->ln1w, D, 0, "%sweight", ln[0]));
    G3D_TRY(g3d_clip_readf(ck, "", &b->ln1b, D, 0, "%sbias", ln[0]));
    G3D_TRY(g3d_clip_readf(ck, "", &b->ln2w, D, 0, "%sweight", ln[1]));
    G3D_TRY(g3d_clip_readf(ck, "", &b->ln2b, D, 0, "%sbias", ln[1]));
    static const char *const hfn[3] = {"self_attn.out_proj", "mlp.fc1", "mlp.fc2"};
    static const char *const ocn[3] = {"attn.out_proj", "mlp.c_fc", "mlp.c_proj"};
    g3d_nn_lin *L[3] = {&b->out, &b->fc1, &b->fc2};
    int dims[3][2] = {{D, D}, {M, D}, {D, M}};
    for (int k = 0; k < 3; k++) {
        snprintf(w[0], sizeof w[0], "%s%s.weight", base, hf ? hfn[k] : ocn[k]);
        snprintf(bs[0], sizeof bs[0], "%s%s.bias", base, hf ? hfn[k] : ocn[k]);
        G3D_TRY(g3d_clip_lin(ck, "", L[k], dims[k][0], dims[k][1], 1, wp, bp));
    }
    return G3D_OK;
}

void g3d_clip_block_free(g3d_clip_block *b)
{
    free(b->ln1w); free(b->ln1b); free(b->ln2w); free(b->ln2b);
    g3d_nn_lin_free(&b->qkv);
    g3d_nn_lin_free(&b->out);
    g3d_nn_lin_free(&b->fc1);
    g3d_nn_lin_free(&b->fc2);
}

g3d_status g3d_clip_block_forward(const g3d_clip_block *b, const g3d_clip_block_shape *s, float *X, int n,
                                  g3d_clip_scratch *w)
{
    int D = s->width, hd = D / s->heads;
    g3d_nn_layernorm(X, n, D, b->ln1w, b->ln1b, s->eps, w->T);
    g3d_status rc = g3d_nn_lin_forward(&b->qkv, w->T, n, 0, w->QKV, 0, NULL);
    g3d_nn_attn a = {.nq = n, .nk = n, .heads = s->heads, .hd = hd, .q = w->QKV, .k = w->QKV + D, .v = w->QKV + 2 * D,
                     .ldq = 3 * D, .ldk = 3 * D, .ldv = 3 * D, .out = w->A, .scale = 1.0f / sqrtf((float)hd),
                     .causal = s->causal};
    if (rc == G3D_OK) rc = g3d_nn_attend(&a);
    g3d_nn_epi res = {.res = X};
    if (rc == G3D_OK) rc = g3d_nn_lin_forward(&b->out, w->A, n, 0, X, 0, &res);
    g3d_nn_layernorm(X, n, D, b->ln2w, b->ln2b, s->eps, w->T);
    g3d_nn_epi act = {.act = s->act};
    if (rc == G3D_OK) rc = g3d_nn_lin_forward(&b->fc1, w->T, n, 0, w->H, 0, &act);
    if (rc == G3D_OK) rc = g3d_nn_lin_forward(&b->fc2, w->H, n, 0, X, 0, &res);
    return rc;
}

g3d_status g3d_clip_scratch_alloc(g3d_clip_scratch *w, int n, int D, int M)
{
    size_t nd = (size_t)n * D;
    w->T = malloc(sizeof(float) * nd);
    w->A = malloc(sizeof(float) * nd);
    w->QKV = malloc(sizeof(float) * 3 * nd);
    w->H = malloc(sizeof(float) * (size_t)n * M);
    if (w->T && w->A && w->QKV && w->H) return G3D_OK;
    g3d_clip_scratch_free(w);
    return G3D_ERR(G3D_ERR_NOMEM, "out of memory in a CLIP transformer");
}

void g3d_clip_scratch_free(g3d_clip_scratch *w)
{
    free(w->T);
    free(w->A);
    free(w->QKV);
    free(w->H);
    memset(w, 0, sizeof *w);
}

/* CLIPModel's text_projection: Hugging Face's Linear weight [embed, width] or OpenAI's matrix
 * [width, embed] (x @ P), beside the tower; absent in Stable Diffusion's text encoders. */
static g3d_status load_projection(const g3d_ckpt *ck, const g3d_clip_text_config *c, g3d_nn_lin *L)
{
    int hf = c->family == G3D_CLIP_HF;
    const g3d_tensor_info *t = g3d_clip_findf(ck, c->prefix, hf ? "text_projection.weight" : "text_projection");
    if (!t) return G3D_OK;
    if (t->ndim != 2 || t->shape[hf ? 1 : 0] != c->width)
        return G3D_ERR(G3D_ERR_MODEL, "%s: %stext_projection is not a [%d, embed] matrix", g3d_ckpt_path(ck), c->prefix, c->width);
    int E = (int)t->shape[hf ? 0 : 1], W = c->width;
    float *P = NULL, *Q = malloc(sizeof(float) * (size_t)E * W);
    int64_t shape[2] = {t->shape[0], t->shape[1]};
    g3d_status rc = Q ? g3d_clip_readf(ck, c->prefix, &P, shape[0], shape[1], hf ? "text_projection.weight" : "text_projection")
                      : G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the text encoder");
    for (int e = 0; rc == G3D_OK && e < E; e++)
        for (int k = 0; k < W; k++) Q[(size_t)e * W + k] = hf ? P[(size_t)e * W + k] : P[(size_t)k * E + e];
    if (rc == G3D_OK) rc = g3d_nn_lin_init(L, Q, G3D_DT_F32, NULL, E, W, G3D_DT_F32);
    free(P);
    free(Q);
    return rc;
}

g3d_status g3d_clip_text_load_ckpt(const g3d_ckpt *ck, const char *cfg_json, g3d_clip_text **out)
{
    *out = NULL;
    g3d_clip_text *m = calloc(1, sizeof *m);
    if (!m) return G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the text encoder");
    g3d_status rc = g3d_clip_text_probe(ck, cfg_json, &m->cfg);
    const g3d_clip_text_config *c = &m->cfg;
    const char *p = c->prefix;
    int hf = c->family == G3D_CLIP_HF, D = c->width;
    if (rc == G3D_OK) {
        m->tok = g3d_clip_findf(ck, p, hf ? "text_model.embeddings.token_embedding.weight" : "token_embedding.weight");
        rc = g3d_clip_readf(ck, p, &m->pos, c->context, D, hf ? "text_model.embeddings.position_embedding.weight" : "positional_embedding");
    }
    if (rc == G3D_OK) rc = g3d_clip_readf(ck, p, &m->lnfw, D, 0, hf ? "text_model.final_layer_norm.weight" : "ln_final.weight");
    if (rc == G3D_OK) rc = g3d_clip_readf(ck, p, &m->lnfb, D, 0, hf ? "text_model.final_layer_norm.bias" : "ln_final.bias");
    if (rc == G3D_OK && !(m->blocks = calloc((size_t)c->run_layers, sizeof *m->blocks)))
        rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the text encoder");
    for (int i = 0; rc == G3D_OK && i < c->run_layers; i++) {
        char base[256];
        snprintf(base, sizeof base, hf ? "%stext_model.encoder.layers.%d." : "%stransformer.resblocks.%d.", p, i);
        rc = g3d_clip_block_load(ck, hf, base, D, c->mlp, &m->blocks[i]);
    }
    if (rc == G3D_OK) rc = load_projection(ck, c, &m->proj);
    if (rc != G3D_OK) {
        if (!m->blocks) m->cfg.run_layers = 0;
        g3d_clip_text_free(m);
        return rc;
    }
    *out = m;
    return G3D_OK;
}

static int is_file(const char *p)
{
    struct stat st;
    return stat(p, &st) == 0 && S_ISREG(st.st_mode);
}

g3d_status g3d_clip_text_load(const char *path, g3d_clip_text **out)
{
    *out = NULL;
    struct stat st;
    if (stat(path, &st) != 0) return G3D_ERR(G3D_ERR_IO, "%s: no such file or folder", path);
    char *file = NULL, *cfg = NULL;
    if (S_ISDIR(st.st_mode)) {
        /* a diffusers folder (text_encoder/) or the text_encoder folder itself */
        static const char *const names[] = {"text_encoder/model.safetensors", "text_encoder/pytorch_model.bin",
                                            "model.safetensors", "pytorch_model.bin"};
        for (size_t i = 0; i < sizeof names / sizeof names[0] && !file; i++) {
            char *f = g3d_path_join(path, names[i]);
            if (f && is_file(f)) {
                file = f;
                cfg = g3d_path_join(path, i < 2 ? "text_encoder/config.json" : "config.json");
            } else {
                free(f);
            }
        }
        if (!file)
            return G3D_ERR(G3D_ERR_IO, "%s: no text encoder here (text_encoder/model.safetensors or pytorch_model.bin expected)", path);
    } else {
        file = strdup(path);
    }
    unsigned char *cj = NULL;
    size_t cn;
    g3d_ckpt *ck = NULL;
    g3d_status rc = file ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK && cfg && is_file(cfg)) rc = g3d_read_file(cfg, 1 << 20, &cj, &cn);
    if (rc == G3D_OK) rc = g3d_ckpt_open(file, &ck);
    if (rc == G3D_OK) rc = g3d_clip_text_load_ckpt(ck, (const char *)cj, out);
    if (rc == G3D_OK) (*out)->own = ck;
    else g3d_ckpt_free(ck);
    free(cj);
    free(cfg);
    free(file);
    return rc;
}

const g3d_clip_text_config *g3d_clip_text_get_config(const g3d_clip_text *m) { return &m->cfg; }
int g3d_clip_text_width(const g3d_clip_text *m) { return m->cfg.width; }

int32_t g3d_clip_text_pad_id(const g3d_clip_text *m, const g3d_clip_tokenizer *t)
{
    if (m->cfg.pad_id >= 0) return m->cfg.pad_id;
    int32_t pad = t ? g3d_clip_tokenizer_pad(t) : -1;
    return pad >= 0 ? pad : t ? g3d_clip_tokenizer_eot(t) : 0;
}

const char *g3d_clip_text_describe(const g3d_clip_text_config *c, char *buf, size_t n)
{
    int sd2 = !strcmp(c->prefix, "cond_stage_model.model.");
    int sd1 = !strcmp(c->prefix, "cond_stage_model.transformer.");
    snprintf(buf, n, "CLIP text encoder (%s%s: %d layers, width %d, %d heads, MLP %d, context %d, vocabulary %d, %s, %s)",
             sd2 ? "SD 2.x, " : sd1 ? "SD 1.x, " : "", c->family == G3D_CLIP_HF ? "Hugging Face layout" : "OpenCLIP layout",
             c->layers, c->width, c->heads, c->mlp, c->context, c->vocab, c->act == G3D_ACT_GELU ? "gelu" : "quick_gelu",
             c->run_layers == c->layers ? "last layer" : c->run_layers == c->layers - 1 ? "penultimate layer" : "earlier layer");
    return buf;
}

void g3d_clip_text_trace_free(g3d_clip_text_trace *tr)
{
    if (!tr) return;
    free(tr->embed);
    for (int i = 0; tr->hidden && i < tr->nhidden; i++) free(tr->hidden[i]);
    free(tr->hidden);
    tr->embed = NULL;
    tr->hidden = NULL;
    tr->nhidden = 0;
}

static float *dup_rows(const float *x, size_t n)
{
    float *y = malloc(sizeof(float) * n);
    if (y) memcpy(y, x, sizeof(float) * n);
    return y;
}

g3d_status g3d_clip_text_forward(const g3d_clip_text *m, const int32_t *ids, int n, float *out, g3d_clip_text_trace *tr)
{
    const g3d_clip_text_config *c = &m->cfg;
    int D = c->width;
    if (n < 1 || n > c->context) return G3D_ERR(G3D_ERR_ARG, "%d tokens: 1 to %d expected", n, c->context);
    for (int i = 0; i < n; i++)
        if (ids[i] < 0 || ids[i] >= c->vocab)
            return G3D_ERR(G3D_ERR_ARG, "token id %d at %d outside the vocabulary (%d)", ids[i], i, c->vocab);
    size_t nd = (size_t)n * D;
    g3d_clip_scratch w = {0};
    float *X = malloc(sizeof(float) * nd);
    g3d_status rc = X ? g3d_clip_scratch_alloc(&w, n, D, c->mlp) : G3D_ERR(G3D_ERR_NOMEM, "out of memory in the text encoder");
    if (tr && tr->want && rc == G3D_OK) {
        g3d_clip_text_trace_free(tr);
        tr->hidden = calloc((size_t)c->run_layers, sizeof *tr->hidden);
        if (!tr->hidden) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory in the text encoder");
        else tr->nhidden = c->run_layers;
    }
    if (rc == G3D_OK) {
        size_t es = g3d_dtype_size(m->tok->dtype);
        for (int i = 0; i < n; i++) {
            g3d_dtype_to_f32(m->tok->dtype, (const char *)m->tok->data + (size_t)ids[i] * D * es, X + (size_t)i * D, D);
            for (int k = 0; k < D; k++) X[(size_t)i * D + k] += m->pos[(size_t)i * D + k];
        }
        if (tr && tr->want) tr->embed = dup_rows(X, nd);
    }
    g3d_clip_block_shape sh = {.width = D, .heads = c->heads, .act = c->act, .eps = c->eps, .causal = 1};
    for (int l = 0; rc == G3D_OK && l < c->run_layers; l++) {
        rc = g3d_clip_block_forward(&m->blocks[l], &sh, X, n, &w);
        if (rc == G3D_OK && tr && tr->want) tr->hidden[l] = dup_rows(X, nd);
    }
    if (rc == G3D_OK) g3d_nn_layernorm(X, n, D, m->lnfw, m->lnfb, c->eps, out);
    free(X);
    g3d_clip_scratch_free(&w);
    return rc;
}

int g3d_clip_text_embed_dim(const g3d_clip_text *m) { return m->proj.in ? m->proj.out : 0; }

g3d_status g3d_clip_text_pooled(const g3d_clip_text *m, const int32_t *ids, int n, float *out)
{
    if (!m->proj.in) return G3D_ERR(G3D_ERR_MODEL, "the text encoder has no text_projection (not a CLIPModel checkpoint)");
    int eot = 0;
    for (int i = 1; i < n; i++)
        if (ids[i] > ids[eot]) eot = i;
    /* the mask is causal: the rows after the end token change nothing before it */
    float *h = malloc(sizeof(float) * (size_t)(eot + 1) * m->cfg.width);
    g3d_status rc = h ? g3d_clip_text_forward(m, ids, eot + 1, h, NULL) : G3D_ERR(G3D_ERR_NOMEM, "out of memory in the text encoder");
    if (rc == G3D_OK) rc = g3d_nn_lin_forward(&m->proj, h + (size_t)eot * m->cfg.width, 1, 0, out, 0, NULL);
    free(h);
    return rc;
}
