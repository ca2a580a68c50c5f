#!/bin/sh
# Fetches the second real held-out pair: Middlebury 2006 "Aloe" (rectified stereo, 1282 x 1110
# JPEG, and the left view's ground-truth disparity as an 8-bit PNG, 0 = unknown), as shipped
# in Debian's opencv-doc package (about 96 MB to download; three files, 730 kB, are kept).
#   scripts/fetch-aloe.sh [DIR]      (default DIR: cache/aloe)
# Prints DIR as an absolute path (a relative DIR is taken from the repository root). Does
# nothing if the files are already there. docs/eval.md says how the pair is scored.
set -eu
exec sh "$(dirname "$0")/fetch-deb-data.sh" opencv-doc opencv-doc/examples/data "${1:-cache/aloe}" \
    aloeL.jpg aloeR.jpg aloeGT.png
