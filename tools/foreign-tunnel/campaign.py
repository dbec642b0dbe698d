#!/usr/bin/env python3
"""Blind diagnosis campaigns from the foreign tunnel, for `host-tools validate-diagnosis
--campaign DIR`.

    campaign.py --out DIR --seed N [--cases-per-class K] [--duration-s 20] [--alphas auto|a,b,c]
                [--workers 2]

README
======

A second synthetic wind tunnel, written apart from firmware-sim and the diagnosis from the
physical definitions only (tunnel.py: the physics; effects.py: the effects). It writes

    DIR/campaign.json         {"format": "foreign-campaign/1", "seed", "clean": "clean",
                               "cases": [{"id", "data", "truth", "truth_sha256"}, ...]}
    DIR/clean/                a recording without effect (its own seed) to fit the model on
    DIR/cases/case-NNN/       one recording per case (manifest.toml + runs/*.csv)
    DIR/sealed/case-NNN.json  the truth: {"id", "class", "form", "params", "channels",
                               "channel_ratios", "ratio", "stream", "alpha_deg", "seed"}

Classes: "none", the 11 vocabulary effects and two outside it (q_fluctuation,
cubic_stiffness), K cases each, case ids shuffled. Every recording: the campaign's three
alphas (auto: one in [0, 4], one in [8, 13], one in [16, 22] deg), runs roll, actuation and
roll+actuation at each, 1 kHz; each case with its own seed (excitation and noise). The rig
is drawn from the campaign seed (tunnel.Rig.random): geometry, tunnel speed 7-12 m/s,
balance C_l noise RMS 3e-4..1e-3 (AR(1), coefficient 0.1-0.5), Cp noise 0.004..0.012 per
channel, the lift states (static-curve centre 18-26 deg, 1.5-5 Hz, damping 0.6-1.1), the
jet (delay 3-10 ms, gain, power 0.45-0.85, 5-14 Hz, sign), the coupling, the taps (six per
half-wing: a baseline suction, more suction under the own side's vortex growing with alpha,
sideslip and roll-rate terms of opposite sign on the two sides, the port jet's suction; a
2-6 ms tube lag) and the excitation (sums of 4-7 sines 0.2-3 Hz, 18-30 deg; blowing levels
held 0.2-2.4 s). Files: the raw moment `mx_nm`, shuffled columns, an unknown
`temperature_c` column, a few `NaN` on one channel, non-zero time origins. Deterministic
for a seed; nothing in a case's files reveals its effect.

Size. Each case draws a target ratio log-uniform in [0.5, 4]: the RMS of the effect's
contribution to the stream it acts on ('cl' = balance roll-moment coefficient for the plant,
disturbance, coupling, balance and outside effects; 'cp' for the sensor effects) over the
runs it acts on (and its channels), divided by that stream's noise RMS (the AR(1) balance
noise's stationary RMS; the channels' Cp noise RMS). The contribution = recording with the
effect - the same recording (same seeds) without it, noise excluded; a run is acted on when
its contribution's RMS is at least 10 % of the largest run's (`alpha_deg` lists their
alphas). Amplitude-type parameters are scaled linearly to the target; delay, lag and
duration parameters are bisected within their range, and where the range cannot reach the
target the nearest end is kept. `ratio` is the achieved value (`channel_ratios` per channel
for sensor effects).

Effects and forms (one form drawn per case; signs random unless said):
- actuator_delay: extra transport delay 15-120 ms (bisected) of the effective Cmu: integer
  samples | fractional, linear interpolation | fractional, 4-point cubic Lagrange.
- actuator_lag: lag 15-150 ms (bisected) of the effective Cmu: first order | second order
  critically damped (two equal poles) | second order overdamped (tau2 = 0.25-0.7 tau);
  each discretised exact ZOH or Tustin.
- inertial_tare: unsubtracted I_extra * roll acceleration in every rolling run (sign mostly
  negative): one constant | a constant differing by up to +-15 % per run | the acceleration
  through the balance's 2nd-order Butterworth filter (15-60 Hz).
- gravity_tare: m g d sin(phi) | m g (d_sin sin(phi) + d_cos (cos(phi) - 1)), a centre of
  gravity off the axis both ways (|d_cos/d_sin| 0.5-3), tared at phi = 0.
- roll_damping (mostly damping, sometimes anti-damping): -K p_hat | -K (1 + g alpha/20deg)
  p_hat, g 1-4 | -K p_hat |p_hat|.
- vortex_lag: a second flow state tau x' + x = u, tau 0.2-3 s, driven by the sideslip
  beta = asin(sin a sin phi) | sin(phi) | the roll rate p_hat | the half-wing lift-state
  asymmetry; moment K x (state) or K (x - u) (deficit); weighted over alpha: equal,
  (alpha/alpha_max)^2, or at the highest alpha only; in half the cases also an imprint on
  3-6 taps (0.3-1.5 x their noise).
- coupling (roll+actuation runs only): K Cmu p_hat | K Cmu sin(phi) | K sqrt(Cmu) beta |
  K jet moment x lift-state asymmetry (the jet's moment changed by the flow state) |
  K lag(Cmu p_hat), lag 30-200 ms.
- pressure_lag: first-order lag 20-100 ms (bisected) on all 12 channels with one tau | on a
  group of 3-6 with one tau | on a group with own taus (0.5-1 x the largest) | on one
  channel; discretised exact ZOH or Tustin.
- pressure_fault, one channel: stuck at the value it had when it stuck | dead, reading 0 |
  dead, reading the ambient Cp 0.5-1.0 (these three for 0.8-1 x a duration, 1 s to T-1 s
  bisected, placed at random in each run, with the sensor's own noise) | a step bias with
  its onset (1 s to T-2 s) and size (0.5-1.5 x) differing per run | bursts of 1-5 samples
  of spikes, 0.3-3 bursts/s, random signs.
- balance_resonance: a mode f 4-40 Hz, zeta 0.005-0.1 between load and gauges; the balance
  reads gain x (H - 1) u extra, u = the roll-acceleration reaction | the aerodynamic moment |
  both; ZOH or Tustin.
- bias_drift (from zero at each run's start): a ramp (slope 0.5-1.5 x, per run) | a cubic
  polynomial with random coefficients per run | a random walk plus a trend.
- q_fluctuation (outside): q(t) = q (1 + eps(t)) with the recorded speed constant; every
  aerodynamic moment scales by (1 + eps), and in half the cases every Cp too: eps an
  Ornstein-Uhlenbeck process (tau 0.3-5 s) | slow surges (1-3 sines, 0.05-1.5 Hz) plus a
  little OU noise.
- cubic_stiffness (outside): a structural spring across the balance -k phi^3 | an
  aerodynamic -k (sin a / sin a_max) phi^3 | a cubic balance spring, the gauge reading
  M - k3 M^3; k mostly restoring.
"""

