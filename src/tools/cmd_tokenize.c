/* gen3d tokenize: CLIP token ids of a prompt, and optionally its text-encoder embeddings. */
#include "cli.h"
#include "gen3d/clip_text.h"
#include "gen3d/npy.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static const char *DESCRIPTION =
    "Prints the CLIP token ids of a prompt as Stable Diffusion frames them: start token, the\n"
    "prompt's BPE tokens, end token, padding to the context length (77). The vocabulary comes from\n"
    "--tokenizer (a folder with vocab.json + merges.txt, a diffusers model folder, or a merges file\n"
    "such as OpenAI's bpe_simple_vocab_16e6.txt.gz), else from the -m model folder's tokenizer/,\n"
    "else from the copy of OpenAI's vocabulary the build installed (docs/text.md).\n"
    "With -m the padding and the special strings follow the model's family (SD 1.x: the end token,\n"
    "SD 2.x: 0); without it the tokenizer's configuration decides (OpenAI's merges file: 0, as\n"
    "clip.tokenize pads). A prompt longer than the context is truncated with a warning.\n"
    "The text clean-up is OpenAI's (ftfy, HTML entities, white space, lower case) for a merges file\n"
    "and Hugging Face's (the same without its two HTML-unescaping passes) for vocab.json + merges.txt;\n"
    "--clean picks one.\n"
    "--encode runs the text encoder of -m (a diffusers folder or a single-file SD 1.x / 2.x\n"
    "checkpoint) and writes the embeddings [1, 77, width] to -o as .npy.";

static int is_dir(const char *p)
{
    struct stat st;
    return p && stat(p, &st) == 0 && S_ISDIR(st.st_mode);
}

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    const char *tokenizer = NULL, *model = NULL, *prompt = NULL, *clean = NULL;
    int encode = 0, pad = -1;
    g3d_cli_common_init(&common);
    common.output = NULL;
    g3d_opt opts[] = {
        {'p', "prompt", G3D_OPT_STRING, &prompt, "TEXT", "the prompt (UTF-8)"},
        {0, "tokenizer", G3D_OPT_STRING, &tokenizer, "DIR|FILE", "CLIP vocabulary (default: the model's, else OpenAI's)"},
        {'m', "model", G3D_OPT_STRING, &model, "MODEL", "Stable Diffusion model (folder or file): its text encoder's family"},
        {0, "pad", G3D_OPT_INT, &pad, "ID", "padding id (-1: as the model or the tokenizer says)"},
        {0, "clean", G3D_OPT_STRING, &clean, "official|hf", "text clean-up (default: the vocabulary's own)"},
        {0, "encode", G3D_OPT_FLAG, &encode, NULL, "write the text encoder's output for the ids to -o (.npy)"},
        G3D_COMMON_OPTS(&common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts),
                                  "gen3d tokenize [--tokenizer DIR|FILE] [-m MODEL [--encode -o OUT.npy]] -p PROMPT",
                                  DESCRIPTION, pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if (!prompt) return g3d_cli_errorf(G3D_EXIT_USAGE, "-p PROMPT is required (see gen3d tokenize --help)");
    if (encode && (!model || !common.output)) return g3d_cli_errorf(G3D_EXIT_USAGE, "--encode needs -m MODEL and -o OUT.npy");
    if (!encode && common.output) return g3d_cli_errorf(G3D_EXIT_USAGE, "-o is for --encode");
    if (pad < -1) return g3d_cli_errorf(G3D_EXIT_USAGE, "--pad must be an id (0 or more) or -1");
    if (clean && strcmp(clean, "official") && strcmp(clean, "hf"))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--clean must be official or hf");
    common.quiet = 1; /* no seed line: nothing here is random (warnings still show) */
    g3d_cli_common_apply(&common);

    g3d_clip_text *enc = NULL;
    g3d_clip_tokenizer *tok = NULL;
    g3d_status rc = G3D_OK;
    if (model) rc = g3d_clip_text_load(model, &enc);
    if (rc == G3D_OK) {
        char *mt = !tokenizer && is_dir(model) ? g3d_path_join(model, "tokenizer") : NULL;
        rc = g3d_clip_tokenizer_load(tokenizer ? tokenizer : is_dir(mt) ? model : NULL, &tok);
        free(mt);
    }
    int context = enc ? g3d_clip_text_get_config(enc)->context : 77;
    int32_t *ids = rc == G3D_OK ? malloc(sizeof(int32_t) * (size_t)context) : NULL;
    g3d_clip_tokens info = {0};
    if (rc == G3D_OK && !ids) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) {
        if (enc && g3d_clip_text_get_config(enc)->family == G3D_CLIP_OPENCLIP) g3d_clip_tokenizer_set_openclip(tok, 1);
        if (clean) g3d_clip_tokenizer_set_clean(tok, strcmp(clean, "hf") ? G3D_CLIP_CLEAN_OFFICIAL : G3D_CLIP_CLEAN_HF_FTFY);
        int32_t p = pad >= 0 ? pad : enc ? g3d_clip_text_pad_id(enc, tok) : g3d_clip_tokenizer_pad(tok) >= 0 ? g3d_clip_tokenizer_pad(tok) : 0;
        rc = g3d_clip_tokenize(tok, prompt, context, p, ids, &info);
    }
    if (rc == G3D_OK && info.dropped)
        g3d_log(G3D_LOG_WARN, "the prompt is %d tokens too long for the context of %d: truncated", info.dropped, context);
    float *emb = NULL;
    if (rc == G3D_OK && encode) {
        int w = g3d_clip_text_width(enc);
        emb = malloc(sizeof(float) * (size_t)context * (size_t)w);
        if (!emb) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        if (rc == G3D_OK) rc = g3d_clip_text_forward(enc, ids, context, emb, NULL);
        int64_t shape[3] = {1, context, w};
        if (rc == G3D_OK) rc = g3d_npy_save(common.output, emb, 3, shape);
    }
    if (rc == G3D_OK) {
        for (int i = 0; i < context; i++) printf("%s%d", i ? " " : "", ids[i]);
        printf("\n");
        if (encode) printf("%s\n", common.output);
    }
    free(emb);
    free(ids);
    g3d_clip_tokenizer_free(tok);
    g3d_clip_text_free(enc);
    return rc == G3D_OK ? G3D_EXIT_OK : g3d_cli_fail(rc);
}

const g3d_command g3d_cmd_tokenize = {"tokenize", "CLIP token ids of a prompt (and text-encoder embeddings)", run};
