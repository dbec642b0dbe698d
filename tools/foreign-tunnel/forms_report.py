#!/usr/bin/env python3
"""Per-form results of a blind campaign from the foreign tunnel (campaign.py).

    forms_report.py CAMPAIGN_DIR REPORT_DIR

REPORT_DIR is the folder written by `host-tools validate-diagnosis --campaign CAMPAIGN_DIR
--report REPORT_DIR`; its validation.json holds one record per case (id, class, verdict,
named, named_channels, correct, ...). The truth of each case is read from the campaign's
sealed/case-NNN.json (its `form`, `effect` and `recover`).

Prints:
- per form: cases, "first right" (no effect: verdict none; an effect outside the
  vocabulary: verdict unattributed; otherwise the injected name ranked first, and for a
  sensor effect its channels among the named ones), and the scorer's own `correct` count;
- a parameter-recovery table: per class and parameter, the median relative error
  |diagnosed - true| / |true| over the cases whose first named effect is the injected one,
  and the share within 20 %. A pressure lag's `tau_s_by_channel` is scored per channel: each
  lagged channel the diagnosis named, its `tau_s_<channel>` against its own time constant (the
  "cases" column then counts channels).
  The true values are the truth's `recover`; the diagnosed ones are each case's first named
  effect's params, read from the record's `named_params` (the first named effect's
  {param: value}, as host-tools validate-diagnosis writes it; or a list aligned with `named`)
  or `effects` (a list of {"name", "params"}); without either the table says so.
  Parameter names are matched after unit normalisation: `*_ms` -> `*_s` (/1000),
  `f_hz`, `frequency_hz`, `f1_hz` -> `freq_hz`, `delay_ms`/`tau_ms` likewise.
"""

import json
import os
import statistics
import sys
from collections import defaultdict

VOCABULARY = {"actuator_delay", "actuator_lag", "inertial_tare", "gravity_tare", "roll_damping", "vortex_lag",
              "coupling", "pressure_lag", "pressure_fault", "balance_resonance", "bias_drift"}
ALIASES = {"f_hz": "freq_hz", "frequency_hz": "freq_hz", "f1_hz": "freq_hz", "mode_hz": "freq_hz",
           "damping_ratio": "zeta", "zeta1": "zeta"}


def normalise(params):
    """{name: value} of a diagnosis's params with units and names brought to the truth's keys."""
    out = {}
    for k, v in (params or {}).items():
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            continue
        k2, v2 = k, float(v)
        if k.endswith("_ms"):
            k2, v2 = k[:-3] + "_s", v2 / 1000.0
        out[ALIASES.get(k2, k2)] = v2
    return out


def diagnosed_params(record):
    """The first named effect's params, or None when validation.json does not keep them."""
    if isinstance(record.get("named_params"), dict) and record["named_params"]:
        return record["named_params"]
    if isinstance(record.get("named_params"), list) and record["named_params"]:
        return record["named_params"][0]
    if isinstance(record.get("effects"), list) and record["effects"]:
        return record["effects"][0].get("params")
    return None


def first_right(truth, record):
    effect = truth.get("effect", truth["class"])
    named = record.get("named") or []
    if effect == "none":
        return record.get("verdict") == "none"
    if effect not in VOCABULARY:
        return record.get("verdict") == "unattributed"
    if not named or named[0] != effect:
        return False
    if truth.get("stream") == "cp" and truth.get("channels"):
        return set(truth["channels"]) <= set(record.get("named_channels") or [])
    return True


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__.split("\n\n")[1])
    campaign_dir, report_dir = sys.argv[1], sys.argv[2]
    campaign = json.load(open(os.path.join(campaign_dir, "campaign.json")))
    validation = json.load(open(os.path.join(report_dir, "validation.json")))
    records = {r["id"]: r for r in validation["cases"]}
    per_form = defaultdict(lambda: [0, 0, 0])
    errors = defaultdict(list)
    have_params = False
    missing = []
    for case in campaign["cases"]:
        truth = json.load(open(os.path.join(campaign_dir, case["truth"])))
        record = records.get(case["id"])
        if record is None:
            missing.append(case["id"])
            continue
        form = truth.get("form", "none")
        right = first_right(truth, record)
        row = per_form[form]
        row[0] += 1
        row[1] += int(right)
        row[2] += int(bool(record.get("correct")))
        effect = truth.get("effect", truth["class"])
        diag = diagnosed_params(record)
        if diag is not None:
            have_params = True
        if right and effect in VOCABULARY and diag is not None:
            got = normalise(diag)
            for key, true in truth.get("recover", {}).items():
                if isinstance(true, (int, float)) and key in got and true != 0:
                    errors[(effect, key)].append(abs(got[key] - true) / abs(true))
                elif key == "tau_s_by_channel" and isinstance(true, dict):
                    # Each lagged channel the diagnosis named, against its own time constant.
                    for channel, tau_s in true.items():
                        if f"tau_s_{channel}" in got and tau_s:
                            error = abs(got[f"tau_s_{channel}"] - tau_s) / abs(tau_s)
                            errors[(effect, "tau_s per channel")].append(error)

    print(f"{'form':48s} {'cases':>5s} {'first right':>11s} {'scorer right':>12s}")
    totals = [0, 0, 0]
    for form in sorted(per_form):
        n, r, c = per_form[form]
        totals = [totals[0] + n, totals[1] + r, totals[2] + c]
        print(f"{form:48s} {n:5d} {r:11d} {c:12d}")
    print(f"{'all':48s} {totals[0]:5d} {totals[1]:11d} {totals[2]:12d}")
    if missing:
        print(f"not scored: cases {', '.join(map(str, missing))}")
    print()
    if not have_params:
        print("parameter recovery: validation.json keeps no diagnosed params (a per-case `named_params`, "
              "the params of each named effect aligned with `named`, is needed); table skipped")
        return
    print(f"{'class':20s} {'param':24s} {'cases':>5s} {'median rel. error':>18s} {'within 20 %':>11s}")
    for (effect, key) in sorted(errors):
        e = errors[(effect, key)]
        within = sum(error <= 0.2 for error in e) / len(e)
        print(f"{effect:20s} {key:24s} {len(e):5d} {statistics.median(e):18.3f} {100 * within:10.1f}%")


if __name__ == "__main__":
    main()
