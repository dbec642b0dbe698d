#!/usr/bin/env python3
"""A second, independent wind tunnel that writes datasets in the contract format
(shared/spec/dataset-format.md), to check that the tools generalise beyond
firmware-sim's tunnel.

Nothing here is shared with firmware-sim: other equations (a second-order lift
response of each half-wing instead of the Goman-Khrabrov lag, a nonlinear roll
damping, a second-order underdamped jet with a power-law gain, a bilinear
blowing-roll-rate coupling), other excitation (sums of sines, ramped blowing
levels), other wing and tunnel, other noise (AR(1) balance noise), and other
file conventions (the raw balance moment `mx_nm` instead of `cl`, shuffled
columns, an unknown column, `NaN` spelled in capitals, a time origin that is
not zero, no starboard jet column).

Effects of the diagnosis vocabulary can be injected one at a time with
`--effect`; the manifest records nothing about it (the truth is printed). At
`--magnitude 1` each is about 2 to 3 times the balance noise RMS in the runs it
acts on.

Usage: foreign_tunnel.py --out DIR [--seed N] [--duration-s T]
                          [--alphas 4,12,18] [--effect NAME] [--magnitude X]
"""

import argparse
import math
import os
import sys

import numpy as np

EFFECTS = ["none", "actuator_delay", "inertial_tare", "gravity_tare", "roll_damping", "bias_drift"]

# Wing and tunnel: a larger, faster model than the paper's.
U_MPS, RHO = 9.0, 1.18
CHORD, SPAN, AREA, IXX, MASS = 0.28, 0.35, 0.055, 4.5e-4, 0.21
Q = 0.5 * RHO * U_MPS**2
QSB = Q * AREA * SPAN
HZ = 1000.0


def sum_of_sines(rng, n, dt, amplitude, f_lo, f_hi, count=5):
    """A roll trajectory and its analytic derivatives (rad, rad/s, rad/s^2)."""
    t = np.arange(n) * dt
    freqs = rng.uniform(f_lo, f_hi, count)
    phases = rng.uniform(0, 2 * np.pi, count)
    weights = rng.uniform(0.4, 1.0, count) / freqs**0.5
    phi = sum(w * np.sin(2 * np.pi * f * t + p) for w, f, p in zip(weights, freqs, phases))
    dphi = sum(w * 2 * np.pi * f * np.cos(2 * np.pi * f * t + p) for w, f, p in zip(weights, freqs, phases))
    ddphi = sum(-w * (2 * np.pi * f) ** 2 * np.sin(2 * np.pi * f * t + p) for w, f, p in zip(weights, freqs, phases))
    scale = amplitude / np.max(np.abs(phi))
    # A smooth start: the motion fades in over the first second.
    ramp = np.clip(t / 1.0, 0, 1)
    ramp = ramp * ramp * (3 - 2 * ramp)
    dramp = np.where(t < 1.0, 6 * (t / 1.0) * (1 - t / 1.0) / 1.0, 0.0)
    ddramp = np.where(t < 1.0, (6 - 12 * t / 1.0) / 1.0, 0.0)
    return (
        scale * ramp * phi,
        scale * (ramp * dphi + dramp * phi),
        scale * (ramp * ddphi + 2 * dramp * dphi + ddramp * phi),
    )


def blowing(rng, n, dt, cmu_max, start_s):
    """Random levels held 0.25 to 1.2 s, joined by 25 ms ramps; off before `start_s`."""
    cmu = np.zeros(n)
    k = int(start_s / dt)
    level = 0.0
    while k < n:
        new = rng.uniform(0, cmu_max) if rng.random() > 0.2 else 0.0
        ramp = int(0.025 / dt)
        hold = int(rng.uniform(0.25, 1.2) / dt)
        seg = np.concatenate([np.linspace(level, new, ramp, endpoint=False), np.full(hold, new)])
        cmu[k : k + len(seg)] = seg[: max(0, n - k)]
        k += len(seg)
        level = new
    return cmu


def second_order(u, dt, wn, zeta):
    """y'' + 2 zeta wn y' + wn^2 y = wn^2 u, semi-implicit Euler substeps."""
    y, v = 0.0, 0.0
    out = np.empty_like(u)
    sub = 4
    h = dt / sub
    for k, uk in enumerate(u):
        for _ in range(sub):
            v += h * (wn * wn * (uk - y) - 2 * zeta * wn * v)
            y += h * v
        out[k] = y
    return out


def first_order(u, dt, tau):
    a = math.exp(-dt / tau)
    out = np.empty_like(u)
    y = u[0]
    for k, uk in enumerate(u):
        y = a * y + (1 - a) * uk
        out[k] = y
    return out


