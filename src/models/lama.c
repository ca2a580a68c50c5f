/* LaMa's FFC ResNet generator (advimman/lama, saicinpainting/training/modules/ffc.py) on the
 * layer library, and the official predict pipeline around it.
 *
 * Every FFC layer keeps its channels as one map [local; global]. The two convolutions feeding
 * the local output (local->local and global->local) sum before the same BatchNorm, so they are
 * one convolution over the whole input with their weights side by side. The global output is
 * the local->global convolution plus the spectral transform: the BatchNorm after their sum is
 * folded into both (its scale) and into the first (its shift). */
#include "gen3d/lama.h"

#include "gen3d/nn.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define BN_EPS 1e-5f /* torch.nn.BatchNorm2d's default; LaMa never changes it */

/* A convolution with its own float32 weights (BatchNorm folded in). */
typedef struct conv {
    g3d_nn_conv c;
    float *w, *b;
} conv;

/* Spectral transform (the global->global path): 1x1 conv + BN + ReLU, Fourier unit (and the
 * local Fourier unit when present), 1x1 conv. */
typedef struct spectral {
    int half;       /* channels inside: out_g / 2 */
    conv in, fu, lfu, out;
    int has_lfu;
} spectral;

/* FFC + BatchNorm + ReLU. */
typedef struct ffc {
    int in_l, in_g, out_l, out_g, k, stride;
    conv to_l;      /* [out_l, in_l + in_g]: local->local and global->local together */
    conv l2g;       /* [out_g, in_l] */
    spectral st;    /* global->global */
    int has_l2g, has_st;
} ffc;

struct g3d_lama {
    int in_ch, out_ch, ngf, n_down, n_blocks;
    ffc init;
    ffc *down;      /* [n_down] */
    ffc *blocks;    /* [n_blocks][2] */
    conv *up;       /* [n_down] ConvTranspose2d + BN (+ ReLU) */
    conv final;     /* 7x7 reflect-padded, then sigmoid */
    g3d_nn_arena *arena;
};

/* ---- loading ------------------------------------------------------------------------------ */

typedef struct loader {
    const g3d_ckpt *ck;
    const char *prefix; /* "generator.model." or "model." */
} loader;

static const g3d_tensor_info *find(const loader *L, const char *name)
{
    char full[256];
    snprintf(full, sizeof full, "%s%s", L->prefix, name);
    return g3d_ckpt_find(L->ck, full);
}

/* Reads prefix+name of the given shape (ndim 1 or 4) into a new buffer. */
static g3d_status read_t(const loader *L, const char *name, int ndim, int64_t a, int64_t b, int64_t c, int64_t d,
                         float **out)
{
    char full[256];
    snprintf(full, sizeof full, "%s%s", L->prefix, name);
    int64_t shape[4] = {a, b, c, d};
    return g3d_ckpt_read_alloc(L->ck, full, ndim, shape, out);
}

/* Folds the BatchNorm `bn` (prefix of .weight/.bias/.running_mean/.running_var) of c channels
 * into w viewed as [outer, c, inner] and into bias (which it creates when NULL). */
static g3d_status fold(const loader *L, const char *bn, float *w, float **bias, int outer, int c, int inner)
{
    static const char *const parts[4] = {"weight", "bias", "running_mean", "running_var"};
    float *p[4] = {0};
    g3d_status rc = G3D_OK;
    for (int k = 0; k < 4 && rc == G3D_OK; k++) {
        char name[200];
        snprintf(name, sizeof name, "%s.%s", bn, parts[k]);
        rc = read_t(L, name, 1, c, 0, 0, 0, &p[k]);
    }
    if (rc == G3D_OK && !*bias && !(*bias = calloc((size_t)c, sizeof(float))))
        rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) g3d_nn_fold_bn(w, *bias, outer, c, inner, p[0], p[1], p[2], p[3], BN_EPS);
    for (int k = 0; k < 4; k++) free(p[k]);
    return rc;
}

static void conv_free(conv *c)
{
    g3d_nn_conv_release(&c->c);
    free(c->w);
    free(c->b);
    memset(c, 0, sizeof *c);
}

