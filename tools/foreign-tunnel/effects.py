"""Effects injected by the foreign tunnel's blind campaigns (campaign.py), each in every form
the contract (docs/spec/diagnosis.md, "What each name covers") lists, as noise-free
contributions added to a case's clean signals.

Every effect class lists its form ids in `forms` and has `setup(rng, case, form)`, which
draws the form's fixed parameters, the random shapes it needs per run and a calibration spec,
and `contrib(case, st, v, cp)`, which returns per run the contribution (dcl, dcp) (either None
when zero; a third element dphi, when present, is a change of the recorded roll angle, and dcl
is then the moment gap it makes, used for sizing only) for the calibrated parameter value `v`.
`calibrate` scales `v` to the case's target ratio (see campaign.py's docstring), and
`finish(st, v, case)` fills the truth's `params` and `recover` (the physical parameters a
diagnosis should recover, under standard keys: delay_s, tau_s, freq_hz, zeta, gain, channel).
"""

import math

import numpy as np
from scipy import signal

import tunnel

CHANNELS = [f"cp{i + 1:02d}" for i in range(12)]


def lu(rng, lo, hi):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def sign(rng, p_neg=0.5):
    return -1.0 if rng.random() < p_neg else 1.0


def rolls(run):
    return run["kind"] in ("roll", "roll+actuation")


def blows(run):
    return run["kind"] in ("actuation", "roll+actuation")


def _replant(case, run, cmu2, cmu2s, cp):
    """The change of the jets' moment, the coupling and (with `cp`) the taps when the effective
    Cmu of the port jet becomes cmu2 and that of the starboard jet cmu2s."""
    rig = case.rig
    jet2, coup2 = tunnel.actuation(rig, run["fl"], cmu2, cmu2s)
    dcl = (jet2 + coup2) - (run["jet"] + run["coup"])
    dcp = tunnel.taps(rig, run["fl"], cmu2, cmu2s) - run["cp"] if cp else None
    return dcl, dcp


def fractional_delay(x, d_samples, method):
    """x delayed by d_samples (>= 0), padded with its first value: 'linear' interpolation
    between the two nearest samples, or 4-point cubic 'lagrange' (linear below 1 sample)."""
    m = int(math.floor(d_samples))
    f = d_samples - m
    if method == "linear" or m < 1:
        return (1 - f) * tunnel.delay_samples(x, m) + f * tunnel.delay_samples(x, m + 1)
    # Taps at delays m-1, m, m+1, m+2; the wanted delay sits at 1 + f from the first.
    d = 1.0 + f
    y = np.zeros_like(x)
    for j in range(4):
        h = 1.0
        for i in range(4):
            if i != j:
                h *= (d - i) / (j - i)
        y += h * tunnel.delay_samples(x, m - 1 + j)
    return y


def lti(u, num, den, dt, method, settled=True):
    """A continuous transfer function num/den applied to the rows of u, discretised by
    `method` ('zoh', 'foh' or 'tustin'), started at its steady state for u's first value."""
    b, a = tunnel.c2d(num, den, dt, method)
    return tunnel._filter(b, a, u, settled)


def rate_limit(x, rate, dt):
    """A valve that moves at most `rate` per second toward its command x."""
    y = np.empty_like(x)
    step = rate * dt
    prev = x[0]
    for k in range(len(x)):
        prev += min(max(x[k] - prev, -step), step)
        y[k] = prev
    return y


DISCS = ["zoh", "foh", "tustin"]


def _jets(run):
    """The run's effective Cmu of the port jet and of the starboard jet (None without one)."""
    return run["cmu_eff"], run.get("cmu_eff_s")


# ---------------------------------------------------------------------------------------------
# Plant effects: the effective Cmu is changed, and with it the jets, the coupling and the taps.


class ActuatorDelay:
    """A transport delay of the effective Cmu, d in (0, 0.5] s (bisected), by fractional
    interpolation (linear or cubic Lagrange, drawn); the same on both jets or per jet (the
    other jet's delay 0-1 x the larger), alone or followed by a first-order smoothing of
    5-20 % of the delay."""

    name, stream = "actuator_delay", "cl"
    forms = ["same_pure", "same_smoothed", "per_jet_pure", "per_jet_smoothed"]

    def setup(self, rng, case, form):
        st = {"form": form, "interp": str(rng.choice(["linear", "lagrange"])), "params": {},
              "rel": np.ones(2), "smooth": 0.0, "calib": ("bisect", "delay_s", 0.002, 0.5, False)}
        if form.startswith("per_jet"):
            rel = np.array([1.0, rng.uniform(0.0, 1.0)])
            st["rel"] = rel[rng.permutation(2)]
        if form.endswith("smoothed"):
            st["smooth"] = float(rng.uniform(0.05, 0.2))
            st["disc"] = str(rng.choice(DISCS))
        return st

    def _apply(self, case, st, x, d):
        hz = case.rig.hz
        y = fractional_delay(x, d * hz, st["interp"])
        if st["smooth"] > 0 and d > 0:
            y = lti(y, [1.0], [st["smooth"] * d, 1.0], 1.0 / hz, st["disc"])
        return y

    def contrib(self, case, st, v, cp):
        out = []
        for run in case.runs:
            if not blows(run):
                out.append((None, None))
                continue
            cp_, cs = _jets(run)
            cp2 = self._apply(case, st, cp_, v * st["rel"][0])
            cs2 = self._apply(case, st, cs, v * st["rel"][1]) if cs is not None else None
            out.append(_replant(case, run, cp2, cs2, cp))
        return out

    def finish(self, st, v, case):
        dp, ds = v * st["rel"][0], v * st["rel"][1]
        st["params"].update({"delay_s": v, "delay_port_s": dp, "delay_stbd_s": ds, "interp": st["interp"]})
        st["recover"] = {"delay_s": v, "delay_port_s": dp, "delay_stbd_s": ds}
        if st["smooth"]:
            st["params"]["smoothing_tau_s"] = st["smooth"] * v
            st["recover"]["smoothing_tau_s"] = st["smooth"] * v
        if not case.rig.stbd_jet:
            st["recover"].pop("delay_stbd_s")


