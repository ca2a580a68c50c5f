#!/bin/sh
# The main job on the built-in default input (Middlebury 2014 "Motorcycle"): installs the
# dependencies, fetches the input from Debian's archive, builds gen3d, and runs the whole
# pipeline - world generation, Gaussian-splat training, rendering. Output: out/default-scene
# (scene.ply, scene.spz, viewer.html, video.mp4, preview.png, cameras.json, transforms.json,
# points.ply, config.json, summary.json, dataset/).
set -eu
cd "$(dirname "$0")/.."
sh scripts/install-deps.sh
input=$(sh scripts/fetch-default-input.sh)
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j "$(nproc)"
mkdir -p out
./build/gen3d generate --default-input "$input" --trajectory rotate --steps 6 --angle 24 --extra 12 \
    --max-side 512 --iters 400 -o out/default-scene
./build/gen3d info out/default-scene/scene.ply
echo "result: out/default-scene (viewer.html opens in a web browser; scene.ply in any 3DGS viewer; video.mp4 is the fly-through)"
