/* MoGe-2: DINOv2 encoder, ConvStack neck and heads, scale MLP, and the focal/shift recovery
 * of infer(). The configuration is read from the checkpoint's model_config. */
#include "gen3d/moge.h"

#include "gen3d/dinov2.h"
#include "gen3d/nn.h"
#include "gen3d/resize.h"

#include <cjson/cJSON.h>
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PATCH 14
#define MAX_LEVELS 8
#define MAX_LAYERS 8
#define MAX_MLP 8
#define LOWRES 64   /* side of the subsample the focal/shift fit runs on */

typedef struct conv {
    float *w, *b;   /* w [cout, cin, k, k] (ConvTranspose: [cin, cout, k, k]) */
    int cin, cout, k;
} conv;

typedef enum resampler { RS_CONV_TRANSPOSE, RS_BILINEAR, RS_NEAREST } resampler;

/* The official ConvStack: per level an optional 1x1 input conv added to the running tensor,
 * residual blocks, an optional 1x1 output conv, then a x2 resampler to the next level. */
typedef struct stack {
    int nlev;
    int dim[MAX_LEVELS];    /* channels of the running tensor per level */
    int din[MAX_LEVELS];    /* input channels, -1 = identity input */
    int dout[MAX_LEVELS];   /* output channels, -1 = identity output */
    int nres[MAX_LEVELS], hidden[MAX_LEVELS];
    resampler rs[MAX_LEVELS];
    conv in[MAX_LEVELS], out[MAX_LEVELS], up[MAX_LEVELS], upconv[MAX_LEVELS];
    conv *res[MAX_LEVELS];  /* 2 * nres[l] convs: (layers.2, layers.5) per block */
} stack;

enum { HEAD_POINTS, HEAD_NORMAL, HEAD_MASK, NHEADS };
static const char *const HEAD_NAME[NHEADS] = {"points_head", "normal_head", "mask_head"};
static const int HEAD_CH[NHEADS] = {3, 3, 1};

typedef enum remap { REMAP_LINEAR, REMAP_SINH, REMAP_EXP, REMAP_SINH_EXP } remap;

struct g3d_moge {
    g3d_dinov2 *backbone;
    char backbone_name[64];
    int D, nlayers, layers[MAX_LAYERS], dim_out;
    conv proj[MAX_LAYERS];
    float mean[3], std[3];
    stack neck, head[NHEADS];
    int has_head[NHEADS];
    int nmlp, mlp_dims[MAX_MLP + 1];
    float *mlp_w[MAX_MLP], *mlp_b[MAX_MLP];
    remap remap;
    int tokens_min, tokens_max;
};

/* ---- loading ------------------------------------------------------------------------------ */

typedef struct loader {
    const g3d_ckpt *ck;
    const char *path;
} loader;

static g3d_status load_conv(const loader *l, conv *c, int transpose, int cout, int cin, int k, const char *fmt, ...)
{
    char base[160], name[192];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(base, sizeof base, fmt, ap);
    va_end(ap);
    c->cin = cin;
    c->cout = cout;
    c->k = k;
    int64_t ws[4] = {cout, cin, k, k}, bs[1] = {cout};
    if (transpose) {
        ws[0] = cin;
        ws[1] = cout;
    }
    snprintf(name, sizeof name, "%s.weight", base);
    G3D_TRY(g3d_ckpt_read_alloc(l->ck, name, 4, ws, &c->w));
    snprintf(name, sizeof name, "%s.bias", base);
    return g3d_ckpt_read_alloc(l->ck, name, 1, bs, &c->b);
}

static void free_conv(conv *c)
{
    free(c->w);
    free(c->b);
    c->w = c->b = NULL;
}

static void free_stack(stack *s)
{
    for (int l = 0; l < MAX_LEVELS; l++) {
        free_conv(&s->in[l]);
        free_conv(&s->out[l]);
        free_conv(&s->up[l]);
        free_conv(&s->upconv[l]);
        if (s->res[l])
            for (int j = 0; j < 2 * s->nres[l]; j++) free_conv(&s->res[l][j]);
        free(s->res[l]);
        s->res[l] = NULL;
    }
}

void g3d_moge_free(g3d_moge *m)
{
    if (!m) return;
    g3d_dinov2_free(m->backbone);
    for (int i = 0; i < MAX_LAYERS; i++) free_conv(&m->proj[i]);
    free_stack(&m->neck);
    for (int h = 0; h < NHEADS; h++) free_stack(&m->head[h]);
    for (int i = 0; i < MAX_MLP; i++) {
        free(m->mlp_w[i]);
        free(m->mlp_b[i]);
    }
    free(m);
}

/* Configuration values: `where` is the dotted key path used in messages. */
static g3d_status cfg_err(const loader *l, const char *where, const char *what)
{
    return G3D_ERR(G3D_ERR_MODEL, "%s: model_config.%s %s", l->path, where, what);
}

static int is_int(const cJSON *v) { return cJSON_IsNumber(v) && v->valuedouble == floor(v->valuedouble) && fabs(v->valuedouble) < 1e9; }

/* A list of n ints (null entries -> -1 when allow_null), or one value repeated n times. */
static g3d_status cfg_ints(const loader *l, const cJSON *obj, const char *key, const char *where, int n, int allow_null,
                           int def, int *out)
{
    char path[128];
    snprintf(path, sizeof path, "%s%s%s", where, *where ? "." : "", key);
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!v) {
        if (def == INT32_MIN) return cfg_err(l, path, "is missing");
        for (int i = 0; i < n; i++) out[i] = def;
        return G3D_OK;
    }
    if (cJSON_IsArray(v)) {
        if (cJSON_GetArraySize(v) != n) return cfg_err(l, path, "has the wrong number of entries");
        int i = 0;
        for (const cJSON *e = v->child; e; e = e->next, i++) {
            if (cJSON_IsNull(e) && allow_null) out[i] = -1;
            else if (is_int(e) && e->valuedouble > 0) out[i] = (int)e->valuedouble;
            else if (is_int(e) && e->valuedouble == 0 && !allow_null) out[i] = 0;
            else return cfg_err(l, path, "holds a value that is not a valid size");
        }
        return G3D_OK;
    }
    int x;
    if (cJSON_IsNull(v) && allow_null) x = -1;
    else if (is_int(v) && v->valuedouble >= 0) x = (int)v->valuedouble;
    else return cfg_err(l, path, "is not a size or a list of sizes");
    for (int i = 0; i < n; i++) out[i] = x;
    return G3D_OK;
}

/* A string key that must equal one of `allowed` (NULL-terminated); absent -> def. */
static g3d_status cfg_choice(const loader *l, const cJSON *obj, const char *key, const char *where, const char *def,
                             const char *const *allowed, int *idx)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(obj, key);
    const char *s = v ? cJSON_GetStringValue(v) : def;
    char path[128], what[160];
    snprintf(path, sizeof path, "%s%s%s", where, *where ? "." : "", key);
    if (!s) return cfg_err(l, path, "is not a string");
    for (int i = 0; allowed[i]; i++)
        if (!strcmp(s, allowed[i])) {
            *idx = i;
            return G3D_OK;
        }
    snprintf(what, sizeof what, "'%s' is not supported (supported: %s%s%s)", s, allowed[0], allowed[1] ? ", " : "",
             allowed[1] ? allowed[1] : "");
    return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: model_config.%s %s", l->path, path, what);
}

