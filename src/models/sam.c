/* Segment Anything: loading the three parts from the official state dict, and the ViT image
 * encoder (windowed and global attention with decomposed relative positions, then the neck). */
#include "sam_int.h"

#include "gen3d/resize.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define ENC_LN_EPS 1e-6f /* the encoder's LayerNorm and every LayerNorm2d */
static const float PIXEL_MEAN[3] = {123.675f, 116.28f, 103.53f}, PIXEL_STD[3] = {58.395f, 57.12f, 57.375f};

float *sam_dup(const float *x, size_t n)
{
    float *d = malloc(sizeof(float) * (n ? n : 1));
    if (d && n) memcpy(d, x, sizeof(float) * n);
    return d;
}

void sam_transpose(const float *x, int rows, int cols, float *y)
{
#pragma omp parallel for schedule(static) if ((size_t)rows * cols > 65536)
    for (int c = 0; c < cols; c++)
        for (int r = 0; r < rows; r++) y[(size_t)c * rows + r] = x[(size_t)r * cols + c];
}

/* ---- loading ------------------------------------------------------------------------------ */

typedef struct loader {
    const g3d_ckpt *ck;
    g3d_status rc;
} loader;

static void vname(char *buf, size_t n, const char *fmt, va_list ap) { vsnprintf(buf, n, fmt, ap); }

static const g3d_tensor_info *find(const loader *l, const char *fmt, ...)
{
    char name[256];
    va_list ap;
    va_start(ap, fmt);
    vname(name, sizeof name, fmt, ap);
    va_end(ap);
    return g3d_ckpt_find(l->ck, name);
}

/* Reads a float tensor of the given shape into *dst; the first failure sticks in l->rc and later
 * reads do nothing. */
static void rd(loader *l, float **dst, int nd, const int64_t *shape, const char *fmt, ...)
{
    if (l->rc != G3D_OK) return;
    char name[256];
    va_list ap;
    va_start(ap, fmt);
    vname(name, sizeof name, fmt, ap);
    va_end(ap);
    l->rc = g3d_ckpt_read_alloc(l->ck, name, nd, shape, dst);
}

/* A Linear layer `prefix`.weight [out, in] (+ .bias when bias) packed for the product kernel. */
static void rd_lin(loader *l, g3d_nn_lin *L, int out, int in, int bias, const char *fmt, ...)
{
    if (l->rc != G3D_OK) return;
    char prefix[256];
    va_list ap;
    va_start(ap, fmt);
    vname(prefix, sizeof prefix, fmt, ap);
    va_end(ap);
    float *w = NULL, *b = NULL;
    const int64_t ws[] = {out, in}, bs[] = {out};
    rd(l, &w, 2, ws, "%s.weight", prefix);
    if (bias) rd(l, &b, 1, bs, "%s.bias", prefix);
    if (l->rc == G3D_OK) l->rc = g3d_nn_lin_init(L, w, G3D_DT_F32, b, out, in, G3D_DT_F32);
    free(w);
    free(b);
}

static void free_attn(sam_attn *a)
{
    g3d_nn_lin_free(&a->q); g3d_nn_lin_free(&a->k); g3d_nn_lin_free(&a->v); g3d_nn_lin_free(&a->o);
}

static void free_mlp(sam_mlp *m)
{
    for (int i = 0; m->l && i < m->n; i++) g3d_nn_lin_free(&m->l[i]);
    free(m->l);
}

