/* The latent-diffusion UNet of Stable Diffusion 1.x / 2.x (ldm's UNetModel with spatial
 * transformers), from the original key names. The structure is read from the tensors, level by
 * level, in the order the official constructor builds it. */
#include "gen3d/sd.h"

#include "sd_int.h"

#include <cjson/cJSON.h>

#include <ctype.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define GN_EPS_RES 1e-5f  /* GroupNorm32 of the ResBlocks and the output (PyTorch's default) */
#define GN_EPS_ST 1e-6f   /* the spatial transformer's Normalize() */
#define LN_EPS 1e-5f
/* cldm's input_hint_block: eight 3x3 convolutions (SiLU between them), these of stride 2 */
#define HINT_CONVS 8
static const int HINT_STRIDE[HINT_CONVS] = {1, 1, 2, 1, 2, 1, 2, 1};

typedef struct sd_tblock {
    float *ln[3][2];
    g3d_nn_lin qkv, out1, q2, kv2, out2, ff1, ff2;
    int ff;
} sd_tblock;

/* SpatialTransformer: GroupNorm, proj_in, `depth` blocks, proj_out, plus the input. */
typedef struct sd_st {
    int c, inner, heads, hd, depth;
    float *gn_g, *gn_b;
    g3d_nn_lin pin, pout;
    sd_tblock *blk;
} sd_st;

typedef struct sd_block {
    int has_res, has_st, has_down, has_up;
    sd_res res;
    sd_st st;
    g3d_nn_conv resample;
    int cout;
} sd_block;

struct g3d_sd_unet {
    g3d_sd_unet_config cfg;
    int nin, nout, temb_dim;
    g3d_nn_lin te1, te2;
    g3d_nn_conv conv_in, conv_out;
    float *gn_out_g, *gn_out_b;
    sd_block *in, *out, mid[3];
    /* a ControlNet: the encoder half (no output blocks) with its hint block and zero convolutions */
    int control;
    g3d_nn_conv hint[HINT_CONVS], *zero, mid_out;
};

struct g3d_sd_controlnet {
    g3d_sd_unet net;   /* first: the encoder's code runs on it */
    g3d_sd_controlnet_config cfg;
};

/* ---- configuration ------------------------------------------------------------------- */

/* The integer after "key:" on a line of a yaml text, or -1 (first occurrence). */
static int yaml_int(const char *y, const char *key, int *v)
{
    size_t kn = strlen(key);
    for (const char *p = y; p && *p; p = strchr(p, '\n'), p = p ? p + 1 : NULL) {
        const char *s = p;
        while (*s == ' ' || *s == '\t') s++;
        if (!strncmp(s, key, kn) && s[kn] == ':') {
            s += kn + 1;
            while (*s == ' ' || *s == '"' || *s == '\'') s++;
            if (v) *v = isdigit((unsigned char)*s) ? atoi(s) : -1;
            return (int)(s - y);
        }
    }
    return -1;
}

static const char *const UNET_PREFIXES[] = {"model.diffusion_model.", ""};

static sd_ld unet_ld(const g3d_ckpt *ck, const g3d_sd_unet_config *c)
{
    return (sd_ld){ck, c->prefix, c->diffusers ? SD_DIFFUSERS_UNET : SD_ORIGINAL, c->nres[0], c->levels};
}

/* diffusers' unet/config.json: attention_head_dim (or num_attention_heads) is the head count,
 * one for every level or a list; in_channels and cross_attention_dim are checked. */
static g3d_status apply_json(const g3d_ckpt *ck, const char *text, g3d_sd_unet_config *c)
{
    cJSON *j = cJSON_Parse(text);
    if (!j) return G3D_ERR(G3D_ERR_FORMAT, "%s: the UNet's config.json is not JSON", g3d_ckpt_path(ck));
    const cJSON *h = cJSON_GetObjectItemCaseSensitive(j, "num_attention_heads");
    if (!h || cJSON_IsNull(h)) h = cJSON_GetObjectItemCaseSensitive(j, "attention_head_dim");
    const cJSON *in = cJSON_GetObjectItemCaseSensitive(j, "in_channels"), *cd = cJSON_GetObjectItemCaseSensitive(j, "cross_attention_dim");
    g3d_status rc = G3D_OK;
    if (cJSON_IsNumber(h) && h->valueint > 0) c->heads = h->valueint, c->head_dim = 0;
    if (cJSON_IsArray(h) && cJSON_IsNumber(cJSON_GetArrayItem(h, 0)) && cJSON_GetArrayItem(h, 0)->valueint > 0) {
        /* heads per level; the published lists keep 64 channels per head */
        c->head_dim = c->mult[0] * c->model_ch / cJSON_GetArrayItem(h, 0)->valueint;
        c->heads = 0;
    }
    if (cJSON_IsNumber(in) && in->valueint != c->in_ch)
        rc = G3D_ERR(G3D_ERR_MODEL, "%s: config.json says %d input channels, the tensors have %d", g3d_ckpt_path(ck), in->valueint, c->in_ch);
    if (cJSON_IsNumber(cd) && cd->valueint != c->context_dim)
        rc = G3D_ERR(G3D_ERR_MODEL, "%s: config.json says context %d, the tensors have %d", g3d_ckpt_path(ck), cd->valueint, c->context_dim);
    cJSON_Delete(j);
    return rc;
}

/* The encoder half both the UNet and a ControlNet have, in the order the constructor builds
 * it, with ld's prefix and layout already found: in-channels, model channels, the levels, the
 * middle block's transformer (context width, depth, projections), the family's head split. */
