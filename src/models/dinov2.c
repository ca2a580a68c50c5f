/* DINOv2 ViT backbone: patch embedding, resized position grid, pre-norm blocks with LayerScale.
 * Every size is read from the tensors; only the head width (64, as in every published DINOv2)
 * is not stored in them. */
#include "gen3d/dinov2.h"

#include "gen3d/nn.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define HEAD_DIM 64
#define LN_EPS 1e-6f
/* The official code adds 0.1 to the target grid size before deriving the scale factor, to
 * dodge a floating-point rounding problem in the output size; the scale it yields is used. */
#define POS_OFFSET 0.1

/* Linear layers are packed once at load (g3d_nn_lin); the float copies read from the
 * checkpoint are freed after packing. */
typedef struct dino_block {
    float *n1w, *n1b, *ls1, *n2w, *n2b, *ls2;
    g3d_nn_lin qkv, proj, fc1, fc2;
} dino_block;

struct g3d_dinov2 {
    int dim, depth, hidden, grid, patch; /* grid: side of the trained position grid */
    float *cls, *pos, *normw, *normb;
    g3d_nn_lin pe; /* the patch embedding as a product over flattened patches */
    dino_block *blocks;
};

typedef struct loader {
    const g3d_ckpt *ck;
    const char *prefix;
} loader;