class ActuatorLag:
    """A stable low-pass of unit static gain between the recorded and the effective Cmu, tau
    5-500 ms (bisected): first order on both jets or on one; second order with real poles
    (tau2 = 0.1-1 x tau) or lightly damped complex poles (zeta 0.15-0.6, wn = 1/tau) on one
    or both jets (drawn); or a valve rate limit (the time to slew the full Cmu range,
    5-500 ms, bisected). Discretised exact ZOH, FOH or Tustin."""

    name, stream = "actuator_lag", "cl"
    forms = ["first_order_both", "first_order_one_jet", "second_order_real", "second_order_complex", "rate_limit"]

    def setup(self, rng, case, form):
        st = {"form": form, "disc": str(rng.choice(DISCS)), "params": {},
              "calib": ("bisect", "tau_s", 0.005, 0.5, False)}
        if form == "first_order_both":
            st["jets"] = [0, 1]
        elif form == "first_order_one_jet":
            st["jets"] = [int(rng.integers(0, 2))] if case.rig.stbd_jet else [0]
        else:
            st["jets"] = [[0, 1], [0], [1]][int(rng.integers(0, 3))] if case.rig.stbd_jet else [0]
        if form == "second_order_real":
            st["ratio"] = float(rng.uniform(0.1, 1.0))
        if form == "second_order_complex":
            st["zeta"] = float(rng.uniform(0.15, 0.6))
        if form == "rate_limit":
            st["calib"] = ("bisect", "slew_time_s", 0.005, 0.5, False)
        return st

    def _apply(self, case, st, x, v):
        dt = 1.0 / case.rig.hz
        form = st["form"]
        if form == "rate_limit":
            return rate_limit(x, case.rig.cmu_max / v, dt)
        if form.startswith("first_order"):
            den = [v, 1.0]
        elif form == "second_order_real":
            den = [v * v * st["ratio"], v * (1 + st["ratio"]), 1.0]
        else:
            den = [v * v, 2 * st["zeta"] * v, 1.0]
        return lti(x, [1.0], den, dt, st["disc"])

    def contrib(self, case, st, v, cp):
        out = []
        for run in case.runs:
            if not blows(run):
                out.append((None, None))
                continue
            cp_, cs = _jets(run)
            cp2 = self._apply(case, st, cp_, v) if 0 in st["jets"] else cp_
            cs2 = self._apply(case, st, cs, v) if cs is not None and 1 in st["jets"] else cs
            out.append(_replant(case, run, cp2, cs2, cp))
        return out

    def finish(self, st, v, case):
        jets = "+".join(["port", "stbd"][j] for j in st["jets"])
        st["params"].update({"jets": jets, "disc": st["disc"]})
        if st["form"] == "rate_limit":
            rate = case.rig.cmu_max / v
            st["params"].update({"slew_time_s": v, "rate_per_s": rate})
            st["recover"] = {"rate_per_s": rate, "jets": jets}
            return
        st["params"]["tau_s"] = v
        st["recover"] = {"tau_s": v, "jets": jets}
        if "ratio" in st:
            st["params"]["tau2_s"] = v * st["ratio"]
            st["recover"]["tau2_s"] = v * st["ratio"]
        if "zeta" in st:
            st["params"]["zeta"] = st["zeta"]
            st["recover"]["zeta"] = st["zeta"]


class Coupling:
    """An interaction of the disturbance x (the roll angle sin(phi), the reduced rate p_hat or
    the vortex state = the half-wing lift-state asymmetry) with the blowing f(Cmu) = the jets'
    differential Cmu/Cmu_max (linear) or its signed square root, K f x, instantaneous or
    through a first-order lag of 30-300 ms (ZOH or Tustin). Only where the wing rolls and a jet
    blows (roll+actuation runs)."""

    name, stream = "coupling", "cl"
    forms = [f"{x}_{f}_{t}" for x in ("phi", "rate", "vortex") for f in ("linear", "sqrt") for t in ("instant", "lagged")]

    def setup(self, rng, case, form):
        x, f, t = form.split("_")
        st = {"form": form, "x": x, "f": f, "t": t, "sign": sign(rng), "params": {}, "calib": ("linear", "gain")}
        if t == "lagged":
            st["tau"] = lu(rng, 0.03, 0.3)
            st["disc"] = str(rng.choice(["zoh", "tustin"]))
        return st

    def contrib(self, case, st, v, cp):
        rig = case.rig
        out = []
        for run in case.runs:
            if run["kind"] != "roll+actuation":
                out.append((None, None))
                continue
            fl = run["fl"]
            cp_, cs = _jets(run)
            c = np.maximum(cp_, 0) / rig.cmu_max
            if cs is not None:
                c = c - np.maximum(cs, 0) / rig.cmu_max
            fc = c if st["f"] == "linear" else np.sign(c) * np.sqrt(np.abs(c))
            x = {"phi": np.sin(fl["phi"]), "rate": fl["p_hat"], "vortex": fl["l_port"] - fl["l_stbd"]}[st["x"]]
            d = fc * x
            if st["t"] == "lagged":
                d = lti(d, [1.0], [st["tau"], 1.0], 1.0 / rig.hz, st["disc"])
            out.append((st["sign"] * v * d, None))
        return out

    def finish(self, st, v, case):
        st["params"]["gain"] = st["sign"] * v
        st["recover"] = {"gain": st["sign"] * v}
        if "tau" in st:
            st["params"]["tau_s"] = st["tau"]
            st["recover"]["tau_s"] = st["tau"]


