/* gen3d/sd.h - Stable Diffusion's latent-diffusion UNet and its VAE (AutoencoderKL), loaded from
 * the published single-file checkpoints (model.diffusion_model.*, first_stage_model.*; .ckpt or
 * .safetensors) with no conversion.
 *
 *   g3d_ckpt *ck;  g3d_sd_unet *unet;  g3d_sd_vae *vae;
 *   g3d_ckpt_open("v1-5-pruned-emaonly.safetensors", &ck);
 *   g3d_sd_unet_load(ck, NULL, &unet);                  // SD 1.x defaults, or a yaml's fields
 *   g3d_sd_vae_load(ck, &vae);
 *   g3d_sd_unet_forward(unet, x, 64, 64, 981, ctx, 77, eps, NULL);   // x [in_ch, 64, 64]
 *   g3d_sd_vae_decode(vae, z, 64, 64, rgb);            // z = latent / G3D_SD_VAE_SCALE
 *
 * Layouts are channels first, batch 1: a latent is [4, h, w], a picture [3, 8h, 8w] in [-1, 1]
 * (for the published 4-level VAE), the text context [n, context_dim] row-major.
 *
 * ARCHITECTURE. Sizes come from the tensors: in-channels (4 text-to-image, 9 inpainting), model
 * channels, the channel multipliers and res blocks per level, which levels have attention, the
 * transformer depth, the context width, Linear or 1x1-conv projections. What the tensors cannot
 * say, the head split, follows the family's published configuration (SD 1.x: 8 heads; SD 2.x,
 * the Linear-projection UNets: heads of 64 channels) unless the original yaml configuration
 * (num_heads / num_head_channels / parameterization) is given. Weights stay in the file's type
 * (fp16, bf16 or fp32) and, for safetensors and PyTorch zips, in the memory mapping.
 *
 * A model is immutable after loading; several threads may run it at once.
 */
#ifndef G3D_SD_H
#define G3D_SD_H

#include "gen3d/base.h"
#include "gen3d/ckpt.h"
#include "gen3d/image.h"
#include "gen3d/providers.h"

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define G3D_SD_MAX_LEVELS 8
/* The latent scale of SD 1.x and 2.x (latent = scale * the VAE's mean). */
#define G3D_SD_VAE_SCALE 0.18215f

typedef enum g3d_sd_pred {
    G3D_SD_PRED_EPS, /* the UNet predicts the noise (SD 1.x, SD 2.x base 512) */
    G3D_SD_PRED_V    /* v-prediction (SD 2.x 768-v): from the yaml's parameterization: "v" */
} g3d_sd_pred;

typedef struct g3d_sd_unet_config {
    const char *prefix;           /* key prefix, e.g. "model.diffusion_model." (static) */
    int in_ch, out_ch, model_ch;  /* 4 or 9, 4, 320 */
    int levels;                   /* len(channel_mult) */
    int mult[G3D_SD_MAX_LEVELS];  /* channel multipliers (1, 2, 4, 4) */
    int nres[G3D_SD_MAX_LEVELS];  /* res blocks per level (2) */
    int attn[G3D_SD_MAX_LEVELS];  /* 1 where the level's res blocks have a transformer */
    int depth;                    /* transformer blocks per spatial transformer (1) */
    int context_dim;              /* 768 (SD 1.x), 1024 (SD 2.x) */
    int heads;                    /* fixed head count (SD 1.x: 8), or 0 ... */
    int head_dim;                 /* ... fixed channels per head (SD 2.x: 64) */
    int linear_proj;              /* 1: Linear proj_in / proj_out (SD 2.x), 0: 1x1 convolutions */
    g3d_sd_pred pred;
    int family;                   /* 1 or 2 (SD 1.x / 2.x), from the conventions above */
    int diffusers;                /* 1: diffusers' key names (unet/diffusion_pytorch_model.*) */
} g3d_sd_unet_config;

typedef struct g3d_sd_unet g3d_sd_unet;

