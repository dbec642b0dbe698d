#!/usr/bin/env bash
# The tools on datasets from a second, independent tunnel (foreign_tunnel.py: other equations,
# other excitation, other noise and other file conventions than firmware-sim's tunnel).
#
# A clean recording is fitted; then each effect of the vocabulary that this tunnel can inject
# is recorded with the same excitation and noise, and `diagnose` with the fitted model must
# name that effect first (verdict `effect`), while the clean recording must give `none`.
# Prints one line per case and fails if any verdict or first name is wrong.
#
#   tools/foreign-tunnel/check.sh [WORK_DIR]   (needs python3 with numpy and a release build)
set -euo pipefail
source "$(dirname "$0")/common.sh"
recording() { generate --seed 1 --duration-s 30 --alphas 4,18 "$@"; }

rm -rf "$work/clean" "$work/model"
recording --out "$work/clean"
"$tools" fit --data "$work/clean" --out "$work/model" >/dev/null 2>&1

failed=0
for effect in none actuator_delay inertial_tare gravity_tare roll_damping bias_drift; do
    data="$work/clean"
    if [ "$effect" != none ]; then
        data="$work/$effect"
        rm -rf "$data"
        recording --out "$data" --effect "$effect"
    fi
    read -r verdict first _ < <(diagnosis "$data" "$work/model" "$work/diagnosis-$effect")
    expected_verdict=effect
    [ "$effect" = none ] && expected_verdict=none
    if [ "$verdict" = "$expected_verdict" ] && { [ "$effect" = none ] || [ "$first" = "$effect" ]; }; then
        echo "foreign tunnel: $effect -> $verdict $first: ok"
    else
        echo "foreign tunnel: $effect -> $verdict $first: WRONG (expected $expected_verdict ${effect/none/-})"
        failed=1
    fi
done
exit "$failed"
