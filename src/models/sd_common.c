/* Tensor look-up and the residual block shared by the Stable Diffusion UNet and VAE. */
#include "sd_int.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* rest with its first component renamed by the table (from -> to), into buf; rest itself when
 * no entry matches. */
static const char *rename_leaf(const char *rest, const char *const (*map)[2], size_t n_map, char *buf, size_t n)
{
    for (size_t i = 0; i < n_map; i++) {
        size_t k = strlen(map[i][0]);
        if (!strncmp(rest, map[i][0], k)) {
            snprintf(buf, n, "%s%s", map[i][1], rest + k);
            return buf;
        }
    }
    return rest;
}

/* A res block's leaves in diffusers' spelling (the UNet's in_layers.0 ..., the VAE's nin_shortcut). */
static const char *const RES_LEAVES[][2] = {{"in_layers.0.", "norm1."},          {"in_layers.2.", "conv1."},
                                            {"emb_layers.1.", "time_emb_proj."}, {"out_layers.0.", "norm2."},
                                            {"out_layers.3.", "conv2."},         {"skip_connection.", "conv_shortcut."},
                                            {"nin_shortcut.", "conv_shortcut."}};
/* The VAE's AttnBlock leaves in diffusers' current spelling. */
static const char *const ATTN_LEAVES[][2] = {{"norm.", "group_norm."}, {"q.", "to_q."}, {"k.", "to_k."}, {"v.", "to_v."},
                                             {"proj_out.", "to_out.0."}};

static const char *res_leaf(const char *rest, char *buf, size_t n)
{
    return rename_leaf(rest, RES_LEAVES, sizeof RES_LEAVES / sizeof *RES_LEAVES, buf, n);
}

static const char *attn_leaf(const char *rest, char *buf, size_t n)
{
    return rename_leaf(rest, ATTN_LEAVES, sizeof ATTN_LEAVES / sizeof *ATTN_LEAVES, buf, n);
}

static int unet_key(const sd_ld *ld, const char *name, char *out, size_t n)
{
    int i, j, off = 0;
    char b[256];
    if (!strncmp(name, "time_embed.0.", 13)) return snprintf(out, n, "time_embedding.linear_1.%s", name + 13) > 0;
    if (!strncmp(name, "time_embed.2.", 13)) return snprintf(out, n, "time_embedding.linear_2.%s", name + 13) > 0;
    if (!strncmp(name, "out.0.", 6)) return snprintf(out, n, "conv_norm_out.%s", name + 6) > 0;
    if (!strncmp(name, "out.2.", 6)) return snprintf(out, n, "conv_out.%s", name + 6) > 0;
    if (!strncmp(name, "input_blocks.0.0.", 17)) return snprintf(out, n, "conv_in.%s", name + 17) > 0;
    /* a ControlNet's hint block (convolutions at 0, 2, ..., 14), zero convolutions, middle output */
    if (sscanf(name, "input_hint_block.%d.%n", &i, &off) == 1 && off && i % 2 == 0 && i <= 14) {
        if (i == 0 || i == 14) return snprintf(out, n, "controlnet_cond_embedding.conv_%s.%s", i ? "out" : "in", name + off) > 0;
        return snprintf(out, n, "controlnet_cond_embedding.blocks.%d.%s", i / 2 - 1, name + off) > 0;
    }
    if (sscanf(name, "zero_convs.%d.0.%n", &i, &off) == 1 && off) return snprintf(out, n, "controlnet_down_blocks.%d.%s", i, name + off) > 0;
    if (!strncmp(name, "middle_block_out.0.", 19)) return snprintf(out, n, "controlnet_mid_block.%s", name + 19) > 0;
    int per = ld->nres + 1;
    if (sscanf(name, "input_blocks.%d.%d.%n", &i, &j, &off) == 2 && off && i >= 1) {
        const char *rest = name + off;
        int L = (i - 1) / per, r = (i - 1) % per;
        if (r == ld->nres) return j == 0 && !strncmp(rest, "op.", 3) && snprintf(out, n, "down_blocks.%d.downsamplers.0.conv.%s", L, rest + 3) > 0;
        if (j == 0) return snprintf(out, n, "down_blocks.%d.resnets.%d.%s", L, r, res_leaf(rest, b, sizeof b)) > 0;
        return j == 1 && snprintf(out, n, "down_blocks.%d.attentions.%d.%s", L, r, rest) > 0;
    }
    if (sscanf(name, "middle_block.%d.%n", &j, &off) == 1 && off) {
        const char *rest = name + off;
        if (j == 1) return snprintf(out, n, "mid_block.attentions.0.%s", rest) > 0;
        return (j == 0 || j == 2) && snprintf(out, n, "mid_block.resnets.%d.%s", j / 2, res_leaf(rest, b, sizeof b)) > 0;
    }
    if (sscanf(name, "output_blocks.%d.%d.%n", &i, &j, &off) == 2 && off) {
        const char *rest = name + off;
        int L = i / per, r = i % per;
        if (j == 0) return snprintf(out, n, "up_blocks.%d.resnets.%d.%s", L, r, res_leaf(rest, b, sizeof b)) > 0;
        if (!strncmp(rest, "conv.", 5)) return snprintf(out, n, "up_blocks.%d.upsamplers.0.%s", L, rest) > 0;
        return j == 1 && snprintf(out, n, "up_blocks.%d.attentions.%d.%s", L, r, rest) > 0;
    }
    return 0;
}

