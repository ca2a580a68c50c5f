#!/bin/sh
# gen3d eval: a scene scored against its own renders (PSNR "inf", SSIM 1) and against shifted
# cameras, the input view and the baselines, --input-only, the report and contact sheets, and
# refusals of bad input (missing or wrong-size images, a scene that does not load, NaN depth):
# one line, exit 1, nothing written.
set -u
T="$G3D_TEST_TMP/cli_eval"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"

flat() { tr -d ' \t\n' < "$1"; }
# mean PSNR of a method over all pixels, from eval.json
mean_psnr() { flat "$1" | sed -n "s/.*\"mean\":{.*\"$2\":{\"all\":{\"pixels\":[0-9]*,\"psnr\":\([^,]*\),.*/\1/p"; }

scene_ply "$T/scene.ply" "" 0
# ground truth: the scene's own renders at the input camera (identity) and two other cameras,
# one of another size and focal length
frames() {  # $1: sideways shift of the scored cameras, metres
    cat <<JSON
{"version": 1, "frames": [
 {"name": "frames/00000.png", "depth_path": "depth/00000.png", "fx": 60, "fy": 60, "cx": 31.5, "cy": 23.5, "width": 64, "height": 48,
  "c2w": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]},
 {"name": "frames/00001.png", "depth_path": "depth/00001.png", "fx": 60, "fy": 60, "cx": 31.5, "cy": 23.5, "width": 64, "height": 48,
  "c2w": [[1,0,0,$(awk -v s="$1" 'BEGIN { print 0.1 + s }')],[0,1,0,0],[0,0,1,0],[0,0,0,1]]},
 {"name": "frames/00002.png", "depth_path": "${2:-depth/00002.png}", "fx": 50, "fy": 50, "cx": 20, "cy": 30, "width": 40, "height": 60,
  "c2w": [[1,0,0,$(awk -v s="$1" 'BEGIN { print -0.1 + s }')],[0,1,0,0.05],[0,0,1,0.2],[0,0,0,1]]}]}
JSON
}
frames 0 > "$T/path.json"
expect 0 "ground-truth renders" "$GEN3D" render --scene "$T/scene.ply" --trajectory "$T/path.json" --depth --no-video -q -o "$T/gt"
expect 0 "eval help" "$GEN3D" eval --help
grep -q -- "--input-only" "$T/out" && grep -q "inf" "$T/out" && ok "help describes the report" || bad "help describes the report"

expect 0 "scene against its own renders" "$GEN3D" eval --scene "$T/scene.ply" --views "$T/gt/cameras.json" -q -o "$T/e"
[ "$(head -n 1 "$T/out")" = "$T/e" ] && ok "prints the output folder" || bad "prints the output folder"
# per view and mean, on all pixels: PSNR infinite (written "inf") and SSIM exactly 1
n=$(flat "$T/e/eval.json" | grep -o '"scene":{"all":{"pixels":[0-9]*,"psnr":"inf","ssim":1,' | wc -l)
[ "$n" = 3 ] && ok "perfect scene: PSNR inf, SSIM 1 (2 views + mean)" || bad "perfect scene: PSNR inf, SSIM 1 ($n)"
flat "$T/e/eval.json" | grep -q '"input_view":"frames/00000.png"' && ok "input view: the identity frame" || bad "input view: the identity frame"
flat "$T/e/eval.json" | grep -q '"methods":\["scene","input_image","forward_warp"\]' && ok "baselines in the same report" || bad "baselines in the same report"
[ "$(flat "$T/e/eval.json" | grep -o '"covisible_from":"view_depth"' | wc -l)" = 2 ] && ok "co-visible from depth" || bad "co-visible from depth"
[ "$(png_size "$T/e/sheets/000_00001.png")" = 200x152 ] && [ "$(png_size "$T/e/sheets/001_00002.png")" = 128x188 ] \
    && ok "contact sheets: 3 methods x (truth | prediction | error)" || bad "contact sheets"
flat "$T/e/eval.json" | grep -q '"sheet":"sheets/001_00002.png"' && ok "report names the sheets" || bad "report names the sheets"

# the same images with the scored cameras moved 5 and 20 cm sideways score lower, and lower
frames 0.05 > "$T/gt/shifted.json"
expect 0 "cameras shifted 5 cm" "$GEN3D" eval --scene "$T/scene.ply" --views "$T/gt/shifted.json" -q -o "$T/s"
frames 0.2 > "$T/gt/shifted2.json"
expect 0 "cameras shifted 20 cm" "$GEN3D" eval --scene "$T/scene.ply" --views "$T/gt/shifted2.json" -q -o "$T/s2"
p1=$(mean_psnr "$T/s/eval.json" scene); p2=$(mean_psnr "$T/s2/eval.json" scene)
echo "$p1" | grep -Eq '^[0-9]+\.[0-9]+$' && awk -v a="$p1" -v b="$p2" 'BEGIN { exit !(a > b + 3) }' && ok "shifted: finite PSNR, falling ($p1, $p2 dB)" || bad "shifted: PSNR '$p1' '$p2'"

