/* The pipeline: input -> layers -> world -> splats -> outputs, each stage handing the next a
 * struct in memory; the files are written once, at the end. */
#include "gen3d/generate.h"
#include "gen3d/depth_complete.h"
#include "gen3d/describe.h"
#include "gen3d/imageio.h"
#include "gen3d/init.h"
#include "gen3d/inpaint_classic.h"
#include "gen3d/lama.h"
#include "gen3d/ply.h"
#include "gen3d/raster.h"
#include "gen3d/regions.h"
#include "gen3d/sam.h"
#include "gen3d/spz.h"
#include "gen3d/viewer.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>

#define G3D_MOVE_STEPS 2   /* generation steps of a keyframed preset */

static const char *const g_stage_names[G3D_STAGE_COUNT] = {"input", "layers", "world", "splats", "outputs"};

const char *g3d_stage_name(g3d_stage s)
{
    return (int)s >= 0 && s < G3D_STAGE_COUNT ? g_stage_names[s] : "unknown";
}

void g3d_generate_params_default(g3d_generate_params *p)
{
    memset(p, 0, sizeof *p);
    g3d_frame_params_default(&p->input);
    p->input.max_side = 768;
    g3d_depth_model_params_default(&p->depth_model_params);
    p->layers = 1;
    g3d_layers_params_default(&p->layers_params);
    p->trajectory = "rotate";
    g3d_trajectory_params_default(&p->trajectory_params);
    /* The keyframed presets (WorldScore's moves) make 50 frames for a video; as generation
     * steps those move 7 mm each on the default input, and each step inpaints and lifts holes a
     * pixel or two wide at every depth edge, whose mixed colours then sit beside the edges at
     * any camera along the path (docs/splatting.md: fewer, wider steps score better). */
    p->trajectory_params.interp = G3D_MOVE_STEPS - 1;
    g3d_world_params_default(&p->world);
    p->sh_degree = 3;
    g3d_footprint_init_default(&p->footprint);
    p->input_every = 2;
    p->coverage_weight = 0.2;
    g3d_train_params_default(&p->train, 500);
    p->last_stage = G3D_STAGE_OUTPUTS;
    p->video = 1;
    p->video_trajectory = "swing";
    p->video_frames = 120;
    g3d_video_params_default(&p->video_params);
    g3d_explore_params_default(&p->explore);
    p->explore_views = -1;
    p->sd_parts.prediction = -1;
    g3d_sd_view_params_default(&p->diffusion);
    p->seed = 42;
}

void g3d_generate_result_free(g3d_generate_result *res)
{
    if (!res) return;
    g3d_gaussians_free(&res->scene);
    memset(res, 0, sizeof *res);
}

/* One run's state: what each stage made, and the plug-ins made here (own_*). */
typedef struct run {
    const g3d_generate_params *p;
    g3d_progress progress;             /* the user's progress, polling the cancel request */
    g3d_frame frame;                   /* loaded here, unless p->frame */
    const g3d_frame *input;
    g3d_inpainter own_inpainter;
    g3d_inpainter own_bg, own_prefill; /* the ControlNet's background inpainter and its prefill */
    g3d_sd *views_sd;                  /* the views' model when it carries the background's ControlNet */
    g3d_depth_estimator own_depth;
    g3d_mask_provider own_masks;
    g3d_prompt_provider own_prompts;   /* the automatic prompts made here */
    const g3d_prompt_provider *auto_prompts;  /* the caller's or own_prompts; NULL: none */
    g3d_prompt_provider run_prompts;   /* the user's, the automatic and the neutral prompts */
    const g3d_prompt_provider *prompts;  /* &run_prompts, or NULL: the run has no prompts */
    char *bg_prompt, *view_prompt;     /* the prompts of a run without layers */
    const g3d_inpainter *inpainter;
    const g3d_inpainter *bg_inner;     /* the background's inpainter, timed through bg_timed */
    g3d_inpainter bg_timed;
    double seconds_txt2img, seconds_background;
    char label[48];                    /* what the diffusion steps reported now belong to */
    const g3d_depth_estimator *depth;
    const g3d_mask_provider *masks;
    g3d_layers layers;
    g3d_world world;
    g3d_gaussians scene;
    int64_t initial_gaussians;
    g3d_train_result train;
    g3d_render_result video;
    int viewer_written;                /* viewer.html was written */
    char *tmp;                         /* the output folder being written */
} run;

/* Passes the stages' reports on; the engine's "denoise" steps are named after what they draw
 * (the text input, the background, the view the world loop is at). */
static int report(void *user, const char *stage, int64_t step, int64_t total, const char *info)
{
    run *r = user;
    const g3d_generate_params *p = r->p;
    if (!strcmp(stage, "denoise"))
        stage = r->label;
    else if (!strcmp(stage, "world") && step < total)
        snprintf(r->label, sizeof r->label, "view %d/%d", (int)step, (int)(total - 1));
    int stop = g3d_progress_report(&p->progress, stage, step, total, info);
    return stop || g3d_cancel_requested(&p->cancel);
}

static g3d_status check_cancel(const run *r)
{
    return g3d_cancel_requested(&r->p->cancel) ? G3D_ERR(G3D_CANCELLED, "cancelled") : G3D_OK;
}

/* The world takes generation steps at the exploration set's cameras (explore_views): by
 * default with the built-in classical and LaMa inpainters, not with diffusion or a caller's. */
static int explore_steps(const g3d_generate_params *p)
{
    return p->explore_views > 0 || (p->explore_views < 0 && !p->inpaint_model && !p->inpainter);
}

/* The run builds the exploration set: to measure the scene, or for generation steps. */
static int uses_explore(const g3d_generate_params *p)
{
    return p->last_stage == G3D_STAGE_OUTPUTS || (explore_steps(p) && !p->world_dir && p->last_stage == G3D_STAGE_WORLD);
}

/* Everything that can be refused without work is refused before any: a mistyped path name
 * fails now, not after minutes of training. */