static g3d_status load_stack(const loader *l, const cJSON *cfg, const char *prefix, stack *s)
{
    if (!cJSON_IsObject(cfg)) return cfg_err(l, prefix, "is not a dictionary");
    const cJSON *dr = cJSON_GetObjectItemCaseSensitive(cfg, "dim_res_blocks");
    int n = cJSON_IsArray(dr) ? cJSON_GetArraySize(dr) : 0;
    if (n < 1 || n > MAX_LEVELS) {
        char path[96];
        snprintf(path, sizeof path, "%s.dim_res_blocks", prefix);
        return cfg_err(l, path, "must be a list of 1..8 sizes");
    }
    s->nlev = n;
    int mult[MAX_LEVELS], idx;
    G3D_TRY(cfg_ints(l, cfg, "dim_res_blocks", prefix, n, 0, INT32_MIN, s->dim));
    for (int i = 0; i < n; i++)
        if (s->dim[i] <= 0) return cfg_err(l, prefix, "has a zero dim_res_blocks entry");
    G3D_TRY(cfg_ints(l, cfg, "dim_in", prefix, n, 1, INT32_MIN, s->din));
    G3D_TRY(cfg_ints(l, cfg, "dim_out", prefix, n, 1, INT32_MIN, s->dout));
    G3D_TRY(cfg_ints(l, cfg, "num_res_blocks", prefix, n, 0, 1, s->nres));
    G3D_TRY(cfg_ints(l, cfg, "dim_times_res_block_hidden", prefix, 1, 0, 1, mult));
    static const char *const none[] = {"none", NULL}, *const relu[] = {"relu", NULL};
    G3D_TRY(cfg_choice(l, cfg, "res_block_in_norm", prefix, "layer_norm", none, &idx));
    G3D_TRY(cfg_choice(l, cfg, "res_block_hidden_norm", prefix, "group_norm", none, &idx));
    G3D_TRY(cfg_choice(l, cfg, "activation", prefix, "relu", relu, &idx));
    static const char *const kinds[] = {"conv_transpose", "bilinear", "nearest", NULL};
    const cJSON *rs = cJSON_GetObjectItemCaseSensitive(cfg, "resamplers");
    char where[96];
    snprintf(where, sizeof where, "%s.resamplers", prefix);
    for (int i = 0; i + 1 < n; i++) {
        const cJSON *e = cJSON_IsArray(rs) ? cJSON_GetArrayItem(rs, i) : rs;
        if (cJSON_IsArray(rs) && cJSON_GetArraySize(rs) != n - 1) return cfg_err(l, where, "has the wrong number of entries");
        const char *name = cJSON_GetStringValue(e);
        int k = -1;
        for (int j = 0; name && kinds[j]; j++)
            if (!strcmp(name, kinds[j])) k = j;
        if (k < 0)
            return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: model_config.%s: resampler '%s' is not supported (conv_transpose, "
                           "bilinear, nearest)", l->path, where, name ? name : "?");
        s->rs[i] = (resampler)k;
    }
    for (int i = 0; i < n; i++) {
        s->hidden[i] = mult[0] * s->dim[i];
        if (s->din[i] > 0) G3D_TRY(load_conv(l, &s->in[i], 0, s->dim[i], s->din[i], 1, "%s.input_blocks.%d", prefix, i));
        if (s->dout[i] > 0) G3D_TRY(load_conv(l, &s->out[i], 0, s->dout[i], s->dim[i], 1, "%s.output_blocks.%d", prefix, i));
        if (s->nres[i] > 64) return cfg_err(l, prefix, "has more than 64 residual blocks at one level");
        if (s->nres[i]) {
            s->res[i] = calloc((size_t)2 * s->nres[i], sizeof(conv));
            if (!s->res[i]) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        }
        for (int j = 0; j < s->nres[i]; j++) {
            G3D_TRY(load_conv(l, &s->res[i][2 * j], 0, s->hidden[i], s->dim[i], 3, "%s.res_blocks.%d.%d.layers.2", prefix, i, j));
            G3D_TRY(load_conv(l, &s->res[i][2 * j + 1], 0, s->dim[i], s->hidden[i], 3, "%s.res_blocks.%d.%d.layers.5", prefix, i, j));
        }
        if (i + 1 < n) {
            if (s->rs[i] == RS_CONV_TRANSPOSE) {
                G3D_TRY(load_conv(l, &s->up[i], 1, s->dim[i + 1], s->dim[i], 2, "%s.resamplers.%d.0", prefix, i));
                G3D_TRY(load_conv(l, &s->upconv[i], 0, s->dim[i + 1], s->dim[i + 1], 3, "%s.resamplers.%d.1", prefix, i));
            } else {
                G3D_TRY(load_conv(l, &s->upconv[i], 0, s->dim[i + 1], s->dim[i], 3, "%s.resamplers.%d.1", prefix, i));
            }
        }
    }
    return G3D_OK;
}

/* Channels a stack emits at level i. */
static int stack_out_ch(const stack *s, int i) { return s->dout[i] > 0 ? s->dout[i] : s->dim[i]; }

/* Input channels a stack needs at level i given what is fed there (identity inputs keep it). */
static g3d_status check_inputs(const loader *l, const stack *s, const char *prefix, const int *fed)
{
    for (int i = 0; i < s->nlev; i++) {
        int need = s->din[i] > 0 ? s->din[i] : s->dim[i];
        if (fed[i] != need)
            return G3D_ERR(G3D_ERR_MODEL, "%s: model_config.%s.dim_in[%d] is %d but level %d carries %d channels", l->path,
                           prefix, i, need, i, fed[i]);
    }
    return G3D_OK;
}

