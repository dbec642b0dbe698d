#!/usr/bin/env bash
# The tools on datasets from a second, independent tunnel (foreign_tunnel.py: other equations,
# other excitation, other noise and other file conventions than firmware-sim's tunnel).
#
# A clean recording is fitted; then each effect of the vocabulary that this tunnel can inject
# is recorded with the same excitation and noise, and `diagnose` with the fitted model must
# name that effect first (verdict `effect`), while the clean recording must give `none`.
# Prints one line per case and fails on the first wrong verdict or name.
#
#   tools/foreign-tunnel/check.sh [WORK_DIR]   (needs python3 with numpy and a release build)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
tools="${CARGO_TARGET_DIR:-$root/target}/release/host-tools"
work="${1:-$(mktemp -d)}"
mkdir -p "$work"
generate() { python3 "$here/foreign_tunnel.py" --seed 1 --duration-s 30 --alphas 4,18 "$@" 2>/dev/null; }

rm -rf "$work/clean" "$work/model"
generate --out "$work/clean"
"$tools" fit --data "$work/clean" --out "$work/model" >/dev/null 2>&1

verdict_of() {
    python3 - "$1/diagnosis.json" <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
names = [e["name"] for e in d["effects"]]
print(d["verdict"], names[0] if names else "-")
EOF
}

failed=0
for effect in none actuator_delay inertial_tare gravity_tare roll_damping bias_drift; do
    data="$work/clean"
    if [ "$effect" != none ]; then
        data="$work/$effect"
        rm -rf "$data"
        generate --out "$data" --effect "$effect"
    fi
    rm -rf "$work/diagnosis-$effect"
    "$tools" diagnose --real "$data" --model "$work/model" --report "$work/diagnosis-$effect" >/dev/null 2>&1
    read -r verdict first < <(verdict_of "$work/diagnosis-$effect")
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