/* Sets the layer up on its weights and prepares it (Winograd, transposed kernels). */
static g3d_status conv_setup(conv *c, int cin, int cout, int k, int stride, int pad, g3d_nn_padmode mode)
{
    c->c = (g3d_nn_conv){.cin = cin, .cout = cout, .kh = k, .kw = k, .stride = stride, .pad_h = pad, .pad_w = pad,
                         .pad_mode = mode, .w = c->w, .b = c->b};
    return g3d_nn_conv_prepare(&c->c);
}

/* A bias-free 1x1 convolution `name` [cout, cin] with the BatchNorm `bn` folded in (bn NULL:
 * none). */
static g3d_status load_1x1(const loader *L, const char *name, const char *bn, int cin, int cout, conv *c)
{
    G3D_TRY(read_t(L, name, 4, cout, cin, 1, 1, &c->w));
    if (bn) G3D_TRY(fold(L, bn, c->w, &c->b, 1, cout, cin));
    return conv_setup(c, cin, cout, 1, 1, 0, G3D_PAD_ZEROS);
}

static g3d_status load_fourier(const loader *L, const char *at, int half, conv *c)
{
    char w[200], bn[200];
    snprintf(w, sizeof w, "%s.conv_layer.weight", at);
    snprintf(bn, sizeof bn, "%s.bn", at);
    return load_1x1(L, w, bn, 2 * half, 2 * half, c);
}

/* The FFC_BN_ACT at `at` (e.g. "4" or "5.conv1") with in_l/in_g input channels. Output
 * channels come from its BatchNorms, which exist exactly for the non-empty outputs. */