static g3d_status probe_encoder(const sd_ld *ldp, g3d_sd_unet_config *c)
{
    const sd_ld ld = *ldp;
    const g3d_ckpt *ck = ld.ck;
    c->prefix = ld.prefix;
    const g3d_tensor_info *t = sd_find(&ld, "input_blocks.0.0.weight");
    if (t->ndim != 4 || t->shape[2] != 3 || t->shape[3] != 3)
        return G3D_ERR(G3D_ERR_MODEL, "%s: tensor %sinput_blocks.0.0.weight is not a 3x3 convolution", g3d_ckpt_path(ck), ld.prefix);
    c->model_ch = (int)t->shape[0];
    c->in_ch = (int)t->shape[1];
    if (c->model_ch % 32)
        return G3D_ERR(G3D_ERR_MODEL, "%s: %d model channels do not split into 32 groups", g3d_ckpt_path(ck), c->model_ch);
    /* walk the input blocks as the constructor made them: res blocks (+ transformer), then a
     * downsampling convolution between levels */
    int level = 0;
    for (int i = 1;; i++) {
        if (sd_find(&ld, "input_blocks.%d.0.op.weight", i)) {
            if (++level >= G3D_SD_MAX_LEVELS) return G3D_ERR(G3D_ERR_MODEL, "%s: more than %d levels", g3d_ckpt_path(ck), G3D_SD_MAX_LEVELS);
            continue;
        }
        const g3d_tensor_info *w = sd_find(&ld, "input_blocks.%d.0.in_layers.2.weight", i);
        if (!w) break;
        if (w->ndim != 4 || w->shape[0] % c->model_ch)
            return G3D_ERR(G3D_ERR_MODEL, "%s: tensor %sinput_blocks.%d.0.in_layers.2.weight: %lld channels, not a multiple of %d",
                           g3d_ckpt_path(ck), ld.prefix, i, (long long)w->shape[0], c->model_ch);
        c->mult[level] = (int)(w->shape[0] / c->model_ch);
        c->nres[level]++;
        if (sd_find(&ld, "input_blocks.%d.1.norm.weight", i)) c->attn[level] = 1;
    }
    c->levels = level + 1;
    for (int l = 0; l < c->levels; l++)
        if (!c->nres[l])
            return G3D_ERR(G3D_ERR_MODEL, "%s: level %d has no res block (missing tensor %sinput_blocks.*.0.in_layers.2.weight)",
                           g3d_ckpt_path(ck), l, ld.prefix);
    const g3d_tensor_info *k = sd_find(&ld, "middle_block.1.transformer_blocks.0.attn2.to_k.weight");
    const g3d_tensor_info *pin = sd_find(&ld, "middle_block.1.proj_in.weight");
    if (!k || k->ndim != 2 || !pin)
        return G3D_ERR(G3D_ERR_MODEL, "%s: missing tensor %smiddle_block.1.%s", g3d_ckpt_path(ck), ld.prefix,
                       !pin ? "proj_in.weight" : "transformer_blocks.0.attn2.to_k.weight");
    c->context_dim = (int)k->shape[1];
    c->linear_proj = pin->ndim == 2;
    while (sd_find(&ld, "middle_block.1.transformer_blocks.%d.attn1.to_q.weight", c->depth)) c->depth++;
    /* the published conventions: SD 1.x 8 heads and 1x1-conv projections, SD 2.x heads of 64
     * channels and Linear projections */
    c->family = c->linear_proj || c->context_dim == 1024 ? 2 : 1;
    if (c->family == 2) c->head_dim = 64;
    else c->heads = 8;
    c->pred = G3D_SD_PRED_EPS;
    return G3D_OK;
}

/* The original yaml configuration's fields, or diffusers' config.json (text starting with '{'). */
static g3d_status apply_config(const g3d_ckpt *ck, const char *yaml, g3d_sd_unet_config *c)
{
    const char *y = yaml;
    while (y && isspace((unsigned char)*y)) y++;
    if (y && *y == '{') return apply_json(ck, y, c);
    if (yaml) {
        int v;
        if (yaml_int(yaml, "num_heads", &v) >= 0 && v > 0) c->heads = v, c->head_dim = 0;
        if (yaml_int(yaml, "num_head_channels", &v) >= 0 && v > 0) c->head_dim = v, c->heads = 0;
        int at = yaml_int(yaml, "parameterization", NULL);
        if (at >= 0 && yaml[at] == 'v' && !isalnum((unsigned char)yaml[at + 1])) c->pred = G3D_SD_PRED_V;
        if (yaml_int(yaml, "in_channels", &v) >= 0 && v > 0 && v != c->in_ch)
            return G3D_ERR(G3D_ERR_MODEL, "%s: the configuration says %d input channels, the tensors have %d", g3d_ckpt_path(ck), v,
                           c->in_ch);
        if (yaml_int(yaml, "context_dim", &v) >= 0 && v > 0 && v != c->context_dim)
            return G3D_ERR(G3D_ERR_MODEL, "%s: the configuration says context %d, the tensors have %d", g3d_ckpt_path(ck), v,
                           c->context_dim);
    }
    return G3D_OK;
}

/* Counts diffusers' res blocks per level (down_blocks.0.resnets.N) into ld->nres. */
static void diffusers_nres(sd_ld *ld)
{
    char k[64];
    ld->nres = 0;
    do snprintf(k, sizeof k, "down_blocks.0.resnets.%d.conv1.weight", ld->nres);
    while (g3d_ckpt_find(ld->ck, k) && ++ld->nres < 64);
}

/* Where a network's tensors are: under the first of the prefixes that holds both original
 * names mark[0] and mark[1], else in diffusers' layout when the file holds its names mark[2]
 * and mark[3]. ld->prefix stays NULL when neither. */
static void find_layout(const g3d_ckpt *ck, const char *const *prefixes, size_t np, const char *const mark[4], sd_ld *ld,
                        g3d_sd_unet_config *c)
{
    *ld = (sd_ld){ck, NULL, SD_ORIGINAL, 0, 0};
    for (size_t i = 0; i < np && !ld->prefix; i++) {
        sd_ld t = {ck, prefixes[i], SD_ORIGINAL, 0, 0};
        if (sd_find(&t, mark[0]) && sd_find(&t, mark[1])) ld->prefix = t.prefix;
    }
    if (!ld->prefix && g3d_ckpt_find(ck, mark[2]) && g3d_ckpt_find(ck, mark[3])) {
        ld->prefix = "";
        ld->layout = SD_DIFFUSERS_UNET;
        c->diffusers = 1;
        diffusers_nres(ld);
    }
}

