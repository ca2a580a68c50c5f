/* gen3d/describe.h - the automatic prompts of the Gen3d paper (section 3.2): the scene
 * category by CLIP zero-shot classification, the dominant colours of the background layer,
 * and the background template filled with them.
 *
 *   g3d_description d;
 *   g3d_describe_scene(clip, tok, &rgb, &layers.fg_mask, NULL, 0, 3, seed, &d);
 *   puts(d.background_prompt);   // "high-resolution kitchen background with white, beige and
 *   g3d_description_free(&d);    //  brown colors, photorealistic, 8K"
 */
#ifndef G3D_DESCRIBE_H
#define G3D_DESCRIBE_H

#include "gen3d/blip.h"
#include "gen3d/clip.h"
#include "gen3d/providers.h"

#ifdef __cplusplus
extern "C" {
#endif

/* CLIP's zero-shot prompt for the scene categories. */
#define G3D_SCENE_PROMPT "a photo of a {}."
/* Most colour clusters g3d_dominant_colors finds, and how many names the template takes. */
#define G3D_MAX_COLORS 8
#define G3D_TEMPLATE_COLORS 3

/* The built-in scene categories (indoor and outdoor; static strings), *n set to their count. */
const char *const *g3d_scene_categories(int *n);
/* Reads categories from a text file, one per line (surrounding white space trimmed, blank
 * lines and lines starting with '#' skipped). *labels is a malloc'd array of malloc'd strings
 * (g3d_scene_categories_free). A file with no category is G3D_ERR_FORMAT. */
g3d_status g3d_scene_categories_load(const char *path, char ***labels, int *n);
void g3d_scene_categories_free(char **labels, int n);

/* sRGB in [0, 1] to CIELAB (D65 white, the sRGB transfer curve undone first), and back
 * (clamped to [0, 1]). */
void g3d_srgb_to_lab(const float rgb[3], float lab[3]);
void g3d_lab_to_srgb(const float lab[3], float rgb[3]);
/* The name of the colour-name table's entry nearest to lab (CIE76 distance); static string. */
const char *g3d_color_name(const float lab[3]);

typedef struct g3d_color {
    float lab[3], rgb[3]; /* the cluster centre */
    float share;          /* fraction of the pixels in the cluster */
    const char *name;     /* g3d_color_name of the centre (static) */
} g3d_color;

/* k-means (k-means++ start from `seed`, then Lloyd's iterations until no pixel changes
 * cluster) in CIELAB over the pixels of an RGB (or grey) image whose `exclude` mask (h, w, 1; may be
 * NULL) is below 0.5, e.g. the background of a foreground mask; at most 65,536 pixels, taken
 * at a regular stride. out[k] (k <= G3D_MAX_COLORS) by decreasing share; *nout may be below
 * k when fewer distinct colours exist. G3D_ERR_ARG when no pixel is left. Deterministic. */
g3d_status g3d_dominant_colors(const g3d_image *rgb, const g3d_image *exclude, int k, uint64_t seed, g3d_color *out,
                               int *nout);

/* The paper's background template, "high-resolution <category> background with <colors>
 * colors, photorealistic, 8K", the colour names joined as "a, b and c". malloc'd. */
char *g3d_background_prompt(const char *category, const char *const *colors, int n);

typedef struct g3d_description {
    int ncat;                        /* top-k categories, most likely first */
    char **category;                 /* [ncat] malloc'd */
    float *prob;                     /* [ncat] softmax probabilities over all categories */
    int ncolors;
    g3d_color colors[G3D_MAX_COLORS];
    char *background_prompt;         /* the template with the top category and colours */
} g3d_description;
void g3d_description_free(g3d_description *d);
/* The description as a JSON object (caller deletes): {"categories": [{"label", "probability"}],
 * "colors": [{"name", "rgb": "#rrggbb", "share"}], "background_prompt"}; NULL if out of memory. */
struct cJSON *g3d_description_json(const g3d_description *d);

/* The scene category of rgb by zero-shot classification over labels[n] (NULL: the built-in
 * list) with G3D_SCENE_PROMPT, its top_k with probabilities, the dominant colours (5
 * clusters) of the pixels outside `exclude` (may be NULL), and the filled template with the
 * first G3D_TEMPLATE_COLORS distinct colour names. clip may be NULL: no category, and the
 * template says "scene". */
g3d_status g3d_describe_scene(const g3d_clip *clip, const g3d_clip_tokenizer *tok, const g3d_image *rgb,
                              const g3d_image *exclude, const char *const *labels, int n, int top_k, uint64_t seed,
                              g3d_description *out);

/* The tokenizer for a CLIP model: `tokenizer` when given, else the model folder's own
 * (vocab.json + merges.txt), else OpenAI's default vocabulary (g3d_clip_default_vocab). */
g3d_status g3d_describe_tokenizer_load(const char *clip_model, const char *tokenizer, g3d_clip_tokenizer **out);

/* The prompt provider of automatic prompts: background = the template filled with the top
 * scene category (CLIP at clip_model; "scene" when NULL) and the dominant colours of the
 * pixels outside the foreground (k-means seeded with seed); view = BLIP's caption of the
 * image (beam search, BLIP's settings) when caption_model is given, else NULL. tokenizer as
 * g3d_describe_tokenizer_load. Free with g3d_prompt_provider_free. */
g3d_status g3d_prompt_provider_describe_create(const char *clip_model, const char *tokenizer, const char *caption_model,
                                               uint64_t seed, g3d_prompt_provider *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_DESCRIBE_H */