void g3d_sam_free(g3d_sam *m)
{
    if (!m) return;
    free(m->pew); free(m->peb); free(m->pos);
    for (int i = 0; m->blocks && i < m->depth; i++) {
        sam_enc_block *b = &m->blocks[i];
        free(b->n1w); free(b->n1b); free(b->n2w); free(b->n2b); free(b->relh); free(b->relw);
        g3d_nn_lin_free(&b->qkv); g3d_nn_lin_free(&b->proj); g3d_nn_lin_free(&b->lin1); g3d_nn_lin_free(&b->lin2);
    }
    free(m->blocks);
    free(m->neck0); free(m->nln0w); free(m->nln0b); free(m->neck2); free(m->nln1w); free(m->nln1b);
    free(m->gauss);
    for (int i = 0; i < 4; i++) free(m->point_emb[i]);
    free(m->not_a_point); free(m->no_mask);
    free(m->md0w); free(m->md0b); free(m->md1w); free(m->md1b); free(m->md3w); free(m->md3b);
    free(m->md4w); free(m->md4b); free(m->md6w); free(m->md6b);
    for (int i = 0; m->layers && i < m->ndec; i++) {
        sam_dec_layer *d = &m->layers[i];
        free_attn(&d->self); free_attn(&d->t2i); free_attn(&d->i2t);
        free(d->n1w); free(d->n1b); free(d->n2w); free(d->n2b); free(d->n3w); free(d->n3b); free(d->n4w); free(d->n4b);
        g3d_nn_lin_free(&d->lin1); g3d_nn_lin_free(&d->lin2);
    }
    free(m->layers);
    free_attn(&m->final_attn);
    free(m->nfw); free(m->nfb); free(m->iou_token); free(m->mask_tokens);
    free(m->up0w); free(m->up0b); free(m->uplnw); free(m->uplnb); free(m->up3w); free(m->up3b);
    for (int i = 0; m->hyper && i < m->nmask; i++) free_mlp(&m->hyper[i]);
    free(m->hyper);
    free_mlp(&m->iou_head);
    free(m);
}

static void rd_attn(loader *l, sam_attn *a, int C, int internal, const char *prefix)
{
    a->internal = internal;
    rd_lin(l, &a->q, internal, C, 1, "%s.q_proj", prefix);
    rd_lin(l, &a->k, internal, C, 1, "%s.k_proj", prefix);
    rd_lin(l, &a->v, internal, C, 1, "%s.v_proj", prefix);
    rd_lin(l, &a->o, C, internal, 1, "%s.out_proj", prefix);
}

/* The internal width of attention `prefix` (q_proj's rows), checked against the 8 heads. */
static int attn_width(loader *l, int C, const char *prefix)
{
    const g3d_tensor_info *t = find(l, "%s.q_proj.weight", prefix);
    if (l->rc != G3D_OK) return 0;
    if (!t || t->ndim != 2 || t->shape[1] != C || t->shape[0] < SAM_DEC_HEADS || t->shape[0] % SAM_DEC_HEADS) {
        l->rc = G3D_ERR(G3D_ERR_MODEL, "%s: tensor %s.q_proj.weight %s", g3d_ckpt_path(l->ck), prefix,
                        t ? "is not [8k, C]" : "is missing");
        return 0;
    }
    return (int)t->shape[0];
}

/* An MLP of Linear layers `prefix`.layers.N (SAM's MLP class): in -> hidden ... -> out. */
static void rd_mlp(loader *l, sam_mlp *m, int in, int hidden, int out, const char *prefix)
{
    if (l->rc != G3D_OK) return;
    int n = 0;
    while (find(l, "%s.layers.%d.weight", prefix, n)) n++;
    if (n < 1) {
        l->rc = G3D_ERR(G3D_ERR_MODEL, "%s: no tensors %s.layers.*", g3d_ckpt_path(l->ck), prefix);
        return;
    }
    if (!(m->l = calloc((size_t)n, sizeof *m->l))) {
        l->rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        return;
    }
    m->n = n;
    for (int i = 0; i < n; i++)
        rd_lin(l, &m->l[i], i == n - 1 ? out : hidden, i ? hidden : in, 1, "%s.layers.%d", prefix, i);
}

static int count(const loader *l, const char *fmt)
{
    int n = 0;
    while (find(l, fmt, n)) n++;
    return n;
}

static g3d_status shape_err(const loader *l, const char *name, const char *want)
{
    return G3D_ERR(G3D_ERR_MODEL, "%s: tensor %s is missing or not %s", g3d_ckpt_path(l->ck), name, want);
}