static g3d_status check_params(const g3d_generate_params *p)
{
    if (p->last_stage != G3D_STAGE_INPUT && p->last_stage != G3D_STAGE_WORLD && p->last_stage != G3D_STAGE_OUTPUTS)
        return G3D_ERR(G3D_ERR_ARG, "generate: a run can stop after the input, the world or the outputs, not the %s",
                       g3d_stage_name(p->last_stage));
    if (p->world_dir && p->last_stage != G3D_STAGE_OUTPUTS)
        return G3D_ERR(G3D_ERR_ARG, "%s: a run from a saved world goes on to the outputs", p->world_dir);
    if (p->last_stage != G3D_STAGE_OUTPUTS && !p->output_dir)
        return G3D_ERR(G3D_ERR_ARG, "generate: stopping after the %s writes its folder: give an output folder",
                       g3d_stage_name(p->last_stage));
    if (p->input_every < 0) return G3D_ERR(G3D_ERR_ARG, "generate: input view every %d iterations (need >= 0)", p->input_every);
    if (!(p->coverage_weight >= 0 && p->coverage_weight <= 100))
        return G3D_ERR(G3D_ERR_ARG, "generate: coverage weight %g (need 0..100)", p->coverage_weight);
    if (p->sh_degree < 0 || p->sh_degree > G3D_SH_MAX_DEGREE)
        return G3D_ERR(G3D_ERR_ARG, "generate: SH degree %d is not in 0..%d", p->sh_degree, G3D_SH_MAX_DEGREE);
    if (p->steps < 0 || p->steps > 10000) return G3D_ERR(G3D_ERR_ARG, "generate: %d steps (need 0..10000)", p->steps);
    if (p->sd_model && !p->world_dir) {
        if (!p->prompt || !p->prompt[strspn(p->prompt, " \t\r\n")])
            return G3D_ERR(G3D_ERR_ARG, "%s: text input needs a prompt", p->sd_model);
        if (p->frame || p->input.rgb_path || p->input.depth_path)
            return G3D_ERR(G3D_ERR_ARG, "%s: text input draws the first image: no input image or depth", p->sd_model);
        if (!p->depth && !p->depth_model)
            return G3D_ERR(G3D_ERR_ARG, "%s: text input needs a depth model (MoGe-2) for the image's depth", p->sd_model);
    }
    if (p->controlnet_model && !p->bg_inpainter && !p->inpaint_model)
        return G3D_ERR(G3D_ERR_ARG, "%s: the ControlNet needs its base model: give an inpainting model", p->controlnet_model);
    if (p->sd_model || p->inpaint_model || p->controlnet_model) G3D_TRY(g3d_sd_view_params_check(&p->diffusion));
    if (p->last_stage == G3D_STAGE_OUTPUTS && p->output_dir && p->video) {
        if (p->video_frames < 2) return G3D_ERR(G3D_ERR_ARG, "generate: a video needs 2 frames at least, not %d", p->video_frames);
        g3d_camera probe = {g3d_intrinsics_from_fov(60, 64, 48), g3d_mat4_identity()}, *cams = NULL;
        int n;
        G3D_TRY(g3d_render_flythrough(p->video_trajectory, NULL, NULL, &probe, 1.0, 2, &cams, &n));
        free(cams);
    }
    if (uses_explore(p)) {
        /* the distance's bound depends on the scene: checked again once the input is known */
        double d = p->explore.distance;
        g3d_camera probe = {g3d_intrinsics_from_fov(60, 64, 48), g3d_mat4_identity()}, *cams = NULL;
        G3D_TRY(g3d_explore_cameras(&probe, d > 0 && isfinite(d) ? d : 1.0, &p->explore, &cams, NULL));
        free(cams);
    }
    if (!p->world_dir && p->last_stage != G3D_STAGE_INPUT && !g3d_trajectory_is_file(p->trajectory)) {
        g3d_mat4 *poses = NULL;
        int n;
        G3D_TRY(g3d_trajectory_make(p->trajectory, &p->trajectory_params, 1.0, &poses, &n));
        free(poses);
    }
    return G3D_OK;
}

/* ---- input ----------------------------------------------------------------------------------- */

static void log_frame(const g3d_frame *f)
{
    size_t valid = 0, n = g3d_image_size(&f->depth);
    double lo = 1e30, hi = 0;
    for (size_t i = 0; i < n; i++)
        if (f->depth.data[i] > 0) {
            valid++;
            lo = f->depth.data[i] < lo ? f->depth.data[i] : lo;
            hi = f->depth.data[i] > hi ? f->depth.data[i] : hi;
        }
    g3d_log(G3D_LOG_INFO, "input %s: %dx%d, fx %.1f fy %.1f cx %.1f cy %.1f (horizontal fov %.1f deg)", f->name, f->rgb.w,
            f->rgb.h, f->cam.K.fx, f->cam.K.fy, f->cam.K.cx, f->cam.K.cy, g3d_intrinsics_fov_x_deg(f->cam.K));
    g3d_log(G3D_LOG_INFO, "depth %.3f .. %.3f m, %.1f %% of pixels valid%s", lo, hi, 100.0 * valid / n,
            f->heldout.data ? "; a real held-out view is included" : "");
}

/* The depth estimator: the caller's, the model in p->depth_model, or depth completion. */
static g3d_status make_depth(run *r)
{
    const g3d_generate_params *p = r->p;
    if (p->depth) {
        r->depth = p->depth;
        return G3D_OK;
    }
    r->depth = &r->own_depth;
    if (!p->depth_model) return g3d_depth_estimator_completion_create(&r->own_depth);
    int metric = 0;
    G3D_TRY(g3d_depth_estimator_model_create(p->depth_model, &p->depth_model_params, &r->own_depth, &metric));
    g3d_log(G3D_LOG_INFO, "depth model: %s (%s)", p->depth_model, r->own_depth.name);
    const char *rgb = p->input.rgb_path;
    if (!p->frame && rgb && !p->input.depth_path && !metric)
        return G3D_ERR(G3D_ERR_ARG, "%s: relative Depth Anything V2 gives no metres for %s; use MoGe-2 or a metric "
                       "checkpoint (--max-depth), or give --depth", p->depth_model, rgb);
    return G3D_OK;
}

/* LaMa from p->lama_model, else the classical inpainter, into *out; role names it in the log. */
static g3d_status make_lama_or_classic(const g3d_generate_params *p, const char *role, g3d_inpainter *out)
{
    if (!p->lama_model) return g3d_inpainter_classic_create(NULL, out);
    G3D_TRY(g3d_inpainter_lama_create(p->lama_model, out));
    char desc[256];
    g3d_log(G3D_LOG_INFO, "%s: %s (%s)", role, p->lama_model, g3d_lama_describe(out->ctx, desc, sizeof desc));
    return G3D_OK;
}

/* Loads the Stable Diffusion model `model` with the run's parts (VAE, text encoder, tokenizer,
 * configuration), and the ControlNet `controlnet` when not NULL. */
static g3d_status load_sd(const g3d_generate_params *p, const char *model, const char *controlnet, g3d_sd **m)
{
    g3d_sd_paths paths = p->sd_parts;
    paths.model = model;
    if (controlnet) paths.controlnet = controlnet;
    return g3d_sd_load(&paths, m);
}

/* The diffusion inpainter (sd_views.h) on m, which it owns from here, with the run's settings
 * and progress; prefill, when not NULL, fills the ControlNet's hint. Without prefill a model's
 * ControlNet (the background's, sharing the model) is not run. */