g3d_status g3d_sd_unet_probe(const g3d_ckpt *ck, const char *yaml, g3d_sd_unet_config *c)
{
    static const char *const mark[4] = {"input_blocks.0.0.weight", "time_embed.0.weight", "conv_in.weight", "time_embedding.linear_1.weight"};
    memset(c, 0, sizeof *c);
    sd_ld ld;
    find_layout(ck, UNET_PREFIXES, sizeof UNET_PREFIXES / sizeof *UNET_PREFIXES, mark, &ld, c);
    if (!ld.prefix)
        return G3D_ERR(G3D_ERR_MODEL, "%s: not a Stable Diffusion UNet (missing tensor model.diffusion_model.input_blocks.0.0.weight)",
                       g3d_ckpt_path(ck));
    G3D_TRY(probe_encoder(&ld, c));
    const g3d_tensor_info *o = sd_find(&ld, "out.2.weight");
    if (!o || o->ndim != 4) return G3D_ERR(G3D_ERR_MODEL, "%s: missing tensor %sout.2.weight", g3d_ckpt_path(ck), ld.prefix);
    c->out_ch = (int)o->shape[0];
    return apply_config(ck, yaml, c);
}

static const char *const CONTROL_PREFIXES[] = {"control_model.", ""};

g3d_status g3d_sd_controlnet_probe(const g3d_ckpt *ck, const char *config, g3d_sd_controlnet_config *cc)
{
    static const char *const mark[4] = {"input_hint_block.0.weight", "input_blocks.0.0.weight",
                                        "controlnet_cond_embedding.conv_in.weight", "conv_in.weight"};
    memset(cc, 0, sizeof *cc);
    g3d_sd_unet_config *c = &cc->net;
    sd_ld ld;
    find_layout(ck, CONTROL_PREFIXES, sizeof CONTROL_PREFIXES / sizeof *CONTROL_PREFIXES, mark, &ld, c);
    if (!ld.prefix)
        return G3D_ERR(G3D_ERR_MODEL, "%s: not a ControlNet (missing tensor control_model.input_hint_block.0.weight)", g3d_ckpt_path(ck));
    G3D_TRY(probe_encoder(&ld, c));
    const g3d_tensor_info *h = sd_find(&ld, "input_hint_block.0.weight");
    if (h->ndim != 4) return G3D_ERR(G3D_ERR_MODEL, "%s: tensor %sinput_hint_block.0.weight is not a convolution", g3d_ckpt_path(ck), ld.prefix);
    cc->hint_ch = (int)h->shape[1];
    return apply_config(ck, config, c);
}

char *g3d_sd_yaml_beside(const char *model_path)
{
    size_t n = strlen(model_path);
    const char *dot = strrchr(model_path, '.'), *slash = strrchr(model_path, '/');
    if (!dot || (slash && dot < slash)) dot = model_path + n;
    char *y = malloc((size_t)(dot - model_path) + 6);
    if (!y) return NULL;
    memcpy(y, model_path, (size_t)(dot - model_path));
    strcpy(y + (dot - model_path), ".yaml");
    unsigned char *text = NULL;
    size_t len;
    FILE *f = fopen(y, "rb");
    if (f) fclose(f);
    if (!f || g3d_read_file(y, 1 << 20, &text, &len) != G3D_OK) {
        g3d_error_clear();
        text = NULL;
    }
    free(y);
    return (char *)text;
}

const char *g3d_sd_unet_describe(const g3d_sd_unet_config *c, char *buf, size_t n)
{
    char mult[64] = "", nres[64] = "", attn[64] = "";
    for (int l = 0; l < c->levels; l++) {
        snprintf(mult + strlen(mult), sizeof mult - strlen(mult), "%s%d", l ? "/" : "", c->mult[l]);
        snprintf(nres + strlen(nres), sizeof nres - strlen(nres), "%s%d", l ? "/" : "", c->nres[l]);
        if (c->attn[l]) snprintf(attn + strlen(attn), sizeof attn - strlen(attn), "%s%d", attn[0] ? "/" : "", l);
    }
    char heads[32];
    if (c->heads) snprintf(heads, sizeof heads, "%d heads", c->heads);
    else snprintf(heads, sizeof heads, "heads of %d", c->head_dim);
    snprintf(buf, n, "SD %d.x UNet (%s%d input channels%s, model channels %d, multipliers %s, res blocks %s, attention at levels %s, "
             "transformer depth %d, context %d, %s, %s projections, %s prediction)",
             c->family, c->diffusers ? "diffusers layout, " : "", c->in_ch, c->in_ch == 9 ? ": inpainting" : "", c->model_ch, mult, nres,
             attn[0] ? attn : "none", c->depth, c->context_dim, heads, c->linear_proj ? "Linear" : "1x1-conv",
             c->pred == G3D_SD_PRED_V ? "v" : "epsilon");
    return buf;
}

/* ---- loading -------------------------------------------------------------------------- */