static g3d_status load_ffc(const loader *L, const char *at, int in_l, int in_g, int stride, ffc *f)
{
    char n[200], n2[200];
    const g3d_tensor_info *t;
    f->in_l = in_l;
    f->in_g = in_g;
    f->stride = stride;
    snprintf(n, sizeof n, "%s.ffc.gate.weight", at);
    if (find(L, n)) return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: gated FFC layers (%s%s) are not supported", g3d_ckpt_path(L->ck), L->prefix, n);
    snprintf(n, sizeof n, "%s.bn_l.weight", at);
    f->out_l = (t = find(L, n)) && t->ndim == 1 ? (int)t->shape[0] : 0;
    snprintf(n, sizeof n, "%s.bn_g.weight", at);
    f->out_g = (t = find(L, n)) && t->ndim == 1 ? (int)t->shape[0] : 0;
    /* the kernel size, from whichever convolution feeds the first output */
    snprintf(n, sizeof n, "%s.ffc.%s.weight", at, in_l ? (f->out_l ? "convl2l" : "convl2g") : "convg2l");
    t = find(L, n);
    if (!t || t->ndim != 4)
        return G3D_ERR(G3D_ERR_MODEL, "%s: no LaMa generator layer: missing %s%s", g3d_ckpt_path(L->ck), L->prefix, n);
    f->k = (int)t->shape[3];
    if (f->k < 1 || f->k > 15 || f->k % 2 == 0 || t->shape[2] != f->k || f->out_l + f->out_g == 0)
        return G3D_ERR(G3D_ERR_MODEL, "%s: %s%s has an unexpected shape", g3d_ckpt_path(L->ck), L->prefix, n);
    const int k = f->k, kk = k * k, cin = in_l + in_g;
    if (f->out_l) {
        /* [out_l, in_l + in_g, k, k]: local->local weights, then global->local ones */
        if (!(f->to_l.w = malloc(sizeof(float) * (size_t)f->out_l * cin * kk))) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        for (int part = 0; part < 2; part++) {
            int ci = part ? in_g : in_l, off = part ? in_l : 0;
            if (!ci) continue;
            float *src = NULL;
            snprintf(n, sizeof n, "%s.ffc.%s.weight", at, part ? "convg2l" : "convl2l");
            G3D_TRY(read_t(L, n, 4, f->out_l, ci, k, k, &src));
            for (int o = 0; o < f->out_l; o++)
                memcpy(f->to_l.w + ((size_t)o * cin + off) * kk, src + (size_t)o * ci * kk, sizeof(float) * (size_t)ci * kk);
            free(src);
        }
        snprintf(n, sizeof n, "%s.bn_l", at);
        G3D_TRY(fold(L, n, f->to_l.w, &f->to_l.b, 1, f->out_l, cin * kk));
        G3D_TRY(conv_setup(&f->to_l, cin, f->out_l, k, stride, k / 2, G3D_PAD_REFLECT));
    }
    if (!f->out_g) return G3D_OK;
    snprintf(n2, sizeof n2, "%s.bn_g", at);
    float *gbias = NULL; /* the folded bias goes to the first of the two global paths */
    if ((f->has_l2g = in_l > 0)) {
        snprintf(n, sizeof n, "%s.ffc.convl2g.weight", at);
        G3D_TRY(read_t(L, n, 4, f->out_g, in_l, k, k, &f->l2g.w));
        G3D_TRY(fold(L, n2, f->l2g.w, &f->l2g.b, 1, f->out_g, in_l * kk));
        G3D_TRY(conv_setup(&f->l2g, in_l, f->out_g, k, stride, k / 2, G3D_PAD_REFLECT));
        gbias = f->l2g.b;
    }
    if (!(f->has_st = in_g > 0)) return G3D_OK;
    if (stride != 1 || f->out_g % 2)
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: spectral transform at %s%s with stride %d or %d channels", g3d_ckpt_path(L->ck),
                       L->prefix, at, stride, f->out_g);
    spectral *s = &f->st;
    s->half = f->out_g / 2;
    snprintf(n, sizeof n, "%s.ffc.convg2g.conv1.0.weight", at);
    snprintf(n2, sizeof n2, "%s.ffc.convg2g.conv1.1", at);
    G3D_TRY(load_1x1(L, n, n2, in_g, s->half, &s->in));
    snprintf(n, sizeof n, "%s.ffc.convg2g.fu", at);
    G3D_TRY(load_fourier(L, n, s->half, &s->fu));
    snprintf(n, sizeof n, "%s.ffc.convg2g.lfu.conv_layer.weight", at);
    if ((s->has_lfu = find(L, n) != NULL)) {
        if (s->half % 4) return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: local Fourier unit over %d channels", g3d_ckpt_path(L->ck), s->half);
        snprintf(n, sizeof n, "%s.ffc.convg2g.lfu", at);
        G3D_TRY(load_fourier(L, n, s->half, &s->lfu));
    }
    snprintf(n, sizeof n, "%s.ffc.convg2g.conv2.weight", at);
    G3D_TRY(read_t(L, n, 4, f->out_g, s->half, 1, 1, &s->out.w));
    snprintf(n2, sizeof n2, "%s.bn_g", at);
    float *scratch = NULL;
    G3D_TRY(fold(L, n2, s->out.w, &scratch, 1, f->out_g, s->half));
    if (gbias) free(scratch); /* the bias is already on local->global */
    else s->out.b = scratch;
    return conv_setup(&s->out, s->half, f->out_g, 1, 1, 0, G3D_PAD_ZEROS);
}

static void ffc_free(ffc *f)
{
    conv_free(&f->to_l);
    conv_free(&f->l2g);
    conv_free(&f->st.in);
    conv_free(&f->st.fu);
    conv_free(&f->st.lfu);
    conv_free(&f->st.out);
}

void g3d_lama_free(g3d_lama *m)
{
    if (!m) return;
    ffc_free(&m->init);
    for (int i = 0; m->down && i < m->n_down; i++) ffc_free(&m->down[i]);
    for (int i = 0; m->blocks && i < 2 * m->n_blocks; i++) ffc_free(&m->blocks[i]);
    for (int i = 0; m->up && i < m->n_down; i++) conv_free(&m->up[i]);
    conv_free(&m->final);
    free(m->down);
    free(m->blocks);
    free(m->up);
    g3d_nn_arena_free(m->arena);
    free(m);
}