static g3d_status make_sd_views(run *r, g3d_sd *m, const g3d_inpainter *prefill, g3d_inpainter *out)
{
    g3d_sd_view_params vp = r->p->diffusion;
    vp.progress = r->progress;
    if (prefill) vp.prefill = prefill;
    else vp.sd.control_scale = 0;
    return g3d_inpainter_sd_views_create(m, &vp, out);
}

/* Whether the background is filled through the ControlNet (make_bg_inpainter). */
static int controlnet_background(const g3d_generate_params *p)
{
    return p->layers && !p->bg_inpainter && p->controlnet_model;
}

/* The inpainter: the caller's, LaMa from p->lama_model, or the classical one. Made before the
 * input is loaded, so that a bad checkpoint fails before any work. A diffusion inpainter is
 * loaded with the background's ControlNet, so that the two hold one copy of the base model. */
static g3d_status make_inpainter(run *r)
{
    const g3d_generate_params *p = r->p;
    r->inpainter = p->inpainter ? p->inpainter : &r->own_inpainter;
    if (p->inpainter) return G3D_OK;
    if (p->inpaint_model) {
        g3d_sd *m;
        G3D_TRY(load_sd(p, p->inpaint_model, controlnet_background(p) ? p->controlnet_model : NULL, &m));
        char desc[512];
        g3d_log(G3D_LOG_INFO, "inpainter: %s (%s)", p->inpaint_model, g3d_sd_unet_describe(g3d_sd_get_unet(m), desc, sizeof desc));
        G3D_TRY(make_sd_views(r, m, NULL, &r->own_inpainter));
        if (g3d_sd_get_controlnet(m)) r->views_sd = m;
        return G3D_OK;
    }
    return make_lama_or_classic(p, "inpainter", &r->own_inpainter);
}

/* The background's inpainter when a ControlNet is given: the inpainting model with the
 * ControlNet (the views' model when it has it), its hint's hole prefilled by LaMa or the
 * classical inpainter. */
static g3d_status make_bg_inpainter(run *r)
{
    const g3d_generate_params *p = r->p;
    if (!controlnet_background(p)) return G3D_OK;
    G3D_TRY(make_lama_or_classic(p, "background prefill", &r->own_prefill));
    g3d_sd *m = g3d_sd_share(r->views_sd);
    if (!m) G3D_TRY(load_sd(p, p->inpaint_model, p->controlnet_model, &m));
    char desc[512];
    g3d_log(G3D_LOG_INFO, "background: %s (%s), hint prefilled by %s", p->controlnet_model,
            g3d_sd_controlnet_describe(g3d_sd_controlnet_get_config(g3d_sd_get_controlnet(m)), desc, sizeof desc),
            r->own_prefill.name);
    return make_sd_views(r, m, &r->own_prefill, &r->own_bg);
}

/* The run's prompts (generate.h, PROMPTS): the user's view prompt, else the provider's, else
 * the neutral one; the provider's background prompt, else the neutral template. */
static g3d_status run_prompt(void *ctx, const g3d_image *rgb, const g3d_image *exclude, char **bg, char **view)
{
    const run *r = ctx;
    *bg = *view = NULL;
    if (r->auto_prompts) G3D_TRY(r->auto_prompts->prompt(r->auto_prompts->ctx, rgb, exclude, bg, view));
    if (r->p->prompt) {
        free(*view);
        *view = NULL;
    }
    if (!*view) *view = strdup(r->p->prompt ? r->p->prompt : G3D_NEUTRAL_VIEW_PROMPT);
    if (!*bg) {
        const char *colors = G3D_NEUTRAL_COLORS;
        *bg = g3d_background_prompt(G3D_NEUTRAL_CATEGORY, &colors, 1);
    }
    if (*bg && *view) return G3D_OK;
    free(*bg);
    free(*view);
    *bg = *view = NULL;
    return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
}

/* The prompt provider: the caller's, or the automatic prompts from the CLIP and BLIP models
 * (no captions when the user gives the views' prompt); wrapped into the run's prompts when
 * anything gives or uses a prompt. */
static g3d_status make_prompts(run *r)
{
    const g3d_generate_params *p = r->p;
    const char *caption = p->prompt ? NULL : p->caption_model;
    r->auto_prompts = p->prompts;
    if (!p->prompts && (p->clip_model || caption)) {
        G3D_TRY(g3d_prompt_provider_describe_create(p->clip_model, NULL, caption, p->seed, &r->own_prompts));
        r->auto_prompts = &r->own_prompts;
    }
    if (!r->auto_prompts && !p->prompt && !p->inpaint_model && !p->inpainter) return G3D_OK;
    const char *name = r->auto_prompts ? r->auto_prompts->name : p->prompt ? "user" : "neutral";
    r->run_prompts = (g3d_prompt_provider){name, r, run_prompt, NULL};
    r->prompts = &r->run_prompts;
    return G3D_OK;
}

/* Text input: the first image drawn from the prompt at the model's native size, square; its
 * depth and camera from the depth model (or the 60-degree convention when it gives none). */
static g3d_status text_input(run *r)
{
    const g3d_generate_params *p = r->p;
    g3d_sd *m;
    g3d_image img = {0};
    G3D_TRY(load_sd(p, p->sd_model, NULL, &m));
    int k = g3d_sd_size_multiple(m), side = p->diffusion.size / k * k;
    g3d_sd_params sp = p->diffusion.sd;
    sp.prompt = p->prompt;
    sp.width = sp.height = side < k ? k : side;
    sp.seed = p->seed;
    sp.noise = NULL;
    sp.progress = r->progress;
    snprintf(r->label, sizeof r->label, "text");
    g3d_log(G3D_LOG_INFO, "text input: %dx%d from \"%s\" (%s)", sp.width, sp.height, p->prompt, p->sd_model);
    double t = g3d_time_now();
    g3d_status rc = g3d_sd_txt2img(m, &sp, &img);
    r->seconds_txt2img = g3d_time_now() - t;
    g3d_sd_free(m);
    if (rc == G3D_OK && sp.truncated)
        g3d_log(G3D_LOG_WARN, "the prompts lost %d tokens beyond the text encoder's context", sp.truncated);
    if (rc == G3D_OK) rc = g3d_frame_from_image(&img, "text", r->depth, p->input.K, p->input.fov_deg, p->input.max_side, &r->frame);
    else g3d_image_free(&img);
    return rc;
}