static g3d_status load_encoder(const loader *l, const cJSON *enc, g3d_moge *m)
{
    if (!cJSON_IsObject(enc)) return cfg_err(l, "encoder", "is missing or not a dictionary");
    const char *bb = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(enc, "backbone"));
    if (!bb) return cfg_err(l, "encoder.backbone", "is missing or not a string");
    snprintf(m->backbone_name, sizeof m->backbone_name, "%s", bb);
    /* The official encoder builds the backbone by this name from DINOv2's hub functions; their
     * sizes are read from the tensors, but what the tensors do not show must be known: the
     * ViT-g builders use a SwiGLU MLP, and the *_reg builders add register tokens whose
     * position grid is interpolated with antialiasing. Neither is supported. */
    if (strncmp(bb, "dinov2_vit", 10) || !strncmp(bb, "dinov2_vitg", 11) || strstr(bb, "_reg"))
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: model_config.encoder.backbone '%s' is not supported (a DINOv2 ViT "
                       "without SwiGLU MLP or registers, such as dinov2_vits14, dinov2_vitb14, dinov2_vitl14)", l->path, bb);
    G3D_TRY(g3d_dinov2_load(l->ck, "encoder.backbone.", &m->backbone));
    m->D = g3d_dinov2_width(m->backbone);
    int depth = g3d_dinov2_depth(m->backbone);
    if (g3d_dinov2_patch(m->backbone) != PATCH)
        return G3D_ERR(G3D_ERR_MODEL, "%s: tensor encoder.backbone.patch_embed.proj.weight has %d-pixel patches; the MoGe "
                       "encoder works on %d-pixel patches", l->path, g3d_dinov2_patch(m->backbone), PATCH);
    const cJSON *il = cJSON_GetObjectItemCaseSensitive(enc, "intermediate_layers");
    if (is_int(il) && il->valuedouble >= 1 && il->valuedouble <= depth && il->valuedouble <= MAX_LAYERS) {
        /* an integer n means the last n blocks */
        m->nlayers = (int)il->valuedouble;
        for (int i = 0; i < m->nlayers; i++) m->layers[i] = depth - m->nlayers + i;
    } else if (cJSON_IsArray(il) && cJSON_GetArraySize(il) >= 1 && cJSON_GetArraySize(il) <= MAX_LAYERS) {
        m->nlayers = cJSON_GetArraySize(il);
        int i = 0;
        for (const cJSON *e = il->child; e; e = e->next, i++) {
            if (!is_int(e) || e->valuedouble < 0 || e->valuedouble >= depth || (i && e->valuedouble <= m->layers[i - 1]))
                return cfg_err(l, "encoder.intermediate_layers", "must hold increasing block indices below the depth");
            m->layers[i] = (int)e->valuedouble;
        }
    } else {
        return cfg_err(l, "encoder.intermediate_layers", "must be a block count or a list of 1..8 block indices");
    }
    G3D_TRY(cfg_ints(l, enc, "dim_out", "encoder", 1, 0, INT32_MIN, &m->dim_out));
    if (m->dim_out <= 0) return cfg_err(l, "encoder.dim_out", "must be positive");
    for (int i = 0; i < m->nlayers; i++)
        G3D_TRY(load_conv(l, &m->proj[i], 0, m->dim_out, m->D, 1, "encoder.output_projections.%d", i));
    /* The normalisation constants are buffers of the checkpoint (stored in its precision). */
    static const int64_t shape[4] = {1, 3, 1, 1};
    G3D_TRY(g3d_ckpt_read(l->ck, "encoder.image_mean", 4, shape, m->mean));
    G3D_TRY(g3d_ckpt_read(l->ck, "encoder.image_std", 4, shape, m->std));
    for (int c = 0; c < 3; c++)
        if (!isfinite(m->std[c]) || m->std[c] == 0 || !isfinite(m->mean[c]))
            return G3D_ERR(G3D_ERR_MODEL, "%s: tensor encoder.image_std or image_mean holds zero or non-finite values", l->path);
    return G3D_OK;
}

static g3d_status load_scale_head(const loader *l, const cJSON *cfg, g3d_moge *m)
{
    const cJSON *dims = cJSON_GetObjectItemCaseSensitive(cfg, "dims");
    int n = cJSON_IsArray(dims) ? cJSON_GetArraySize(dims) : 0;
    if (n < 2 || n > MAX_MLP + 1) return cfg_err(l, "scale_head.dims", "must be a list of 2..9 sizes");
    G3D_TRY(cfg_ints(l, cfg, "dims", "scale_head", n, 0, INT32_MIN, m->mlp_dims));
    if (m->mlp_dims[0] != m->D)
        return G3D_ERR(G3D_ERR_MODEL, "%s: model_config.scale_head.dims[0] is %d, the encoder width is %d", l->path,
                       m->mlp_dims[0], m->D);
    if (m->mlp_dims[n - 1] != 1) return cfg_err(l, "scale_head.dims", "must end with 1");
    m->nmlp = n - 1;
    for (int i = 0; i < m->nmlp; i++) {
        char name[64];
        int64_t ws[2] = {m->mlp_dims[i + 1], m->mlp_dims[i]}, bs[1] = {m->mlp_dims[i + 1]};
        /* Sequential(Linear, ReLU, Linear, ReLU, ..., Linear): Linear layers at even indices */
        snprintf(name, sizeof name, "scale_head.%d.weight", 2 * i);
        G3D_TRY(g3d_ckpt_read_alloc(l->ck, name, 2, ws, &m->mlp_w[i]));
        snprintf(name, sizeof name, "scale_head.%d.bias", 2 * i);
        G3D_TRY(g3d_ckpt_read_alloc(l->ck, name, 1, bs, &m->mlp_b[i]));
    }
    return G3D_OK;
}

static g3d_status load_all(const loader *l, const cJSON *cfg, g3d_moge *m)
{
    G3D_TRY(load_encoder(l, cJSON_GetObjectItemCaseSensitive(cfg, "encoder"), m));
    const cJSON *neck = cJSON_GetObjectItemCaseSensitive(cfg, "neck");
    if (!neck) return cfg_err(l, "neck", "is missing (a MoGe-1 checkpoint? only MoGe-2 is supported)");
    G3D_TRY(load_stack(l, neck, "neck", &m->neck));
    int fed[MAX_LEVELS];
    fed[0] = m->dim_out + 2;   /* features + view-plane UV */
    for (int i = 1; i < m->neck.nlev; i++) fed[i] = 2;
    G3D_TRY(check_inputs(l, &m->neck, "neck", fed));
    for (int i = 0; i < m->neck.nlev; i++) fed[i] = stack_out_ch(&m->neck, i);
    for (int h = 0; h < NHEADS; h++) {
        const cJSON *hc = cJSON_GetObjectItemCaseSensitive(cfg, HEAD_NAME[h]);
        if (!hc || cJSON_IsNull(hc)) continue;
        stack *s = &m->head[h];
        G3D_TRY(load_stack(l, hc, HEAD_NAME[h], s));
        if (s->nlev != m->neck.nlev)
            return G3D_ERR(G3D_ERR_MODEL, "%s: model_config.%s has %d levels, the neck %d", l->path, HEAD_NAME[h],
                           s->nlev, m->neck.nlev);
        G3D_TRY(check_inputs(l, s, HEAD_NAME[h], fed));
        if (s->dout[s->nlev - 1] != HEAD_CH[h])
            return G3D_ERR(G3D_ERR_MODEL, "%s: model_config.%s.dim_out must end with %d", l->path, HEAD_NAME[h], HEAD_CH[h]);
        m->has_head[h] = 1;
    }
    if (!m->has_head[HEAD_POINTS]) return cfg_err(l, "points_head", "is missing");
    const cJSON *sc = cJSON_GetObjectItemCaseSensitive(cfg, "scale_head");
    if (sc && !cJSON_IsNull(sc)) G3D_TRY(load_scale_head(l, sc, m));
    static const char *const remaps[] = {"linear", "sinh", "exp", "sinh_exp", NULL};
    int r;
    G3D_TRY(cfg_choice(l, cfg, "remap_output", "", "linear", remaps, &r));
    m->remap = (remap)r;
    int range[2];
    const cJSON *tr = cJSON_GetObjectItemCaseSensitive(cfg, "num_tokens_range");
    if (tr) {
        G3D_TRY(cfg_ints(l, cfg, "num_tokens_range", "", 2, 0, INT32_MIN, range));
    } else {
        range[0] = 1200;
        range[1] = 3600;
    }
    if (range[0] < 1 || range[1] < range[0]) return cfg_err(l, "num_tokens_range", "must be two increasing counts");
    m->tokens_min = range[0];
    m->tokens_max = range[1];
    return G3D_OK;
}

