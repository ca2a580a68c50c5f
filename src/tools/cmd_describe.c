/* gen3d describe: the automatic prompts of an image (scene category, dominant colours, the
 * background template, a caption). */
#include "cli.h"
#include "gen3d/blip.h"
#include "gen3d/describe.h"
#include "gen3d/imageio.h"

#include <cjson/cJSON.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *DESCRIPTION =
    "Prints what gen3d generate writes into its prompts when the input has no text: the scene\n"
    "category by CLIP zero-shot classification (\"a photo of a {}.\" over the built-in indoor and\n"
    "outdoor scene types, or --categories FILE with one per line) with the top K probabilities,\n"
    "the dominant colours (k-means in CIELAB over the pixels outside --fg-mask, named from a\n"
    "colour table), and the paper's background template filled with both. --clip takes a Hugging\n"
    "Face CLIPModel folder (its vocab.json + merges.txt are the tokenizer), an OpenCLIP folder or a\n"
    "single state-dict file (the tokenizer is then OpenAI's vocabulary, or --tokenizer). Without\n"
    "--clip only the colours are computed and the template says \"scene\".\n"
    "--caption-model adds a BLIP caption (a folder with Salesforce's model_base_capfilt_large.pth or\n"
    "Hugging Face's BlipForConditionalGeneration weights, and vocab.txt): beam search with 3 beams\n"
    "after \"a picture of \", as BLIP's own captioning runs; --beams 1 is greedy. docs/describe.md.";