static g3d_status stage_input(run *r)
{
    const g3d_generate_params *p = r->p;
    G3D_TRY(make_inpainter(r));
    G3D_TRY(make_bg_inpainter(r));
    G3D_TRY(make_prompts(r));
    G3D_TRY(make_depth(r));
    if (p->frame) {
        G3D_TRY(g3d_frame_validate(p->frame, p->frame->name[0] ? p->frame->name : "input frame"));
        r->input = p->frame;
    } else if (p->sd_model) {
        G3D_TRY(text_input(r));
        r->input = &r->frame;
    } else {
        /* only a model predicts the depth of an image; completion needs depth to start from */
        const g3d_depth_estimator *model = p->depth || p->depth_model ? r->depth : NULL;
        G3D_TRY(g3d_frame_load(&p->input, model, &r->frame));
        r->input = &r->frame;
    }
    log_frame(r->input);
    if (p->last_stage == G3D_STAGE_INPUT) return g3d_frame_save(r->input, p->output_dir);
    return G3D_OK;
}

/* ---- layers ---------------------------------------------------------------------------------- */

/* The background's inpainter, timed (the summary's seconds_background). */
static g3d_status timed_inpaint(void *ctx, g3d_image *image, const g3d_image *mask, const char *prompt, uint64_t seed)
{
    run *r = ctx;
    double t = g3d_time_now();
    g3d_status rc = r->bg_inner->inpaint(r->bg_inner->ctx, image, mask, prompt, seed);
    r->seconds_background += g3d_time_now() - t;
    return rc;
}

static g3d_status stage_layers(run *r)
{
    const g3d_generate_params *p = r->p;
    if (!p->layers) return G3D_OK;
    r->masks = p->masks;
    if (!r->masks && p->seg_model) {
        G3D_TRY(g3d_mask_provider_sam_create(p->seg_model, NULL, &r->own_masks));
        g3d_log(G3D_LOG_INFO, "layer masks: Segment Anything (%s)", p->seg_model);
        r->masks = &r->own_masks;
    } else if (!r->masks) {
        G3D_TRY(g3d_mask_provider_regions_create(NULL, r->input->cam.K, &r->own_masks));
        r->masks = &r->own_masks;
    }
    const g3d_frame *f = r->input;
    g3d_layers_params lp = p->layers_params;
    if (r->prompts) lp.prompts = r->prompts;
    r->bg_inner = p->bg_inpainter ? p->bg_inpainter : r->own_bg.inpaint ? &r->own_bg : r->inpainter;
    r->bg_timed = (g3d_inpainter){r->bg_inner->name, r, timed_inpaint, NULL};
    snprintf(r->label, sizeof r->label, "background");
    G3D_TRY(g3d_layers_compute(&f->rgb, &f->depth, r->masks, &r->bg_timed, r->depth, &lp, p->seed, &r->layers));
    if (r->layers.bg_prompt) g3d_log(G3D_LOG_INFO, "background prompt: %s", r->layers.bg_prompt);
    return G3D_OK;
}

/* ---- world ----------------------------------------------------------------------------------- */

/* Generation steps at the exploration set's cameras (all but the input's own), after the
 * trajectory: a rotation reveals nothing behind the input's depth edges, and the set's
 * steps and turns do, so their holes are inpainted and lifted, as the world's side steps
 * (world.h: at a lower resolution). */
static g3d_status append_explore_poses(const g3d_generate_params *p, const g3d_frame *f, g3d_mat4 **poses, int *n)
{
    g3d_camera origin = {f->cam.K, g3d_mat4_identity()}, *cams;
    G3D_TRY(g3d_explore_cameras(&origin, g3d_depth_median(&f->depth), &p->explore, &cams, NULL));
    g3d_mat4 *all = realloc(*poses, sizeof **poses * (size_t)(*n + G3D_EXPLORE_CAMERAS));
    if (!all) {
        free(cams);
        return G3D_ERR(G3D_ERR_NOMEM, "generate: out of memory");
    }
    *poses = all;
    for (int i = 0; i < G3D_EXPLORE_CAMERAS; i++)
        if (g3d_mat4_max_abs_diff(cams[i].c2w, g3d_mat4_identity()) > 1e-12) all[(*n)++] = cams[i].c2w;
    free(cams);
    return G3D_OK;
}

/* The trajectory's poses: a camera file, or a preset scaled by the input's median depth;
 * then picked to steps + 1 poses when steps is given (*n_path of them); then, with
 * explore_views, the exploration set's cameras. */
static g3d_status make_poses(const g3d_generate_params *p, const g3d_frame *f, g3d_mat4 **poses, int *n, int *n_path)
{
    g3d_status rc;
    *poses = NULL;
    *n = 0;
    if (g3d_trajectory_is_file(p->trajectory)) {
        g3d_camera *cams = NULL;
        rc = g3d_trajectory_load(p->trajectory, &cams, n);
        if (rc == G3D_OK && !(*poses = g3d_calloc((size_t)*n, sizeof **poses, "poses"))) rc = G3D_ERR_NOMEM;
        for (int i = 0; rc == G3D_OK && i < *n; i++) (*poses)[i] = cams[i].c2w;
        free(cams);
    } else {
        g3d_trajectory_params tp = p->trajectory_params;
        if (p->steps > 0 && !strcmp(p->trajectory, "rotate")) tp.steps = p->steps;
        /* a keyframed preset then makes exactly those poses, evenly spaced (the pick below
         * would repeat poses to go beyond the preset's count) */
        if (p->steps > 0 && p->steps - 1 <= G3D_TRAJECTORY_MAX_INTERP) tp.interp = p->steps - 1;
        rc = g3d_trajectory_make(p->trajectory, &tp, g3d_depth_median(&f->depth), poses, n);
    }
    if (rc == G3D_OK && p->steps > 0 && p->steps + 1 != *n) {
        g3d_mat4 *picked;
        rc = g3d_trajectory_pick(*poses, *n, p->steps + 1, &picked);
        if (rc == G3D_OK) {
            free(*poses);
            *poses = picked;
            *n = p->steps + 1;
        }
    }
    *n_path = *n;
    if (rc == G3D_OK && explore_steps(p)) rc = append_explore_poses(p, f, poses, n);
    if (rc != G3D_OK) {
        free(*poses);
        *poses = NULL;
    }
    return rc;
}