/* Reads the UNet's configuration from an open checkpoint (model.diffusion_model.* or, for a
 * bare UNet state dict, no prefix; or diffusers' UNet2DConditionModel names). yaml, when not
 * NULL, is the text of the original configuration file (v1-inference.yaml, v2-inference-v.yaml,
 * ...): its num_heads, num_head_channels and parameterization are used, and its in_channels and
 * context_dim must agree with the tensors; or, for the diffusers layout, unet/config.json (its
 * attention_head_dim: the heads, per level when a list). G3D_ERR_MODEL naming the first missing or
 * mis-shaped tensor when the file is not a Stable Diffusion UNet. */
g3d_status g3d_sd_unet_probe(const g3d_ckpt *ck, const char *yaml, g3d_sd_unet_config *c);
/* The original configuration published beside a single-file checkpoint: the text of the file
 * with the same name and .yaml in place of the extension (model.ckpt -> model.yaml), malloc'd,
 * or NULL when there is none. */
char *g3d_sd_yaml_beside(const char *model_path);
/* Loads the UNet (the checkpoint must outlive it). Free with g3d_sd_unet_free. */
g3d_status g3d_sd_unet_load(const g3d_ckpt *ck, const char *yaml, g3d_sd_unet **out);
void g3d_sd_unet_free(g3d_sd_unet *m);
const g3d_sd_unet_config *g3d_sd_unet_get_config(const g3d_sd_unet *m);
/* "SD 1.x UNet (4 input channels, model channels 320, multipliers 1/2/4/4, 2 res blocks,
 * attention at levels 0/1/2, context 768, 8 heads, 1x1-conv projections, epsilon)" into buf. */
const char *g3d_sd_unet_describe(const g3d_sd_unet_config *c, char *buf, size_t n);

/* Receives named intermediate results while a network runs (tests compare them with the
 * official code's): a [c, h, w] map, or a vector (h = w = 1). Names: "temb", "in<i>", "mid",
 * "out<i>" for the UNet; "enc_mid", "moments", "dec_conv_in", "dec_mid", "dec_up<level>"
 * for the VAE. */
typedef void (*g3d_sd_trace_fn)(void *ctx, const char *name, const float *x, int c, int h, int w);

/* out [out_ch, h, w] = the UNet at timestep t on x [in_ch, h, w] with the text context
 * ctx [nctx, context_dim]. h and w must be multiples of 2^(levels-1). trace may be NULL. */
g3d_status g3d_sd_unet_forward(const g3d_sd_unet *m, const float *x, int h, int w, float t, const float *ctx,
                               int nctx, float *out, g3d_sd_trace_fn trace, void *trace_ctx);

/* ---- ControlNet ------------------------------------------------------------------------- */
/* ControlNet (lllyasviel's cldm ControlNet, e.g. control_v11p_sd15_inpaint.pth): a copy of the
 * UNet's encoder and middle block whose input gets a hint picture (through input_hint_block:
 * eight 3x3 convolutions with SiLU between them, three of stride 2, so the hint is 8 times the
 * latent's size) added after the first convolution, and a 1x1 "zero" convolution after every
 * input block and the middle block. Their outputs, times a control scale, are added to the
 * UNet's skip connections and to its middle block's output (cldm's ControlledUnetModel). */
#define G3D_SD_HINT_FACTOR 8

typedef struct g3d_sd_controlnet_config {
    g3d_sd_unet_config net;  /* its encoder's configuration (out_ch 0); prefix "control_model." or "" */
    int hint_ch;             /* channels of the hint picture (3) */
} g3d_sd_controlnet_config;

typedef struct g3d_sd_controlnet g3d_sd_controlnet;

/* Reads a ControlNet's configuration from an open checkpoint: the published original layout
 * (control_model.*, or the same names bare) or diffusers' ControlNetModel
 * (diffusion_pytorch_model.safetensors; config, when not NULL, is its config.json text). The
 * head split follows the UNet's rules (SD 1.x: 8 heads; SD 2.x: heads of 64 channels).
 * G3D_ERR_MODEL naming the first missing tensor when the file is not a ControlNet. */