static g3d_status st_load(const sd_ld *ld, const g3d_sd_unet_config *c, sd_st *s, int ch, const char *base)
{
    char n[256];
    const g3d_tensor_info *t;
    memset(s, 0, sizeof *s);
    s->c = ch;
    s->depth = c->depth;
    t = sd_find(ld, "%s.proj_in.weight", base);
    s->inner = t && t->ndim >= 2 ? (int)t->shape[0] : ch;
    if (c->heads) s->heads = c->heads, s->hd = s->inner / c->heads;
    else s->hd = c->head_dim, s->heads = s->inner / c->head_dim;
    if (s->heads < 1 || s->hd < 1 || s->heads * s->hd != s->inner)
        return G3D_ERR(G3D_ERR_MODEL, "%s: %s has %d channels, which do not split into %s", g3d_ckpt_path(ld->ck), base, s->inner,
                       c->heads ? "the configured heads" : "heads of the configured width");
    snprintf(n, sizeof n, "%s.norm", base);
    G3D_TRY(sd_vec(ld, &s->gn_g, ch, n, "weight"));
    G3D_TRY(sd_vec(ld, &s->gn_b, ch, n, "bias"));
    snprintf(n, sizeof n, "%s.proj_in", base);
    G3D_TRY(sd_lin_load(ld, &s->pin, s->inner, ch, 1, n));
    snprintf(n, sizeof n, "%s.proj_out", base);
    G3D_TRY(sd_lin_load(ld, &s->pout, ch, s->inner, 1, n));
    if (!(s->blk = calloc((size_t)s->depth, sizeof *s->blk))) return G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the UNet");
    int D = s->inner;
    for (int d = 0; d < s->depth; d++) {
        sd_tblock *b = &s->blk[d];
        for (int k = 0; k < 3; k++) {
            snprintf(n, sizeof n, "%s.transformer_blocks.%d.norm%d", base, d, k + 1);
            G3D_TRY(sd_vec(ld, &b->ln[k][0], D, n, "weight"));
            G3D_TRY(sd_vec(ld, &b->ln[k][1], D, n, "bias"));
        }
        t = sd_find(ld, "%s.transformer_blocks.%d.ff.net.0.proj.weight", base, d);
        b->ff = t && t->ndim == 2 ? (int)t->shape[0] / 2 : 4 * D;
        static const char *const qkv[] = {"to_q", "to_k", "to_v"};
        /* self-attention's q, k and v (no bias) as one layer */
        snprintf(n, sizeof n, "%s.transformer_blocks.%d.attn1", base, d);
        G3D_TRY(sd_lin_packed(ld, &b->qkv, 3, D, D, 0, n, qkv));
        snprintf(n, sizeof n, "%s.transformer_blocks.%d.attn1.to_out.0", base, d);
        G3D_TRY(sd_lin_load(ld, &b->out1, D, D, 1, n));
        snprintf(n, sizeof n, "%s.transformer_blocks.%d.attn2.to_q", base, d);
        G3D_TRY(sd_lin_load(ld, &b->q2, D, D, 0, n));
        /* cross-attention's k and v read the text context: one layer too */
        snprintf(n, sizeof n, "%s.transformer_blocks.%d.attn2", base, d);
        G3D_TRY(sd_lin_packed(ld, &b->kv2, 2, D, c->context_dim, 0, n, qkv + 1));
        snprintf(n, sizeof n, "%s.transformer_blocks.%d.attn2.to_out.0", base, d);
        G3D_TRY(sd_lin_load(ld, &b->out2, D, D, 1, n));
        snprintf(n, sizeof n, "%s.transformer_blocks.%d.ff.net.0.proj", base, d);
        G3D_TRY(sd_lin_load(ld, &b->ff1, 2 * b->ff, D, 1, n));
        snprintf(n, sizeof n, "%s.transformer_blocks.%d.ff.net.2", base, d);
        G3D_TRY(sd_lin_load(ld, &b->ff2, D, b->ff, 1, n));
    }
    return G3D_OK;
}

static void st_free(sd_st *s)
{
    free(s->gn_g);
    free(s->gn_b);
    g3d_nn_lin_free(&s->pin);
    g3d_nn_lin_free(&s->pout);
    for (int d = 0; s->blk && d < s->depth; d++) {
        sd_tblock *b = &s->blk[d];
        for (int k = 0; k < 3; k++) free(b->ln[k][0]), free(b->ln[k][1]);
        g3d_nn_lin *L[] = {&b->qkv, &b->out1, &b->q2, &b->kv2, &b->out2, &b->ff1, &b->ff2};
        for (size_t i = 0; i < sizeof L / sizeof *L; i++) g3d_nn_lin_free(L[i]);
    }
    free(s->blk);
}

static void block_free(sd_block *b)
{
    if (b->has_res) sd_res_free(&b->res);
    if (b->has_st) st_free(&b->st);
    sd_conv_free(&b->resample);
}

static void unet_release(g3d_sd_unet *m)
{
    for (int i = 0; m->in && i < m->nin; i++) block_free(&m->in[i]);
    for (int i = 0; m->out && i < m->nout; i++) block_free(&m->out[i]);
    for (int i = 0; i < 3; i++) block_free(&m->mid[i]);
    free(m->in);
    free(m->out);
    g3d_nn_lin_free(&m->te1);
    g3d_nn_lin_free(&m->te2);
    sd_conv_free(&m->conv_in);
    sd_conv_free(&m->conv_out);
    free(m->gn_out_g);
    free(m->gn_out_b);
    for (int i = 0; i < HINT_CONVS; i++) sd_conv_free(&m->hint[i]);
    for (int i = 0; m->zero && i < m->nin; i++) sd_conv_free(&m->zero[i]);
    free(m->zero);
    sd_conv_free(&m->mid_out);
}

void g3d_sd_unet_free(g3d_sd_unet *m)
{
    if (!m) return;
    unet_release(m);
    free(m);
}

void g3d_sd_controlnet_free(g3d_sd_controlnet *m)
{
    if (!m) return;
    unet_release(&m->net);
    free(m);
}

/* The 3x3 convolutions on the two finest maps (64 x 64 and 32 x 32 latents at 512 x 512)
 * through Winograd: F(4x4) on the finest, F(2x2) on the next, whose 62 M weights would cost
 * 1 GB as F(4x4) kernels (0.45 GB as F(2x2)). The coarser maps (16 x 16 and 8 x 8) are too
 * small for F(4x4) to pay (docs/nn.md) and hold most of the weights. */
static g3d_status prepare_at(g3d_nn_conv *c, int res_level)
{
    if (res_level > 1) return G3D_OK;
    c->wino_small = res_level == 1;
    return g3d_nn_conv_prepare(c);
}

/* A res block, then a transformer when `st`, at <base>.0 and <base>.1; `level` is the
 * resolution level the block runs at. */
static g3d_status res_st(const sd_ld *ld, const g3d_sd_unet *m, sd_block *b, int cin, int cout, int st, int level,
                         const char *base)
{
    char n[272];
    snprintf(n, sizeof n, "%s.0", base);
    b->has_res = 1;
    G3D_TRY(sd_res_load(ld, &b->res, cin, cout, m->temb_dim, GN_EPS_RES, n));
    G3D_TRY(prepare_at(&b->res.c1, level));
    G3D_TRY(prepare_at(&b->res.c2, level));
    b->cout = cout;
    if (st) {
        snprintf(n, sizeof n, "%s.1", base);
        b->has_st = 1;
        G3D_TRY(st_load(ld, &m->cfg, &b->st, cout, n));
    }
    return G3D_OK;
}