static g3d_status stage_world(run *r)
{
    const g3d_generate_params *p = r->p;
    if (p->world_dir) {
        G3D_TRY(g3d_world_load(p->world_dir, &r->world));
        if (r->world.n_views + r->world.n_extra == 0) return G3D_ERR(G3D_ERR_FORMAT, "%s: the world has no views", p->world_dir);
        g3d_log(G3D_LOG_INFO, "world %s: %lld points, %d views + %d extra", p->world_dir, (long long)r->world.cloud.n,
                r->world.n_views, r->world.n_extra);
        return G3D_OK;
    }
    const g3d_frame *f = r->input;
    g3d_mat4 *poses;
    int n, n_path;
    G3D_TRY(make_poses(p, f, &poses, &n, &n_path));
    g3d_world_params wp = p->world;
    wp.side_from = n_path < n ? n_path : 0;
    wp.progress = r->progress;
    if (r->prompts && !p->layers)
        G3D_TRY(r->prompts->prompt(r->prompts->ctx, &f->rgb, NULL, &r->bg_prompt, &r->view_prompt));
    if (r->prompts) wp.prompt = p->layers ? r->layers.view_prompt : r->view_prompt;
    if (wp.prompt) g3d_log(G3D_LOG_INFO, "views' prompt: %s", wp.prompt);
    g3d_log(G3D_LOG_INFO, "world: %s, %dx%d, %d poses (%s), %d extra views", f->name, f->rgb.w, f->rgb.h, n, p->trajectory,
            wp.extra_views);
    double t0 = g3d_time_now();
    g3d_status rc = g3d_world_generate(f, poses, n, r->inpainter, r->depth, p->layers ? &r->layers : NULL, &wp, p->seed,
                                       &r->world);
    free(poses);
    if (rc != G3D_OK) return rc;
    g3d_log(G3D_LOG_INFO, "world: %lld points, %d views + %d extra, %d foreground objects, %.1f s", (long long)r->world.cloud.n,
            r->world.n_views, r->world.n_extra, r->world.layers.n_foreground, g3d_time_now() - t0);
    if (p->last_stage == G3D_STAGE_WORLD) return g3d_world_save(&r->world, p->output_dir, p->seed);
    return G3D_OK;
}

/* ---- splats ---------------------------------------------------------------------------------- */

/* The training views: every generated view whole, the extra views on their valid pixels. */
static g3d_status train_views(const g3d_world *w, g3d_train_view **out, int *n)
{
    *n = w->n_views + w->n_extra;
    g3d_train_view *v = g3d_calloc((size_t)*n, sizeof *v, "training views");
    if (!v) return G3D_ERR_NOMEM;
    for (int i = 0; i < w->n_views; i++) v[i] = (g3d_train_view){w->cams[i], &w->rgb[i], NULL};
    for (int i = 0; i < w->n_extra; i++)
        v[w->n_views + i] = (g3d_train_view){w->extra_cams[i], &w->extra_rgb[i], &w->extra_mask[i]};
    *out = v;
    return G3D_OK;
}

/* A generated world's points keep their pixel footprints; a world read from a folder has none. */
static int cloud_has_footprints(const g3d_cloud *c)
{
    for (int64_t i = 0; i < c->n; i++)
        if (!(c->size[i] > 0)) return 0;
    return 1;
}

static g3d_status stage_splats(run *r)
{
    const g3d_generate_params *p = r->p;
    const g3d_world *w = &r->world;
    g3d_train_view *views = NULL;
    int nviews = 0;
    G3D_TRY(train_views(w, &views, &nviews));
    g3d_status rc;
    if (w->cloud.n > 0 && !p->knn_init && cloud_has_footprints(&w->cloud)) {
        rc = g3d_gaussians_init_from_footprints(&r->scene, w->cloud.xyz, w->cloud.rgb, w->cloud.span, w->cloud.n,
                                                p->sh_degree, &p->footprint);
    } else if (w->cloud.n > 0) {
        rc = g3d_gaussians_init_from_points(&r->scene, w->cloud.xyz, w->cloud.rgb, w->cloud.n, p->sh_degree);
    } else {
        g3d_log(G3D_LOG_WARN, "no point cloud: starting from %d random points", G3D_RANDOM_INIT_POINTS);
        rc = g3d_gaussians_init_random(&r->scene, views, nviews, G3D_RANDOM_INIT_POINTS, p->sh_degree, p->seed);
    }
    r->initial_gaussians = r->scene.n;
    if (rc == G3D_OK) {
        g3d_train_params tp = p->train;
        tp.seed = p->seed;
        if (w->n_views > 0) tp.first_view_every = p->input_every;
        tp.coverage_weight = p->coverage_weight;
        tp.progress = r->progress;
        rc = g3d_train(&r->scene, views, nviews, &tp, &r->train);
    }
    free(views);
    if (rc == G3D_OK)
        g3d_log(G3D_LOG_INFO, "splats: %d views, %lld -> %lld Gaussians, PSNR %.2f dB", nviews, (long long)r->initial_gaussians,
                (long long)r->scene.n, r->train.last_psnr);
    return rc;
}

/* ---- exploration ----------------------------------------------------------------------------- */

/* The input camera and the scene's median depth that the exploration set is built around: the
 * input's depth, else a saved world's first depth map, else (scale 0) to be measured on the
 * trained scene. */
static g3d_camera explore_origin(const run *r, double *scale)
{
    const g3d_world *w = &r->world;
    *scale = 0;
    if (r->input) {
        *scale = g3d_depth_median(&r->input->depth);
        return r->input->cam;
    }
    if (w->n_views && w->depth[0].data) *scale = g3d_depth_median(&w->depth[0]);
    return w->n_views ? w->cams[0] : w->extra_cams[0];
}

/* The exploration set (*cams malloc'd), refused as soon as the scene's scale is known. */
static g3d_status explore_set(const run *r, g3d_camera **cams, double *distance)
{
    double scale;
    g3d_camera origin = explore_origin(r, &scale);
    *cams = NULL;
    if (!(scale > 0) && r->scene.n > 0) G3D_TRY(g3d_render_scene_scale(&r->scene, &origin, &scale));
    if (!(scale > 0)) return G3D_OK;
    return g3d_explore_cameras(&origin, scale, &r->p->explore, cams, distance);
}

/* Columns of the contact sheet (three rows of nine for the exploration set), and the longer
 * side of its thumbnails in pixels. */
#define SHEET_COLUMNS 9
#define SHEET_THUMB 128

/* Coverage of the exploration set: the figures into res, the contact sheet into *sheet (when
 * non-NULL) and the cameras into *cams (malloc'd). */
static g3d_status measure_exploration(const run *r, g3d_generate_result *res, g3d_image *sheet, g3d_camera **cams)
{
    G3D_TRY(explore_set(r, cams, &res->explore_distance));
    if (!*cams) return G3D_ERR(G3D_ERR_ARG, "generate: the scene has no depth in front of the input camera to scale the exploration set");
    G3D_TRY(g3d_explore_coverage(&r->scene, *cams, G3D_EXPLORE_CAMERAS, res->explore_empty, sheet, SHEET_COLUMNS,
                                 SHEET_THUMB));
    res->explore_mean_empty = res->explore_max_empty = 0;
    for (int i = 0; i < G3D_EXPLORE_CAMERAS; i++) {
        res->explore_mean_empty += res->explore_empty[i] / G3D_EXPLORE_CAMERAS;
        if (res->explore_empty[i] > res->explore_max_empty) res->explore_max_empty = res->explore_empty[i];
    }
    g3d_log(G3D_LOG_INFO, "exploration: %d cameras within %.2f m, empty pixels %.3f %% mean, %.3f %% worst",
            G3D_EXPLORE_CAMERAS, res->explore_distance, 100 * res->explore_mean_empty, 100 * res->explore_max_empty);
    return G3D_OK;
}

