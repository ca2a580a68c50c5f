#!/bin/sh
# gen3d world from the command line: the dataset it writes and its refusals.
set -u
T="$G3D_TEST_TMP/cli_world"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"
need_default_input

expect 0 "world help" "$GEN3D" world --help
for t in rotate lookdown push_in orbit_left pan_right; do
    grep -q "^  $t " "$T/out" && ok "help describes $t" || bad "help describes $t"
done

# The default input, a short path, small images.
expect 0 "world on the default input" "$GEN3D" world --default-input "$MB" --trajectory orbit_left --steps 2 --extra 3 --max-side 160 -q -o "$T/w"
for f in views/view_000.png views/view_002.png depth/view_001.png depth/view_002.npy extra/extra_002.png masks/extra_000.png \
         layers/fg_mask.png layers/bg_rgb.png cameras.json transforms.json points.ply log.json; do
    [ -s "$T/w/$f" ] && ok "wrote $f" || bad "wrote $f"
done
grep -q '"mask_path"' "$T/w/transforms.json" && ok "extra views carry masks" || bad "extra views carry masks"
expect 0 "info on the cloud" "$GEN3D" info "$T/w/points.ply"
grep -q "point cloud" "$T/out" && ok "cloud readable" || bad "cloud readable"

# Same seed, same bytes; a pose file works like a preset.
expect 0 "world again" "$GEN3D" world --default-input "$MB" --trajectory orbit_left --steps 2 --extra 3 --max-side 160 -q -o "$T/w2"
cmp -s "$T/w/points.ply" "$T/w2/points.ply" && cmp -s "$T/w/views/view_002.png" "$T/w2/views/view_002.png" \
    && ok "deterministic" || bad "deterministic"
expect 0 "trajectory from a file" "$GEN3D" world --default-input "$MB" --trajectory "$T/w/cameras.json" --steps 2 --extra 0 --max-side 160 -q -o "$T/w3"

# RGB-D input: the default input's image and depth as prepare writes them.
expect 0 "prepare an RGB-D pair" "$GEN3D" prepare --default-input "$MB" -q -o "$T/pair"
expect 0 "world on an RGB-D pair" "$GEN3D" world -i "$T/pair/rgb.png" --depth "$T/pair/depth.png" --fx 994.978 --cx 311.193 --cy 254.877 \
    --steps 1 --angle 20 --extra 1 --max-side 128 --no-layers -q -o "$T/w4"

# Refusals: one line, exit 1 or 2, nothing left behind.
expect 1 "unknown trajectory" "$GEN3D" world --default-input "$MB" --trajectory spiral -o "$T/never"
grep -q "unknown trajectory 'spiral'" "$T/err" && ok "names the trajectory" || bad "names the trajectory"
printf '{"frames": [ {"fx": ' >"$T/broken.json"
expect 1 "malformed trajectory file" "$GEN3D" world --default-input "$MB" --trajectory "$T/broken.json" -o "$T/never"
cat >"$T/away.json" <<'JSON'
{"frames": [{"fx": 500, "fy": 500, "cx": 80, "cy": 54, "width": 160, "height": 108, "c2w": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]},
            {"fx": 500, "fy": 500, "cx": 80, "cy": 54, "width": 160, "height": 108, "c2w": [[-1,0,0,0],[0,1,0,0],[0,0,-1,0],[0,0,0,1]]}]}
JSON
expect 1 "trajectory leaving the scene" "$GEN3D" world --default-input "$MB" --trajectory "$T/away.json" --max-side 160 -o "$T/never"
grep -q "sees none of the scene" "$T/err" && ok "says why" || bad "says why"
expect 2 "steps out of range" "$GEN3D" world --steps 5000 -o "$T/never"
expect 2 "extra out of range" "$GEN3D" world --extra -1 -o "$T/never"
expect 2 "depth without image" "$GEN3D" world --depth "$T/pair/depth.png" -o "$T/never"
expect 1 "mismatched depth" "$GEN3D" world -i "$T/w/views/view_000.png" --depth "$T/pair/depth.png" -o "$T/never"
printf 'P5\n' >"$T/nodepth.png"
expect 1 "missing depth file" "$GEN3D" world -i "$T/pair/rgb.png" --depth "$T/none.png" -o "$T/never"
[ ! -e "$T/never" ] && ok "no output folder after failures" || bad "no output folder after failures"
ls "$T" | grep -q "tmp-" && bad "temporary folders left behind" || ok "no temporary folders left behind"

finish
