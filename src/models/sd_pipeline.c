/* Stable Diffusion's text-to-image and inpainting loops: prompt -> CLIP tokens -> text
 * embedding -> sampler on the UNet with classifier-free guidance -> VAE decoding; the inpainter
 * plug-in on top. */
#include "gen3d/sd.h"

#include "gen3d/clip_text.h"

#include <cjson/cJSON.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

struct g3d_sd {
    g3d_ckpt *ck[4];   /* the model, the VAE's file, the text encoder's file (NULL: the model's), the ControlNet's */
    g3d_sd_unet *unet;
    g3d_sd_controlnet *cn;
    g3d_sd_vae *vae;
    g3d_clip_text *text;
    g3d_clip_tokenizer *tok;
    int holders;       /* g3d_sd_share calls not yet matched by g3d_sd_free */
};

g3d_sd *g3d_sd_share(g3d_sd *m)
{
    if (m) m->holders++;
    return m;
}

void g3d_sd_free(g3d_sd *m)
{
    if (!m) return;
    if (m->holders > 0) {
        m->holders--;
        return;
    }
    g3d_sd_unet_free(m->unet);
    g3d_sd_vae_free(m->vae);
    g3d_clip_text_free(m->text);
    g3d_clip_tokenizer_free(m->tok);
    g3d_sd_controlnet_free(m->cn);
    for (int i = 0; i < 4; i++) g3d_ckpt_free(m->ck[i]);
    free(m);
}

/* The first floating tensor holding a NaN or an infinity under `prefix`, checked on the raw
 * bits (the exponent all ones) without converting. */
static g3d_status check_finite(const g3d_ckpt *ck, const char *prefix)
{
    size_t pn = strlen(prefix);
    for (int64_t i = 0; i < g3d_ckpt_count(ck); i++) {
        const g3d_tensor_info *t = g3d_ckpt_tensor(ck, i);
        if (strncmp(t->name, prefix, pn)) continue;
        int bad = 0;
        if (t->dtype == G3D_DT_F32) {
            const unsigned char *p = t->data;
            for (int64_t k = 0; k < t->numel && !bad; k++) {
                uint32_t v;
                memcpy(&v, p + 4 * k, 4);
                bad = (v & 0x7f800000u) == 0x7f800000u;
            }
        } else if (t->dtype == G3D_DT_F16 || t->dtype == G3D_DT_BF16) {
            uint16_t mask = t->dtype == G3D_DT_F16 ? 0x7c00u : 0x7f80u;
            const unsigned char *p = t->data;
            for (int64_t k = 0; k < t->numel && !bad; k++) {
                uint16_t v;
                memcpy(&v, p + 2 * k, 2);
                bad = (v & mask) == mask;
            }
        }
        if (bad) return G3D_ERR(G3D_ERR_MODEL, "%s: tensor %s holds NaN or infinite values", g3d_ckpt_path(ck), t->name);
    }
    return G3D_OK;
}

static int is_dir(const char *p)
{
    struct stat st;
    return p && stat(p, &st) == 0 && S_ISDIR(st.st_mode);
}

/* <dir>/<sub>/<the first of names that exists>, malloc'd, or NULL. */
static char *first_file(const char *dir, const char *sub, const char *const *names, int n)
{
    struct stat st;
    for (int i = 0; i < n; i++) {
        size_t len = strlen(dir) + strlen(sub) + strlen(names[i]) + 3;
        char *f = malloc(len);
        if (!f) return NULL;
        snprintf(f, len, "%s/%s/%s", dir, sub, names[i]);
        if (stat(f, &st) == 0 && S_ISREG(st.st_mode)) return f;
        free(f);
    }
    return NULL;
}

/* The text of <dir>/<sub>/<name> (malloc'd), or NULL when there is none. */
static char *read_text(const char *dir, const char *sub, const char *name)
{
    char *f = first_file(dir, sub, &name, 1);
    unsigned char *t = NULL;
    size_t n;
    if (f && g3d_read_file(f, 1 << 20, &t, &n) != G3D_OK) t = NULL;
    free(f);
    return (char *)t;
}