static void print_text(const g3d_description *d, const char *caption)
{
    if (d->ncat) {
        printf("category:");
        for (int i = 0; i < d->ncat; i++) printf("%s %s %.4f", i ? "," : "", d->category[i], d->prob[i]);
        printf("\n");
    }
    printf("colors:");
    for (int i = 0; i < d->ncolors; i++) {
        const g3d_color *c = &d->colors[i];
        printf("%s %s #%02x%02x%02x %.1f%%", i ? "," : "", c->name, (int)(c->rgb[0] * 255 + 0.5f), (int)(c->rgb[1] * 255 + 0.5f),
               (int)(c->rgb[2] * 255 + 0.5f), 100 * c->share);
    }
    printf("\nbackground prompt: %s\n", d->background_prompt);
    if (caption) printf("caption: %s\n", caption);
}

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    const char *input = NULL, *clip_path = NULL, *tokenizer = NULL, *categories = NULL, *fg_mask = NULL, *blip_path = NULL;
    int top = 3, json = 0, beams = 3;
    g3d_cli_common_init(&common);
    common.output = NULL;
    g3d_opt opts[] = {
        {'i', "input", G3D_OPT_PATH, &input, "IMAGE", "input image (.png, .jpg)"},
        {0, "clip", G3D_OPT_PATH, &clip_path, "MODEL", "CLIP model (folder or file) for the scene category"},
        {0, "tokenizer", G3D_OPT_PATH, &tokenizer, "DIR|FILE", "CLIP vocabulary (default: the model folder's, else OpenAI's)"},
        {0, "categories", G3D_OPT_PATH, &categories, "FILE", "scene categories, one per line (default: the built-in list)"},
        {0, "top", G3D_OPT_INT, &top, "K", "categories to print"},
        {0, "caption-model", G3D_OPT_PATH, &blip_path, "MODEL", "BLIP captioning model (folder or file) for a caption"},
        {0, "beams", G3D_OPT_INT, &beams, "N", "beam search width for the caption (1: greedy)"},
        {0, "fg-mask", G3D_OPT_PATH, &fg_mask, "MASK", "foreground mask (non-zero = foreground): colours from the rest"},
        {0, "json", G3D_OPT_FLAG, &json, NULL, "print JSON"},
        G3D_COMMON_OPTS(&common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts),
                                  "gen3d describe [--clip MODEL] [--caption-model MODEL] [--categories FILE] [--top K] -i IMAGE [--json] [-o OUT.json]",
                                  DESCRIPTION, pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if (!input) return g3d_cli_errorf(G3D_EXIT_USAGE, "-i IMAGE is required (see gen3d describe --help)");
    if (top < 1) return g3d_cli_errorf(G3D_EXIT_USAGE, "--top must be at least 1");
    if (beams < 1 || beams > 16) return g3d_cli_errorf(G3D_EXIT_USAGE, "--beams must be 1 to 16");
    g3d_cli_common_apply(&common);

    g3d_image img = {0}, mask = {0};
    char **labels = NULL;
    int nlabels = 0;
    g3d_clip *clip = NULL;
    g3d_clip_tokenizer *tok = NULL;
    g3d_description d = {0};
    g3d_blip *blip = NULL;
    char *caption = NULL;
    g3d_status rc = g3d_image_load(input, 3, &img);
    if (rc == G3D_OK && fg_mask) rc = g3d_image_load(fg_mask, 1, &mask);
    if (rc == G3D_OK && mask.data && (mask.w != img.w || mask.h != img.h))
        rc = G3D_ERR(G3D_ERR_ARG, "%s: the mask is %dx%d, the image %dx%d", fg_mask, mask.w, mask.h, img.w, img.h);
    for (size_t i = 0; rc == G3D_OK && i < (size_t)mask.w * mask.h; i++) mask.data[i] = mask.data[i] > 0 ? 1.0f : 0.0f;
    if (rc == G3D_OK && categories) rc = g3d_scene_categories_load(categories, &labels, &nlabels);
    if (rc == G3D_OK && clip_path) {
        g3d_log(G3D_LOG_INFO, "loading CLIP from %s", clip_path);
        rc = g3d_clip_load(clip_path, &clip);
        if (rc == G3D_OK) rc = g3d_describe_tokenizer_load(clip_path, tokenizer, &tok);
    }
    if (rc == G3D_OK && blip_path) {
        g3d_log(G3D_LOG_INFO, "loading BLIP from %s", blip_path);
        rc = g3d_blip_load(blip_path, &blip);
    }
    char buf[320];
    if (rc == G3D_OK && clip) g3d_log(G3D_LOG_INFO, "%s", g3d_clip_describe(clip, buf, sizeof buf));
    if (rc == G3D_OK && blip) g3d_log(G3D_LOG_INFO, "%s", g3d_blip_describe(blip, buf, sizeof buf));
    if (rc == G3D_OK)
        rc = g3d_describe_scene(clip, tok, &img, mask.data ? &mask : NULL, (const char *const *)labels, nlabels, top,
                                (uint64_t)common.seed, &d);
    if (rc == G3D_OK && blip) {
        g3d_blip_gen g;
        g3d_blip_gen_default(&g);
        g.num_beams = beams;
        rc = g3d_blip_caption(blip, &img, &g, &caption);
    }
    char *js = NULL;
    if (rc == G3D_OK && (json || common.output)) {
        cJSON *j = g3d_description_json(&d);
        if (j && caption) cJSON_AddStringToObject(j, "caption", caption);
        js = j ? cJSON_Print(j) : NULL;
        cJSON_Delete(j);
        if (!js) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    if (rc == G3D_OK && common.output) rc = g3d_write_file_atomic(common.output, js, strlen(js));
    if (rc == G3D_OK) {
        if (json) printf("%s\n", js);
        else print_text(&d, caption);
        if (common.output) printf("%s\n", common.output);
    }
    free(js);
    free(caption);
    g3d_blip_free(blip);
    g3d_description_free(&d);
    g3d_clip_tokenizer_free(tok);
    g3d_clip_free(clip);
    g3d_scene_categories_free(labels, nlabels);
    g3d_image_free(&img);
    g3d_image_free(&mask);
    return rc == G3D_OK ? G3D_EXIT_OK : g3d_cli_fail(rc);
}

const g3d_command g3d_cmd_describe = {"describe", "automatic prompts of an image: scene category, colours, template", run};
