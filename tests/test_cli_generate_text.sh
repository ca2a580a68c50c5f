#!/bin/sh
# gen3d generate with the diffusion models, on the tiny fixtures: text input and RGB input run
# the whole pipeline with every new view inpainted by Stable Diffusion; the settings and
# prompts recorded, timings per stage and per view, the same bytes for the same seed; a
# model of the wrong kind for its flag, or missing tokenizer files: one line, exit 1, no folder.
set -u
T="$G3D_TEST_TMP/cli_generate_text"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"
need_default_input
PARTS="--vae $FIX/sdunet_vae_tiny.safetensors --text-encoder $FIX/clip_sd1_tiny.ckpt --tokenizer $FIX/cliptok_merges.txt.gz"
SD="$FIX/sdpipe_unet_tiny.safetensors"
MOGE="$FIX/moge_tiny.pt"
SMALL="--sd-size 32 --sd-steps 2 --steps 2 --extra 2 --iters 20 --sh-degree 0 --frames 4 -t 2"
PROMPT="a cosy living room with a green sofa"
# shellcheck disable=SC2086
text() { "$GEN3D" generate -p "$PROMPT" --sd-model "$SD" --inpaint-model "$SD" $PARTS --depth-model "$MOGE" $SMALL "$@"; }

expect 0 "help names the diffusion options" "$GEN3D" generate --help
missing=""
for o in --sd-model --inpaint-model --prompt --negative --sd-steps --cfg --sampler --sd-size --tokenizer; do
    grep -q -- "$o" "$T/out" || missing="$missing $o"
done
[ -z "$missing" ] && ok "help lists the diffusion options" || bad "help lacks$missing"

# text input: the whole pipeline
expect 0 "text input" text -o "$T/text"
for f in scene.ply scene.spz preview.png config.json summary.json dataset/views/view_000.png dataset/views/view_002.png; do
    [ -s "$T/text/$f" ] || bad "text input: no $f"
done
[ "$(png_size "$T/text/dataset/views/view_000.png")" = 32x32 ] && ok "the first image at --sd-size" || bad "first image $(png_size "$T/text/dataset/views/view_000.png")"
grep -q "\"prompt\":[[:space:]]*\"$PROMPT\"" "$T/text/config.json" && ok "config.json: the prompt" || bad "config.json: no prompt"
grep -q "\"view_prompt\":[[:space:]]*\"$PROMPT\"" "$T/text/config.json" && ok "the prompt inpaints the views" || bad "views' prompt"
grep -q '"background_prompt":[[:space:]]*"high-resolution scene background with natural colors, photorealistic, 8K"' "$T/text/config.json" \
    && ok "the neutral background template" || bad "background prompt: $(grep background_prompt "$T/text/config.json")"
for k in '"inpainter":[[:space:]]*"stable-diffusion"' '"sampler":[[:space:]]*"dpmpp_2m"' '"steps":[[:space:]]*2,' '"guidance":[[:space:]]*7.5' \
         '"negative_prompt":' '"sd_model":' '"inpaint_model":' '"input":[[:space:]]*"text"'; do
    grep -q "$k" "$T/text/config.json" || bad "config.json lacks $k"
done
grep -q '"seconds_txt2img"' "$T/text/summary.json" && [ "$(grep -c '"inpaint":' "$T/text/summary.json")" = 2 ] \
    && ok "summary: seconds of the first image and of each view" || bad "summary timings"
[ "$(grep -c "latent blending" "$T/err")" = 1 ] && ok "the fallback said once" || bad "fallback messages: $(grep -c "latent blending" "$T/err")"
expect 0 "text input again, same seed" text -o "$T/text2"
cmp -s "$T/text/scene.ply" "$T/text2/scene.ply" && ok "same seed, same scene.ply" || bad "same seed, different scene.ply"
expect 0 "text input, another seed" text -s 7 -o "$T/text3"
cmp -s "$T/text/dataset/views/view_000.png" "$T/text3/dataset/views/view_000.png" && bad "another seed, same first image" || ok "another seed, another image"

# RGB input: the first image is given, MoGe-2 its depth and camera; the views and the
# background (the Middlebury frame has foreground objects) inpainted by the model
# shellcheck disable=SC2086
expect 0 "RGB input" "$GEN3D" generate -i "$MB/motorcycle_left.png" --max-side 64 --depth-model "$MOGE" --inpaint-model "$SD" $PARTS $SMALL \
    -n "people" --sampler euler --cfg 5 -o "$T/rgb"
grep -q '"background_inpainter":[[:space:]]*"stable-diffusion"' "$T/rgb/config.json" && grep -q '"sampler":[[:space:]]*"euler"' "$T/rgb/config.json" \
    && grep -q '"negative_prompt":[[:space:]]*"people"' "$T/rgb/config.json" && grep -q '"guidance":[[:space:]]*5' "$T/rgb/config.json" \
    && ok "RGB input: settings recorded" || bad "RGB input: settings"
grep -q "\"view_prompt\":[[:space:]]*\"a high-resolution photograph" "$T/rgb/config.json" && ok "no prompt: the neutral views' prompt" || bad "views' prompt"
# the Middlebury frame's depth has foreground objects: the background behind them filled by the model
# shellcheck disable=SC2086
expect 0 "RGB-D input, background by the model" "$GEN3D" generate --default-input "$MB" --max-side 64 --inpaint-model "$SD" $PARTS $SMALL \
    --no-video -o "$T/rgbd-bg"