/* Opens a part: a file, or in a diffusers folder <dir>/<sub>/ its weights. */
static g3d_status open_part(g3d_sd *m, int slot, const char *path, const char *sub)
{
    static const char *const unet[] = {"diffusion_pytorch_model.safetensors", "diffusion_pytorch_model.fp16.safetensors",
                                       "diffusion_pytorch_model.bin", "diffusion_pytorch_model.fp16.bin"};
    static const char *const text[] = {"model.safetensors", "model.fp16.safetensors", "pytorch_model.bin", "pytorch_model.fp16.bin"};
    if (!is_dir(path)) return g3d_ckpt_open(path, &m->ck[slot]);
    char *f = first_file(path, sub, strcmp(sub, "text_encoder") ? unet : text, 4);
    if (!f && !strcmp(sub, ".")) return G3D_ERR(G3D_ERR_IO, "%s: neither a checkpoint file nor a folder with diffusion_pytorch_model weights", path);
    if (!f) return G3D_ERR(G3D_ERR_IO, "%s: neither a checkpoint file nor a diffusers folder with %s/ weights", path, sub);
    g3d_status rc = g3d_ckpt_open(f, &m->ck[slot]);
    free(f);
    return rc;
}

/* diffusers' scheduler/scheduler_config.json: prediction_type, or -1. */
static int folder_prediction(const char *dir)
{
    char *t = read_text(dir, "scheduler", "scheduler_config.json");
    cJSON *j = t ? cJSON_Parse(t) : NULL;
    const char *pt = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(j, "prediction_type"));
    int r = pt ? (!strcmp(pt, "v_prediction") ? G3D_SD_PRED_V : G3D_SD_PRED_EPS) : -1;
    cJSON_Delete(j);
    free(t);
    return r;
}

/* The ControlNet: its file, or a diffusers folder (diffusion_pytorch_model.* and config.json);
 * it must fit the UNet and read the VAE's latent. */
static g3d_status load_controlnet(g3d_sd *m, const char *path)
{
    G3D_TRY(open_part(m, 3, path, "."));
    char *cfg = is_dir(path) ? read_text(path, ".", "config.json") : NULL;
    g3d_status rc = g3d_sd_controlnet_load(m->ck[3], cfg, &m->cn);
    free(cfg);
    G3D_TRY(rc);
    const g3d_sd_controlnet_config *cc = g3d_sd_controlnet_get_config(m->cn);
    G3D_TRY(g3d_sd_controlnet_check(cc, path, g3d_sd_unet_get_config(m->unet)));
    if (cc->net.in_ch != g3d_sd_vae_get_config(m->vae)->z_ch)
        return G3D_ERR(G3D_ERR_MODEL, "%s: the ControlNet reads %d latent channels, the VAE gives %d", path, cc->net.in_ch,
                       g3d_sd_vae_get_config(m->vae)->z_ch);
    return check_finite(m->ck[3], cc->net.prefix);
}

