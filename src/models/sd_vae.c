/* Stable Diffusion's VAE (ldm's AutoencoderKL: Encoder, quant_conv, post_quant_conv, Decoder)
 * from the original key names; sizes from the tensors. */
#include "gen3d/sd.h"

#include "sd_int.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define GN_EPS 1e-6f   /* ldm's Normalize() in the VAE */

/* AttnBlock: one head over every pixel, q/k/v/proj_out 1x1 convolutions. */
typedef struct vae_attn {
    int c;
    float *g, *b;
    g3d_nn_lin qkv, proj;
} vae_attn;

typedef struct vae_level {
    sd_res *res;
    vae_attn *attn;   /* one per res block, or NULL */
    int has_resample;
    g3d_nn_conv resample;
} vae_level;

struct g3d_sd_vae {
    g3d_sd_vae_config cfg;
    g3d_nn_conv enc_in, enc_out, quant, post_quant, dec_in, dec_out;
    float *enc_ng, *enc_nb, *dec_ng, *dec_nb;
    vae_level *down, *up;
    sd_res enc_mid[2], dec_mid[2];
    vae_attn enc_attn, dec_attn;
};

static const char *const VAE_PREFIXES[] = {"first_stage_model.", ""};

g3d_status g3d_sd_vae_probe(const g3d_ckpt *ck, g3d_sd_vae_config *c)
{
    memset(c, 0, sizeof *c);
    sd_ld ld = {ck, NULL, SD_ORIGINAL, 0, 0};
    if (g3d_ckpt_find(ck, "encoder.down_blocks.0.resnets.0.conv1.weight")) {
        char k[64];
        ld.prefix = "";
        ld.layout = SD_DIFFUSERS_VAE;
        c->diffusers = 1;
        do snprintf(k, sizeof k, "encoder.down_blocks.%d.resnets.0.conv1.weight", ld.levels);
        while (g3d_ckpt_find(ck, k) && ++ld.levels < G3D_SD_MAX_LEVELS);
    }
    for (size_t i = 0; i < sizeof VAE_PREFIXES / sizeof *VAE_PREFIXES && !ld.prefix; i++) {
        sd_ld t = {ck, VAE_PREFIXES[i], SD_ORIGINAL, 0, 0};
        if (sd_find(&t, "encoder.conv_in.weight") && sd_find(&t, "decoder.conv_in.weight")) ld.prefix = t.prefix;
    }
    if (!ld.prefix)
        return G3D_ERR(G3D_ERR_MODEL, "%s: no Stable Diffusion VAE (missing tensor first_stage_model.encoder.conv_in.weight)",
                       g3d_ckpt_path(ck));
    c->prefix = ld.prefix;
    const g3d_tensor_info *ci = sd_find(&ld, "encoder.conv_in.weight"), *di = sd_find(&ld, "decoder.conv_in.weight");
    if (ci->ndim != 4 || di->ndim != 4 || ci->shape[1] != 3)
        return G3D_ERR(G3D_ERR_MODEL, "%s: tensor %sencoder.conv_in.weight is not a 3-channel convolution", g3d_ckpt_path(ck), ld.prefix);
    c->ch = (int)ci->shape[0];
    c->z_ch = (int)di->shape[1];
    while (c->levels < G3D_SD_MAX_LEVELS && sd_find(&ld, "encoder.down.%d.block.0.conv1.weight", c->levels)) {
        const g3d_tensor_info *w = sd_find(&ld, "encoder.down.%d.block.0.conv1.weight", c->levels);
        if (w->ndim != 4 || w->shape[0] % c->ch)
            return G3D_ERR(G3D_ERR_MODEL, "%s: tensor %sencoder.down.%d.block.0.conv1.weight has %lld channels, not a multiple of %d",
                           g3d_ckpt_path(ck), ld.prefix, c->levels, (long long)w->shape[0], c->ch);
        c->mult[c->levels] = (int)(w->shape[0] / c->ch);
        c->levels++;
    }
    while (sd_find(&ld, "encoder.down.0.block.%d.conv1.weight", c->nres)) c->nres++;
    if (!c->levels)
        return G3D_ERR(G3D_ERR_MODEL, "%s: missing tensor %sencoder.down.0.block.0.conv1.weight", g3d_ckpt_path(ck), ld.prefix);
    c->factor = 1 << (c->levels - 1);
    return G3D_OK;
}

