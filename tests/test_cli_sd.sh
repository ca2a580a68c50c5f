#!/bin/sh
# gen3d info on Stable Diffusion checkpoints (the family and configuration, read from the files);
# gen3d txt2img and gen3d inpaint on the tiny fixture models: reproducible, --noise, the
# refusals of bad input (one line, non-zero exit, no output).
set -u
T="$G3D_TEST_TMP/cli_sd"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"

expect 0 "info names an SD 1.x UNet" "$GEN3D" info "$FIX/sdunet_sd1_tiny.ckpt"
grep -q "SD 1.x UNet (4 input channels, model channels 32, multipliers 1/1/1, res blocks 2/2/2, attention at levels 0/1.*context 48, 8 heads, 1x1-conv" "$T/out" \
    && ok "SD 1.x configuration" || bad "info: $(head -1 "$T/out")"
expect 0 "info names an SD 2.x inpainting UNet" "$GEN3D" info "$FIX/sdunet_sd2_tiny.safetensors"
grep -q "SD 2.x UNet (9 input channels: inpainting.*multipliers 1/1/2.*context 64, heads of 16, Linear projections, v prediction" "$T/out" \
    && ok "SD 2.x configuration" || bad "info: $(head -1 "$T/out")"
expect 0 "info names the VAE" "$GEN3D" info "$FIX/sdunet_vae_tiny.safetensors"
grep -q "Stable Diffusion VAE (channels 32, multipliers 1/2, 1 res blocks, 4 latent channels" "$T/out" \
    && ok "VAE configuration" || bad "info: $(head -1 "$T/out")"