/* ---- outputs --------------------------------------------------------------------------------- */

/* Runs `call` with `path` = tmp/name (the macro keeps every file write one line). */
#define WRITE(name, call)                                                                      \
    do {                                                                                       \
        char *path = g3d_path_join(r->tmp, name);                                              \
        rc = path ? (call) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");                          \
        free(path);                                                                            \
    } while (0)

static g3d_status write_json(run *r, const char *name, cJSON *o)
{
    g3d_status rc;
    char *text = cJSON_Print(o);
    if (!text) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    WRITE(name, g3d_write_file_atomic(path, text, strlen(text)));
    free(text);
    return rc;
}

/* cameras.json, transforms.json and points.ply at the top of the folder (image paths under
 * dataset/), so that the folder is itself a dataset for `gen3d train` and nerfstudio tools. */
static g3d_status write_cameras(run *r)
{
    g3d_camera_list l;
    g3d_points pts = {0};
    G3D_TRY(g3d_world_cameras(&r->world, "dataset/", &l));
    g3d_status rc;
    WRITE("cameras.json", g3d_cameras_json_write(path, &l));
    if (rc == G3D_OK) WRITE("transforms.json", g3d_transforms_json_write(path, &l));
    if (rc == G3D_OK) rc = g3d_cloud_to_points(&r->world.cloud, &pts);
    if (rc == G3D_OK) WRITE("points.ply", g3d_ply_write_points(path, &pts));
    g3d_camera_list_free(&l);
    g3d_points_free(&pts);
    return rc;
}

/* The scene seen from the input camera. */
static g3d_status write_preview(run *r)
{
    const g3d_camera *cam = &r->world.cams[0];
    g3d_raster_ws *ws = NULL;
    g3d_raster_params s;
    g3d_raster_params_default(&s);
    g3d_image img;
    g3d_status rc = g3d_image_create(&img, cam->K.width, cam->K.height, 3);
    if (rc != G3D_OK) return rc;
    rc = g3d_raster_ws_create(&ws);
    if (rc == G3D_OK) rc = g3d_raster_fwd(ws, &r->scene, cam, &s, img.data, NULL, NULL, NULL);
    g3d_raster_ws_free(ws);
    if (rc == G3D_OK) WRITE("preview.png", g3d_image_save_png(path, &img, 8));
    g3d_image_free(&img);
    return rc;
}

/* The fly-through: video.mp4, or PNG frames in frames/ when ffmpeg is missing. */
static g3d_status write_video(run *r)
{
    const g3d_generate_params *p = r->p;
    g3d_camera *cams = NULL;
    int n = 0;
    G3D_TRY(g3d_render_flythrough(p->video_trajectory, NULL, &r->scene, &r->world.cams[0], 0, p->video_frames, &cams, &n));
    g3d_render_params rp;
    g3d_render_params_default(&rp);
    rp.progress = r->progress;
    g3d_render_output_params out;
    g3d_render_output_params_default(&out);
    out.frames = 0;
    out.cameras = 0;
    out.video_params = p->video_params;
    g3d_status rc = g3d_render_to_dir(&r->scene, cams, n, &rp, &out, r->tmp, &r->video);
    free(cams);
    return rc;
}

/* The diffusion settings both models run with. */
static cJSON *diffusion_json(const g3d_generate_params *p)
{
    const g3d_sd_view_params *d = &p->diffusion;
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "negative_prompt", d->sd.negative ? d->sd.negative : "");
    cJSON_AddStringToObject(o, "sampler", g3d_sd_sampler_name(d->sd.sampler.kind));
    cJSON_AddNumberToObject(o, "steps", d->sd.sampler.steps);
    cJSON_AddNumberToObject(o, "guidance", d->sd.cfg);
    cJSON_AddBoolToObject(o, "karras", d->sd.sampler.karras);
    cJSON_AddNumberToObject(o, "eta", d->sd.sampler.eta);
    cJSON_AddNumberToObject(o, "size", d->size);
    cJSON_AddNumberToObject(o, "dilate", d->dilate);
    const char *parts[][2] = {{"vae", p->sd_parts.vae}, {"text_encoder", p->sd_parts.text_encoder},
                              {"tokenizer", p->sd_parts.tokenizer}, {"config", p->sd_parts.yaml}};
    for (int i = 0; i < 4; i++)
        if (parts[i][1]) cJSON_AddStringToObject(o, parts[i][0], parts[i][1]);
    return o;
}

