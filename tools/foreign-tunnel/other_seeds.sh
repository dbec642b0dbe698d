#!/usr/bin/env bash
# The harder case, printed rather than checked: the model is fitted on one recording of the
# second tunnel (seed 1, three alphas, 40 s runs) and each diagnosed recording has its own
# excitation and noise (seeds 2 to 7: no effect, then one effect each), so the sim's own error
# differs from its signature. Prints the verdict and the named effects of every case.
#
#   tools/foreign-tunnel/other_seeds.sh [WORK_DIR]   (needs python3 with numpy and a release build)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
tools="${CARGO_TARGET_DIR:-$root/target}/release/host-tools"
work="${1:-$(mktemp -d)}"
mkdir -p "$work"
rm -rf "$work/clean" "$work/model"
python3 "$here/foreign_tunnel.py" --out "$work/clean" --seed 1 2>/dev/null
"$tools" fit --data "$work/clean" --out "$work/model" >/dev/null 2>&1
seed=2
for effect in none actuator_delay inertial_tare gravity_tare roll_damping bias_drift; do
    rm -rf "$work/$effect" "$work/diagnosis-$effect"
    python3 "$here/foreign_tunnel.py" --out "$work/$effect" --seed "$seed" --effect "$effect" 2>/dev/null
    "$tools" diagnose --real "$work/$effect" --model "$work/model" --report "$work/diagnosis-$effect" >/dev/null 2>&1
    python3 - "$work/diagnosis-$effect/diagnosis.json" "$effect" "$seed" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
named = ", ".join(f"{e['name']} (shrink {e['shrink']:.2f})" for e in d["effects"]) or "-"
print(f"seed {sys.argv[3]}, injected {sys.argv[2]}: {d['verdict']}: {named}")
PY
    seed=$((seed + 1))
done