const g3d_sd_vae_config *g3d_sd_vae_get_config(const g3d_sd_vae *m) { return &m->cfg; }

static g3d_status attn_load(const sd_ld *ld, vae_attn *a, int c, const char *base)
{
    char n[300];
    memset(a, 0, sizeof *a);
    a->c = c;
    snprintf(n, sizeof n, "%s.norm", base);
    G3D_TRY(sd_vec(ld, &a->g, c, n, "weight"));
    G3D_TRY(sd_vec(ld, &a->b, c, n, "bias"));
    static const char *const qkv[] = {"q", "k", "v"};
    G3D_TRY(sd_lin_packed(ld, &a->qkv, 3, c, c, 1, base, qkv));
    snprintf(n, sizeof n, "%s.proj_out", base);
    return sd_lin_load(ld, &a->proj, c, c, 1, n);
}

static void attn_free(vae_attn *a)
{
    free(a->g);
    free(a->b);
    g3d_nn_lin_free(&a->qkv);
    g3d_nn_lin_free(&a->proj);
}

static void level_free(vae_level *l, int nres)
{
    for (int b = 0; l->res && b < nres; b++) {
        sd_res_free(&l->res[b]);
        if (l->attn) attn_free(&l->attn[b]);
    }
    free(l->res);
    free(l->attn);
    sd_conv_free(&l->resample);
}

void g3d_sd_vae_free(g3d_sd_vae *m)
{
    if (!m) return;
    const g3d_sd_vae_config *c = &m->cfg;
    for (int l = 0; m->down && l < c->levels; l++) level_free(&m->down[l], c->nres);
    for (int l = 0; m->up && l < c->levels; l++) level_free(&m->up[l], c->nres + 1);
    free(m->down);
    free(m->up);
    for (int i = 0; i < 2; i++) sd_res_free(&m->enc_mid[i]), sd_res_free(&m->dec_mid[i]);
    attn_free(&m->enc_attn);
    attn_free(&m->dec_attn);
    g3d_nn_conv *cv[] = {&m->enc_in, &m->enc_out, &m->quant, &m->post_quant, &m->dec_in, &m->dec_out};
    for (size_t i = 0; i < sizeof cv / sizeof *cv; i++) sd_conv_free(cv[i]);
    free(m->enc_ng);
    free(m->enc_nb);
    free(m->dec_ng);
    free(m->dec_nb);
    free(m);
}

/* The res blocks (and attention, where the file has it) of one level of <side>.<down|up>.<l>. */
static g3d_status level_load(const sd_ld *ld, vae_level *L, const char *side, int l, int nres, int cin, int cout)
{
    char n[300];
    L->res = calloc((size_t)nres, sizeof *L->res);
    if (!L->res) return G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the VAE");
    if (sd_find(ld, "%s.%d.attn.0.norm.weight", side, l) && !(L->attn = calloc((size_t)nres, sizeof *L->attn)))
        return G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the VAE");
    for (int b = 0; b < nres; b++) {
        snprintf(n, sizeof n, "%s.%d.block.%d", side, l, b);
        G3D_TRY(sd_res_load(ld, &L->res[b], b ? cout : cin, cout, 0, GN_EPS, n));
        if (L->attn) {
            snprintf(n, sizeof n, "%s.%d.attn.%d", side, l, b);
            G3D_TRY(attn_load(ld, &L->attn[b], cout, n));
        }
    }
    return G3D_OK;
}

/* The decoder's 3x3 convolutions through Winograd: decoding is what every pipeline runs, on
 * maps large enough for F(4x4); its transformed kernels cost 4x the float32 weights (the
 * encoder, used only for image-to-image, stays unprepared). */