static cJSON *config_json(const run *r)
{
    const g3d_generate_params *p = r->p;
    cJSON *c = cJSON_CreateObject();
    if (p->world_dir) {
        cJSON_AddStringToObject(c, "world", p->world_dir);
    } else {
        const g3d_frame *f = r->input;
        cJSON_AddStringToObject(c, "input", f->name);
        cJSON_AddNumberToObject(c, "width", f->rgb.w);
        cJSON_AddNumberToObject(c, "height", f->rgb.h);
        cJSON_AddNumberToObject(c, "fx", f->cam.K.fx);
        cJSON_AddNumberToObject(c, "fy", f->cam.K.fy);
        cJSON_AddNumberToObject(c, "cx", f->cam.K.cx);
        cJSON_AddNumberToObject(c, "cy", f->cam.K.cy);
    }
    cJSON_AddNumberToObject(c, "seed", (double)p->seed);
    if (!p->world_dir) {
        cJSON_AddStringToObject(c, "trajectory", p->trajectory);
        cJSON_AddNumberToObject(c, "steps", p->steps);
        cJSON_AddNumberToObject(c, "angle", p->trajectory_params.angle_deg);
        cJSON_AddNumberToObject(c, "distance", p->trajectory_params.distance);
        cJSON_AddNumberToObject(c, "extra", p->world.extra_views);
        cJSON_AddNumberToObject(c, "max_side", p->input.max_side);
        cJSON_AddBoolToObject(c, "layers", p->layers);
        cJSON_AddStringToObject(c, "inpainter", r->inpainter->name);
        cJSON_AddStringToObject(c, "depth_estimator", r->depth->name);
        if (p->layers) cJSON_AddStringToObject(c, "mask_provider", r->masks->name);
        if (p->depth_model && !p->depth) cJSON_AddStringToObject(c, "depth_model", p->depth_model);
        if (p->lama_model && !p->inpainter) cJSON_AddStringToObject(c, "lama_model", p->lama_model);
        if (p->seg_model && !p->masks) cJSON_AddStringToObject(c, "seg_model", p->seg_model);
        if (p->layers) cJSON_AddStringToObject(c, "background_inpainter", r->bg_inner->name);
        if (p->prompt) cJSON_AddStringToObject(c, "prompt", p->prompt);
        if (p->sd_model) cJSON_AddStringToObject(c, "sd_model", p->sd_model);
        if (p->inpaint_model && !p->inpainter) cJSON_AddStringToObject(c, "inpaint_model", p->inpaint_model);
        if (r->own_bg.inpaint) cJSON_AddStringToObject(c, "controlnet_model", p->controlnet_model);
        if (p->sd_model || (p->inpaint_model && !p->inpainter)) cJSON_AddItemToObject(c, "diffusion", diffusion_json(p));
        if (r->prompts) {
            const char *bg = p->layers ? r->layers.bg_prompt : r->bg_prompt, *view = p->layers ? r->layers.view_prompt : r->view_prompt;
            cJSON_AddStringToObject(c, "prompt_provider", r->prompts->name);
            if (p->clip_model && !p->prompts) cJSON_AddStringToObject(c, "clip_model", p->clip_model);
            if (p->caption_model && !p->prompts) cJSON_AddStringToObject(c, "caption_model", p->caption_model);
            if (bg) cJSON_AddStringToObject(c, "background_prompt", bg);
            if (view) cJSON_AddStringToObject(c, "view_prompt", view);
        }
    }
    if (!p->world_dir) cJSON_AddBoolToObject(c, "explore_views", explore_steps(p));
    cJSON_AddNumberToObject(c, "explore_distance", p->explore.distance);
    cJSON_AddNumberToObject(c, "explore_angle", p->explore.angle_deg);
    cJSON_AddNumberToObject(c, "iterations", (double)p->train.iterations);
    cJSON_AddNumberToObject(c, "sh_degree", p->sh_degree);
    cJSON_AddStringToObject(c, "init", p->knn_init ? "knn" : "footprint");
    cJSON_AddNumberToObject(c, "input_every", p->input_every);
    cJSON_AddNumberToObject(c, "coverage_weight", p->coverage_weight);
    cJSON_AddStringToObject(c, "video_trajectory", p->video_trajectory);
    cJSON_AddNumberToObject(c, "video_frames", p->video_frames);
    cJSON_AddNumberToObject(c, "fps", p->video_params.fps);
    cJSON_AddBoolToObject(c, "video", p->video);
    cJSON_AddNumberToObject(c, "threads", omp_get_max_threads());
    return c;
}

/* Seconds of each generation step after the input, by part. */
static cJSON *view_seconds_json(const g3d_world *w)
{
    cJSON *a = cJSON_CreateArray();
    for (int i = 1; i < w->n_views; i++) {
        const g3d_world_step *st = &w->steps[i];
        cJSON *o = cJSON_CreateObject();
        cJSON_AddNumberToObject(o, "view", i);
        cJSON_AddNumberToObject(o, "reproject", st->seconds_reproject);
        cJSON_AddNumberToObject(o, "inpaint", st->seconds_inpaint);
        cJSON_AddNumberToObject(o, "depth", st->seconds_depth);
        cJSON_AddNumberToObject(o, "align", st->seconds_align);
        cJSON_AddNumberToObject(o, "lift", st->seconds_lift);
        cJSON_AddNumberToObject(o, "total", st->seconds_reproject + st->seconds_inpaint + st->seconds_depth +
                                                st->seconds_align + st->seconds_lift);
        cJSON_AddItemToArray(a, o);
    }
    return a;
}

static cJSON *summary_json(const run *r, const g3d_generate_result *res)
{
    cJSON *s = cJSON_CreateObject();
    cJSON_AddNumberToObject(s, "points", (double)res->points);
    cJSON_AddNumberToObject(s, "views", res->views);
    cJSON_AddNumberToObject(s, "extra_views", res->extra_views);
    cJSON_AddNumberToObject(s, "foreground_objects", res->foreground_objects);
    cJSON_AddNumberToObject(s, "initial_gaussians", (double)res->initial_gaussians);
    cJSON_AddNumberToObject(s, "gaussians", (double)res->gaussians);
    cJSON_AddNumberToObject(s, "train_loss", res->train_loss);
    cJSON_AddNumberToObject(s, "train_psnr_db", res->train_psnr);
    cJSON_AddBoolToObject(s, "video", res->video_written);
    if (res->video_note) cJSON_AddStringToObject(s, "video_note", res->video_note);
    cJSON_AddBoolToObject(s, "viewer", res->viewer_written);
    if (res->explore_distance > 0) {
        cJSON *e = cJSON_AddObjectToObject(s, "exploration");
        cJSON_AddNumberToObject(e, "cameras", G3D_EXPLORE_CAMERAS);
        cJSON_AddNumberToObject(e, "distance_m", res->explore_distance);
        cJSON_AddNumberToObject(e, "mean_empty_fraction", res->explore_mean_empty);
        cJSON_AddNumberToObject(e, "max_empty_fraction", res->explore_max_empty);
        cJSON_AddItemToObject(e, "empty_fraction", cJSON_CreateDoubleArray(res->explore_empty, G3D_EXPLORE_CAMERAS));
    }
    char key[64];
    for (int st = 0; st < G3D_STAGE_COUNT; st++) {
        snprintf(key, sizeof key, "seconds_%s", g3d_stage_name((g3d_stage)st));
        cJSON_AddNumberToObject(s, key, res->seconds[st]);
    }
    cJSON_AddNumberToObject(s, "seconds_total", res->seconds_total);
    if (r->p->sd_model) cJSON_AddNumberToObject(s, "seconds_txt2img", res->seconds_txt2img);
    if (!r->p->world_dir && r->p->layers) cJSON_AddNumberToObject(s, "seconds_background", res->seconds_background);
    if (!r->p->world_dir) cJSON_AddItemToObject(s, "seconds_per_view", view_seconds_json(&r->world));
    struct rusage ru;   /* the whole process's peak resident memory so far (Linux: KiB) */
    if (getrusage(RUSAGE_SELF, &ru) == 0) cJSON_AddNumberToObject(s, "peak_memory_mb", ru.ru_maxrss / 1024.0);
    return s;
}