static g3d_status load(const loader *l, float **dst, int ndim, const int64_t *shape, const char *fmt, ...)
{
    char name[256], full[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(name, sizeof name, fmt, ap);
    va_end(ap);
    snprintf(full, sizeof full, "%s%s", l->prefix, name);
    return g3d_ckpt_read_alloc(l->ck, full, ndim, shape, dst);
}

/* Packs the Linear layer NAME.weight (of shape wshape, [out, ...] flattening to [out, in]) with
 * NAME.bias [out]. */
static g3d_status load_lin(const loader *l, g3d_nn_lin *L, int wdims, const int64_t *wshape, const char *fmt, int i)
{
    char name[192], wn[256], bn[256];
    snprintf(name, sizeof name, fmt, i);
    snprintf(wn, sizeof wn, "%s.weight", name);
    snprintf(bn, sizeof bn, "%s.bias", name);
    const int out = (int)wshape[0];
    int64_t in = 1;
    for (int d = 1; d < wdims; d++) in *= wshape[d];
    const int64_t bshape[] = {out};
    float *w = NULL, *b = NULL;
    g3d_status rc = load(l, &w, wdims, wshape, "%s", wn);
    if (rc == G3D_OK) rc = load(l, &b, 1, bshape, "%s", bn);
    if (rc == G3D_OK) rc = g3d_nn_lin_init(L, w, G3D_DT_F32, b, out, (int)in, G3D_DT_F32);
    free(w);
    free(b);
    return rc;
}

static const g3d_tensor_info *find(const loader *l, const char *name)
{
    char full[512];
    snprintf(full, sizeof full, "%s%s", l->prefix, name);
    return g3d_ckpt_find(l->ck, full);
}

void g3d_dinov2_free(g3d_dinov2 *m)
{
    if (!m) return;
    free(m->cls); free(m->pos); free(m->normw); free(m->normb);
    g3d_nn_lin_free(&m->pe);
    if (m->blocks) {
        for (int i = 0; i < m->depth; i++) {
            dino_block *b = &m->blocks[i];
            free(b->n1w); free(b->n1b); free(b->ls1); free(b->n2w); free(b->n2b); free(b->ls2);
            g3d_nn_lin_free(&b->qkv); g3d_nn_lin_free(&b->proj); g3d_nn_lin_free(&b->fc1); g3d_nn_lin_free(&b->fc2);
        }
        free(m->blocks);
    }
    free(m);
}

g3d_status g3d_dinov2_load(const g3d_ckpt *ck, const char *prefix, g3d_dinov2 **out)
{
    *out = NULL;
    loader l = {ck, prefix ? prefix : ""};
    const g3d_tensor_info *pe = find(&l, "pos_embed");
    if (!pe || pe->ndim != 3 || pe->shape[0] != 1)
        return G3D_ERR(G3D_ERR_MODEL, "%s: no DINOv2 backbone: tensor %spos_embed %s", g3d_ckpt_path(ck), l.prefix,
                       pe ? "is not [1, N, D]" : "is missing");
    if (find(&l, "blocks.0.mlp.w12.weight"))
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: DINOv2 with a SwiGLU MLP (ViT-G) is not supported", g3d_ckpt_path(ck));
    /* Register tokens come with antialiased position interpolation in the official builders. */
    if (find(&l, "register_tokens"))
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: tensor %sregister_tokens: DINOv2 with register tokens is not supported",
                       g3d_ckpt_path(ck), l.prefix);
    const g3d_tensor_info *pw = find(&l, "patch_embed.proj.weight");
    if (!pw || pw->ndim != 4 || pw->shape[1] != 3 || pw->shape[2] != pw->shape[3] || pw->shape[2] < 1 || pw->shape[2] > 64)
        return G3D_ERR(G3D_ERR_MODEL, "%s: tensor %spatch_embed.proj.weight %s", g3d_ckpt_path(ck), l.prefix,
                       pw ? "is not [D, 3, p, p] with square patches of at most 64 pixels" : "is missing");
    int64_t npos = pe->shape[1] - 1, D = pe->shape[2];
    int grid = (int)lround(sqrt((double)npos));
    if (grid * grid != npos || D % HEAD_DIM || D > 4096)
        return G3D_ERR(G3D_ERR_MODEL, "%s: %spos_embed has shape [1, %lld, %lld]: not a square grid of a known width",
                       g3d_ckpt_path(ck), l.prefix, (long long)pe->shape[1], (long long)D);
    const g3d_tensor_info *fc1 = find(&l, "blocks.0.mlp.fc1.weight");
    if (!fc1 || fc1->ndim != 2)
        return G3D_ERR(G3D_ERR_MODEL, "%s: tensor %sblocks.0.mlp.fc1.weight is missing or not 2-D", g3d_ckpt_path(ck),
                       l.prefix);
    int depth = 0;
    char name[64];
    for (;; depth++) {
        snprintf(name, sizeof name, "blocks.%d.norm1.weight", depth);
        if (!find(&l, name)) break;
    }
    g3d_dinov2 *m = calloc(1, sizeof *m);
    if (!m) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    m->dim = (int)D;
    m->depth = depth;
    m->hidden = (int)fc1->shape[0];
    m->grid = grid;
    m->patch = (int)pw->shape[2];
    m->blocks = calloc((size_t)(depth ? depth : 1), sizeof *m->blocks);
    g3d_status rc = m->blocks ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    const int64_t d1[] = {D}, cls[] = {1, 1, D}, pos[] = {1, npos + 1, D}, pew[] = {D, 3, m->patch, m->patch};
    const int64_t qkvw[] = {3 * D, D}, projw[] = {D, D}, fc1w[] = {m->hidden, D}, fc2w[] = {D, m->hidden};
    if (rc == G3D_OK) rc = load(&l, &m->cls, 3, cls, "cls_token");
    if (rc == G3D_OK) rc = load(&l, &m->pos, 3, pos, "pos_embed");
    if (rc == G3D_OK) rc = load_lin(&l, &m->pe, 4, pew, "patch_embed.proj", 0);
    if (rc == G3D_OK) rc = load(&l, &m->normw, 1, d1, "norm.weight");
    if (rc == G3D_OK) rc = load(&l, &m->normb, 1, d1, "norm.bias");
    for (int i = 0; i < depth && rc == G3D_OK; i++) {
        dino_block *b = &m->blocks[i];
        struct { float **dst; const char *name; } t[] = {
            {&b->n1w, "norm1.weight"}, {&b->n1b, "norm1.bias"}, {&b->ls1, "ls1.gamma"},
            {&b->n2w, "norm2.weight"}, {&b->n2b, "norm2.bias"}, {&b->ls2, "ls2.gamma"},
        };
        for (size_t j = 0; j < sizeof t / sizeof *t && rc == G3D_OK; j++)
            rc = load(&l, t[j].dst, 1, d1, "blocks.%d.%s", i, t[j].name);
        struct { g3d_nn_lin *L; const int64_t *shape; const char *name; } u[] = {
            {&b->qkv, qkvw, "blocks.%d.attn.qkv"}, {&b->proj, projw, "blocks.%d.attn.proj"},
            {&b->fc1, fc1w, "blocks.%d.mlp.fc1"},  {&b->fc2, fc2w, "blocks.%d.mlp.fc2"},
        };
        for (size_t j = 0; j < sizeof u / sizeof *u && rc == G3D_OK; j++) rc = load_lin(&l, u[j].L, 2, u[j].shape, u[j].name, i);
    }
    if (rc == G3D_OK && depth == 0) rc = G3D_ERR(G3D_ERR_MODEL, "%s: no %sblocks.0.* tensors", g3d_ckpt_path(ck), l.prefix);
    if (rc != G3D_OK) {
        g3d_dinov2_free(m);
        return rc;
    }
    *out = m;
    return G3D_OK;
}