g3d_status g3d_sd_controlnet_probe(const g3d_ckpt *ck, const char *config, g3d_sd_controlnet_config *c);
/* Loads it (the checkpoint must outlive it). Free with g3d_sd_controlnet_free. */
g3d_status g3d_sd_controlnet_load(const g3d_ckpt *ck, const char *config, g3d_sd_controlnet **out);
void g3d_sd_controlnet_free(g3d_sd_controlnet *m);
const g3d_sd_controlnet_config *g3d_sd_controlnet_get_config(const g3d_sd_controlnet *m);
/* "ControlNet for SD 1.x (hint 3 channels at 8x the latent; 4 input channels, ...)" into buf. */
const char *g3d_sd_controlnet_describe(const g3d_sd_controlnet_config *c, char *buf, size_t n);
/* G3D_OK when the ControlNet's residuals fit the UNet (model channels, levels, multipliers, res
 * blocks and context width alike); else G3D_ERR_MODEL, one line naming `path` and both models'
 * figures (an SD 2.x ControlNet given with an SD 1.5 UNet, ...). */
g3d_status g3d_sd_controlnet_check(const g3d_sd_controlnet_config *cn, const char *path, const g3d_sd_unet_config *unet);
/* Floats of the residuals for a latent of h x w: every input block's map, then the middle's. */
size_t g3d_sd_controlnet_residual_floats(const g3d_sd_controlnet *m, int h, int w);
/* residuals = scale x the ControlNet's outputs for the latent x [in_ch, h, w] at timestep t with
 * the context ctx [nctx, context_dim] and the hint [hint_ch, 8h, 8w]. trace (may be NULL)
 * receives "temb", "guided_hint" (the hint block's output) and "control<i>" (unscaled). */
g3d_status g3d_sd_controlnet_forward(const g3d_sd_controlnet *m, const float *x, int h, int w, float t, const float *ctx,
                                     int nctx, const float *hint, float scale, float *residuals, g3d_sd_trace_fn trace,
                                     void *trace_ctx);
/* g3d_sd_unet_forward with a ControlNet's residuals (from g3d_sd_controlnet_forward for the same
 * h x w, checked to fit with g3d_sd_controlnet_check) added to the skip connections and to the
 * middle block's output; residuals NULL: the plain UNet. */
g3d_status g3d_sd_unet_forward_controlled(const g3d_sd_unet *m, const float *x, int h, int w, float t, const float *ctx,
                                          int nctx, const float *residuals, float *out, g3d_sd_trace_fn trace, void *trace_ctx);

/* ---- VAE -------------------------------------------------------------------------------- */

typedef struct g3d_sd_vae_config {
    const char *prefix;          /* "first_stage_model." or "" */
    int diffusers;               /* 1: diffusers' AutoencoderKL names (vae/diffusion_pytorch_model.*) */
    int ch, levels, nres, z_ch;  /* 128, 4, 2, 4 for the published VAE */
    int mult[G3D_SD_MAX_LEVELS]; /* 1, 2, 4, 4 */
    int factor;                  /* picture pixels per latent pixel: 2^(levels-1) */
} g3d_sd_vae_config;

typedef struct g3d_sd_vae g3d_sd_vae;

/* Reads / loads the VAE from an open checkpoint (first_stage_model.*, a bare state dict, or
 * diffusers' names); the same errors as the UNet. */
g3d_status g3d_sd_vae_probe(const g3d_ckpt *ck, g3d_sd_vae_config *c);
g3d_status g3d_sd_vae_load(const g3d_ckpt *ck, g3d_sd_vae **out);
void g3d_sd_vae_free(g3d_sd_vae *m);
const g3d_sd_vae_config *g3d_sd_vae_get_config(const g3d_sd_vae *m);

/* Encoder: rgb [3, H, W] in [-1, 1] -> moments [2 z_ch, H/f, W/f] (the posterior's mean, then
 * its log-variance, after quant_conv). H, W multiples of the factor f. */
g3d_status g3d_sd_vae_encode(const g3d_sd_vae *m, const float *rgb, int H, int W, float *moments,
                             g3d_sd_trace_fn trace, void *trace_ctx);
