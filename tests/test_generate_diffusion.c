/* The generative pipeline on the tiny fixture models: text input (Stable Diffusion draws the
 * first image, MoGe-2 gives its depth and camera) and the Middlebury frame, both with every new
 * view and the background filled by the diffusion inpainter (sd_views.h). A recorder around the
 * inpainter checks each call: the mask is the view's holes, known pixels come back unchanged,
 * the views keep its output and their new pixels are lifted, the background behind the
 * foreground is filled with the template prompt. */
#include "testutil.h"
#include "inpaint_recorder.h"

#include "gen3d/describe.h"
#include "gen3d/generate.h"
#include "gen3d/imageio.h"
#include "gen3d/inpaint_classic.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const g_prompt = "a cosy living room with a green sofa";

TEST(geometry)
{
    int dw, dh, pw, ph;
    /* the default input at SD 1.5's native size: 512 x 345, padded to 512 x 384 */
    g3d_sd_view_geometry(741, 500, 512, 64, &dw, &dh, &pw, &ph);
    CHECK(dw == 512 && dh == 345 && pw == 512 && ph == 384);
    /* portrait, and a size that is not a multiple: rounded down to one */
    g3d_sd_view_geometry(300, 400, 500, 64, &dw, &dh, &pw, &ph);
    CHECK(dh == 448 && dw == 336 && pw == 384 && ph == 448);
    /* a small view is enlarged; the scale is the same on both axes to within rounding */
    g3d_sd_view_geometry(64, 43, 32, 4, &dw, &dh, &pw, &ph);
    CHECK(dw == 32 && dh == 22 && pw == 32 && ph == 24);
    CHECK(fabs((double)dh / 43 - (double)dw / 64) <= 0.5 / 43 + 1e-12);
    g3d_sd_view_geometry(10, 10, 4, 8, &dw, &dh, &pw, &ph);
    CHECK(dw == 8 && dh == 8 && pw == 8 && ph == 8);
}

/* The tiny SD pipeline (a text-to-image UNet: inpainting by latent blending). */
static g3d_sd_paths parts(void)
{
    static char vae[1024], te[1024], tok[1024];
    snprintf(vae, sizeof vae, "%s", test_fixture("sdunet_vae_tiny.safetensors"));
    snprintf(te, sizeof te, "%s", test_fixture("clip_sd1_tiny.ckpt"));
    snprintf(tok, sizeof tok, "%s", test_fixture("cliptok_merges.txt.gz"));
    return (g3d_sd_paths){.vae = vae, .text_encoder = te, .tokenizer = tok, .prediction = -1};
}

static void params(g3d_generate_params *p, const char *out)
{
    g3d_generate_params_default(p);
    p->sd_parts = parts();
    p->diffusion.size = 32;
    p->diffusion.sd.sampler.steps = 2;
    p->steps = 2;
    p->world.extra_views = 0;
    p->last_stage = G3D_STAGE_WORLD;
    p->output_dir = out;
    p->seed = 5;
}

/* An inpainting UNet (9 input channels: latent, mask, masked picture's latent) made from the
 * text-to-image fixture: its first convolution widened, the extra input channels' weights
 * repeating the first four's. Written to `path`. */
static void make_inpainting_unet(const char *path)
{
    g3d_ckpt *ck = NULL;
    CHECK_OK(g3d_ckpt_open(test_fixture("sdpipe_unet_tiny.safetensors"), &ck));
    if (!ck) return;
    int64_t n = g3d_ckpt_count(ck);
    g3d_tensor_out *t = calloc((size_t)n, sizeof *t);
    uint16_t *wide = NULL;
    for (int64_t i = 0; t && i < n; i++) {
        const g3d_tensor_info *in = g3d_ckpt_tensor(ck, i);
        t[i] = (g3d_tensor_out){in->name, in->dtype, in->ndim, {0}, in->data};
        memcpy(t[i].shape, in->shape, sizeof in->shape);
        if (strcmp(in->name, "model.diffusion_model.input_blocks.0.0.weight")) continue;
        CHECK(in->dtype == G3D_DT_F16 && in->ndim == 4 && in->shape[1] == 4);
        int64_t co = in->shape[0], k = in->shape[2] * in->shape[3];
        wide = malloc(sizeof *wide * (size_t)(co * 9 * k));
        for (int64_t o = 0; wide && o < co; o++)
            for (int c = 0; c < 9; c++)
                memcpy(wide + (o * 9 + c) * k, (const uint16_t *)in->data + (o * 4 + c % 4) * k, sizeof *wide * (size_t)k);
        t[i].shape[1] = 9;
        t[i].data = wide;
    }
    CHECK(wide != NULL);
    if (t && wide) CHECK_OK(g3d_safetensors_write(path, t, (int)n, NULL));
    free(wide);
    free(t);
    g3d_ckpt_free(ck);
}