g3d_status g3d_moge_load(const g3d_ckpt *ck, g3d_moge **out)
{
    *out = NULL;
    loader l = {ck, g3d_ckpt_path(ck)};
    const cJSON *meta = g3d_ckpt_meta(ck);
    const cJSON *cfg = meta ? cJSON_GetObjectItemCaseSensitive(meta, "model_config") : NULL;
    if (cJSON_IsObject(cfg) && !g3d_ckpt_find(ck, "encoder.backbone.pos_embed") && g3d_ckpt_find(ck, "backbone.pos_embed"))
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: a MoGe-1 checkpoint (backbone.*, no encoder.backbone.*): only MoGe-2 is "
                       "supported", l.path);
    if (!cJSON_IsObject(cfg) || !g3d_ckpt_find(ck, "encoder.backbone.pos_embed"))
        return G3D_ERR(G3D_ERR_MODEL, "%s: not a MoGe checkpoint: %s is missing", l.path,
                       cJSON_IsObject(cfg) ? "tensor encoder.backbone.pos_embed" : "the 'model_config' dictionary");
    g3d_moge *m = calloc(1, sizeof *m);
    if (!m) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_status rc = load_all(&l, cfg, m);
    if (rc != G3D_OK) {
        g3d_moge_free(m);
        return rc;
    }
    *out = m;
    return G3D_OK;
}

g3d_status g3d_moge_load_file(const char *path, g3d_moge **out)
{
    g3d_ckpt *ck;
    *out = NULL;
    G3D_TRY(g3d_ckpt_open(path, &ck));
    g3d_status rc = g3d_moge_load(ck, out);
    g3d_ckpt_free(ck);
    return rc;
}

int g3d_moge_default_tokens(const g3d_moge *m) { return m->tokens_max; }
int g3d_moge_has_normal(const g3d_moge *m) { return m->has_head[HEAD_NORMAL]; }
int g3d_moge_has_mask(const g3d_moge *m) { return m->has_head[HEAD_MASK]; }
int g3d_moge_has_scale(const g3d_moge *m) { return m->nmlp > 0; }

const char *g3d_moge_describe(const g3d_moge *m, char *buf, size_t n)
{
    snprintf(buf, n, "MoGe-2 (%s, %d blocks, width %d; heads: points%s%s%s)", m->backbone_name,
             g3d_dinov2_depth(m->backbone), m->D, m->has_head[HEAD_NORMAL] ? ", normal" : "",
             m->has_head[HEAD_MASK] ? ", mask" : "", m->nmlp ? ", metric scale" : "");
    return buf;
}

/* ---- forward ------------------------------------------------------------------------------ */

static float *alloc_f(size_t n) { return malloc(sizeof(float) * (n ? n : 1)); }

#define NOMEM() G3D_ERR(G3D_ERR_NOMEM, "MoGe: out of memory")

/* x [c, h, w] -> y [c, h+2, w+2] with the border pixels repeated (padding_mode='replicate'). */
static void pad_replicate(const float *x, int c, int h, int w, float *y)
{
    int W = w + 2;
#pragma omp parallel for schedule(static)
    for (int ch = 0; ch < c; ch++)
        for (int r = 0; r < h + 2; r++) {
            int sr = r == 0 ? 0 : r > h ? h - 1 : r - 1;
            const float *src = x + ((size_t)ch * h + sr) * w;
            float *dst = y + ((size_t)ch * (h + 2) + r) * W;
            dst[0] = src[0];
            memcpy(dst + 1, src, sizeof(float) * (size_t)w);
            dst[w + 1] = src[w - 1];
        }
}

/* Work buffers reused through one forward pass: the full-resolution levels need tens of MB
 * per temporary, and fresh allocations of that size are new pages (faults, zeroing) every time. */
enum { SC_PAD, SC_A, SC_B, SC_R, SC_T, SC_COUNT };
typedef struct scratch {
    float *buf[SC_COUNT];
    size_t cap[SC_COUNT];
} scratch;

static float *scratch_get(scratch *sc, int slot, size_t n)
{
    if (sc->cap[slot] < n) {
        free(sc->buf[slot]);
        sc->buf[slot] = alloc_f(n);
        sc->cap[slot] = sc->buf[slot] ? n : 0;
    }
    return sc->buf[slot];
}

static void scratch_free(scratch *sc)
{
    for (int i = 0; i < SC_COUNT; i++) free(sc->buf[i]);
}

/* 3x3 convolution with replicate padding; y must not alias x. */
static g3d_status conv3_rep(const conv *c, const float *x, int h, int w, float *y, scratch *sc)
{
    float *p = scratch_get(sc, SC_PAD, (size_t)c->cin * (h + 2) * (w + 2));
    if (!p) return NOMEM();
    pad_replicate(x, c->cin, h, w, p);
    return g3d_nn_conv2d(p, c->cin, h + 2, w + 2, c->w, c->b, c->cout, 3, 1, 0, y);
}

static g3d_status conv1(const conv *c, const float *x, int h, int w, float *y)
{
    return g3d_nn_conv2d(x, c->cin, h, w, c->w, c->b, c->cout, 1, 1, 0, y);
}

/* x += conv(relu(conv(relu(x)))) */
static g3d_status res_block(const conv *c1, const conv *c2, float *x, int h, int w, scratch *sc)
{
    size_t plane = (size_t)h * w;
    float *a = scratch_get(sc, SC_A, (size_t)c1->cin * plane), *b = scratch_get(sc, SC_B, (size_t)c1->cout * plane);
    float *r = scratch_get(sc, SC_R, (size_t)c2->cout * plane);
    if (!a || !b || !r) return NOMEM();
    memcpy(a, x, sizeof(float) * c1->cin * plane);
    g3d_nn_relu(a, (size_t)c1->cin * plane);
    G3D_TRY(conv3_rep(c1, a, h, w, b, sc));
    g3d_nn_relu(b, (size_t)c1->cout * plane);
    G3D_TRY(conv3_rep(c2, b, h, w, r, sc));
    g3d_nn_add(x, r, (size_t)c2->cout * plane);
    return G3D_OK;
}

/* Per-plane resize of [c, sh, sw] into [c, dh, dw]. */
static g3d_status resize_planes(const float *src, int c, int sh, int sw, float *dst, int dh, int dw, g3d_resize_mode mode)
{
    for (int i = 0; i < c; i++)
        G3D_TRY(g3d_resize_buffer(src + (size_t)i * sh * sw, sw, sh, 1, dst + (size_t)i * dh * dw, dw, dh, mode));
    return G3D_OK;
}

