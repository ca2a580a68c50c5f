#!/bin/sh
# gen3d train on a dataset written by gen3d world: outputs, determinism, refusals.
set -u
T="$G3D_TEST_TMP/cli_train"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"
need_default_input

expect 0 "train help" "$GEN3D" train --help
grep -q -- "--iters N" "$T/out" && ok "help lists --iters" || bad "help lists --iters"
expect 0 "world dataset" "$GEN3D" world --default-input "$MB" --trajectory orbit_left --steps 1 --extra 2 --max-side 96 -q -o "$T/data"
expect 0 "train" "$GEN3D" train --data "$T/data" --iters 60 --sh-degree 1 -q -t 2 -o "$T/a"
for f in scene.ply scene.spz train.json; do
    [ -s "$T/a/$f" ] && ok "wrote $f" || bad "wrote $f"
done
expect 0 "info on the trained scene" "$GEN3D" info "$T/a/scene.ply"
grep -q "3D Gaussian splats" "$T/out" && grep -q "SH degree 1" "$T/out" && ok "standard 3DGS PLY" || bad "standard 3DGS PLY"
expect 0 "train again" "$GEN3D" train --data "$T/data" --iters 60 --sh-degree 1 -q -t 2 -o "$T/b"
cmp -s "$T/a/scene.ply" "$T/b/scene.ply" && ok "same seed and threads, same scene" || bad "same seed and threads, same scene"
[ ! -e "$T/a.checkpoint.safetensors" ] && ok "no checkpoint left after a completed run" || bad "no checkpoint left after a completed run"
expect 0 "train keeping a checkpoint" "$GEN3D" train --data "$T/data" --iters 60 --sh-degree 1 --checkpoint-every 25 --keep-checkpoint -q -t 2 -o "$T/k"
cmp -s "$T/a/scene.ply" "$T/k/scene.ply" && ok "checkpointing changes nothing" || bad "checkpointing changes nothing"
expect 0 "resume" "$GEN3D" train --data "$T/data" --iters 60 --resume "$T/k.checkpoint.safetensors" -q -t 2 -o "$T/r"
cmp -s "$T/a/scene.ply" "$T/r/scene.ply" && ok "resumed run ends where the whole run did" || bad "resumed run ends where the whole run did"
grep -q resumed_from "$T/r/train.json" && ok "train.json records the resume" || bad "train.json records the resume"
expect 1 "resume with another seed" "$GEN3D" train --data "$T/data" --iters 60 --resume "$T/k.checkpoint.safetensors" -s 7 -q -o "$T/never"
grep -q "seed" "$T/err" && ok "names the seed mismatch" || bad "names the seed mismatch"
expect 1 "resume from a scene file" "$GEN3D" train --data "$T/data" --iters 60 --resume "$T/a/scene.ply" -q -o "$T/never"
cp -r "$T/data" "$T/nopoints"; rm "$T/nopoints/points.ply"
expect 0 "no point cloud" "$GEN3D" train --data "$T/nopoints" --iters 5 -t 2 -o "$T/np"
grep -q "random points" "$T/err" && [ -s "$T/np/scene.ply" ] && ok "starts from random points" || bad "starts from random points"
expect 0 "downscaled" "$GEN3D" train --data "$T/data" --iters 10 --downscale 2 -q -o "$T/c"

expect 2 "no data" "$GEN3D" train -o "$T/never"
expect 2 "zero iterations" "$GEN3D" train --data "$T/data" --iters 0 -o "$T/never"
expect 2 "bad SH degree" "$GEN3D" train --data "$T/data" --sh-degree 4 -o "$T/never"
expect 1 "missing folder" "$GEN3D" train --data "$T/nothing" -o "$T/never"
cp -r "$T/data" "$T/bad"
"$GEN3D" scene --width 40 --height 30 -q -o "$T/small" >/dev/null 2>&1
cp "$T/small/rgb_000.png" "$T/bad/views/view_001.png"
expect 1 "image of the wrong size" "$GEN3D" train --data "$T/bad" --iters 5 -o "$T/never"
grep -q "view_001.png" "$T/err" && ok "names the image" || bad "names the image"
cp -r "$T/data" "$T/badmask"
cp "$T/small/rgb_000.png" "$T/badmask/masks/extra_000.png"
expect 1 "mask of the wrong size" "$GEN3D" train --data "$T/badmask" --iters 5 -o "$T/never"
grep -q "extra_000.png" "$T/err" && ok "names the mask" || bad "names the mask"
rm "$T/badmask/masks/extra_001.png"
cp "$T/data/masks/extra_000.png" "$T/badmask/masks/extra_000.png"
expect 1 "missing mask" "$GEN3D" train --data "$T/badmask" --iters 5 -o "$T/never"
grep -q "extra_001.png" "$T/err" && ok "names the missing mask" || bad "names the missing mask"
[ ! -e "$T/never" ] && ok "no output after failures" || bad "no output after failures"
finish