/* Decoder: z [z_ch, h, w] (unscaled: latent / G3D_SD_VAE_SCALE) -> rgb [3, h f, w f]. */
g3d_status g3d_sd_vae_decode(const g3d_sd_vae *m, const float *z, int h, int w, float *rgb,
                             g3d_sd_trace_fn trace, void *trace_ctx);

/* The decoder on overlapping latent tiles of tile x tile (overlap latent pixels shared by
 * neighbours, blended with linear ramps), for pictures whose whole-latent decoding would need
 * too much memory. Each tile is decoded on its own (its GroupNorm statistics and mid-block
 * attention see only the tile), which is what tiled decoders do; a tile covering the whole
 * latent gives g3d_sd_vae_decode's result exactly. 0 < overlap < tile. */
g3d_status g3d_sd_vae_decode_tiled(const g3d_sd_vae *m, const float *z, int h, int w, int tile, int overlap, float *rgb);

/* ---- samplers --------------------------------------------------------------------------- */
/* The noise schedule is Stable Diffusion's: 1000 steps, betas = linspace(sqrt 0.00085,
 * sqrt 0.012)^2, alphas_cumprod in float32 as ldm stores them. */
#define G3D_SD_TRAIN_STEPS 1000

typedef enum g3d_sd_sampler_kind {
    G3D_SD_DDIM,     /* ldm's DDIMSampler: timesteps 1000/N apart from 1, eta */
    G3D_SD_EULER,    /* k-diffusion sample_euler */
    G3D_SD_EULER_A,  /* k-diffusion sample_euler_ancestral (eta 1) */
    G3D_SD_DPMPP_2M, /* k-diffusion sample_dpmpp_2m */
    G3D_SD_PNDM,     /* diffusers' PNDMScheduler as SD 1.5 configures it: PLMS steps only (its warm-up
                        evaluates the second timestep twice: N + 1 model calls), "leading" timesteps
                        1000/N apart from 1, diffusers' float32 schedule; the default of SD 1.5's
                        diffusers pipeline */
    G3D_SD_PLMS,     /* ldm's PLMSSampler: DDIM's timesteps, a pseudo improved Euler first step (N + 1 model
                        calls), then Adams-Bashforth of order 2 to 4; epsilon models, eta 0 */
    G3D_SD_SAMPLER_COUNT
} g3d_sd_sampler_kind;

/* "ddim", "euler", "euler_a", "dpmpp_2m" (also "dpm++2m"), "pndm", "plms"; -1 if unknown. */
int g3d_sd_sampler_parse(const char *name);
const char *g3d_sd_sampler_name(g3d_sd_sampler_kind k);

typedef struct g3d_sd_sampler {
    g3d_sd_sampler_kind kind;
    int steps;       /* N >= 1 (DDIM may run a few more: ldm's spacing, see g3d_sd_ddim_timesteps) */
    float eta;       /* DDIM only: 0 deterministic, 1 DDPM-like */
    int karras;      /* k-diffusion samplers: Karras et al.'s sigmas (rho 7) instead of the discrete ones */
    g3d_sd_pred pred;
} g3d_sd_sampler;

/* alphas_cumprod[1000] of the schedule (float32 values). */
void g3d_sd_alphas_cumprod(float *ac);
/* DDIM's timesteps for N steps in sampling order (981, 961, ..., 1 for 50): ldm's "uniform"
 * spacing range(0, 1000, 1000 // N) + 1, which gives more than N steps when N does not divide
 * 1000 (7 -> 8). t holds 1000 entries; returns the count. */
int g3d_sd_ddim_timesteps(int steps, int *t);
/* PNDM's timesteps for N steps in calling order (901 801 801 701 ... 1 for 10); t holds N + 1
 * entries; returns the count (N + 1, or 1 for one step). */
int g3d_sd_pndm_timesteps(int steps, int *t);
/* k-diffusion's sigmas for N steps, then a final 0: sigmas[N + 1]. Discrete: CompVisDenoiser's
 * get_sigmas (log-sigma interpolation of 1000 training levels from t = 999 down to 0); Karras:
 * get_sigmas_karras between the smallest and the largest training sigma. */
void g3d_sd_sigmas(int steps, int karras, float *sigmas);

