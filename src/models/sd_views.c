/* Stable Diffusion inpainting of views of any size: scaled to the model's native side, padded to
 * its size multiple, the hole grown so that the seam is redrawn, only the hole written back. */
#include "gen3d/sd_views.h"

#include "gen3d/resize.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void g3d_sd_view_params_default(g3d_sd_view_params *p)
{
    memset(p, 0, sizeof *p);
    p->sd = g3d_sd_defaults();
    p->sd.sampler.kind = G3D_SD_DPMPP_2M;
    p->sd.sampler.steps = 25;
    p->sd.negative = G3D_SD_VIEW_NEGATIVE;
    p->size = 512;
    p->dilate = 4;
}

g3d_status g3d_sd_view_params_check(const g3d_sd_view_params *p)
{
    if (p->size < 8 || p->size > 4096 || p->dilate < 0 || p->dilate > 64)
        return G3D_ERR(G3D_ERR_ARG, "diffusion inpainting: size %d (need 8..4096) or dilation %d (need 0..64)", p->size, p->dilate);
    return G3D_OK;
}

void g3d_sd_view_geometry(int w, int h, int size, int multiple, int *dw, int *dh, int *pw, int *ph)
{
    int side = size / multiple * multiple;
    if (side < multiple) side = multiple;
    double s = (double)side / (w > h ? w : h);
    *dw = w >= h ? side : (int)lround(w * s);
    *dh = h > w ? side : (int)lround(h * s);
    if (*dw < 1) *dw = 1;
    if (*dh < 1) *dh = 1;
    *pw = (*dw + multiple - 1) / multiple * multiple;
    *ph = (*dh + multiple - 1) / multiple * multiple;
}

typedef struct views {
    g3d_sd *m;
    g3d_sd_view_params p;
} views;

static void views_free(void *ctx)
{
    views *v = ctx;
    g3d_sd_free(v->m);
    free(v);
}

/* mask > 0.5 grown by r pixels (a square neighbourhood: rows, then columns), as 0/1 in out. */
static g3d_status grow(const g3d_image *mask, int r, g3d_image *out)
{
    int W = mask->w, H = mask->h;
    g3d_image tmp = {0};
    G3D_TRY(g3d_image_create(out, W, H, 1));
    g3d_status rc = g3d_image_create(&tmp, W, H, 1);
    for (int y = 0; rc == G3D_OK && y < H; y++)
        for (int x = 0; x < W; x++) {
            float v = 0;
            for (int d = -r; d <= r && !v; d++)
                if (x + d >= 0 && x + d < W && mask->data[(size_t)y * W + x + d] > 0.5f) v = 1;
            tmp.data[(size_t)y * W + x] = v;
        }
    for (int y = 0; rc == G3D_OK && y < H; y++)
        for (int x = 0; x < W; x++) {
            float v = 0;
            for (int d = -r; d <= r && !v; d++)
                if (y + d >= 0 && y + d < H && tmp.data[(size_t)(y + d) * W + x] > 0) v = 1;
            out->data[(size_t)y * W + x] = v;
        }
    g3d_image_free(&tmp);
    if (rc != G3D_OK) g3d_image_free(out);
    return rc;
}

/* src (dw x dh) into a new pw x ph picture, the last column and row repeated into the padding. */
static g3d_status pad(const g3d_image *src, int pw, int ph, g3d_image *out)
{
    G3D_TRY(g3d_image_create(out, pw, ph, src->c));
    for (int y = 0; y < ph; y++)
        for (int x = 0; x < pw; x++)
            memcpy(g3d_image_px(out, x, y), g3d_image_px(src, x < src->w ? x : src->w - 1, y < src->h ? y : src->h - 1),
                   sizeof(float) * (size_t)src->c);
    return G3D_OK;
}

/* The picture the model draws with its hole filled by the prefill inpainter: the ControlNet's
 * hint takes its colours there. */
static g3d_status prefill(const views *v, const g3d_image *pic, const g3d_image *mask, const char *prompt, uint64_t seed,
                          g3d_image *pre)
{
    G3D_TRY(g3d_image_clone(pre, pic));
    return v->p.prefill->inpaint(v->p.prefill->ctx, pre, mask, prompt, seed);
}