/* Runs p with the diffusion inpainter of `model` behind a recorder; returns the world written
 * (loaded back) in *w. */
static void run_world(g3d_generate_params *p, const char *model, recorder *rec, g3d_world *w)
{
    g3d_sd_paths sp = p->sd_parts;
    sp.model = model;
    g3d_sd *m = NULL;
    g3d_inpainter sd = {0};
    memset(w, 0, sizeof *w);
    CHECK_OK(g3d_sd_load(&sp, &m));
    if (!m) return;
    CHECK_OK(g3d_inpainter_sd_views_create(m, &p->diffusion, &sd));
    memset(rec, 0, sizeof *rec);
    rec->inner = &sd;
    g3d_inpainter wrap = {"recorder", rec, record, NULL};
    p->inpainter = &wrap;
    CHECK_OK(g3d_generate(p, NULL));
    CHECK_OK(g3d_world_load(p->output_dir, w));
    g3d_inpainter_free(&sd);
}

/* One call per view after the input with the view's holes as its mask; known pixels unchanged,
 * hole pixels redrawn; the view saved is the inpainter's output; new pixels lifted. */
static void check_views(const char *label, const recorder *r, int first, const g3d_world *w, const char *view_prompt)
{
    CHECK_MSG(r->known_changed == 0, "%s: %zu known pixels changed", label, r->known_changed);
    CHECK_MSG(r->bad_masks == 0, "%s: %zu masks not 0/1, empty or full", label, r->bad_masks);
    CHECK_MSG(w->n_views == 3 && r->calls == first + w->n_views - 1, "%s: %d calls for %d views", label, r->calls, w->n_views);
    for (int i = 1, k = first; i < w->n_views && k < r->calls && k < MAX_CALLS; i++, k++) {
        const g3d_image *m = &r->mask[k];
        size_t holes = 0, n = (size_t)m->w * m->h, redrawn = 0;
        for (size_t j = 0; j < n; j++) holes += m->data[j] > 0.5f;
        CHECK_MSG(fabs((double)holes / n - w->steps[i].hole_fraction) < 1e-9, "%s: view %d's mask is not its holes", label, i);
        for (size_t j = 0; j < n; j++)
            if (m->data[j] > 0.5f) redrawn += memcmp(&r->in[k].data[3 * j], &r->out[k].data[3 * j], 3 * sizeof(float)) != 0;
        CHECK_MSG(redrawn > holes / 2, "%s: view %d: %zu of %zu hole pixels redrawn", label, i, redrawn, holes);
        /* the saved view (8-bit) is the inpainter's output */
        double worst = 0;
        for (size_t j = 0; j < 3 * n && w->rgb[i].w == m->w; j++) worst = fmax(worst, fabs(w->rgb[i].data[j] - r->out[k].data[j]));
        CHECK_MSG(w->rgb[i].w == m->w && worst <= 0.5 / 255 + 1e-6, "%s: view %d differs from the output by %g", label, i, worst);
        CHECK_MSG(w->steps[i].points_added > 0, "%s: view %d lifted no points", label, i);
        CHECK_MSG(r->prompt[k] && !strcmp(r->prompt[k], view_prompt), "%s: view %d's prompt %s", label, i, r->prompt[k]);
    }
}