static g3d_status sd_build(g3d_sd *m, const g3d_sd_paths *p)
{
    int folder = is_dir(p->model);
    G3D_TRY(open_part(m, 0, p->model, "unet"));
    char *yaml = NULL;
    if (p->yaml) {
        unsigned char *y = NULL;
        size_t n;
        G3D_TRY(g3d_read_file(p->yaml, 1 << 20, &y, &n));
        yaml = (char *)y;
    } else {
        yaml = folder ? read_text(p->model, "unet", "config.json") : g3d_sd_yaml_beside(p->model);
    }
    g3d_status rc = g3d_sd_unet_load(m->ck[0], yaml, &m->unet);
    free(yaml);
    G3D_TRY(rc);
    g3d_sd_unet_config *uc = (g3d_sd_unet_config *)g3d_sd_unet_get_config(m->unet);
    int pred = p->prediction >= 0 ? p->prediction : folder ? folder_prediction(p->model) : -1;
    if (pred >= 0) uc->pred = (g3d_sd_pred)pred;
    G3D_TRY(check_finite(m->ck[0], uc->prefix));
    if (p->vae || folder) G3D_TRY(open_part(m, 1, p->vae ? p->vae : p->model, "vae"));
    const g3d_ckpt *vck = m->ck[1] ? m->ck[1] : m->ck[0];
    G3D_TRY(g3d_sd_vae_load(vck, &m->vae));
    G3D_TRY(check_finite(vck, g3d_sd_vae_get_config(m->vae)->prefix));
    if (p->text_encoder || folder) G3D_TRY(open_part(m, 2, p->text_encoder ? p->text_encoder : p->model, "text_encoder"));
    const g3d_ckpt *tck = m->ck[2] ? m->ck[2] : m->ck[0];
    char *tcfg = !p->text_encoder && folder ? read_text(p->model, "text_encoder", "config.json") : NULL;
    rc = g3d_clip_text_load_ckpt(tck, tcfg, &m->text);
    free(tcfg);
    G3D_TRY(rc);
    const g3d_clip_text_config *tc = g3d_clip_text_get_config(m->text);
    G3D_TRY(check_finite(tck, tc->prefix));
    if (tc->width != uc->context_dim)
        return G3D_ERR(G3D_ERR_MODEL, "%s: the text encoder's width %d is not the UNet's context width %d", g3d_ckpt_path(tck),
                       tc->width, uc->context_dim);
    if (g3d_sd_vae_get_config(m->vae)->z_ch * (uc->in_ch == 9 ? 2 : 1) + (uc->in_ch == 9) != uc->in_ch)
        return G3D_ERR(G3D_ERR_MODEL, "%s: the VAE's %d latent channels do not fit the UNet's %d input channels",
                       g3d_ckpt_path(vck), g3d_sd_vae_get_config(m->vae)->z_ch, uc->in_ch);
    char *tokdir = folder && !p->tokenizer ? g3d_path_join(p->model, "tokenizer") : NULL;
    rc = g3d_clip_tokenizer_load(p->tokenizer ? p->tokenizer : is_dir(tokdir) ? p->model : NULL, &m->tok);
    free(tokdir);
    G3D_TRY(rc);
    g3d_clip_tokenizer_set_openclip(m->tok, tc->family == G3D_CLIP_OPENCLIP);
    return p->controlnet ? load_controlnet(m, p->controlnet) : G3D_OK;
}

g3d_status g3d_sd_load(const g3d_sd_paths *p, g3d_sd **out)
{
    *out = NULL;
    if (!p || !p->model) return G3D_ERR(G3D_ERR_ARG, "no model given");
    g3d_sd *m = calloc(1, sizeof *m);
    if (!m) return G3D_ERR(G3D_ERR_NOMEM, "out of memory loading the model");
    g3d_status rc = sd_build(m, p);
    if (rc != G3D_OK) {
        g3d_sd_free(m);
        return rc;
    }
    *out = m;
    return G3D_OK;
}

const g3d_sd_unet_config *g3d_sd_get_unet(const g3d_sd *m) { return g3d_sd_unet_get_config(m->unet); }

const g3d_sd_controlnet *g3d_sd_get_controlnet(const g3d_sd *m) { return m->cn; }

int g3d_sd_size_multiple(const g3d_sd *m)
{
    return g3d_sd_vae_get_config(m->vae)->factor << (g3d_sd_unet_get_config(m->unet)->levels - 1);
}

g3d_status g3d_sd_check_prompt(const g3d_sd *m, const char *text, int *dropped)
{
    const g3d_clip_text_config *c = g3d_clip_text_get_config(m->text);
    int32_t *ids = malloc(sizeof(int32_t) * (size_t)c->context);
    g3d_clip_tokens info = {0};
    if (!ids) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_status rc = g3d_clip_tokenize(m->tok, text, c->context, 0, ids, &info);
    free(ids);
    *dropped = info.dropped;
    return rc;
}

g3d_sd_params g3d_sd_defaults(void)
{
    g3d_sd_params p = {0};
    p.width = p.height = 512;
    p.sampler = (g3d_sd_sampler){G3D_SD_DDIM, 50, 0.0f, 0, G3D_SD_PRED_EPS};
    p.cfg = 7.5f;
    p.control_scale = 1.0f;
    return p;
}

