#!/bin/sh
# gen3d render: preset and file trajectories, per-frame intrinsics, depth, video and its
# PNG fallback without ffmpeg, determinism, refusals.
set -u
T="$G3D_TEST_TMP/cli_render"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"

count() { ls "$1" 2>/dev/null | wc -l | tr -d ' '; }

scene_ply "$T/scene.ply" "" 0
expect 0 "render help" "$GEN3D" render --help
grep -q -- "--trajectory NAME|FILE" "$T/out" && grep -q "orbit_left" "$T/out" && ok "help lists trajectories" || bad "help lists trajectories"

# a preset, resampled, with depth and video
expect 0 "preset" "$GEN3D" render --scene "$T/scene.ply" --trajectory orbit_left --frames 7 --width 64 --height 48 --depth -q -o "$T/a"
[ "$(count "$T/a/frames")" = 7 ] && ok "7 frames" || bad "7 frames ($(count "$T/a/frames"))"
[ "$(count "$T/a/depth")" = 7 ] && ok "7 depth frames" || bad "7 depth frames"
[ "$(png_size "$T/a/frames/00006.png")" = 64x48 ] && ok "frame size" || bad "frame size $(png_size "$T/a/frames/00006.png")"
[ -s "$T/a/cameras.json" ] && grep -q '"width":[[:space:]]*64' "$T/a/cameras.json" && ok "cameras.json" || bad "cameras.json"
# depth: 16-bit grey PNG (bit depth 16, colour type 0)
[ "$(od -An -tu1 -j24 -N2 "$T/a/depth/00003.png" | tr -s ' ')" = " 16 0" ] && ok "depth is 16-bit grey" || bad "depth is 16-bit grey"
if command -v ffprobe >/dev/null 2>&1; then
    info=$(ffprobe -v error -count_frames -select_streams v:0 -show_entries stream=nb_read_frames,width,height -of csv=p=0 "$T/a/video.mp4")
    [ "$info" = "64,48,7" ] && ok "video: 64x48, 7 frames" || bad "video: got '$info'"
