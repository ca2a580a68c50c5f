#!/bin/sh
# The committed fixtures stay small: each file at most 2 MB, all of them at most 25 MB, and
# each model golden has the script that made it beside it.
set -u
T="$G3D_TEST_TMP/fixtures"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"

total=0 big=0
for f in $(find "$FIX" -type f); do
    n=$(wc -c <"$f")
    total=$((total + n))
    [ "$n" -le 2097152 ] || { big=1; bad "${f#"$FIX"/} is $n bytes (over 2 MB)"; }
done
[ "$big" = 0 ] && ok "every fixture at most 2 MB"
[ "$total" -le 26214400 ] && ok "all fixtures together $total bytes (at most 25 MB)" || bad "fixtures total $total bytes (over 25 MB)"
for g in "$FIX"/*_golden.safetensors; do
    model=${g##*/}; model=${model%%_*}
    [ -f "$FIX/make_${model}_golden.py" ] && ok "make_${model}_golden.py made ${g##*/}" || bad "no make_${model}_golden.py for ${g##*/}"
done
finish