PARTS="--vae $FIX/sdunet_vae_tiny.safetensors --text-encoder $FIX/clip_sd1_tiny.ckpt --tokenizer $FIX/cliptok_merges.txt.gz"
M="$FIX/sdpipe_unet_tiny.safetensors"
PROMPT="a cosy living room with a green velvet sofa, warm light, 4k photo"
# shellcheck disable=SC2086
t2i() { "$GEN3D" txt2img -m "$M" $PARTS -p "$PROMPT" -W 24 -H 16 --steps 4 "$@"; }
rm -f "$T"/*.png
expect 0 "txt2img" t2i -s 3 -o "$T/a.png"
expect 0 "txt2img again, same seed" t2i -s 3 -o "$T/b.png"
cmp -s "$T/a.png" "$T/b.png" && ok "same seed, same bytes" || bad "same seed, different bytes"
# Progress: per step with an ETA on a terminal (a pseudo-terminal from script(1)), nothing in a pipe.
grep -q "denoise" "$T/err" && bad "progress printed into a pipe: $(cat "$T/err")" || ok "no progress in a pipe"
if command -v script >/dev/null 2>&1; then
    script -qec "$GEN3D txt2img -m $M $PARTS -p 'a room' -W 24 -H 16 --steps 4 -s 3 -o $T/tty.png" /dev/null >"$T/tty" 2>&1
    grep -q "denoise *4/4" "$T/tty" && ok "progress per step on a terminal" || bad "terminal progress: $(cat "$T/tty")"
    script -qec "$GEN3D txt2img -q -m $M $PARTS -p 'a room' -W 24 -H 16 --steps 4 -s 3 -o $T/tty.png" /dev/null >"$T/tty" 2>&1
    grep -q "denoise" "$T/tty" && bad "progress with -q: $(cat "$T/tty")" || ok "-q silences the terminal"
fi
expect 0 "another seed" t2i -s 4 --sampler dpmpp_2m --karras -o "$T/c.png"
cmp -s "$T/a.png" "$T/c.png" && bad "another seed, same bytes" || ok "another seed, another picture"
expect 0 "ldm's PLMS" t2i -s 3 --sampler plms -o "$T/p.png"
cmp -s "$T/a.png" "$T/p.png" && bad "plms gave DDIM's picture" || ok "plms: another sampler, another picture"
expect 2 "--karras with plms" t2i --sampler plms --karras -o "$T/bad.png"
expect 0 "--noise instead of the seed" t2i -s 1 --noise "$FIX/sdpipe_noise.npy" -o "$T/n1.png"
expect 0 "--noise, another seed" t2i -s 2 --noise "$FIX/sdpipe_noise.npy" -o "$T/n2.png"
cmp -s "$T/n1.png" "$T/n2.png" && ok "the given noise decides" || bad "--noise ignored"
"$GEN3D" info "$T/a.png" | grep -q "24 x 16\|24x16" && ok "a 24 x 16 picture" || bad "info: $("$GEN3D" info "$T/a.png" | head -1)"

# inpainting with a text-to-image model: latent blending, said on stderr
expect 0 "inpaint (fallback)" "$GEN3D" inpaint -m "$M" $PARTS -i "$T/a.png" --mask "$T/c.png" -p "$PROMPT" --steps 3 -o "$T/i.png"
grep -q "latent blending" "$T/err" && ok "the fallback is named" || bad "no word of the fallback"

# a 9-channel inpainting model from the official run's noise: no fallback
expect 0 "inpaint (9-channel model, --noise)" "$GEN3D" inpaint -m "$FIX/sdinpaint_unet_tiny.safetensors" $PARTS -i "$FIX/sdinpaint_image.png" \
    --mask "$FIX/sdinpaint_mask.png" -p "$PROMPT" --steps 10 --noise "$FIX/sdinpaint_noise.npy" -o "$T/i9.png"
grep -q "latent blending" "$T/err" && bad "a fallback for an inpainting model" || ok "no fallback"

# the inpainting ControlNet (fitting the 9-channel model), its hint as the official demo makes it or prefilled by LaMa
M9="$FIX/sdinpaint_unet_tiny.safetensors"
# shellcheck disable=SC2086
i9() { "$GEN3D" inpaint -m "$M9" $PARTS -i "$FIX/sdinpaint_image.png" --mask "$FIX/sdinpaint_mask.png" -p "$PROMPT" --steps 3 "$@"; }
expect 0 "info names a ControlNet" "$GEN3D" info "$FIX/sdcontrol_tiny.pth"
grep -q "ControlNet for SD 1.x (hint 3 channels at 8x the latent; .*model channels 32, multipliers 1/1.*context 128" "$T/out" \
    && ok "ControlNet configuration" || bad "info: $(head -1 "$T/out")"
expect 0 "inpaint without a ControlNet" i9 -o "$T/ipl.png"
expect 0 "inpaint with a ControlNet" i9 --controlnet "$FIX/sdcontrol_tiny.pth" -o "$T/icn.png"
cmp -s "$T/ipl.png" "$T/icn.png" && bad "the ControlNet changed nothing" || ok "the ControlNet changes the picture"
expect 0 "control scale 0" i9 --controlnet "$FIX/sdcontrol_tiny.pth" --control-scale 0 -o "$T/icn0.png"
cmp -s "$T/ipl.png" "$T/icn0.png" && ok "scale 0: the plain model's picture" || bad "scale 0 differs from no ControlNet"
expect 0 "inpaint with a LaMa-prefilled hint" i9 --controlnet "$FIX/sdcontrol_tiny.pth" --prefill-lama "$FIX/lama_tiny.ckpt" -o "$T/ilama.png"
cmp -s "$T/icn.png" "$T/ilama.png" && bad "the prefill changed nothing" || ok "the prefill changes the picture"

# bad input: one line, non-zero exit, no output
no_out() { [ ! -e "$T/bad.png" ] && ok "$1: no output" || { bad "$1: output written"; rm -f "$T/bad.png"; }; }
expect 1 "not a diffusion checkpoint" "$GEN3D" txt2img -m "$FIX/dav2_tiny.pth" $PARTS -p x -W 24 -H 16 -o "$T/bad.png"
no_out "not a diffusion checkpoint"
head -c 100000 "$M" >"$T/trunc.safetensors"
expect 1 "truncated file" "$GEN3D" txt2img -m "$T/trunc.safetensors" $PARTS -p x -W 24 -H 16 -o "$T/bad.png"
no_out "truncated file"
expect 2 "width not a multiple of 8" t2i -W 20 -o "$T/bad.png"
no_out "width not a multiple of 8"
expect 2 "empty prompt" "$GEN3D" txt2img -m "$M" $PARTS -p "  " -W 24 -H 16 -o "$T/bad.png"
no_out "empty prompt"
long=$(i=0; while [ $i -lt 90 ]; do printf 'chair '; i=$((i + 1)); done)
expect 1 "over-long prompt" "$GEN3D" txt2img -m "$M" $PARTS -p "$long" -W 24 -H 16 -o "$T/bad.png"
no_out "over-long prompt"
"$GEN3D" txt2img -m "$M" $PARTS -p x -W 24 -H 32 -o "$T/mask32.png" -q --steps 1 >/dev/null 2>&1
expect 1 "mask of another size" "$GEN3D" inpaint -m "$M" $PARTS -i "$T/a.png" --mask "$T/mask32.png" -p x -o "$T/bad.png"
no_out "mask of another size"
cp "$M" "$T/nan.safetensors"
printf '\001\176' | dd of="$T/nan.safetensors" bs=1 seek=$(($(wc -c <"$M") - 2)) conv=notrunc 2>/dev/null
expect 1 "NaN weights" "$GEN3D" txt2img -m "$T/nan.safetensors" $PARTS -p x -W 24 -H 16 -o "$T/bad.png"
grep -q "NaN" "$T/err" && ok "the NaN tensor named" || bad "NaN: $(cat "$T/err")"
no_out "NaN weights"
[ "$(grep -c "error" "$T/err")" -eq 1 ] && ok "one error line" || bad "error lines: $(cat "$T/err")"
expect 1 "not a ControlNet" "$GEN3D" inpaint -m "$M" $PARTS --controlnet "$FIX/sdunet_sd1_tiny.ckpt" -i "$T/a.png" --mask "$T/c.png" \
    -p x -o "$T/bad.png"
grep -q "sdunet_sd1_tiny.ckpt: not a ControlNet" "$T/err" && ok "the file named" || bad "not a ControlNet: $(cat "$T/err")"
no_out "not a ControlNet"
expect 1 "a ControlNet of another UNet" "$GEN3D" inpaint -m "$M" $PARTS --controlnet "$FIX/sdcontrol_tiny.pth" -i "$T/a.png" \
    --mask "$T/c.png" -p x -o "$T/bad.png"
grep -q "sdcontrol_tiny.pth: the ControlNet (.*) does not fit the UNet" "$T/err" && ok "the misfit named" || bad "misfit: $(cat "$T/err")"
no_out "a ControlNet of another UNet"
expect 2 "--prefill-lama without --controlnet" "$GEN3D" inpaint -m "$M" $PARTS --prefill-lama "$FIX/lama_tiny.ckpt" -i "$T/a.png" \
    --mask "$T/c.png" -p x -o "$T/bad.png"
no_out "--prefill-lama without --controlnet"
expect 2 "--control-scale without --controlnet" "$GEN3D" inpaint -m "$M" $PARTS --control-scale 0.5 -i "$T/a.png" --mask "$T/c.png" \
    -p x -o "$T/bad.png"
no_out "--control-scale without --controlnet"
finish