fi
expect 0 "preset again" "$GEN3D" render --scene "$T/scene.ply" --trajectory orbit_left --frames 7 --width 64 --height 48 --depth -q -o "$T/b"
same=1
for f in "$T"/a/frames/*.png "$T"/a/depth/*.png; do cmp -s "$f" "$T/b/${f#"$T"/a/}" || same=0; done
[ "$same" = 1 ] && ok "deterministic frames" || bad "deterministic frames"
expect 0 "preset, own poses, odd size" "$GEN3D" render --scene "$T/scene.ply" --trajectory rotate --steps 3 --width 33 --height 25 --fov 70 -q -o "$T/r"
[ "$(count "$T/r/frames")" = 4 ] && ok "rotate: input + 3 steps" || bad "rotate: input + 3 steps"
[ "$(png_size "$T/r/frames/00000.png")" = 33x25 ] && ok "odd frame size kept" || bad "odd frame size kept"

# a transforms.json whose two frames differ in size and intrinsics
cat > "$T/path.json" <<'EOF'
{"camera_model": "PINHOLE",
 "frames": [
  {"file_path": "a.png", "fl_x": 40, "fl_y": 40, "cx": 20, "cy": 15, "w": 40, "h": 30,
   "transform_matrix": [[1,0,0,0],[0,-1,0,0],[0,0,-1,0],[0,0,0,1]]},
  {"file_path": "b.png", "fl_x": 60, "fl_y": 55, "cx": 10.5, "cy": 20.5, "w": 24, "h": 36,
   "transform_matrix": [[1,0,0,0.2],[0,-1,0,0],[0,0,-1,0.5],[0,0,0,1]]}]}
EOF
expect 0 "transforms.json path" "$GEN3D" render --scene "$T/scene.ply" --trajectory "$T/path.json" -o "$T/c"
[ "$(png_size "$T/c/frames/00000.png")" = 40x30 ] && [ "$(png_size "$T/c/frames/00001.png")" = 24x36 ] \
    && ok "per-frame image sizes" || bad "per-frame image sizes"
grep -q "differ in image size" "$T/err" && [ ! -e "$T/c/video.mp4" ] && ok "mixed sizes: frames only, says why" || bad "mixed sizes: frames only, says why"
# nerfstudio puts pixel centres at +0.5: cx 10.5 -> 10, fy kept; pose converted to OpenCV axes
tr -d ' \t\n' < "$T/c/cameras.json" | sed 's/-0\([],]\)/0\1/g' > "$T/c.min"
grep -q '"fx":60,"fy":55,"cx":10,"cy":20,"width":24,"height":36' "$T/c.min" && ok "per-frame intrinsics honoured" || bad "per-frame intrinsics honoured"
grep -q '"c2w":\[\[1,0,0,0.2\],\[0,1,0,0\],\[0,0,1,0.5\]' "$T/c.min" && ok "pose converted to OpenCV" || bad "pose converted to OpenCV"
# the cameras.json written is itself a valid trajectory and gives the same frames
expect 0 "cameras.json path" "$GEN3D" render --scene "$T/scene.ply" --trajectory "$T/c/cameras.json" -q -o "$T/c2"
cmp -s "$T/c/frames/00001.png" "$T/c2/frames/00001.png" && ok "cameras.json round trip" || bad "cameras.json round trip"

# no ffmpeg: PNG frames and a clear message
G3D_FFMPEG=/nonexistent/ffmpeg expect 0 "no ffmpeg" "$GEN3D" render --scene "$T/scene.ply" --trajectory push_in --frames 4 --width 32 --height 24 -o "$T/d"
grep -q "ffmpeg is not installed" "$T/err" && ok "says ffmpeg is missing" || bad "says ffmpeg is missing"
[ "$(count "$T/d/frames")" = 4 ] && [ ! -e "$T/d/video.mp4" ] && ok "fallback frames, no video" || bad "fallback frames, no video"
expect 0 "no video" "$GEN3D" render --scene "$T/scene.ply" --trajectory swing --frames 3 --width 32 --height 24 --no-video --background 1,1,1 -o "$T/e"
[ ! -e "$T/e/video.mp4" ] && ! grep -q warning "$T/err" && ok "--no-video: no video, no warning" || bad "--no-video: no video, no warning"
# a white background shows in the corner the wall does not cover (first byte of raw pixel data is
# compressed, so compare against the black-background render instead)
expect 0 "black background" "$GEN3D" render --scene "$T/scene.ply" --trajectory swing --frames 3 --width 32 --height 24 --no-video -q -o "$T/e0"
cmp -s "$T/e/frames/00001.png" "$T/e0/frames/00001.png" && bad "background changes the frames" || ok "background changes the frames"

# WorldScore's benchmark path: 1 + 49 frames per move, 512x512, its camera_data.json
expect 0 "worldscore path" "$GEN3D" render --scene "$T/scene.ply" --trajectory worldscore:orbit_left,push_in --distance 0.5 --no-video -q -o "$T/ws"
[ "$(count "$T/ws/frames")" = 99 ] && ok "worldscore: 99 frames for two moves" || bad "worldscore: 99 frames for two moves ($(count "$T/ws/frames"))"
[ "$(png_size "$T/ws/frames/00098.png")" = 512x512 ] && ok "worldscore: 512x512" || bad "worldscore: 512x512"
tr -d ' \t\n' < "$T/ws/cameras.json" | grep -q '"fx":500,"fy":500,"cx":255.5,"cy":255.5' && ok "worldscore: focal 500" || bad "worldscore: focal 500"
tr -d ' \t\n' < "$T/ws/camera_data.json" | grep -q '"focal_length":500,"scale":0.5' && ok "worldscore: camera_data.json" || bad "worldscore: camera_data.json"
expect 2 "worldscore with --frames" "$GEN3D" render --scene "$T/scene.ply" --trajectory worldscore:push_in --frames 10 -o "$T/never"
expect 1 "unknown worldscore move" "$GEN3D" render --scene "$T/scene.ply" --trajectory worldscore:push_in,spin -o "$T/never"
grep -q "spin" "$T/err" && grep -q "pan_right" "$T/err" && ok "names the move and lists the known ones" || bad "names the move and lists the known ones"

# coverage: the empty-pixel fraction per camera, printed; nothing written
cat > "$T/cover.json" <<'JSON'
{"version": 1, "convention": "opencv_c2w", "frames": [
 {"fx": 20, "fy": 20, "cx": 15.5, "cy": 11.5, "width": 32, "height": 24, "c2w": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]},
 {"fx": 20, "fy": 20, "cx": 15.5, "cy": 11.5, "width": 32, "height": 24, "c2w": [[-1,0,0,0],[0,1,0,0],[0,0,-1,0],[0,0,0,1]]}]}
JSON
expect 0 "coverage of a camera file" "$GEN3D" render --scene "$T/scene.ply" --trajectory "$T/cover.json" --coverage -o "$T/never"
grep -q "^camera 1: 100.0000 % empty" "$T/out" && ok "a camera facing away is all empty" || bad "a camera facing away is all empty"
f0=$(awk '/^camera 0:/ { print $3 }' "$T/out")
awk -v f="$f0" 'BEGIN { exit !(f < 100) }' && grep -q "^mean .* worst 100.0000 %, over 2 cameras" "$T/out" \
    && ok "coverage: the camera facing the wall sees it ($f0 % empty)" || bad "coverage: $(cat "$T/out")"
expect 0 "coverage of the exploration set" "$GEN3D" render --scene "$T/scene.ply" --trajectory explore --width 32 --height 24 --coverage -o "$T/never"
[ "$(grep -c '^camera ' "$T/out")" = 27 ] && ok "exploration set: 27 cameras" || bad "exploration set: 27 cameras"
expect 2 "exploration angle of 90 degrees" "$GEN3D" render --scene "$T/scene.ply" --trajectory explore --explore-angle 90 --coverage -o "$T/never"
expect 1 "exploration distance beyond the scene" "$GEN3D" render --scene "$T/scene.ply" --trajectory explore --distance 40 --coverage -o "$T/never"
grep -q "median depth" "$T/err" && ok "names the distance problem" || bad "names the distance problem"

# refusals
expect 2 "no scene" "$GEN3D" render -o "$T/never"
expect 2 "bad background" "$GEN3D" render --scene "$T/scene.ply" --background 1,2 -o "$T/never"
expect 2 "zero width" "$GEN3D" render --scene "$T/scene.ply" --width 0 -o "$T/never"
expect 2 "--frames with a file" "$GEN3D" render --scene "$T/scene.ply" --trajectory "$T/path.json" --frames 5 -o "$T/never"
expect 1 "missing scene" "$GEN3D" render --scene "$T/nothing.ply" -o "$T/never"
grep -q "nothing.ply" "$T/err" && ok "names the missing scene" || bad "names the missing scene"
scene_ply "$T/nan.ply" nan 0
expect 1 "NaN in the scene" "$GEN3D" render --scene "$T/nan.ply" -o "$T/never"
grep -q "nan.ply" "$T/err" && ok "names the NaN scene" || bad "names the NaN scene"
scene_ply "$T/sh.ply" "" 5
expect 1 "unsupported SH layout" "$GEN3D" render --scene "$T/sh.ply" -o "$T/never"
grep -q "f_rest" "$T/err" && ok "says what is wrong with SH" || bad "says what is wrong with SH"
expect 1 "SH degree above the scene's" "$GEN3D" render --scene "$T/scene.ply" --sh-degree 2 -o "$T/never"
expect 1 "unknown scene format" "$GEN3D" render --scene "$T/path.json" -o "$T/never"
printf '{"frames": [ {"fl_x": 3' > "$T/broken.json"
expect 1 "broken trajectory file" "$GEN3D" render --scene "$T/scene.ply" --trajectory "$T/broken.json" -o "$T/never"
grep -q "broken.json" "$T/err" && ok "names the trajectory file" || bad "names the trajectory file"
expect 1 "missing trajectory file" "$GEN3D" render --scene "$T/scene.ply" --trajectory "$T/none.json" -o "$T/never"
expect 1 "unknown preset" "$GEN3D" render --scene "$T/scene.ply" --trajectory sideways -o "$T/never"
grep -q "orbit_left" "$T/err" && ok "lists the presets" || bad "lists the presets"
: > "$T/afile"
expect 1 "unwritable output" "$GEN3D" render --scene "$T/scene.ply" --frames 2 --width 16 --height 16 -o "$T/afile/out"
mkdir -p "$T/userdir" && : > "$T/userdir/keep.txt"
expect 1 "output over a user folder" "$GEN3D" render --scene "$T/scene.ply" --frames 2 --width 16 --height 16 -o "$T/userdir"
[ -e "$T/userdir/keep.txt" ] && ok "user folder untouched" || bad "user folder untouched"
[ ! -e "$T/never" ] && [ -z "$(ls -d "$T"/never* "$T"/*.tmp-* 2>/dev/null)" ] && ok "no output after failures" || bad "no output after failures"
finish
