#!/bin/sh
# The main job on the built-in default input (Middlebury 2014 "Motorcycle"): installs the
# dependencies, fetches the input from Debian's archive, builds gen3d, and runs it.
# Output: out/default-frame (the prepared input frame: RGB, metric depth, cameras, point cloud).
set -eu
cd "$(dirname "$0")/.."
sh scripts/install-deps.sh
input=$(sh scripts/fetch-default-input.sh)
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j "$(nproc)"
mkdir -p out
./build/gen3d prepare --default-input "$input" -o out/default-frame
./build/gen3d info out/default-frame/points.ply
