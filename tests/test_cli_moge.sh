#!/bin/sh
# gen3d depth with a MoGe-2 checkpoint: recognised automatically, metric depth at the image's
# size, the predicted camera as JSON, refusals that leave nothing behind.
set -u
T="$G3D_TEST_TMP/cli_moge"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"
# M: MoGe-2, D: Depth Anything V2, I: a JPEG of W x H, ARCH: the description info gives of M,
# RANGE: M's model_config.num_tokens_range, CX: the principal point's x in pixels
if [ "$EXTENDED" = 1 ]; then
    M="$G3D_SHARED_DIR/golden/moge2_vits_config/model.pt"
    D="$G3D_SHARED_DIR/golden/depth_anything_v2_vits/weights.safetensors"
    I="$G3D_SHARED_DIR/testdata/demo_inputs/images/ld_Image012_whitecat.jpg"
    W=512 H=512 CX=255.5 ARCH="MoGe-2 (dinov2_vits14, 12 blocks, width 384" RANGE="1200,3600"
else
    M="$FIX/moge_tiny.pt"
    D="$FIX/dav2_tiny.pth"
    I="$FIX/jpeg_420_61x47.jpg"
    W=61 H=47 CX=30 ARCH="MoGe-2 (dinov2_vitt14, 4 blocks, width 128" RANGE="24,96"
fi

expect 0 "info names the architecture" "$GEN3D" info "$M"
grep -q "$ARCH" "$T/out" && ok "info: $ARCH" || bad "info: $ARCH"
grep -q "\"num_tokens_range\":\[$RANGE\]" "$T/out" && ok "info shows model_config" || bad "info shows model_config"

expect 0 "depth with intrinsics" "$GEN3D" depth -q -t 2 -m "$M" -i "$I" -o "$T/a.npy" --num-tokens 300 \
    --intrinsics-out "$T/K.json"
[ "$(head -1 "$T/out")" = "$T/a.npy" ] && ok "prints its outputs" || bad "prints its outputs"
expect 0 "info on depth" "$GEN3D" info "$T/a.npy"
grep -q "($H, $W)" "$T/out" && ok "depth has the image's size" || bad "depth has the image's size"
for k in width height fx fy cx cy fov_x_deg fov_y_deg; do
    grep -q "\"$k\":" "$T/K.json" || bad "intrinsics JSON has $k"
done
grep -q "\"cx\":[[:space:]]*$CX[,.}]" "$T/K.json" && ok "principal point at the centre" || bad "principal point at the centre"
# the golden model's camera: fx = 0.5 w / tan(fov_x / 2) must hold inside the file
awk -F'[:,]' -v w="$W" '/"fx"/{fx=$2} /"fov_x_deg"/{f=$2} END{d=0.5*w/(sin(f*3.14159265358979/360)/cos(f*3.14159265358979/360))-fx;
    exit !(fx > 0 && d < 1e-3 && d > -1e-3)}' "$T/K.json" && ok "fov matches fx" || bad "fov matches fx"
expect 0 "depth again" "$GEN3D" depth -q -t 2 -m "$M" -i "$I" -o "$T/b.npy" --num-tokens 300
cmp -s "$T/a.npy" "$T/b.npy" && ok "deterministic" || bad "deterministic"

expect 2 "intrinsics with Depth Anything" "$GEN3D" depth -q -m "$D" -i "$I" -o "$T/c.npy" --intrinsics-out "$T/c.json"
grep -q "MoGe-2" "$T/err" && ok "refusal says why" || bad "refusal says why"
expect 2 "negative tokens" "$GEN3D" depth -q -m "$M" -i "$I" -o "$T/c.npy" --num-tokens -5
expect 1 "unwritable intrinsics" "$GEN3D" depth -q -t 2 -m "$M" -i "$I" -o "$T/c.npy" --num-tokens 100 \
    --intrinsics-out "$T/nodir/K.json"
expect 1 "missing image" "$GEN3D" depth -q -m "$M" -i "$T/nope.png" -o "$T/c.npy"
[ ! -e "$T/c.npy" ] && [ ! -e "$T/c.json" ] && ok "no output after failures" || bad "no output after failures"

finish
