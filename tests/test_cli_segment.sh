#!/bin/sh
# gen3d segment and --seg-model in world and generate: outputs, determinism, refusals that
# name the file and leave nothing behind.
set -u
T="$G3D_TEST_TMP/cli_segment"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"
need_default_input
CK="$FIX/sam_tiny.pth"
IMG="$FIX/lama_image.png"
LOOSE="--points-per-side 4 --pred-iou-thresh 0.5 --stability-thresh 0.1 --nms-thresh 1"

expect 0 "segment help" "$GEN3D" segment --help
grep -q -- "--points-per-side N" "$T/out" && ok "help shows --points-per-side" || bad "help shows --points-per-side"
expect 0 "segment" "$GEN3D" segment -t 2 -m "$CK" -i "$IMG" $LOOSE -o "$T/a"
[ "$(cat "$T/out")" = "$T/a" ] && ok "prints its output" || bad "prints its output"
n=$(ls "$T/a" | grep -c '^mask_[0-9]*\.png$')
[ "$n" -gt 1 ] && ok "writes masks ($n)" || bad "writes masks ($n)"
[ "$(grep -c '"predicted_iou"' "$T/a/masks.json")" = "$n" ] && ok "masks.json lists every mask" || bad "masks.json lists every mask"
[ "$(png_size "$T/a/mask_000.png")" = "45x37" ] && [ "$(png_size "$T/a/overlay.png")" = "45x37" ] &&
    ok "masks and overlay have the picture's size" || bad "masks and overlay have the picture's size"
expect 0 "again, one thread" "$GEN3D" segment -q -t 1 -m "$CK" -i "$IMG" $LOOSE -o "$T/b"
cmp -s "$T/a/masks.json" "$T/b/masks.json" && cmp -s "$T/a/overlay.png" "$T/b/overlay.png" &&
    ok "deterministic across thread counts" || bad "deterministic across thread counts"
[ ! -s "$T/err" ] && ok "quiet with -q" || bad "quiet with -q"
expect 0 "default thresholds" "$GEN3D" segment -q -m "$CK" -i "$IMG" --points-per-side 2 -o "$T/c"
[ -s "$T/c/masks.json" ] && ok "writes masks.json with the defaults" || bad "writes masks.json with the defaults"

expect 0 "one point" "$GEN3D" segment -q -m "$CK" -i "$IMG" --point 10,12 -o "$T/p"
[ "$(grep -c '"predicted_iou"' "$T/p/masks.json")" = 3 ] && [ -s "$T/p/mask_002.png" ] && ok "three masks for a point" || bad "three masks for a point"
grep -q '"point_coords":[[:space:]]*\[10, 12\]' "$T/p/masks.json" && ok "records the point" || bad "records the point"
expect 0 "a box and a background point" "$GEN3D" segment -q -m "$CK" -i "$IMG" --box 1,2,30,25 --point 40,30,0 -o "$T/q"
cmp -s "$T/p/masks.json" "$T/q/masks.json" && bad "the prompts give other masks" || ok "the prompts give other masks"
expect 2 "bad point" "$GEN3D" segment -m "$CK" -i "$IMG" --point 10 -o "$T/never"
expect 2 "bad label" "$GEN3D" segment -m "$CK" -i "$IMG" --point 10,12,2 -o "$T/never"
expect 2 "bad box" "$GEN3D" segment -m "$CK" -i "$IMG" --box 1,2,3 -o "$T/never"
expect 0 "info names the model" "$GEN3D" info "$CK"
grep -q "Segment Anything (ViT encoder width 32, 4 blocks, input 256; prompt width 32)" "$T/out" &&
    ok "info describes SAM" || bad "info describes SAM"
expect 1 "a checkpoint without SAM" "$GEN3D" segment -m "$FIX/dav2_tiny.pth" -i "$IMG" -o "$T/never"
grep -q "dav2_tiny.pth: not a Segment Anything checkpoint" "$T/err" && ok "names the checkpoint" || bad "names the checkpoint"
expect 1 "a truncated checkpoint" "$GEN3D" segment -m "$FIX/truncated.pth" -i "$IMG" -o "$T/never"
grep -q "truncated.pth" "$T/err" && ok "names the truncated file" || bad "names the truncated file"
expect 1 "missing picture" "$GEN3D" segment -m "$CK" -i "$T/nothing.png" -o "$T/never"
printf 'not a picture' > "$T/empty.png"
expect 1 "not a picture" "$GEN3D" segment -m "$CK" -i "$T/empty.png" -o "$T/never"
expect 2 "no model" "$GEN3D" segment -i "$IMG" -o "$T/never"
expect 2 "bad grid" "$GEN3D" segment -m "$CK" -i "$IMG" --points-per-side 0 -o "$T/never"
[ ! -e "$T/never" ] && ok "no output after failures" || bad "no output after failures"

# the layers stage with SAM's masks
expect 0 "world with SAM" "$GEN3D" world --default-input "$MB" --seg-model "$CK" --max-side 96 --steps 1 --angle 10 \
    -t 2 -o "$T/world"
grep -q "layer masks: Segment Anything" "$T/err" && ok "world uses SAM" || bad "world uses SAM"
[ -s "$T/world/layers/bg_rgb.png" ] && ok "layers written" || bad "layers written"
expect 0 "generate with SAM" "$GEN3D" generate --default-input "$MB" --seg-model "$CK" --max-side 64 --steps 1 \
    --angle 10 --iters 10 --no-video -q -t 2 -o "$T/gen"
grep -q '"mask_provider":[[:space:]]*"sam"' "$T/gen/config.json" && grep -q '"seg_model"' "$T/gen/config.json" &&
    ok "config.json names SAM and its checkpoint" || bad "config.json names SAM and its checkpoint"
expect 1 "world with a non-SAM checkpoint" "$GEN3D" world --default-input "$MB" --seg-model "$IMG" --max-side 96 -o "$T/never"
grep -q "lama_image.png" "$T/err" && ok "names the file" || bad "names the file"
[ ! -e "$T/never" ] && ok "no world folder after failures" || bad "no world folder after failures"
finish