static int has_layer(const loader *L, int i, const char *sub)
{
    char n[200];
    for (int g = 0; g < 2; g++) {
        snprintf(n, sizeof n, "%d%s.bn_%c.weight", i, sub, g ? 'g' : 'l');
        if (find(L, n)) return 1;
    }
    return 0;
}

#define MAX_LAYERS 256

static g3d_status load(const loader *L, g3d_lama *m)
{
    const char *path = g3d_ckpt_path(L->ck);
    char n[200], n2[200];
    /* model.0 is a reflection pad, model.1 the 7x7 input layer (local channels only) */
    const g3d_tensor_info *t = find(L, "1.ffc.convl2l.weight");
    if (!t || t->ndim != 4)
        return G3D_ERR(G3D_ERR_MODEL, "%s: no LaMa generator: missing %s1.ffc.convl2l.weight", path, L->prefix);
    m->in_ch = (int)t->shape[1];
    G3D_TRY(load_ffc(L, "1", m->in_ch, 0, 1, &m->init));
    if (m->init.out_g) return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: the input layer has global channels", path);
    m->ngf = m->init.out_l;
    int i = 2, cl = m->init.out_l, cg = 0;
    while (i < MAX_LAYERS && has_layer(L, i, "")) i++;
    m->n_down = i - 2;
    if (m->n_down < 1 || m->n_down > 6)
        return G3D_ERR(G3D_ERR_MODEL, "%s: %d downsampling layers (missing %s2.bn_l.weight?)", path, m->n_down, L->prefix);
    if (!(m->down = calloc((size_t)m->n_down, sizeof *m->down)) || !(m->up = calloc((size_t)m->n_down, sizeof *m->up)))
        return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    for (int d = 0; d < m->n_down; d++) {
        snprintf(n, sizeof n, "%d", 2 + d);
        G3D_TRY(load_ffc(L, n, cl, cg, 2, &m->down[d]));
        cl = m->down[d].out_l;
        cg = m->down[d].out_g;
    }
    int first_block = i;
    while (i < MAX_LAYERS && has_layer(L, i, ".conv1")) i++;
    m->n_blocks = i - first_block;
    if (m->n_blocks && !(m->blocks = calloc((size_t)m->n_blocks * 2, sizeof *m->blocks)))
        return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    for (int b = 0; b < m->n_blocks; b++)
        for (int h = 0; h < 2; h++) {
            ffc *f = &m->blocks[2 * b + h];
            snprintf(n, sizeof n, "%d.conv%d", first_block + b, h + 1);
            G3D_TRY(load_ffc(L, n, cl, cg, 1, f));
            if (f->out_l != cl || f->out_g != cg)
                return G3D_ERR(G3D_ERR_MODEL, "%s: residual block %s%s changes its channels", path, L->prefix, n);
        }
    i++; /* the layer that concatenates local and global channels */
    int c = cl + cg;
    for (int u = 0; u < m->n_down; u++, i += 3) {
        conv *up = &m->up[u];
        snprintf(n, sizeof n, "%d.weight", i);
        t = find(L, n);
        if (!t || t->ndim != 4 || t->shape[0] != c)
            return G3D_ERR(G3D_ERR_MODEL, "%s: missing or unexpected %s%s (upsampling layer %d of %d, %d input channels)",
                           path, L->prefix, n, u + 1, m->n_down, c);
        int co = (int)t->shape[1];
        G3D_TRY(read_t(L, n, 4, c, co, 3, 3, &up->w));
        snprintf(n, sizeof n, "%d.bias", i);
        G3D_TRY(read_t(L, n, 1, co, 0, 0, 0, &up->b));
        snprintf(n2, sizeof n2, "%d", i + 1);
        G3D_TRY(fold(L, n2, up->w, &up->b, c, co, 9));
        up->c = (g3d_nn_conv){.cin = c, .cout = co, .kh = 3, .kw = 3, .stride = 2, .pad_h = 1, .pad_w = 1,
                              .transposed = 1, .output_padding = 1, .w = up->w, .b = up->b};
        G3D_TRY(g3d_nn_conv_prepare(&up->c));
        c = co;
    }
    /* a reflection pad, then the 7x7 output convolution */
    snprintf(n, sizeof n, "%d.weight", i + 1);
    t = find(L, n);
    if (!t || t->ndim != 4 || t->shape[1] != c)
        return G3D_ERR(G3D_ERR_MODEL, "%s: missing or unexpected %s%s (the output layer, %d input channels)", path, L->prefix, n, c);
    m->out_ch = (int)t->shape[0];
    int k = (int)t->shape[3];
    if (k % 2 == 0 || t->shape[2] != k) return G3D_ERR(G3D_ERR_MODEL, "%s: %s%s has an unexpected shape", path, L->prefix, n);
    G3D_TRY(read_t(L, n, 4, m->out_ch, c, k, k, &m->final.w));
    snprintf(n, sizeof n, "%d.bias", i + 1);
    G3D_TRY(read_t(L, n, 1, m->out_ch, 0, 0, 0, &m->final.b));
    G3D_TRY(conv_setup(&m->final, c, m->out_ch, k, 1, k / 2, G3D_PAD_REFLECT));
    if (!(m->arena = g3d_nn_arena_new(0))) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    return G3D_OK;
}