import argparse
import hashlib
import json
import math
import multiprocessing as mp
import os
import sys
import time

import numpy as np
from scipy import signal

import effects
import tunnel
from tunnel import Rig

CLASSES = ["none", "actuator_delay", "actuator_lag", "inertial_tare", "gravity_tare", "roll_damping", "vortex_lag",
           "coupling", "pressure_lag", "pressure_fault", "balance_resonance", "bias_drift", "q_fluctuation",
           "cubic_stiffness", "rig_tone", "encoder", "balance_saturation"]
KINDS = (("roll", "r"), ("actuation", "a"), ("roll+actuation", "ra"))
FORMATS = {"t_s": "%.4f", "phi_deg": "%.4f", "mx_nm": "%.8g", "temperature_c": "%.1f", "cmu_port": "%.6g",
           "cmu_stbd": "%.6g"}
FORMATS.update({c: "%.6g" for c in effects.CHANNELS})


def seed_of(*key):
    return int(np.random.SeedSequence(list(key)).generate_state(1, np.uint32)[0])


class Case:
    """The runs of one recording, noise-free signals and their noise draws, without effect."""

    def __init__(self, rig, alphas, duration, seed):
        self.rig, self.alphas, self.duration, self.seed = rig, alphas, duration, seed
        hz = rig.hz
        dt = 1.0 / hz
        n = int(round(duration * hz))
        self.runs = []
        for alpha in alphas:
            for kind, stem in KINDS:
                rng = np.random.default_rng([seed, len(self.runs)])
                run = {"kind": kind, "alpha": alpha, "file": f"runs/{stem}_{alpha:g}.csv", "n": n, "t": np.arange(n) * dt}
                if kind != "actuation":
                    run["phi"], run["p"], run["pdot"] = tunnel.sum_of_sines(
                        rng, n, dt, math.radians(rig.roll_amp_deg), rig.roll_f_lo, rig.roll_f_hi, rig.roll_count)
                else:
                    run["phi"] = run["p"] = run["pdot"] = np.zeros(n)
                start = rig.ra_blow_start_s if kind == "roll+actuation" else rig.a_blow_start_s
                run["cmu"] = tunnel.blowing(rng, n, dt, rig.cmu_max, start, rig.blow_hold, rig.blow_ramp_s,
                                            rig.blow_zero_prob) if kind != "roll" else np.zeros(n)
                fl = tunnel.flow(rig, alpha, run["phi"], run["p"])
                run["fl"] = fl
                run["cmu_eff"] = tunnel.plant_cmu(rig, run["cmu"])
                if rig.stbd_jet:
                    # The starboard jet's own levels, from a stream of its own (the port jet's
                    # draws and the noise stay those of a port-only rig).
                    rs = np.random.default_rng([seed, len(self.runs), 7])
                    run["cmu_s"] = tunnel.blowing(rs, n, dt, rig.cmu_max, start, rig.blow_hold, rig.blow_ramp_s,
                                                  rig.blow_zero_prob) if kind != "roll" else np.zeros(n)
                    run["cmu_eff_s"] = tunnel.plant_cmu(rig, run["cmu_s"])
                    run["cmu_noise_s"] = rs.normal(0, rig.cmu_noise, n)
                run["jet"], run["coup"] = tunnel.actuation(rig, fl, run["cmu_eff"], run.get("cmu_eff_s"))
                run["cl"] = fl["cl_roll"] + run["jet"] + run["coup"]
                run["cp"] = tunnel.taps(rig, fl, run["cmu_eff"], run.get("cmu_eff_s"))
                # Noise: AR(1) balance noise started stationary, white Cp and Cmu noise.
                white = rng.normal(0, rig.cl_white, n)
                e0 = rng.normal(0, rig.cl_noise_rms)
                run["cl_noise"] = signal.lfilter([1.0], [1.0, -rig.cl_ar], white, zi=[rig.cl_ar * e0])[0]
                run["cp_noise"] = rng.normal(0, 1, (12, n)) * rig.cp_noise[:, None]
                run["cmu_noise"] = rng.normal(0, rig.cmu_noise, n)
                run["nan_idx"] = rng.integers(0, n, rig.nan_count)
                run["t0"] = round(rig.t0_s + float(rng.uniform(0, 30)), 3)
                run["order_key"] = rng.random(17)
                if rig.stbd_jet:
                    run["order_key"] = np.append(run["order_key"], rs.random())
                self.runs.append(run)

    def write(self, out, contribs=None):
        rig = self.rig
        os.makedirs(os.path.join(out, "runs"))
        for i, run in enumerate(self.runs):
            dcl, dcp, dphi = (tuple(contribs[i]) + (None,))[:3] if contribs else (None, None, None)
            if dphi is not None:
                dcl = None  # the moment gap of a misread angle: the recording keeps the true moment
            cl = run["cl"] + (dcl if dcl is not None else 0.0) + run["cl_noise"]
            cp = run["cp"] + (dcp if dcp is not None else 0.0) + run["cp_noise"]
            cp[rig.nan_channel, run["nan_idx"]] = np.nan
            n = run["n"]
            columns = {"mx_nm": cl * rig.qsb, "temperature_c": np.full(n, rig.temperature_c),
                       "phi_deg": tunnel.quantise_phi(rig, run["phi"] + (dphi if dphi is not None else 0.0)) + 0.0,
                       "t_s": run["t0"] + run["t"]}
            for j, c in enumerate(effects.CHANNELS):
                columns[c] = cp[j]
            columns["cmu_port"] = tunnel.measured_cmu(run["cmu"], run["cmu_noise"])
            if rig.stbd_jet:
                columns["cmu_stbd"] = tunnel.measured_cmu(run["cmu_s"], run["cmu_noise_s"])
            names = list(columns)
            order = [names[k] for k in np.argsort(run["order_key"][: len(names)])]
            tunnel.write_run_csv(os.path.join(out, run["file"]), columns, order, FORMATS)
        with open(os.path.join(out, "manifest.toml"), "w") as f:
            f.write(tunnel.manifest_text(rig, [(r["file"], r["kind"], r["alpha"]) for r in self.runs]))