/* ---- the loop ---------------------------------------------------------------------------- */

typedef struct loop {
    const g3d_sd *m;
    g3d_sd_params *p;
    int h, w, zc;          /* latent size and channels */
    float *cond, *uncond;  /* [77, width] */
    int nctx;
    float *extra;          /* inpainting models: mask [1, h, w] then masked latent [zc, h, w] */
    float *xin, *u;        /* scratch: the UNet's input, the unconditional output */
    float *hint, *res;     /* with a ControlNet: its hint [hint_ch, 8h, 8w], scratch for its residuals */
    /* latent blending (a text-to-image model inpainting) */
    const float *known, *lmask, *noise0;
    g3d_rng rng;
} loop;

static g3d_status encode_text(loop *L, const char *text, float **emb)
{
    const g3d_clip_text_config *c = g3d_clip_text_get_config(L->m->text);
    g3d_clip_tokens info = {0};
    int32_t *ids = malloc(sizeof(int32_t) * (size_t)c->context);
    *emb = malloc(sizeof(float) * (size_t)c->context * c->width);
    g3d_status rc = ids && *emb ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK)
        rc = g3d_clip_tokenize(L->m->tok, text ? text : "", c->context, g3d_clip_text_pad_id(L->m->text, L->m->tok), ids, &info);
    L->p->truncated += info.dropped;
    L->nctx = c->context;
    if (rc == G3D_OK) rc = g3d_clip_text_forward(L->m->text, ids, c->context, *emb, NULL);
    free(ids);
    return rc;
}

static g3d_status run_unet(loop *L, const float *x, float t, const float *ctx, float *out)
{
    const float *in = x;
    if (L->extra) {
        size_t hw = (size_t)L->h * L->w;
        memcpy(L->xin, x, sizeof(float) * L->zc * hw);
        memcpy(L->xin + L->zc * hw, L->extra, sizeof(float) * (L->zc + 1) * hw);
        in = L->xin;
    }
    if (L->hint)
        G3D_TRY(g3d_sd_controlnet_forward(L->m->cn, x, L->h, L->w, t, ctx, L->nctx, L->hint, L->p->control_scale, L->res, NULL, NULL));
    return g3d_sd_unet_forward_controlled(L->m->unet, in, L->h, L->w, t, ctx, L->nctx, L->hint ? L->res : NULL, out, NULL, NULL);
}

static g3d_status model_fn(void *ctx, const float *x, float t, float *out)
{
    loop *L = ctx;
    size_t n = (size_t)L->zc * L->h * L->w;
    if (L->p->cfg == 1.0f) return run_unet(L, x, t, L->cond, out);
    G3D_TRY(run_unet(L, x, t, L->uncond, L->u));
    G3D_TRY(run_unet(L, x, t, L->cond, out));
    float s = L->p->cfg;
    for (size_t i = 0; i < n; i++) out[i] = L->u[i] + s * (out[i] - L->u[i]);
    return G3D_OK;
}

static void noise_fn(void *ctx, float *z, size_t n)
{
    loop *L = ctx;
    for (size_t i = 0; i < n; i++) z[i] = g3d_rng_normal(&L->rng);
}

static int step_fn(void *ctx, int i, int total, float *x, size_t n, float a, float b)
{
    loop *L = ctx;
    if (L->known) {
        /* keep the known region on the trajectory: its latent noised to the next level */
        size_t hw = (size_t)L->h * L->w;
        for (size_t j = 0; j < n; j++) {
            float k = a * L->known[j] + b * L->noise0[j];
            float mm = L->lmask[j % hw];
            x[j] = mm * x[j] + (1.0f - mm) * k;
        }
    }
    return g3d_progress_report(&L->p->progress, "denoise", i + 1, total, NULL);
}

