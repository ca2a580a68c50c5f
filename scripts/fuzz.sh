#!/bin/sh
# Builds the libFuzzer targets with clang in build-fuzz/ and runs each for a bounded time,
# seeded with the test fixtures. Not part of the default test run.
#   scripts/fuzz.sh [seconds per target, default 60]
set -eu
cd "$(dirname "$0")/.."
secs=${1:-60}
CC=clang cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=Debug -DG3D_FUZZ=ON -DG3D_CUDA=OFF >/dev/null
cmake --build build-fuzz -j "$(nproc)" --target fuzz_ckpt fuzz_pickle fuzz_zip fuzz_npy fuzz_ply
for t in ckpt pickle zip npy ply; do
    corpus=build-fuzz/corpus-$t
    mkdir -p "$corpus"
    case $t in
        ckpt) cp tests/fixtures/*.safetensors tests/fixtures/*.pth tests/fixtures/*.pt tests/fixtures/*.ckpt "$corpus/" ;;
        pickle) for f in tests/fixtures/state.pth tests/fixtures/ok_handmade.pth tests/fixtures/ckpt_nested.pt tests/fixtures/ckpt_lists.pt tests/fixtures/lama_tiny.ckpt; do unzip -p "$f" '*/data.pkl' >"$corpus/$(basename "$f").pkl"; done ;;
        zip) cp tests/fixtures/*.npz "$corpus/" ;;
        npy) for f in tests/fixtures/*.npz; do unzip -o -q -d "$corpus" "$f"; done ;;
        ply) printf 'ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n' >"$corpus/seed.ply" ;;
    esac
    echo "fuzzing $t for $secs s"
    ./build-fuzz/fuzz_$t -max_total_time="$secs" -max_len=65536 "$corpus"
done
