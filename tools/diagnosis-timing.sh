#!/usr/bin/env bash
# The paper-sized diagnosis timed side by side: two builds of host-tools on one machine, on the
# main job's campaign (the paper's, recorded by the synthetic tunnel), each diagnosing against a
# model it fitted itself (so each has its own signature), alternated run by run so that both
# see the same machine. Prints every run's wall time and a table of medians.
#
#   tools/diagnosis-timing.sh OLD_BIN NEW_BIN [ROUNDS] [WORK_DIR]
#
# OLD_BIN, NEW_BIN: host-tools binaries (for example one built from an earlier commit with
# `git worktree add` and `cargo build --release -p host-tools`, and target/release/host-tools).
# ROUNDS: runs per build (default 5). Wall times on a shared machine scatter by a tenth; compare
# medians, and more rounds when they are close.
set -euo pipefail
old="${1:?usage: tools/diagnosis-timing.sh OLD_BIN NEW_BIN [ROUNDS] [WORK_DIR]}"
new="${2:?usage: tools/diagnosis-timing.sh OLD_BIN NEW_BIN [ROUNDS] [WORK_DIR]}"
rounds="${3:-5}"
root="$(cd "$(dirname "$0")/.." && pwd)"
work="${4:-$root/out/diagnosis-timing}"
for bin in "$old" "$new"; do
    [ -x "$bin" ] || { echo "diagnosis-timing: $bin is not an executable host-tools" >&2; exit 2; }
done
mkdir -p "$work"
[ -f "$work/campaign/manifest.toml" ] || "$new" simulate --out "$work/campaign" > /dev/null 2>&1
"$old" fit --data "$work/campaign" --out "$work/model-old" > /dev/null 2>&1
"$new" fit --data "$work/campaign" --out "$work/model-new" > /dev/null 2>&1
times="$work/times.txt"
: > "$times"
for round in $(seq 1 "$rounds"); do
    for build in old new; do
        bin="$old"; [ "$build" = new ] && bin="$new"
        start=$(date +%s.%N)
        "$bin" diagnose --real "$work/campaign" --model "$work/model-$build" --report "$work/report-$build" \
            > /dev/null 2>&1
        end=$(date +%s.%N)
        seconds=$(awk -v s="$start" -v e="$end" 'BEGIN { printf "%.2f", e - s }')
        echo "round $round $build $seconds s"
        echo "$build $seconds" >> "$times"
    done
done
echo "verdicts: old $(grep -o '"verdict": *"[a-z]*"' "$work/report-old/diagnosis.json" | head -1)," \
    "new $(grep -o '"verdict": *"[a-z]*"' "$work/report-new/diagnosis.json" | head -1)"
printf '%-6s %6s %10s %8s %8s\n' build runs "median s" "min s" "max s"
for build in old new; do
    grep "^$build " "$times" | awk '{ print $2 }' | sort -n | awk -v build="$build" '
        { v[NR] = $1 }
        END {
            median = (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2
            printf "%-6s %6d %10.2f %8.2f %8.2f\n", build, NR, median, v[1], v[NR]
        }'
done