# ---------------------------------------------------------------------------------------------
# Disturbance effects (aerodynamic, in C_l).


class RollDamping:
    """-K sign(p_hat) |p_hat|^n, n = 1, 2 or 3 (always opposing the rate), K constant or
    K (1 + g alpha / 20 deg), g 0.5-4."""

    name, stream = "roll_damping", "cl"
    forms = [f"{o}_{w}" for o in ("linear", "quadratic", "cubic") for w in ("constant", "alpha")]

    def setup(self, rng, case, form):
        o, w = form.split("_")
        st = {"form": form, "n": {"linear": 1, "quadratic": 2, "cubic": 3}[o], "g": 0.0, "params": {},
              "calib": ("linear", "gain")}
        if w == "alpha":
            st["g"] = float(rng.uniform(0.5, 4.0))
        return st

    def contrib(self, case, st, v, cp):
        out = []
        for run in case.runs:
            if not rolls(run):
                out.append((None, None))
                continue
            ph = run["fl"]["p_hat"]
            w = 1.0 + st["g"] * run["alpha"] / 20.0
            out.append((-v * w * np.sign(ph) * np.abs(ph) ** st["n"], None))
        return out

    def finish(self, st, v, case):
        st["params"].update({"gain": v, "order": st["n"], "alpha_gain_per_20deg": st["g"]})
        st["recover"] = {"gain": v, "order": st["n"]}
        if st["g"]:
            st["recover"]["alpha_gain_per_20deg"] = st["g"]


class VortexLag:
    """A second, slower flow state x: tau x' + x = u, tau = 2-50 x the rig's lift lag
    (1 / (2 pi f_v)); u = the sideslip beta, sin(phi), the reduced rate p_hat, or the
    half-wing lift-state asymmetry (the vortex state itself); moment K x (state) or K (x - u)
    (deficit, drawn); at every alpha, or only at some (one or two of the alphas, drawn).
    Discretised exact ZOH, FOH or Tustin."""

    name, stream = "vortex_lag", "cl"
    forms = [f"{d}_{s}" for d in ("beta", "phi", "rate", "lift") for s in ("all_alpha", "some_alpha")]

    def setup(self, rng, case, form):
        driver, scope = form.split("_", 1)
        tau_flow = 1.0 / (2 * np.pi * case.rig.f_v)
        ratio = lu(rng, 2.0, 50.0)
        st = {"form": form, "driver": driver, "output": str(rng.choice(["state", "deficit"])),
              "tau": ratio * tau_flow, "ratio": ratio, "sign": sign(rng), "disc": str(rng.choice(DISCS)),
              "calib": ("linear", "gain"), "params": {}}
        alphas = sorted(set(case.alphas))
        if scope == "all_alpha":
            st["alphas"] = alphas
        else:
            k = int(rng.integers(1, max(2, len(alphas))))
            st["alphas"] = sorted(float(a) for a in rng.permutation(alphas)[:k])
        return st

    def contrib(self, case, st, v, cp):
        out = []
        for run in case.runs:
            if not rolls(run) or run["alpha"] not in st["alphas"]:
                out.append((None, None))
                continue
            fl = run["fl"]
            u = {"beta": fl["beta"], "phi": np.sin(fl["phi"]), "rate": fl["p_hat"],
                 "lift": fl["l_port"] - fl["l_stbd"]}[st["driver"]]
            x = lti(u, [1.0], [st["tau"], 1.0], 1.0 / case.rig.hz, st["disc"])
            m = x if st["output"] == "state" else x - u
            out.append((st["sign"] * v * m, None))
        return out

    def finish(self, st, v, case):
        st["params"].update({"tau_s": st["tau"], "tau_over_flow_lag": st["ratio"], "gain": st["sign"] * v,
                             "output": st["output"], "alphas": ",".join(f"{a:g}" for a in st["alphas"])})
        st["recover"] = {"tau_s": st["tau"], "gain": st["sign"] * v}


# ---------------------------------------------------------------------------------------------
# Balance effects (in the balance's moment; C_l units here).