int g3d_dinov2_width(const g3d_dinov2 *m) { return m->dim; }
int g3d_dinov2_depth(const g3d_dinov2 *m) { return m->depth; }
int g3d_dinov2_patch(const g3d_dinov2 *m) { return m->patch; }

void g3d_dinov2_trace_free(g3d_dinov2_trace *t)
{
    if (!t) return;
    free(t->patch_embed);
    if (t->block)
        for (int i = 0; i < t->nblocks; i++) free(t->block[i]);
    free(t->block);
    t->patch_embed = NULL;
    t->block = NULL;
    t->nblocks = 0;
}

/* PyTorch's bicubic convolution kernel, a = -0.75, evaluated in float as it does. */
static void cubic_weights(float t, float w[4])
{
    const float A = -0.75f;
    float x1 = t + 1, x2 = 1 - t, x3 = 2 - t;
    w[0] = ((A * x1 - 5 * A) * x1 + 8 * A) * x1 - 4 * A;
    w[1] = ((A + 2) * t - (A + 3)) * t * t + 1;
    w[2] = ((A + 2) * x2 - (A + 3)) * x2 * x2 + 1;
    w[3] = ((A * x3 - 5 * A) * x3 + 8 * A) * x3 - 4 * A;
}

/* Source taps of F.interpolate(mode='bicubic', align_corners=False, scale_factor=s): the
 * coordinate maps with 1/s (not in/out), indices are clamped to the border. */
static void cubic_taps(int dst, double s, int n, int idx[4], float w[4])
{
    float inv = (float)(1.0 / s);
    float real = inv * ((float)dst + 0.5f) - 0.5f;
    float f = floorf(real);
    cubic_weights(real - f, w);
    for (int k = 0; k < 4; k++) {
        int i = (int)f - 1 + k;
        idx[k] = i < 0 ? 0 : i >= n ? n - 1 : i;
    }
}

/* pos [(1 + g*g), D] -> out [(1 + h*w), D]. */
static void resize_pos(const g3d_dinov2 *m, int h, int w, float *out)
{
    int g = m->grid, D = m->dim;
    memcpy(out, m->pos, sizeof(float) * (size_t)D);
    if (h == g && w == g) {
        memcpy(out + D, m->pos + D, sizeof(float) * (size_t)D * g * g);
        return;
    }
    double sy = (h + POS_OFFSET) / g, sx = (w + POS_OFFSET) / g;
    const float *grid = m->pos + D;
#pragma omp parallel for schedule(static)
    for (int oy = 0; oy < h; oy++) {
        int iy[4], ix[4];
        float wy[4], wx[4];
        cubic_taps(oy, sy, g, iy, wy);
        for (int ox = 0; ox < w; ox++) {
            cubic_taps(ox, sx, g, ix, wx);
            float *dst = out + (size_t)(1 + oy * w + ox) * D;
            for (int c = 0; c < D; c++) {
                float acc = 0;
                for (int ky = 0; ky < 4; ky++) {
                    const float *row = grid + (size_t)iy[ky] * g * D + c;
                    float r = row[(size_t)ix[0] * D] * wx[0] + row[(size_t)ix[1] * D] * wx[1] +
                              row[(size_t)ix[2] * D] * wx[2] + row[(size_t)ix[3] * D] * wx[3];
                    acc += r * wy[ky];
                }
                dst[c] = acc;
            }
        }
    }
}

static float *dup(const float *v, size_t n)
{
    float *d = malloc(sizeof(float) * n);
    if (d) memcpy(d, v, sizeof(float) * n);
    return d;
}