def clean_number(x):
    """A truth value: numbers to 6 significant digits (non-finite refused), strings and
    integers kept, dicts cleaned value by value."""
    if isinstance(x, dict):
        return {k: clean_number(v) for k, v in x.items()}
    if isinstance(x, str):
        return x
    if isinstance(x, (int, np.integer)) and not isinstance(x, bool):
        return int(x)
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"non-finite value {x}")
    return float(f"{x:.6g}")


def form_table():
    """{class: [form ids]} of every class with an effect."""
    return {c: [f"{c}/{f}" for f in effects.EFFECTS[c].forms] for c in CLASSES if c != "none"}


def form_schedule(seed, classes):
    """The form of each case: per class, its forms in a shuffled order (the campaign seed's),
    the class's k-th case taking the (k mod n)-th, so K >= n cases of a class draw every form."""
    shuffled = {}
    for j, c in enumerate(CLASSES):
        if c != "none":
            forms = list(effects.EFFECTS[c].forms)
            np.random.default_rng([seed, 5, j]).shuffle(forms)
            shuffled[c] = forms
    seen = {}
    out = []
    for c in classes:
        k = seen.get(c, 0)
        seen[c] = k + 1
        out.append(shuffled[c][k % len(shuffled[c])] if c != "none" else "none")
    return out


