#!/usr/bin/env bash
# A slice of a blind campaign on the second tunnel (campaign.py): one clean case and one case
# of each of a third of the other classes, drawn with the seed (so every class is flown every
# few commits, and CI stays short), the model fitted on the campaign's clean recording and every
# case recorded with its own seed (excitation and noise differ from the fit's), the truth
# sealed before the diagnosis runs. `validate-diagnosis --campaign` prints the criterion table;
# this script fails if the command fails, if a case is not scored, if a sealed truth does not
# match its hash, or if the clean case names an effect (a wrong name where there is none). The
# other criteria are printed, not checked: at one case per class they are a sample, and their
# goals are measured on the full campaign (docs/results.md, "The gap diagnosis: the first
# campaigns").
#
# Without SEED, the seed is the commit under test's: the first 8 hex digits of
# `git rev-parse HEAD` as an integer (3 outside git), so every commit draws other forms and
# another rig. The seed and the command that reproduces the slice are printed first.
#
#   tools/foreign-tunnel/campaign_check.sh [WORK_DIR] [SEED]   (python3 with numpy and scipy,
#                                                               a release build of host-tools)
set -euo pipefail
source "$(dirname "$0")/common.sh"
seed="${2:-}"
if [ -z "$seed" ]; then
    head="$(git -C "$root" rev-parse HEAD 2>/dev/null || true)"
    if [ -n "$head" ]; then seed=$((16#${head:0:8})); else seed=3; fi
fi
classes="$(cd "$here" && python3 -c '
import random, sys
from campaign import CLASSES
others = [name for name in CLASSES if name != "none"]
print(",".join(["none"] + sorted(random.Random(int(sys.argv[1])).sample(others, len(others) // 3))))
' "$seed")"
echo "foreign campaign slice: seed $seed, classes $classes (reproduce: tools/foreign-tunnel/campaign_check.sh $work $seed)"
rm -rf "$work/campaign" "$work/report"
python3 "$here/campaign.py" --out "$work/campaign" --seed "$seed" --cases-per-class 1 --duration-s 20 \
    --classes "$classes" 2>/dev/null
"$tools" validate-diagnosis --campaign "$work/campaign" --report "$work/report" 2>/dev/null
python3 - "$work/campaign" "$work/report/validation.json" <<'PY'
import hashlib, json, sys
campaign = json.load(open(f"{sys.argv[1]}/campaign.json"))
validation = json.load(open(sys.argv[2]))
failures = []
cases = {c["id"]: c for c in validation["cases"]}
for case in campaign["cases"]:
    record = cases.get(case["id"])
    if record is None:
        failures.append(f"case {case['id']}: not scored")
        continue
    sealed = open(f"{sys.argv[1]}/{case['truth']}", "rb").read()
    if hashlib.sha256(sealed).hexdigest() != case["truth_sha256"]:
        failures.append(f"case {case['id']}: sealed truth does not match its hash")
    if record["class"] == "none" and record["named"]:
        failures.append(f"case {case['id']}: no effect injected, but {record['named'][0]} named")
print(f"foreign campaign slice: {len(cases)} of {len(campaign['cases'])} cases scored")
for failure in failures:
    print(f"foreign campaign slice: {failure}")
sys.exit(1 if failures else 0)
PY
