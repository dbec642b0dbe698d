#!/usr/bin/env python3
"""A second, independent wind tunnel that writes datasets in the contract format
(docs/spec/dataset-format.md), to check that the tools generalise beyond
firmware-sim's tunnel.

Nothing here is shared with firmware-sim: other equations (a second-order lift
response of each half-wing instead of the Goman-Khrabrov lag, a nonlinear roll
damping, a second-order underdamped jet with a power-law gain, a bilinear
blowing-roll-rate coupling), other excitation (sums of sines, ramped blowing
levels), other wing and tunnel, other noise (AR(1) balance noise), and other
file conventions (the raw balance moment `mx_nm` instead of `cl`, shuffled
columns, an unknown column, `NaN` spelled in capitals, a time origin that is
not zero, no starboard jet column). The physics lives in tunnel.py (this script
uses its default rig, the original one); campaign.py writes whole blind
campaigns with every effect in several forms and a rig drawn per campaign.

Effects of the diagnosis vocabulary can be injected one at a time with
`--effect`; the manifest records nothing about it (the truth is printed). At
`--magnitude 1` each is about 2 to 3 times the balance noise RMS in the runs it
acts on.

Usage: foreign_tunnel.py --out DIR [--seed N] [--duration-s T]
                          [--alphas 4,12,18] [--effect NAME] [--magnitude X]
"""

import argparse
import os
import sys

import numpy as np

import tunnel
from tunnel import HZ, Rig

EFFECTS = ["none", "actuator_delay", "inertial_tare", "gravity_tare", "roll_damping", "bias_drift"]


def run(rng, kind, alpha_deg, duration_s, effect, magnitude, rig):
    """One run of the original tunnel; random draws in the original order."""
    n = int(duration_s * HZ)
    dt = 1.0 / HZ
    rolls = kind in ("roll", "roll+actuation")
    blows = kind in ("actuation", "roll+actuation")
    if rolls:
        phi, p, pdot = tunnel.sum_of_sines(rng, n, dt, np.radians(rig.roll_amp_deg), rig.roll_f_lo, rig.roll_f_hi, rig.roll_count)
    else:
        phi = p = pdot = np.zeros(n)
    cmu = tunnel.blowing(rng, n, dt, rig.cmu_max, rig.ra_blow_start_s if kind == "roll+actuation" else rig.a_blow_start_s) if blows else np.zeros(n)
    fl = tunnel.flow(rig, alpha_deg, phi, p)
    # The port jet's 6 ms pneumatic delay is part of the real plant, not an effect.
    delay = int(rig.jet_delay_s * HZ)
    if effect == "actuator_delay":
        delay += int(round(magnitude * 0.020 * HZ))
    cmu_eff = tunnel.delay_samples(cmu, delay) if delay else cmu
    jet, coupling = tunnel.actuation(rig, fl, cmu_eff)
    cl = fl["cl_roll"] + jet + coupling
    if effect == "roll_damping":
        cl = cl - magnitude * 0.02 * fl["p_hat"]
    cp = tunnel.taps(rig, fl, cmu_eff)
    cp += rng.normal(0, rig.cp_noise[:, None], cp.shape)
    noise = tunnel.ar1_noise(rng.normal(0, rig.cl_white, n), rig.cl_ar)
    qsb = rig.qsb
    mx = (cl + noise) * qsb
    if effect == "inertial_tare":
        mx = mx - magnitude * 0.08 * rig.ixx * pdot
    if effect == "gravity_tare":
        mx = mx + magnitude * rig.mass * 9.81 * 0.0015 * np.sin(phi)
    if effect == "bias_drift":
        t = np.arange(n) * dt
        mx = mx + magnitude * 1.2e-3 * qsb * (t / duration_s) ** 1.5
    phi_meas = tunnel.quantise_phi(rig, phi)
    cmu_meas = tunnel.measured_cmu(cmu, rng.normal(0, rig.cmu_noise, n))
    return phi_meas, cmu_meas, cp, mx


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--duration-s", type=float, default=40.0)
    parser.add_argument("--alphas", default="4,12,18")
    parser.add_argument("--effect", default="none", choices=EFFECTS)
    parser.add_argument("--magnitude", type=float, default=1.0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    rig = Rig()
    os.makedirs(os.path.join(args.out, "runs"), exist_ok=False)
    alphas = [float(a) for a in args.alphas.split(",")]
    runs = []
    formats = {}
    for alpha in alphas:
        for kind, stem in (("roll", "r"), ("actuation", "a"), ("roll+actuation", "ra")):
            phi, cmu, cp, mx = run(rng, kind, alpha, args.duration_s, args.effect, args.magnitude, rig)
            name = f"runs/{stem}_{alpha:g}.csv"
            n = len(phi)
            cp[rig.nan_channel, rng.integers(0, n, rig.nan_count)] = np.nan
            columns = {"mx_nm": mx, "temperature_c": np.full(n, rig.temperature_c), "phi_deg": phi, "t_s": rig.t0_s + np.arange(n) / HZ}
            for i in range(12):
                columns[f"cp{i + 1:02d}"] = cp[i]
            columns["cmu_port"] = cmu
            order = list(columns)
            rng.shuffle(order)
            formats = {c: "%r" for c in columns}
            tunnel.write_run_csv(os.path.join(args.out, name), columns, order, formats)
            runs.append((name, kind, alpha))
    with open(os.path.join(args.out, "manifest.toml"), "w") as f:
        f.write(tunnel.manifest_text(rig, runs))
    print(f"wrote {args.out}: effect {args.effect} x{args.magnitude}", file=sys.stderr)


if __name__ == "__main__":
    main()
