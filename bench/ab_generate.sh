#!/bin/sh
# A/B of `gen3d generate` between a baseline commit and this checkout, on one machine in one
# session: builds both (Release, in a scratch folder), then runs them interleaved - old, new,
# old, new ... - so that a drifting machine load hits both alike, and prints per run the wall
# and CPU seconds, the peak memory, the Gaussian count and the PSNR at the real Middlebury right
# camera on the co-visible pixels (`gen3d eval`, the measure of tests/test_generate_middlebury.c),
# then the ratios of the medians (new / old).
#
#   sh bench/ab_generate.sh [-b COMMIT] [-n ROUNDS] [-e EVAL_SIDE] [-w DIR] [-- generate options]
#
#   -b COMMIT     the baseline (default: main)
#   -n ROUNDS     old/new pairs (default 1)
#   -e SIDE       --max-side of the evaluation (default 0: the real right view at full size)
#   -w DIR        scratch folder (default a new one under /tmp); builds are reused when present
#   G3D_DEFAULT_INPUT=DIR  the default input already fetched elsewhere
#   after --       generate options for both runs (default: none, i.e. the default input and
#                  settings); -o, -q and --default-input are added here
#
# CPU seconds (user + system) are the figure to trust on a shared machine: they do not grow
# with other people's load the way wall time does.
set -eu
cd "$(dirname "$0")/.."
base=main rounds=1 eval_side=0 work=
while [ $# -gt 0 ]; do
    case $1 in
    -b) base=$2; shift 2 ;;
    -n) rounds=$2; shift 2 ;;
    -e) eval_side=$2; shift 2 ;;
    -w) work=$2; shift 2 ;;
    --) shift; break ;;
    *) echo "usage: sh bench/ab_generate.sh [-b COMMIT] [-n ROUNDS] [-e EVAL_SIDE] [-w DIR] [-- generate options]" >&2; exit 2 ;;
    esac
done
[ -n "$work" ] || work=$(mktemp -d /tmp/gen3d-ab.XXXXXX)
mkdir -p "$work"
input=${G3D_DEFAULT_INPUT:-$(sh scripts/fetch-default-input.sh)}
jobs=$(nproc)

if [ ! -x "$work/old/gen3d" ]; then
    echo "building the baseline ($base) in $work/old"
    rm -rf "$work/old-src"
    mkdir -p "$work/old-src"
    git archive "$base" | tar -x -C "$work/old-src"
    cmake -S "$work/old-src" -B "$work/old" -DCMAKE_BUILD_TYPE=Release >/dev/null
    cmake --build "$work/old" -j "$jobs" --target gen3d_cli >/dev/null
fi
echo "building this checkout in $work/new"
cmake -S . -B "$work/new" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$work/new" -j "$jobs" --target gen3d_cli >/dev/null

# one run: prints "wall cpu peak_mb gaussians psnr"
run() {
    bin=$1 out=$2
    shift 2
    rm -rf "$out" "$out.eval"
    /usr/bin/time -f "%e %U %S %M" -o "$out.time" "$bin/gen3d" generate --default-input "$input" "$@" -q -o "$out" \
        >"$out.log" 2>&1 || { echo "ab_generate: $bin/gen3d generate failed: see $out.log" >&2; exit 1; }
    "$bin/gen3d" eval --scene "$out/scene.ply" --views "$input" --max-side "$eval_side" -q -o "$out.eval" \
        >"$out.eval.log" 2>&1 || { echo "ab_generate: $bin/gen3d eval failed: see $out.eval.log" >&2; exit 1; }
    python3 - "$out" <<'EOF'
import json, sys
out = sys.argv[1]
wall, user, sys_, kb = open(out + ".time").read().split()[-4:]
s = json.load(open(out + "/summary.json"))
e = json.load(open(out + ".eval/eval.json"))
psnr = e["per_view"][0]["scene"]["covisible"]["psnr"]
print("%.1f %.1f %.0f %d %.2f" % (float(wall), float(user) + float(sys_), int(kb) / 1024, s["gaussians"], psnr))
EOF
}

printf "%-4s %5s %9s %9s %8s %10s %8s\n" run round wall_s cpu_s peak_mb gaussians psnr_db
: >"$work/results"
i=1
while [ "$i" -le "$rounds" ]; do
    for v in old new; do
        r=$(run "$work/$v" "$work/$v-run$i" "$@") || exit 1
        echo "$v $r" >>"$work/results"
        echo "$v $i $r" | awk '{printf "%-4s %5d %9.1f %9.1f %8.0f %10d %8.2f\n", $1, $2, $3, $4, $5, $6, $7}'
    done
    i=$((i + 1))
done
python3 - "$work/results" <<'EOF'
import statistics, sys
rows = [l.split() for l in open(sys.argv[1])]
med = lambda v, k: statistics.median(float(r[k]) for r in rows if r[0] == v)
names = ["wall s", "cpu s", "peak MB", "gaussians"]
print("median new / old: " + ", ".join("%s %.2f" % (n, med("new", k + 1) / med("old", k + 1)) for k, n in enumerate(names))
      + "; PSNR %+.2f dB" % (med("new", 5) - med("old", 5)))
EOF