static g3d_status unet_build(g3d_sd_unet *m, const g3d_ckpt *ck)
{
    const g3d_sd_unet_config *c = &m->cfg;
    sd_ld ld = unet_ld(ck, c);
    int C = c->model_ch;
    char n[256];
    m->temb_dim = 4 * C;
    G3D_TRY(sd_lin_load(&ld, &m->te1, m->temb_dim, C, 1, "time_embed.0"));
    G3D_TRY(sd_lin_load(&ld, &m->te2, m->temb_dim, m->temb_dim, 1, "time_embed.2"));
    G3D_TRY(sd_conv_load(&ld, &m->conv_in, c->in_ch, C, 3, 1, "input_blocks.0.0"));
    int total = 1;
    for (int l = 0; l < c->levels; l++) total += c->nres[l] + (l < c->levels - 1);
    if (total > 64) return G3D_ERR(G3D_ERR_MODEL, "%s: %d input blocks (at most 64)", g3d_ckpt_path(ck), total);
    m->in = calloc((size_t)total, sizeof *m->in);
    m->out = calloc((size_t)total, sizeof *m->out);
    if (!m->in || !m->out) return G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the UNet");
    int chans[64], nch = 0, ch = C, i = 1;
    chans[nch++] = C;
    m->nin = 1;
    for (int l = 0; l < c->levels; l++) {
        for (int r = 0; r < c->nres[l]; r++, i++) {
            snprintf(n, sizeof n, "input_blocks.%d", i);
            m->nin = i + 1;   /* freed with the model even when it fails half-way */
            G3D_TRY(res_st(&ld, m, &m->in[i], ch, c->mult[l] * C, c->attn[l], l, n));
            ch = c->mult[l] * C;
            chans[nch++] = ch;
        }
        if (l < c->levels - 1) {
            snprintf(n, sizeof n, "input_blocks.%d.0.op", i);
            m->in[i].has_down = 1;
            m->in[i].cout = ch;
            m->nin = i + 1;
            G3D_TRY(sd_conv_load(&ld, &m->in[i].resample, ch, ch, 3, 2, n));
            i++;
            chans[nch++] = ch;
        }
    }
    /* ResBlock, transformer (at every level's configuration), ResBlock */
    for (int k = 0; k < 3; k++) {
        snprintf(n, sizeof n, "middle_block.%d", k);
        m->mid[k].cout = ch;
        if (k == 1) m->mid[k].has_st = 1;
        else m->mid[k].has_res = 1;
        G3D_TRY(k == 1 ? st_load(&ld, c, &m->mid[k].st, ch, n) : sd_res_load(&ld, &m->mid[k].res, ch, ch, m->temb_dim, GN_EPS_RES, n));
    }
    if (m->control) {
        /* the hint block's widths come from its tensors; its last convolution gives the model channels */
        int hc = ((const g3d_sd_controlnet *)m)->cfg.hint_ch;
        for (int k = 0; k < HINT_CONVS; k++) {
            const g3d_tensor_info *t = sd_find(&ld, "input_hint_block.%d.weight", 2 * k);
            int co = k == HINT_CONVS - 1 ? C : t && t->ndim == 4 ? (int)t->shape[0] : 1;
            snprintf(n, sizeof n, "input_hint_block.%d", 2 * k);
            G3D_TRY(sd_conv_load(&ld, &m->hint[k], hc, co, 3, HINT_STRIDE[k], n));
            hc = co;
        }
        if (!(m->zero = calloc((size_t)m->nin, sizeof *m->zero))) return G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the ControlNet");
        for (int b = 0; b < m->nin; b++) {
            snprintf(n, sizeof n, "zero_convs.%d.0", b);
            G3D_TRY(sd_conv_load(&ld, &m->zero[b], chans[b], chans[b], 1, 1, n));
        }
        return sd_conv_load(&ld, &m->mid_out, ch, ch, 1, 1, "middle_block_out.0");
    }
    i = 0;
    for (int l = c->levels - 1; l >= 0; l--)
        for (int r = 0; r <= c->nres[l]; r++, i++) {
            int ich = chans[--nch];
            snprintf(n, sizeof n, "output_blocks.%d", i);
            m->nout = i + 1;
            G3D_TRY(res_st(&ld, m, &m->out[i], ch + ich, c->mult[l] * C, c->attn[l], l, n));
            ch = c->mult[l] * C;
            if (l && r == c->nres[l]) {
                snprintf(n, sizeof n, "output_blocks.%d.%d.conv", i, c->attn[l] ? 2 : 1);
                m->out[i].has_up = 1;
                G3D_TRY(sd_conv_load(&ld, &m->out[i].resample, ch, ch, 3, 1, n));
                G3D_TRY(prepare_at(&m->out[i].resample, l - 1)); /* after the upsampling */
            }
        }
    G3D_TRY(sd_vec(&ld, &m->gn_out_g, ch, "out.0", "weight"));
    G3D_TRY(sd_vec(&ld, &m->gn_out_b, ch, "out.0", "bias"));
    G3D_TRY(sd_conv_load(&ld, &m->conv_out, ch, c->out_ch, 3, 1, "out.2"));
    return G3D_OK;
}

g3d_status g3d_sd_unet_load(const g3d_ckpt *ck, const char *yaml, g3d_sd_unet **out)
{
    *out = NULL;
    g3d_sd_unet *m = calloc(1, sizeof *m);
    if (!m) return G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the UNet");
    g3d_status rc = g3d_sd_unet_probe(ck, yaml, &m->cfg);
    if (rc == G3D_OK) rc = unet_build(m, ck);
    if (rc != G3D_OK) {
        g3d_sd_unet_free(m);
        return rc;
    }
    *out = m;
    return G3D_OK;
}

const g3d_sd_unet_config *g3d_sd_unet_get_config(const g3d_sd_unet *m) { return &m->cfg; }

/* ---- forward ------------------------------------------------------------------------- */

typedef struct fwd {
    g3d_nn_arena *ar;
    const float *ctx;
    int nctx;
    const float *emb;
    g3d_sd_trace_fn trace;
    void *tctx;
} fwd;

static float *take(fwd *f, size_t n) { return g3d_nn_arena_floats(f->ar, n); }

#define NOMEM G3D_ERR(G3D_ERR_NOMEM, "out of memory in the UNet")

