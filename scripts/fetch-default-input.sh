#!/bin/sh
# Fetches the default input (Middlebury 2014 "Motorcycle", as shipped in Debian's
# python3-skimage package) without installing Python: the package is downloaded from the
# archive and only its three data files are unpacked.
#   scripts/fetch-default-input.sh [DIR]      (default DIR: cache/default-input)
# Prints DIR. Does nothing if the files are already there.
set -eu
cd "$(dirname "$0")/.."
dir=${1:-cache/default-input}
files="motorcycle_left.png motorcycle_right.png motorcycle_disp.npz"
have=1
for f in $files; do [ -s "$dir/$f" ] || have=0; done
if [ $have = 0 ]; then
    tmp=$(mktemp -d)
    trap 'rm -rf "$tmp"' EXIT
    (cd "$tmp" && apt-get download python3-skimage >/dev/null 2>&1) || {
        apt-get update -qq >/dev/null 2>&1 || true
        (cd "$tmp" && apt-get download python3-skimage >/dev/null)
    }
    dpkg-deb -x "$tmp"/python3-skimage_*.deb "$tmp/x"
    mkdir -p "$dir"
    for f in $files; do
        src=$(find "$tmp/x" -path "*skimage/data/$f" | head -n 1)
        [ -n "$src" ] || { echo "fetch-default-input: $f not found in python3-skimage" >&2; exit 1; }
        cp "$src" "$dir/$f.part" && mv "$dir/$f.part" "$dir/$f"
    done
fi
echo "$dir"
