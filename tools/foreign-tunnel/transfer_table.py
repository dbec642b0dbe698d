"""Every block's held-out error over the balance noise, per angle of attack, on clean rigs of
the second tunnel and on the default campaign: how well the estimate transfers to rigs it was
not built on.

    transfer_table.py --host-tools BIN --out DIR --seeds S1,S2,... [--duration-s 40]

For each seed, `campaign.py` draws a rig (tunnel.Rig.random) and records two clean
recordings of it at alpha 0, 10 and 20 deg: the fit recording and a second one with its own
excitation and noise. `host-tools fit` fits the rig's model on the fit recording's training
part, and `host-tools evaluate` scores every block on

- the fit recording's held-out part (the last fifth of every run, never used for fitting or
  selection), and
- the whole second recording, which the model never saw.

The default campaign (`host-tools simulate`) is evaluated with the model fitted on it. Each
table cell is the block's RMS error over the balance's white noise at that angle (the floor no
estimator beats): the median over the rigs, then the worst rig. Everything is seeded, so a
run prints the same table again.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ALPHAS_DEG = (0.0, 10.0, 20.0)
BLOCKS = ("egk", "pressure", "fused", "plant", "linear", "coupled")


def run(command):
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit(f"{' '.join(command)} failed:\n{result.stderr}")


def ratios(report_dir):
    """{(block, alpha_deg): RMS / noise} from an evaluation report."""
    with open(os.path.join(report_dir, "evaluation.json")) as f:
        blocks = json.load(f)["evaluation"]["blocks"]
    return {(row["block"], round(row["alpha_deg"], 1)): row["rms_over_noise"] for row in blocks}


def rig(bin_path, out, seed, duration_s):
    """The two evaluations of one rig: (fit recording's held-out part, second recording)."""
    data = os.path.join(out, f"rig-{seed}")
    if not os.path.isdir(data):
        run([sys.executable, os.path.join(HERE, "campaign.py"), "--out", data, "--seed", str(seed),
             "--cases-per-class", "1", "--classes", "none", "--duration-s", str(duration_s),
             "--alphas", ",".join(f"{a:g}" for a in ALPHAS_DEG)])
    model = os.path.join(out, f"model-{seed}")
    run([bin_path, "fit", "--data", os.path.join(data, "clean"), "--out", model])
    held_out = os.path.join(out, f"eval-{seed}-heldout")
    second = os.path.join(out, f"eval-{seed}-second")
    run([bin_path, "evaluate", "--model", model, "--data", os.path.join(data, "clean"), "--report", held_out])
    run([bin_path, "evaluate", "--model", model, "--data", os.path.join(data, "cases", "case-000"), "--report", second])
    return ratios(held_out), ratios(second)


def default_campaign(bin_path, out):
    data = os.path.join(out, "default-campaign")
    if not os.path.isdir(data):
        run([bin_path, "simulate", "--out", data])
    model = os.path.join(out, "model-default")
    run([bin_path, "fit", "--data", data, "--out", model])
    report = os.path.join(out, "eval-default")
    run([bin_path, "evaluate", "--model", model, "--data", data, "--report", report])
    return ratios(report)


def table(title, per_rig, default):
    print(f"\n{title}\n")
    header = " | ".join(f"{a:g} deg" for a in ALPHAS_DEG)
    print(f"| block | {header} | default campaign, {header} |")
    print("|" + " --- |" * (1 + 2 * len(ALPHAS_DEG)))
    for block in BLOCKS:
        cells = []
        for alpha in ALPHAS_DEG:
            values = [r[(block, alpha)] for r in per_rig if (block, alpha) in r]
            cells.append(f"{statistics.median(values):.2f} ({max(values):.2f})" if values else "-")
        defaults = [f"{default[(block, a)]:.2f}" if (block, a) in default else "-" for a in ALPHAS_DEG]
        print(f"| {block} | " + " | ".join(cells) + " | " + " | ".join(defaults) + " |")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--host-tools", required=True, help="the host-tools binary")
    parser.add_argument("--out", required=True, help="working folder (recordings, models, reports)")
    parser.add_argument("--seeds", required=True, help="comma-separated rig seeds")
    parser.add_argument("--duration-s", type=float, default=40.0)
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    os.makedirs(args.out, exist_ok=True)
    results = [rig(args.host_tools, args.out, seed, args.duration_s) for seed in seeds]
    default = default_campaign(args.host_tools, args.out)
    rigs = f"{len(seeds)} rigs of the second tunnel (seeds {args.seeds}, {args.duration_s:g} s runs)"
    print(f"Held-out RMS / balance noise: median over the rigs (worst rig); {rigs}")
    table("On the fit recording's held-out part:", [r[0] for r in results], default)
    table("On a second recording of each rig (the default campaign: its held-out part):",
          [r[1] for r in results], default)


if __name__ == "__main__":
    main()