g3d_status g3d_lama_load(const g3d_ckpt *ck, g3d_lama **out)
{
    *out = NULL;
    static const char *const prefixes[] = {"generator.model.", "model."};
    loader L = {ck, prefixes[0]};
    for (size_t p = 0; p < sizeof prefixes / sizeof *prefixes; p++) {
        L.prefix = prefixes[p];
        if (find(&L, "1.ffc.convl2l.weight")) break;
        L.prefix = prefixes[0]; /* messages name the Lightning layout when neither is there */
    }
    g3d_lama *m = calloc(1, sizeof *m);
    if (!m) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_status rc = load(&L, m);
    if (rc != G3D_OK) {
        g3d_lama_free(m);
        return rc;
    }
    *out = m;
    return G3D_OK;
}

g3d_status g3d_lama_load_file(const char *path, g3d_lama **out)
{
    *out = NULL;
    g3d_ckpt *ck = NULL;
    G3D_TRY(g3d_ckpt_open(path, &ck));
    g3d_status rc = g3d_lama_load(ck, out);
    g3d_ckpt_free(ck);
    return rc;
}

const char *g3d_lama_describe(const g3d_lama *m, char *buf, size_t n)
{
    const ffc *b = m->n_blocks ? &m->blocks[0] : NULL;
    int lfu = b && b->has_st && b->st.has_lfu;
    snprintf(buf, n, "LaMa FFC ResNet generator: %d -> %d channels, width %d, %d downsamplings, %d residual blocks of %d "
             "channels (%d global)%s", m->in_ch, m->out_ch, m->ngf, m->n_down, m->n_blocks, b ? b->out_l + b->out_g : 0,
             b ? b->out_g : 0, lfu ? ", local Fourier units" : "");
    return buf;
}

/* ---- the forward pass --------------------------------------------------------------------- */

/* The Fourier unit on x [c, h, w] -> y [c, h, w]: rfft2, 1x1 conv + BN + ReLU over the
 * [re, im] channel pairs, irfft2. */
static g3d_status fourier(g3d_nn_arena *a, const conv *fu, const float *x, int c, int h, int w, float *y)
{
    const int wf = w / 2 + 1;
    float *f = g3d_nn_arena_floats(a, (size_t)2 * c * h * wf), *g = g3d_nn_arena_floats(a, (size_t)2 * c * h * wf);
    if (!f || !g) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    G3D_TRY(g3d_nn_rfft2(x, c, h, w, f));
    const g3d_nn_epi relu = {G3D_ACT_RELU, NULL, NULL};
    G3D_TRY(g3d_nn_conv_forward(&fu->c, f, h, wf, g, &relu));
    return g3d_nn_irfft2(g, c, h, w, y);
}

/* Spectral transform: x [in_g, h, w] -> y [out_g, h, w]; res (may be y) is added to the
 * output convolution's result, before the caller's activation. */