static g3d_status dec_prepare(g3d_sd_vae *m)
{
    const g3d_sd_vae_config *c = &m->cfg;
    for (int i = 0; i < 2; i++) {
        G3D_TRY(g3d_nn_conv_prepare(&m->dec_mid[i].c1));
        G3D_TRY(g3d_nn_conv_prepare(&m->dec_mid[i].c2));
    }
    for (int l = 0; l < c->levels; l++) {
        for (int b = 0; b < c->nres + 1; b++) {
            G3D_TRY(g3d_nn_conv_prepare(&m->up[l].res[b].c1));
            G3D_TRY(g3d_nn_conv_prepare(&m->up[l].res[b].c2));
        }
        if (m->up[l].has_resample) G3D_TRY(g3d_nn_conv_prepare(&m->up[l].resample));
    }
    return G3D_OK;
}

static g3d_status vae_build(g3d_sd_vae *m, const g3d_ckpt *ck)
{
    const g3d_sd_vae_config *c = &m->cfg;
    sd_ld ld = {ck, c->prefix, c->diffusers ? SD_DIFFUSERS_VAE : SD_ORIGINAL, c->nres, c->levels};
    char n[300];
    int z = c->z_ch, top = c->ch * c->mult[c->levels - 1];
    m->down = calloc((size_t)c->levels, sizeof *m->down);
    m->up = calloc((size_t)c->levels, sizeof *m->up);
    if (!m->down || !m->up) return G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the VAE");
    G3D_TRY(sd_conv_load(&ld, &m->enc_in, 3, c->ch, 3, 1, "encoder.conv_in"));
    int ch = c->ch;
    for (int l = 0; l < c->levels; l++) {
        G3D_TRY(level_load(&ld, &m->down[l], "encoder.down", l, c->nres, ch, c->ch * c->mult[l]));
        ch = c->ch * c->mult[l];
        if (l < c->levels - 1) {
            snprintf(n, sizeof n, "encoder.down.%d.downsample.conv", l);
            G3D_TRY(sd_conv_load(&ld, &m->down[l].resample, ch, ch, 3, 2, n));
            /* padded (0, 1, 0, 1) by hand before the convolution, as the official code does */
            m->down[l].resample.pad_h = m->down[l].resample.pad_w = 0;
            m->down[l].has_resample = 1;
        }
    }
    for (int s = 0; s < 2; s++) {
        const char *side = s ? "decoder" : "encoder";
        sd_res *mid = s ? m->dec_mid : m->enc_mid;
        for (int i = 0; i < 2; i++) {
            snprintf(n, sizeof n, "%s.mid.block_%d", side, i + 1);
            G3D_TRY(sd_res_load(&ld, &mid[i], top, top, 0, GN_EPS, n));
        }
        snprintf(n, sizeof n, "%s.mid.attn_1", side);
        G3D_TRY(attn_load(&ld, s ? &m->dec_attn : &m->enc_attn, top, n));
    }
    G3D_TRY(sd_vec(&ld, &m->enc_ng, top, "encoder.norm_out", "weight"));
    G3D_TRY(sd_vec(&ld, &m->enc_nb, top, "encoder.norm_out", "bias"));
    G3D_TRY(sd_conv_load(&ld, &m->enc_out, top, 2 * z, 3, 1, "encoder.conv_out"));
    G3D_TRY(sd_conv_load(&ld, &m->quant, 2 * z, 2 * z, 1, 1, "quant_conv"));
    G3D_TRY(sd_conv_load(&ld, &m->post_quant, z, z, 1, 1, "post_quant_conv"));
    G3D_TRY(sd_conv_load(&ld, &m->dec_in, z, top, 3, 1, "decoder.conv_in"));
    ch = top;
    for (int l = c->levels - 1; l >= 0; l--) {
        G3D_TRY(level_load(&ld, &m->up[l], "decoder.up", l, c->nres + 1, ch, c->ch * c->mult[l]));
        ch = c->ch * c->mult[l];
        if (l) {
            snprintf(n, sizeof n, "decoder.up.%d.upsample.conv", l);
            G3D_TRY(sd_conv_load(&ld, &m->up[l].resample, ch, ch, 3, 1, n));
            m->up[l].has_resample = 1;
        }
    }
    G3D_TRY(sd_vec(&ld, &m->dec_ng, ch, "decoder.norm_out", "weight"));
    G3D_TRY(sd_vec(&ld, &m->dec_nb, ch, "decoder.norm_out", "bias"));
    G3D_TRY(sd_conv_load(&ld, &m->dec_out, ch, 3, 3, 1, "decoder.conv_out"));
    return dec_prepare(m);
}