class InertialTare:
    """An unsubtracted -I pdot in the balance moment (I = 0.02-... x, calibrated), the gain
    constant or changing per mounting (per run, +-30 %), seen directly or through the
    balance's own low-pass (first order 10-60 Hz, or second-order Butterworth 15-80 Hz)."""

    name, stream = "inertial_tare", "cl"
    forms = ["constant_direct", "constant_filtered", "per_run_direct", "per_run_filtered"]

    def setup(self, rng, case, form):
        st = {"form": form, "sign": sign(rng, 0.7), "params": {}, "calib": ("linear", "gain")}
        n = len(case.runs)
        st["spread"] = rng.uniform(-0.3, 0.3, n) if form.startswith("per_run") else np.zeros(n)
        if form.endswith("filtered"):
            if rng.random() < 0.5:
                st["fc"], st["order"] = float(rng.uniform(10.0, 60.0)), 1
            else:
                st["fc"], st["order"] = float(rng.uniform(15.0, 80.0)), 2
        return st

    def contrib(self, case, st, v, cp):
        rig = case.rig
        out = []
        for i, run in enumerate(case.runs):
            if not rolls(run):
                out.append((None, None))
                continue
            acc = run["pdot"]
            if "fc" in st:
                if st["order"] == 1:
                    acc = lti(acc, [1.0], [1.0 / (2 * np.pi * st["fc"]), 1.0], 1.0 / rig.hz, "tustin")
                else:
                    b, a = signal.butter(2, st["fc"], fs=rig.hz)
                    acc = signal.lfilter(b, a, acc)
            ixx = -st["sign"] * v * (1.0 + st["spread"][i])
            out.append((ixx * acc / rig.qsb, None))
        return out

    def finish(self, st, v, case):
        g = -st["sign"] * v
        st["params"]["ixx_kgm2"] = g
        st["recover"] = {"gain": g}
        if np.any(st["spread"]):
            by_run = {case.runs[i]["file"]: g * (1 + s) for i, s in enumerate(st["spread"]) if rolls(case.runs[i])}
            st["recover"]["gain_by_run"] = by_run
            st["params"]["per_run_spread_max"] = float(np.max(np.abs(st["spread"])))
        if "fc" in st:
            st["params"].update({"filter_hz": st["fc"], "filter_order": st["order"]})
            st["recover"]["filter_hz"] = st["fc"]


class GravityTare:
    """m g r sin(phi + phi0) w(alpha) of a centre of gravity off the roll axis, phi0 uniform in
    (-180, 180] deg, w = 1 (constant) or cos(alpha) / cos(alpha_min); the balance zeroed at
    phi = 0 in half the cases (else its constant part stays, also in the runs that hold
    phi = 0)."""

    name, stream = "gravity_tare", "cl"
    forms = ["constant", "cos_alpha"]

    def setup(self, rng, case, form):
        return {"form": form, "phi0": float(rng.uniform(-np.pi, np.pi)), "tared": bool(rng.random() < 0.5),
                "params": {}, "calib": ("linear", "mgr_nm")}

    def contrib(self, case, st, v, cp):
        rig = case.rig
        a0 = min(case.alphas)
        out = []
        for run in case.runs:
            w = 1.0 if st["form"] == "constant" else math.cos(math.radians(run["alpha"])) / math.cos(math.radians(a0))
            m = np.sin(run["phi"] + st["phi0"])
            if st["tared"]:
                m = m - math.sin(st["phi0"])
            if not np.any(m):
                out.append((None, None))
                continue
            out.append((v * w * m / rig.qsb, None))
        return out

    def finish(self, st, v, case):
        r = v / (case.rig.mass * 9.81)
        st["params"].update({"mgr_nm": v, "r_m": r, "phi0_deg": math.degrees(st["phi0"]), "tared": int(st["tared"])})
        st["recover"] = {"gain": v, "phi0_deg": math.degrees(st["phi0"])}


class BalanceResonance:
    """One or two lightly damped modes H = wn^2 / (s^2 + 2 zeta wn s + wn^2) between a load
    and the gauges, f 3-min(300, 0.35 fs) Hz log-uniform (a second mode 1.5-4 x higher),
    zeta 0.005-0.3 log-uniform: the balance reads gain x sum (H_i - 1) u extra, u = the
    motion's inertial reaction (-Ixx pdot), the aerodynamic load (the moment plus a broadband
    buffet of 20-60 % of its RMS) or the jets' moment (blowing). ZOH, FOH or Tustin."""

    name, stream = "balance_resonance", "cl"
    forms = [f"{m}_{x}" for m in ("one_mode", "two_modes") for x in ("motion", "aero", "blowing")]

    def setup(self, rng, case, form):
        m, x = form.rsplit("_", 1)
        fmax = min(300.0, 0.35 * case.rig.hz)
        f1 = lu(rng, 3.0, fmax)
        modes = [(f1, lu(rng, 0.005, 0.3))]
        if m == "two_modes":
            f2 = min(f1 * rng.uniform(1.5, 4.0), fmax)
            modes.append((f2, lu(rng, 0.005, 0.3)))
        st = {"form": form, "x": x, "modes": modes, "disc": str(rng.choice(DISCS)),
              "calib": ("linear", "gain"), "params": {}}
        if x == "aero":
            st["buffet"] = float(rng.uniform(0.2, 0.6))
            st["buffet_seed"] = int(rng.integers(0, 2**31))
        return st

    def _load(self, case, st, i, run):
        rig = case.rig
        if st["x"] == "motion":
            return -rig.ixx * run["pdot"] / rig.qsb
        if st["x"] == "blowing":
            return run["jet"]
        w = np.random.default_rng([st["buffet_seed"], i]).normal(0, 1, run["n"])
        return run["cl"] + st["buffet"] * np.sqrt(np.mean(run["cl"] ** 2)) * w

    def contrib(self, case, st, v, cp):
        dt = 1.0 / case.rig.hz
        out = []
        for i, run in enumerate(case.runs):
            u = self._load(case, st, i, run)
            if not np.any(u):
                out.append((None, None))
                continue
            d = np.zeros(run["n"])
            for f, z in st["modes"]:
                wn = 2 * np.pi * f
                d += lti(u, [-1.0, -2 * z * wn, 0.0], [1.0, 2 * z * wn, wn * wn], dt, st["disc"])
            out.append((v * d, None))
        return out

    def finish(self, st, v, case):
        (f1, z1) = st["modes"][0]
        st["params"].update({"gain": v, "disc": st["disc"]})
        for k, (f, z) in enumerate(st["modes"]):
            st["params"][f"f{k + 1}_hz"] = f
            st["params"][f"zeta{k + 1}"] = z
        st["recover"] = {"freq_hz": f1, "zeta": z1, "gain": v}
        if len(st["modes"]) > 1:
            st["recover"]["freq_hz_2"], st["recover"]["zeta_2"] = st["modes"][1]
        if "buffet" in st:
            st["params"]["buffet_ratio"] = st["buffet"]