TEST(text_input)
{
    g3d_generate_params p;
    recorder rec;
    g3d_world w;
    params(&p, test_tmp("gen_diffusion_text"));
    static char sd[1024], moge[1024];
    snprintf(sd, sizeof sd, "%s", test_fixture("sdpipe_unet_tiny.safetensors"));
    snprintf(moge, sizeof moge, "%s", test_fixture("moge_tiny.pt"));
    p.sd_model = sd;
    p.depth_model = moge;
    p.prompt = g_prompt;
    p.layers = 0;
    run_world(&p, sd, &rec, &w);
    /* the first image: the model's own text-to-image picture at the native size */
    g3d_sd_paths sp = parts();
    sp.model = sd;
    g3d_sd *m = NULL;
    g3d_image img = {0};
    CHECK_OK(g3d_sd_load(&sp, &m));
    g3d_sd_params tp = p.diffusion.sd;
    tp.prompt = g_prompt;
    tp.width = tp.height = 32;
    tp.seed = p.seed;
    if (m) CHECK_OK(g3d_sd_txt2img(m, &tp, &img));
    g3d_sd_free(m);
    double worst = 1;
    if (w.n_views && img.data && w.rgb[0].w == 32 && w.rgb[0].h == 32) {
        worst = 0;
        for (size_t j = 0; j < g3d_image_size(&img); j++) worst = fmax(worst, fabs(w.rgb[0].data[j] - img.data[j]));
    }
    CHECK_MSG(worst <= 0.5 / 255 + 1e-6, "the first view is not the text-to-image picture (%g)", worst);
    check_views("text", &rec, 0, &w, g_prompt);
    g3d_image_free(&img);
    recorder_free(&rec);
    g3d_world_free(&w);
}

/* The Middlebury frame (RGB-D, foreground objects in its depth) with `model` filling the
 * background and the views. */
static void middlebury(const char *label, const char *model)
{
    g3d_generate_params p;
    recorder rec;
    g3d_world w;
    params(&p, test_tmp("gen_diffusion_middlebury"));
    p.input.default_dir = test_default_input();
    p.input.max_side = 64;
    run_world(&p, model, &rec, &w);
    CHECK_MSG(w.layers.n_foreground > 0, "%s: no foreground: the background fill is not exercised", label);
    char *bg = NULL;
    const char *colors = G3D_NEUTRAL_COLORS;
    bg = g3d_background_prompt(G3D_NEUTRAL_CATEGORY, &colors, 1);
    /* call 0: the background behind the foreground, with the template prompt */
    CHECK(rec.calls > 0 && rec.prompt[0] && bg && !strcmp(rec.prompt[0], bg));
    if (rec.calls > 0 && w.layers.bg_rgb.data && w.layers.fg_mask.data) {
        const g3d_image *m = &rec.mask[0];
        size_t fg = 0, covered = 0, changed = 0, n = (size_t)m->w * m->h;
        for (size_t j = 0; j < n; j++) {
            fg += w.layers.fg_mask.data[j] > 0.5f;
            covered += w.layers.fg_mask.data[j] > 0.5f && m->data[j] > 0.5f;
            if (m->data[j] > 0.5f) changed += memcmp(&rec.in[0].data[3 * j], &rec.out[0].data[3 * j], 3 * sizeof(float)) != 0;
        }
        CHECK_MSG(fg > 0 && covered == fg, "the background fill's mask misses %zu foreground pixels", fg - covered);
        CHECK_MSG(changed > 0, "the background behind the foreground was not filled");
        double worst = 0;
        for (size_t j = 0; j < 3 * n && w.layers.bg_rgb.w == m->w; j++)
            worst = fmax(worst, fabs(w.layers.bg_rgb.data[j] - rec.out[0].data[j]));
        CHECK_MSG(worst <= 0.5 / 255 + 1e-6, "the saved background is not the filled one (%g)", worst);
    }
    check_views(label, &rec, 1, &w, G3D_NEUTRAL_VIEW_PROMPT);
    free(bg);
    recorder_free(&rec);
    g3d_world_free(&w);
}

TEST(middlebury_text_to_image_model)
{
    middlebury("Middlebury, latent blending", test_fixture("sdpipe_unet_tiny.safetensors"));
}

TEST(middlebury_inpainting_model)
{
    static char path[1024];
    snprintf(path, sizeof path, "%s", test_tmp("sd_inpainting_tiny.safetensors"));
    make_inpainting_unet(path);
    g3d_sd_paths sp = parts();
    g3d_sd *m = NULL;
    sp.model = path;
    CHECK_OK(g3d_sd_load(&sp, &m));
    CHECK(m && g3d_sd_get_unet(m)->in_ch == 9);
    g3d_sd_free(m);
    middlebury("Middlebury, inpainting model", path);
}