static void load_encoder(loader *l, g3d_sam *m)
{
    const g3d_tensor_info *pos = find(l, "image_encoder.pos_embed");
    const g3d_tensor_info *rh = find(l, "image_encoder.blocks.0.attn.rel_pos_h");
    const g3d_tensor_info *fc = find(l, "image_encoder.blocks.0.mlp.lin1.weight");
    const g3d_tensor_info *nk = find(l, "image_encoder.neck.0.weight");
    const g3d_tensor_info *pw = find(l, "image_encoder.patch_embed.proj.weight");
    if (!pos || pos->ndim != 4 || pos->shape[0] != 1 || pos->shape[1] != pos->shape[2] || pos->shape[1] < 1 ||
        pos->shape[1] > 256) {
        l->rc = shape_err(l, "image_encoder.pos_embed", "[1, g, g, D]");
        return;
    }
    m->grid = (int)pos->shape[1];
    m->D = (int)pos->shape[3];
    m->patch = (int)pw->shape[2];
    m->S = m->grid * m->patch;
    if (!rh || rh->ndim != 2 || rh->shape[1] < 1 || m->D % rh->shape[1]) {
        l->rc = shape_err(l, "image_encoder.blocks.0.attn.rel_pos_h", "[2w-1, head width] (SAM without relative positions is not supported)");
        return;
    }
    m->hd = (int)rh->shape[1];
    m->heads = m->D / m->hd;
    if (!fc || fc->ndim != 2 || fc->shape[1] != m->D) {
        l->rc = shape_err(l, "image_encoder.blocks.0.mlp.lin1.weight", "[hidden, D]");
        return;
    }
    m->hidden = (int)fc->shape[0];
    if (!nk || nk->ndim != 4 || nk->shape[1] != m->D) {
        l->rc = shape_err(l, "image_encoder.neck.0.weight", "[C, D, 1, 1]");
        return;
    }
    m->C = (int)nk->shape[0];
    m->depth = count(l, "image_encoder.blocks.%d.norm1.weight");
    if (m->depth < 1 || !(m->blocks = calloc((size_t)m->depth, sizeof *m->blocks))) {
        l->rc = m->depth < 1 ? shape_err(l, "image_encoder.blocks.0.norm1.weight", "[D]")
                             : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        return;
    }
    const int D = m->D, P = m->patch, C = m->C;
    const int64_t d1[] = {D}, pws[] = {D, 3, P, P}, poss[] = {1, m->grid, m->grid, D}, c1[] = {C},
                  n0[] = {C, D, 1, 1}, n2[] = {C, C, 3, 3};
    rd(l, &m->pew, 4, pws, "image_encoder.patch_embed.proj.weight");
    rd(l, &m->peb, 1, d1, "image_encoder.patch_embed.proj.bias");
    rd(l, &m->pos, 4, poss, "image_encoder.pos_embed");
    for (int i = 0; i < m->depth && l->rc == G3D_OK; i++) {
        sam_enc_block *b = &m->blocks[i];
        const g3d_tensor_info *r = find(l, "image_encoder.blocks.%d.attn.rel_pos_h", i);
        int len = r && r->ndim == 2 ? (int)r->shape[0] : 0;
        /* A block attends globally when its table spans the whole grid; otherwise it spans a window. */
        if (len == 2 * m->grid - 1)
            b->window = 0;
        else if (len >= 1 && len % 2 == 1 && len < 2 * m->grid - 1)
            b->window = (len + 1) / 2;
        else {
            char name[96];
            snprintf(name, sizeof name, "image_encoder.blocks.%d.attn.rel_pos_h", i);
            l->rc = shape_err(l, name, "[2w-1, head width] for a window w up to the grid");
            return;
        }
        if (b->window) m->window = b->window;
        const int64_t rs[] = {2 * (b->window ? b->window : m->grid) - 1, m->hd};
        rd(l, &b->n1w, 1, d1, "image_encoder.blocks.%d.norm1.weight", i);
        rd(l, &b->n1b, 1, d1, "image_encoder.blocks.%d.norm1.bias", i);
        rd(l, &b->n2w, 1, d1, "image_encoder.blocks.%d.norm2.weight", i);
        rd(l, &b->n2b, 1, d1, "image_encoder.blocks.%d.norm2.bias", i);
        rd(l, &b->relh, 2, rs, "image_encoder.blocks.%d.attn.rel_pos_h", i);
        rd(l, &b->relw, 2, rs, "image_encoder.blocks.%d.attn.rel_pos_w", i);
        rd_lin(l, &b->qkv, 3 * D, D, 1, "image_encoder.blocks.%d.attn.qkv", i);
        rd_lin(l, &b->proj, D, D, 1, "image_encoder.blocks.%d.attn.proj", i);
        rd_lin(l, &b->lin1, m->hidden, D, 1, "image_encoder.blocks.%d.mlp.lin1", i);
        rd_lin(l, &b->lin2, D, m->hidden, 1, "image_encoder.blocks.%d.mlp.lin2", i);
    }
    rd(l, &m->neck0, 4, n0, "image_encoder.neck.0.weight");
    rd(l, &m->nln0w, 1, c1, "image_encoder.neck.1.weight");
    rd(l, &m->nln0b, 1, c1, "image_encoder.neck.1.bias");
    rd(l, &m->neck2, 4, n2, "image_encoder.neck.2.weight");
    rd(l, &m->nln1w, 1, c1, "image_encoder.neck.3.weight");
    rd(l, &m->nln1b, 1, c1, "image_encoder.neck.3.bias");
}