/* x [dim[l], h, w] -> *y [dim[l+1], 2h, 2w] (new buffer). */
static g3d_status resample(const stack *s, int l, const float *x, int h, int w, float **y, scratch *sc)
{
    int c = s->dim[l];
    size_t n2 = (size_t)4 * h * w;
    float *t = scratch_get(sc, SC_T, (size_t)(s->rs[l] == RS_CONV_TRANSPOSE ? s->dim[l + 1] : c) * n2);
    *y = alloc_f((size_t)s->dim[l + 1] * n2);
    g3d_status rc = t && *y ? G3D_OK : NOMEM();
    if (rc == G3D_OK) {
        if (s->rs[l] == RS_CONV_TRANSPOSE) {
            rc = g3d_nn_conv_transpose2d(x, c, h, w, s->up[l].w, s->up[l].b, s->dim[l + 1], 2, t);
        } else if (s->rs[l] == RS_BILINEAR) {
            rc = resize_planes(x, c, h, w, t, 2 * h, 2 * w, G3D_RESIZE_BILINEAR);
        } else {
            for (int ch = 0; ch < c; ch++)
                for (int r = 0; r < 2 * h; r++)
                    for (int q = 0; q < 2 * w; q++)
                        t[((size_t)ch * 2 * h + r) * 2 * w + q] = x[((size_t)ch * h + r / 2) * w + q / 2];
        }
    }
    if (rc == G3D_OK) rc = conv3_rep(&s->upconv[l], t, 2 * h, 2 * w, *y, sc);
    if (rc != G3D_OK) {
        free(*y);
        *y = NULL;
    }
    return rc;
}

/* Runs a ConvStack. in[l] is level l's input ([fed channels, rows << l, cols << l]) or NULL.
 * Level outputs go to outs[l] (new buffers) for every level when `all`, else only the last. */
static g3d_status stack_forward(const stack *s, float *const *in, int rows, int cols, int all, float **outs, scratch *sc)
{
    float *x = NULL;
    g3d_status rc = G3D_OK;
    for (int l = 0; l < s->nlev; l++) outs[l] = NULL;
    for (int l = 0; l < s->nlev && rc == G3D_OK; l++) {
        int h = rows << l, w = cols << l;
        size_t plane = (size_t)h * w, n = (size_t)s->dim[l] * plane;
        if (in[l]) {
            float *f = in[l];
            if (s->din[l] > 0) {
                if (!(f = alloc_f(n))) {
                    rc = NOMEM();
                    break;
                }
                rc = conv1(&s->in[l], in[l], h, w, f);
            }
            if (rc == G3D_OK && !x) {
                x = f == in[l] ? alloc_f(n) : f;
                if (!x) rc = NOMEM();
                else if (f == in[l]) memcpy(x, f, sizeof(float) * n);
            } else if (rc == G3D_OK) {
                g3d_nn_add(x, f, n);
            }
            if (f != in[l] && f != x) free(f);
        } else if (!x) {
            rc = G3D_ERR(G3D_ERR_INTERNAL, "MoGe: ConvStack level %d has no input", l);
        }
        for (int j = 0; j < s->nres[l] && rc == G3D_OK; j++) rc = res_block(&s->res[l][2 * j], &s->res[l][2 * j + 1], x, h, w, sc);
        if (rc == G3D_OK && (all || l == s->nlev - 1)) {
            int oc = stack_out_ch(s, l);
            if (!(outs[l] = alloc_f((size_t)oc * plane))) rc = NOMEM();
            else if (s->dout[l] > 0) rc = conv1(&s->out[l], x, h, w, outs[l]);
            else memcpy(outs[l], x, sizeof(float) * n);
        }
        if (rc == G3D_OK && l + 1 < s->nlev) {
            float *y;
            rc = resample(s, l, x, h, w, &y, sc);
            free(x);
            x = rc == G3D_OK ? y : NULL;
        }
    }
    free(x);
    if (rc != G3D_OK)
        for (int l = 0; l < s->nlev; l++) {
            free(outs[l]);
            outs[l] = NULL;
        }
    return rc;
}

/* torch.linspace in float32: the first half counts up from start, the second down from end. */
static void linspace_f(float start, float end, int n, float *out)
{
    if (n == 1) {
        out[0] = start;
        return;
    }
    float step = (end - start) / (float)(n - 1);
    for (int i = 0; i < n; i++) out[i] = i < n / 2 ? start + step * (float)i : end - step * (float)(n - 1 - i);
}

/* The view-plane UV grid [2, h, w] of the official normalized_view_plane_uv: u spans
 * +-(a / sqrt(1 + a^2)) (w - 1) / w, v spans +-(1 / sqrt(1 + a^2)) (h - 1) / h. */
static g3d_status view_plane_uv(int w, int h, double aspect, float *uv)
{
    double sx = aspect / sqrt(1 + aspect * aspect), sy = 1 / sqrt(1 + aspect * aspect);
    float *u = alloc_f((size_t)w), *v = alloc_f((size_t)h);
    if (!u || !v) {
        free(u);
        free(v);
        return NOMEM();
    }
    linspace_f((float)(-sx * (w - 1) / w), (float)(sx * (w - 1) / w), w, u);
    linspace_f((float)(-sy * (h - 1) / h), (float)(sy * (h - 1) / h), h, v);
    size_t plane = (size_t)w * h;
    for (int r = 0; r < h; r++)
        for (int q = 0; q < w; q++) {
            uv[(size_t)r * w + q] = u[q];
            uv[plane + (size_t)r * w + q] = v[r];
        }
    free(u);
    free(v);
    return G3D_OK;
}

void g3d_moge_trace_free(g3d_moge_trace *t)
{
    if (!t) return;
    free(t->image14);
    free(t->features);
    free(t->cls);
    t->image14 = t->features = t->cls = NULL;
    for (int i = 0; i < 5; i++) {
        free(t->neck[i]);
        t->neck[i] = NULL;
    }
}

void g3d_moge_output_free(g3d_moge_output *o)
{
    if (!o) return;
    free(o->points);
    free(o->mask);
    free(o->normal);
    memset(o, 0, sizeof *o);
}

static float *dup_f(const float *x, size_t n)
{
    float *y = alloc_f(n);
    if (y) memcpy(y, x, sizeof(float) * n);
    return y;
}

/* Encoder: resize + normalise, backbone, summed projections [dim_out, rows*cols] and the
 * class token of the last intermediate layer [D]. */
static g3d_status encode(const g3d_moge *m, const float *rgb, int w, int h, int rows, int cols, float *feat, float *cls,
                         g3d_moge_trace *trace)
{
    int H = rows * PATCH, W = cols * PATCH, np = rows * cols, D = m->D;
    size_t plane = (size_t)W * H;
    float *rs = alloc_f(3 * plane), *x = alloc_f(3 * plane), *tok = alloc_f((size_t)np * D), *p = alloc_f((size_t)m->dim_out * np);
    float *feats[MAX_LAYERS] = {0}, *clss[MAX_LAYERS] = {0};
    g3d_status rc = rs && x && tok && p ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "MoGe: out of memory at %dx%d", W, H);
    if (rc == G3D_OK) rc = g3d_resize_buffer(rgb, w, h, 3, rs, W, H, G3D_RESIZE_BILINEAR_AA);
    if (rc == G3D_OK) {
        for (size_t i = 0; i < plane; i++)
            for (int c = 0; c < 3; c++) x[c * plane + i] = (rs[i * 3 + c] - m->mean[c]) / m->std[c];
        if (trace && !(trace->image14 = dup_f(x, 3 * plane))) rc = NOMEM();
    }
    if (rc == G3D_OK) rc = g3d_dinov2_forward(m->backbone, x, H, W, m->layers, m->nlayers, feats, clss, NULL);
    for (int i = 0; i < m->nlayers && rc == G3D_OK; i++) {
        for (int t = 0; t < np; t++)
            for (int c = 0; c < D; c++) tok[(size_t)c * np + t] = feats[i][(size_t)t * D + c];
        rc = conv1(&m->proj[i], tok, rows, cols, i ? p : feat);
        if (rc == G3D_OK && i) g3d_nn_add(feat, p, (size_t)m->dim_out * np);
    }
    if (rc == G3D_OK) memcpy(cls, clss[m->nlayers - 1], sizeof(float) * D);
    for (int i = 0; i < m->nlayers; i++) {
        free(feats[i]);
        free(clss[i]);
    }
    free(rs);
    free(x);
    free(tok);
    free(p);
    return rc;
}