/* x [c, hw] -> y [c, hw] = x + transformer(x). */
static g3d_status st_forward(const sd_st *s, fwd *f, const float *x, int hw, float *y)
{
    size_t mark = g3d_nn_arena_mark(f->ar);
    int C = s->c, D = s->inner;
    float *g = take(f, (size_t)C * hw), *T = take(f, (size_t)C * hw), *X = take(f, (size_t)D * hw);
    float *N = take(f, (size_t)D * hw), *A = take(f, (size_t)D * hw), *Q = take(f, 3 * (size_t)D * hw);
    float *KV = take(f, 2 * (size_t)D * f->nctx);
    int ffmax = 0;
    for (int d = 0; d < s->depth; d++) ffmax = s->blk[d].ff > ffmax ? s->blk[d].ff : ffmax;
    float *H = take(f, 2 * (size_t)ffmax * hw), *G = take(f, (size_t)ffmax * hw);
    if (!g || !T || !X || !N || !A || !Q || !KV || !H || !G) return NOMEM;
    g3d_nn_groupnorm(x, C, hw, 32, s->gn_g, s->gn_b, GN_EPS_ST, G3D_ACT_NONE, g);
    sd_transpose(g, C, hw, T, 0);
    G3D_TRY(g3d_nn_lin_forward(&s->pin, T, hw, 0, X, 0, NULL));
    float scale = 1.0f / sqrtf((float)s->hd);
    g3d_nn_epi res = {.res = X};
    for (int d = 0; d < s->depth; d++) {
        const sd_tblock *b = &s->blk[d];
        g3d_nn_layernorm(X, hw, D, b->ln[0][0], b->ln[0][1], LN_EPS, N);
        G3D_TRY(g3d_nn_lin_forward(&b->qkv, N, hw, 0, Q, 0, NULL));
        g3d_nn_attn a = {.nq = hw, .nk = hw, .heads = s->heads, .hd = s->hd, .q = Q, .k = Q + D, .v = Q + 2 * D,
                         .ldq = 3 * D, .ldk = 3 * D, .ldv = 3 * D, .out = A, .scale = scale};
        G3D_TRY(g3d_nn_attend(&a));
        G3D_TRY(g3d_nn_lin_forward(&b->out1, A, hw, 0, X, 0, &res));
        g3d_nn_layernorm(X, hw, D, b->ln[1][0], b->ln[1][1], LN_EPS, N);
        G3D_TRY(g3d_nn_lin_forward(&b->q2, N, hw, 0, Q, 0, NULL));
        G3D_TRY(g3d_nn_lin_forward(&b->kv2, f->ctx, f->nctx, 0, KV, 0, NULL));
        g3d_nn_attn a2 = {.nq = hw, .nk = f->nctx, .heads = s->heads, .hd = s->hd, .q = Q, .k = KV, .v = KV + D,
                          .ldq = D, .ldk = 2 * D, .ldv = 2 * D, .out = A, .scale = scale};
        G3D_TRY(g3d_nn_attend(&a2));
        G3D_TRY(g3d_nn_lin_forward(&b->out2, A, hw, 0, X, 0, &res));
        g3d_nn_layernorm(X, hw, D, b->ln[2][0], b->ln[2][1], LN_EPS, N);
        G3D_TRY(g3d_nn_lin_forward(&b->ff1, N, hw, 0, H, 0, NULL));
        g3d_nn_geglu(H, hw, b->ff, G);
        G3D_TRY(g3d_nn_lin_forward(&b->ff2, G, hw, 0, X, 0, &res));
    }
    G3D_TRY(g3d_nn_lin_forward(&s->pout, X, hw, 0, T, 0, NULL));
    memcpy(y, x, sizeof(float) * (size_t)C * hw);
    sd_transpose(T, hw, C, y, 1);
    g3d_nn_arena_reset(f->ar, mark);
    return G3D_OK;
}

/* One block of the UNet: x [cin, h, w] -> *y (allocated from the arena; its size in *h, *w). */
static g3d_status block_forward(const sd_block *b, fwd *f, const float *x, int *h, int *w, float **y)
{
    int hw = *h * *w;
    float *cur = (float *)x;
    if (b->has_res) {
        float *o = take(f, (size_t)b->res.cout * hw);
        size_t mark = g3d_nn_arena_mark(f->ar);
        int big = b->res.cin > b->res.cout ? b->res.cin : b->res.cout;
        float *tmp = take(f, (size_t)big * hw + b->res.cout);
        if (!o || !tmp) return NOMEM;
        G3D_TRY(sd_res_forward(&b->res, cur, *h, *w, f->emb, o, tmp));
        g3d_nn_arena_reset(f->ar, mark);
        cur = o;
    }
    if (b->has_st) {
        float *o = take(f, (size_t)b->st.c * hw);
        if (!o) return NOMEM;
        G3D_TRY(st_forward(&b->st, f, cur, hw, o));
        cur = o;
    }
    if (b->has_down) {
        int ho, wo;
        G3D_TRY(g3d_nn_conv_out_size(&b->resample, *h, *w, &ho, &wo));
        float *o = take(f, (size_t)b->resample.cout * ho * wo);
        if (!o) return NOMEM;
        G3D_TRY(g3d_nn_conv_forward(&b->resample, cur, *h, *w, o, NULL));
        cur = o, *h = ho, *w = wo;
    }
    if (b->has_up) {
        int c = b->resample.cin;
        float *u = take(f, (size_t)c * 4 * hw), *o = take(f, (size_t)b->resample.cout * 4 * hw);
        if (!u || !o) return NOMEM;
        g3d_nn_upsample2x(cur, c, *h, *w, u);
        *h *= 2, *w *= 2;
        G3D_TRY(g3d_nn_conv_forward(&b->resample, u, *h, *w, o, NULL));
        cur = o;
    }
    *y = cur;
    return G3D_OK;
}

static void emit(const fwd *f, const char *fmt, int i, const float *x, int c, int h, int w)
{
    if (!f->trace) return;
    char n[32];
    snprintf(n, sizeof n, fmt, i);
    f->trace(f->tctx, n, x, c, h, w);
}

/* The shapes of the skip connections (and the middle block's output, last): where each of a
 * ControlNet's residuals sits in their packed buffer. */
