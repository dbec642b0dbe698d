#!/usr/bin/env python3
"""Blind diagnosis campaigns from the foreign tunnel, for `host-tools validate-diagnosis
--campaign DIR`.

    campaign.py --out DIR --seed N [--cases-per-class K] [--duration-s 20] [--alphas auto|a,b,c]
                [--workers 2] [--classes none,coupling,...]
    campaign.py --list-forms

README
======

A second synthetic wind tunnel, written apart from firmware-sim and the diagnosis from the
physical definitions only (tunnel.py: the physics; effects.py: the effects, written from the
contract's table "What each name covers" in docs/spec/diagnosis.md). It writes

    DIR/campaign.json         {"format": "foreign-campaign/1", "seed", "clean": "clean",
                               "cases": [{"id", "data", "truth", "truth_sha256"}, ...]}
    DIR/clean/                a recording without effect (its own seed) to fit the model on
    DIR/cases/case-NNN/       one recording per case (manifest.toml + runs/*.csv)
    DIR/sealed/case-NNN.json  the truth: {"id", "class", "form", "params", "channels",
                               "channel_ratios", "ratio", "stream", "alpha_deg", "seed",
                               "effect", "recover", "target_ratio"}

`form` is a stable id "class/form" (`--list-forms` prints them all); `effect` the injected
effect's own name; `recover` the physical parameters a diagnosis should recover, under
standard keys where they apply: delay_s (and delay_port_s, delay_stbd_s), tau_s (pressure
lag: also tau_s_by_channel), freq_hz and zeta (the first mode; freq_hz_2, zeta_2 for a second),
gain, channel (one-channel sensor effects), phi0_deg, rate_per_s, width_deg, limit_nm, ...;
`channels` lists every channel a sensor effect touches; `target_ratio` the drawn target (null
where the form has no size to calibrate).

Classes: "none", the 11 vocabulary effects and five outside it (q_fluctuation,
cubic_stiffness, rig_tone, encoder, balance_saturation), K cases each, case ids shuffled.
Every class is written under its own name; the scorer
(host-tools validate-diagnosis --campaign) scores any class outside the vocabulary as outside.

Forms. Each case's form is drawn from its class's forms: per class the forms are shuffled
(from the campaign seed) and the class's k-th case takes the (k mod n)-th, so K >= n cases
draw every form. Its parameters are drawn in the contract's ranges.

Every recording: the campaign's three alphas (auto: one in [0, 4], one in [8, 13], one in
[16, 22] deg), runs roll, actuation and roll+actuation at each, 1 kHz; each case with its own
seed (excitation and noise). The rig is drawn from the campaign seed (tunnel.Rig.random), so
every campaign has a new one: geometry, tunnel speed 7-12 m/s, balance C_l noise RMS
3e-4..1e-3 (AR(1), coefficient 0.1-0.5), Cp noise 0.004..0.012 per channel, the lift states
(static-curve centre 18-26 deg, 1.5-5 Hz, damping 0.6-1.1), two jets (port and starboard,
the starboard one mirrored, 0.8-1.2 x as strong, its own blowing levels; delay 3-10 ms, gain,
power 0.45-0.85, 5-14 Hz, sign), the coupling, the taps (six per half-wing: a baseline
suction, more suction under the own side's vortex growing with alpha, sideslip and roll-rate
terms of opposite sign on the two sides, each jet's suction on its side; a 2-6 ms tube lag)
and the excitation (sums of 4-7 sines 0.2-3 Hz, 18-30 deg; blowing levels held 0.2-2.4 s).
Files: the raw moment `mx_nm`, `cmu_port` and `cmu_stbd`, shuffled columns, an unknown
`temperature_c` column, a few `NaN` on one channel, non-zero time origins. Deterministic for
a seed; nothing in a case's files reveals its effect.

Size. Each case draws a target ratio log-uniform in [0.5, 4]: the RMS of the effect's
contribution to the stream it acts on ('cl' = balance roll-moment coefficient for the plant,
disturbance, coupling, balance and outside effects; 'cp' for the sensor effects) over the
runs it acts on (and its channels), divided by that stream's noise RMS (the AR(1) balance
noise's stationary RMS; the channels' Cp noise RMS). The contribution = recording with the
effect - the same recording (same seeds) without it, noise excluded; a run is acted on when
its contribution's RMS is at least 10 % of the largest run's (`alpha_deg` lists their
alphas). Where the form has a gain or amplitude, it is scaled linearly to the target and the
form's physical parameters (tau, frequency, zeta, offsets) are drawn in their ranges; where
the size can only come from a delay, lag, slew time, width or depth, that is bisected within
its range, and where the range cannot reach the target the nearest end is kept. A stuck or
dead channel has no size (its ratio is what it is; a dead channel's is null). `ratio` is the
achieved value (`channel_ratios` per channel for sensor effects).

Discretisations: exact ZOH, FOH (exact for a linearly interpolated input) or Tustin, drawn per
case; fractional delays by linear or 4-point Lagrange interpolation; a rate limit and a
backlash by their sample-by-sample recursions.

Effects and forms (form ids after the slash; signs random unless said):
- actuator_delay/{same,per_jet}_{pure,smoothed}: a transport delay d of the effective Cmu,
  d bisected in 2-500 ms; the same on both jets, or per jet (one jet d, the other 0-1 x d);
  alone or followed by a first-order smoothing of 5-20 % of the delay.
- actuator_lag: unit-static-gain low-pass, tau bisected in 5-500 ms: first_order_both |
  first_order_one_jet | second_order_real (poles tau and 0.1-1 x tau) | second_order_complex
  (wn = 1/tau, zeta 0.15-0.6) (these two on port, starboard or both) | rate_limit (the valve
  slews the full Cmu range in 5-500 ms, bisected).
- inertial_tare/{constant,per_run}_{direct,filtered}: -I pdot in the balance moment (I
  mostly positive), one gain or a gain differing by up to +-30 % per run (per mounting), seen
  directly or through the balance's own low-pass (first order 10-60 Hz, or second-order
  Butterworth 15-80 Hz).
- gravity_tare/{constant,cos_alpha}: m g r sin(phi + phi0), phi0 uniform in (-180, 180] deg,
  size constant or x cos(alpha)/cos(alpha_min); the balance zeroed at phi = 0 in half the cases
  (otherwise its constant part stays, also in the runs held at phi = 0).
- roll_damping/{linear,quadratic,cubic}_{constant,alpha}: -K sign(p_hat) |p_hat|^n, n = 1, 2,
  3, K constant or K (1 + g alpha / 20 deg), g 0.5-4.
- vortex_lag/{beta,phi,rate,lift}_{all_alpha,some_alpha}: a second flow state tau x' + x = u,
  tau 2-50 x the rig's lift lag 1/(2 pi f_v), u = sideslip beta, sin(phi), p_hat, or the
  lift-state asymmetry (the vortex state itself); moment K x or K (x - u); at every alpha or
  at one or two of them.
- coupling/{phi,rate,vortex}_{linear,sqrt}_{instant,lagged}: K f(Cmu) x in roll+actuation runs,
  x = sin(phi), p_hat or the lift-state asymmetry, f = the jets' differential Cmu/Cmu_max or
  its signed square root, instantaneous or through a 30-300 ms lag.
- pressure_lag/{first_order,second_order}_{shared,own}: a lag of k channels (k uniform 1-12;
  2-12 for own taus), first order or second order (wn = 1/tau, zeta 0.3-1.2); the largest tau
  bisected in 5-500 ms, the same for every lagged channel or its own (0.1-1 x the largest,
  never below 5 ms).
- pressure_fault/{stuck,dead,biased,drifting,gain,noise,spikes_single,spikes_burst}_from_
  {start,onset}: one channel stuck at its value at the onset | dead (NaN) | a constant bias |
  a ramp | a wrong gain (reads g Cp) | extra white noise | single-sample spikes (1-5 /s) |
  bursts of 5-40 samples (0.2-2 /s); from every run's start, or from an onset drawn per run
  at 10-90 % of it.
- balance_resonance/{one_mode,two_modes}_{motion,aero,blowing}: modes H = wn^2/(s^2 + 2 zeta
  wn s + wn^2), f log-uniform 3-min(300, 0.35 fs) Hz (a second mode 1.5-4 x higher), zeta
  log-uniform 0.005-0.3; the balance reads gain x sum (H_i - 1) u extra, u = the motion's
  inertial reaction | the aerodynamic load (the moment plus a broadband buffet of 20-60 % of
  its RMS) | the jets' moment.
- bias_drift/{ramp,exp_settling,random_walk,steps}: from each run's start: a ramp (0.5-1.5 x
  per run) | D (1 - exp(-t/T)), T 2-20 s | a random walk through a second-order 0.02-0.1 Hz
  low-pass | 1-4 steps at random times.
- q_fluctuation/{ou,surge} (outside): q(t) = q (1 + eps(t)) with the recorded speed constant;
  every aerodynamic moment scales by (1 + eps), in half the cases every Cp too: eps an OU
  process (tau 0.3-5 s) | slow surges (1-3 sines, 0.05-1.5 Hz) plus a little OU noise.
- cubic_stiffness/{structural_phi3,aero_phi3,balance_cubic_spring} (outside): -k phi^3 |
  -k (sin a / sin a_max) phi^3 | the gauge reading M - k3 M^3.
- rig_tone/{pure,harmonics,wandering} (outside): a tone in the balance moment, f 5-150 Hz,
  its phase per run; with 1-2 harmonics; or its frequency wandering +-1-5 % at 0.02-0.2 Hz.
- encoder/{backlash,quantisation} (outside): the recorded roll angle through a play of width
  b, or quantised to steps of b, b bisected in 0.02-5 deg; sized by the moment gap it makes
  (the plant's roll moment at the reading minus at the true angle), which can stay below the
  target at 5 deg.
- balance_saturation/{hard_clip,soft_tanh} (outside): the balance reads clip(M, +-M_s) or
  M_s tanh(M/M_s), M_s = (1 - depth) max |M|, depth bisected in 0.005-0.9.
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
    rig, alphas, duration, out, case_id, cls, seed, form = job
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
            "class": cls,
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
    parser.add_argument("--classes", help="comma-separated classes to draw (default: every class)")
    parser.add_argument("--list-forms", action="store_true", help="print the classes and their form ids, and stop")
    args = parser.parse_args()
    if args.list_forms:
        for c, forms in form_table().items():
            kind = "outside" if c in effects.OUTSIDE else "vocabulary"
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
    chosen = CLASSES if args.classes is None else args.classes.split(",")
    unknown = [c for c in chosen if c not in CLASSES]
    if unknown:
        parser.error(f"--classes: unknown class {unknown[0]!r} (expected one of {', '.join(CLASSES)})")
    classes = [c for c in chosen for _ in range(args.cases_per_class)]
    np.random.default_rng([seed, 2]).shuffle(classes)
    os.makedirs(os.path.join(args.out, "sealed"), exist_ok=True)
    os.makedirs(os.path.join(args.out, "cases"), exist_ok=True)

    t0 = time.time()
    Case(rig, alphas, args.duration_s, seed_of(seed, 4)).write(os.path.join(args.out, "clean"))
    print(f"campaign.py: clean recording written ({time.time() - t0:.1f} s)", file=sys.stderr)
    forms = form_schedule(seed, classes)
    jobs = [(rig, alphas, args.duration_s, args.out, i, cls, seed_of(seed, 3, i), forms[i])
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