/* levels: the number of neck levels; the finest runs at 2^(levels-1) times the token grid. */
static g3d_status token_grid(int w, int h, int num_tokens, int levels, int *rows, int *cols)
{
    if (w < 1 || h < 1 || w > G3D_MAX_IMAGE_SIDE || h > G3D_MAX_IMAGE_SIDE)
        return G3D_ERR(G3D_ERR_ARG, "MoGe: image size %dx%d is outside 1..%d", w, h, G3D_MAX_IMAGE_SIDE);
    double a = (double)w / h;
    /* Python's round(): half to even, as nearbyint in the default rounding mode */
    double r = nearbyint(sqrt(num_tokens / a)), c = nearbyint(sqrt(num_tokens * a));
    int up = 1 << (levels - 1), f = up > PATCH ? up : PATCH;
    if (r < 1 || c < 1 || r * f > G3D_MAX_IMAGE_SIDE || c * f > G3D_MAX_IMAGE_SIDE || num_tokens > G3D_MOGE_MAX_TOKENS)
        return G3D_ERR(G3D_ERR_ARG, "MoGe: %d tokens on a %dx%d image give a %.0fx%.0f token grid (each side must be "
                       "1..%d, at most %d tokens)", num_tokens, w, h, c, r, G3D_MAX_IMAGE_SIDE / f, G3D_MOGE_MAX_TOKENS);
    *rows = (int)r;
    *cols = (int)c;
    return G3D_OK;
}