static void load_prompt_encoder(loader *l, g3d_sam *m)
{
    const int C = m->C;
    const g3d_tensor_info *md = find(l, "prompt_encoder.mask_downscaling.3.weight");
    if (l->rc != G3D_OK) return;
    if (!md || md->ndim != 4 || md->shape[0] < 4 || md->shape[0] % 4) {
        l->rc = shape_err(l, "prompt_encoder.mask_downscaling.3.weight", "[m, m/4, 2, 2]");
        return;
    }
    int mc = m->mask_ch = (int)md->shape[0], mq = mc / 4;
    const int64_t g[] = {2, C / 2}, e[] = {1, C}, w0[] = {mq, 1, 2, 2}, q1[] = {mq}, w3[] = {mc, mq, 2, 2},
                  m1[] = {mc}, w6[] = {C, mc, 1, 1}, c1[] = {C};
    rd(l, &m->gauss, 2, g, "prompt_encoder.pe_layer.positional_encoding_gaussian_matrix");
    for (int i = 0; i < 4; i++) rd(l, &m->point_emb[i], 2, e, "prompt_encoder.point_embeddings.%d.weight", i);
    rd(l, &m->not_a_point, 2, e, "prompt_encoder.not_a_point_embed.weight");
    rd(l, &m->no_mask, 2, e, "prompt_encoder.no_mask_embed.weight");
    rd(l, &m->md0w, 4, w0, "prompt_encoder.mask_downscaling.0.weight");
    rd(l, &m->md0b, 1, q1, "prompt_encoder.mask_downscaling.0.bias");
    rd(l, &m->md1w, 1, q1, "prompt_encoder.mask_downscaling.1.weight");
    rd(l, &m->md1b, 1, q1, "prompt_encoder.mask_downscaling.1.bias");
    rd(l, &m->md3w, 4, w3, "prompt_encoder.mask_downscaling.3.weight");
    rd(l, &m->md3b, 1, m1, "prompt_encoder.mask_downscaling.3.bias");
    rd(l, &m->md4w, 1, m1, "prompt_encoder.mask_downscaling.4.weight");
    rd(l, &m->md4b, 1, m1, "prompt_encoder.mask_downscaling.4.bias");
    rd(l, &m->md6w, 4, w6, "prompt_encoder.mask_downscaling.6.weight");
    rd(l, &m->md6b, 1, c1, "prompt_encoder.mask_downscaling.6.bias");
}

