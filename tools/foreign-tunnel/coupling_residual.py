"""What the coupling operator misses on rigs it was not built on: the coupled estimate's residual
on the roll+actuation runs, regressed on families of candidate terms that vanish without
blowing, each family fitted on the fit recording's training part and scored on its held-out
part and on a second recording of the rig.

    coupling_residual.py --out DIR --seeds S1,S2,... [--duration-s 40] [--host-tools BIN]

For each seed, `campaign.py` records two clean recordings of a rig of the second tunnel at 0, 10
and 20 deg (as transfer_table.py does, and into the same folders). `rollest.fit` fits the rig's
model on the fit recording; the estimator that flies is run over every roll+actuation run. The
residual `cl - cl_est` is regressed (least squares, all alphas at once, as the operator is
fitted) on each family's terms over the training part (the first 80 % of each run), and the
table gives the coupled estimate's RMS over the balance noise per alpha: as flown, and with each
family's correction, on the held-out part and on the second recording. Development seeds only:
this chooses what to try, it does not report.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from typing import Callable, Dict, List, Tuple

import numpy as np

import rollest

HERE = os.path.dirname(os.path.abspath(__file__))
ALPHAS_DEG = (0.0, 10.0, 20.0)


def lag(x: np.ndarray, tau_s: float, dt_s: float) -> np.ndarray:
    """First-order lag of `x` with time constant `tau_s` (zero-order hold)."""
    a = np.exp(-dt_s / tau_s)
    out = np.empty_like(x)
    state = x[0]
    for k, value in enumerate(x):
        state = a * state + (1 - a) * value
        out[k] = state
    return out


def variables(run: rollest.Run, est: Dict[str, np.ndarray]) -> Dict[str, np.ndarray]:
    arrays = run.arrays
    cmu = np.nan_to_num(arrays["cmu_port"]) + np.nan_to_num(arrays.get("cmu_stbd", np.zeros(len(run))))
    dt_s = 1.0 / run.sample_hz
    v = {
        "cmu": cmu,
        "sqrt_cmu": np.sqrt(np.maximum(cmu, 0.0)),
        "p": est["phi_dot_rad_s"].astype(float),
        "phi": np.radians(arrays["phi_deg"]),
        "cl_roll": est["cl_roll"].astype(float),
        "cl_afc": est["cl_afc"].astype(float),
        "cl_egk": est["cl_egk"].astype(float),
        "cl_pressure": est["cl_pressure"].astype(float),
        "alpha": np.radians(run.alpha_series()),
    }
    for tau in (0.02, 0.05, 0.1, 0.3):
        v[f"cmu_lag{int(tau * 1000)}"] = lag(cmu, tau, dt_s)
    v["dcmu"] = np.gradient(cmu, dt_s)
    return v


FAMILIES: Dict[str, Callable[[Dict[str, np.ndarray]], List[np.ndarray]]] = {
    "cmu x (p, phi, cl_roll) x alpha": lambda v: [v["cmu"] * f * a for f in (v["p"], v["phi"], v["cl_roll"]) for a in (1, v["alpha"], v["alpha"] ** 2)],
    "sqrt(cmu) x (1, p, phi, cl_roll)": lambda v: [v["sqrt_cmu"] * f for f in (np.ones_like(v["p"]), v["p"], v["phi"], v["cl_roll"])],
    "lagged cmu x (p, phi, cl_roll)": lambda v: [v[f"cmu_lag{t}"] * f for t in (20, 50, 100, 300) for f in (v["p"], v["phi"], v["cl_roll"])],
    "cl_afc x (p, phi, cl_roll, cl_egk - cl_roll)": lambda v: [v["cl_afc"] * f for f in (v["p"], v["phi"], v["cl_roll"], v["cl_egk"] - v["cl_roll"])],
    "cmu x (p^2, phi^2, phi p, p|p|)": lambda v: [v["cmu"] * f for f in (v["p"] ** 2, v["phi"] ** 2, v["phi"] * v["p"], v["p"] * np.abs(v["p"]))],
    "cmu x taps' moment (cl_pressure, cl_pressure - cl_egk)": lambda v: [v["cmu"] * v["cl_pressure"], v["cmu"] * (v["cl_pressure"] - v["cl_egk"])],
    "dcmu x (1, p, phi, cl_roll)": lambda v: [v["dcmu"] * f for f in (np.ones_like(v["p"]), v["p"], v["phi"], v["cl_roll"])],
    "cmu (no roll factor)": lambda v: [v["cmu"], v["cmu"] ** 2, v["sqrt_cmu"]],
}


def rig(out: str, seed: int, duration_s: float):
    data = os.path.join(out, f"rig-{seed}")
    if not os.path.isdir(data):
        subprocess.run([sys.executable, os.path.join(HERE, "campaign.py"), "--out", data, "--seed", str(seed),
                        "--cases-per-class", "1", "--classes", "none", "--duration-s", str(duration_s),
                        "--alphas", ",".join(f"{a:g}" for a in ALPHAS_DEG)], check=True, capture_output=True)
    clean = rollest.load_dataset(os.path.join(data, "clean"))
    second = rollest.load_dataset(os.path.join(data, "cases", "case-000"))
    model = rollest.fit(clean)
    noise = {}
    for row in rollest.evaluate(clean, model=model).results["evaluation"]["blocks"]:
        if row["block"] == "coupled":
            noise[round(row["alpha_deg"])] = row["rms"] / row["rms_over_noise"]
    return clean, second, model, noise


def rows_of(dataset: rollest.Dataset, model: rollest.Model, part: str):
    """Per roll+actuation run: alpha, residual, variables, over the samples of `part`."""
    out = []
    for run in dataset.runs:
        if run.kind != "roll+actuation":
            continue
        est = rollest.Estimator(model).run(run)
        v = variables(run, est)
        r = run.arrays["cl"] - est["cl_est"].astype(float)
        start = rollest.heldout_start(len(run))
        warm = int(1.0 * run.sample_hz)
        sl = {"train": slice(warm, start), "heldout": slice(start, None), "all": slice(warm, None)}[part]
        keep = np.isfinite(r[sl])
        out.append((round(run.alpha_deg), r[sl][keep], {k: x[sl][keep] for k, x in v.items()}))
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", required=True)
    parser.add_argument("--seeds", required=True)
    parser.add_argument("--duration-s", type=float, default=40.0)
    args = parser.parse_args()
    table: Dict[str, Dict[Tuple[str, int], List[float]]] = {}
    for seed in [int(s) for s in args.seeds.split(",")]:
        clean, second, model, noise = rig(args.out, seed, args.duration_s)
        train = rows_of(clean, model, "train")
        scored = {"held-out": rows_of(clean, model, "heldout"), "second": rows_of(second, model, "all")}
        for name, family in [("as flown", None), *FAMILIES.items()]:
            if family is not None:
                X = np.vstack([np.column_stack(family(v)) for _, _, v in train])
                y = np.concatenate([r for _, r, _ in train])
                scale = np.sqrt(np.mean(X**2, axis=0)) + 1e-30
                w = np.linalg.lstsq(X / scale, y, rcond=None)[0] / scale
            for where, rows in scored.items():
                for alpha, r, v in rows:
                    e = r if family is None else r - np.column_stack(family(v)) @ w
                    ratio = float(np.sqrt(np.mean(e**2)) / noise[alpha])
                    table.setdefault(name, {}).setdefault((where, alpha), []).append(ratio)
        print(f"rig {seed} done", file=sys.stderr)
    print("| candidate family | " + " | ".join(f"{w} {a} deg" for w in ("held-out", "second") for a in (0, 10, 20)) + " |")
    print("| --- " * 7 + "|")
    for name, cells in table.items():
        values = [cells[(w, a)] for w in ("held-out", "second") for a in (0, 10, 20)]
        print(f"| {name} | " + " | ".join(f"{statistics.median(x):.2f} ({max(x):.2f})" for x in values) + " |")


if __name__ == "__main__":
    main()