g3d_status g3d_sd_vae_load(const g3d_ckpt *ck, g3d_sd_vae **out)
{
    *out = NULL;
    g3d_sd_vae *m = calloc(1, sizeof *m);
    if (!m) return G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the VAE");
    g3d_status rc = g3d_sd_vae_probe(ck, &m->cfg);
    if (rc == G3D_OK) rc = vae_build(m, ck);
    if (rc != G3D_OK) {
        g3d_sd_vae_free(m);
        return rc;
    }
    *out = m;
    return G3D_OK;
}

/* ---- forward ------------------------------------------------------------------------- */

#define NOMEM G3D_ERR(G3D_ERR_NOMEM, "out of memory in the VAE")

typedef struct vfwd {
    g3d_nn_arena *ar;
    g3d_sd_trace_fn trace;
    void *tctx;
} vfwd;

static void vemit(const vfwd *f, const char *name, const float *x, int c, int h, int w)
{
    if (f->trace) f->trace(f->tctx, name, x, c, h, w);
}

/* x [c, hw] += proj(attention(norm(x))) in place. */
static g3d_status attn_forward(const vae_attn *a, vfwd *f, float *x, int hw)
{
    size_t mark = g3d_nn_arena_mark(f->ar);
    int C = a->c;
    float *g = g3d_nn_arena_floats(f->ar, (size_t)C * hw), *T = g3d_nn_arena_floats(f->ar, (size_t)C * hw);
    float *Q = g3d_nn_arena_floats(f->ar, 3 * (size_t)C * hw), *A = g3d_nn_arena_floats(f->ar, (size_t)C * hw);
    if (!g || !T || !Q || !A) return NOMEM;
    g3d_nn_groupnorm(x, C, hw, 32, a->g, a->b, GN_EPS, G3D_ACT_NONE, g);
    sd_transpose(g, C, hw, T, 0);
    G3D_TRY(g3d_nn_lin_forward(&a->qkv, T, hw, 0, Q, 0, NULL));
    g3d_nn_attn at = {.nq = hw, .nk = hw, .heads = 1, .hd = C, .q = Q, .k = Q + C, .v = Q + 2 * C, .ldq = 3 * C,
                      .ldk = 3 * C, .ldv = 3 * C, .out = A, .scale = 1.0f / sqrtf((float)C)};
    G3D_TRY(g3d_nn_attend(&at));
    G3D_TRY(g3d_nn_lin_forward(&a->proj, A, hw, 0, T, 0, NULL));
    sd_transpose(T, hw, C, x, 1);
    g3d_nn_arena_reset(f->ar, mark);
    return G3D_OK;
}

/* The current map lives alone at the arena offset `base`: a step computes its successor above it,
 * then moves it down to base, so the decoder holds one full-resolution map at a time. base is
 * never 0 (see run_base): resetting an arena to 0 merges its chunks, freeing the successor. */
static float *settle(vfwd *f, size_t base, const float *y, size_t n)
{
    g3d_nn_arena_reset(f->ar, base);
    float *x = g3d_nn_arena_floats(f->ar, n);   /* fits where the old map was, or further up */
    if (x && x != y) memmove(x, y, sizeof(float) * n);
    return x;
}

