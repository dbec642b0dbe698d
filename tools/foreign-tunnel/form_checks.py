#!/usr/bin/env python3
"""Numerical checks that each form injects what it says (no diagnosis involved).

    form_checks.py [--seed N] [--duration-s T]

For one rig and one case it draws every form of every effect at a fixed target ratio and
checks, from the injected contribution or the filters it uses: the calibrated ratio (or, where
the form has no size or its range cannot reach it, that it is said so); unit static gain of
every lag; the delay recovered by cross-correlation; a lag's tau from its step response; the
mode's frequency from the contribution's spectrum; a tone's frequency; a drift's power below
0.2 Hz; a backlash within its half-width; a gravity tare's phi0 by least squares; the channels
of a sensor effect. Prints one line per form and exits non-zero on a failed check.
"""

import argparse
import math
import sys

import numpy as np
from scipy import signal

import campaign
import effects
import tunnel


def peak_hz(x, hz, lo=1.0, hi=None):
    x = x - np.mean(x)
    spec = np.abs(np.fft.rfft(x * np.hanning(len(x))))
    f = np.fft.rfftfreq(len(x), 1.0 / hz)
    spec[f < lo] = 0
    if hi is not None:
        spec[f > hi] = 0
    return float(f[np.argmax(spec)])


def xcorr_delay(x, y, hz, max_s=0.6):
    """The delay of y behind x, s, by cross-correlation of their derivatives, refined by a
    parabola through the peak."""
    dx, dy = np.diff(x), np.diff(y)
    m = int(max_s * hz)
    c = np.array([np.dot(dx[: len(dx) - k], dy[k:]) for k in range(m)])
    k = int(np.argmax(c))
    if 0 < k < m - 1:
        a, b, d = c[k - 1], c[k], c[k + 1]
        k = k + 0.5 * (a - d) / (a - 2 * b + d)
    return k / hz


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--duration-s", type=float, default=12.0)
    args = ap.parse_args()
    rig = tunnel.Rig.random(np.random.default_rng([args.seed, 0]))
    hz = rig.hz
    dt = 1.0 / hz
    case = campaign.Case(rig, [2.0, 10.0, 18.0], args.duration_s, args.seed + 1)
    failures = []

    def check(label, ok, text):
        print(f"  {'ok  ' if ok else 'FAIL'} {label}: {text}")
        if not ok:
            failures.append(label)

    # Filters used by the forms: unit static gain, whatever the discretisation.
    step = np.concatenate([np.zeros(100), np.ones(int(10 * hz))])
    for disc in effects.DISCS:
        for den in ([0.05, 1.0], [0.05 * 0.02, 0.07, 1.0], [0.1**2, 2 * 0.2 * 0.1, 1.0]):
            y = effects.lti(step, [1.0], den, dt, disc)
            check(f"lti {disc} {den}", abs(y[-1] - 1) < 1e-6, f"static gain {y[-1]:.8f}")
        y = effects.lti(step, [1.0], [0.05, 1.0], dt, disc)
        k63 = int(np.argmax(y >= 1 - math.exp(-1))) - 100
        check(f"first-order tau {disc}", abs(k63 * dt - 0.05) < 2.5e-3, f"63 % at {k63 * dt * 1000:.1f} ms (tau 50)")
    x = np.cumsum(np.random.default_rng(1).normal(0, 1, 20000))
    for method in ("linear", "lagrange"):
        for d in (0.0123, 0.1377, 0.4991):
            est = xcorr_delay(x, effects.fractional_delay(x, d * hz, method), hz)
            check(f"fractional delay {method} {d}", abs(est - d) < 0.6e-3, f"cross-correlation {est * 1000:.2f} ms")
    ramp = np.concatenate([np.zeros(100), np.full(2000, 0.008)])
    y = effects.rate_limit(ramp, 0.04, dt)
    check("rate limit", abs(np.max(np.diff(y)) / dt - 0.04) < 1e-9 and abs(y[-1] - 0.008) < 1e-12,
          f"max slope {np.max(np.diff(y)) / dt:.4f} /s")

    for name, eff in effects.EFFECTS.items():
        print(name)
        for form in eff.forms:
            rng = np.random.default_rng([args.seed, 1000])
            target = 2.0
            st = eff.setup(rng, case, form)
            v = effects.calibrate(eff, case, st, target)
            eff.finish(st, v, case)
            c = eff.contrib(case, st, v, True)
            chans = st.get("channels") if eff.stream == "cp" else None
            ratio = effects.stream_ratio(case, c, eff.stream, chans)[0]
            rec = st.get("recover", {})
            label = f"{name}/{form}"
            calib = st["calib"]
            if calib[0] == "none":
                check(label, ratio > 0, f"no size to calibrate, ratio {ratio:.2f}")
            elif calib[0] == "bisect" and abs(ratio - target) > 0.05 * target:
                at_end = min(abs(v - calib[2]), abs(v - calib[3])) < 1e-6 * calib[3]
                check(label, at_end, f"ratio {ratio:.2f} at the range's end {v:.4g} (target {target})")
            else:
                check(label, abs(ratio - target) < 0.05 * target, f"ratio {ratio:.2f} (target {target})")
            if name == "balance_resonance" and "aero" in form:
                run = max(range(len(c)), key=lambda i: np.mean(c[i][0] ** 2) if c[i][0] is not None else 0)
                # The mode's peak in its octave band (below it the quasi-static part of H - 1
                # follows the load's own low-frequency content).
                f = peak_hz(c[run][0], hz, 0.5 * rec["freq_hz"], 2 * rec["freq_hz"])
                check(f"{label} mode", abs(f - rec["freq_hz"]) < 0.05 * rec["freq_hz"] + 0.5 or
                      ("freq_hz_2" in rec and abs(f - rec["freq_hz_2"]) < 0.05 * rec["freq_hz_2"] + 0.5),
                      f"spectral peak {f:.1f} Hz, modes {rec['freq_hz']:.1f}/{rec.get('freq_hz_2', float('nan')):.1f} Hz")
            if name == "rig_tone":
                f = peak_hz(c[0][0], hz)
                check(f"{label} tone", abs(f - rec["freq_hz"]) < 0.06 * rec["freq_hz"] + 0.2, f"peak {f:.2f} Hz, tone {rec['freq_hz']:.2f}")
            if name == "bias_drift" and form != "steps":
                # What a zero-phase 0.2 Hz low-pass (odd padding: a ramp passes whole) leaves out,
                # relative to the drift's peak-to-peak size; steps are broadband by nature and not
                # checked. The check's own filter also takes part of what lies between a walk's
                # corner (up to 0.1 Hz) and 0.2 Hz, hence 10 % and not less.
                b, a = signal.butter(2, 0.2, fs=hz)
                hi = [np.sqrt(np.mean((x_[0] - signal.filtfilt(b, a, x_[0], padtype="odd")) ** 2)) / np.ptp(x_[0]) for x_ in c]
                check(f"{label} slow", max(hi) < 0.1, f"RMS above 0.2 Hz {max(hi):.4f} x its peak-to-peak (worst run)")
            if name == "gravity_tare":
                run = case.runs[0]
                a = np.column_stack([np.sin(run["phi"]), np.cos(run["phi"]), np.ones(run["n"])])
                sol = np.linalg.lstsq(a, c[0][0] * rig.qsb, rcond=None)[0]
                phi0 = math.degrees(math.atan2(sol[1], sol[0]))
                check(f"{label} phi0", abs((phi0 - rec["phi0_deg"] + 180) % 360 - 180) < 0.5,
                      f"fitted {phi0:.1f} deg, true {rec['phi0_deg']:.1f}")
            if name == "encoder" and form == "backlash":
                run = case.runs[0]
                check(f"{label} play", np.max(np.abs(c[0][2])) <= math.radians(v) / 2 + 1e-12,
                      f"max |reading - angle| {math.degrees(np.max(np.abs(c[0][2]))):.3f} deg, width {v:.3f}")
            if name == "actuator_delay":
                run = next(r for r, x_ in zip(case.runs, c) if x_[0] is not None)
                y = effects.fractional_delay(run["cmu_eff"], rec["delay_port_s"] * hz, st["interp"])
                est = xcorr_delay(run["cmu_eff"], y, hz)
                check(f"{label} delay", abs(est - rec["delay_port_s"]) < 1e-3, f"port {est * 1000:.1f} ms vs {rec['delay_port_s'] * 1000:.1f}")
            if eff.stream == "cp":
                hit = sorted({effects.CHANNELS[j] for x_ in c if x_[1] is not None
                              for j in range(12) if np.any(np.nan_to_num(x_[1][j], nan=1.0) != 0)})
                check(f"{label} channels", hit == [effects.CHANNELS[j] for j in chans], f"{len(hit)} channel(s) {','.join(hit)}")
    print(f"form_checks: {len(failures)} failed" + (f": {', '.join(failures)}" if failures else ""))
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