grep -Eq '"foreground_objects":[[:space:]]*[1-9]' "$T/rgbd-bg/summary.json" && grep -Eq '"seconds_background":[[:space:]]*[0-9.]*[1-9]' "$T/rgbd-bg/summary.json" \
    && [ -s "$T/rgbd-bg/dataset/layers/bg_rgb.png" ] && ok "the background layer filled, timed" || bad "background layer: $(grep -E 'foreground|background' "$T/rgbd-bg/summary.json")"

# the background by the inpainting ControlNet on a LaMa-prefilled hint (the fixtures fit the 9-channel UNet)
M9="$FIX/sdinpaint_unet_tiny.safetensors"
CN="$FIX/sdcontrol_tiny.pth"
# shellcheck disable=SC2086
expect 0 "RGB-D input, background by the ControlNet" "$GEN3D" generate --default-input "$MB" --max-side 64 --inpaint-model "$M9" \
    --controlnet "$CN" --inpainter lama --lama-model "$FIX/lama_tiny.ckpt" $PARTS $SMALL --no-video -o "$T/rgbd-cn"
grep -q "background: .*sdcontrol_tiny.pth (ControlNet for SD 1.x.*prefilled by lama" "$T/err" && ok "the ControlNet and its LaMa prefill named" \
    || bad "ControlNet log: $(grep background "$T/err")"
grep -q '"controlnet_model":[[:space:]]*".*sdcontrol_tiny.pth"' "$T/rgbd-cn/config.json" && [ -s "$T/rgbd-cn/dataset/layers/bg_rgb.png" ] \
    && ok "config.json names the ControlNet; the background saved" || bad "ControlNet run: config or background missing"
grep -q "lama-model is not used" "$T/err" && bad "LaMa called unused though it prefills" || ok "LaMa used for the prefill"

# RGB-D input with a prompt and no model to use it: a warning, the run goes on
expect 0 "RGB-D input with an unused prompt" "$GEN3D" generate --default-input "$MB" --max-side 48 -p "a motorcycle" $SMALL --no-video -o "$T/rgbd"
grep -q "prompt is not used" "$T/err" && ok "the unused prompt is named" || bad "no warning for the unused prompt"

# bad input: one line naming the flag and the file, exit 1, no output folder
refuse() {  # $1: name, $2: flag the line must name, $3: file it must name, then the command
    name=$1 flag=$2 file=$3; shift 3
    expect 1 "$name" "$@"
    [ "$(wc -l <"$T/err")" = 1 ] && grep -q -- "$flag" "$T/err" && grep -qF "$file" "$T/err" && ok "$name: one line, flag and file" \
        || bad "$name: $(cat "$T/err")"
    [ ! -e "$T/bad" ] && ok "$name: no output folder" || { bad "$name: output folder written"; rm -rf "$T/bad"; }
}
# shellcheck disable=SC2086
refuse "a diffusion model as --depth-model" --depth-model "$SD" \
    "$GEN3D" generate -i "$MB/motorcycle_left.png" --depth-model "$SD" -q -o "$T/bad"
refuse "a text encoder without UNet as --sd-model" --sd-model clip_sd1_tiny.ckpt \
    "$GEN3D" generate -p x --sd-model "$FIX/clip_sd1_tiny.ckpt" --depth-model "$MOGE" -q -o "$T/bad"
refuse "an inpainting UNet as --sd-model" --sd-model sdunet_sd2_tiny.safetensors \
    "$GEN3D" generate -p x --sd-model "$FIX/sdunet_sd2_tiny.safetensors" --depth-model "$MOGE" -q -o "$T/bad"
refuse "a depth model as --inpaint-model" --inpaint-model "$MOGE" \
    "$GEN3D" generate --default-input "$MB" --inpaint-model "$MOGE" -q -o "$T/bad"
refuse "a LaMa checkpoint as --controlnet" --controlnet lama_tiny.ckpt \
    "$GEN3D" generate --default-input "$MB" --inpaint-model "$M9" --controlnet "$FIX/lama_tiny.ckpt" -q -o "$T/bad"
# shellcheck disable=SC2086
refuse "a ControlNet of another base model" --controlnet sdcontrol_tiny.pth \
    "$GEN3D" generate --default-input "$MB" --inpaint-model "$SD" --controlnet "$CN" $PARTS -q -o "$T/bad"
expect 2 "--controlnet without --inpaint-model" "$GEN3D" generate --default-input "$MB" --controlnet "$CN" -q -o "$T/bad"
[ ! -e "$T/bad" ] && ok "--controlnet alone: no output folder" || { bad "--controlnet alone: output folder written"; rm -rf "$T/bad"; }
refuse "a diffusion model as --lama-model" --lama-model "$SD" \
    "$GEN3D" generate --default-input "$MB" --inpainter lama --lama-model "$SD" -q -o "$T/bad"
mkdir -p "$T/tok"
# shellcheck disable=SC2086
refuse "missing tokenizer files" --tokenizer "$T/tok" \
    "$GEN3D" generate -p x --sd-model "$SD" --vae "$FIX/sdunet_vae_tiny.safetensors" --text-encoder "$FIX/clip_sd1_tiny.ckpt" \
    --tokenizer "$T/tok" --depth-model "$MOGE" -q -o "$T/bad"
expect 2 "--sd-model without a prompt" "$GEN3D" generate --sd-model "$SD" --depth-model "$MOGE" -o "$T/bad"
expect 2 "--sd-model with -i" "$GEN3D" generate -p x --sd-model "$SD" -i "$MB/motorcycle_left.png" --depth-model "$MOGE" -o "$T/bad"
expect 2 "text input without a depth model" "$GEN3D" generate -p x --sd-model "$SD" -o "$T/bad"
expect 2 "an unknown sampler" text --sampler heun -o "$T/bad"
[ ! -e "$T/bad" ] && ok "usage errors: no output folder" || bad "usage errors: output folder written"
finish