/* rgb [3, H, W] in [-1, 1] -> out (H, W, 3) in [0, 1]. */
static g3d_status to_image(const float *rgb, int W, int H, g3d_image *out)
{
    G3D_TRY(g3d_image_create(out, W, H, 3));
    size_t hw = (size_t)W * H;
    for (size_t i = 0; i < hw; i++)
        for (int c = 0; c < 3; c++) {
            float v = (rgb[c * hw + i] + 1.0f) * 0.5f;
            out->data[i * 3 + c] = v < 0 ? 0 : v > 1 ? 1 : v;
        }
    return G3D_OK;
}

/* The picture (H, W, 3) in [0, 1] as [3, H, W] in [-1, 1], with the masked pixels set to 0
 * (grey) when mask is given. */
static float *from_image(const g3d_image *img, const g3d_image *mask)
{
    size_t hw = (size_t)img->w * img->h;
    float *x = malloc(sizeof(float) * 3 * hw);
    if (!x) return NULL;
    for (size_t i = 0; i < hw; i++)
        for (int c = 0; c < 3; c++) x[c * hw + i] = mask && mask->data[i] > 0.5f ? 0.0f : img->data[i * 3 + c] * 2.0f - 1.0f;
    return x;
}

static g3d_status check_params(const g3d_sd *m, const g3d_sd_params *p)
{
    int k = g3d_sd_size_multiple(m);
    if (!p->prompt) return G3D_ERR(G3D_ERR_ARG, "no prompt");
    if (p->width < k || p->height < k || p->width % k || p->height % k)
        return G3D_ERR(G3D_ERR_ARG, "%dx%d: width and height must be positive multiples of %d for this model", p->width, p->height, k);
    if (!(p->cfg >= 0 && p->cfg < 1000)) return G3D_ERR(G3D_ERR_ARG, "guidance scale %g out of range", p->cfg);
    return G3D_OK;
}

/* The ControlNet's hint (p->control as [hint_ch, 8h, 8w]) and room for its residuals. */
static g3d_status control_hint(loop *L)
{
    const g3d_image *c = L->p->control;
    if (L->m->cn && L->p->control_scale == 0) return G3D_OK; /* its residuals would all be 0: not run */
    if (!c) return L->m->cn ? G3D_ERR(G3D_ERR_ARG, "the ControlNet needs a control image") : G3D_OK;
    if (!L->m->cn) return G3D_ERR(G3D_ERR_ARG, "a control image without a ControlNet");
    int ch = g3d_sd_controlnet_get_config(L->m->cn)->hint_ch, W = L->w * G3D_SD_HINT_FACTOR, H = L->h * G3D_SD_HINT_FACTOR;
    if (c->w != W || c->h != H || c->c != ch)
        return G3D_ERR(G3D_ERR_ARG, "the control image is %dx%d with %d channels, the ControlNet needs %dx%d with %d", c->w, c->h,
                       c->c, W, H, ch);
    size_t hw = (size_t)W * H;
    L->hint = malloc(sizeof(float) * hw * ch);
    L->res = malloc(sizeof(float) * g3d_sd_controlnet_residual_floats(L->m->cn, L->h, L->w));
    if (!L->hint || !L->res) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    for (size_t i = 0; i < hw; i++)
        for (int k = 0; k < ch; k++) L->hint[k * hw + i] = c->data[i * ch + k];
    return G3D_OK;
}

g3d_status g3d_sd_inpaint_hint(const g3d_image *image, const g3d_image *mask, const g3d_image *prefill, int w, int h,
                               g3d_image *hint)
{
    memset(hint, 0, sizeof *hint);
    if (!image || !mask || image->c != 3 || mask->c != 1 || mask->w != image->w || mask->h != image->h)
        return G3D_ERR(G3D_ERR_ARG, "the inpainting hint needs an RGB picture and a mask of its size");
    if (prefill && (prefill->w != image->w || prefill->h != image->h || prefill->c != 3))
        return G3D_ERR(G3D_ERR_ARG, "the prefilled picture is %dx%d, the picture %dx%d", prefill->w, prefill->h, image->w, image->h);
    G3D_TRY(g3d_image_create(hint, w, h, 3));
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            int sx = (int)((int64_t)x * image->w / w), sy = (int)((int64_t)y * image->h / h);
            const float *src = g3d_image_px(image, sx, sy);
            if (*g3d_image_px(mask, sx, sy) > 0.5f) src = prefill ? g3d_image_px(prefill, sx, sy) : NULL;
            for (int k = 0; k < 3; k++) g3d_image_px(hint, x, y)[k] = src ? src[k] : -1.0f;
        }
    return G3D_OK;
}

