# Helpers shared by the CLI tests (sourced, not run): a scratch folder, pass/fail counting,
# and `expect CODE NAME COMMAND...`, which runs COMMAND and checks its exit status, keeping
# its stdout in $T/out and its stderr in $T/err.
# Usage: T="$G3D_TEST_TMP/<name>"; . "$G3D_SOURCE_DIR/tests/cli_lib.sh"; ...; finish
rm -rf "$T"; mkdir -p "$T"
pass=0; fail=0
ok()  { pass=$((pass + 1)); echo "ok   $1"; }
bad() { fail=$((fail + 1)); echo "FAIL $1"; }
expect() {
    code=$1; name=$2; shift 2
    "$@" >"$T/out" 2>"$T/err"; rc=$?
    if [ "$rc" -eq "$code" ]; then ok "$name"; else bad "$name (exit $rc, expected $code)"; sed 's/^/    /' "$T/err"; fi
}
finish() {
    echo "$pass passed, $fail failed"
    [ "$fail" -eq 0 ]
}