def make_case(job):
    """Generate and write one case; returns its truth."""
    rig, alphas, duration, out, case_id, cls, seed, form, own_outside = job
    t_start = time.time()
    case = Case(rig, alphas, duration, seed)
    truth = {"id": case_id, "class": cls, "form": "none", "params": {}, "channels": [], "channel_ratios": {},
             "ratio": None, "stream": None, "alpha_deg": [], "seed": seed, "effect": cls, "recover": {}}
    contribs = None
    if cls != "none":
        eff = effects.EFFECTS[cls]
        rng = np.random.default_rng([seed, 1000])
        target = effects.lu(rng, 0.5, 4.0)
        for _ in range(20):
            st = eff.setup(rng, case, form)
            try:
                v = effects.calibrate(eff, case, st, target)
                break
            except ValueError:
                continue
        else:
            raise RuntimeError(f"case {case_id}: no usable draw of {cls}/{form}")
        eff.finish(st, v, case)
        contribs = eff.contrib(case, st, v, True)
        chans = st.get("channels") if eff.stream == "cp" else None
        ratio, acting, chan_ratios = effects.stream_ratio(case, contribs, eff.stream, chans)
        recover = dict(st.get("recover", {}))
        if chans and len(chans) == 1:
            recover.setdefault("channel", effects.CHANNELS[chans[0]])
        truth.update({
            "class": cls if own_outside else effects.SCORED_OUTSIDE.get(cls, cls),
            "form": f"{cls}/{st['form']}",
            "params": {k: clean_number(x) for k, x in st["params"].items()},
            "channels": [effects.CHANNELS[c] for c in chans] if chans else [],
            "channel_ratios": {k: (clean_number(x) if math.isfinite(x) else None) for k, x in chan_ratios.items()},
            "ratio": clean_number(ratio) if math.isfinite(ratio) else None,
            "stream": eff.stream,
            "alpha_deg": sorted({float(case.runs[i]["alpha"]) for i in acting}),
            "target_ratio": clean_number(target) if st["calib"][0] != "none" else None,
            "recover": clean_number(recover),
        })
    case.write(os.path.join(out, "cases", f"case-{case_id:03d}"), contribs)
    return truth, time.time() - t_start


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out")
    parser.add_argument("--seed", type=int)
    parser.add_argument("--cases-per-class", type=int, default=10)
    parser.add_argument("--duration-s", type=float, default=20.0)
    parser.add_argument("--alphas", default="auto")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--list-forms", action="store_true", help="print the classes and their form ids, and stop")
    parser.add_argument("--own-outside-classes", action="store_true",
                        help="write the outside effects' own names as the truth's class (rig_tone, encoder, "
                             "balance_saturation), which the current scorer refuses as unknown classes")
    args = parser.parse_args()
    if args.list_forms:
        for c, forms in form_table().items():
            kind = "outside" if c in effects.SCORED_OUTSIDE else "vocabulary"
            print(f"{c} ({kind}, {len(forms)} forms): {' '.join(forms)}")
        return
    if args.out is None or args.seed is None:
        parser.error("--out and --seed are required")
    if os.path.exists(args.out) and os.listdir(args.out):
        sys.exit(f"campaign.py: {args.out} exists and is not empty")
    seed = args.seed
    rig = Rig.random(np.random.default_rng([seed, 0]))
    if args.alphas == "auto":
        ar = np.random.default_rng([seed, 1])
        alphas = [round(float(ar.uniform(lo, hi)), 1) for lo, hi in ((0.0, 4.0), (8.0, 13.0), (16.0, 22.0))]
    else:
        alphas = [float(a) for a in args.alphas.split(",")]
    classes = [c for c in CLASSES for _ in range(args.cases_per_class)]
    np.random.default_rng([seed, 2]).shuffle(classes)
    os.makedirs(os.path.join(args.out, "sealed"), exist_ok=True)
    os.makedirs(os.path.join(args.out, "cases"), exist_ok=True)

    t0 = time.time()
    Case(rig, alphas, args.duration_s, seed_of(seed, 4)).write(os.path.join(args.out, "clean"))
    print(f"campaign.py: clean recording written ({time.time() - t0:.1f} s)", file=sys.stderr)
    forms = form_schedule(seed, classes)
    jobs = [(rig, alphas, args.duration_s, args.out, i, cls, seed_of(seed, 3, i), forms[i], args.own_outside_classes)
            for i, cls in enumerate(classes)]
    entries = {}
    done = 0
    with mp.get_context("fork").Pool(max(1, args.workers)) as pool:
        for truth, secs in pool.imap_unordered(make_case, jobs):
            i = truth["id"]
            data = json.dumps(truth, indent=1, sort_keys=False).encode() + b"\n"
            rel = f"sealed/case-{i:03d}.json"
            with open(os.path.join(args.out, rel), "wb") as f:
                f.write(data)
            entries[i] = {"id": i, "data": f"cases/case-{i:03d}", "truth": rel,
                          "truth_sha256": hashlib.sha256(data).hexdigest()}
            done += 1
            print(f"campaign.py: case {i:03d} written ({done}/{len(jobs)}, {secs:.1f} s)", file=sys.stderr)
    index = {"format": "foreign-campaign/1", "seed": seed, "clean": "clean",
             "cases": [entries[i] for i in sorted(entries)]}
    with open(os.path.join(args.out, "campaign.json"), "w") as f:
        json.dump(index, f, indent=1)
        f.write("\n")
    print(f"campaign.py: {len(jobs)} cases in {time.time() - t0:.0f} s, {args.out}/campaign.json", file=sys.stderr)


if __name__ == "__main__":
    main()