typedef struct skips {
    const float *x[65];
    int c[65], h[65], w[65], n;
} skips;

/* Time embedding (into f->emb), input blocks and middle block: the skips and, in *cur, the
 * middle block's output. guided (a ControlNet's hint features, [model_ch, h, w]) is added
 * after the first convolution, as cldm's ControlNet does. */
static g3d_status encode(const g3d_sd_unet *m, fwd *f, const float *x, int h, int w, float t, const float *guided, skips *s,
                         float **cur)
{
    const g3d_sd_unet_config *c = &m->cfg;
    int E = m->temb_dim, C = c->model_ch;
    float *te = take(f, (size_t)C), *e1 = take(f, (size_t)E), *emb = take(f, (size_t)E);
    if (!te || !e1 || !emb) return NOMEM;
    g3d_nn_timestep_embedding(t, C, 10000.0f, te);
    g3d_nn_epi silu = {.act = G3D_ACT_SILU};
    G3D_TRY(g3d_nn_lin_forward(&m->te1, te, 1, 0, e1, 0, &silu));
    G3D_TRY(g3d_nn_lin_forward(&m->te2, e1, 1, 0, emb, 0, NULL));
    emit(f, "temb", 0, emb, E, 1, 1);
    /* every ResBlock starts its embedding branch with SiLU */
    g3d_nn_activate(G3D_ACT_SILU, emb, (size_t)E);
    f->emb = emb;
    float *h0 = take(f, (size_t)C * h * w);
    if (!h0) return NOMEM;
    g3d_nn_epi add = {.res = guided};
    G3D_TRY(g3d_nn_conv_forward(&m->conv_in, x, h, w, h0, guided ? &add : NULL));
    *cur = h0;
    int ch = C;
    s->n = 0;
    for (int i = 0; i < m->nin; i++) {
        if (i) G3D_TRY(block_forward(&m->in[i], f, *cur, &h, &w, cur));
        ch = i ? m->in[i].cout : C;
        emit(f, "in%d", i, *cur, ch, h, w);
        s->x[s->n] = *cur, s->c[s->n] = ch, s->h[s->n] = h, s->w[s->n++] = w;
    }
    for (int i = 0; i < 3; i++) G3D_TRY(block_forward(&m->mid[i], f, *cur, &h, &w, cur));
    emit(f, "mid", 0, *cur, ch, h, w);
    s->x[s->n] = *cur, s->c[s->n] = ch, s->h[s->n] = h, s->w[s->n] = w;
    return G3D_OK;
}

static g3d_status unet_run(const g3d_sd_unet *m, fwd *f, const float *x, int h, int w, float t, const float *res, float *out)
{
    skips s;
    float *cur;
    G3D_TRY(encode(m, f, x, h, w, t, NULL, &s, &cur));
    /* a ControlNet's residuals: one per skip, in order, then the middle block's */
    const float *rs[65];
    for (int i = 0; res && i <= s.n; i++) {
        rs[i] = res;
        res += (size_t)s.c[i] * s.h[i] * s.w[i];
    }
    int ch = s.c[s.n], ns = s.n;
    h = s.h[ns], w = s.w[ns];
    if (res)
        for (size_t i = 0; i < (size_t)ch * h * w; i++) cur[i] += rs[ns][i];
    for (int i = 0; i < m->nout; i++) {
        int ich = s.c[--ns];
        size_t hw = (size_t)h * w;
        float *cat = take(f, (size_t)(ch + ich) * hw);
        if (!cat) return NOMEM;
        memcpy(cat, cur, sizeof(float) * ch * hw);
        memcpy(cat + ch * hw, s.x[ns], sizeof(float) * ich * hw);
        if (res)
            for (size_t k = 0; k < (size_t)ich * hw; k++) cat[ch * hw + k] += rs[ns][k];
        G3D_TRY(block_forward(&m->out[i], f, cat, &h, &w, &cur));
        ch = m->out[i].cout;
        emit(f, "out%d", i, cur, ch, h, w);
    }
    float *g = take(f, (size_t)ch * h * w);
    if (!g) return NOMEM;
    g3d_nn_groupnorm(cur, ch, h * w, 32, m->gn_out_g, m->gn_out_b, GN_EPS_RES, G3D_ACT_SILU, g);
    return g3d_nn_conv_forward(&m->conv_out, g, h, w, out, NULL);
}

/* The checks every forward shares; the arena in f. */
static g3d_status fwd_begin(const g3d_sd_unet *m, fwd *f, int h, int w, const float *ctx, int nctx, g3d_sd_trace_fn trace,
                            void *trace_ctx)
{
    int f2 = 1 << (m->cfg.levels - 1);
    if (h < 1 || w < 1 || h % f2 || w % f2)
        return G3D_ERR(G3D_ERR_ARG, "latent %dx%d: width and height must be multiples of %d", w, h, f2);
    if (nctx < 1 || !ctx) return G3D_ERR(G3D_ERR_ARG, "the UNet needs a text context");
    *f = (fwd){.ar = g3d_nn_arena_new(0), .ctx = ctx, .nctx = nctx, .trace = trace, .tctx = trace_ctx};
    return f->ar ? G3D_OK : NOMEM;
}

g3d_status g3d_sd_unet_forward_controlled(const g3d_sd_unet *m, const float *x, int h, int w, float t, const float *ctx,
                                          int nctx, const float *residuals, float *out, g3d_sd_trace_fn trace, void *trace_ctx)
{
    fwd f;
    G3D_TRY(fwd_begin(m, &f, h, w, ctx, nctx, trace, trace_ctx));
    g3d_status rc = unet_run(m, &f, x, h, w, t, residuals, out);
    g3d_nn_arena_free(f.ar);
    return rc;
}

g3d_status g3d_sd_unet_forward(const g3d_sd_unet *m, const float *x, int h, int w, float t, const float *ctx, int nctx,
                               float *out, g3d_sd_trace_fn trace, void *trace_ctx)
{
    return g3d_sd_unet_forward_controlled(m, x, h, w, t, ctx, nctx, NULL, out, trace, trace_ctx);
}

/* ---- ControlNet ------------------------------------------------------------------------ */

