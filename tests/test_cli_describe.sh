#!/bin/sh
# gen3d describe: category, colours and template as text and JSON with the tiny CLIP fixture,
# colours alone, foreground masks, a category file, BLIP captions, and the refusals.
set -u
T="$G3D_TEST_TMP/cli_describe"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"
TOK="$FIX/cliptok_merges.txt.gz"
IMG="$FIX/clip_image.png"

printf 'kitchen\nbeach\n\nforest path\n' > "$T/cats.txt"
expect 0 "category from a file" "$GEN3D" describe -q --clip "$FIX/clip_vit_tiny.pt" --tokenizer "$TOK" --categories "$T/cats.txt" --top 2 -i "$IMG"
# the golden's logits rank forest path, then beach
grep -q "^category: forest path 0\.9[0-9]*, beach 0\.0" "$T/out" && ok "top 2 in the official code's order" || bad "category: $(head -1 "$T/out")"
grep -q "^background prompt: high-resolution forest path background with .* colors, photorealistic, 8K$" "$T/out" &&
    ok "template filled" || bad "template: $(cat "$T/out")"
expect 0 "JSON to a file" "$GEN3D" describe -q --clip "$FIX/clip_vit_tiny_hf.safetensors" --tokenizer "$TOK" --categories "$T/cats.txt" -i "$IMG" --json -o "$T/d.json"
grep -q '"label":[[:space:]]*"forest path"' "$T/d.json" && grep -q '"rgb":[[:space:]]*"#[0-9a-f]\{6\}"' "$T/d.json" &&
    [ "$(head -n -1 "$T/out")" = "$(cat "$T/d.json")" ] && [ "$(tail -n 1 "$T/out")" = "$T/d.json" ] &&
    ok "JSON printed and written" || bad "JSON: $(cat "$T/d.json")"
expect 0 "colours without CLIP" "$GEN3D" describe -q -i "$IMG"
grep -q "^background prompt: high-resolution scene background with" "$T/out" && ! grep -q "^category" "$T/out" &&
    ok "no category without --clip" || bad "$(cat "$T/out")"
