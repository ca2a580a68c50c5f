#!/bin/sh
# gen3d batch --slurm against a real Slurm: starts munged, slurmctld and slurmd on this machine
# with tests/slurm/slurm.conf.in (state and logs in a temporary folder), submits 4 small
# scenes as a job array, checks each scene's outputs and status, then adds a scene with a bad
# input and one more, loses one result, and checks that resubmitting runs only what is
# missing, that --retry-failed reruns the failed one after its input is fixed, and that
# nothing is submitted when nothing is left. Stops exactly the daemons it started.
# Needs root and Debian's slurmctld, slurmd, slurm-client and munge
# (sh scripts/install-deps.sh --slurm); skipped (exit 77) where they are missing or Slurm
# cannot start, unless G3D_SLURM_REQUIRED=1 (CI), which makes that a failure.
set -u

skip() {
    if [ "${G3D_SLURM_REQUIRED:-0}" = 1 ]; then echo "FAIL Slurm is required here: $1"; exit 1; fi
    echo "skipped: $1"
    exit 77
}
for p in munged slurmctld slurmd sbatch squeue scontrol sinfo scancel; do
    command -v $p >/dev/null 2>&1 || [ -x "/usr/sbin/$p" ] ||
        skip "no $p (Slurm and munge: sh scripts/install-deps.sh --slurm)"
done
[ "$(id -u)" = 0 ] || skip "the test daemons run as root"
T="$G3D_TEST_TMP/batch_slurm"
. "$G3D_SOURCE_DIR/tests/cli_lib.sh"
need_default_input

# The daemons' folder: short, since munge's socket path must fit in 108 bytes.
D=$(mktemp -d /tmp/g3d-slurm.XXXXXX)
PATH="$PATH:/usr/sbin"
stop_daemons() {
    # only what this script started, by the pid each daemon wrote
    for f in "$D/slurmd.pid" "$D/slurmctld.pid" "$D/munge/munged.pid"; do
        [ -s "$f" ] || continue
        pid=$(cat "$f")
        kill "$pid" 2>/dev/null || continue
        i=0
        while kill -0 "$pid" 2>/dev/null && [ $i -lt 100 ]; do sleep 0.1; i=$((i + 1)); done
    done
    rm -rf "$D"
}
trap stop_daemons EXIT
trap 'exit 130' INT TERM

mkdir -p "$D/munge" "$D/state" "$D/spool"
chmod 711 "$D" "$D/munge"
: >"$D/plugstack.conf"
dd if=/dev/urandom of="$D/munge/munge.key" bs=1024 count=1 2>/dev/null
chmod 600 "$D/munge/munge.key"
munged --force --socket="$D/munge/munge.socket" --key-file="$D/munge/munge.key" --pid-file="$D/munge/munged.pid" \
    --log-file="$D/munge/munged.log" --seed-file="$D/munge/seed" 2>"$D/munged.err" ||
    skip "munged does not start: $(tail -n 1 "$D/munged.err")"
# ports of our own, so that a Slurm already running here is not disturbed
port=$((20000 + ($$ % 10000) * 2))
sed -e "s#@DIR@#$D#g" -e "s#@HOST@#$(hostname)#g" -e "s#@CTLD_PORT@#$port#" -e "s#@SLURMD_PORT@#$((port + 1))#" \
    -e "s#@CPUS@#$(nproc)#" "$G3D_SOURCE_DIR/tests/slurm/slurm.conf.in" >"$D/slurm.conf"
export SLURM_CONF="$D/slurm.conf"
slurmctld -f "$SLURM_CONF" -i 2>>"$D/start.err" || skip "slurmctld does not start: $(tail -n 1 "$D/slurmctld.log" 2>/dev/null)"
slurmd -f "$SLURM_CONF" 2>>"$D/start.err" || skip "slurmd does not start: $(tail -n 1 "$D/slurmd.log" 2>/dev/null)"
i=0
until sinfo -h -o %T 2>/dev/null | grep -q idle; do
    i=$((i + 1))
    [ $i -lt 60 ] || skip "the node does not come up: $(tail -n 1 "$D/slurmd.log" 2>/dev/null)"
    sleep 0.5
done
ok "a one-node Slurm is up"

# Waits until job $1 has left the queue (at most 10 minutes: a sanitizer build is slow).
wait_job() {
    i=0
    while [ -n "$(squeue -h -j "$1" 2>/dev/null)" ]; do
        i=$((i + 1))
        if [ $i -gt 1200 ]; then bad "job $1 still queued after 10 minutes"; scancel "$1"; return 1; fi
        if [ $((i % 4)) = 1 ]; then "$GEN3D" batch --status "$O" >"$T/status.$1" 2>&1 || bad "batch --status while job $1 runs"; fi
        sleep 0.5
    done
}
# The exit codes of a job's array tasks, one per line ("0:0").
task_codes() { scontrol -o show job "$1" | sed -n 's/.* ExitCode=\([0-9:]*\).*/\1/p'; }

M="$T/m/scenes.jsonl"
O="$T/batch"
mkdir -p "$T/m"
cat >"$T/m/defaults.json" <<EOF
{"default-input": "$MB", "max-side": 96, "steps": 2, "extra": 2, "iters": 200, "sh-degree": 0, "no-video": true}
EOF
for k in 0 1 2 3; do echo "{\"id\": \"s$k\", \"seed\": $k}"; done >"$M"
B="batch $M --defaults $T/m/defaults.json -o $O"