static void load_decoder(loader *l, g3d_sam *m)
{
    const int C = m->C;
    const g3d_tensor_info *mt = find(l, "mask_decoder.mask_tokens.weight");
    const g3d_tensor_info *fc = find(l, "mask_decoder.transformer.layers.0.mlp.lin1.weight");
    if (l->rc != G3D_OK) return;
    if (!mt || mt->ndim != 2 || mt->shape[1] != C || mt->shape[0] < 1 || mt->shape[0] > 8) {
        l->rc = shape_err(l, "mask_decoder.mask_tokens.weight", "[masks, C] with at most 8 masks");
        return;
    }
    if (!fc || fc->ndim != 2 || fc->shape[1] != C) {
        l->rc = shape_err(l, "mask_decoder.transformer.layers.0.mlp.lin1.weight", "[hidden, C]");
        return;
    }
    if (C % 8 || C / 2 % SAM_DEC_HEADS) {
        l->rc = G3D_ERR(G3D_ERR_MODEL, "%s: prompt width %d is not a multiple of 16", g3d_ckpt_path(l->ck), C);
        return;
    }
    m->nmask = (int)mt->shape[0];
    m->dec_hidden = (int)fc->shape[0];
    m->ndec = count(l, "mask_decoder.transformer.layers.%d.norm1.weight");
    if (!(m->layers = calloc((size_t)m->ndec + 1, sizeof *m->layers)) ||
        !(m->hyper = calloc((size_t)m->nmask, sizeof *m->hyper))) {
        l->rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        return;
    }
    const int64_t c1[] = {C}, e1[] = {1, C}, em[] = {m->nmask, C}, u0[] = {C, C / 4, 2, 2}, q1[] = {C / 4},
                  u3[] = {C / 4, C / 8, 2, 2}, o1[] = {C / 8};
    char p[160];
    for (int i = 0; i < m->ndec && l->rc == G3D_OK; i++) {
        sam_dec_layer *d = &m->layers[i];
        snprintf(p, sizeof p, "mask_decoder.transformer.layers.%d.self_attn", i);
        rd_attn(l, &d->self, C, attn_width(l, C, p), p);
        snprintf(p, sizeof p, "mask_decoder.transformer.layers.%d.cross_attn_token_to_image", i);
        rd_attn(l, &d->t2i, C, attn_width(l, C, p), p);
        snprintf(p, sizeof p, "mask_decoder.transformer.layers.%d.cross_attn_image_to_token", i);
        rd_attn(l, &d->i2t, C, attn_width(l, C, p), p);
        float **norms[8] = {&d->n1w, &d->n1b, &d->n2w, &d->n2b, &d->n3w, &d->n3b, &d->n4w, &d->n4b};
        for (int k = 0; k < 8; k++)
            rd(l, norms[k], 1, c1, "mask_decoder.transformer.layers.%d.norm%d.%s", i, k / 2 + 1, k % 2 ? "bias" : "weight");
        rd_lin(l, &d->lin1, m->dec_hidden, C, 1, "mask_decoder.transformer.layers.%d.mlp.lin1", i);
        rd_lin(l, &d->lin2, C, m->dec_hidden, 1, "mask_decoder.transformer.layers.%d.mlp.lin2", i);
    }
    snprintf(p, sizeof p, "mask_decoder.transformer.final_attn_token_to_image");
    rd_attn(l, &m->final_attn, C, attn_width(l, C, p), p);
    rd(l, &m->nfw, 1, c1, "mask_decoder.transformer.norm_final_attn.weight");
    rd(l, &m->nfb, 1, c1, "mask_decoder.transformer.norm_final_attn.bias");
    rd(l, &m->iou_token, 2, e1, "mask_decoder.iou_token.weight");
    rd(l, &m->mask_tokens, 2, em, "mask_decoder.mask_tokens.weight");
    rd(l, &m->up0w, 4, u0, "mask_decoder.output_upscaling.0.weight");
    rd(l, &m->up0b, 1, q1, "mask_decoder.output_upscaling.0.bias");
    rd(l, &m->uplnw, 1, q1, "mask_decoder.output_upscaling.1.weight");
    rd(l, &m->uplnb, 1, q1, "mask_decoder.output_upscaling.1.bias");
    rd(l, &m->up3w, 4, u3, "mask_decoder.output_upscaling.3.weight");
    rd(l, &m->up3b, 1, o1, "mask_decoder.output_upscaling.3.bias");
    for (int i = 0; i < m->nmask; i++) {
        snprintf(p, sizeof p, "mask_decoder.output_hypernetworks_mlps.%d", i);
        rd_mlp(l, &m->hyper[i], C, C, C / 8, p);
    }
    const g3d_tensor_info *ih = find(l, "mask_decoder.iou_prediction_head.layers.0.weight");
    if (l->rc == G3D_OK && (!ih || ih->ndim != 2 || ih->shape[1] != C))
        l->rc = shape_err(l, "mask_decoder.iou_prediction_head.layers.0.weight", "[hidden, C]");
    if (l->rc == G3D_OK) rd_mlp(l, &m->iou_head, C, (int)ih->shape[0], m->nmask, "mask_decoder.iou_prediction_head");
}