/* *x [cin, h, w] at base -> [r->cout, h, w] at base. */
static g3d_status res_step(const sd_res *r, vfwd *f, float **x, size_t base, int h, int w)
{
    size_t hw = (size_t)h * w;
    float *y = g3d_nn_arena_floats(f->ar, (size_t)r->cout * hw);
    int big = r->cin > r->cout ? r->cin : r->cout;
    float *tmp = g3d_nn_arena_floats(f->ar, (size_t)big * hw + r->cout);
    if (!y || !tmp) return NOMEM;
    G3D_TRY(sd_res_forward(r, *x, h, w, NULL, y, tmp));
    return (*x = settle(f, base, y, (size_t)r->cout * hw)) ? G3D_OK : NOMEM;
}

static g3d_status level_forward(const vae_level *L, int nres, vfwd *f, float **x, size_t base, int h, int w)
{
    for (int b = 0; b < nres; b++) {
        G3D_TRY(res_step(&L->res[b], f, x, base, h, w));
        if (L->attn) G3D_TRY(attn_forward(&L->attn[b], f, *x, h * w));
    }
    return G3D_OK;
}

static g3d_status mid_forward(const sd_res *mid, const vae_attn *a, vfwd *f, float **x, size_t base, int h, int w)
{
    G3D_TRY(res_step(&mid[0], f, x, base, h, w));
    G3D_TRY(attn_forward(a, f, *x, h * w));
    return res_step(&mid[1], f, x, base, h, w);
}

/* GroupNorm + SiLU, then conv (3x3) into out. */
static g3d_status norm_conv(vfwd *f, const float *x, int c, int h, int w, const float *g, const float *b,
                            const g3d_nn_conv *cv, float *out)
{
    float *t = g3d_nn_arena_floats(f->ar, (size_t)c * h * w);
    if (!t) return NOMEM;
    g3d_nn_groupnorm(x, c, h * w, 32, g, b, GN_EPS, G3D_ACT_SILU, t);
    return g3d_nn_conv_forward(cv, t, h, w, out, NULL);
}

/* A non-zero base offset for settle. */
static size_t run_base(vfwd *f)
{
    return g3d_nn_arena_floats(f->ar, 1) ? g3d_nn_arena_mark(f->ar) : 0;
}

static g3d_status encode_run(const g3d_sd_vae *m, vfwd *f, const float *rgb, int H, int W, float *moments)
{
    const g3d_sd_vae_config *c = &m->cfg;
    int h = H, w = W, ch = c->ch;
    size_t base = run_base(f);
    if (!base) return NOMEM;
    float *x = g3d_nn_arena_floats(f->ar, (size_t)ch * h * w);
    if (!x) return NOMEM;
    G3D_TRY(g3d_nn_conv_forward(&m->enc_in, rgb, h, w, x, NULL));
    for (int l = 0; l < c->levels; l++) {
        G3D_TRY(level_forward(&m->down[l], c->nres, f, &x, base, h, w));
        ch = c->ch * c->mult[l];
        if (m->down[l].has_resample) {
            float *p = g3d_nn_arena_floats(f->ar, (size_t)ch * (h + 1) * (w + 1));
            float *y = g3d_nn_arena_floats(f->ar, (size_t)ch * (h / 2) * (w / 2));
            if (!p || !y) return NOMEM;
            G3D_TRY(g3d_nn_pad2d(x, ch, h, w, 0, 1, 0, 1, G3D_PAD_ZEROS, p));
            G3D_TRY(g3d_nn_conv_forward(&m->down[l].resample, p, h + 1, w + 1, y, NULL));
            h /= 2, w /= 2;
            if (!(x = settle(f, base, y, (size_t)ch * h * w))) return NOMEM;
        }
    }
    G3D_TRY(mid_forward(m->enc_mid, &m->enc_attn, f, &x, base, h, w));
    vemit(f, "enc_mid", x, ch, h, w);
    float *e = g3d_nn_arena_floats(f->ar, 2 * (size_t)c->z_ch * h * w);
    if (!e) return NOMEM;
    G3D_TRY(norm_conv(f, x, ch, h, w, m->enc_ng, m->enc_nb, &m->enc_out, e));
    G3D_TRY(g3d_nn_conv_forward(&m->quant, e, h, w, moments, NULL));
    vemit(f, "moments", moments, 2 * c->z_ch, h, w);
    return G3D_OK;
}

