#!/bin/sh
# RGB input with --depth-model: MoGe-2 and metric Depth Anything V2 give the input's depth and
# the depth of every new view; relative models and non-models are refused clearly.
set -u
T="$G3D_TEST_TMP/cli_depth_model"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"
need_default_input
IMG="$MB/motorcycle_left.png"
if [ "$EXTENDED" = 1 ]; then
    MOGE="$G3D_SHARED_DIR/golden/moge2_vits_config/model.pt"
    DAV2="$G3D_SHARED_DIR/golden/depth_anything_v2_vits/weights.safetensors"
else
    MOGE="$FIX/moge_tiny.pt"
    DAV2="$FIX/dav2_tiny.pth"
fi

expect 0 "world with MoGe-2" "$GEN3D" world -i "$IMG" --depth-model "$MOGE" --depth-tokens 600 --max-side 64 --steps 1 --angle 15 --extra 1 -t 2 -o "$T/moge"
[ -s "$T/moge/points.ply" ] && [ -s "$T/moge/views/view_001.png" ] && ok "dataset written" || bad "dataset written"
grep -q "camera from the depth model" "$T/err" && ok "MoGe-2's camera is used" || bad "MoGe-2's camera is used"
expect 0 "world with metric Depth Anything V2" "$GEN3D" world -i "$IMG" --depth-model "$DAV2" --max-depth 20 --fov 60 \
    --max-side 64 --steps 1 --angle 15 --extra 1 -t 2 -o "$T/dav2"
expect 0 "the same model on RGB-D input aligns new views" "$GEN3D" world --default-input \
    "$MB" --depth-model "$DAV2" --max-side 64 --steps 1 --angle 15 --extra 1 -t 2 -o "$T/rgbd"

expect 2 "RGB alone" "$GEN3D" world -i "$IMG" -o "$T/never"
grep -q -- "--depth-model" "$T/err" && ok "suggests --depth-model" || bad "suggests --depth-model"
expect 1 "relative Depth Anything V2 for RGB alone" "$GEN3D" world -i "$IMG" --depth-model "$DAV2" -o "$T/never"
grep -q "relative" "$T/err" && grep -q "max-depth" "$T/err" && ok "explains metric is needed" || bad "explains metric is needed"
expect 1 "an image as a model" "$GEN3D" world -i "$IMG" --depth-model "$IMG" -o "$T/never"
grep -q "motorcycle_left.png" "$T/err" && ok "names the file" || bad "names the file"
expect 2 "negative token count" "$GEN3D" world -i "$IMG" --depth-model "$MOGE" --depth-tokens -1 -o "$T/never"
expect 2 "negative max depth" "$GEN3D" world -i "$IMG" --depth-model "$DAV2" --max-depth -3 -o "$T/never"
[ ! -e "$T/never" ] && ok "no output after failures" || bad "no output after failures"
finish
