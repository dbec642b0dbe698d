#!/usr/bin/env bash
# The diagnosis's acceptance campaigns, on seeds nobody chose: both seeds derive from the hash of
# the last commit that changed the diagnosis, the models it fits (the fit and the core), or the
# second tunnel, so they are fixed only after the last change to any of them, and no campaign
# that tuned them can be the one reported.
#
#   tools/diagnosis-campaigns.sh [OUT_DIR] [CASES_PER_CLASS]   (a release build of host-tools;
#                                                              python3 with numpy and scipy)
#
# 1. The form-drawing second tunnel (tools/foreign-tunnel/campaign.py): every case draws a form
#    of its effect from the contract's table, on a rig drawn for the campaign.
# 2. The project's own tunnel (`validate-diagnosis`), on the next seed.
# Prints the seeds, the commands and both criterion tables; forms_report.py adds the rate per
# form and the parameter recovery of the second tunnel's campaign.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
out="${1:-$root/out/diagnosis-campaigns}"
per_class="${2:-10}"
tools="${CARGO_TARGET_DIR:-$root/target}/release/host-tools"
last=$(git -C "$root" log -1 --format=%H -- diagnosis/src/diagnose host-tools/src/diagnose tools/foreign-tunnel \
    model-fit/src/fit estimator-core/src)
seed=$(( 0x${last:0:8} % 1000000 ))
own_seed=$(( seed + 1 ))
cases=$(( per_class * 14 ))
echo "last change to the diagnosis, its models or the second tunnel: $last"
echo "second tunnel: python3 tools/foreign-tunnel/campaign.py --out $out/foreign --seed $seed --cases-per-class $per_class --duration-s 20"
echo "               $tools validate-diagnosis --campaign $out/foreign --report $out/foreign-report"
echo "own tunnel:    $tools validate-diagnosis --cases $cases --seed $own_seed --report $out/own-report"
rm -rf "$out/foreign" "$out/foreign-report" "$out/own-report"
mkdir -p "$out"
python3 "$root/tools/foreign-tunnel/campaign.py" --out "$out/foreign" --seed "$seed" \
    --cases-per-class "$per_class" --duration-s 20 2>/dev/null
"$tools" validate-diagnosis --campaign "$out/foreign" --report "$out/foreign-report" 2>/dev/null
python3 "$root/tools/foreign-tunnel/forms_report.py" "$out/foreign" "$out/foreign-report"
"$tools" validate-diagnosis --cases "$cases" --seed "$own_seed" --report "$out/own-report" 2>/dev/null