static int vae_key(const sd_ld *ld, const char *name, char *out, size_t n)
{
    int l, k, off = 0;
    char b[256], side[8];
    if (sscanf(name, "%7[a-z].%n", side, &off) != 1 || (strcmp(side, "encoder") && strcmp(side, "decoder"))) {
        snprintf(out, n, "%s", name);
        return 1;
    }
    const char *rest = name + off;
    int dec = side[0] == 'd';
    if (sscanf(rest, dec ? "up.%d.block.%d.%n" : "down.%d.block.%d.%n", &l, &k, &off) == 2 && off)
        return snprintf(out, n, "%s.%s_blocks.%d.resnets.%d.%s", side, dec ? "up" : "down", dec ? ld->levels - 1 - l : l, k,
                        res_leaf(rest + off, b, sizeof b)) > 0;
    if (sscanf(rest, dec ? "up.%d.attn.%d.%n" : "down.%d.attn.%d.%n", &l, &k, &off) == 2 && off)
        return snprintf(out, n, "%s.%s_blocks.%d.attentions.%d.%s", side, dec ? "up" : "down", dec ? ld->levels - 1 - l : l, k,
                        attn_leaf(rest + off, b, sizeof b)) > 0;
    if (sscanf(rest, dec ? "up.%d.upsample.%n" : "down.%d.downsample.%n", &l, &off) == 1 && off)
        return snprintf(out, n, "%s.%s_blocks.%d.%s.0.%s", side, dec ? "up" : "down", dec ? ld->levels - 1 - l : l,
                        dec ? "upsamplers" : "downsamplers", rest + off) > 0;
    if (!strncmp(rest, "mid.block_", 10) && (rest[10] == '1' || rest[10] == '2') && rest[11] == '.')
        return snprintf(out, n, "%s.mid_block.resnets.%d.%s", side, rest[10] - '1', res_leaf(rest + 12, b, sizeof b)) > 0;
    if (!strncmp(rest, "mid.attn_1.", 11))
        return snprintf(out, n, "%s.mid_block.attentions.0.%s", side, attn_leaf(rest + 11, b, sizeof b)) > 0;
    if (!strncmp(rest, "norm_out.", 9)) return snprintf(out, n, "%s.conv_norm_out.%s", side, rest + 9) > 0;
    snprintf(out, n, "%s", name);
    return 1;
}

