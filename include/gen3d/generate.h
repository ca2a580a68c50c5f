/* gen3d/generate.h - the whole pipeline in one call: one input to a trained Gaussian-splat
 * scene and its outputs.
 *
 *     input ──► layers ──► world ──► splats ──► outputs
 *     (frame)   (fg/bg)    (cloud,    (trained   (scene.ply/.spz, cameras, dataset,
 *                           views)     Gaussians)  preview, video, summary)
 *
 * Each stage hands the next a struct in memory (g3d_frame, g3d_layers, g3d_world,
 * g3d_gaussians); files are only written at the end, into one output folder, atomically: a
 * run that fails or is cancelled leaves nothing behind.
 *
 * USAGE
 *     g3d_generate_params p;
 *     g3d_generate_params_default(&p);
 *     p.input.rgb_path = "room.png";                 // or p.frame = &my_frame
 *     p.input.depth_path = "room_depth.png";         // or p.depth_model = "moge2.pt"
 *     g3d_train_params_default(&p.train, 200);       // a shorter schedule
 *     p.output_dir = "scene";
 *     g3d_generate_result r;
 *     if (g3d_generate(&p, &r) != G3D_OK) fprintf(stderr, "%s\n", g3d_error_message());
 *     ... r.scene, r.seconds[G3D_STAGE_SPLATS] ...
 *     g3d_generate_result_free(&r);
 *
 * PLUG-INS
 *   The inpainter, depth estimator and mask provider (providers.h) are either passed in (the
 *   caller keeps ownership; e.g. a diffusion inpainter or a segmentation model) or, when NULL,
 *   made by the run from the parameters and released at its end: Stable Diffusion from
 *   `inpaint_model` (sd_views.h), else LaMa from `lama_model`, else the classical inpainter,
 *   for the views and the background alike (the background by the ControlNet of
 *   `controlnet_model` on a LaMa-prefilled hint when given); the depth model in `depth_model` or else depth
 *   completion, the weight-free region proposals (regions.h). A plug-in's own parameters go to
 *   its create function.
 *
 * PROMPTS
 *   The views' prompt is `prompt`, else the prompt provider's view prompt (`prompts`, or the
 *   automatic prompts of describe.h from clip_model / caption_model), else
 *   G3D_NEUTRAL_VIEW_PROMPT; the background's is the provider's template, else the template
 *   with G3D_NEUTRAL_CATEGORY and G3D_NEUTRAL_COLORS. Runs with no prompt, no provider and no
 *   inpaint_model have no prompts.
 *
 * PROGRESS AND CANCELLING
 *   `progress` receives every stage's reports (stage names "text", "background", "view i/n"
 *   for the diffusion steps, "world", "extra views", "train", "render"); `cancel` is polled at
 *   each report and between the stages. A cancelled run
 *   returns G3D_CANCELLED. The progress fields inside the stage parameters are ignored.
 *
 * A run is deterministic for a seed and thread count. Runs in different threads are
 * independent apart from the process-wide log and OpenMP settings (base.h).
 */
#ifndef G3D_GENERATE_H
#define G3D_GENERATE_H

#include "gen3d/depth_estimators.h"
#include "gen3d/explore.h"
#include "gen3d/frame.h"
#include "gen3d/init.h"
#include "gen3d/layers.h"
#include "gen3d/providers.h"
#include "gen3d/render.h"
#include "gen3d/sd_views.h"
#include "gen3d/train.h"
#include "gen3d/trajectory.h"
#include "gen3d/world.h"

