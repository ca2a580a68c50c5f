/* MoGe-2: the configuration read from the checkpoint's model_config, and the weights it
 * names (the network that runs them: moge_net.c). */
#include "moge_int.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const HEAD_NAME[NHEADS] = {"points_head", "normal_head", "mask_head"};

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
    G3D_TRY(g3d_ckpt_read_alloc(l->ck, name, 1, bs, &c->b));
    /* the official convolutions: 3x3 with replicate padding, 1x1, and 2x2 stride-2 transposed;
     * preparing gives the 3x3 ones Winograd and the transposed one its phase kernels */
    c->nc = g3d_nn_conv_make(cin, cout, k, transpose ? k : 1, k == 3, c->w, c->b);
    c->nc.transposed = transpose;
    if (k == 3) c->nc.pad_mode = G3D_PAD_REPLICATE;
    return g3d_nn_conv_prepare(&c->nc);
}

static void free_conv(conv *c)
{
    g3d_nn_conv_release(&c->nc);
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