int sd_key(const sd_ld *ld, const char *name, char *key, size_t n)
{
    char k[320];
    int ok = 1;
    if (ld->layout == SD_DIFFUSERS_UNET) ok = unet_key(ld, name, k, sizeof k);
    else if (ld->layout == SD_DIFFUSERS_VAE) ok = vae_key(ld, name, k, sizeof k);
    else snprintf(k, sizeof k, "%s", name);
    snprintf(key, n, "%s%s", ld->prefix, ok ? k : name);
    return ok;
}

/* The tensor under its file key; diffusers' VAE attention also under its older names
 * (query, key, value, proj_attn). */
static const g3d_tensor_info *find_key(const sd_ld *ld, const char *name, char *key, size_t n)
{
    if (!sd_key(ld, name, key, n)) return NULL;
    const g3d_tensor_info *t = g3d_ckpt_find(ld->ck, key);
    if (t || ld->layout != SD_DIFFUSERS_VAE) return t;
    static const char *const older[][2] = {{".to_q.", ".query."}, {".to_k.", ".key."}, {".to_v.", ".value."}, {".to_out.0.", ".proj_attn."}};
    for (size_t i = 0; i < sizeof older / sizeof *older; i++) {
        char *at = strstr(key, older[i][0]);
        if (!at) continue;
        char alt[384];
        snprintf(alt, sizeof alt, "%.*s%s%s", (int)(at - key), key, older[i][1], at + strlen(older[i][0]));
        return g3d_ckpt_find(ld->ck, alt);
    }
    return NULL;
}

const g3d_tensor_info *sd_find(const sd_ld *ld, const char *fmt, ...)
{
    char name[256], key[384];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(name, sizeof name, fmt, ap);
    va_end(ap);
    return find_key(ld, name, key, sizeof key);
}

static void shape_str(char *b, size_t n, int ndim, const int64_t *s)
{
    size_t k = (size_t)snprintf(b, n, "[");
    for (int i = 0; i < ndim && k < n; i++) k += (size_t)snprintf(b + k, n - k, "%s%lld", i ? ", " : "", (long long)s[i]);
    if (k < n) snprintf(b + k, n - k, "]");
}

g3d_status sd_need(const sd_ld *ld, const g3d_tensor_info **t, int ndim, const int64_t *shape, const char *name)
{
    char key[384];
    const g3d_tensor_info *x = find_key(ld, name, key, sizeof key);
    *t = x;
    if (!x) return G3D_ERR(G3D_ERR_MODEL, "%s: missing tensor %s", g3d_ckpt_path(ld->ck), key);
    int ok = x->ndim == ndim;
    for (int i = 0; ok && i < ndim; i++) ok = x->shape[i] == shape[i];
    /* a 1x1 convolution read as a Linear layer */
    if (!ok && ndim == 2 && x->ndim == 4 && x->shape[2] == 1 && x->shape[3] == 1)
        ok = x->shape[0] == shape[0] && x->shape[1] == shape[1];
    if (ok && x->dtype != G3D_DT_F32 && x->dtype != G3D_DT_F16 && x->dtype != G3D_DT_BF16)
        return G3D_ERR(G3D_ERR_MODEL, "%s: tensor %s is %s (F32, F16 or BF16 expected)", g3d_ckpt_path(ld->ck), key,
                       g3d_dtype_name(x->dtype));
    if (!ok) {
        char got[96], want[96];
        shape_str(got, sizeof got, x->ndim, x->shape);
        shape_str(want, sizeof want, ndim, shape);
        return G3D_ERR(G3D_ERR_MODEL, "%s: tensor %s has shape %s, expected %s", g3d_ckpt_path(ld->ck), key, got, want);
    }
    return G3D_OK;
}