# foreground masks: none of the pixels, some, all
expect 0 "no mask" "$GEN3D" describe -q -i "$FIX/lama_image.png"
mv "$T/out" "$T/whole"
expect 0 "empty foreground mask" "$GEN3D" describe -q -i "$FIX/lama_image.png" --fg-mask "$FIX/lama_mask_empty.png"
cmp -s "$T/out" "$T/whole" && ok "an empty mask changes nothing" || bad "$(cat "$T/out")"
expect 0 "foreground mask" "$GEN3D" describe -q -i "$FIX/lama_image.png" --fg-mask "$FIX/lama_mask.png"
! cmp -s "$T/out" "$T/whole" && ok "the masked pixels left out" || bad "the mask changed nothing"
expect 1 "all foreground" "$GEN3D" describe -q -i "$FIX/lama_image.png" --fg-mask "$FIX/lama_mask_full.png"
grep -q "no pixels outside the mask" "$T/err" && ok "said" || bad "$(cat "$T/err")"
expect 1 "mask of another size" "$GEN3D" describe -q -i "$IMG" --fg-mask "$FIX/lama_mask.png"
: > "$T/empty.txt"
expect 1 "empty category file" "$GEN3D" describe -q --clip "$FIX/clip_vit_tiny.pt" --tokenizer "$TOK" --categories "$T/empty.txt" -i "$IMG"
[ "$(wc -l < "$T/err")" = 1 ] && grep -q "empty.txt: no categories" "$T/err" && ok "one line naming the file" || bad "$(cat "$T/err")"
expect 1 "a text encoder as CLIP" "$GEN3D" describe -q --clip "$FIX/clip_sd2_tiny.safetensors" --tokenizer "$TOK" -i "$IMG"
grep -q "clip_sd2_tiny.safetensors: not a CLIP model" "$T/err" && ok "named" || bad "$(cat "$T/err")"
expect 1 "image too small" "$GEN3D" describe -q --clip "$FIX/clip_vit_tiny.pt" --tokenizer "$TOK" -i "$FIX/jpeg_grey_23x17.png" -o "$T/small.json"
[ "$(wc -l < "$T/err")" = 1 ] && grep -q "23x17" "$T/err" && [ ! -e "$T/small.json" ] && ok "one line, no output" || bad "$(cat "$T/err")"
# captions: the golden's beam search and greedy ids, decoded; the wrong model kinds
expect 0 "caption, beam search" "$GEN3D" describe -q -i "$IMG" --caption-model "$FIX/blip_tiny" --json
grep -q '"caption":[[:space:]]*" y"' "$T/out" && ok "caption of the golden's beam ids" || bad "caption: $(cat "$T/out")"
expect 0 "caption, greedy" "$GEN3D" describe -q -i "$IMG" --caption-model "$FIX/blip_tiny_hf" --beams 1
grep -q "^caption:  y trees y white street" "$T/out" && ok "caption of the golden's greedy ids" || bad "caption: $(cat "$T/out")"
expect 1 "CLIP given as the caption model" "$GEN3D" describe -q -i "$IMG" --caption-model "$FIX/clip_vit_tiny.pt"
[ "$(wc -l < "$T/err")" = 1 ] && grep -q "a CLIP model, not a BLIP captioner" "$T/err" && ok "said in one line" || bad "$(cat "$T/err")"
expect 1 "BLIP given as the CLIP model" "$GEN3D" describe -q -i "$IMG" --clip "$FIX/blip_tiny/model.pth" --tokenizer "$TOK"
[ "$(wc -l < "$T/err")" = 1 ] && grep -q "a BLIP checkpoint, not a CLIP model" "$T/err" && ok "said in one line" || bad "$(cat "$T/err")"
expect 2 "bad --beams" "$GEN3D" describe -q -i "$IMG" --beams 0
expect 0 "info on a CLIP model" "$GEN3D" info "$FIX/clip_vit_tiny_hf.safetensors"
grep -q "CLIP model (image tower: 32 px, patch 8, width 64, 2 layers; embedding 32" "$T/out" && ok "named" || bad "$(head -1 "$T/out")"
expect 0 "info on a BLIP captioner" "$GEN3D" info "$FIX/blip_tiny/model.pth"
grep -q "BLIP captioner (Salesforce layout: ViT 32 px" "$T/out" && ok "named" || bad "$(head -1 "$T/out")"

# gen3d generate with automatic prompts: computed once, recorded in config.json. A CLIP folder
# in Hugging Face's layout carries its own vocabulary (vocab.json + merges.txt).
need_default_input
mkdir -p "$T/clip"
cp "$FIX/clip_vit_tiny_hf.safetensors" "$T/clip/model.safetensors"
cp "$FIX/cliptok_vocab.json" "$T/clip/vocab.json"
cp "$FIX/cliptok_merges.txt" "$T/clip/merges.txt"
G="generate --default-input $MB --max-side 96 --steps 2 --extra 1 --iters 10 --sh-degree 0 --no-video -t 2"
expect 0 "generate with --clip and --caption-model" "$GEN3D" $G --clip "$T/clip" --caption-model "$FIX/blip_tiny" -o "$T/gen"
grep -q '"prompt_provider":[[:space:]]*"clip+blip"' "$T/gen/config.json" &&
    grep -q '"background_prompt":[[:space:]]*"high-resolution [a-z ]* background with [a-z ,]* colors, photorealistic, 8K"' "$T/gen/config.json" &&
    grep -q '"view_prompt":' "$T/gen/config.json" && ok "prompts recorded in config.json" || bad "config: $(cat "$T/gen/config.json")"
expect 1 "generate: CLIP as the caption model" "$GEN3D" $G --caption-model "$T/clip" -o "$T/gen_bad"
grep -q "a CLIP model, not a BLIP captioner" "$T/err" && [ ! -e "$T/gen_bad" ] && ok "refused before any output" || bad "$(cat "$T/err")"
expect 2 "--world with --clip" "$GEN3D" generate --world "$T/gen/dataset" --clip "$T/clip" -o "$T/gen_w"
expect 2 "no image" "$GEN3D" describe -q
expect 2 "bad --top" "$GEN3D" describe -q -i "$IMG" --top 0
finish