static g3d_status spectral_forward(g3d_nn_arena *a, const spectral *s, const float *x, int h, int w, float *y,
                                   const float *res)
{
    const size_t hw = (size_t)h * w, mark = g3d_nn_arena_mark(a);
    const int c = s->half;
    float *t = g3d_nn_arena_floats(a, c * hw), *u = g3d_nn_arena_floats(a, c * hw);
    if (!t || !u) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    const g3d_nn_epi relu = {G3D_ACT_RELU, NULL, NULL};
    G3D_TRY(g3d_nn_conv_forward(&s->in.c, x, h, w, t, &relu));
    G3D_TRY(fourier(a, &s->fu, t, c, h, w, u));
    g3d_nn_add(u, t, c * hw);
    if (s->has_lfu) {
        /* The first quarter of the channels cut into four quadrants stacked as channels
         * (top-left, bottom-left, top-right, bottom-right: the official split along H, then W),
         * through the unit, then tiled 2 x 2 over the map. The official code cuts both axes at
         * h / 2, so only square maps of even side work there. */
        if (h != w || h % 2) return G3D_ERR(G3D_ERR_ARG, "LaMa: a local Fourier unit needs a square bottleneck of even side, not %d x %d", w, h);
        const int q = c / 4, hh = h / 2;
        const size_t qq = (size_t)hh * hh;
        float *xs = g3d_nn_arena_floats(a, c * qq), *ys = g3d_nn_arena_floats(a, c * qq);
        if (!xs || !ys) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        for (int part = 0; part < 4; part++) {
            const int oy = part % 2 ? hh : 0, ox = part / 2 ? hh : 0;
            for (int ch = 0; ch < q; ch++)
                for (int yy = 0; yy < hh; yy++)
                    memcpy(xs + ((size_t)(part * q + ch) * hh + yy) * hh, t + ((size_t)ch * h + oy + yy) * w + ox,
                           sizeof(float) * (size_t)hh);
        }
        G3D_TRY(fourier(a, &s->lfu, xs, c, hh, hh, ys));
        for (int ch = 0; ch < c; ch++)
            for (int yy = 0; yy < h; yy++)
                for (int xx = 0; xx < w; xx++) u[(size_t)ch * hw + (size_t)yy * w + xx] += ys[((size_t)ch * hh + yy % hh) * hh + xx % hh];
    }
    const g3d_nn_epi add = {G3D_ACT_NONE, NULL, res};
    g3d_status rc = g3d_nn_conv_forward(&s->out.c, u, h, w, y, res ? &add : NULL);
    g3d_nn_arena_reset(a, mark);
    return rc;
}

/* FFC + BN + ReLU on x [in_l + in_g, h, w] -> y [out_l + out_g, ho, wo]; with res (the block
 * input, y's shape) the result is res + ReLU(...), the residual block's last step. */
static g3d_status ffc_forward(g3d_nn_arena *a, const ffc *f, const float *x, int h, int w, float *y, const float *res)
{
    int ho = h, wo = w;
    const conv *first = f->out_l ? &f->to_l : f->has_l2g ? &f->l2g : NULL;
    if (first) G3D_TRY(g3d_nn_conv_out_size(&first->c, h, w, &ho, &wo));
    const size_t hw = (size_t)ho * wo;
    if (f->out_l) {
        const g3d_nn_epi e = {G3D_ACT_RELU, NULL, res};
        G3D_TRY(g3d_nn_conv_forward(&f->to_l.c, x, h, w, y, &e));
    }
    if (!f->out_g) return G3D_OK;
    float *yg = y + (size_t)f->out_l * hw;
    const float *xg = x + (size_t)f->in_l * h * w;
    if (f->has_l2g) G3D_TRY(g3d_nn_conv_forward(&f->l2g.c, x, h, w, yg, NULL));
    if (f->has_st) G3D_TRY(spectral_forward(a, &f->st, xg, h, w, yg, f->has_l2g ? yg : NULL));
    const size_t n = (size_t)f->out_g * hw;
    g3d_nn_relu(yg, n);
    if (res) g3d_nn_add(yg, res + (size_t)f->out_l * hw, n);
    return G3D_OK;
}

