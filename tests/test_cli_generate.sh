#!/bin/sh
# gen3d generate: one folder with every output, determinism, and refusals that leave nothing.
set -u
T="$G3D_TEST_TMP/cli_generate"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"
need_default_input
G="generate --default-input $MB --max-side 96 --steps 2 --extra 2 --iters 40 --sh-degree 1 --frames 8 -t 2"

expect 0 "generate help" "$GEN3D" generate --help
grep -q -- "--video-trajectory" "$T/out" && grep -q "rotate" "$T/out" && ok "help lists options and trajectories" || bad "help lists options and trajectories"
expect 0 "generate" "$GEN3D" $G -o "$T/a"
for f in scene.ply scene.spz video.mp4 preview.png cameras.json transforms.json config.json summary.json points.ply dataset/points.ply \
         exploration.png exploration_cameras.json; do
    [ -s "$T/a/$f" ] && ok "wrote $f" || bad "wrote $f"
done
grep -q "train" "$T/out" && grep -q "PSNR" "$T/out" && grep -q "total" "$T/out" && ok "summary on stdout" || bad "summary on stdout"
if [ -f "$(dirname "$GEN3D")/gen3d-viewer.html" ]; then  # the viewer was built
    [ -s "$T/a/viewer.html" ] && grep -q '"viewer":[[:space:]]*true' "$T/a/summary.json" && ok "wrote viewer.html" || bad "wrote viewer.html"
fi
grep -Eq '"peak_memory_mb":[[:space:]]*[1-9][0-9]' "$T/a/summary.json" && ok "summary reports the peak memory" || bad "summary reports the peak memory"
grep -q '"seed":' "$T/a/config.json" && grep -q '"iterations":' "$T/a/config.json" && ok "config records the settings" || bad "config records the settings"
grep -q '"dataset/views/view_000.png"' "$T/a/transforms.json" && ok "cameras point into dataset/" || bad "cameras point into dataset/"
# the exploration set: 27 cameras, their empty fractions in the summary, the same figures from render --coverage
n=$(grep -c '"c2w"' "$T/a/exploration_cameras.json")
[ "$n" = 27 ] && ok "27 exploration cameras" || bad "27 exploration cameras (got $n)"
grep -q '"mean_empty_fraction"' "$T/a/summary.json" && grep -q '"empty_fraction"' "$T/a/summary.json" \
    && ok "summary holds the exploration coverage" || bad "summary holds the exploration coverage"
[ "$(png_size "$T/a/exploration.png")" = "874x199" ] && ok "contact sheet: 9 x 3 thumbnails" || bad "contact sheet size $(png_size "$T/a/exploration.png")"
grep -q "explore .* 27 cameras" "$T/out" && ok "coverage on stdout" || bad "coverage on stdout"
expect 0 "render --coverage on the exploration cameras" "$GEN3D" render --scene "$T/a/scene.ply" --trajectory "$T/a/exploration_cameras.json" --coverage -o "$T/cov"
[ "$(grep -c '^camera ' "$T/out")" = 27 ] && grep -q '^mean ' "$T/out" && ok "render --coverage prints every camera" || bad "render --coverage prints every camera"
[ ! -e "$T/cov" ] && ok "render --coverage writes nothing" || bad "render --coverage writes nothing"
mean=$(awk '/"mean_empty_fraction"/ { gsub(/[,:]/, " "); printf "%.4f", 100 * $2 }' "$T/a/summary.json")
grep -q "^mean $mean % empty" "$T/out" && ok "render --coverage agrees with the summary ($mean %)" || bad "render --coverage: $(tail -1 "$T/out"), summary $mean %"
expect 0 "the folder trains as a nerfstudio dataset" "$GEN3D" train --data "$T/a" --iters 5 --sh-degree 0 -q -o "$T/retrained"
expect 0 "info on the scene" "$GEN3D" info "$T/a/scene.ply"
grep -q "3D Gaussian splats" "$T/out" && ok "standard 3DGS PLY" || bad "standard 3DGS PLY"
if command -v ffprobe >/dev/null 2>&1; then
    n=$(ffprobe -v error -select_streams v:0 -count_frames -show_entries stream=nb_read_frames -of csv=p=0 "$T/a/video.mp4")
    [ "$n" = 8 ] && ok "video has --frames frames" || bad "video has --frames frames (got $n)"
fi
G3D_FFMPEG="$T/no-ffmpeg" expect 0 "generate without ffmpeg" "$GEN3D" $G -q -o "$T/noff"
[ -f "$T/noff/frames/00000.png" ] && [ ! -e "$T/noff/video.mp4" ] && ok "PNG frames instead of a video" || bad "PNG frames instead of a video"
expect 0 "generate again" "$GEN3D" $G -q -o "$T/b"
cmp -s "$T/a/scene.ply" "$T/b/scene.ply" && ok "same input, seed and threads: same scene" || bad "same input, seed and threads: same scene"

# A stop request (SIGTERM, like Ctrl-C) once the run has claimed its folder: exit 130, nothing left.
"$GEN3D" $G --iters 100000 -q -o "$T/stopped" >"$T/out" 2>"$T/err" &
pid=$!
i=0
while [ $i -lt 300 ] && ! ls "$T" | grep -q "stopped.tmp-"; do sleep 0.1; i=$((i + 1)); done
kill -TERM $pid
wait $pid
rc=$?
[ "$rc" = 130 ] && grep -q "interrupted" "$T/err" && ok "a stopped run exits 130" || bad "a stopped run exits 130 (exit $rc)"
[ ! -e "$T/stopped" ] && ! ls "$T" | grep -q "stopped.tmp-" && ok "a stopped run leaves nothing" || bad "a stopped run leaves nothing"

expect 2 "zero iterations" "$GEN3D" $G --iters 0 -o "$T/never"
expect 2 "bad SH degree" "$GEN3D" $G --sh-degree 5 -o "$T/never"
expect 2 "negative input beat" "$GEN3D" $G --input-every -1 -o "$T/never"
expect 2 "negative coverage weight" "$GEN3D" $G --coverage-weight -0.5 -o "$T/never"
expect 2 "negative exploration distance" "$GEN3D" $G --explore-distance -1 -o "$T/never"
expect 2 "exploration angle of 90 degrees" "$GEN3D" $G --explore-angle 90 -o "$T/never"
expect 1 "exploration distance beyond the scene" "$GEN3D" $G --explore-distance 50 -o "$T/never"
[ "$(grep -c "error" "$T/err")" = 1 ] && grep "error" "$T/err" | grep -q "median depth" && ok "says why in one line" || bad "says why in one line"
expect 1 "unknown video trajectory" "$GEN3D" $G --video-trajectory elsewhere -o "$T/never"
grep -q "elsewhere" "$T/err" && ok "names the video trajectory" || bad "names the video trajectory"
expect 1 "unknown trajectory" "$GEN3D" $G --trajectory nowhere -o "$T/never"
grep -q "nowhere" "$T/err" && ok "names the trajectory" || bad "names the trajectory"
touch "$T/file"
expect 1 "output under a file" "$GEN3D" $G -o "$T/file/out"
mkdir -p "$T/user"; echo keep > "$T/user/notes.txt"
expect 1 "a folder that is not ours" "$GEN3D" $G -o "$T/user"
[ -f "$T/user/notes.txt" ] && ok "the user's folder is left alone" || bad "the user's folder is left alone"
[ ! -e "$T/never" ] && ok "no output after failures" || bad "no output after failures"
ls "$T" | grep -q "tmp-" && bad "temporary folders left behind" || ok "no temporary folders left behind"
finish
