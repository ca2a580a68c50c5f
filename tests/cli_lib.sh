# Helpers shared by the CLI tests (sourced, not run): a scratch folder, pass/fail counting,
# `expect CODE NAME COMMAND...`, which runs COMMAND and checks its exit status, keeping
# its stdout in $T/out and its stderr in $T/err; a small scene file and a PNG size reader.
# Usage: T="$G3D_TEST_TMP/<name>"; . "$G3D_SOURCE_DIR/tests/cli_lib.sh"; ...; finish
#
# Data: committed fixtures in $FIX, the default input (scripts/fetch-default-input.sh) in $MB.
# A script that refers to $EXTENDED is also registered as <name>_extended, run with the
# argument --extended: then EXTENDED=1 and it checks the large references in $G3D_SHARED_DIR;
# without that folder the run stops here as skipped (exit 77, one line saying why).
EXTENDED=0
if [ "${1:-}" = --extended ]; then
    if [ ! -d "$G3D_SHARED_DIR" ]; then
        echo "skipped: no shared reference data at $G3D_SHARED_DIR (configure with -DG3D_SHARED_DIR=DIR)"
        exit 77
    fi
    EXTENDED=1
fi
FIX="$G3D_SOURCE_DIR/tests/fixtures"
MB="$G3D_DEFAULT_INPUT_DIR"
rm -rf "$T"; mkdir -p "$T"
pass=0; fail=0
ok()  { pass=$((pass + 1)); echo "ok   $1"; }
bad() { fail=$((fail + 1)); echo "FAIL $1"; }
expect() {
    code=$1; name=$2; shift 2
    "$@" >"$T/out" 2>"$T/err"; rc=$?
    if [ "$rc" -eq "$code" ]; then ok "$name"; else bad "$name (exit $rc, expected $code)"; sed 's/^/    /' "$T/err"; fi
}
# A failed check, with the remedy, when the default input has not been fetched.
need_default_input() {
    [ -s "$MB/motorcycle_disp.npz" ] || bad "no default input in $MB: run scripts/fetch-default-input.sh"
}
finish() {
    echo "$pass passed, $fail failed"
    [ "$fail" -eq 0 ]
}
# A small 3DGS scene as an ASCII PLY: a 10 x 8 wall of Gaussians 3 m ahead plus a row 2 m
# ahead, colours varying across the grid (SH degree 0).
scene_ply() {  # $1: file, $2: value replacing the first x (to inject a NaN), $3: extra f_rest count
    awk -v bad="$2" -v nrest="$3" 'BEGIN {
        n = 90
        print "ply"; print "format ascii 1.0"; print "element vertex " n
        split("x y z nx ny nz f_dc_0 f_dc_1 f_dc_2", names, " ")
        for (i = 1; i <= 9; i++) print "property float " names[i]
        for (i = 0; i < nrest; i++) print "property float f_rest_" i
        print "property float opacity"
        for (i = 0; i < 3; i++) print "property float scale_" i
        for (i = 0; i < 4; i++) print "property float rot_" i
        print "end_header"
        for (k = 0; k < n; k++) {
            if (k < 80) { x = (k % 10 - 4.5) * 0.35; y = (int(k / 10) - 3.5) * 0.3; z = 3.0 }
            else { x = (k - 84.5) * 0.3; y = 0.4; z = 2.0 }
            line = (k == 0 && bad != "" ? bad : x) " " y " " z " 0 0 0 " (k % 10) / 6 - 0.8 " " int(k / 10) / 5 - 0.8 " 0.5"
            for (i = 0; i < nrest; i++) line = line " 0"
            print line " 4 -1.6 -1.6 -1.6 1 0 0 0"
        }
    }' > "$1"
}
# Width and height of a PNG, from its IHDR chunk.
png_size() { od -An -tu1 -j16 -N8 "$1" | awk '{ printf "%dx%d\n", $3 * 256 + $4, $7 * 256 + $8 }'; }