static void tap_out(g3d_lama_tap tap, void *user, const char *stage, int i, const float *x, int c, int h, int w)
{
    char name[32];
    if (i >= 0) snprintf(name, sizeof name, "%s%d", stage, i);
    else snprintf(name, sizeof name, "%s", stage);
    if (tap) tap(user, name, x, c, h, w);
}

/* The sizes every layer needs: divisible by 2^n_down, reflection pads smaller than the map. */
static g3d_status check_size(const g3d_lama *m, int h, int w)
{
    const int f = 1 << m->n_down;
    if (h % f || w % f) return G3D_ERR(G3D_ERR_ARG, "LaMa: %d x %d is not a multiple of %d", w, h, f);
    int need = f * 2; /* 3x3 reflect-padded layers at the bottleneck need 2 pixels */
    if (m->final.c.pad_h >= need) need = m->final.c.pad_h + 1;
    if (m->init.k / 2 >= need) need = m->init.k / 2 + 1;
    if (h < need || w < need) return G3D_ERR(G3D_ERR_ARG, "LaMa: %d x %d is too small (at least %d x %d)", w, h, need, need);
    return G3D_OK;
}

g3d_status g3d_lama_forward(g3d_lama *m, const float *x, int h, int w, float *y, g3d_lama_tap tap, void *user)
{
    G3D_TRY(check_size(m, h, w));
    g3d_nn_arena *a = m->arena;
    g3d_nn_arena_reset(a, 0);
    float *cur = g3d_nn_arena_floats(a, (size_t)m->ngf * h * w);
    if (!cur) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    G3D_TRY(ffc_forward(a, &m->init, x, h, w, cur, NULL));
    tap_out(tap, user, "init", -1, cur, m->ngf, h, w);
    /* every stage's output above its input on the arena: the maps shrink 4x per downsampling */
    for (int d = 0; d < m->n_down; d++) {
        const ffc *f = &m->down[d];
        int ho = h / 2, wo = w / 2;
        float *nx = g3d_nn_arena_floats(a, (size_t)(f->out_l + f->out_g) * ho * wo);
        if (!nx) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        G3D_TRY(ffc_forward(a, f, cur, h, w, nx, NULL));
        cur = nx;
        h = ho;
        w = wo;
        tap_out(tap, user, "down", d, cur, f->out_l + f->out_g, h, w);
    }
    const ffc *last = &m->down[m->n_down - 1];
    const int c = last->out_l + last->out_g;
    /* residual blocks: input, middle and output buffers, input and output swapped per block */
    float *mid = g3d_nn_arena_floats(a, (size_t)c * h * w), *nxt = g3d_nn_arena_floats(a, (size_t)c * h * w);
    if (!mid || !nxt) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    for (int b = 0; b < m->n_blocks; b++) {
        G3D_TRY(ffc_forward(a, &m->blocks[2 * b], cur, h, w, mid, NULL));
        G3D_TRY(ffc_forward(a, &m->blocks[2 * b + 1], mid, h, w, nxt, cur));
        float *t = cur;
        cur = nxt;
        nxt = t;
        tap_out(tap, user, "block", b, cur, c, h, w);
    }
    for (int u = 0; u < m->n_down; u++) {
        const conv *up = &m->up[u];
        float *nx = g3d_nn_arena_floats(a, (size_t)up->c.cout * 4 * h * w);
        if (!nx) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        const g3d_nn_epi relu = {G3D_ACT_RELU, NULL, NULL};
        G3D_TRY(g3d_nn_conv_forward(&up->c, cur, h, w, nx, &relu));
        cur = nx;
        h *= 2;
        w *= 2;
        tap_out(tap, user, "up", u, cur, up->c.cout, h, w);
    }
    const g3d_nn_epi sig = {G3D_ACT_SIGMOID, NULL, NULL};
    g3d_status rc = g3d_nn_conv_forward(&m->final.c, cur, h, w, y, &sig);
    if (rc == G3D_OK) tap_out(tap, user, "pred", -1, y, m->out_ch, h, w);
    g3d_nn_arena_reset(a, 0);
    return rc;
}

/* ---- the predict pipeline and the plug-in ------------------------------------------------ */