# baselines only
expect 0 "--input-only" "$GEN3D" eval --input-only --views "$T/gt/cameras.json" -q -o "$T/b"
flat "$T/b/eval.json" | grep -q '"scene":null,.*"methods":\["input_image","forward_warp"\]' && ok "--input-only: the two baselines" || bad "--input-only: the two baselines"

# the procedural room: no identity frame, so no input view unless named
expect 0 "room views" "$GEN3D" scene --arc 3 --width 64 --height 48 -q -o "$T/room"
expect 0 "room without an input view" "$GEN3D" eval --scene "$T/scene.ply" --views "$T/room" -q -o "$T/r1"
flat "$T/r1/eval.json" | grep -q '"methods":\["scene"\]' && [ "$(flat "$T/r1/eval.json" | grep -o '"covisible_from":"scene_alpha"' | wc -l)" = 3 ] \
    && ok "no input view: scene only, co-visible from alpha" || bad "no input view: scene only, co-visible from alpha"
expect 0 "room, input view 1" "$GEN3D" eval --scene "$T/scene.ply" --views "$T/room/transforms.json" --input-view 1 --max-side 32 -q -o "$T/r2"
flat "$T/r2/eval.json" | grep -q '"input_view":"rgb_001.png"' && [ "$(flat "$T/r2/eval.json" | grep -o '"covisible_from":"view_depth"' | wc -l)" = 2 ] \
    && ok "input view by index, room depth" || bad "input view by index, room depth"
flat "$T/r2/eval.json" | grep -q '"width":32,"height":24' && ok "--max-side downscales the views" || bad "--max-side downscales the views"

# refusals: one line, exit 1, nothing written
refuse() {  # $1: name, rest: arguments
    name=$1; shift
    expect 1 "$name" "$GEN3D" eval "$@" -q -o "$T/never"
    [ "$(wc -l < "$T/err" | tr -d ' ')" = 1 ] && ok "$name: one line" || { bad "$name: one line"; cat "$T/err"; }
}
cp -r "$T/gt" "$T/missing" && rm "$T/missing/frames/00001.png"
refuse "missing image" --scene "$T/scene.ply" --views "$T/missing/cameras.json"
grep -q "00001.png" "$T/err" && ok "names the missing image" || bad "names the missing image"
cp -r "$T/gt" "$T/size" && cp "$T/gt/frames/00001.png" "$T/size/frames/00002.png"
refuse "image of another size" --scene "$T/scene.ply" --views "$T/size/cameras.json"
grep -q "00002.png.*64x48.*40x60" "$T/err" && ok "says the sizes" || bad "says the sizes"
refuse "missing scene" --scene "$T/nothing.ply" --views "$T/gt/cameras.json"
scene_ply "$T/nan.ply" nan 0
refuse "scene with NaN" --scene "$T/nan.ply" --views "$T/gt/cameras.json"
grep -q "nan.ply" "$T/err" && ok "names the scene" || bad "names the scene"
# a 40x60 float depth map with one NaN
{ printf 'Pf\n40 60\n-1.0\n'; i=0; while [ $i -lt 2400 ]; do
      if [ $i = 100 ]; then printf '\000\000\300\177'; else printf '\000\000\200\077'; fi; i=$((i + 1)); done; } > "$T/gt/nan.pfm"
frames 0 nan.pfm > "$T/gt/nan.json"
refuse "NaN in ground-truth depth" --scene "$T/scene.ply" --views "$T/gt/nan.json"
grep -q "nan.pfm.*NaN" "$T/err" && ok "names the depth file" || bad "names the depth file"
refuse "--input-only without an input view" --input-only --views "$T/room"
refuse "unknown views folder" --scene "$T/scene.ply" --views "$T"
expect 2 "no --views" "$GEN3D" eval --scene "$T/scene.ply" -o "$T/never"
expect 2 "neither --scene nor --input-only" "$GEN3D" eval --views "$T/gt" -o "$T/never"
expect 2 "--scene with --input-only" "$GEN3D" eval --scene "$T/scene.ply" --input-only --views "$T/gt" -o "$T/never"
expect 2 "bad --input-view" "$GEN3D" eval --scene "$T/scene.ply" --views "$T/gt" --input-view first -o "$T/never"
mkdir -p "$T/userdir" && : > "$T/userdir/keep.txt"
expect 1 "output over a user folder" "$GEN3D" eval --scene "$T/scene.ply" --views "$T/gt/cameras.json" -o "$T/userdir"
[ -e "$T/userdir/keep.txt" ] && [ -z "$(ls "$T/userdir" | grep -v keep.txt)" ] && ok "user folder untouched" || bad "user folder untouched"
[ ! -e "$T/never" ] && [ -z "$(ls -d "$T"/never* "$T"/*.tmp-* 2>/dev/null)" ] && ok "no output after failures" || bad "no output after failures"
finish
