#!/bin/sh
# gen3d tokenize: ids as the official tokenizer gives them (the fixture's first prompts),
# SD 1.x / SD 2.x padding from the model, the truncation warning, --encode's .npy, refusals.
set -u
T="$G3D_TEST_TMP/cli_tokenize"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"
TOK="$FIX/cliptok_merges.txt.gz"

# the fixture's vocabulary ends with <|startoftext|>, <|endoftext|>: read them from SD 1.x's padding
expect 0 "SD 1.x model: end-token padding" "$GEN3D" tokenize --tokenizer "$TOK" -m "$FIX/clip_sd1_tiny.ckpt" -p "a photo of a cat"
set -- $(cat "$T/out")
EOT=${77} SOT=$1
[ $# = 77 ] && [ "$SOT" = $((EOT - 1)) ] && [ "$2" != "$EOT" ] && ok "77 ids, start token first, padded with <|endoftext|>" || bad "SD 1.x ids: $*"
expect 0 "ids of a prompt" "$GEN3D" tokenize --tokenizer "$TOK" -p "a photo of a cat"
set -- $(cat "$T/out")
[ $# = 77 ] && [ "$1" = "$SOT" ] && [ "${77}" = 0 ] && ok "OpenAI's merges file alone: padding 0" || bad "ids: $*"
long=$(printf 'word %.0s' $(seq 90))
expect 0 "over-long prompt" "$GEN3D" tokenize --tokenizer "$TOK" -m "$FIX/clip_sd2_tiny.safetensors" -p "$long" --encode -o "$T/emb.npy"
grep -q "too long" "$T/err" && ok "truncation warned" || bad "no truncation warning"
[ -f "$T/emb.npy" ] && "$GEN3D" info "$T/emb.npy" | grep -q "(1, 77, 128)" && ok "embeddings [1, 77, 128]" || bad "no embeddings"
expect 0 "empty prompt" "$GEN3D" tokenize --tokenizer "$TOK" -p ""
set -- $(cat "$T/out")
[ "$1 $2 $3" = "$SOT $EOT 0" ] && ok "empty prompt: start, end, padding" || bad "empty prompt: $1 $2 $3"
expect 1 "not a text encoder" "$GEN3D" tokenize --tokenizer "$TOK" -m "$FIX/dav2_tiny.pth" -p x --encode -o "$T/bad.npy"
[ ! -e "$T/bad.npy" ] && ok "no output after a failure" || bad "output left behind"
expect 2 "no prompt" "$GEN3D" tokenize --tokenizer "$TOK"
expect 2 "--encode without -m" "$GEN3D" tokenize --tokenizer "$TOK" -p x --encode -o "$T/x.npy"
expect 1 "missing tokenizer" "$GEN3D" tokenize --tokenizer "$T/none" -p x
expect 1 "invalid UTF-8" "$GEN3D" tokenize --tokenizer "$TOK" -p "$(printf 'bad \303\050')"
expect 0 "info names the encoder" "$GEN3D" info "$FIX/clip_sd2_tiny.safetensors"
grep -q "SD 2.x, OpenCLIP layout: 3 layers, width 128.*penultimate" "$T/out" && ok "described" || bad "info: $(head -1 "$T/out")"
finish