class BiasDrift:
    """A slow zero drift of the balance from each run's start, sized D: a ramp D s_r t / T
    (s_r = 0.5-1.5 per run) | an exponential settling D s_r (1 - exp(-t / T_s)), T_s 2-20 s |
    a random walk low-passed below 0.1 Hz (second-order Butterworth, corner 0.02-0.1 Hz) | 1-4 steps of
    random sizes at random times."""

    name, stream = "bias_drift", "cl"
    forms = ["ramp", "exp_settling", "random_walk", "steps"]

    def setup(self, rng, case, form):
        s = sign(rng)
        dt = 1.0 / case.rig.hz
        st = {"form": form, "params": {}, "calib": ("linear", "drift_cl")}
        if form == "exp_settling":
            st["ts"] = float(rng.uniform(2.0, 20.0))
        if form == "random_walk":
            st["fc"] = float(rng.uniform(0.02, 0.1))
        shapes = []
        for run in case.runs:
            t = run["t"]
            if form == "ramp":
                shp = s * rng.uniform(0.5, 1.5) * t / t[-1]
            elif form == "exp_settling":
                shp = s * rng.uniform(0.5, 1.5) * (1 - np.exp(-t / st["ts"]))
            elif form == "random_walk":
                walk = np.cumsum(rng.normal(0, math.sqrt(dt), run["n"]))
                wc = 2 * np.pi * st["fc"]
                shp = lti(walk, [1.0], [1 / wc**2, math.sqrt(2) / wc, 1.0], dt, "zoh", settled=False)
            else:
                shp = np.zeros(run["n"])
                for _ in range(int(rng.integers(1, 5))):
                    shp += sign(rng) * rng.uniform(0.3, 1.0) * (t >= rng.uniform(0.05, 0.95) * t[-1])
            shapes.append(shp)
        rms = math.sqrt(np.mean(np.concatenate(shapes) ** 2)) or 1.0
        st["shapes"] = [x / rms for x in shapes]
        return st

    def contrib(self, case, st, v, cp):
        return [(v * shp, None) for shp in st["shapes"]]

    def finish(self, st, v, case):
        st["params"].update({"drift_rms_cl": v, "drift_rms_nm": v * case.rig.qsb})
        st["recover"] = {"gain": v}
        if "ts" in st:
            st["params"]["tau_s"] = st["ts"]
            st["recover"]["tau_s"] = st["ts"]
        if "fc" in st:
            st["params"]["corner_hz"] = st["fc"]


# ---------------------------------------------------------------------------------------------
# Sensor effects (pressure channels).


class PressureLag:
    """A first-order lag 1 / (tau s + 1) or a second-order one wn^2 / (s^2 + 2 zeta wn s + wn^2)
    (wn = 1 / tau, zeta 0.3-1.2) of k channels, k uniform in 1-12, random channels; the same
    tau for every lagged channel, or its own (0.1-1 x the largest); the largest tau bisected
    in 5-500 ms (the smallest kept >= 5 ms). ZOH, FOH or Tustin."""

    name, stream = "pressure_lag", "cp"
    forms = ["first_order_shared", "first_order_own", "second_order_shared", "second_order_own"]

    def setup(self, rng, case, form):
        order, share = form.rsplit("_", 1)
        k = int(rng.integers(1, 13)) if share == "shared" else int(rng.integers(2, 13))
        chans = sorted(int(c) for c in rng.permutation(12)[:k])
        rel = np.ones(k)
        if share == "own":
            rel = rng.uniform(0.1, 1.0, k)
            rel[int(rng.integers(0, k))] = 1.0
        st = {"form": form, "order": order, "disc": str(rng.choice(DISCS)), "channels": chans, "rel": rel,
              "params": {}, "calib": ("bisect", "tau_s", 0.005 / rel.min(), 0.5, False)}
        if order == "second_order":
            st["zeta"] = float(rng.uniform(0.3, 1.2))
        return st

    def contrib(self, case, st, v, cp):
        dt = 1.0 / case.rig.hz
        out = []
        for run in case.runs:
            dcp = np.zeros((12, run["n"]))
            for c, r in zip(st["channels"], st["rel"]):
                tau = v * r
                den = [tau, 1.0] if st["order"] == "first_order" else [tau * tau, 2 * st["zeta"] * tau, 1.0]
                dcp[c] = lti(run["cp"][c], [1.0], den, dt, st["disc"]) - run["cp"][c]
            out.append((None, dcp))
        return out

    def finish(self, st, v, case):
        by = {CHANNELS[c]: v * r for c, r in zip(st["channels"], st["rel"])}
        st["params"].update({"tau_s": v, "disc": st["disc"]})
        st["params"].update({f"tau_{c}_s": t for c, t in by.items()})
        st["recover"] = {"tau_s": v, "tau_s_by_channel": by}
        if "zeta" in st:
            st["params"]["zeta"] = st["zeta"]
            st["recover"]["zeta"] = st["zeta"]


