# Helpers shared by the CLI tests (sourced, not run): a scratch folder, pass/fail counting,
# and `expect CODE NAME COMMAND...`, which runs COMMAND and checks its exit status, keeping
# its stdout in $T/out and its stderr in $T/err.
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
