#!/bin/sh
# gen3d batch on this machine: manifest errors with line numbers, a failing scene among good
# ones, resuming, --retry-failed, --force, --shard, --status, --jobs 2 against --jobs 1, the
# Slurm script (--dry-run; tests/test_batch_slurm.sh submits to a real Slurm).
set -u
T="$G3D_TEST_TMP/cli_batch"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"
need_default_input
mkdir -p "$T/m/in"
# small scenes: 96 px, 30 iterations
cat >"$T/m/defaults.json" <<EOF
{"default-input": "$MB", "max-side": 96, "steps": 2, "extra": 1, "iters": 30, "sh-degree": 0, "no-video": true}
EOF
printf 'P5\n2 2\n255\nabcd' >"$T/m/in/broken.png"   # exists, is not a PNG: generate fails on it
cat >"$T/m/good.jsonl" <<EOF
{"id": "s0", "seed": 1}
{"id": "s1", "seed": 2, "trajectory": "rotate"}

{"id": "s2", "seed": 3, "input": "in/broken.png", "depth": "in/broken.png"}
{"id": "s3", "seed": 4, "extra": 2}
EOF
B="batch $T/m/good.jsonl --defaults $T/m/defaults.json"

# ---- --check: every bad line reported with its number
cat >"$T/m/bad.jsonl" <<EOF
{"id": "ok", "iters": 10}
{"id": "x1", "iters": 10
{"id": "x2", "colour": "red"}
{"id": "ok"}
{"id": "x3", "depth": "nowhere.png", "input": "in/broken.png"}
{"id": "x4", "iters": 0}
{"id": "x5", "iters": 2.5}
{"iters": 5}
{"id": "../x6"}
{"id": "x7", "trajectory": "nowhere"}
EOF
expect 1 "check finds bad lines" "$GEN3D" batch "$T/m/bad.jsonl" --defaults "$T/m/defaults.json" --check
for want in ":2: scene\|:2: not JSON" ":3: scene 'x2': unknown key 'colour'" ":4: duplicate id 'ok' (first on line 1)" \
    ":5: scene 'x3': depth: nowhere.png" ":6: scene 'x4': --iters must be in" ":7: scene 'x5': iters: expected a whole number" \
    ':8: no "id"' ':9: "id" must be' ":10: scene 'x7': trajectory: nowhere"; do
    grep -q "$want" "$T/err" && ok "check reports '$want'" || bad "check reports '$want'"
done
[ "$(grep -c 'error' "$T/err")" = 9 ] && ok "one line per bad line" || bad "one line per bad line ($(grep -c error "$T/err"))"
grep -q ":1:" "$T/err" && bad "a good line is reported" || ok "good lines are not reported"
expect 0 "check passes a good manifest" "$GEN3D" $B --check
printf '{"iters": 5, "id": "x"}' >"$T/m/d_id.json"
expect 1 "defaults with an id" "$GEN3D" batch "$T/m/good.jsonl" --defaults "$T/m/d_id.json" --check
expect 1 "missing manifest" "$GEN3D" batch "$T/m/none.jsonl" --check
grep -q "none.jsonl" "$T/err" && ok "names the missing manifest" || bad "names the missing manifest"
expect 2 "no output folder" "$GEN3D" $B
expect 2 "bad shard" "$GEN3D" $B -o "$T/never" --shard 2/2
[ ! -e "$T/never" ] && ok "usage errors write nothing" || bad "usage errors write nothing"

# ---- a run: one failing scene, the others finish
expect 1 "run with a failing scene" "$GEN3D" $B -o "$T/a" -t 2
for s in s0 s1 s3; do
    [ -s "$T/a/$s/scene.ply" ] && grep -q '"state":[[:space:]]*"done"' "$T/a/$s/status.json" && ok "$s done" || bad "$s done"
done
grep -q '"splats":' "$T/a/s0/status.json" && grep -q '"iters":[[:space:]]*"30"' "$T/a/s0/status.json" &&
    grep -q '"seed":[[:space:]]*"1"' "$T/a/s0/status.json" && ok "status has stage seconds and options" || bad "status has stage seconds and options"
grep -q '"state":[[:space:]]*"failed"' "$T/a/s2/status.json" && grep -q 'broken.png' "$T/a/s2/status.json" &&
    ok "s2 failed, naming the file" || bad "s2 failed, naming the file"
[ ! -e "$T/a/s2/scene.ply" ] && [ -s "$T/a/s2/log.txt" ] && ok "a failed scene holds its status and log only" || bad "a failed scene holds its status and log only"
grep -q "scene 's2'.*broken.png" "$T/err" && ok "one line names the failed scene" || bad "one line names the failed scene"
grep -q '"done":[[:space:]]*3' "$T/a/summary.json" && grep -q '"failed":[[:space:]]*1' "$T/a/summary.json" &&
    ok "summary.json counts" || bad "summary.json counts"
grep -q "4 scenes: 3 done, 1 failed" "$T/out" && ok "summary on stdout" || bad "summary on stdout"
[ -z "$(ls "$T/a/.batch/work")" ] && ok "nothing half-written left" || bad "nothing half-written left"

# ---- rerun: nothing runs; --retry-failed runs the failed one; --force all
cp "$T/a/s0/status.json" "$T/s0.before"
expect 1 "rerun" "$GEN3D" $B -o "$T/a" -q
grep -q "0 ran (0 done, 0 failed), 4 skipped" "$T/out" && ok "rerun skips finished scenes" || bad "rerun skips finished scenes"
cmp -s "$T/s0.before" "$T/a/s0/status.json" && ok "finished scenes untouched" || bad "finished scenes untouched"
rm -r "$T/a/s3"
expect 1 "rerun after a scene was lost" "$GEN3D" $B -o "$T/a" -q
grep -q "1 ran (1 done, 0 failed), 3 skipped" "$T/out" && [ -s "$T/a/s3/scene.ply" ] && ok "runs only what is missing" || bad "runs only what is missing"
sed 's#, "input": "in/broken.png", "depth": "in/broken.png"##' "$T/m/good.jsonl" >"$T/m/good2.jsonl" &&
    mv "$T/m/good2.jsonl" "$T/m/good.jsonl"
expect 1 "a fixed scene stays failed without --retry-failed" "$GEN3D" $B -o "$T/a" -q
expect 0 "--retry-failed" "$GEN3D" $B -o "$T/a" -q --retry-failed
grep -q "1 ran (1 done, 0 failed)" "$T/out" && grep -q '"state":[[:space:]]*"done"' "$T/a/s2/status.json" &&
    ok "--retry-failed reruns the failed scene only" || bad "--retry-failed reruns the failed scene only"
expect 0 "--force" "$GEN3D" $B -o "$T/a" -q --force --shard 0/2
grep -q "2 ran (2 done, 0 failed)" "$T/out" && ! cmp -s "$T/s0.before" "$T/a/s0/status.json" && ok "--force reruns (shard 0/2: s0, s2)" || bad "--force reruns"

# ---- --status
expect 0 "status" "$GEN3D" batch --status "$T/a"
grep -q "^s1 .*done" "$T/out" && grep -q "4 scenes: 4 done, 0 failed, 0 running, 0 pending" "$T/out" && ok "status lists scenes" || bad "status lists scenes"
expect 1 "status of a folder that is not a batch" "$GEN3D" batch --status "$T/m"

# ---- a folder of another manifest is refused, and a user's folder
cp "$T/m/good.jsonl" "$T/m/copy.jsonl"
expect 1 "another manifest's folder" "$GEN3D" batch "$T/m/copy.jsonl" --defaults "$T/m/defaults.json" -o "$T/a"
grep -q "another manifest" "$T/err" && ok "says it holds another manifest's scenes" || bad "says it holds another manifest's scenes"
mkdir -p "$T/user"; echo keep >"$T/user/notes.txt"
expect 1 "a user's folder" "$GEN3D" $B -o "$T/user"
[ -f "$T/user/notes.txt" ] && [ ! -e "$T/user/batch.json" ] && ok "the user's folder is left alone" || bad "the user's folder is left alone"

# ---- shards: each scene runs in exactly one; the Slurm array variables choose the shard
SLURM_ARRAY_TASK_ID=1 SLURM_ARRAY_TASK_COUNT=2 expect 0 "array task 1 of 2" "$GEN3D" $B -o "$T/sh" -q -t 1
[ -e "$T/sh/s1" ] && [ -e "$T/sh/s3" ] && [ ! -e "$T/sh/s0" ] && [ ! -e "$T/sh/s2" ] && ok "task 1 of 2 ran s1 and s3" || bad "task 1 of 2 ran s1 and s3"
expect 0 "shard 0/2" "$GEN3D" $B -o "$T/sh" -q -t 1 --shard 0/2
expect 0 "status after both shards" "$GEN3D" batch --status "$T/sh"
grep -q "4 done" "$T/out" && ok "two shards cover the manifest" || bad "two shards cover the manifest"

# ---- --jobs 2 gives the same scenes as --jobs 1
expect 0 "jobs 2" "$GEN3D" $B -o "$T/j2" -q -t 2 --jobs 2
same=1
for s in s0 s1 s2 s3; do cmp -s "$T/a/$s/scene.ply" "$T/j2/$s/scene.ply" || same=0; done
[ $same = 1 ] && ok "--jobs 2 writes the same scene.ply bytes as --jobs 1" || bad "--jobs 2 writes the same scene.ply bytes as --jobs 1"
grep -q '"threads":[[:space:]]*1' "$T/j2/s0/status.json" && ok "2 threads split over 2 jobs" || bad "2 threads split over 2 jobs"

# ---- a stopped run: exit 130, no scene half-written, and the next run finishes it
"$GEN3D" batch "$T/m/good.jsonl" --defaults "$T/m/defaults.json" -o "$T/stop" -q -t 1 --jobs 2 >"$T/out" 2>"$T/err" &
pid=$!
i=0
while [ $i -lt 300 ] && [ -z "$(ls "$T/stop/.batch/work" 2>/dev/null)" ]; do sleep 0.05; i=$((i + 1)); done
kill -INT $pid
wait $pid
rc=$?
[ "$rc" = 130 ] && ok "a stopped run exits 130" || bad "a stopped run exits 130 (exit $rc)"
for d in "$T"/stop/s[0-9]; do
    [ -e "$d" ] || continue
    [ -s "$d/status.json" ] || bad "$d has no status"
done
[ -z "$(ls "$T/stop/.batch/work")" ] && ok "a stopped run leaves no work folders" || bad "a stopped run leaves no work folders"
expect 0 "the stopped run goes on" "$GEN3D" $B -o "$T/stop" -q -t 2
grep -q "4 scenes: 4 done" "$T/out" && ok "all done after the rerun" || bad "all done after the rerun"

# ---- the Slurm script, not submitted
expect 0 "slurm dry run" "$GEN3D" $B -o "$T/sl" --slurm --dry-run --array-size 3 --partition gpu --gres gpu:1 \
    --time 2:00:00 --cpus-per-task 8 --sbatch-arg=--account=lab --sbatch-arg --qos=low
S="$T/sl/slurm/batch.sbatch"
grep -qx "$S" "$T/out" && ok "prints the script" || bad "prints the script"
for want in "#SBATCH --array=0-2" "#SBATCH --partition=gpu" "#SBATCH --gres=gpu:1" "#SBATCH --time=2:00:00" \
    "#SBATCH --cpus-per-task=8" "#SBATCH --account=lab" "#SBATCH --qos=low" '--shard "$SLURM_ARRAY_TASK_ID/3"'; do
    grep -qF -- "$want" "$S" && ok "script has $want" || bad "script has $want"
done
sh -n "$S" && ok "the script is valid sh" || bad "the script is valid sh"
# only the shards with work: s1 and s3 finished here, s0 and s2 (indices 0, 2) left: shard 0 of 2
expect 0 "shard 1/2 here" "$GEN3D" $B -o "$T/sl" -q -t 2 --shard 1/2
expect 0 "slurm dry run with two scenes left" "$GEN3D" $B -o "$T/sl" --slurm --dry-run --array-size 2
grep -q "#SBATCH --array=0$" "$S" && ok "the array holds only the shards with work" || bad "the array holds only the shards with work"
finish