class PressureFault:
    """One channel: stuck (held at its value at the onset) | dead (missing: NaN) | biased
    (a constant offset) | drifting (a ramp from the onset) | a wrong gain (reads g x Cp,
    g = 1 +- calibrated) | extra white noise | spiking in single samples (1-5 /s) | spiking in
    bursts of 5-40 samples (0.2-2 /s); from the start of every run or from an onset drawn
    per run (10-90 % of the run). Stuck and dead have no size to calibrate (their ratio is
    what it is; a dead channel's is null)."""

    name, stream = "pressure_fault", "cp"
    kinds = ["stuck", "dead", "biased", "drifting", "gain", "noise", "spikes_single", "spikes_burst"]
    forms = [f"{k}_{w}" for k in kinds for w in ("from_start", "from_onset")]

    def setup(self, rng, case, form):
        kind, when = form.rsplit("_from_", 1)
        ch = int(rng.integers(0, 12))
        n_runs = len(case.runs)
        T = case.duration
        st = {"form": form, "kind": kind, "channels": [ch], "params": {}, "calib": ("linear", "size"),
              "onset": np.zeros(n_runs) if when == "start" else rng.uniform(0.1, 0.9, n_runs) * T,
              "sign": sign(rng)}
        if kind in ("stuck", "dead"):
            st["calib"] = ("none",)
        shapes = []
        for i, run in enumerate(case.runs):
            on = run["t"] >= st["onset"][i]
            if kind == "biased":
                shp = on * 1.0
            elif kind == "drifting":
                shp = on * (run["t"] - st["onset"][i]) / T
            elif kind == "noise":
                shp = on * rng.normal(0, 1, run["n"])
            elif kind.startswith("spikes"):
                shp = np.zeros(run["n"])
                single = kind == "spikes_single"
                rate = rng.uniform(1.0, 5.0) if single else rng.uniform(0.2, 2.0)
                for _ in range(rng.poisson(rate * T)):
                    k = int(rng.integers(0, run["n"]))
                    w = 1 if single else int(rng.integers(5, 41))
                    shp[k : k + w] += sign(rng) * rng.uniform(0.5, 1.5)
                shp *= on
            else:
                shp = None
            shapes.append(shp)
        st["shapes"] = shapes
        return st

    def contrib(self, case, st, v, cp):
        ch = st["channels"][0]
        out = []
        for i, run in enumerate(case.runs):
            dcp = np.zeros((12, run["n"]))
            x = run["cp"][ch]
            on = run["t"] >= st["onset"][i]
            kind = st["kind"]
            if kind == "stuck":
                k0 = int(np.argmax(on))
                dcp[ch] = on * (x[k0] - x)
            elif kind == "dead":
                dcp[ch] = np.where(on, np.nan, 0.0)
            elif kind == "gain":
                dcp[ch] = on * st["sign"] * v * x
            else:
                dcp[ch] = st["sign"] * v * st["shapes"][i]
            out.append((None, dcp))
        return out

    def finish(self, st, v, case):
        kind = st["kind"]
        st["recover"] = {"channel": CHANNELS[st["channels"][0]]}
        if np.any(st["onset"]):
            st["params"]["onset_s_by_run"] = ",".join(f"{t:.3f}" for t in st["onset"])
            st["recover"]["onset_s_by_run"] = {r["file"]: float(t) for r, t in zip(case.runs, st["onset"])}
        if kind == "gain":
            st["params"]["gain"] = 1 + st["sign"] * v
            st["recover"]["gain"] = 1 + st["sign"] * v
        elif kind not in ("stuck", "dead"):
            key = {"biased": "bias_cp", "drifting": "drift_cp_per_run_length", "noise": "noise_rms_cp"}.get(kind, "spike_cp")
            st["params"][key] = st["sign"] * v if kind != "noise" else v
            st["recover"]["gain"] = st["params"][key]


# ---------------------------------------------------------------------------------------------
# Outside the vocabulary.


class QFluctuation:
    """The dynamic pressure fluctuates, q(t) = q (1 + eps(t)), while the recorded tunnel speed
    stays constant: every aerodynamic moment (and, in half the cases, every Cp) scales by
    1 + eps: eps an Ornstein-Uhlenbeck process (tau 0.3-5 s) | slow surges (1-3 sines,
    0.05-1.5 Hz) plus a little OU noise."""

    name, stream = "q_fluctuation", "cl"
    forms = ["ou", "surge"]

    def setup(self, rng, case, form):
        dt = 1.0 / case.rig.hz
        tau = lu(rng, 0.3, 5.0)
        a = math.exp(-dt / tau)
        st = {"form": form, "params": {"tau_s": tau}, "calib": ("linear", "eps_rms"),
              "cp_scaled": bool(rng.random() < 0.5)}
        shapes = []
        freqs = rng.uniform(0.05, 1.5, int(rng.integers(1, 4)))
        for run in case.runs:
            w = rng.normal(0, math.sqrt(1 - a * a), run["n"])
            ou = signal.lfilter([1.0], [1.0, -a], w, zi=[a * rng.normal()])[0]
            if form == "surge":
                s = sum(rng.uniform(0.5, 1.0) * np.sin(2 * np.pi * f * run["t"] + rng.uniform(0, 2 * np.pi)) for f in freqs)
                ou = s / np.sqrt(np.mean(s**2)) + 0.3 * ou
            shapes.append(ou)
        rms = math.sqrt(np.mean(np.concatenate(shapes) ** 2))
        st["shapes"] = [s / rms for s in shapes]
        if form == "surge":
            st["params"].update({f"surge_hz_{i + 1}": float(f) for i, f in enumerate(freqs)})
        st["params"]["cp_scaled"] = 1.0 if st["cp_scaled"] else 0.0
        return st

    def contrib(self, case, st, v, cp):
        out = []
        for run, shp in zip(case.runs, st["shapes"]):
            eps = v * shp
            dcp = eps * run["cp"] if cp and st["cp_scaled"] else None
            out.append((eps * run["cl"], dcp))
        return out

    def finish(self, st, v, case):
        st["params"]["eps_rms"] = v
        st["recover"] = {"gain": v}


