#!/bin/sh
# gen3d depth: output at the image's size, deterministic, refusals leave nothing behind.
set -u
T="$G3D_TEST_TMP/cli_depth"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"
# W: weights, A: their golden activations (not a checkpoint), I: a JPEG of size SIZE (numpy order)
if [ "$EXTENDED" = 1 ]; then
    W="$G3D_SHARED_DIR/golden/depth_anything_v2_vits/weights.safetensors"
    A="$G3D_SHARED_DIR/golden/depth_anything_v2_vits/activations.safetensors"
    I="$G3D_SHARED_DIR/testdata/demo_inputs/images/ld_Image012_whitecat.jpg"
    SIZE="(512, 512)"
else
    W="$FIX/dav2_tiny.pth"
    A="$FIX/dav2_tiny_golden.safetensors"
    I="$FIX/jpeg_420_61x47.jpg"
    SIZE="(47, 61)"
fi

expect 0 "depth help" "$GEN3D" depth --help
grep -q -- "--input-size" "$T/out" && ok "help shows --input-size" || bad "help shows --input-size"
expect 0 "depth npy" "$GEN3D" depth -q -t 2 -m "$W" -i "$I" -o "$T/a.npy" --input-size 140
[ "$(cat "$T/out")" = "$T/a.npy" ] && ok "prints its output" || bad "prints its output"
expect 0 "info on result" "$GEN3D" info "$T/a.npy"
grep -q "$SIZE" "$T/out" && ok "output has the image's size" || bad "output has the image's size"
expect 0 "depth again" "$GEN3D" depth -q -t 2 -m "$W" -i "$I" -o "$T/b.npy" --input-size 140
cmp -s "$T/a.npy" "$T/b.npy" && ok "deterministic" || bad "deterministic"
expect 0 "depth pfm" "$GEN3D" depth -q -t 2 -m "$W" -i "$I" -o "$T/a.pfm" --input-size 140
[ -s "$T/a.pfm" ] && ok "pfm written" || bad "pfm written"
expect 0 "metric with --max-depth" "$GEN3D" depth -q -t 2 -m "$W" -i "$I" -o "$T/m.npy" --input-size 70 --max-depth 20
expect 0 "info on metric result" "$GEN3D" info "$T/m.npy"
max=$(sed -n 's/.*max \([0-9.]*\).*/\1/p' "$T/out")
awk -v m="$max" 'BEGIN { exit !(m > 0 && m < 20) }' && ok "metric depth below its maximum ($max m)" || bad "metric depth below its maximum ($max)"
K="$T/depth_anything_v2_metric_vkitti_vits.${W##*.}"
cp "$W" "$K"
expect 0 "metric from the file name" "$GEN3D" depth -t 2 -m "$K" -i "$I" -o "$T/k.npy" --input-size 70
grep -q "at most 80 m" "$T/err" && ok "outdoor model: 80 m" || bad "outdoor model: 80 m"
expect 2 "negative max depth" "$GEN3D" depth -m "$W" -i "$I" -o "$T/c.npy" --max-depth -1

expect 2 "missing model" "$GEN3D" depth -i "$I" -o "$T/c.npy"
expect 2 "bad input size" "$GEN3D" depth -m "$W" -i "$I" -o "$T/c.npy" --input-size 3
expect 1 "image as checkpoint" "$GEN3D" depth -q -m "$I" -i "$I" -o "$T/c.npy"
grep -q "${I##*/}" "$T/err" && ok "error names the file" || bad "error names the file"
expect 1 "wrong checkpoint" "$GEN3D" depth -q -m "$A" -i "$I" -o "$T/c.npy"
grep -q "depth_head" "$T/err" && ok "error names the tensor" || bad "error names the tensor"
expect 1 "missing image" "$GEN3D" depth -q -m "$W" -i "$T/nope.png" -o "$T/c.npy"
[ ! -e "$T/c.npy" ] && ok "no output after failures" || bad "no output after failures"

finish