static g3d_status decode_run(const g3d_sd_vae *m, vfwd *f, const float *z, int h, int w, float *rgb)
{
    const g3d_sd_vae_config *c = &m->cfg;
    int ch = c->ch * c->mult[c->levels - 1];
    size_t base = run_base(f);
    if (!base) return NOMEM;
    float *q = g3d_nn_arena_floats(f->ar, (size_t)c->z_ch * h * w), *x = g3d_nn_arena_floats(f->ar, (size_t)ch * h * w);
    if (!q || !x) return NOMEM;
    G3D_TRY(g3d_nn_conv_forward(&m->post_quant, z, h, w, q, NULL));
    G3D_TRY(g3d_nn_conv_forward(&m->dec_in, q, h, w, x, NULL));
    if (!(x = settle(f, base, x, (size_t)ch * h * w))) return NOMEM;
    vemit(f, "dec_conv_in", x, ch, h, w);
    G3D_TRY(mid_forward(m->dec_mid, &m->dec_attn, f, &x, base, h, w));
    vemit(f, "dec_mid", x, ch, h, w);
    for (int l = c->levels - 1; l >= 0; l--) {
        G3D_TRY(level_forward(&m->up[l], c->nres + 1, f, &x, base, h, w));
        ch = c->ch * c->mult[l];
        if (m->up[l].has_resample) {
            float *u = g3d_nn_arena_floats(f->ar, (size_t)ch * 4 * h * w), *y = g3d_nn_arena_floats(f->ar, (size_t)ch * 4 * h * w);
            if (!u || !y) return NOMEM;
            g3d_nn_upsample2x(x, ch, h, w, u);
            h *= 2, w *= 2;
            G3D_TRY(g3d_nn_conv_forward(&m->up[l].resample, u, h, w, y, NULL));
            if (!(x = settle(f, base, y, (size_t)ch * h * w))) return NOMEM;
        }
        char n[24];
        snprintf(n, sizeof n, "dec_up%d", l);
        vemit(f, n, x, ch, h, w);
    }
    return norm_conv(f, x, ch, h, w, m->dec_ng, m->dec_nb, &m->dec_out, rgb);
}

g3d_status g3d_sd_vae_encode(const g3d_sd_vae *m, const float *rgb, int H, int W, float *moments, g3d_sd_trace_fn trace,
                             void *trace_ctx)
{
    int fct = m->cfg.factor;
    if (H < fct || W < fct || H % fct || W % fct)
        return G3D_ERR(G3D_ERR_ARG, "picture %dx%d: width and height must be multiples of %d", W, H, fct);
    vfwd f = {g3d_nn_arena_new(0), trace, trace_ctx};
    if (!f.ar) return NOMEM;
    g3d_status rc = encode_run(m, &f, rgb, H, W, moments);
    g3d_nn_arena_free(f.ar);
    return rc;
}

g3d_status g3d_sd_vae_decode(const g3d_sd_vae *m, const float *z, int h, int w, float *rgb, g3d_sd_trace_fn trace,
                             void *trace_ctx)
{
    if (h < 1 || w < 1) return G3D_ERR(G3D_ERR_ARG, "latent %dx%d: empty", w, h);
    vfwd f = {g3d_nn_arena_new(0), trace, trace_ctx};
    if (!f.ar) return NOMEM;
    g3d_status rc = decode_run(m, &f, z, h, w, rgb);
    g3d_nn_arena_free(f.ar);
    return rc;
}