class CubicStiffness:
    """A roll moment cubic in the roll angle (a structural spring across the balance, or an
    aerodynamic one growing with alpha), or a cubic spring of the balance itself (the gauge
    reading M - k3 M^3)."""

    name, stream = "cubic_stiffness", "cl"
    forms = ["structural_phi3", "aero_phi3", "balance_cubic_spring"]

    def setup(self, rng, case, form):
        return {"form": form, "sign": sign(rng, 0.3), "params": {}, "calib": ("linear", "k")}

    def contrib(self, case, st, v, cp):
        rig = case.rig
        amax = max(case.alphas)
        out = []
        for run in case.runs:
            if st["form"] == "balance_cubic_spring":
                m = run["cl"] * rig.qsb
                out.append((-st["sign"] * v * m**3 / rig.qsb, None))
                continue
            if not rolls(run):
                out.append((None, None))
                continue
            phi3 = run["phi"] ** 3
            if st["form"] == "structural_phi3":
                out.append((-st["sign"] * v * phi3 / rig.qsb, None))  # k in N m / rad^3
            else:
                w = math.sin(math.radians(run["alpha"])) / math.sin(math.radians(amax)) if amax > 0 else 0.0
                out.append((-st["sign"] * v * w * phi3, None))  # k in C_l / rad^3
        return out

    def finish(self, st, v, case):
        key = {"structural_phi3": "k_nm_per_rad3", "aero_phi3": "k_cl_per_rad3", "balance_cubic_spring": "k3_per_nm2"}[st["form"]]
        st["params"][key] = st["sign"] * v  # positive: restoring (or softening for the balance)
        st["recover"] = {"gain": st["sign"] * v}


class RigTone:
    """A tone from the rig (a fan, a pump, the drive) in the balance moment: A sin(2 pi f t +
    theta_r), f 5-min(150, 0.3 fs) Hz, theta per run | the same with 1-2 harmonics (0.2-0.7 x
    each) | a tone whose frequency wanders slowly (+-1-5 % at 0.02-0.2 Hz)."""

    name, stream = "rig_tone", "cl"
    forms = ["pure", "harmonics", "wandering"]

    def setup(self, rng, case, form):
        f = lu(rng, 5.0, min(150.0, 0.3 * case.rig.hz))
        st = {"form": form, "f": f, "params": {"freq_hz": f}, "calib": ("linear", "amp_cl")}
        harm = [(1, 1.0)]
        if form == "harmonics":
            harm += [(k, float(rng.uniform(0.2, 0.7))) for k in range(2, 2 + int(rng.integers(1, 3)))
                     if k * f < 0.4 * case.rig.hz]
        dev, fm = (float(rng.uniform(0.01, 0.05)), float(rng.uniform(0.02, 0.2))) if form == "wandering" else (0.0, 0.0)
        shapes = []
        for run in case.runs:
            t = run["t"]
            ph = 2 * np.pi * f * t
            if dev:
                ph = ph + dev * f / fm * (1 - np.cos(2 * np.pi * fm * t))
            th = rng.uniform(0, 2 * np.pi)
            shapes.append(sum(a * np.sin(k * (ph + th)) for k, a in harm))
        rms = math.sqrt(np.mean(np.concatenate(shapes) ** 2))
        st["shapes"] = [s / rms for s in shapes]
        st["params"].update({"harmonics": len(harm), "wander_frac": dev, "wander_hz": fm})
        return st

    def contrib(self, case, st, v, cp):
        return [(v * s, None) for s in st["shapes"]]

    def finish(self, st, v, case):
        st["params"]["amp_rms_cl"] = v
        st["recover"] = {"freq_hz": st["f"], "gain": v}


def backlash(x, width):
    """A play operator: the output follows x only once x has moved width/2 beyond it."""
    y = np.empty_like(x)
    h = width / 2
    prev = x[0]
    for k in range(len(x)):
        prev = min(max(prev, x[k] - h), x[k] + h)
        y[k] = prev
    return y