static g3d_status views_inpaint(void *ctx, g3d_image *image, const g3d_image *mask, const char *prompt, uint64_t seed)
{
    views *v = ctx;
    int W = image->w, H = image->h, dw, dh, pw, ph;
    g3d_sd_view_geometry(W, H, v->p.size, g3d_sd_size_multiple(v->m), &dw, &dh, &pw, &ph);
    g3d_image grown = {0}, small = {0}, smask = {0}, pimg = {0}, pmask = {0}, out = {0}, crop = {0}, back = {0}, pre = {0};
    g3d_status rc = grow(mask, v->p.dilate, &grown);
    if (rc == G3D_OK) rc = g3d_image_resize(image, dw, dh, G3D_RESIZE_BILINEAR_AA, &small);
    if (rc == G3D_OK) rc = g3d_image_resize(&grown, dw, dh, G3D_RESIZE_BILINEAR_AA, &smask);
    /* a picture pixel that any hole pixel reaches is redrawn */
    for (size_t i = 0; rc == G3D_OK && i < g3d_image_size(&smask); i++) smask.data[i] = smask.data[i] > 1e-3f;
    if (rc == G3D_OK) rc = pad(&small, pw, ph, &pimg);
    if (rc == G3D_OK) rc = g3d_image_create(&pmask, pw, ph, 1);
    for (int y = 0; rc == G3D_OK && y < dh; y++) memcpy(g3d_image_px(&pmask, 0, y), g3d_image_px(&smask, 0, y), sizeof(float) * dw);
    if (rc == G3D_OK && v->p.prefill && g3d_sd_get_controlnet(v->m)) rc = prefill(v, &pimg, &pmask, prompt, seed, &pre);
    if (rc == G3D_OK) {
        g3d_sd_params p = v->p.sd;
        if (pre.data) p.prefill = &pre;
        if (!p.prompt) p.prompt = prompt ? prompt : "";
        p.seed = seed;
        p.noise = NULL;
        p.progress = v->p.progress;
        rc = g3d_sd_inpaint(v->m, &p, &pimg, &pmask, &out);
    }
    if (rc == G3D_OK) rc = g3d_image_create(&crop, dw, dh, 3);
    for (int y = 0; rc == G3D_OK && y < dh; y++) memcpy(g3d_image_px(&crop, 0, y), g3d_image_px(&out, 0, y), sizeof(float) * 3 * dw);
    if (rc == G3D_OK) rc = g3d_image_resize(&crop, W, H, G3D_RESIZE_BILINEAR_AA, &back);
    for (size_t i = 0; rc == G3D_OK && i < (size_t)W * H; i++)
        if (mask->data[i] > 0.5f)
            for (int c = 0; c < 3; c++) {
                float x = back.data[3 * i + c];
                image->data[3 * i + c] = x < 0 ? 0 : x > 1 ? 1 : x;
            }
    g3d_image *all[] = {&grown, &small, &smask, &pimg, &pmask, &out, &crop, &back, &pre};
    for (size_t i = 0; i < sizeof all / sizeof all[0]; i++) g3d_image_free(all[i]);
    return rc;
}

g3d_status g3d_inpainter_sd_views_create(g3d_sd *model, const g3d_sd_view_params *p, g3d_inpainter *out)
{
    memset(out, 0, sizeof *out);
    g3d_sd_view_params d;
    g3d_sd_view_params_default(&d);
    if (!p) p = &d;
    g3d_status rc = g3d_sd_view_params_check(p);
    if (rc != G3D_OK) {
        g3d_sd_free(model);
        return rc;
    }
    views *v = calloc(1, sizeof *v);
    if (!v) {
        g3d_sd_free(model);
        return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    v->m = model;
    v->p = *p;
    const g3d_sd_unet_config *u = g3d_sd_get_unet(model);
    if (u->in_ch == 4)
        g3d_log(G3D_LOG_INFO, "the inpainting model is a text-to-image model: it fills holes by latent blending");
    out->name = "stable-diffusion";
    out->ctx = v;
    out->inpaint = views_inpaint;
    out->free = views_free;
    return G3D_OK;
}