g3d_status g3d_dinov2_forward(const g3d_dinov2 *m, const float *x, int H, int W, const int *layers, int nlayers,
                              float **feats, float **cls, g3d_dinov2_trace *trace)
{
    const int P = m->patch;
    if (H <= 0 || W <= 0 || H % P || W % P || H > 32768 || W > 32768)
        return G3D_ERR(G3D_ERR_ARG, "DINOv2 input %dx%d: sides must be positive multiples of %d up to 32768", W, H, P);
    for (int i = 0; i < nlayers; i++)
        if (layers[i] < 0 || layers[i] >= m->depth || (i && layers[i] <= layers[i - 1]))
            return G3D_ERR(G3D_ERR_ARG, "DINOv2: layer list must be increasing block indices below %d", m->depth);
    int h = H / P, w = W / P, np = h * w, n = np + 1, D = m->dim, K = 3 * P * P;
    for (int i = 0; i < nlayers; i++) {
        feats[i] = NULL;
        if (cls) cls[i] = NULL;
    }
    if (trace && trace->want) {
        trace->nblocks = m->depth;
        trace->patch_embed = NULL;
        trace->block = calloc((size_t)m->depth, sizeof(float *));
        if (!trace->block) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    size_t nd = (size_t)n * D;
    float *X = malloc(sizeof(float) * nd), *T = malloc(sizeof(float) * nd), *A = malloc(sizeof(float) * nd);
    float *big = malloc(sizeof(float) * (size_t)n * (size_t)(m->hidden > 3 * D ? m->hidden : 3 * D));
    float *patches = malloc(sizeof(float) * (size_t)np * (K > D ? K : D));
    g3d_status rc = G3D_OK;
    if (!X || !T || !A || !big || !patches) {
        rc = G3D_ERR(G3D_ERR_NOMEM, "DINOv2: cannot allocate activations for %dx%d", W, H);
        goto done;
    }
    /* Patch embedding as a product: each P x P x 3 patch becomes a row in the weight's order. */
    for (int py = 0; py < h; py++)
        for (int px = 0; px < w; px++) {
            float *row = patches + (size_t)(py * w + px) * K;
            for (int c = 0; c < 3; c++)
                for (int ky = 0; ky < P; ky++)
                    memcpy(row + (c * P + ky) * P, x + ((size_t)c * H + py * P + ky) * W + px * P, sizeof(float) * P);
        }
    rc = g3d_nn_lin_forward(&m->pe, patches, np, K, X + D, D, NULL);
    if (rc != G3D_OK) goto done;
    if (trace && trace->want && !(trace->patch_embed = dup(X + D, (size_t)np * D))) {
        rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        goto done;
    }
    memcpy(X, m->cls, sizeof(float) * (size_t)D);
    resize_pos(m, h, w, T);
    g3d_nn_add(X, T, nd);

    int next = 0;
    for (int bi = 0; bi < m->depth && rc == G3D_OK; bi++) {
        const dino_block *b = &m->blocks[bi];
        /* X += ls1 * proj(attn(qkv(norm1(X)))); X += ls2 * fc2(GELU(fc1(norm2(X)))): LayerScale,
         * residual and GELU ride in the products' epilogues */
        const g3d_nn_epi res1 = {.scale = b->ls1, .res = X}, gelu = {.act = G3D_ACT_GELU}, res2 = {.scale = b->ls2, .res = X};
        g3d_nn_layernorm(X, n, D, b->n1w, b->n1b, LN_EPS, T);
        rc = g3d_nn_lin_forward(&b->qkv, T, n, D, big, 3 * D, NULL);
        if (rc == G3D_OK) rc = g3d_nn_attention(big, n, D / HEAD_DIM, HEAD_DIM, 1.0f / sqrtf((float)HEAD_DIM), A);
        if (rc == G3D_OK) rc = g3d_nn_lin_forward(&b->proj, A, n, D, X, D, &res1);
        if (rc != G3D_OK) break;
        g3d_nn_layernorm(X, n, D, b->n2w, b->n2b, LN_EPS, T);
        rc = g3d_nn_lin_forward(&b->fc1, T, n, D, big, m->hidden, &gelu);
        if (rc == G3D_OK) rc = g3d_nn_lin_forward(&b->fc2, big, n, m->hidden, X, D, &res2);
        if (rc != G3D_OK) break;
        if (trace && trace->want && !(trace->block[bi] = dup(X, nd))) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        if (next < nlayers && layers[next] == bi && rc == G3D_OK) {
            g3d_nn_layernorm(X, n, D, m->normw, m->normb, LN_EPS, T);
            feats[next] = dup(T + D, (size_t)np * D);
            if (cls) cls[next] = dup(T, (size_t)D);
            if (!feats[next] || (cls && !cls[next])) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
            next++;
        }
    }
done:
    free(X); free(T); free(A); free(big); free(patches);
    if (rc != G3D_OK) {
        for (int i = 0; i < nlayers; i++) {
            free(feats[i]);
            feats[i] = NULL;
            if (cls) { free(cls[i]); cls[i] = NULL; }
        }
        g3d_dinov2_trace_free(trace);
    }
    return rc;
}
