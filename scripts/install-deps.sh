#!/bin/sh
# Installs everything gen3d needs to build, test and run, from Debian's archive.
# Idempotent and non-interactive; run as root (or through sudo) on Debian 12.
set -eu

PKGS="build-essential cmake pkg-config libstb-dev libjpeg62-turbo-dev libopenblas-dev libcjson-dev zlib1g-dev libfftw3-dev ffmpeg"

missing=""
for p in $PKGS; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done

if [ -n "$missing" ]; then
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    export DEBIAN_FRONTEND=noninteractive
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq --no-install-recommends $missing
fi
