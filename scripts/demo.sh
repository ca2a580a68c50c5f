#!/bin/sh
# The main job on the built-in default input (Middlebury 2014 "Motorcycle"): installs the
# dependencies, fetches the input from Debian's archive, builds gen3d, and runs world
# generation. Output: out/default-world (views, depth, extra views with masks, layers,
# cameras.json, transforms.json, points.ply, log.json).
set -eu
cd "$(dirname "$0")/.."
sh scripts/install-deps.sh
input=$(sh scripts/fetch-default-input.sh)
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j "$(nproc)"
mkdir -p out
./build/gen3d world --default-input "$input" --trajectory rotate --steps 6 --angle 24 --extra 12 -o out/default-world
./build/gen3d info out/default-world/points.ply
echo "result: out/default-world (open points.ply in a point-cloud viewer; transforms.json + images train 3DGS)"