/* The network: out[n] = the model's prediction (eps or v, guidance already applied) for the
 * latent x[n] at timestep t (fractional for the k-diffusion samplers). */
typedef g3d_status (*g3d_sd_model_fn)(void *ctx, const float *x, float t, float *out);
/* Fills z[n] with standard normal values (ancestral steps, DDIM with eta > 0). */
typedef void (*g3d_sd_noise_fn)(void *ctx, float *z, size_t n);
/* Called after step i (from 0) of `total` with the latent so far, which may be changed (latent
 * blending for inpainting with a text-to-image model: known content noised to the level the
 * next step expects is a x0 + b noise, with a = sqrt(alphas_cumprod) and b = sqrt(1 -
 * alphas_cumprod) for DDIM, a = 1 and b = sigma for the others; a = 1, b = 0 after the last
 * step). Non-zero cancels (G3D_CANCELLED). */
typedef int (*g3d_sd_step_fn)(void *ctx, int i, int total, float *x, size_t n, float a, float b);

/* Runs the sampler: x[n] holds the initial noise N(0, 1) on entry (scaled by the first sigma
 * inside for the k-diffusion samplers) and the final latent on return. noise may be NULL for
 * the deterministic samplers; step may be NULL. */
g3d_status g3d_sd_sample(const g3d_sd_sampler *s, float *x, size_t n, g3d_sd_model_fn model, void *model_ctx,
                         g3d_sd_noise_fn noise, void *noise_ctx, g3d_sd_step_fn step, void *step_ctx);

/* ---- text-to-image and inpainting ---------------------------------------------------------
 *
 *   g3d_sd *sd;  g3d_image img = {0};
 *   g3d_sd_load(&(g3d_sd_paths){.model = "v1-5-pruned-emaonly.safetensors"}, &sd);
 *   g3d_sd_params p = g3d_sd_defaults();  p.prompt = "a cosy living room";  p.seed = 1;
 *   g3d_sd_txt2img(sd, &p, &img);                       // 512 x 512 RGB in [0, 1]
 */
typedef struct g3d_sd_paths {
    const char *model;        /* a single-file checkpoint (.safetensors / .ckpt), or a diffusers folder
                                 (unet/, vae/, text_encoder/, tokenizer/, scheduler/ for the prediction type) */
    const char *vae;          /* another file's VAE (first_stage_model.* or bare), or NULL */
    const char *text_encoder; /* another file's text encoder (clip_text.h), or NULL */
    const char *tokenizer;    /* clip_text.h's g3d_clip_tokenizer_load path; NULL: the default vocabulary */
    const char *yaml;         /* the original configuration; NULL: <model>.yaml when it exists */
    int prediction;           /* -1: from the configuration (else epsilon), or a g3d_sd_pred */
    const char *controlnet;   /* a ControlNet (its .pth / .safetensors, or a diffusers folder), or NULL */
} g3d_sd_paths;

typedef struct g3d_sd g3d_sd;

/* Loads the UNet, the VAE, the text encoder, the tokenizer and the ControlNet when one is given;
 * refuses parts that do not fit together (the text width must be the UNet's context width, the
 * ControlNet must fit the UNet) and weights that are not finite (naming the tensor). The
 * model's files stay mapped until g3d_sd_free. */
g3d_status g3d_sd_load(const g3d_sd_paths *p, g3d_sd **out);
/* Gives one more holder the model (e.g. two plug-ins that each free what they own): each
 * holder calls g3d_sd_free, and the last call frees it. Not thread-safe. Returns m. */
g3d_sd *g3d_sd_share(g3d_sd *m);
/* Frees the model once every holder (g3d_sd_share) has let it go. NULL is allowed. */
void g3d_sd_free(g3d_sd *m);
const g3d_sd_unet_config *g3d_sd_get_unet(const g3d_sd *m);
/* Picture sides must be multiples of this (the VAE's factor times the UNet's 2^(levels-1): 64 for SD). */
int g3d_sd_size_multiple(const g3d_sd *m);

/* How many tokens of `text` the text encoder's context cannot hold (0: it fits), in *dropped. */
g3d_status g3d_sd_check_prompt(const g3d_sd *m, const char *text, int *dropped);

