#!/bin/sh
# gen3d view: one viewer.html from a .ply or .spz, the options that shape it, and refusals
# (not a 3DGS PLY, an empty scene, bad files and arguments) that say one line and leave no
# file. Without a built viewer template the command must say so instead.
set -u
T="$G3D_TEST_TMP/cli_view"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"

# A 3DGS scene as an ASCII PLY: $2 Gaussians on a grid 3 m ahead, SH degree 1; $3 replaces
# the first x (to inject a NaN).
scene_ply() {
    awk -v n="$2" -v bad="$3" 'BEGIN {
        print "ply"; print "format ascii 1.0"; print "element vertex " n
        split("x y z nx ny nz f_dc_0 f_dc_1 f_dc_2", names, " ")
        for (i = 1; i <= 9; i++) print "property float " names[i]
        for (i = 0; i < 9; i++) print "property float f_rest_" i
        print "property float opacity"
        for (i = 0; i < 3; i++) print "property float scale_" i
        for (i = 0; i < 4; i++) print "property float rot_" i
        print "end_header"
        for (k = 0; k < n; k++) {
            x = (k % 10 - 4.5) * 0.3; y = (int(k / 10) - 2) * 0.3
            line = (k == 0 && bad != "" ? bad : x) " " y " 3 0 0 0 " (k % 7) / 4 - 0.8 " 0.2 -0.3"
            for (i = 0; i < 9; i++) line = line " " (i - 4) / 20
            print line " " (k % 5) - 1 " -2.5 -2.2 -2.8 1 0.1 0 0"
        }
    }' > "$1"
}
# One error line naming $1 (besides the "seed:" line every command prints), no file $2.
refused() {
    [ "$(grep -v '^seed: ' "$T/err" | grep -c .)" = 1 ] && grep -q "^gen3d: error: .*$1" "$T/err" && [ ! -e "$2" ] &&
        ok "  one line naming $1, no file" || { bad "  one line naming $1, no file"; sed 's/^/    /' "$T/err"; }
}

scene_ply "$T/scene.ply" 50 ""
expect 0 "view help" "$GEN3D" view --help
grep -q -- "--cameras" "$T/out" && grep -q -- "--max-gaussians" "$T/out" && ok "help lists the options" || bad "help lists the options"

if [ -f "$(dirname "$GEN3D")/gen3d-viewer.html" ]; then
    expect 0 "view a .ply" "$GEN3D" view "$T/scene.ply" -q -o "$T/v.html"
    [ "$(head -c 15 "$T/v.html")" = "<!doctype html>" ] && ! grep -q "@@G3D_" "$T/v.html" && ok "a filled-in page" || bad "a filled-in page"
    grep -q '"gaussians":50,"sh_degree":1' "$T/v.html" && ok "the page describes the scene" || bad "the page describes the scene"
    grep -q '"name":"video"' "$T/v.html" && ! grep -q '"name":"generation"' "$T/v.html" && ok "a video path, no generation path without --cameras" || bad "paths without --cameras"
    "$GEN3D" render --scene "$T/scene.ply" --trajectory rotate --steps 2 --width 64 --height 48 --no-video -q -o "$T/r" >/dev/null
    expect 0 "view with cameras, reduced" "$GEN3D" view "$T/scene.ply" --cameras "$T/r/cameras.json" --video-trajectory none --max-gaussians 20 --sh-degree 0 -q -o "$T/small.html"
    grep -q '"gaussians":20,"sh_degree":0' "$T/small.html" && grep -q '"name":"generation"' "$T/small.html" && ! grep -q '"name":"video"' "$T/small.html" &&
        ok "reduced scene, generation path only" || bad "reduced scene, generation path only"
    grep -q '"input":{"w":64,"h":48' "$T/small.html" && ok "input camera from the cameras file" || bad "input camera from the cameras file"
    # a one-Gaussian .spz (version 2: gzip of the header and the attribute arrays), 3 m ahead
    printf '\116\107\123\120\002\000\000\000\001\000\000\000\000\014\000\000\000\000\000\000\000\000\000\320\377\310\177\177\177\160\160\160\200\200\200' | gzip -n > "$T/one.spz"
    expect 0 "view a .spz, the video path from a camera file" "$GEN3D" view "$T/one.spz" --video-trajectory "$T/r/cameras.json" -q -o "$T/spz.html"
    grep -q '"gaussians":1,"sh_degree":0' "$T/spz.html" && grep -q '"name":"video","fps":30,"cameras":\[{"w":64' "$T/spz.html" &&
        ok "the .spz and the camera-file video path" || bad "the .spz and the camera-file video path"
    sh -c "cd '$T' && '$GEN3D' view scene.ply -q" >/dev/null && [ -s "$T/viewer.html" ] && ok "default output viewer.html" || bad "default output viewer.html"
    # the same scene through .spz gives the same page
    "$GEN3D" view "$T/scene.ply" -q -o "$T/again.html" >/dev/null
    cmp -s "$T/v.html" "$T/again.html" && ok "deterministic page" || bad "deterministic page"