/* Everything but the inputs that differ: text, noise, sampling, decoding into out. */
static g3d_status generate(loop *L, float *x, g3d_image *out)
{
    const g3d_sd *m = L->m;
    g3d_sd_params *p = L->p;
    size_t n = (size_t)L->zc * L->h * L->w;
    g3d_status rc = encode_text(L, p->prompt, &L->cond);
    if (rc == G3D_OK && p->cfg != 1.0f) rc = encode_text(L, p->negative, &L->uncond);
    L->u = malloc(sizeof(float) * n);
    L->xin = malloc(sizeof(float) * (size_t)g3d_sd_unet_get_config(m->unet)->in_ch * L->h * L->w);
    if (rc == G3D_OK && (!L->u || !L->xin)) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) rc = control_hint(L);
    g3d_sd_sampler s = p->sampler;
    s.pred = g3d_sd_unet_get_config(m->unet)->pred;
    if (rc == G3D_OK) rc = g3d_sd_sample(&s, x, n, model_fn, L, noise_fn, L, step_fn, L);
    float *rgb = rc == G3D_OK ? malloc(sizeof(float) * 3 * (size_t)p->width * p->height) : NULL;
    if (rc == G3D_OK && !rgb) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) {
        for (size_t i = 0; i < n; i++) x[i] /= G3D_SD_VAE_SCALE;
        /* above 768 x 768 pixels (SD's VAE) the whole-picture decoder's maps pass 2 GB: tiles */
        if (L->h * L->w > 96 * 96) rc = g3d_sd_vae_decode_tiled(m->vae, x, L->h, L->w, 64, 16, rgb);
        else rc = g3d_sd_vae_decode(m->vae, x, L->h, L->w, rgb, NULL, NULL);
    }
    if (rc == G3D_OK) rc = to_image(rgb, p->width, p->height, out);
    free(rgb);
    free(L->cond);
    free(L->uncond);
    free(L->u);
    free(L->xin);
    free(L->hint);
    free(L->res);
    return rc;
}

/* The initial noise: given, or standard normal from the seed. */
static void initial_noise(loop *L, float *x, size_t n)
{
    g3d_rng_seed(&L->rng, L->p->seed, 0x5d);
    if (L->p->noise) memcpy(x, L->p->noise, sizeof(float) * n);
    else for (size_t i = 0; i < n; i++) x[i] = g3d_rng_normal(&L->rng);
}

g3d_status g3d_sd_txt2img(const g3d_sd *m, g3d_sd_params *p, g3d_image *out)
{
    memset(out, 0, sizeof *out);
    G3D_TRY(check_params(m, p));
    if (g3d_sd_unet_get_config(m->unet)->in_ch != g3d_sd_vae_get_config(m->vae)->z_ch)
        return G3D_ERR(G3D_ERR_ARG, "an inpainting model (%d input channels): use inpainting with a picture and a mask",
                       g3d_sd_unet_get_config(m->unet)->in_ch);
    int f = g3d_sd_vae_get_config(m->vae)->factor;
    loop L = {.m = m, .p = p, .h = p->height / f, .w = p->width / f, .zc = g3d_sd_vae_get_config(m->vae)->z_ch};
    size_t n = (size_t)L.zc * L.h * L.w;
    p->truncated = 0;
    float *x = malloc(sizeof(float) * n);
    if (!x) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    initial_noise(&L, x, n);
    g3d_status rc = generate(&L, x, out);
    free(x);
    if (rc != G3D_OK) g3d_image_free(out);
    return rc;
}

/* Replaces gen by image outside the mask, and inside it blends towards the picture over
 * `feather` pixels from the nearest known pixel (chamfer distance). */