typedef struct g3d_sd_params {
    const char *prompt;       /* required */
    const char *negative;     /* the unconditional prompt ("" when NULL) */
    int width, height;        /* pixels */
    g3d_sd_sampler sampler;
    float cfg;                /* classifier-free guidance scale (1: the prompt alone, one pass a step) */
    uint64_t seed;            /* the initial noise (and ancestral noise) */
    const float *noise;       /* the initial latent noise [z_ch, height/f, width/f] instead of the seed's, or NULL */
    const g3d_image *control; /* the ControlNet's hint, (8 width/f) x (8 height/f) (the picture's size for SD),
                                 hint_ch channels; NULL: inpainting builds the inpainting hint itself,
                                 from `prefill` when given (g3d_sd_inpaint_hint) */
    const g3d_image *prefill; /* inpainting with a ControlNet: the picture with its hole already filled
                                 (e.g. by LaMa), the picture's size; the hint takes its colours there */
    float control_scale;      /* the ControlNet's residuals are multiplied by this (1); 0 does not run the
                                 ControlNet, and needs no control image */
    g3d_progress progress;    /* stage "denoise": step, total */
    int truncated;            /* out: prompt tokens dropped because they did not fit (both prompts) */
    int fallback;             /* out, inpainting: 1 when a text-to-image model inpainted by latent blending */
} g3d_sd_params;

/* The ControlNet loaded with the model, or NULL. */
const g3d_sd_controlnet *g3d_sd_get_controlnet(const g3d_sd *m);

/* The inpainting ControlNet's hint (control_v11p_sd15_inpaint), w x h x 3 (allocated): the
 * picture (RGB in [0, 1]) with its masked pixels (mask > 0.5) set to -1, as the official v1.1
 * inpainting demo builds it; or, when prefill (the same size as the picture) is not NULL, the
 * masked pixels taken from it (a picture already filled, e.g. by LaMa). A size other than the
 * picture's is sampled nearest. */
g3d_status g3d_sd_inpaint_hint(const g3d_image *image, const g3d_image *mask, const g3d_image *prefill, int w, int h,
                               g3d_image *hint);

/* DDIM 50 steps, guidance 7.5, 512 x 512, seed 0, control scale 1. */
g3d_sd_params g3d_sd_defaults(void);

/* A picture for the prompt: out (allocated, RGB in [0, 1], width x height) from the VAE's
 * decoding of the sampled latent (clamp((x + 1) / 2, 0, 1)). */
g3d_status g3d_sd_txt2img(const g3d_sd *m, g3d_sd_params *p, g3d_image *out);

/* Fills the masked pixels (mask (h, w, 1) > 0.5) of image (h, w, 3; p->width and p->height are
 * taken from it) with content for the prompt; out is allocated. A published inpainting model
 * (9 input channels) gets the noisy latent, the mask at latent resolution (nearest) and the
 * latent of the masked picture, as ldm's inpainting scripts build them (the masked picture's
 * latent is the posterior mean). A text-to-image model inpaints by latent blending: after
 * every step the unmasked latent is replaced by the picture's latent noised to the next
 * level (p->fallback is set). With a ControlNet loaded, its residuals join every UNet pass (the
 * unconditional one too, as cldm does); p->control NULL gives it g3d_sd_inpaint_hint's hint
 * without prefill. Then the known pixels are pasted back at full resolution with a seam
 * feathered over 8 pixels inside the mask, so pixels outside the mask are unchanged. */
g3d_status g3d_sd_inpaint(const g3d_sd *m, g3d_sd_params *p, const g3d_image *image, const g3d_image *mask,
                          g3d_image *out);

/* The inpainter plug-in (providers.h) on a loaded model (owned by the plug-in afterwards: it
 * frees it): the picture is padded by repeating its edges to the size multiple, inpainted
 * with `params` (prompt NULL means the plug-in call's prompt, else "") and cropped back. */
g3d_status g3d_inpainter_sd_create(g3d_sd *model, const g3d_sd_params *params, g3d_inpainter *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_SD_H */
