/* Segment Anything: the prompt encoder (random Fourier positions, point and box embeddings, the
 * mask-input branch), the two-way transformer mask decoder, and SamPredictor.predict's pre- and
 * post-processing of one prompt. */
#include "sam_int.h"

#include "gen3d/resize.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define DEC_LN_EPS 1e-5f /* nn.LayerNorm's default in the two-way transformer */
#define LN2D_EPS 1e-6f

/* PositionEmbeddingRandom._pe_encoding of a point already divided by the input size. */
static void pe_encode(const g3d_sam *m, float cx, float cy, float *out)
{
    const int F = m->C / 2;
    const float tau = (float)(2.0 * M_PI);
    float a = 2 * cx - 1, b = 2 * cy - 1;
    for (int j = 0; j < F; j++) {
        float v = (a * m->gauss[j] + b * m->gauss[F + j]) * tau;
        out[j] = sinf(v);
        out[F + j] = cosf(v);
    }
}

/* get_dense_pe(): [C, g, g] */
static void dense_pe(const g3d_sam *m, float *pe)
{
    const int g = m->grid, C = m->C;
    float *v = malloc(sizeof(float) * C);
    if (!v) return;
    for (int y = 0; y < g; y++)
        for (int x = 0; x < g; x++) {
            pe_encode(m, ((float)x + 1 - 0.5f) / (float)g, ((float)y + 1 - 0.5f) / (float)g, v);
            for (int c = 0; c < C; c++) pe[((size_t)c * g + y) * g + x] = v[c];
        }
    free(v);
}

/* The sparse embeddings [n, C] of points (input-frame coordinates, already scaled by
 * ResizeLongestSide) and a box; a padding point is added when there is no box. */
static int sparse_embed(const g3d_sam *m, int np, const double *pts, const int *labels, const double *box,
                        int round_early, float *out)
{
    const int C = m->C, S = m->S;
    int n = 0;
    for (int i = 0; i <= np; i++) {
        if (i == np && box) break;
        int lab = i < np ? labels[i] : -1;
        float *e = out + (size_t)n++ * C;
        if (lab == -1) {
            memcpy(e, m->not_a_point, sizeof(float) * C);
            continue;
        }
        /* The predictor hands torch float32 coordinates; the generator float64 ones, made float32
         * only after dividing by the input size. */
        float cx, cy;
        if (round_early) {
            cx = ((float)pts[2 * i] + 0.5f) / (float)S;
            cy = ((float)pts[2 * i + 1] + 0.5f) / (float)S;
        } else {
            cx = (float)((pts[2 * i] + 0.5) / S);
            cy = (float)((pts[2 * i + 1] + 0.5) / S);
        }
        pe_encode(m, cx, cy, e);
        if (lab == 0 || lab == 1)
            for (int c = 0; c < C; c++) e[c] += m->point_emb[lab][c];
    }
    if (box)
        for (int k = 0; k < 2; k++) {
            float *e = out + (size_t)n++ * C;
            pe_encode(m, ((float)box[2 * k] + 0.5f) / (float)S, ((float)box[2 * k + 1] + 0.5f) / (float)S, e);
            for (int c = 0; c < C; c++) e[c] += m->point_emb[2 + k][c];
        }
    return n;
}

/* mask_downscaling: [4g, 4g] logits -> [C, g, g]. */
static g3d_status mask_embed(const g3d_sam *m, const float *mask, float *out)
{
    const int g = m->grid, mc = m->mask_ch, mq = mc / 4;
    float *a = malloc(sizeof(float) * (size_t)mq * 4 * g * g), *b = malloc(sizeof(float) * (size_t)mc * g * g);
    g3d_status rc = a && b ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_nn_conv c0 = g3d_nn_conv_make(1, mq, 2, 2, 0, m->md0w, m->md0b), c3 = g3d_nn_conv_make(mq, mc, 2, 2, 0, m->md3w, m->md3b),
                c6 = g3d_nn_conv_make(mc, m->C, 1, 1, 0, m->md6w, m->md6b);
    if (rc == G3D_OK) rc = g3d_nn_conv_forward(&c0, mask, 4 * g, 4 * g, a, NULL);
    if (rc == G3D_OK) {
        g3d_nn_layernorm2d(a, mq, 4 * g * g, m->md1w, m->md1b, LN2D_EPS, a);
        g3d_nn_gelu(a, (size_t)mq * 4 * g * g);
        rc = g3d_nn_conv_forward(&c3, a, 2 * g, 2 * g, b, NULL);
    }
    if (rc == G3D_OK) {
        g3d_nn_layernorm2d(b, mc, g * g, m->md4w, m->md4b, LN2D_EPS, b);
        g3d_nn_gelu(b, (size_t)mc * g * g);
        rc = g3d_nn_conv_forward(&c6, b, g, g, out, NULL);
    }
    free(a);
    free(b);
    return rc;
}