static void paste_back(const g3d_image *image, const g3d_image *mask, g3d_image *gen, float feather)
{
    int W = image->w, H = image->h;
    float *d = malloc(sizeof(float) * (size_t)W * H);
    if (!d) feather = 0;
    for (int i = 0; d && i < W * H; i++) d[i] = mask->data[i] > 0.5f ? 1e9f : 0.0f;
    for (int pass = 0; d && pass < 2; pass++)
        for (int k = 0; k < W * H; k++) {
            int i = pass ? W * H - 1 - k : k, x = i % W, y = i / W, s = pass ? 1 : -1;
            float v = d[i];
            if (x + s >= 0 && x + s < W && d[i + s] + 1 < v) v = d[i + s] + 1;
            if (y + s >= 0 && y + s < H && d[i + s * W] + 1 < v) v = d[i + s * W] + 1;
            if (x + s >= 0 && x + s < W && y + s >= 0 && y + s < H && d[i + s * W + s] + 1.4142f < v) v = d[i + s * W + s] + 1.4142f;
            if (x - s >= 0 && x - s < W && y + s >= 0 && y + s < H && d[i + s * W - s] + 1.4142f < v) v = d[i + s * W - s] + 1.4142f;
            d[i] = v;
        }
    for (int i = 0; i < W * H; i++) {
        float wgen = mask->data[i] > 0.5f ? (feather > 0 ? d[i] / feather : 1.0f) : 0.0f;
        if (wgen > 1) wgen = 1;
        for (int c = 0; c < 3; c++) {
            float *g = &gen->data[(size_t)i * 3 + c];
            float k = image->data[(size_t)i * 3 + c];
            *g = wgen == 0.0f ? k : wgen * *g + (1.0f - wgen) * k;
        }
    }
    free(d);
}

g3d_status g3d_sd_inpaint(const g3d_sd *m, g3d_sd_params *p, const g3d_image *image, const g3d_image *mask, g3d_image *out)
{
    memset(out, 0, sizeof *out);
    if (!image || !mask || image->c != 3 || mask->c != 1)
        return G3D_ERR(G3D_ERR_ARG, "inpainting needs an RGB picture and a one-channel mask");
    if (mask->w != image->w || mask->h != image->h)
        return G3D_ERR(G3D_ERR_ARG, "the mask is %dx%d, the picture %dx%d", mask->w, mask->h, image->w, image->h);
    p->width = image->w;
    p->height = image->h;
    G3D_TRY(check_params(m, p));
    const g3d_sd_vae_config *vc = g3d_sd_vae_get_config(m->vae);
    int f = vc->factor, inpaint_model = g3d_sd_unet_get_config(m->unet)->in_ch != vc->z_ch;
    loop L = {.m = m, .p = p, .h = p->height / f, .w = p->width / f, .zc = vc->z_ch};
    size_t hw = (size_t)L.h * L.w, n = (size_t)L.zc * hw;
    p->truncated = 0;
    p->fallback = !inpaint_model;
    float *x = malloc(sizeof(float) * n), *mom = malloc(sizeof(float) * 2 * n), *lm = malloc(sizeof(float) * hw);
    float *pic = from_image(image, inpaint_model ? mask : NULL), *noise0 = malloc(sizeof(float) * n);
    float *extra = inpaint_model ? malloc(sizeof(float) * (n + hw)) : NULL;
    g3d_image hint = {0};
    g3d_status rc = x && mom && lm && pic && noise0 && (extra || !inpaint_model) ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) rc = g3d_sd_vae_encode(m->vae, pic, p->height, p->width, mom, NULL, NULL);
    if (rc == G3D_OK) {
        initial_noise(&L, x, n);
        memcpy(noise0, x, sizeof(float) * n);
        for (size_t i = 0; i < n; i++) mom[i] *= G3D_SD_VAE_SCALE;   /* the posterior mean, scaled */
        for (int y = 0; y < L.h; y++)
            for (int xx = 0; xx < L.w; xx++) {
                float v;
                if (inpaint_model) {
                    /* nearest (F.interpolate's default): the block's top-left pixel */
                    v = mask->data[(size_t)y * f * p->width + (size_t)xx * f] > 0.5f ? 1.0f : 0.0f;
                } else {
                    /* regenerate every latent pixel that touches the mask */
                    v = 0;
                    for (int dy = 0; dy < f; dy++)
                        for (int dx = 0; dx < f; dx++)
                            if (mask->data[(size_t)(y * f + dy) * p->width + (size_t)xx * f + dx] > 0.5f) v = 1;
                }
                lm[(size_t)y * L.w + xx] = v;
            }
        if (inpaint_model) {
            memcpy(extra, lm, sizeof(float) * hw);
            memcpy(extra + hw, mom, sizeof(float) * n);
            L.extra = extra;
        } else {
            L.known = mom;
            L.lmask = lm;
            L.noise0 = noise0;
        }
        if (m->cn && !p->control && p->control_scale != 0) {
            rc = g3d_sd_inpaint_hint(image, mask, p->prefill, L.w * G3D_SD_HINT_FACTOR, L.h * G3D_SD_HINT_FACTOR, &hint);
            p->control = &hint;
        }
        if (rc == G3D_OK) rc = generate(&L, x, out);
        if (p->control == &hint) p->control = NULL;
    }
    if (rc == G3D_OK) paste_back(image, mask, out, 8.0f);
    free(x);
    free(mom);
    free(lm);
    free(pic);
    free(noise0);
    free(extra);
    g3d_image_free(&hint);
    if (rc != G3D_OK) g3d_image_free(out);
    return rc;
}

