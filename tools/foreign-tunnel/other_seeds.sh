#!/usr/bin/env bash
# The harder case, printed rather than checked: the model is fitted on one recording of the
# second tunnel (seed 1, three alphas, 40 s runs) and each diagnosed recording has its own
# excitation and noise (seeds 2 to 7: no effect, then one effect each), so the sim's own error
# differs from its signature. Prints the verdict and the named effects of every case.
#
#   tools/foreign-tunnel/other_seeds.sh [WORK_DIR]   (needs python3 with numpy and a release build)
set -euo pipefail
source "$(dirname "$0")/common.sh"
rm -rf "$work/clean" "$work/model"
generate --out "$work/clean" --seed 1
"$tools" fit --data "$work/clean" --out "$work/model" >/dev/null 2>&1
seed=2
for effect in none actuator_delay inertial_tare gravity_tare roll_damping bias_drift; do
    rm -rf "$work/$effect"
    generate --out "$work/$effect" --seed "$seed" --effect "$effect"
    echo "seed $seed, injected $effect: $(diagnosis "$work/$effect" "$work/model" "$work/diagnosis-$effect")"
    seed=$((seed + 1))
done