#ifdef __cplusplus
extern "C" {
#endif

/* The views' inpainting prompt when neither the user nor a model gives one. */
#define G3D_NEUTRAL_VIEW_PROMPT "a high-resolution photograph of the same scene, photorealistic, 8K"
/* The background template's bracketed parts without a CLIP model (describe.h has the template). */
#define G3D_NEUTRAL_CATEGORY "scene"
#define G3D_NEUTRAL_COLORS "natural"

typedef enum g3d_stage {
    G3D_STAGE_INPUT,    /* the input frame: files, or an image and a depth model */
    G3D_STAGE_LAYERS,   /* foreground / background split */
    G3D_STAGE_WORLD,    /* world generation along the trajectory */
    G3D_STAGE_SPLATS,   /* Gaussians initialised from the cloud and trained */
    G3D_STAGE_OUTPUTS,  /* files: dataset, cameras, scene, preview, video, summary */
    G3D_STAGE_COUNT
} g3d_stage;

/* "input", "layers", "world", "splats", "outputs"; "unknown" otherwise. */
const char *g3d_stage_name(g3d_stage s);

typedef struct g3d_generate_params {
    /* ---- input ---- */
    g3d_frame_params input;           /* where the frame comes from; max_side 768 (the default
                                         input at its full 741 x 500) */
    const g3d_frame *frame;           /* a frame already in memory instead, used as it is
                                         (borrowed; `input` is then ignored) */
    const char *world_dir;            /* start from a saved world folder (g3d_world_load; any
                                         dataset folder): input, layers and world are skipped */
    /* ---- plug-ins: NULL = made by the run ---- */
    const g3d_inpainter *inpainter;       /* NULL: LaMa when lama_model is given, else the
                                             classical PatchMatch inpainter */
    const g3d_depth_estimator *depth;     /* NULL: depth_model when given, else depth completion */
    const g3d_mask_provider *masks;       /* NULL: SAM's automatic masks when seg_model is given,
                                             else weight-free region proposals */
    const char *depth_model;              /* checkpoint for the depth estimator (recognize.h) */
    const char *lama_model;               /* LaMa checkpoint for the inpainter (lama.h) */
    const char *seg_model;                /* Segment Anything checkpoint for the layers (sam.h) */
    const g3d_prompt_provider *prompts;   /* NULL: automatic prompts (describe.h) when clip_model
                                             or caption_model is given, else no prompts */
    const char *clip_model;               /* CLIP model: the background prompt's scene category */
    const char *caption_model;            /* BLIP captioner: the views' prompt */
    const g3d_inpainter *bg_inpainter;    /* the background behind the foreground; NULL: the
                                             views' inpainter (a conditioned inpainter, e.g. on a
                                             LaMa-prefilled picture, plugs in here) */
    /* ---- text and diffusion ---- */
    const char *prompt;                   /* the user's prompt: with sd_model the text input, and
                                             the views' inpainting prompt (NULL: the automatic
                                             prompts, else G3D_NEUTRAL_VIEW_PROMPT) */
    const char *sd_model;                 /* text input: a text-to-image Stable Diffusion model
                                             draws the first image from `prompt` (sd.h), whose
                                             depth and camera the depth model gives (input.rgb_path
                                             must be NULL) */
    const char *inpaint_model;            /* Stable Diffusion inpainting (or text-to-image) model
                                             for every new view and the background (sd_views.h);
                                             NULL: LaMa / classical as above */
    const char *controlnet_model;         /* the inpainting ControlNet (control_v11p_sd15_inpaint)
                                             for the background behind the foreground, with
                                             inpaint_model as its base: the hole is prefilled by
                                             LaMa (lama_model), else the classical inpainter, and
                                             that picture is the ControlNet's hint (sd_views.h);
                                             ignored when bg_inpainter is given */
    g3d_sd_paths sd_parts;                /* vae, text_encoder, tokenizer, yaml, prediction for
                                             both models (model is ignored) */
    g3d_sd_view_params diffusion;         /* negative prompt, sampler, steps, guidance, native
                                             size (also the text input's side), seam dilation */
    g3d_depth_model_params depth_model_params;
    /* ---- layers ---- */
    int layers;                       /* 1: split foreground and background (default) */
    g3d_layers_params layers_params;
    /* ---- world ---- */
    const char *trajectory;           /* a preset (trajectory.h) or a camera file ("rotate") */
    g3d_trajectory_params trajectory_params;  /* interp 1: a keyframed preset (push_in ..
                                         pan_right) makes 2 steps, not its video's 50 frames */
    int steps;                        /* generation steps after the input; a preset or file of
                                         another length is picked down or up to steps + 1 poses
                                         (g3d_trajectory_pick); 0: as it is */
    g3d_world_params world;
    int explore_views;                /* 1: after the trajectory, generation steps at the
                                         exploration set's cameras (`explore` below) as the
                                         world's side steps (world.side_max_side, side_carve),
                                         so that what they see behind depth edges is filled
                                         (docs/explore.md); 0: none; -1 (default): on with the
                                         built-in classical and LaMa inpainters, off with
                                         inpaint_model or a caller's `inpainter` (26 more
                                         diffusion views would take hours on a CPU) */
    /* ---- splats ---- */
    int sh_degree;                    /* 0..3 (3) */
    int knn_init;                     /* 1: Gaussians start as the Inria recipe (isotropic, 3-NN
                                         scale, opacity 0.1; init.h); 0 (default): as the pixel
                                         footprints of the world's points (`footprint`), where
                                         the cloud keeps them (not a world read from a folder) */
    g3d_footprint_init footprint;     /* g3d_footprint_init_default */
    int input_every;                  /* > 0: the input view is trained every this many
                                         iterations besides its turn among the views (2: the only
                                         view of real pixels, against dozens of re-rendered and
                                         inpainted ones, the exploration's side steps among
                                         them); 0: its turn only */
    double coverage_weight;           /* the training's coverage term (train.h coverage_weight;
                                         0.2): every generated view is whole, so no pixel of it
                                         should end up transparent */
    g3d_train_params train;           /* g3d_train_params_default(&p.train, 500); its seed is
                                         replaced by `seed`, its coverage_weight by the above */
    /* ---- outputs ---- */
    const char *output_dir;           /* NULL: no files (the result still holds the scene) */
    g3d_stage last_stage;             /* G3D_STAGE_OUTPUTS: the whole run into output_dir;
                                         G3D_STAGE_WORLD: stop there, output_dir is the world
                                         folder (g3d_world_save); G3D_STAGE_INPUT: stop there,
                                         output_dir is the frame folder (g3d_frame_save) */
    int video;                        /* 1: a fly-through video.mp4 (PNG frames without ffmpeg) */
    const char *video_trajectory;     /* "swing" or a preset (render.h g3d_render_flythrough) */
    int video_frames;                 /* 120 */
    g3d_video_params video_params;
    g3d_explore_params explore;       /* the exploration set whose coverage the run measures
                                         (explore.h; d: a quarter of the input's median depth) */
    /* ---- the run ---- */
    uint64_t seed;                    /* 42 */
    g3d_progress progress;
    g3d_cancel cancel;
} g3d_generate_params;

/* Fills the defaults given above. */
void g3d_generate_params_default(g3d_generate_params *p);

typedef struct g3d_generate_result {
    double seconds[G3D_STAGE_COUNT];  /* wall time of each stage (0 for stages skipped) */
    double seconds_total;
    double seconds_txt2img;           /* text input: the first image's drawing (within the input stage) */
    double seconds_background;        /* filling the background behind the foreground (within layers) */
    int width, height;                /* of the input frame (the world's first view) */
    int views, extra_views;           /* generated views (input included) and extra views */
    int foreground_objects;
    int64_t points;                   /* points in the world's cloud */
    int64_t initial_gaussians, gaussians;
    double train_loss, train_psnr;    /* over the last report period of training, dB */
    int video_written;                /* video.mp4 exists */
    const char *video_note;           /* why no video was written when one was asked for (static), or NULL */
    int viewer_written;               /* viewer.html exists (the viewer template is installed) */
    double explore_distance;          /* d of the exploration set, metres (0 when not measured) */
    double explore_empty[G3D_EXPLORE_CAMERAS];  /* empty-pixel fraction per exploration camera */
    double explore_mean_empty, explore_max_empty;  /* their mean and largest */
    g3d_gaussians scene;              /* the trained Gaussians (empty when the run stopped earlier) */
} g3d_generate_result;

/* Runs the pipeline p describes. res (may be NULL) is filled on success and zeroed on
 * failure; it owns res->scene (g3d_generate_result_free). Parameters are checked before any
 * work (unknown trajectory or video path, bad sizes: G3D_ERR_ARG), and the output folder is
 * claimed next (an existing folder is replaced only if it is an earlier gen3d output). Errors:
 * those of the stages, each naming its file or step; G3D_CANCELLED when cancelled. */
g3d_status g3d_generate(const g3d_generate_params *p, g3d_generate_result *res);

/* Frees res->scene and zeroes res; NULL is fine. */
void g3d_generate_result_free(g3d_generate_result *res);

#ifdef __cplusplus
}
#endif
#endif /* G3D_GENERATE_H */