/* Tile origins along one side: n tiles of `tile` covering `size` with at least `overlap` shared. */
static int tile_starts(int size, int tile, int overlap, int *o, int max)
{
    if (tile >= size) {
        o[0] = 0;
        return 1;
    }
    int n = 1 + (size - tile + (tile - overlap) - 1) / (tile - overlap);
    if (n > max) n = max;
    for (int i = 0; i < n; i++) o[i] = (int)((long)(size - tile) * i / (n - 1));
    return n;
}

/* Weight of a picture position p in a tile [a, a + len) whose neighbours overlap it: a ramp up
 * over the shared part at each inner edge. */
static float ramp(int p, int a, int len, int lo_shared, int hi_shared)
{
    float wgt = 1.0f;
    if (lo_shared > 0 && p - a < lo_shared) wgt = (float)(p - a + 1) / (float)(lo_shared + 1);
    if (hi_shared > 0 && a + len - 1 - p < hi_shared) {
        float v = (float)(a + len - p) / (float)(hi_shared + 1);
        wgt = v < wgt ? v : wgt;
    }
    return wgt;
}

g3d_status g3d_sd_vae_decode_tiled(const g3d_sd_vae *m, const float *z, int h, int w, int tile, int overlap, float *rgb)
{
    if (tile < 1 || overlap < 0 || overlap >= tile) return G3D_ERR(G3D_ERR_ARG, "tile %d, overlap %d: 0 <= overlap < tile expected", tile, overlap);
    int f = m->cfg.factor, zc = m->cfg.z_ch, oy[256], ox[256];
    int ny = tile_starts(h, tile, overlap, oy, 256), nx = tile_starts(w, tile, overlap, ox, 256);
    int th = tile < h ? tile : h, tw = tile < w ? tile : w;
    size_t H = (size_t)h * f, W = (size_t)w * f;
    float *zt = malloc(sizeof(float) * zc * th * tw), *rt = malloc(sizeof(float) * 3 * th * f * tw * f);
    float *acc = calloc(H * W, sizeof(float));
    g3d_status rc = zt && rt && acc ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory in the VAE");
    if (rc == G3D_OK) memset(rgb, 0, sizeof(float) * 3 * H * W);
    for (int iy = 0; rc == G3D_OK && iy < ny; iy++)
        for (int ix = 0; rc == G3D_OK && ix < nx; ix++) {
            for (int c = 0; c < zc; c++)
                for (int y = 0; y < th; y++)
                    memcpy(zt + ((size_t)c * th + y) * tw, z + ((size_t)c * h + oy[iy] + y) * w + ox[ix], sizeof(float) * tw);
            rc = g3d_sd_vae_decode(m, zt, th, tw, rt, NULL, NULL);
            if (rc != G3D_OK) break;
            /* picture pixels shared with the previous / next tile along each axis */
            int sy0 = iy ? (oy[iy - 1] + th - oy[iy]) * f : 0, sy1 = iy + 1 < ny ? (oy[iy] + th - oy[iy + 1]) * f : 0;
            int sx0 = ix ? (ox[ix - 1] + tw - ox[ix]) * f : 0, sx1 = ix + 1 < nx ? (ox[ix] + tw - ox[ix + 1]) * f : 0;
            int Y0 = oy[iy] * f, X0 = ox[ix] * f, TH = th * f, TW = tw * f;
            for (int y = 0; y < TH; y++)
                for (int x = 0; x < TW; x++) {
                    float wgt = ramp(Y0 + y, Y0, TH, sy0, sy1) * ramp(X0 + x, X0, TW, sx0, sx1);
                    size_t o = (size_t)(Y0 + y) * W + X0 + x;
                    acc[o] += wgt;
                    for (int c = 0; c < 3; c++) rgb[c * H * W + o] += wgt * rt[((size_t)c * TH + y) * TW + x];
                }
        }
    for (size_t i = 0; rc == G3D_OK && i < H * W; i++)
        for (int c = 0; c < 3; c++) rgb[c * H * W + i] /= acc[i];
    free(zt);
    free(rt);
    free(acc);
    return rc;
}