g3d_status g3d_sam_load(const g3d_ckpt *ck, g3d_sam **out)
{
    *out = NULL;
    loader l = {ck, G3D_OK};
    const g3d_tensor_info *pw = find(&l, "image_encoder.patch_embed.proj.weight");
    if (!pw || pw->ndim != 4 || pw->shape[1] != 3 || pw->shape[2] != pw->shape[3] || pw->shape[2] < 1 ||
        pw->shape[2] > 64)
        return G3D_ERR(G3D_ERR_MODEL, "%s: not a Segment Anything checkpoint (tensor "
                                      "image_encoder.patch_embed.proj.weight %s)",
                       g3d_ckpt_path(ck), pw ? "is not [D, 3, p, p]" : "is missing");
    g3d_sam *m = calloc(1, sizeof *m);
    if (!m) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    load_encoder(&l, m);
    load_prompt_encoder(&l, m);
    load_decoder(&l, m);
    if (l.rc != G3D_OK) {
        g3d_sam_free(m);
        return l.rc;
    }
    *out = m;
    return G3D_OK;
}

g3d_status g3d_sam_load_file(const char *path, g3d_sam **out)
{
    *out = NULL;
    g3d_ckpt *ck = NULL;
    G3D_TRY(g3d_ckpt_open(path, &ck));
    g3d_status rc = g3d_sam_load(ck, out);
    g3d_ckpt_free(ck);
    return rc;
}

const char *g3d_sam_describe(const g3d_sam *m, char *buf, size_t n)
{
    int nglobal = 0;
    for (int i = 0; i < m->depth; i++) nglobal += !m->blocks[i].window;
    snprintf(buf, n,
             "Segment Anything: ViT encoder width %d, %d blocks (%d global, windows of %d), %d heads, input %d; "
             "prompt width %d; decoder %d layers, %d masks",
             m->D, m->depth, nglobal, m->window, m->heads, m->S, m->C, m->ndec, m->nmask);
    return buf;
}

int g3d_sam_input_size(const g3d_sam *m) { return m->S; }

void g3d_sam_trace_free(g3d_sam_trace *t)
{
    if (!t) return;
    free(t->input); free(t->patch_embed); free(t->neck); free(t->sparse); free(t->dense); free(t->tokens); free(t->keys);
    for (int i = 0; t->block && i < t->nblocks; i++) free(t->block[i]);
    free(t->block);
    int want = t->want;
    memset(t, 0, sizeof *t);
    t->want = want;
}

void g3d_sam_image_free(g3d_sam_image *img)
{
    if (!img) return;
    free(img->embed);
    memset(img, 0, sizeof *img);
}

uint8_t *g3d_sam_rgb8(const g3d_image *rgb)
{
    size_t n = (size_t)rgb->w * rgb->h * 3;
    uint8_t *p = malloc(n ? n : 1);
    if (!p) return NULL;
    for (size_t i = 0; i < n; i++) {
        float v = rgb->data[i] * 255.0f;
        p[i] = (uint8_t)(v <= 0 ? 0 : v >= 255 ? 255 : lrintf(v));
    }
    return p;
}

/* ---- image encoder ------------------------------------------------------------------------ */

/* Copies the tokens of a g x g grid `grid` [g*g, D] into windows of ws x ws `win` [windows, ws*ws, D]
 * (to_windows), or back (the padding, which the grid does not have, is then dropped). */
static void window_copy(float *win, float *grid, int g, int ws, int D, int to_windows)
{
    const int nside = (g + ws - 1) / ws, L = ws * ws;
    for (int wy = 0; wy < nside; wy++)
        for (int wx = 0; wx < nside; wx++)
            for (int y = 0; y < ws && wy * ws + y < g; y++) {
                int nx = g - wx * ws < ws ? g - wx * ws : ws;
                float *a = win + ((size_t)(wy * nside + wx) * L + y * ws) * D, *b = grid + ((size_t)(wy * ws + y) * g + wx * ws) * D;
                memcpy(to_windows ? a : b, to_windows ? b : a, sizeof(float) * (size_t)nx * D);
            }
}

/* Self-attention of one block over the normalised tokens T [g*g, D] into A [g*g, D]: over the
 * whole grid, or over windows of the grid zero-padded to a multiple of the window (the padded
 * tokens take part as keys, as in the official window_partition). */
