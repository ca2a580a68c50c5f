#!/bin/sh
# Fetches the default input (Middlebury 2014 "Motorcycle", as shipped in Debian's
# python3-skimage package) without installing Python: the package is downloaded from the
# archive and only its three data files are unpacked.
#   scripts/fetch-default-input.sh [DIR]      (default DIR: cache/default-input)
# Prints DIR as an absolute path (a relative DIR is taken from the repository root). Does nothing if the files are already there.
set -eu
exec sh "$(dirname "$0")/fetch-deb-data.sh" python3-skimage skimage/data "${1:-cache/default-input}" \
    motorcycle_left.png motorcycle_right.png motorcycle_disp.npz