g3d_status sd_vec(const sd_ld *ld, float **dst, int n, const char *base, const char *leaf)
{
    char name[256];
    const g3d_tensor_info *t;
    int64_t s = n;
    snprintf(name, sizeof name, "%s.%s", base, leaf);
    G3D_TRY(sd_need(ld, &t, 1, &s, name));
    if (!(*dst = malloc(sizeof(float) * (size_t)n))) return G3D_ERR(G3D_ERR_NOMEM, "out of memory loading %s", name);
    g3d_dtype_to_f32(t->dtype, t->data, *dst, n);
    return G3D_OK;
}

g3d_status sd_conv_load(const sd_ld *ld, g3d_nn_conv *c, int cin, int cout, int k, int stride, const char *base)
{
    char name[256];
    const g3d_tensor_info *t;
    int64_t s[4] = {cout, cin, k, k};
    memset(c, 0, sizeof *c);
    snprintf(name, sizeof name, "%s.weight", base);
    G3D_TRY(sd_need(ld, &t, 4, s, name));
    c->cin = cin;
    c->cout = cout;
    c->kh = c->kw = k;
    c->stride = stride;
    c->pad_h = c->pad_w = k / 2;
    c->w = t->data;
    c->wtype = t->dtype;
    float *b = NULL;
    G3D_TRY(sd_vec(ld, &b, cout, base, "bias"));
    c->b = b;
    return G3D_OK;
}

void sd_conv_free(g3d_nn_conv *c)
{
    g3d_nn_conv_release(c);
    free((void *)c->b);
    c->b = NULL;
}

g3d_status sd_lin_load(const sd_ld *ld, g3d_nn_lin *L, int out, int in, int bias, const char *base)
{
    char name[256];
    const g3d_tensor_info *t;
    int64_t s[2] = {out, in};
    float *b = NULL;
    snprintf(name, sizeof name, "%s.weight", base);
    G3D_TRY(sd_need(ld, &t, 2, s, name));
    if (bias) G3D_TRY(sd_vec(ld, &b, out, base, "bias"));
    g3d_status rc = g3d_nn_lin_init(L, t->data, t->dtype, b, out, in, t->dtype);
    free(b);
    return rc;
}

g3d_status sd_lin_packed(const sd_ld *ld, g3d_nn_lin *L, int parts, int out, int in, int bias, const char *base,
                         const char *const *leaves)
{
    char n[320];
    size_t blk = (size_t)out * in;
    float *w = malloc(sizeof(float) * blk * parts), *b = bias ? malloc(sizeof(float) * (size_t)out * parts) : NULL;
    g3d_status rc = w && (b || !bias) ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory loading %s", base);
    g3d_dtype store = G3D_DT_F32;
    for (int k = 0; k < parts && rc == G3D_OK; k++) {
        const g3d_tensor_info *t;
        int64_t s[2] = {out, in};
        snprintf(n, sizeof n, "%s.%s.weight", base, leaves[k]);
        rc = sd_need(ld, &t, 2, s, n);
        if (rc != G3D_OK) break;
        g3d_dtype_to_f32(t->dtype, t->data, w + k * blk, (int64_t)blk);
        store = t->dtype;
        if (bias) {
            float *bk = NULL;
            snprintf(n, sizeof n, "%s.%s", base, leaves[k]);
            rc = sd_vec(ld, &bk, out, n, "bias");
            if (rc == G3D_OK) memcpy(b + (size_t)k * out, bk, sizeof(float) * out);
            free(bk);
        }
    }
    /* 16-bit weights stay 16-bit in the packed panels (the same values) */
    if (rc == G3D_OK) rc = g3d_nn_lin_init(L, w, G3D_DT_F32, b, parts * out, in, store);
    free(w);
    free(b);
    return rc;
}