/* SAM's Attention: q [nq, C], k [nk, C], v [nk, C] -> out [nq, C] (added to res when res). */
static g3d_status attend(const sam_attn *at, const float *q, int nq, const float *k, const float *v, int nk,
                         float *out, const float *res)
{
    const int I = at->internal, hd = I / SAM_DEC_HEADS;
    float *Q = malloc(sizeof(float) * (size_t)nq * I), *K = malloc(sizeof(float) * (size_t)nk * I);
    float *V = malloc(sizeof(float) * (size_t)nk * I), *O = malloc(sizeof(float) * (size_t)nq * I);
    g3d_status rc = Q && K && V && O ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) rc = g3d_nn_lin_forward(&at->q, q, nq, 0, Q, 0, NULL);
    if (rc == G3D_OK) rc = g3d_nn_lin_forward(&at->k, k, nk, 0, K, 0, NULL);
    if (rc == G3D_OK) rc = g3d_nn_lin_forward(&at->v, v, nk, 0, V, 0, NULL);
    if (rc == G3D_OK) {
        g3d_nn_attn a = {.nq = nq, .nk = nk, .heads = SAM_DEC_HEADS, .hd = hd, .q = Q, .k = K, .v = V, .out = O,
                         .scale = 1.0f / sqrtf((float)hd)};
        rc = g3d_nn_attend(&a);
    }
    g3d_nn_epi e = {G3D_ACT_NONE, NULL, res};
    if (rc == G3D_OK) rc = g3d_nn_lin_forward(&at->o, O, nq, 0, out, 0, res ? &e : NULL);
    free(Q); free(K); free(V); free(O);
    return rc;
}

static void add_into(float *dst, const float *a, const float *b, size_t n)
{
    for (size_t i = 0; i < n; i++) dst[i] = a[i] + b[i];
}

/* SAM's MLP (ReLU between layers) on one row. */
static g3d_status mlp_row(const sam_mlp *m, const float *x, float *y, float *tmp)
{
    const float *in = x;
    for (int i = 0; i < m->n; i++) {
        float *o = i == m->n - 1 ? y : tmp + (i % 2) * m->l[0].out;
        g3d_nn_epi relu = {G3D_ACT_RELU, NULL, NULL};
        G3D_TRY(g3d_nn_lin_forward(&m->l[i], in, 1, 0, o, 0, i == m->n - 1 ? NULL : &relu));
        in = o;
    }
    return G3D_OK;
}

/* MaskDecoder.predict_masks: tokens Q [nt, C] (iou token, mask tokens, sparse prompts) over the
 * image src [C, g*g] (embedding + dense prompt) with positions pe [C, g*g]. Writes every mask's
 * low-resolution logits [nmask, 4g, 4g] and IoU [nmask]. */