static g3d_status enc_attention(const g3d_sam *m, const sam_enc_block *b, float *T, float *A)
{
    const int g = m->grid, D = m->D, ws = b->window ? b->window : g, nside = (g + ws - 1) / ws;
    const int nw = nside * nside, L = ws * ws;
    size_t rows = (size_t)nw * L;
    float *W = b->window ? calloc(rows * D, sizeof(float)) : NULL, *QKV = malloc(sizeof(float) * rows * 3 * D);
    float *O = b->window ? malloc(sizeof(float) * rows * D) : A;
    size_t tab = (size_t)m->heads * ws * L;
    float *rh = malloc(sizeof(float) * tab * nw), *rw = malloc(sizeof(float) * tab * nw);
    g3d_status rc = G3D_OK;
    if ((b->window && (!W || !O)) || !QKV || !rh || !rw) {
        rc = G3D_ERR(G3D_ERR_NOMEM, "SAM: out of memory for attention");
        goto done;
    }
    if (b->window) window_copy(W, T, g, ws, D, 1);
    if ((rc = g3d_nn_lin_forward(&b->qkv, b->window ? W : T, (int)rows, 0, QKV, 0, NULL)) != G3D_OK) goto done;
    for (int w = 0; w < nw && rc == G3D_OK; w++)
        rc = g3d_nn_relpos_tables(QKV + (size_t)w * L * 3 * D, 3 * D, m->heads, m->hd, ws, ws, ws, ws, b->relh, b->relw,
                                  rh + tab * w, rw + tab * w);
    if (rc != G3D_OK) goto done;
    g3d_nn_bias_relpos bias = {rh, rw, L, ws, ws, m->heads};
    g3d_nn_attn a = {.nq = L, .nk = L, .heads = m->heads, .hd = m->hd, .q = QKV, .k = QKV + D, .v = QKV + 2 * D,
                     .ldq = 3 * D, .ldk = 3 * D, .ldv = 3 * D, .out = O, .scale = 1.0f / sqrtf((float)m->hd),
                     .bias = g3d_nn_bias_relpos_fn, .bias_ctx = &bias, .batch = nw, .bsq = (long)L * 3 * D,
                     .bsk = (long)L * 3 * D, .bsv = (long)L * 3 * D, .bso = (long)L * D};
    if ((rc = g3d_nn_attend(&a)) != G3D_OK) goto done;
    if (b->window) window_copy(O, A, g, ws, D, 0);
done:
    free(W); free(QKV); free(rh); free(rw);
    if (O != A) free(O);
    return rc;
}

static g3d_status keep(float **dst, const float *x, size_t n)
{
    return (*dst = sam_dup(x, n)) ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
}