else
    cp "$GEN3D" "$T/gen3d-alone"
    expect 1 "view without a built viewer" "$T/gen3d-alone" view "$T/scene.ply" -q -o "$T/v.html"
    refused "no viewer template" "$T/v.html"
fi

# refusals: exit 1, one line, nothing written
printf 'ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n0 0 1 255 0 0\n1 0 1 0 255 0\n' > "$T/points.ply"
expect 1 "a point cloud, not 3DGS" "$GEN3D" view "$T/points.ply" -o "$T/no.html"
refused "points.ply.*not a 3D Gaussian splatting PLY" "$T/no.html"
scene_ply "$T/empty.ply" 0 ""
expect 1 "an empty scene" "$GEN3D" view "$T/empty.ply" -o "$T/no.html"
refused "empty.ply.*no Gaussians" "$T/no.html"
scene_ply "$T/nan.ply" 50 nan
expect 1 "NaN in the scene" "$GEN3D" view "$T/nan.ply" -o "$T/no.html"
refused "nan.ply" "$T/no.html"
expect 1 "missing scene" "$GEN3D" view "$T/absent.ply" -o "$T/no.html"
refused "absent.ply" "$T/no.html"
echo "not a splat" > "$T/scene.txt"
expect 1 "unknown scene format" "$GEN3D" view "$T/scene.txt" -o "$T/no.html"
refused "scene.txt" "$T/no.html"
head -c 100 "$T/scene.ply" > "$T/cut.spz"
expect 1 "a damaged .spz" "$GEN3D" view "$T/cut.spz" -o "$T/no.html"
refused "cut.spz" "$T/no.html"
echo '{"frames": [' > "$T/broken.json"
expect 1 "broken cameras file" "$GEN3D" view "$T/scene.ply" --cameras "$T/broken.json" -o "$T/no.html"
refused "broken.json" "$T/no.html"
expect 1 "unknown video path" "$GEN3D" view "$T/scene.ply" --video-trajectory elsewhere -o "$T/no.html"
refused "elsewhere" "$T/no.html"
expect 1 "output in a missing folder" "$GEN3D" view "$T/scene.ply" -o "$T/missing/v.html"
[ ! -e "$T/missing" ] && ok "  nothing created" || bad "  nothing created"

# usage errors: exit 2
expect 2 "no scene" "$GEN3D" view -o "$T/no.html"
expect 2 "two scenes" "$GEN3D" view "$T/scene.ply" "$T/scene.ply" -o "$T/no.html"
expect 2 "bad SH degree" "$GEN3D" view "$T/scene.ply" --sh-degree 7 -o "$T/no.html"
expect 2 "negative --max-gaussians" "$GEN3D" view "$T/scene.ply" --max-gaussians -5 -o "$T/no.html"
expect 2 "-o names a folder" "$GEN3D" view "$T/scene.ply" -o "$T"
[ ! -e "$T/no.html" ] && ok "no output after refusals" || bad "no output after refusals"
ls "$T" | grep -q "tmp-" && bad "temporary files left behind" || ok "no temporary files left behind"
finish