static g3d_status decode(const g3d_sam *m, float *Q, int nt, const float *src, const float *pe, float *masks,
                         float *iou, g3d_sam_trace *tr)
{
    const int C = m->C, g = m->grid, N = g * g;
    size_t nc = (size_t)N * C, tc = (size_t)nt * C;
    float *K = malloc(sizeof(float) * nc), *KPE = malloc(sizeof(float) * nc), *kk = malloc(sizeof(float) * nc);
    float *QPE = sam_dup(Q, tc), *qq = malloc(sizeof(float) * tc), *H = malloc(sizeof(float) * (size_t)nt * m->dec_hidden);
    float *U0 = malloc(sizeof(float) * (size_t)C / 4 * 4 * N), *U1 = malloc(sizeof(float) * (size_t)C / 8 * 16 * N);
    float *hyp = malloc(sizeof(float) * (size_t)C / 8), *tmp = malloc(sizeof(float) * 2 * (size_t)(C + m->iou_head.l[0].out));
    g3d_status rc = G3D_OK;
    if (!K || !KPE || !kk || !QPE || !qq || !H || !U0 || !U1 || !hyp || !tmp) {
        rc = G3D_ERR(G3D_ERR_NOMEM, "SAM: out of memory for the mask decoder");
        goto done;
    }
    sam_transpose(src, C, N, K);
    sam_transpose(pe, C, N, KPE);
    for (int i = 0; i < m->ndec && rc == G3D_OK; i++) {
        const sam_dec_layer *d = &m->layers[i];
        if (i == 0) { /* skip_first_layer_pe: no positions and no residual */
            memcpy(qq, Q, sizeof(float) * tc);
            rc = attend(&d->self, qq, nt, qq, qq, nt, Q, NULL);
        } else {
            add_into(qq, Q, QPE, tc);
            rc = attend(&d->self, qq, nt, qq, Q, nt, Q, Q);
        }
        if (rc != G3D_OK) break;
        g3d_nn_layernorm(Q, nt, C, d->n1w, d->n1b, DEC_LN_EPS, Q);
        add_into(qq, Q, QPE, tc);
        add_into(kk, K, KPE, nc);
        if ((rc = attend(&d->t2i, qq, nt, kk, K, N, Q, Q)) != G3D_OK) break;
        g3d_nn_layernorm(Q, nt, C, d->n2w, d->n2b, DEC_LN_EPS, Q);
        g3d_nn_epi relu = {G3D_ACT_RELU, NULL, NULL}, res = {G3D_ACT_NONE, NULL, Q};
        if ((rc = g3d_nn_lin_forward(&d->lin1, Q, nt, 0, H, 0, &relu)) != G3D_OK) break;
        if ((rc = g3d_nn_lin_forward(&d->lin2, H, nt, 0, Q, 0, &res)) != G3D_OK) break;
        g3d_nn_layernorm(Q, nt, C, d->n3w, d->n3b, DEC_LN_EPS, Q);
        add_into(qq, Q, QPE, tc);
        if ((rc = attend(&d->i2t, kk, N, qq, Q, nt, K, K)) != G3D_OK) break;
        g3d_nn_layernorm(K, N, C, d->n4w, d->n4b, DEC_LN_EPS, K);
    }
    if (rc != G3D_OK) goto done;
    add_into(qq, Q, QPE, tc);
    add_into(kk, K, KPE, nc);
    if ((rc = attend(&m->final_attn, qq, nt, kk, K, N, Q, Q)) != G3D_OK) goto done;
    g3d_nn_layernorm(Q, nt, C, m->nfw, m->nfb, DEC_LN_EPS, Q);
    if (tr && tr->want) {
        tr->ntokens = nt;
        if (!(tr->tokens = sam_dup(Q, tc)) || !(tr->keys = sam_dup(K, nc))) {
            rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
            goto done;
        }
    }
    /* output_upscaling: ConvTranspose 2x2/2, LayerNorm2d, GELU, ConvTranspose 2x2/2, GELU */
    sam_transpose(K, N, C, kk);
    g3d_nn_conv t0 = {.cin = C, .cout = C / 4, .kh = 2, .kw = 2, .stride = 2, .transposed = 1, .w = m->up0w, .b = m->up0b};
    g3d_nn_conv t1 = {.cin = C / 4, .cout = C / 8, .kh = 2, .kw = 2, .stride = 2, .transposed = 1, .w = m->up3w, .b = m->up3b};
    if ((rc = g3d_nn_conv_forward(&t0, kk, g, g, U0, NULL)) != G3D_OK) goto done;
    g3d_nn_layernorm2d(U0, C / 4, 4 * N, m->uplnw, m->uplnb, LN2D_EPS, U0);
    g3d_nn_gelu(U0, (size_t)C / 4 * 4 * N);
    if ((rc = g3d_nn_conv_forward(&t1, U0, 2 * g, 2 * g, U1, NULL)) != G3D_OK) goto done;
    g3d_nn_gelu(U1, (size_t)C / 8 * 16 * N);
    for (int k = 0; k < m->nmask && rc == G3D_OK; k++) {
        if ((rc = mlp_row(&m->hyper[k], Q + (size_t)(1 + k) * C, hyp, tmp)) != G3D_OK) break;
        rc = g3d_nn_matmul(0, 0, 1, 16 * N, C / 8, 1.0f, hyp, C / 8, U1, 16 * N, 0.0f, masks + (size_t)k * 16 * N, 16 * N);
    }
    if (rc == G3D_OK) rc = mlp_row(&m->iou_head, Q, iou, tmp);
done:
    free(K); free(KPE); free(kk); free(QPE); free(qq); free(H); free(U0); free(U1); free(hyp); free(tmp);
    return rc;
}

void g3d_sam_prediction_free(g3d_sam_prediction *p)
{
    if (!p) return;
    free(p->logits);
    free(p->low_res);
    memset(p, 0, sizeof *p);
}

/* Sam.postprocess_masks for one mask: low [L, L] -> out [h, w]; scratch holds S*S floats. */
static g3d_status upscale_mask(const g3d_sam *m, const g3d_sam_image *img, const float *low, float *scratch, float *crop,
                               float *out)
{
    const int S = m->S, L = 4 * m->grid;
    G3D_TRY(g3d_resize_buffer(low, L, L, 1, scratch, S, S, G3D_RESIZE_BILINEAR));
    for (int y = 0; y < img->in_h; y++) memcpy(crop + (size_t)y * img->in_w, scratch + (size_t)y * S, sizeof(float) * img->in_w);
    return g3d_resize_buffer(crop, img->in_w, img->in_h, 1, out, img->w, img->h, G3D_RESIZE_BILINEAR);
}