/* The background's ControlNet (sd_views.h with a prefill): the prefill inpainter fills the
 * picture the model draws (the padded, scaled view and its grown hole), its colours reach the
 * ControlNet's hint and so the picture; known pixels stay as they were. */
TEST(controlnet_prefill)
{
    g3d_sd_paths sp = parts();
    static char unet[1024], cn[1024];
    snprintf(unet, sizeof unet, "%s", test_fixture("sdinpaint_unet_tiny.safetensors"));
    snprintf(cn, sizeof cn, "%s", test_fixture("sdcontrol_tiny.pth"));
    sp.model = unet;
    sp.controlnet = cn;
    g3d_image view = {0}, mask = {0};
    CHECK_OK(g3d_image_create(&view, 40, 28, 3));
    CHECK_OK(g3d_image_create(&mask, 40, 28, 1));
    if (!view.data || !mask.data) return;
    for (int y = 0; y < 28; y++)
        for (int x = 0; x < 40; x++) {
            float *px = g3d_image_px(&view, x, y);
            px[0] = x / 40.0f, px[1] = y / 28.0f, px[2] = 0.3f;
            mask.data[y * 40 + x] = x >= 12 && x < 26 && y >= 8 && y < 20;
        }
    g3d_inpainter classic = {0}, with[2] = {{0}};
    recorder rec;
    memset(&rec, 0, sizeof rec);
    rec.inner = &classic;
    g3d_inpainter wrap = {"recorder", &rec, record, NULL};
    CHECK_OK(g3d_inpainter_classic_create(NULL, &classic));
    for (int k = 0; k < 2; k++) {
        g3d_sd *m = NULL;
        CHECK_OK(g3d_sd_load(&sp, &m));
        if (!m) break;
        CHECK(g3d_sd_get_controlnet(m) != NULL);
        g3d_sd_view_params vp;
        g3d_sd_view_params_default(&vp);
        vp.size = 32;
        vp.sd.sampler.steps = 2;
        vp.prefill = k ? &wrap : NULL;
        CHECK_OK(g3d_inpainter_sd_views_create(m, &vp, &with[k]));
    }
    g3d_image out[2] = {{0}};
    for (int k = 0; k < 2 && with[k].inpaint; k++) {
        CHECK_OK(g3d_image_clone(&out[k], &view));
        CHECK_OK(with[k].inpaint(with[k].ctx, &out[k], &mask, g_prompt, 3));
    }
    /* one prefill call, on the picture the model draws: 32 x 22 padded to 32 x 24 (multiple 8) */
    CHECK_MSG(rec.calls == 1, "%d prefill calls", rec.calls);
    CHECK_MSG(rec.known_changed == 0 && rec.bad_masks == 0, "prefill: %zu known pixels changed, %zu bad masks", rec.known_changed,
              rec.bad_masks);
    int dw, dh, pw, ph;
    g3d_sd_view_geometry(40, 28, 32, 8, &dw, &dh, &pw, &ph);
    CHECK(rec.calls < 1 || (rec.mask[0].w == pw && rec.mask[0].h == ph));
    size_t known_changed = 0, differ = 0;
    for (size_t i = 0; out[0].data && out[1].data && i < (size_t)40 * 28; i++) {
        for (int k = 0; k < 2; k++)
            if (mask.data[i] < 0.5f) known_changed += memcmp(&out[k].data[3 * i], &view.data[3 * i], 3 * sizeof(float)) != 0;
        if (mask.data[i] > 0.5f) differ += memcmp(&out[0].data[3 * i], &out[1].data[3 * i], 3 * sizeof(float)) != 0;
    }
    CHECK_MSG(known_changed == 0, "%zu known pixels changed", known_changed);
    CHECK_MSG(differ > 0, "the prefilled hint changed no hole pixel");
    for (int k = 0; k < 2; k++) {
        g3d_inpainter_free(&with[k]);
        g3d_image_free(&out[k]);
    }
    g3d_inpainter_free(&classic);
    recorder_free(&rec);
    g3d_image_free(&view);
    g3d_image_free(&mask);
}

int main(int argc, char **argv)
{
    (void)argc;
    g3d_process_setup(argv);   /* passive OpenMP waits: the machine may be shared */
    RUN(geometry);
    RUN(text_input);
    RUN(middlebury_text_to_image_model);
    RUN(middlebury_inpainting_model);
    RUN(controlnet_prefill);
    return test_summary();
}