g3d_status g3d_lama_inpaint(g3d_lama *m, g3d_image *image, const g3d_image *mask, int64_t *filled)
{
    if (filled) *filled = 0;
    if (image->c != 3 || m->in_ch != 4 || m->out_ch != 3)
        return G3D_ERR(G3D_ERR_ARG, "LaMa: an RGB image and a 4 -> 3 channel generator are needed (image has %d channels, "
                       "generator %d -> %d)", image->c, m->in_ch, m->out_ch);
    if (mask->w != image->w || mask->h != image->h || mask->c != 1)
        return G3D_ERR(G3D_ERR_MISMATCH, "LaMa: the mask is %d x %d x %d, the image %d x %d", mask->w, mask->h, mask->c,
                       image->w, image->h);
    const int w = image->w, h = image->h;
    const size_t n = (size_t)w * h;
    int64_t holes = 0;
    for (size_t i = 0; i < n; i++) holes += mask->data[i] > 0.5f;
    if (filled) *filled = holes;
    if (!holes) return G3D_OK;
    if ((size_t)holes == n) return G3D_ERR(G3D_ERR_ARG, "LaMa: the mask covers every pixel; nothing is left to inpaint from");
    if (w < 16 || h < 16) return G3D_ERR(G3D_ERR_ARG, "LaMa: %d x %d is too small (at least 16 x 16)", w, h);
    /* pad_img_to_modulo: the next multiple of 8 (of 2^downsamplings in general), bottom and
     * right, mirrored with the edge repeated; then [image * (1 - mask), mask] */
    const int f = 1 << m->n_down, hp = (h + f - 1) / f * f, wp = (w + f - 1) / f * f;
    if (hp - h > h || wp - w > w) return G3D_ERR(G3D_ERR_ARG, "LaMa: %d x %d is too small to pad to a multiple of %d", w, h, f);
    const size_t np = (size_t)wp * hp;
    float *planar = malloc(sizeof(float) * 4 * n), *x = malloc(sizeof(float) * 4 * np), *y = malloc(sizeof(float) * 3 * np);
    g3d_status rc = planar && x && y ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) {
        for (size_t i = 0; i < n; i++) {
            const float hole = mask->data[i] > 0.5f ? 1.0f : 0.0f;
            for (int k = 0; k < 3; k++) planar[k * n + i] = image->data[3 * i + k] * (1.0f - hole);
            planar[3 * n + i] = hole;
        }
        rc = g3d_nn_pad2d(planar, 4, h, w, 0, hp - h, 0, wp - w, G3D_PAD_SYMMETRIC, x);
    }
    if (rc == G3D_OK) rc = g3d_lama_forward(m, x, hp, wp, y, NULL, NULL);
    if (rc == G3D_OK)
        for (int yy = 0; yy < h; yy++)
            for (int xx = 0; xx < w; xx++) {
                const size_t i = (size_t)yy * w + xx;
                if (mask->data[i] > 0.5f)
                    for (int k = 0; k < 3; k++) image->data[3 * i + k] = y[k * np + (size_t)yy * wp + xx];
            }
    free(planar);
    free(x);
    free(y);
    return rc;
}

static g3d_status plugin_inpaint(void *ctx, g3d_image *image, const g3d_image *mask, const char *prompt, uint64_t seed)
{
    (void)prompt;
    (void)seed;
    return g3d_lama_inpaint(ctx, image, mask, NULL);
}

static void plugin_free(void *ctx) { g3d_lama_free(ctx); }

g3d_status g3d_inpainter_lama_create(const char *path, g3d_inpainter *out)
{
    memset(out, 0, sizeof *out);
    g3d_lama *m = NULL;
    G3D_TRY(g3d_lama_load_file(path, &m));
    if (m->in_ch != 4 || m->out_ch != 3) {
        const int in = m->in_ch, o = m->out_ch;
        g3d_lama_free(m);
        return G3D_ERR(G3D_ERR_MODEL, "%s: a %d -> %d channel generator; inpainting needs RGB + mask -> RGB", path, in, o);
    }
    *out = (g3d_inpainter){"lama", m, plugin_inpaint, plugin_free};
    return G3D_OK;
}
