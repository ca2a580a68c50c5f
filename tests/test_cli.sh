#!/bin/sh
# The command-line tool: help, version, exit codes, outputs, and no output left behind on failure.
set -u
T="$G3D_TEST_TMP/cli"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"

if [ "$EXTENDED" = 1 ]; then
    # the ViT-S golden's weights: a safetensors file with the official names
    expect 0 "info checkpoint" "$GEN3D" info "$G3D_SHARED_DIR/golden/depth_anything_v2_vits/weights.safetensors"
    grep -q "239 tensors" "$T/out" && grep -q "Depth Anything V2 (vits" "$T/out" && grep -q "pretrained.blocks.0.attn.qkv.weight.*F16 *\[1152, 384\]" "$T/out" \
        && ok "info lists tensors and the architecture" || bad "info lists tensors and the architecture"
    finish
    exit
fi

expect 0 "help" "$GEN3D" --help
grep -q "scene" "$T/out" && grep -q "info" "$T/out" && ok "help lists commands" || bad "help lists commands"
expect 0 "version" "$GEN3D" --version
grep -q "^gen3d [0-9]" "$T/out" && ok "version text" || bad "version text"
expect 2 "no command" "$GEN3D"
expect 2 "unknown command" "$GEN3D" frobnicate
expect 0 "scene help" "$GEN3D" scene --help
grep -q -- "--width" "$T/out" && grep -q "(default 512)" "$T/out" && ok "scene help shows defaults" || bad "scene help shows defaults"
expect 2 "unknown option" "$GEN3D" scene --bogus
expect 2 "bad number" "$GEN3D" scene --width abc
expect 2 "missing value" "$GEN3D" scene --width

# Rendering: files, result path on stdout, nothing on stdout but the path.
expect 0 "scene arc" "$GEN3D" scene --arc 2 --width 48 --height 32 -q -o "$T/views"
[ "$(cat "$T/out")" = "$T/views" ] && ok "scene prints its output" || bad "scene prints its output"
for f in rgb_000.png depth_001.png depth_001.npy ids_000.png cameras.json transforms.json; do
    [ -s "$T/views/$f" ] && ok "scene wrote $f" || bad "scene wrote $f"
done
[ ! -s "$T/err" ] && ok "quiet is quiet" || bad "quiet is quiet"
expect 0 "scene from cameras" "$GEN3D" scene --cameras "$T/views/transforms.json" -q -o "$T/views2"
cmp -s "$T/views/rgb_001.png" "$T/views2/rgb_001.png" && ok "re-render from transforms.json is identical" || bad "re-render from transforms.json is identical"
expect 0 "scene pose" "$GEN3D" scene --pose 0,0,1,20,-5 --width 40 --height 30 -q -o "$T/pose"

# Failures leave nothing behind.
printf '{"frames": [' >"$T/broken.json"
expect 1 "broken cameras file" "$GEN3D" scene --cameras "$T/broken.json" -o "$T/never"
[ ! -e "$T/never" ] && ok "no output folder after failure" || bad "no output folder after failure"
ls "$T" | grep -q "tmp-" && bad "temporary folder left behind" || ok "no temporary folder left behind"
expect 2 "bad pose" "$GEN3D" scene --pose 1,2 -o "$T/never"
mkdir -p "$T/mine"; echo keep >"$T/mine/file.txt"
expect 1 "refuses to replace a user folder" "$GEN3D" scene --width 8 --height 8 -q -o "$T/mine"
[ -s "$T/mine/file.txt" ] && ok "user folder untouched" || bad "user folder untouched"

# prepare: the default input and an RGB-D pair (the default input's image and depth as prepare wrote them).
need_default_input
expect 0 "prepare default input" "$GEN3D" prepare --default-input "$MB" -q -o "$T/frame"
for f in rgb.png depth.png depth.npy heldout.png cameras.json points.ply; do
    [ -s "$T/frame/$f" ] && ok "prepare wrote $f" || bad "prepare wrote $f"
done
expect 0 "info prepared cloud" "$GEN3D" info "$T/frame/points.ply"
grep -q "343274 points" "$T/out" && ok "cloud has every valid pixel" || bad "cloud has every valid pixel"
expect 0 "prepare rgb-d" "$GEN3D" prepare -i "$T/frame/rgb.png" --depth "$T/frame/depth.png" --fx 994.978 --cx 311.193 --cy 254.877 -q -o "$T/frame2"
expect 1 "prepare mismatched depth" "$GEN3D" prepare -i "$T/views/rgb_000.png" --depth "$T/frame/depth.png" -o "$T/never2"
grep -q "depth is 741x500" "$T/err" && ok "mismatch message" || bad "mismatch message"
[ ! -e "$T/never2" ] && ok "no folder after mismatch" || bad "no folder after mismatch"
expect 1 "prepare missing default input" "$GEN3D" prepare --default-input "$T/nothing-here" -o "$T/never3"
expect 2 "prepare -i without depth" "$GEN3D" prepare -i "$T/frame/rgb.png" -o "$T/never3"

# info
expect 0 "info depth png" "$GEN3D" info "$T/views/depth_000.png"
grep -q "48x32" "$T/out" && ok "info size" || bad "info size"
expect 0 "info npy" "$GEN3D" info "$T/views/depth_000.npy"
grep -q "shape (32, 48)" "$T/out" && ok "info npy shape" || bad "info npy shape"
expect 0 "info cameras" "$GEN3D" info "$T/views/cameras.json"
expect 0 "info npz" "$GEN3D" info "$MB/motorcycle_disp.npz"
grep -q "7.35 %" "$T/out" && ok "info invalid fraction" || bad "info invalid fraction"
expect 1 "info missing file" "$GEN3D" info "$T/nope.png"
grep -q "nope.png" "$T/err" && ok "error names the file" || bad "error names the file"
[ "$(wc -l <"$T/err")" -eq 1 ] && ok "one-line error" || bad "one-line error"
printf 'garbage' >"$T/garbage.ply"
expect 1 "info corrupt ply" "$GEN3D" info "$T/garbage.ply"
expect 1 "info unknown type" "$GEN3D" info "$T/broken.txt"
expect 2 "info without file" "$GEN3D" info
expect 0 "info checkpoint" "$GEN3D" info "$FIX/dav2_tiny.pth"
grep -q "127 tensors" "$T/out" && grep -q "Depth Anything V2 (ViT/14, 4 blocks, width 128" "$T/out" \
    && grep -q "pretrained.blocks.0.attn.qkv.weight.*F16 *\[384, 128\]" "$T/out" \
    && ok "info lists tensors and the architecture" || bad "info lists tensors and the architecture"
expect 0 "info pytorch checkpoint" "$GEN3D" info "$G3D_SOURCE_DIR/tests/fixtures/state.pth"
grep -q "9 tensors" "$T/out" && grep -q "encoder.norm.weight.*BF16" "$T/out" && ok "info lists torch tensors" || bad "info lists torch tensors"
printf 'PK\003\004 not really' >"$T/model.pth"
expect 1 "info pth" "$GEN3D" info "$T/model.pth"

finish