g3d_status g3d_sd_controlnet_load(const g3d_ckpt *ck, const char *config, g3d_sd_controlnet **out)
{
    *out = NULL;
    g3d_sd_controlnet *m = calloc(1, sizeof *m);
    if (!m) return G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the ControlNet");
    m->net.control = 1;
    g3d_status rc = g3d_sd_controlnet_probe(ck, config, &m->cfg);
    m->net.cfg = m->cfg.net;
    if (rc == G3D_OK) rc = unet_build(&m->net, ck);
    if (rc != G3D_OK) {
        g3d_sd_controlnet_free(m);
        return rc;
    }
    *out = m;
    return G3D_OK;
}

const g3d_sd_controlnet_config *g3d_sd_controlnet_get_config(const g3d_sd_controlnet *m) { return &m->cfg; }

/* "SD 1.x, context 768, model channels 320, multipliers 1/2/4/4, res blocks 2/2/2/2" */
static void net_figures(const g3d_sd_unet_config *c, char *buf, size_t n)
{
    int k = snprintf(buf, n, "SD %d.x, context %d, model channels %d, multipliers ", c->family, c->context_dim, c->model_ch);
    for (int l = 0; l < c->levels && k > 0 && (size_t)k < n; l++) k += snprintf(buf + k, n - k, "%s%d", l ? "/" : "", c->mult[l]);
    if (k > 0 && (size_t)k < n) k += snprintf(buf + k, n - k, ", res blocks ");
    for (int l = 0; l < c->levels && k > 0 && (size_t)k < n; l++) k += snprintf(buf + k, n - k, "%s%d", l ? "/" : "", c->nres[l]);
}

const char *g3d_sd_controlnet_describe(const g3d_sd_controlnet_config *c, char *buf, size_t n)
{
    char unet[512];
    g3d_sd_unet_describe(&c->net, unet, sizeof unet);
    /* the UNet's description without its output and prediction, which a ControlNet has not */
    char *cut = strstr(unet, ", epsilon prediction)");
    if (cut) strcpy(cut, ")");
    snprintf(buf, n, "ControlNet for SD %d.x (hint %d channels at %dx the latent; encoder: %s)", c->net.family, c->hint_ch,
             G3D_SD_HINT_FACTOR, unet);
    return buf;
}

g3d_status g3d_sd_controlnet_check(const g3d_sd_controlnet_config *cn, const char *path, const g3d_sd_unet_config *u)
{
    const g3d_sd_unet_config *c = &cn->net;
    int ok = c->model_ch == u->model_ch && c->levels == u->levels && c->context_dim == u->context_dim;
    for (int l = 0; ok && l < c->levels; l++) ok = c->mult[l] == u->mult[l] && c->nres[l] == u->nres[l];
    if (ok) return G3D_OK;
    char a[256], b[256];
    net_figures(c, a, sizeof a);
    net_figures(u, b, sizeof b);
    return G3D_ERR(G3D_ERR_MODEL, "%s: the ControlNet (%s) does not fit the UNet (%s)", path, a, b);
}

size_t g3d_sd_controlnet_residual_floats(const g3d_sd_controlnet *m, int h, int w)
{
    const g3d_sd_unet *u = &m->net;
    size_t n = 0;
    int l = 0;
    for (int i = 0; i < u->nin; i++) {
        l += i && u->in[i].has_down;   /* a downsampling block's output is at the next level */
        n += (size_t)(i ? u->in[i].cout : u->cfg.model_ch) * (h >> l) * (w >> l);
    }
    return n + (size_t)u->mid[2].cout * (h >> l) * (w >> l);
}

g3d_status g3d_sd_controlnet_forward(const g3d_sd_controlnet *cn, const float *x, int h, int w, float t, const float *ctx,
                                     int nctx, const float *hint, float scale, float *residuals, g3d_sd_trace_fn trace,
                                     void *trace_ctx)
{
    const g3d_sd_unet *m = &cn->net;
    fwd f;
    G3D_TRY(fwd_begin(m, &f, h, w, ctx, nctx, trace, trace_ctx));
    g3d_status rc = G3D_OK;
    /* the hint block: [hint_ch, 8h, 8w] down to [model_ch, h, w] */
    int hh = h * G3D_SD_HINT_FACTOR, hw = w * G3D_SD_HINT_FACTOR;
    const float *cur = hint;
    for (int k = 0; k < HINT_CONVS && rc == G3D_OK; k++) {
        int ho, wo;
        rc = g3d_nn_conv_out_size(&m->hint[k], hh, hw, &ho, &wo);
        float *o = rc == G3D_OK ? take(&f, (size_t)m->hint[k].cout * ho * wo) : NULL;
        if (rc == G3D_OK && !o) rc = NOMEM;
        g3d_nn_epi silu = {.act = G3D_ACT_SILU};
        if (rc == G3D_OK) rc = g3d_nn_conv_forward(&m->hint[k], cur, hh, hw, o, k < HINT_CONVS - 1 ? &silu : NULL);
        cur = o, hh = ho, hw = wo;
    }
    if (rc == G3D_OK && (hh != h || hw != w))
        rc = G3D_ERR(G3D_ERR_ARG, "the ControlNet's hint block gives %dx%d for a %dx%d latent", hw, hh, w, h);
    if (rc == G3D_OK) emit(&f, "guided_hint", 0, cur, m->cfg.model_ch, h, w);
    skips s = {.n = 0};
    float *mid;
    if (rc == G3D_OK) rc = encode(m, &f, x, h, w, t, cur, &s, &mid);
    float *r = residuals;
    for (int i = 0; i <= s.n && rc == G3D_OK; i++) {
        const g3d_nn_conv *z = i < s.n ? &m->zero[i] : &m->mid_out;
        size_t n = (size_t)s.c[i] * s.h[i] * s.w[i];
        rc = g3d_nn_conv_forward(z, s.x[i], s.h[i], s.w[i], r, NULL);
        if (rc != G3D_OK) break;
        emit(&f, "control%d", i, r, s.c[i], s.h[i], s.w[i]);
        for (size_t k = 0; k < n; k++) r[k] *= scale;
        r += n;
    }
    g3d_nn_arena_free(f.ar);
    return rc;
}