def run(rng, kind, alpha_deg, duration_s, effect, magnitude, taps_gain):
    n = int(duration_s * HZ)
    dt = 1.0 / HZ
    alpha = math.radians(alpha_deg)
    rolls = kind in ("roll", "roll+actuation")
    blows = kind in ("actuation", "roll+actuation")
    if rolls:
        phi, p, pdot = sum_of_sines(rng, n, dt, math.radians(25.0), 0.3, 2.5)
    else:
        phi = p = pdot = np.zeros(n)
    cmu = blowing(rng, n, dt, 0.008, 5.0 if kind == "roll+actuation" else 0.5) if blows else np.zeros(n)

    p_hat = p * SPAN / (2 * U_MPS)
    beta = np.arcsin(np.sin(alpha) * np.sin(phi))
    # Half-wing incidences and their lift states (second-order response to a logistic
    # static curve of lift loss).
    a_port = np.arctan(np.tan(alpha) * np.cos(phi)) - 0.9 * beta + 1.2 * p_hat
    a_stbd = np.arctan(np.tan(alpha) * np.cos(phi)) + 0.9 * beta - 1.2 * p_hat
    static = lambda a: 1.0 / (1.0 + np.exp((a - math.radians(22.0)) / math.radians(4.0)))
    wn_v, zeta_v = 2 * np.pi * 3.0, 0.8
    l_port = second_order(static(a_port), dt, wn_v, zeta_v)
    l_stbd = second_order(static(a_stbd), dt, wn_v, zeta_v)
    cl = (
        0.06 * math.sin(2 * alpha) * (l_port - l_stbd)
        - 0.0045 * alpha_deg * beta * 0.1
        - 0.21 * p_hat
        - 0.6 * p_hat * np.abs(p_hat)
    )
    # The port jet: power-law gain, a 6 ms pneumatic delay (part of the real plant, not an
    # effect), second-order underdamped response.
    delay = int(0.006 * HZ)
    if effect == "actuator_delay":
        delay += int(round(magnitude * 0.020 * HZ))
    cmu_eff = np.concatenate([np.zeros(delay), cmu[: n - delay]]) if delay else cmu
    gain = 0.011 * (1.0 - 0.35 * (alpha_deg / 20.0) ** 2)
    jet = second_order(-gain * (cmu_eff / 0.008) ** 0.6, dt, 2 * np.pi * 9.0, 0.55)
    coupling = -0.9 * cmu_eff / 0.008 * p_hat * 0.05 + 0.004 * (cmu_eff / 0.008) * np.sin(phi) * math.sin(alpha)
    cl = cl + jet + coupling
    if effect == "roll_damping":
        cl = cl - magnitude * 0.02 * p_hat
    # Pressures: each tap a mix of the states, through a tube lag, with noise.
    states = np.vstack([beta, p_hat, l_port, l_stbd, cmu_eff / 0.008, np.ones(n)])
    cp = taps_gain @ states
    cp = np.vstack([first_order(row, dt, 0.004) for row in cp])
    cp += rng.normal(0, 0.006, cp.shape)
    # Balance: AR(1) noise, then the raw moment in N m.
    white = rng.normal(0, 2.0e-4, n)
    noise = np.empty(n)
    e = 0.0
    for k in range(n):
        e = 0.3 * e + white[k]
        noise[k] = e
    mx = (cl + noise) * QSB
    if effect == "inertial_tare":
        mx = mx - magnitude * 0.08 * IXX * pdot
    if effect == "gravity_tare":
        mx = mx + magnitude * MASS * 9.81 * 0.0015 * np.sin(phi)
    if effect == "bias_drift":
        t = np.arange(n) * dt
        mx = mx + magnitude * 1.2e-3 * QSB * (t / duration_s) ** 1.5
    # Encoder: 0.005 deg quantum.
    phi_meas = np.round(np.degrees(phi) / 0.005) * 0.005
    cmu_meas = np.maximum(cmu + rng.normal(0, 1.5e-5, n) * (cmu > 0), 0.0)
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
    # The taps' sensitivities are a property of the model, the same in every recording.
    taps_gain = np.random.default_rng(1234).normal(0, 1, (12, 6)) * np.array([0.3, 0.5, 0.4, 0.4, 0.05, 0.2])
    taps_gain[:6, 2] *= 2.5
    taps_gain[6:, 3] *= 2.5
    taps_gain[:, 5] -= 0.5
    os.makedirs(os.path.join(args.out, "runs"), exist_ok=False)
    alphas = [float(a) for a in args.alphas.split(",")]
    manifest = [
        'format = "roll-dataset/1"',
        "",
        "[tunnel]",
        f"u_inf_mps = {U_MPS}",
        f"rho_kgm3 = {RHO}",
        "",
        "[wing]",
        f"chord_m = {CHORD}",
        f"span_m = {SPAN}",
        f"area_m2 = {AREA}",
        f"ixx_kgm2 = {IXX}",
        f"mass_kg = {MASS}",
    ]
    for alpha in alphas:
        for kind, stem in (("roll", "r"), ("actuation", "a"), ("roll+actuation", "ra")):
            phi, cmu, cp, mx = run(rng, kind, alpha, args.duration_s, args.effect, args.magnitude, taps_gain)
            name = f"runs/{stem}_{alpha:g}.csv"
            n = len(phi)
            t0 = 12.5
            cp[4, rng.integers(0, n, 30)] = np.nan
            columns = {"mx_nm": mx, "temperature_c": np.full(n, 21.5), "phi_deg": phi, "t_s": t0 + np.arange(n) / HZ}
            for i in range(12):
                columns[f"cp{i + 1:02d}"] = cp[i]
            columns["cmu_port"] = cmu
            order = list(columns)
            rng.shuffle(order)
            with open(os.path.join(args.out, name), "w") as f:
                f.write(",".join(order) + "\n")
                data = np.column_stack([columns[c] for c in order])
                for row in data:
                    f.write(",".join("NaN" if not np.isfinite(v) else repr(float(v)) for v in row) + "\n")
            manifest += ["", "[[run]]", f'file = "{name}"', f'kind = "{kind}"', f"alpha_deg = {alpha}", f"sample_hz = {HZ}"]
    with open(os.path.join(args.out, "manifest.toml"), "w") as f:
        f.write("\n".join(manifest) + "\n")
    print(f"wrote {args.out}: effect {args.effect} x{args.magnitude}", file=sys.stderr)


if __name__ == "__main__":
    main()