# ---- 1. four scenes as an array of four tasks
expect 0 "submit 4 scenes" "$GEN3D" $B --slurm --cpus-per-task 1 --time 10 -q
job=$(cat "$T/out")
echo "$job" | grep -qx "[0-9][0-9]*" && ok "prints the job id ($job)" || bad "prints the job id ('$job')"
grep -q "#SBATCH --array=0-3" "$O/slurm/batch.sbatch" && ok "an array of 4 tasks" || bad "an array of 4 tasks"
wait_job "$job"
[ -s "$T/status.$job" ] && grep -q "^s0 " "$T/status.$job" && ok "--status answers while the array runs" || bad "--status answers while the array runs"
[ "$(task_codes "$job" | grep -c '^0:0$')" = 4 ] && ok "4 tasks exited 0" || bad "4 tasks exited 0 ($(task_codes "$job" | tr '\n' ' '))"
for k in 0 1 2 3; do
    [ -s "$O/s$k/scene.ply" ] && [ -s "$O/s$k/scene.spz" ] && grep -q '"state":[[:space:]]*"done"' "$O/s$k/status.json" &&
        ok "s$k done with its outputs" || bad "s$k done with its outputs"
    [ -s "$O/slurm/${job}_$k.out" ] && grep -q "1 ran (1 done" "$O/slurm/${job}_$k.out" && ok "task $k ran one scene" || bad "task $k ran one scene"
done
expect 0 "status" "$GEN3D" batch --status "$O"
grep -q "4 scenes: 4 done, 0 failed, 0 running, 0 pending" "$T/out" && ok "status: 4 done" || bad "status: 4 done"
for k in 0 2 3; do cp "$O/s$k/status.json" "$T/s$k.before"; done

# ---- 2. a scene with a bad input and a new one added, one result lost: only those run
printf 'P5\n2 2\n255\nabcd' >"$T/m/broken.png"
echo '{"id": "s4", "seed": 4, "input": "broken.png", "depth": "broken.png"}' >>"$M"
echo '{"id": "s5", "seed": 5}' >>"$M"
rm -r "$O/s1"
expect 0 "resubmit" "$GEN3D" $B --slurm --cpus-per-task 1 --array-size 4 -q
job=$(cat "$T/out")
grep -q "#SBATCH --array=0-1$" "$O/slurm/batch.sbatch" && ok "tasks only for the shards with work (s1, s4, s5: 0-1)" ||
    bad "tasks only for the shards with work ($(grep array "$O/slurm/batch.sbatch"))"
wait_job "$job"
for k in 0 2 3; do cmp -s "$T/s$k.before" "$O/s$k/status.json" && ok "s$k not run again" || bad "s$k not run again"; done
[ -s "$O/s1/scene.ply" ] && [ -s "$O/s5/scene.ply" ] && ok "s1 and s5 ran" || bad "s1 and s5 ran"
grep -q '"state":[[:space:]]*"failed"' "$O/s4/status.json" && grep -q "broken.png" "$O/s4/status.json" &&
    ok "s4 failed, naming its input" || bad "s4 failed, naming its input"
[ ! -e "$O/s4/scene.ply" ] && [ -z "$(ls "$O/.batch/work")" ] && ok "nothing half-written" || bad "nothing half-written"
task_codes "$job" | grep -qv '^0:0$' && ok "the task with the failed scene exited non-zero" || bad "the task with the failed scene exited non-zero"
grep -q '"failed":[[:space:]]*1' "$O/summary.json" && ok "summary.json counts the failure" || bad "summary.json counts the failure"

# ---- 3. the input fixed: --retry-failed runs s4 alone
sed 's#, "input": "broken.png", "depth": "broken.png"##' "$M" >"$M.new" && mv "$M.new" "$M"
for k in 0 1 2 3 5; do cp "$O/s$k/status.json" "$T/s$k.before"; done
expect 0 "resubmit with --retry-failed" "$GEN3D" $B --slurm --cpus-per-task 1 -q --retry-failed
job=$(cat "$T/out")
grep -q "#SBATCH --array=0$" "$O/slurm/batch.sbatch" && grep -q -- "--retry-failed" "$O/slurm/batch.sbatch" &&
    ok "one task, passing --retry-failed on" || bad "one task, passing --retry-failed on"
wait_job "$job"
grep -q '"state":[[:space:]]*"done"' "$O/s4/status.json" && [ -s "$O/s4/scene.ply" ] && ok "s4 done" || bad "s4 done"
same=1
for k in 0 1 2 3 5; do cmp -s "$T/s$k.before" "$O/s$k/status.json" || same=0; done
[ $same = 1 ] && ok "the other scenes not run again" || bad "the other scenes not run again"

# ---- 4. nothing left: nothing submitted
expect 0 "resubmit a finished batch" "$GEN3D" $B --slurm
[ ! -s "$T/out" ] && grep -q "nothing to run" "$T/err" && ok "nothing submitted" || bad "nothing submitted"
expect 0 "final status" "$GEN3D" batch --status "$O"
grep -q "6 scenes: 6 done" "$T/out" && ok "6 done" || bad "6 done"
finish