g3d_status g3d_moge_forward(const g3d_moge *m, const float *rgb, int w, int h, int num_tokens, g3d_moge_output *out,
                            g3d_moge_trace *trace)
{
    memset(out, 0, sizeof *out);
    if (trace && !trace->want) trace = NULL;
    if (trace) {
        memset(trace, 0, sizeof *trace);
        trace->want = 1;
    }
    if (num_tokens <= 0) num_tokens = m->tokens_max;
    int rows = 0, cols = 0;
    G3D_TRY(token_grid(w, h, num_tokens, m->neck.nlev, &rows, &cols));
    int nlev = m->neck.nlev, np = rows * cols;
    double aspect = (double)w / h;
    float *level_in[MAX_LEVELS] = {0}, *neck_out[MAX_LEVELS] = {0}, *head_out[NHEADS][MAX_LEVELS] = {{0}};
    float *cls = alloc_f((size_t)m->D);
    float *feat = NULL;
    g3d_status rc = cls ? G3D_OK : NOMEM();
    /* level 0 input: [features; uv], level l > 0: uv at (rows << l, cols << l) */
    for (int l = 0; l < nlev && rc == G3D_OK; l++) {
        size_t plane = ((size_t)rows << l) * ((size_t)cols << l);
        int c0 = l ? 0 : m->dim_out;
        if (!(level_in[l] = alloc_f((size_t)(c0 + 2) * plane))) rc = NOMEM();
        else rc = view_plane_uv(cols << l, rows << l, aspect, level_in[l] + (size_t)c0 * plane);
    }
    if (rc == G3D_OK) {
        if (trace) {
            trace->rows = rows;
            trace->cols = cols;
        }
        feat = level_in[0];
        rc = encode(m, rgb, w, h, rows, cols, feat, cls, trace);
    }
    if (rc == G3D_OK && trace) {
        trace->features_c = m->dim_out;
        if (!(trace->features = dup_f(feat, (size_t)m->dim_out * np)) || !(trace->cls = dup_f(cls, (size_t)m->D)))
            rc = NOMEM();
    }
    scratch sc;
    memset(&sc, 0, sizeof sc);
    if (rc == G3D_OK) rc = stack_forward(&m->neck, level_in, rows, cols, 1, neck_out, &sc);
    for (int hd = 0; hd < NHEADS && rc == G3D_OK; hd++)
        if (m->has_head[hd]) rc = stack_forward(&m->head[hd], neck_out, rows, cols, 0, head_out[hd], &sc);
    scratch_free(&sc);

    /* Heads -> image size (bilinear, no antialiasing), channels last, output remaps. */
    int lh = rows << (nlev - 1), lw = cols << (nlev - 1);
    size_t npx = (size_t)w * h;
    float *planes = NULL;
    if (rc == G3D_OK && !(planes = alloc_f(3 * npx))) rc = NOMEM();
    float **dst[NHEADS] = {&out->points, &out->normal, &out->mask};
    for (int hd = 0; hd < NHEADS && rc == G3D_OK; hd++) {
        if (!m->has_head[hd]) continue;
        int c = HEAD_CH[hd];
        rc = resize_planes(head_out[hd][nlev - 1], c, lh, lw, planes, h, w, G3D_RESIZE_BILINEAR);
        if (rc == G3D_OK && !(*dst[hd] = alloc_f((size_t)c * npx))) rc = NOMEM();
        if (rc != G3D_OK) break;
        float *o = *dst[hd];
        for (size_t i = 0; i < npx; i++)
            for (int k = 0; k < c; k++) o[i * c + k] = planes[k * npx + i];
    }
    if (rc == G3D_OK) {
        float *p = out->points;
        for (size_t i = 0; i < npx; i++) {
            float *q = p + 3 * i;
            switch (m->remap) {
            case REMAP_LINEAR: break;
            case REMAP_SINH: for (int k = 0; k < 3; k++) q[k] = sinhf(q[k]); break;
            case REMAP_EXP: q[2] = expf(q[2]); q[0] *= q[2]; q[1] *= q[2]; break;
            case REMAP_SINH_EXP: q[0] = sinhf(q[0]); q[1] = sinhf(q[1]); q[2] = expf(q[2]); break;
            }
        }
        if (out->normal)
            for (size_t i = 0; i < npx; i++) {
                float *q = out->normal + 3 * i;
                /* F.normalize: divide by max(|n|, 1e-12) */
                float len = sqrtf(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
                len = len > 1e-12f ? len : 1e-12f;
                for (int k = 0; k < 3; k++) q[k] /= len;
            }
        if (out->mask)
            for (size_t i = 0; i < npx; i++) out->mask[i] = 1.0f / (1.0f + expf(-out->mask[i]));
        if (m->nmlp) {
            float *a = cls, *b = NULL;
            for (int i = 0; i < m->nmlp && rc == G3D_OK; i++) {
                if (!(b = alloc_f((size_t)m->mlp_dims[i + 1]))) {
                    rc = NOMEM();
                    break;
                }
                g3d_nn_linear(a, 1, m->mlp_dims[i], m->mlp_w[i], m->mlp_b[i], m->mlp_dims[i + 1], b);
                if (i + 1 < m->nmlp) g3d_nn_relu(b, (size_t)m->mlp_dims[i + 1]);
                if (a != cls) free(a);
                a = b;
            }
            if (rc == G3D_OK) out->metric_scale = expf(a[0]);
            if (a != cls) free(a);
        }
        out->w = w;
        out->h = h;
    }
    if (rc == G3D_OK && trace)
        for (int l = 0; l < nlev && l < 5; l++) {
            trace->neck[l] = neck_out[l];
            trace->neck_c[l] = stack_out_ch(&m->neck, l);
            neck_out[l] = NULL;
        }
    for (int l = 0; l < MAX_LEVELS; l++) {
        free(level_in[l]);
        free(neck_out[l]);
        for (int hd = 0; hd < NHEADS; hd++) free(head_out[hd][l]);
    }
    free(planes);
    free(cls);
    if (rc != G3D_OK) {
        g3d_moge_output_free(out);
        g3d_moge_trace_free(trace);
    }
    return rc;
}

/* ---- focal / shift recovery ---------------------------------------------------------------- */

/* Residuals of the fit for shift x: r[2i], r[2i+1] = f * xy_i / (z_i + x) - uv_i, with f the
 * closed-form best focal for that shift (fit_focal) or the given one. */
typedef struct fit {
    int n;
    const float *xyz;   /* [n, 3] */
    const float *uv;    /* [n, 2] */
    int fit_focal;
    double focal;
} fit;

static void residuals(const fit *f, double shift, double *r)
{
    double focal = f->focal;
    if (f->fit_focal) {
        double num = 0, den = 0;
        for (int i = 0; i < f->n; i++) {
            double z = f->xyz[3 * i + 2] + shift, px = f->xyz[3 * i] / z, py = f->xyz[3 * i + 1] / z;
            num += px * f->uv[2 * i] + py * f->uv[2 * i + 1];
            den += px * px + py * py;
        }
        focal = num / den;
    }
    for (int i = 0; i < f->n; i++) {
        double z = f->xyz[3 * i + 2] + shift;
        r[2 * i] = focal * (f->xyz[3 * i] / z) - f->uv[2 * i];
        r[2 * i + 1] = focal * (f->xyz[3 * i + 1] / z) - f->uv[2 * i + 1];
    }
}

static double norm2(const double *v, int n)
{
    double s = 0;
    for (int i = 0; i < n; i++) s += v[i] * v[i];
    return sqrt(s);
}

/* Levenberg-Marquardt for one unknown starting at 0, following MINPACK's lmdif step for step
 * (forward-difference Jacobian, trust region with diag = 1, factor 100, xtol = gtol = 1e-8,
 * at most 200 evaluations), which is what the official code calls with ftol = 1e-3: the
 * early stop it allows makes the exact sequence of steps part of the result. m residuals;
 * work holds 2m doubles. */
static double lm_shift(const fit *f, int m, double ftol, double *work)
{
    const double xtol = 1e-8, gtol = 1e-8, epsmch = DBL_EPSILON, dwarf = DBL_MIN;
    const int maxfev = 200;
    double *fvec = work, *wa = work + m;
    double x = 0, par = 0, delta = 0, xnorm = 0;
    residuals(f, x, fvec);
    int nfev = 1, iter = 1;
    double fnorm = norm2(fvec, m);
    for (;;) {
        double h = sqrt(epsmch) * fabs(x);
        if (h == 0) h = sqrt(epsmch);
        residuals(f, x + h, wa);
        nfev++;
        double jj = 0, jf = 0;
        for (int i = 0; i < m; i++) {
            double J = (wa[i] - fvec[i]) / h;
            jj += J * J;
            jf += J * fvec[i];
        }
        double r = sqrt(jj);   /* |R| of the one-column QR factorisation */
        if (iter == 1) {
            xnorm = fabs(x);
            delta = 100 * xnorm;
            if (delta == 0) delta = 100;
        }
        double gnorm = fnorm != 0 && r != 0 ? fabs(jf / fnorm / r) : 0;
        if (gnorm <= gtol) return x;
        double qtb = jf / r;   /* first component of Q^T f */
        for (;;) {
            /* lmpar: the step s(par) = qtb r / (r^2 + par) with |s| close to delta. */
            double s = qtb / r, dxnorm = fabs(s), fp = dxnorm - delta;
            if (fp <= 0.1 * delta) {
                par = 0;
            } else {
                double parl = (fp / delta) * r * r;   /* ((fp / delta) / |1/r|) / |1/r| */
                double gn = fabs(r * qtb), paru = gn / delta;
                if (paru == 0) paru = dwarf / fmin(delta, 0.1);
                par = fmax(par, parl);
                par = fmin(par, paru);
                if (par == 0) par = gn / dxnorm;
                for (int it = 1;; it++) {
                    if (par == 0) par = fmax(dwarf, 0.001 * paru);
                    double sdiag = sqrt(r * r + par);
                    s = r * qtb / (r * r + par);
                    dxnorm = fabs(s);
                    double prev = fp;
                    fp = dxnorm - delta;
                    if (fabs(fp) <= 0.1 * delta || (parl == 0 && fp <= prev && prev < 0) || it == 10) break;
                    double wn = 1 / sdiag;   /* |(s / |s|) / sdiag| */
                    double parc = (fp / delta) / wn / wn;
                    if (fp > 0) parl = fmax(parl, par);
                    if (fp < 0) paru = fmin(paru, par);
                    par = fmax(parl, par + parc);
                }
            }
            double p = -s, x1 = x + p, pnorm = fabs(p);
            if (iter == 1) delta = fmin(delta, pnorm);
            residuals(f, x1, wa);
            nfev++;
            double fnorm1 = norm2(wa, m);
            double actred = 0.1 * fnorm1 < fnorm ? 1 - (fnorm1 / fnorm) * (fnorm1 / fnorm) : -1;
            double t1 = r * pnorm / fnorm, t2 = sqrt(par) * pnorm / fnorm;
            double prered = t1 * t1 + t2 * t2 / 0.5, dirder = -(t1 * t1 + t2 * t2);
            double ratio = prered != 0 ? actred / prered : 0;
            if (ratio <= 0.25) {
                double t = actred >= 0 ? 0.5 : 0.5 * dirder / (dirder + 0.5 * actred);
                if (0.1 * fnorm1 >= fnorm || t < 0.1) t = 0.1;
                delta = t * fmin(delta, pnorm / 0.1);
                par /= t;
            } else if (par == 0 || ratio >= 0.75) {
                delta = pnorm / 0.5;
                par *= 0.5;
            }
            if (ratio >= 1e-4) {
                x = x1;
                memcpy(fvec, wa, sizeof(double) * (size_t)m);
                xnorm = fabs(x);
                fnorm = fnorm1;
                iter++;
            }
            if (fabs(actred) <= ftol && prered <= ftol && 0.5 * ratio <= 1) return x;
            if (delta <= xtol * xnorm) return x;
            if (nfev >= maxfev) return x;
            if ((fabs(actred) <= epsmch && prered <= epsmch && 0.5 * ratio <= 1) || delta <= epsmch * xnorm ||
                gnorm <= epsmch)
                return x;
            if (ratio >= 1e-4) break;
        }
    }
}

/* PyTorch's nearest index for resizing `in` samples to `out` (scale in float). */
static int nearest_src(int o, int in, int out)
{
    if (in == out) return o;
    int i = (int)floorf((float)o * ((float)in / (float)out));
    return i < in - 1 ? i : in - 1;
}

/* The official recover_focal_shift on points [h, w, 3] and mask [h, w] (NULL = all valid).
 * focal_in > 0 fixes the focal. */
static g3d_status recover_focal_shift(const float *points, const uint8_t *mask, int w, int h, double focal_in,
                                      float *focal_out, float *shift_out)
{
    int nmax = LOWRES * LOWRES;
    float *xyz = alloc_f((size_t)3 * nmax), *uv = alloc_f((size_t)2 * nmax), *uvx = alloc_f((size_t)w + h);
    double *work = malloc(sizeof(double) * 4 * (size_t)nmax);
    if (!xyz || !uv || !uvx || !work) {
        free(xyz); free(uv); free(uvx); free(work);
        return NOMEM();
    }
    double a = (double)w / h, sx = a / sqrt(1 + a * a), sy = 1 / sqrt(1 + a * a);
    float *uu = uvx, *vv = uvx + w;
    linspace_f((float)(-sx * (w - 1) / w), (float)(sx * (w - 1) / w), w, uu);
    linspace_f((float)(-sy * (h - 1) / h), (float)(sy * (h - 1) / h), h, vv);
    int n = 0;
    for (int i = 0; i < LOWRES; i++) {
        int r = nearest_src(i, h, LOWRES);
        for (int j = 0; j < LOWRES; j++) {
            int c = nearest_src(j, w, LOWRES);
            size_t k = (size_t)r * w + c;
            if (mask && !mask[k]) continue;
            memcpy(xyz + 3 * n, points + 3 * k, sizeof(float) * 3);
            uv[2 * n] = uu[c];
            uv[2 * n + 1] = vv[r];
            n++;
        }
    }
    if (n < 2) {
        *focal_out = focal_in > 0 ? (float)focal_in : 1.0f;
        *shift_out = 0;
    } else {
        fit f = {n, xyz, uv, focal_in <= 0, focal_in};
        float shift = (float)lm_shift(&f, 2 * n, 1e-3, work);
        double focal = focal_in;
        if (focal_in <= 0) {
            /* the official code re-evaluates the focal in float32 at the float32 shift */
            double num = 0, den = 0;
            for (int i = 0; i < n; i++) {
                float z = xyz[3 * i + 2] + shift, px = xyz[3 * i] / z, py = xyz[3 * i + 1] / z;
                num += (double)(px * uv[2 * i]) + (double)(py * uv[2 * i + 1]);
                den += (double)(px * px) + (double)(py * py);
            }
            focal = num / den;
        }
        *focal_out = (float)focal;
        *shift_out = shift;
    }
    free(xyz); free(uv); free(uvx); free(work);
    return G3D_OK;
}

void g3d_moge_result_free(g3d_moge_result *r)
{
    if (!r) return;
    free(r->points);
    free(r->depth);
    free(r->mask);
    free(r->normal);
    memset(r, 0, sizeof *r);
}

g3d_status g3d_moge_infer(const g3d_moge *m, const float *rgb, int w, int h, int num_tokens, double fov_x_deg,
                          g3d_moge_result *out)
{
    memset(out, 0, sizeof *out);
    if (!(fov_x_deg < 180)) return G3D_ERR(G3D_ERR_ARG, "MoGe: horizontal field of view %g is not below 180 degrees", fov_x_deg);
    g3d_moge_output o;
    G3D_TRY(g3d_moge_forward(m, rgb, w, h, num_tokens, &o, NULL));
    size_t npx = (size_t)w * h;
    double a = (double)w / h, diag = sqrt(1 + a * a);
    g3d_status rc = G3D_OK;
    out->w = w;
    out->h = h;
    out->mask = malloc(npx);
    out->depth = alloc_f(npx);
    if (!out->mask || !out->depth) rc = NOMEM();
    if (rc == G3D_OK) {
        for (size_t i = 0; i < npx; i++) out->mask[i] = o.mask ? o.mask[i] > 0.5f : 1;
        /* the official code holds a given focal in float32 */
        double focal_in = fov_x_deg > 0 ? (double)(float)(a / diag / tan(fov_x_deg * M_PI / 360.0)) : 0;
        rc = recover_focal_shift(o.points, o.mask ? out->mask : NULL, w, h, focal_in, &out->focal, &out->shift);
    }
    if (rc == G3D_OK) {
        float fx = (float)(out->focal / 2.0 * diag / a), fy = (float)(out->focal / 2.0 * diag);
        float K[9] = {fx, 0, 0.5f, 0, fy, 0.5f, 0, 0, 1};
        memcpy(out->intrinsics, K, sizeof K);
        float s = o.metric_scale > 0 ? o.metric_scale : 1.0f;
        out->metric_scale = s;
        float *u = NULL, *v = NULL;
        if (!(u = alloc_f((size_t)w)) || !(v = alloc_f((size_t)h))) rc = NOMEM();
        if (rc == G3D_OK) {
            /* pixel centres of the unit image, then x = (u - cx) / fx * z (force_projection) */
            linspace_f(0.5f / w, 1.0f - 0.5f / w, w, u);
            linspace_f(0.5f / h, 1.0f - 0.5f / h, h, v);
            float *pts = o.points;
            for (int r = 0; r < h; r++)
                for (int q = 0; q < w; q++) {
                    size_t i = (size_t)r * w + q;
                    float z = pts[3 * i + 2] + out->shift;
                    if (!(z > 0)) out->mask[i] = 0;
                    float d = z * s;
                    if (out->mask[i]) {
                        out->depth[i] = d;
                        pts[3 * i] = (u[q] - 0.5f) / fx * d;
                        pts[3 * i + 1] = (v[r] - 0.5f) / fy * d;
                        pts[3 * i + 2] = d;
                    } else {
                        out->depth[i] = INFINITY;
                        pts[3 * i] = pts[3 * i + 1] = pts[3 * i + 2] = INFINITY;
                        if (o.normal) o.normal[3 * i] = o.normal[3 * i + 1] = o.normal[3 * i + 2] = 0;
                    }
                }
            out->points = o.points;
            out->normal = o.normal;
            o.points = o.normal = NULL;
        }
        free(u);
        free(v);
    }
    g3d_moge_output_free(&o);
    if (rc != G3D_OK) g3d_moge_result_free(out);
    return rc;
}

g3d_intrinsics g3d_moge_intrinsics_pixels(const g3d_moge_result *r)
{
    return g3d_intrinsics_make((double)r->intrinsics[0] * r->w, (double)r->intrinsics[4] * r->h,
                               (double)r->intrinsics[2] * r->w - 0.5, (double)r->intrinsics[5] * r->h - 0.5, r->w, r->h);
}