class Encoder:
    """The roll encoder's reading differs from the angle: a play (backlash) of width b in the
    encoder's drive | a coarse quantisation of q; b or q bisected in 0.02-5 deg. Written into
    the recorded phi; its size is that of the moment gap it makes: the plant's roll moment
    at the reading minus at the true angle (the true rate kept), in the rolling runs."""

    name, stream = "encoder", "cl"
    forms = ["backlash", "quantisation"]

    def setup(self, rng, case, form):
        return {"form": form, "params": {}, "offset": float(rng.uniform(0, 1)),
                "calib": ("bisect", "width_deg", 0.02, 5.0, False)}

    def _reading(self, st, phi, v):
        w = math.radians(v)
        if st["form"] == "backlash":
            return backlash(phi, w)
        return (np.round(phi / w - st["offset"]) + st["offset"]) * w

    def contrib(self, case, st, v, cp):
        out = []
        for run in case.runs:
            if not rolls(run):
                out.append((None, None))
                continue
            phi2 = self._reading(st, run["phi"], v)
            fl2 = tunnel.flow(case.rig, run["alpha"], phi2, run["p"])
            out.append((fl2["cl_roll"] - run["fl"]["cl_roll"], None, phi2 - run["phi"]))
        return out

    def finish(self, st, v, case):
        st["params"]["width_deg"] = v
        st["recover"] = {"width_deg": v}


class BalanceSaturation:
    """The balance saturates: its reading of the moment M (noise-free, all runs) is clipped at
    +-M_s (hard) or M_s tanh(M / M_s) (soft), M_s = (1 - depth) max |M| over the case's runs,
    depth bisected in 0.005-0.9."""

    name, stream = "balance_saturation", "cl"
    forms = ["hard_clip", "soft_tanh"]

    def setup(self, rng, case, form):
        mmax = max(float(np.max(np.abs(r["cl"]))) for r in case.runs)
        return {"form": form, "mmax": mmax, "params": {}, "calib": ("bisect", "depth", 0.005, 0.9, False)}

    def contrib(self, case, st, v, cp):
        ms = (1 - v) * st["mmax"]
        out = []
        for run in case.runs:
            m = run["cl"]
            y = np.clip(m, -ms, ms) if st["form"] == "hard_clip" else ms * np.tanh(m / ms)
            out.append((y - m, None))
        return out

    def finish(self, st, v, case):
        ms = (1 - v) * st["mmax"]
        st["params"].update({"depth": v, "limit_cl": ms, "limit_nm": ms * case.rig.qsb})
        st["recover"] = {"limit_nm": ms * case.rig.qsb}


EFFECTS = {e.name: e for e in [ActuatorDelay(), ActuatorLag(), InertialTare(), GravityTare(), RollDamping(),
                               VortexLag(), Coupling(), PressureLag(), PressureFault(), BalanceResonance(),
                               BiasDrift(), QFluctuation(), CubicStiffness(), RigTone(), Encoder(),
                               BalanceSaturation()]}
# The classes outside the diagnosis vocabulary (the contract's table): a diagnosis should call
# them `unattributed`.
OUTSIDE = ("q_fluctuation", "cubic_stiffness", "rig_tone", "encoder", "balance_saturation")


# ---------------------------------------------------------------------------------------------
# Size of a contribution, and calibration.


def stream_ratio(case, contribs, stream, channels=None):
    """RMS of the contribution over the runs it acts on (and its channels), over the stream's
    noise RMS. A run counts as acted on when its contribution's RMS is at least 10 % of the
    largest run's. Returns (ratio, acting run indices, {channel: ratio})."""
    rig = case.rig
    if stream == "cl":
        ds = [d[0] for d in contribs]
        ms = np.array([np.mean(d**2) if d is not None else 0.0 for d in ds])
        sig2 = rig.cl_noise_rms**2
    else:
        ds = [d[1][channels] if d[1] is not None else None for d in contribs]
        # A missing reading (NaN: a dead channel) counts as an infinite contribution.
        ms = np.array([(np.inf if np.isnan(d).any() else np.mean(d**2)) if d is not None else 0.0 for d in ds])
        sig2 = float(np.mean(rig.cp_noise[channels] ** 2))
    if ms.max() <= 0:
        return 0.0, [], {}
    acting = [i for i, m in enumerate(ms) if m >= 0.01 * ms.max()]  # RMS >= 10 % of the largest
    ratio = math.sqrt(np.mean(ms[acting]) / sig2)
    chans = {}
    if stream == "cp":
        for j, c in enumerate(channels):
            m = np.mean([np.inf if np.isnan(ds[i][j]).any() else np.mean(ds[i][j] ** 2) for i in acting])
            chans[CHANNELS[c]] = math.sqrt(m) / rig.cp_noise[c]
    return ratio, acting, chans


def calibrate(effect, case, st, target):
    """The calibrated parameter's value reaching `target` (or the nearest in its range)."""
    stream, chans = effect.stream, st.get("channels")
    ratio = lambda v: stream_ratio(case, effect.contrib(case, st, v, False), stream, chans)[0]
    spec = st["calib"]
    if spec[0] == "none":
        return 0.0
    if spec[0] == "linear":
        r1 = ratio(1.0)
        if r1 <= 0:
            raise ValueError("the effect has no contribution")
        return target / r1
    _, _, lo, hi, integer = spec
    if integer:
        lo, hi = math.ceil(lo), math.floor(hi)
    rlo, rhi = ratio(lo), ratio(hi)
    if target <= rlo:
        return lo
    if target >= rhi:
        return hi
    for _ in range(40):
        if integer and hi - lo <= 1:
            break
        mid = round((lo + hi) / 2) if integer else 0.5 * (lo + hi)
        rm = ratio(mid)
        if rm < target:
            lo, rlo = mid, rm
        else:
            hi, rhi = mid, rm
        if not integer and hi - lo < 1e-4 * hi:
            break
    return lo if abs(rlo - target) <= abs(rhi - target) else hi