g3d_status sam_predict_scaled(const g3d_sam *m, const g3d_sam_image *img, int np, const double *pts, const int *labels,
                              const double *box, const float *mask_input, int multimask, int round_early,
                              float iou_floor, g3d_sam_prediction *out, g3d_sam_trace *tr)
{
    memset(out, 0, sizeof *out);
    const int C = m->C, g = m->grid, N = g * g, L = 4 * g, nm = m->nmask;
    int first = multimask && nm > 1 ? 1 : 0, n = multimask && nm > 1 ? nm - 1 : 1;
    int nt_max = 1 + nm + np + 2;
    float *Q = malloc(sizeof(float) * (size_t)nt_max * C), *src = malloc(sizeof(float) * (size_t)C * N);
    float *pe = malloc(sizeof(float) * (size_t)C * N), *low = malloc(sizeof(float) * (size_t)nm * L * L);
    float iou[8];
    float *scratch = malloc(sizeof(float) * (size_t)m->S * m->S), *crop = malloc(sizeof(float) * (size_t)img->in_w * img->in_h);
    out->logits = malloc(sizeof(float) * (size_t)n * img->w * img->h);
    out->low_res = malloc(sizeof(float) * (size_t)n * L * L);
    g3d_status rc = G3D_OK;
    if (!Q || !src || !pe || !low || !scratch || !crop || !out->logits || !out->low_res) {
        rc = G3D_ERR(G3D_ERR_NOMEM, "SAM: out of memory for a prediction");
        goto done;
    }
    memcpy(Q, m->iou_token, sizeof(float) * C);
    memcpy(Q + C, m->mask_tokens, sizeof(float) * (size_t)nm * C);
    int ns = sparse_embed(m, np, pts, labels, box, round_early, Q + (size_t)(1 + nm) * C);
    if (mask_input) {
        if ((rc = mask_embed(m, mask_input, src)) != G3D_OK) goto done;
    } else {
        for (int c = 0; c < C; c++)
            for (int i = 0; i < N; i++) src[(size_t)c * N + i] = m->no_mask[c];
    }
    if (tr && tr->want) {
        tr->nsparse = ns;
        if (!(tr->sparse = sam_dup(Q + (size_t)(1 + nm) * C, (size_t)ns * C)) || !(tr->dense = sam_dup(src, (size_t)C * N))) {
            rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
            goto done;
        }
    }
    g3d_nn_add(src, img->embed, (size_t)C * N);
    dense_pe(m, pe);
    if ((rc = decode(m, Q, 1 + nm + ns, src, pe, low, iou, tr)) != G3D_OK) goto done;
    out->n = n;
    out->w = img->w;
    out->h = img->h;
    out->low = L;
    for (int k = 0; k < n && rc == G3D_OK; k++) {
        out->iou[k] = iou[first + k];
        memcpy(out->low_res + (size_t)k * L * L, low + (size_t)(first + k) * L * L, sizeof(float) * L * L);
        if (!(out->iou[k] > iou_floor))
            memset(out->logits + (size_t)k * img->w * img->h, 0, sizeof(float) * img->w * img->h);
        else
            rc = upscale_mask(m, img, low + (size_t)(first + k) * L * L, scratch, crop,
                          out->logits + (size_t)k * img->w * img->h);
    }
done:
    free(Q); free(src); free(pe); free(low); free(scratch); free(crop);
    if (rc != G3D_OK) g3d_sam_prediction_free(out);
    return rc;
}

g3d_status g3d_sam_predict(const g3d_sam *m, const g3d_sam_image *img, const g3d_sam_prompt *p, int multimask,
                           g3d_sam_prediction *out, g3d_sam_trace *trace)
{
    memset(out, 0, sizeof *out);
    if (!p || ((p->n_points <= 0 || !p->points || !p->labels) && !p->box))
        return G3D_ERR(G3D_ERR_ARG, "SAM: a prompt needs a point or a box");
    if (p->n_points < 0 || p->n_points > 1024) return G3D_ERR(G3D_ERR_ARG, "SAM: %d prompt points (at most 1024)", p->n_points);
    int np = p->points && p->labels ? p->n_points : 0;
    double *pts = malloc(sizeof(double) * 2 * (size_t)(np + 1)), box[4];
    if (!pts) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    /* ResizeLongestSide.apply_coords */
    double sx = (double)img->in_w / img->w, sy = (double)img->in_h / img->h;
    for (int i = 0; i < np; i++) {
        pts[2 * i] = p->points[2 * i] * sx;
        pts[2 * i + 1] = p->points[2 * i + 1] * sy;
    }
    if (p->box)
        for (int k = 0; k < 4; k++) box[k] = p->box[k] * (k % 2 ? sy : sx);
    g3d_status rc = sam_predict_scaled(m, img, np, pts, p->labels, p->box ? box : NULL, p->mask_input, multimask, 1,
                                      -INFINITY, out, trace);
    free(pts);
    return rc;
}