/* The figures of the result that the stages so far determine (the scene stays in the run). */
static void collect(const run *r, g3d_generate_result *res)
{
    const g3d_world *w = &r->world;
    res->width = r->input ? r->input->rgb.w : w->n_views ? w->rgb[0].w : 0;
    res->height = r->input ? r->input->rgb.h : w->n_views ? w->rgb[0].h : 0;
    res->views = w->n_views;
    res->extra_views = w->n_extra;
    res->foreground_objects = w->layers.n_foreground;
    res->points = w->cloud.n;
    res->initial_gaussians = r->initial_gaussians;
    res->gaussians = r->scene.n;
    res->train_loss = r->train.last_loss;
    res->train_psnr = r->train.last_psnr;
    res->video_written = r->video.video_written;
    res->video_note = r->video.note;
    res->viewer_written = r->viewer_written;
    res->seconds_txt2img = r->seconds_txt2img;
    res->seconds_background = r->seconds_background;
}

/* The exploration cameras (a camera file for `gen3d render --coverage`) and the contact sheet. */
static g3d_status write_exploration(run *r, const g3d_camera *cams, const g3d_image *sheet)
{
    g3d_camera_list l;
    G3D_TRY(g3d_camera_list_create(&l, G3D_EXPLORE_CAMERAS));
    memcpy(l.cams, cams, sizeof *cams * G3D_EXPLORE_CAMERAS);
    g3d_status rc;
    WRITE("exploration_cameras.json", g3d_cameras_json_write(path, &l));
    g3d_camera_list_free(&l);
    if (rc == G3D_OK) WRITE("exploration.png", g3d_image_save_png(path, sheet, 8));
    return rc;
}

static g3d_status stage_outputs(run *r, g3d_generate_result *res, double t_start)
{
    const g3d_generate_params *p = r->p;
    double t0 = g3d_time_now();
    g3d_image sheet = {0};
    g3d_camera *explore = NULL;
    g3d_status rc = measure_exploration(r, res, r->tmp ? &sheet : NULL, &explore);
    if (rc != G3D_OK || !r->tmp) {
        free(explore);
        return rc;
    }
    rc = write_exploration(r, explore, &sheet);
    free(explore);
    g3d_image_free(&sheet);
    if (rc == G3D_OK) WRITE("dataset", g3d_world_save(&r->world, path, p->seed));
    if (rc == G3D_OK) rc = write_cameras(r);
    if (rc == G3D_OK) WRITE("scene.ply", g3d_ply_write_gaussians(path, &r->scene));
    if (rc == G3D_OK) WRITE("scene.spz", g3d_spz_save(path, &r->scene));
    if (rc == G3D_OK) rc = check_cancel(r);
    if (rc == G3D_OK) rc = write_preview(r);
    if (rc == G3D_OK && p->video) rc = write_video(r);
    if (rc == G3D_OK)
        rc = g3d_viewer_write_generated(r->tmp, &r->scene, r->world.cams, r->world.n_views,
                                        p->video ? p->video_trajectory : NULL, p->video_frames,
                                        p->video_params.fps, &r->viewer_written);
    collect(r, res);
    cJSON *c = rc == G3D_OK ? config_json(r) : NULL;
    if (c) rc = write_json(r, "config.json", c);
    cJSON_Delete(c);
    res->seconds[G3D_STAGE_OUTPUTS] = g3d_time_now() - t0;   /* so far: the summary is the last file */
    res->seconds_total = g3d_time_now() - t_start;
    cJSON *s = rc == G3D_OK ? summary_json(r, res) : NULL;
    if (s) rc = write_json(r, "summary.json", s);
    cJSON_Delete(s);
    return rc;
}

#undef WRITE

/* ---- the run --------------------------------------------------------------------------------- */

static void run_free(run *r)
{
    g3d_frame_free(&r->frame);
    g3d_layers_free(&r->layers);
    g3d_world_free(&r->world);
    g3d_gaussians_free(&r->scene);
    g3d_inpainter_free(&r->own_inpainter);
    g3d_inpainter_free(&r->own_bg);
    g3d_inpainter_free(&r->own_prefill);
    g3d_depth_estimator_free(&r->own_depth);
    g3d_mask_provider_free(&r->own_masks);
    g3d_prompt_provider_free(&r->own_prompts);
    free(r->bg_prompt);
    free(r->view_prompt);
    if (r->tmp) g3d_atomic_dir_abort(r->tmp);
    free(r->tmp);
}

g3d_status g3d_generate(const g3d_generate_params *p, g3d_generate_result *res_out)
{
    g3d_generate_result res;
    run r;
    memset(&res, 0, sizeof res);
    memset(&r, 0, sizeof r);
    if (res_out) memset(res_out, 0, sizeof *res_out);
    r.p = p;
    r.progress = (g3d_progress){report, &r};
    g3d_status rc = check_params(p);
    /* claim the output folder first, so that a bad one fails before minutes of work */
    if (rc == G3D_OK && p->output_dir && p->last_stage == G3D_STAGE_OUTPUTS) rc = g3d_atomic_dir_begin(p->output_dir, &r.tmp);
    double t_start = g3d_time_now(), t;
    /* the stages in order; a run from a saved world starts at the world stage, which loads it */
    for (int st = p->world_dir ? G3D_STAGE_WORLD : G3D_STAGE_INPUT; st <= (int)p->last_stage && rc == G3D_OK; st++) {
        t = g3d_time_now();
        switch ((g3d_stage)st) {
        case G3D_STAGE_INPUT: rc = stage_input(&r); break;
        case G3D_STAGE_LAYERS: rc = stage_layers(&r); break;
        case G3D_STAGE_WORLD: rc = stage_world(&r); break;
        case G3D_STAGE_SPLATS: rc = stage_splats(&r); break;
        case G3D_STAGE_OUTPUTS: rc = stage_outputs(&r, &res, t_start); break;
        default: rc = G3D_ERR(G3D_ERR_INTERNAL, "generate: no stage %d", st);
        }
        res.seconds[st] = g3d_time_now() - t;
        if (rc == G3D_OK) rc = check_cancel(&r);
        /* a distance too long for this scene is refused before the work, not after it */
        if (rc == G3D_OK && st == (p->world_dir ? G3D_STAGE_WORLD : G3D_STAGE_INPUT) && uses_explore(p)) {
            g3d_camera *cams;
            double d;
            rc = explore_set(&r, &cams, &d);
            free(cams);
        }
    }
    if (rc == G3D_OK && r.tmp) rc = g3d_atomic_dir_commit(r.tmp, p->output_dir);
    res.seconds_total = g3d_time_now() - t_start;
    if (rc == G3D_OK) {
        collect(&r, &res);
        res.scene = r.scene;
        memset(&r.scene, 0, sizeof r.scene);
    }
    run_free(&r);
    if (rc == G3D_OK && res_out) *res_out = res;
    else g3d_gaussians_free(&res.scene);
    return rc;
}