g3d_status sd_res_load(const sd_ld *ld, sd_res *r, int cin, int cout, int emb_dim, float eps, const char *base)
{
    char n[256];
    int unet = emb_dim > 0;
    memset(r, 0, sizeof *r);
    r->eps = eps;
    r->cin = cin;
    if (cout < 0) {
        const g3d_tensor_info *w = sd_find(ld, "%s.%s.weight", base, unet ? "in_layers.2" : "conv1");
        cout = w && w->ndim == 4 ? (int)w->shape[0] : cin;
    }
    r->cout = cout;
    snprintf(n, sizeof n, "%s.%s", base, unet ? "in_layers.0" : "norm1");
    G3D_TRY(sd_vec(ld, &r->g1, cin, n, "weight"));
    G3D_TRY(sd_vec(ld, &r->b1, cin, n, "bias"));
    snprintf(n, sizeof n, "%s.%s", base, unet ? "in_layers.2" : "conv1");
    G3D_TRY(sd_conv_load(ld, &r->c1, cin, cout, 3, 1, n));
    if (unet) {
        snprintf(n, sizeof n, "%s.emb_layers.1", base);
        G3D_TRY(sd_lin_load(ld, &r->emb, cout, emb_dim, 1, n));
        r->has_emb = 1;
    }
    snprintf(n, sizeof n, "%s.%s", base, unet ? "out_layers.0" : "norm2");
    G3D_TRY(sd_vec(ld, &r->g2, cout, n, "weight"));
    G3D_TRY(sd_vec(ld, &r->b2, cout, n, "bias"));
    snprintf(n, sizeof n, "%s.%s", base, unet ? "out_layers.3" : "conv2");
    G3D_TRY(sd_conv_load(ld, &r->c2, cout, cout, 3, 1, n));
    if (cin != cout) {
        snprintf(n, sizeof n, "%s.%s", base, unet ? "skip_connection" : "nin_shortcut");
        G3D_TRY(sd_conv_load(ld, &r->skip, cin, cout, 1, 1, n));
        r->has_skip = 1;
    }
    return G3D_OK;
}

void sd_res_free(sd_res *r)
{
    free(r->g1);
    free(r->b1);
    free(r->g2);
    free(r->b2);
    sd_conv_free(&r->c1);
    sd_conv_free(&r->c2);
    sd_conv_free(&r->skip);
    if (r->has_emb) g3d_nn_lin_free(&r->emb);
}

g3d_status sd_res_forward(const sd_res *r, const float *x, int h, int w, const float *emb_silu, float *y, float *tmp)
{
    int hw = h * w;
    int big = r->cin > r->cout ? r->cin : r->cout;
    float *t = tmp, *eb = tmp + (size_t)big * hw;
    g3d_nn_groupnorm(x, r->cin, hw, 32, r->g1, r->b1, r->eps, G3D_ACT_SILU, t);
    g3d_nn_conv c1 = r->c1;
    if (r->has_emb) {
        /* the embedding's projection is a per-channel constant: it joins the convolution's bias */
        G3D_TRY(g3d_nn_lin_forward(&r->emb, emb_silu, 1, 0, eb, 0, NULL));
        for (int i = 0; i < r->cout; i++) eb[i] += r->c1.b[i];
        c1.b = eb;
    }
    G3D_TRY(g3d_nn_conv_forward(&c1, t, h, w, y, NULL));
    g3d_nn_groupnorm(y, r->cout, hw, 32, r->g2, r->b2, r->eps, G3D_ACT_SILU, t);
    const float *res = x;
    if (r->has_skip) {
        G3D_TRY(g3d_nn_conv_forward(&r->skip, x, h, w, y, NULL));
        res = y;
    }
    g3d_nn_epi e = {.res = res};
    return g3d_nn_conv_forward(&r->c2, t, h, w, y, &e);
}

void sd_transpose(const float *x, int r, int s, float *y, int add)
{
    for (int i = 0; i < r; i++)
        for (int j = 0; j < s; j++) {
            float v = x[(size_t)i * s + j];
            if (add) y[(size_t)j * r + i] += v;
            else y[(size_t)j * r + i] = v;
        }
}
