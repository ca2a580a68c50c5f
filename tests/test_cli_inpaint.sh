#!/bin/sh
# gen3d inpaint (LaMa and classical) and --inpainter lama in world and generate: outputs,
# determinism, and refusals that name the file and leave nothing behind.
set -u
T="$G3D_TEST_TMP/cli_inpaint"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"
need_default_input
CK="$FIX/lama_tiny.ckpt"
IMG="$FIX/lama_image.png"
MASK="$FIX/lama_mask.png"

expect 0 "inpaint help" "$GEN3D" inpaint --help
grep -q -- "--lama CKPT" "$T/out" && ok "help shows --lama" || bad "help shows --lama"
expect 0 "inpaint with LaMa" "$GEN3D" inpaint -t 2 --lama "$CK" -i "$IMG" --mask "$MASK" -o "$T/a.png"
[ "$(cat "$T/out")" = "$T/a.png" ] && ok "prints its output" || bad "prints its output"
[ "$(png_size "$T/a.png")" = "45x37" ] && ok "output has the image's size" || bad "output has the image's size"
grep -q "lama: .* hole pixels of 45 x 37" "$T/err" && ok "reports the holes" || bad "reports the holes"
expect 0 "again" "$GEN3D" inpaint -q -t 1 --lama "$CK" -i "$IMG" --mask "$MASK" -o "$T/b.png"
cmp -s "$T/a.png" "$T/b.png" && ok "deterministic across thread counts" || bad "deterministic across thread counts"
[ ! -s "$T/err" ] && ok "quiet with -q" || bad "quiet with -q"
expect 0 "classical inpainter" "$GEN3D" inpaint -q -i "$IMG" --mask "$MASK" -o "$T/c.png"
cmp -s "$T/a.png" "$T/c.png" && bad "LaMa and PatchMatch differ" || ok "LaMa and PatchMatch differ"
expect 0 "empty mask" "$GEN3D" inpaint --lama "$CK" -i "$IMG" --mask "$FIX/lama_mask_empty.png" -o "$T/e.png"
grep -q "lama_mask_empty.png: the mask is empty; the image is written unchanged" "$T/err" && ok "says the mask is empty" || bad "says the mask is empty"
expect 0 "empty mask, classical" "$GEN3D" inpaint -q -i "$IMG" --mask "$FIX/lama_mask_empty.png" -o "$T/e2.png"
cmp -s "$T/e.png" "$T/e2.png" && ok "the image comes back unchanged" || bad "the image comes back unchanged"

expect 1 "full mask" "$GEN3D" inpaint --lama "$CK" -i "$IMG" --mask "$FIX/lama_mask_full.png" -o "$T/never.png"
grep -q "lama_mask_full.png: the mask covers the whole image" "$T/err" && ok "names the full mask" || bad "names the full mask"
expect 1 "mask of another size" "$GEN3D" inpaint --lama "$CK" -i "$IMG" --mask "$FIX/jpeg_grey_23x17.png" -o "$T/never.png"
grep -q "jpeg_grey_23x17.png: the mask is 23 x 17, the image .* 45 x 37" "$T/err" && ok "names the mask and both sizes" || bad "names the mask and both sizes"
expect 1 "a checkpoint without LaMa" "$GEN3D" inpaint --lama "$FIX/dav2_tiny.pth" -i "$IMG" --mask "$MASK" -o "$T/never.png"
grep -q "dav2_tiny.pth: no LaMa generator: missing generator.model.1.ffc.convl2l.weight" "$T/err" && ok "names the first missing tensor" || bad "names the first missing tensor"
expect 1 "missing image" "$GEN3D" inpaint -i "$T/nothing.png" --mask "$MASK" -o "$T/never.png"
expect 2 "no mask" "$GEN3D" inpaint -i "$IMG" -o "$T/never.png"
[ ! -e "$T/never.png" ] && ok "no output after failures" || bad "no output after failures"

# the plug-in in the world loop and the background layer, and in generate
expect 0 "world with LaMa" "$GEN3D" world --default-input "$MB" --inpainter lama --lama-model "$CK" --max-side 96 \
    --steps 2 --angle 15 --extra 1 -t 2 -o "$T/world"
grep -q "inpainter: .*lama_tiny.ckpt (LaMa FFC ResNet generator" "$T/err" && ok "world uses LaMa" || bad "world uses LaMa"
[ -s "$T/world/views/view_002.png" ] && [ -s "$T/world/layers/bg_rgb.png" ] && ok "views and background written" || bad "views and background written"
expect 0 "generate with LaMa" "$GEN3D" generate --default-input "$MB" --inpainter lama --lama-model "$CK" --max-side 64 \
    --steps 1 --angle 10 --extra 1 --iters 20 --no-video -t 2 -o "$T/gen"
grep -q '"inpainter":[[:space:]]*"lama"' "$T/gen/config.json" && ok "config.json names the inpainter" || bad "config.json names the inpainter"
expect 2 "--inpainter lama without a model" "$GEN3D" world --default-input "$MB" --inpainter lama -o "$T/never"
expect 2 "unknown inpainter" "$GEN3D" world --default-input "$MB" --inpainter sd -o "$T/never"
expect 1 "world with a non-LaMa checkpoint" "$GEN3D" world --default-input "$MB" --inpainter lama --lama-model "$IMG" -o "$T/never"
grep -q "lama_image.png" "$T/err" && ok "names the file" || bad "names the file"
[ ! -e "$T/never" ] && ok "no world folder after failures" || bad "no world folder after failures"
finish