/* ---- the plug-in ------------------------------------------------------------------------- */

typedef struct plugin {
    g3d_sd *m;
    g3d_sd_params p;
} plugin;

static void plugin_free(void *ctx)
{
    plugin *pl = ctx;
    g3d_sd_free(pl->m);
    free(pl);
}

static g3d_status plugin_inpaint(void *ctx, g3d_image *image, const g3d_image *mask, const char *prompt, uint64_t seed)
{
    plugin *pl = ctx;
    int k = g3d_sd_size_multiple(pl->m), W = image->w, H = image->h;
    int PW = (W + k - 1) / k * k, PH = (H + k - 1) / k * k;
    g3d_image pi = {0}, pm = {0}, out = {0};
    g3d_status rc = g3d_image_create(&pi, PW, PH, 3);
    if (rc == G3D_OK) rc = g3d_image_create(&pm, PW, PH, 1);
    if (rc == G3D_OK) {
        for (int y = 0; y < PH; y++)
            for (int x = 0; x < PW; x++) {
                int sx = x < W ? x : W - 1, sy = y < H ? y : H - 1;
                memcpy(g3d_image_px(&pi, x, y), g3d_image_px(image, sx, sy), sizeof(float) * 3);
                *g3d_image_px(&pm, x, y) = x < W && y < H ? *g3d_image_px(mask, x, y) : 0.0f;
            }
        g3d_sd_params p = pl->p;
        if (!p.prompt) p.prompt = prompt ? prompt : "";
        p.seed = seed;
        p.noise = NULL;
        p.control = NULL;   /* a ControlNet gets the inpainting hint of the padded picture */
        rc = g3d_sd_inpaint(pl->m, &p, &pi, &pm, &out);
    }
    if (rc == G3D_OK)
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                if (*g3d_image_px(mask, x, y) > 0.5f) memcpy(g3d_image_px(image, x, y), g3d_image_px(&out, x, y), sizeof(float) * 3);
    g3d_image_free(&pi);
    g3d_image_free(&pm);
    g3d_image_free(&out);
    return rc;
}

g3d_status g3d_inpainter_sd_create(g3d_sd *model, const g3d_sd_params *params, g3d_inpainter *out)
{
    memset(out, 0, sizeof *out);
    plugin *pl = calloc(1, sizeof *pl);
    if (!pl) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    pl->m = model;
    pl->p = params ? *params : g3d_sd_defaults();
    out->name = "stable-diffusion";
    out->ctx = pl;
    out->inpaint = plugin_inpaint;
    out->free = plugin_free;
    return G3D_OK;
}
