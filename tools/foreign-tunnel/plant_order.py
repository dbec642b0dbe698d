"""Does the fitted plant miss a jet's dynamics? On each rig's actuation runs, output-error
plants with one pole and with two (complex allowed) are fitted offline, and scored beside the
fitted plant as the estimator flies it; with the floor the evaluation's noise estimate reads for
the rig's AR(1) balance noise.

    plant_order.py --out DIR --seeds S1,S2,...

DIR holds the rigs coupling_residual.py (or transfer_table.py) recorded (`rig-SEED/clean`).
Each offline plant is `C_l = c + sum_j B_j(q) / A(q) g_j(Cmu(t - d))`, with `g` in (Cmu,
sqrt(Cmu), Cmu^2) of each blowing jet, `B_j` of two taps, `A` of one or two poles; the delay `d`
(0, 3, 6 or 10 samples) and the parameters are chosen by the least squares of the training part
(the first 80 % of the run after 1 s), and the error is scored on the held-out part, over the
evaluation's white-noise RMS of the balance. Development seeds only.
"""

from __future__ import annotations

import argparse
import math
import os

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter

import rollest
from tunnel import Rig

DELAYS = (0, 3, 6, 10)


def features(run: rollest.Run, delay: int) -> np.ndarray:
    out = []
    for side in ("cmu_port", "cmu_stbd"):
        u = np.nan_to_num(run.arrays.get(side, np.zeros(len(run))))
        if not np.any(u > 0):
            continue
        u = np.concatenate([np.zeros(delay), u[: len(u) - delay]]) if delay else u
        out += [u, np.sqrt(np.maximum(u, 0)), u**2]
    return np.array(out)


def simulate(theta: np.ndarray, F: np.ndarray, poles: int) -> np.ndarray:
    a, c, b = theta[:poles], theta[poles], theta[poles + 1 :].reshape(F.shape[0], 2)
    den = np.concatenate([[1.0], a])
    return c + sum(lfilter(b[j], den, F[j]) for j in range(F.shape[0]))


def best_fit(run: rollest.Run, poles: int):
    """(training cost, held-out error RMS, delay) of the best delay."""
    y = run.arrays["cl"]
    start = rollest.heldout_start(len(y))
    train = slice(int(run.sample_hz), start)
    ok = np.isfinite(y[train])
    best = None
    for delay in DELAYS:
        F = features(run, delay)
        x0 = np.concatenate([[-1.9, 0.905] if poles == 2 else [-0.95], [0.0], np.zeros(F.shape[0] * 2)])
        fit = least_squares(lambda th: (simulate(th, F, poles) - y)[train][ok], x0, method="lm", max_nfev=600)
        error = (simulate(fit.x, F, poles) - y)[start:]
        error = error[np.isfinite(error)]
        if best is None or fit.cost < best[0]:
            best = (fit.cost, float(np.sqrt(np.mean(error**2))), delay)
    return best


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", required=True)
    parser.add_argument("--seeds", required=True)
    args = parser.parse_args()
    print("| rig | alpha | floor as read | plant as flown | one pole | two poles |\n| --- | --- | --- | --- | --- | --- |")
    for seed in [int(s) for s in args.seeds.split(",")]:
        clean = rollest.load_dataset(os.path.join(args.out, f"rig-{seed}", "clean"))
        model = rollest.fit(clean)
        blocks = rollest.evaluate(clean, model=model).results["evaluation"]["blocks"]
        plant = {round(r["alpha_deg"]): r for r in blocks if r["block"] == "plant"}
        rig = Rig.random(np.random.default_rng([seed, 0]))  # as campaign.py draws it
        floor = 1.0 / math.sqrt(1.0 - rig.cl_ar)  # first differences read AR(1) noise low by sqrt(1 - ar)
        for run in clean.runs:
            if run.kind != "actuation":
                continue
            alpha = round(run.alpha_deg)
            noise = plant[alpha]["rms"] / plant[alpha]["rms_over_noise"]
            one, two = best_fit(run, 1), best_fit(run, 2)
            print(f"| {seed} | {alpha} deg | {floor:.2f} | {plant[alpha]['rms_over_noise']:.2f} | "
                  f"{one[1] / noise:.2f} | {two[1] / noise:.2f} |", flush=True)


if __name__ == "__main__":
    main()
