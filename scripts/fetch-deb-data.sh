#!/bin/sh
# Fetches data files that a Debian package ships, without installing it: the package is
# downloaded from the archive (apt-get download) and only the named files are unpacked.
#   scripts/fetch-deb-data.sh PACKAGE PATH_IN_PACKAGE DIR FILE...
# Copies each FILE found under PATH_IN_PACKAGE (a path ending, e.g. skimage/data) into DIR and
# prints DIR as an absolute path (a relative DIR is taken from the repository root). Does
# nothing if the files are already there. A non-zero exit status, DIR untouched, when the package cannot
# be downloaded or lacks a file.
set -eu
cd "$(dirname "$0")/.."
pkg=$1 sub=$2 dir=$3
shift 3
have=1
for f in "$@"; do [ -s "$dir/$f" ] || have=0; done
if [ $have = 0 ]; then
    tmp=$(mktemp -d)
    trap 'rm -rf "$tmp"' EXIT
    (cd "$tmp" && apt-get download "$pkg" >/dev/null 2>&1) || {
        apt-get update -qq >/dev/null 2>&1 || true
        (cd "$tmp" && apt-get download "$pkg" >/dev/null)
    }
    dpkg-deb -x "$tmp/${pkg}"_*.deb "$tmp/x"
    for f in "$@"; do
        src=$(find "$tmp/x" -path "*$sub/$f" | head -n 1)
        [ -n "$src" ] || { echo "fetch-deb-data: $f not found in $pkg" >&2; exit 1; }
    done
    mkdir -p "$dir"
    for f in "$@"; do
        src=$(find "$tmp/x" -path "*$sub/$f" | head -n 1)
        cp "$src" "$dir/$f.part" && mv "$dir/$f.part" "$dir/$f"
    done
fi
(cd "$dir" && pwd)