/* The encoder on the prepared input x [3, S, S] -> emb [C, g, g]. */
static g3d_status encode(const g3d_sam *m, const float *x, float *emb, g3d_sam_trace *tr)
{
    const int g = m->grid, D = m->D, N = g * g, C = m->C;
    int tracing = tr && tr->want;
    const size_t wide = (size_t)N * (D > C ? D : C); /* T and A also hold the neck's [N, C] maps */
    float *X = malloc(sizeof(float) * (size_t)N * D), *T = malloc(sizeof(float) * wide);
    float *A = malloc(sizeof(float) * wide), *H = malloc(sizeof(float) * (size_t)N * m->hidden);
    g3d_status rc = G3D_OK;
    if (!X || !T || !A || !H || (tracing && !(tr->block = calloc((size_t)m->depth, sizeof(float *))))) {
        rc = G3D_ERR(G3D_ERR_NOMEM, "SAM: out of memory for the image encoder");
        goto done;
    }
    if (tracing) tr->nblocks = m->depth;
    g3d_nn_conv pe = {.cin = 3, .cout = D, .kh = m->patch, .kw = m->patch, .stride = m->patch, .w = m->pew, .b = m->peb};
    if ((rc = g3d_nn_conv_forward(&pe, x, m->S, m->S, A, NULL)) != G3D_OK) goto done;
    sam_transpose(A, D, N, X);
    if (tracing && (rc = keep(&tr->patch_embed, X, (size_t)N * D)) != G3D_OK) goto done;
    g3d_nn_add(X, m->pos, (size_t)N * D);
    for (int i = 0; i < m->depth && rc == G3D_OK; i++) {
        const sam_enc_block *b = &m->blocks[i];
        g3d_nn_layernorm(X, N, D, b->n1w, b->n1b, ENC_LN_EPS, T);
        if ((rc = enc_attention(m, b, T, A)) != G3D_OK) break;
        g3d_nn_epi res = {G3D_ACT_NONE, NULL, X}, gelu = {G3D_ACT_GELU, NULL, NULL};
        if ((rc = g3d_nn_lin_forward(&b->proj, A, N, 0, X, 0, &res)) != G3D_OK) break;
        g3d_nn_layernorm(X, N, D, b->n2w, b->n2b, ENC_LN_EPS, T);
        if ((rc = g3d_nn_lin_forward(&b->lin1, T, N, 0, H, 0, &gelu)) != G3D_OK) break;
        if ((rc = g3d_nn_lin_forward(&b->lin2, H, N, 0, X, 0, &res)) != G3D_OK) break;
        if (tracing) rc = keep(&tr->block[i], X, (size_t)N * D);
    }
    if (rc != G3D_OK) goto done;
    /* neck: 1x1 convolution (a product over tokens), LayerNorm2d, 3x3 convolution, LayerNorm2d */
    g3d_nn_linear(X, N, D, m->neck0, NULL, C, T);
    sam_transpose(T, N, C, A);
    g3d_nn_layernorm2d(A, C, N, m->nln0w, m->nln0b, ENC_LN_EPS, A);
    g3d_nn_conv c3 = g3d_nn_conv_make(C, C, 3, 1, 1, m->neck2, NULL);
    if ((rc = g3d_nn_conv_forward(&c3, A, g, g, emb, NULL)) != G3D_OK) goto done;
    g3d_nn_layernorm2d(emb, C, N, m->nln1w, m->nln1b, ENC_LN_EPS, emb);
    if (tracing) rc = keep(&tr->neck, emb, (size_t)C * N);
done:
    free(X); free(T); free(A); free(H);
    return rc;
}

g3d_status g3d_sam_set_image(const g3d_sam *m, const uint8_t *rgb, int w, int h, g3d_sam_image *out,
                             g3d_sam_trace *trace)
{
    memset(out, 0, sizeof *out);
    if (w < 1 || h < 1 || w > G3D_MAX_IMAGE_SIDE || h > G3D_MAX_IMAGE_SIDE)
        return G3D_ERR(G3D_ERR_ARG, "SAM: picture of %dx%d pixels (sides must be 1..%d)", w, h, G3D_MAX_IMAGE_SIDE);
    /* ResizeLongestSide.get_preprocess_shape */
    const int S = m->S;
    double scale = (double)S / (w > h ? w : h);
    int nw = (int)(w * scale + 0.5), nh = (int)(h * scale + 0.5);
    if (nw < 1) nw = 1;
    if (nh < 1) nh = 1;
    uint8_t *small = malloc((size_t)nw * nh * 3);
    float *x = calloc((size_t)3 * S * S, sizeof(float));
    float *emb = malloc(sizeof(float) * (size_t)m->C * m->grid * m->grid);
    g3d_status rc = small && x && emb ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "SAM: out of memory for the picture");
    if (rc == G3D_OK) rc = g3d_resize_u8_pil_bilinear(rgb, w, h, 3, small, nw, nh);
    if (rc == G3D_OK) {
        for (int c = 0; c < 3; c++)
            for (int y = 0; y < nh; y++)
                for (int i = 0; i < nw; i++)
                    x[((size_t)c * S + y) * S + i] = ((float)small[((size_t)y * nw + i) * 3 + c] - PIXEL_MEAN[c]) / PIXEL_STD[c];
        if (trace && trace->want) rc = keep(&trace->input, x, (size_t)3 * S * S);
    }
    if (rc == G3D_OK) rc = encode(m, x, emb, trace);
    free(small);
    free(x);
    if (rc != G3D_OK) {
        free(emb);
        return rc;
    }
    *out = (g3d_sam_image){w, h, nw, nh, m->C, m->grid, emb};
    return G3D_OK;
}
