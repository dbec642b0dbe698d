"""Effects injected by the foreign tunnel's blind campaigns (campaign.py), each in several
forms, as noise-free contributions added to a case's clean signals.

Every effect class has `setup(rng, case)`, which draws a form, its fixed parameters, the
random shapes it needs per run and a calibration spec, and `contrib(case, st, v, cp)`, which
returns per run the contribution (dcl, dcp) (either None when zero) for the calibrated
parameter value `v`. `calibrate` then scales `v` to the case's target ratio (see
campaign.py's docstring for the definitions).
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


# ---------------------------------------------------------------------------------------------
# Plant effects: the effective Cmu is changed, and with it the jet, the coupling and the taps.


def _replant(case, run, cmu2, cp):
    rig = case.rig
    jet2, coup2 = tunnel.actuation(rig, run["fl"], cmu2)
    dcl = (jet2 + coup2) - (run["jet"] + run["coup"])
    dcp = tunnel.taps(rig, run["fl"], cmu2) - run["cp"] if cp else None
    return dcl, dcp


def fractional_delay(x, d_samples, method):
    """x delayed by d_samples (> 1): 'linear' interpolation or 4-point cubic 'lagrange'."""
    m = int(math.floor(d_samples))
    f = d_samples - m
    if method == "linear":
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


class ActuatorDelay:
    name, stream = "actuator_delay", "cl"
    forms = ["integer", "fractional_linear", "fractional_lagrange"]

    def setup(self, rng, case):
        form = str(rng.choice(self.forms))
        return {"form": form, "params": {}, "calib": ("bisect", "delay_ms", 15.0, 120.0, form == "integer")}

    def contrib(self, case, st, v, cp):
        hz = case.rig.hz
        out = []
        for run in case.runs:
            if not blows(run):
                out.append((None, None))
                continue
            d = v / 1000.0 * hz
            if st["form"] == "integer":
                cmu2 = tunnel.delay_samples(run["cmu_eff"], int(round(d)))
            else:
                cmu2 = fractional_delay(run["cmu_eff"], d, st["form"].split("_")[1])
            out.append(_replant(case, run, cmu2, cp))
        return out

    def finish(self, st, v, case):
        st["params"]["delay_ms"] = float(v)


class ActuatorLag:
    name, stream = "actuator_lag", "cl"
    forms = ["first_order", "second_order_critical", "second_order_overdamped"]

    def setup(self, rng, case):
        order = str(rng.choice(self.forms))
        disc = str(rng.choice(["zoh", "tustin"]))
        ratio = 1.0 if order == "second_order_critical" else float(rng.uniform(0.25, 0.7))
        return {"form": f"{order}/{disc}", "order": order, "disc": disc, "tau_ratio": ratio,
                "params": {} if order == "first_order" else {"tau2_over_tau": ratio},
                "calib": ("bisect", "tau_ms", 15.0, 150.0, False)}

    def contrib(self, case, st, v, cp):
        dt = 1.0 / case.rig.hz
        tau = v / 1000.0
        if st["order"] == "first_order":
            den = [tau, 1.0]
        else:
            tau2 = tau * st["tau_ratio"]
            den = [tau * tau2, tau + tau2, 1.0]
        b, a = tunnel.c2d([1.0], den, dt, st["disc"])
        out = []
        for run in case.runs:
            if not blows(run):
                out.append((None, None))
                continue
            cmu2 = signal.lfilter(b, a, run["cmu_eff"])
            out.append(_replant(case, run, cmu2, cp))
        return out

    def finish(self, st, v, case):
        st["params"]["tau_ms"] = float(v)
        if st["order"] != "first_order":
            st["params"]["tau2_ms"] = float(v) * st["tau_ratio"]


class Coupling:
    """An interaction present only when the wing rolls and the jet blows."""

    name, stream = "coupling", "cl"
    forms = ["cmu_x_rate", "cmu_x_sinphi", "sqrtcmu_x_beta", "jet_x_flowstate", "lagged_cmu_x_rate"]

    def setup(self, rng, case):
        form = str(rng.choice(self.forms))
        st = {"form": form, "sign": sign(rng), "params": {}, "calib": ("linear", "gain")}
        if form == "lagged_cmu_x_rate":
            st["tau"] = lu(rng, 0.03, 0.2)
            st["params"]["tau_ms"] = st["tau"] * 1000
        return st

    def contrib(self, case, st, v, cp):
        rig = case.rig
        k = st["sign"] * v
        out = []
        for run in case.runs:
            if run["kind"] != "roll+actuation":
                out.append((None, None))
                continue
            fl = run["fl"]
            c = np.maximum(run["cmu_eff"], 0) / rig.cmu_max
            form = st["form"]
            if form == "cmu_x_rate":
                d = c * fl["p_hat"]
            elif form == "cmu_x_sinphi":
                d = c * np.sin(fl["phi"])
            elif form == "sqrtcmu_x_beta":
                d = np.sqrt(c) * fl["beta"]
            elif form == "jet_x_flowstate":
                d = run["jet"] / rig.jet_gain * (fl["l_port"] - fl["l_stbd"])
            else:
                d = tunnel.lag(c * fl["p_hat"], 1.0 / rig.hz, st["tau"], "zoh")
            out.append((k * d, None))
        return out

    def finish(self, st, v, case):
        st["params"]["gain"] = st["sign"] * v


# ---------------------------------------------------------------------------------------------
# Disturbance effects (aerodynamic, in C_l).


class RollDamping:
    name, stream = "roll_damping", "cl"
    forms = ["linear", "alpha_growing", "quadratic"]

    def setup(self, rng, case):
        form = str(rng.choice(self.forms))
        st = {"form": form, "sign": sign(rng, 0.2), "params": {}, "calib": ("linear", "clp_extra")}
        if form == "alpha_growing":
            st["g"] = float(rng.uniform(1.0, 4.0))
            st["params"]["alpha_gain_per_20deg"] = st["g"]
        if form == "quadratic":
            st["calib"] = ("linear", "clpp_extra")
        return st

    def contrib(self, case, st, v, cp):
        out = []
        for run in case.runs:
            if not rolls(run):
                out.append((None, None))
                continue
            ph = run["fl"]["p_hat"]
            if st["form"] == "linear":
                d = ph
            elif st["form"] == "alpha_growing":
                d = (1.0 + st["g"] * run["alpha"] / 20.0) * ph
            else:
                d = ph * np.abs(ph)
            # A positive sign is damping (a moment against the roll rate).
            out.append((-st["sign"] * v * d, None))
        return out

    def finish(self, st, v, case):
        st["params"][st["calib"][1]] = -st["sign"] * v  # the C_l derivative added, signed


class VortexLag:
    """A second, slower flow state x: tau x' + x = u(driver); moment K x (state) or
    K (x - u) (deficit), weighted over alpha; with or without an imprint on some taps."""

    name, stream = "vortex_lag", "cl"
    drivers = ["beta", "phi", "rate", "lift"]

    def setup(self, rng, case):
        driver = str(rng.choice(self.drivers))
        output = str(rng.choice(["state", "deficit"]))
        weight = str(rng.choice(["all", "growing", "high_only"]))
        st = {"form": f"{driver}/{output}/{weight}", "driver": driver, "output": output, "weight": weight,
              "tau": lu(rng, 0.2, 3.0), "sign": sign(rng), "calib": ("linear", "gain")}
        st["params"] = {"tau_s": st["tau"]}
        st["imprint"] = rng.random() < 0.5
        if st["imprint"]:
            chans = rng.permutation(12)[: int(rng.integers(3, 7))]
            st["tap_channels"] = sorted(int(c) for c in chans)
            st["tap_gains"] = rng.normal(0, 1, len(chans))
            st["tap_ratio"] = float(rng.uniform(0.3, 1.5))
        return st

    def _driver(self, st, run):
        fl = run["fl"]
        return {"beta": fl["beta"], "phi": np.sin(fl["phi"]), "rate": fl["p_hat"],
                "lift": fl["l_port"] - fl["l_stbd"]}[st["driver"]]

    def _weight(self, st, case, alpha):
        amax = max(case.alphas)
        if st["weight"] == "all" or amax <= 0:
            return 1.0
        if st["weight"] == "growing":
            return (alpha / amax) ** 2
        return 1.0 if alpha == amax else 0.0

    def contrib(self, case, st, v, cp):
        out = []
        for run in case.runs:
            w = self._weight(st, case, run["alpha"])
            if not rolls(run) or w == 0.0:
                out.append((None, None))
                continue
            u = self._driver(st, run)
            x = tunnel.lag(u, 1.0 / case.rig.hz, st["tau"], "zoh")
            m = x if st["output"] == "state" else x - u
            dcl = st["sign"] * v * w * m
            dcp = None
            if cp and st["imprint"] and st.get("tap_scale"):
                dcp = np.zeros((12, run["n"]))
                for c, g in zip(st["tap_channels"], st["tap_gains"]):
                    dcp[c] = st["tap_scale"] * g * dcl
            out.append((dcl, dcp))
        return out

    def finish(self, st, v, case):
        st["params"]["gain"] = st["sign"] * v
        st["params"]["tap_imprint_ratio"] = 0.0
        if st["imprint"]:
            # Scale the taps' imprint to its drawn ratio to the Cp noise over its channels.
            st["tap_scale"] = 1.0
            cs = st["tap_channels"]
            contribs = self.contrib(case, st, v, True)
            r = stream_ratio(case, contribs, "cp", cs)[0]
            st["tap_scale"] = st["tap_ratio"] / r if r > 0 else 0.0
            st["params"]["tap_imprint_ratio"] = st["tap_ratio"]


# ---------------------------------------------------------------------------------------------
# Balance effects (in the balance's moment; C_l units here).


class InertialTare:
    name, stream = "inertial_tare", "cl"
    forms = ["constant", "per_run", "filtered"]

    def setup(self, rng, case):
        form = str(rng.choice(self.forms))
        st = {"form": form, "sign": sign(rng, 0.7), "params": {}, "calib": ("linear", "ixx_extra_kgm2")}
        st["spread"] = rng.uniform(-0.15, 0.15, len(case.runs)) if form == "per_run" else np.zeros(len(case.runs))
        if form == "per_run":
            st["params"]["per_run_spread_max"] = float(np.max(np.abs(st["spread"])))
        if form == "filtered":
            st["fc"] = float(rng.uniform(15.0, 60.0))
            st["params"]["filter_hz"] = st["fc"]
        return st

    def contrib(self, case, st, v, cp):
        rig = case.rig
        out = []
        for i, run in enumerate(case.runs):
            if not rolls(run):
                out.append((None, None))
                continue
            acc = run["pdot"]
            if st["form"] == "filtered":
                b, a = signal.butter(2, st["fc"], fs=rig.hz)
                acc = signal.lfilter(b, a, acc)
            ixx = st["sign"] * v * rig.ixx * (1.0 + st["spread"][i])
            out.append((ixx * acc / rig.qsb, None))
        return out

    def finish(self, st, v, case):
        st["params"]["ixx_extra_kgm2"] = st["sign"] * v * case.rig.ixx


class GravityTare:
    """m g (d_sin sin(phi) + d_cos (cos(phi) - 1)): a centre of gravity off the roll axis,
    the moment at phi = 0 tared."""

    name, stream = "gravity_tare", "cl"
    forms = ["sin", "sin_cos"]

    def setup(self, rng, case):
        form = str(rng.choice(self.forms))
        cos_ratio = float(rng.uniform(0.5, 3.0)) * sign(rng) if form == "sin_cos" else 0.0
        return {"form": form, "sign": sign(rng), "cos_ratio": cos_ratio, "params": {},
                "calib": ("linear", "d_sin_m")}

    def contrib(self, case, st, v, cp):
        rig = case.rig
        out = []
        for run in case.runs:
            if not rolls(run):
                out.append((None, None))
                continue
            phi = run["phi"]
            d_sin = st["sign"] * v * 1e-3
            m = rig.mass * 9.81 * (d_sin * np.sin(phi) + d_sin * st["cos_ratio"] * (np.cos(phi) - 1.0))
            out.append((m / rig.qsb, None))
        return out

    def finish(self, st, v, case):
        d_sin = st["sign"] * v * 1e-3
        st["params"].update({"mass_kg": case.rig.mass, "d_sin_m": d_sin, "d_cos_m": d_sin * st["cos_ratio"],
                             "mgd_sin_nm": case.rig.mass * 9.81 * d_sin})


class BalanceResonance:
    """A lightly damped mode H = wn^2/(s^2 + 2 zeta wn s + wn^2) between the load and the
    gauges: the balance reads H applied to its input instead of the input, the added part
    gain x (H - 1) u, u = the roll-acceleration reaction, the aerodynamic moment, or both."""

    name, stream = "balance_resonance", "cl"
    forms = ["roll_accel", "aero_moment", "base_and_aero"]

    def setup(self, rng, case):
        form = str(rng.choice(self.forms))
        st = {"form": form, "f": lu(rng, 4.0, 40.0), "zeta": lu(rng, 0.005, 0.1),
              "disc": str(rng.choice(["zoh", "tustin"])), "calib": ("linear", "modal_gain")}
        st["form"] = f"{form}/{st['disc']}"
        st["kind"] = form
        st["params"] = {"f_hz": st["f"], "zeta": st["zeta"]}
        return st

    def contrib(self, case, st, v, cp):
        rig = case.rig
        wn = 2 * np.pi * st["f"]
        b, a = tunnel.c2d([-1.0, -2 * st["zeta"] * wn, 0.0], [1.0, 2 * st["zeta"] * wn, wn * wn], 1.0 / rig.hz, st["disc"])
        out = []
        for run in case.runs:
            inertial = -rig.ixx * run["pdot"] / rig.qsb
            u = {"roll_accel": inertial, "aero_moment": run["cl"], "base_and_aero": run["cl"] + inertial}[st["kind"]]
            if not np.any(u):
                out.append((None, None))
                continue
            out.append((v * tunnel._filter(b, a, u, True), None))
        return out

    def finish(self, st, v, case):
        st["params"]["modal_gain"] = v


class BiasDrift:
    name, stream = "bias_drift", "cl"
    forms = ["ramp", "poly", "walk_trend"]

    def setup(self, rng, case):
        form = str(rng.choice(self.forms))
        s = sign(rng)
        shapes = []
        for run in case.runs:
            tau = run["t"] / run["t"][-1]
            if form == "ramp":
                shp = s * rng.uniform(0.5, 1.5) * tau
            elif form == "poly":
                c = rng.normal(0, 1, 3)
                c[0] = s * abs(c[0]) + s
                shp = c[0] * tau + c[1] * tau**2 + c[2] * tau**3
                shp /= np.max(np.abs(shp))
            else:
                dt = 1.0 / case.rig.hz
                walk = np.cumsum(rng.normal(0, math.sqrt(dt), run["n"])) / math.sqrt(run["t"][-1])
                shp = walk + s * rng.uniform(0.3, 1.2) * tau
            shapes.append(shp)
        return {"form": form, "shapes": shapes, "params": {}, "calib": ("linear", "drift_cl")}

    def contrib(self, case, st, v, cp):
        return [(v * shp, None) for shp in st["shapes"]]

    def finish(self, st, v, case):
        st["params"].update({"drift_cl": v, "drift_nm": v * case.rig.qsb})


# ---------------------------------------------------------------------------------------------
# Sensor effects (pressure channels).


class PressureLag:
    name, stream = "pressure_lag", "cp"
    forms = ["all_shared", "group_shared", "group_own", "one"]

    def setup(self, rng, case):
        form = str(rng.choice(self.forms))
        disc = str(rng.choice(["zoh", "tustin"]))
        if form == "all_shared":
            chans = list(range(12))
        elif form == "one":
            chans = [int(rng.integers(0, 12))]
        else:
            chans = sorted(int(c) for c in rng.permutation(12)[: int(rng.integers(3, 7))])
        rel = rng.uniform(0.5, 1.0, len(chans)) if form == "group_own" else np.ones(len(chans))
        rel = rel / rel.max()
        return {"form": f"{form}/{disc}", "disc": disc, "channels": chans, "rel": rel, "params": {},
                "calib": ("bisect", "tau_ms", 20.0 / rel.min(), 100.0, False)}

    def contrib(self, case, st, v, cp):
        dt = 1.0 / case.rig.hz
        out = []
        for run in case.runs:
            dcp = np.zeros((12, run["n"]))
            for c, r in zip(st["channels"], st["rel"]):
                dcp[c] = tunnel.lag(run["cp"][c], dt, v / 1000.0 * r, st["disc"]) - run["cp"][c]
            out.append((None, dcp))
        return out

    def finish(self, st, v, case):
        st["params"]["tau_ms"] = v
        if len(st["channels"]) > 1 and np.ptp(st["rel"]) > 0:
            for c, r in zip(st["channels"], st["rel"]):
                st["params"][f"tau_{CHANNELS[c]}_ms"] = v * r


class PressureFault:
    name, stream = "pressure_fault", "cp"
    forms = ["stuck", "dead_zero", "dead_ambient", "bias_step", "spikes"]

    def setup(self, rng, case):
        form = str(rng.choice(self.forms))
        ch = int(rng.integers(0, 12))
        st = {"form": form, "channels": [ch], "params": {}}
        T = case.duration
        if form in ("stuck", "dead_zero", "dead_ambient"):
            # Per run: the fault lasts u_r x the calibrated duration, placed at w_r of the room left.
            st["u"] = rng.uniform(0.8, 1.0, len(case.runs))
            st["w"] = rng.uniform(0.0, 1.0, len(case.runs))
            st["value"] = 0.0 if form == "dead_zero" else float(rng.uniform(0.5, 1.0))
            st["calib"] = ("bisect", "duration_s", 1.0, T - 1.0, False)
            if form == "dead_ambient":
                st["params"]["reads_cp"] = st["value"]
        elif form == "bias_step":
            s = sign(rng)
            st["onsets"] = rng.uniform(1.0, T - 2.0, len(case.runs))
            st["biases"] = s * rng.uniform(0.5, 1.5, len(case.runs))
            st["calib"] = ("linear", "bias_cp")
        else:
            rate = float(rng.uniform(0.3, 3.0))
            st["params"]["burst_rate_hz"] = rate
            shapes = []
            for run in case.runs:
                shp = np.zeros(run["n"])
                for _ in range(rng.poisson(rate * T)):
                    k = int(rng.integers(0, run["n"] - 5))
                    shp[k : k + int(rng.integers(1, 6))] += sign(rng) * rng.uniform(0.5, 1.5)
                shapes.append(shp)
            st["shapes"] = shapes
            st["calib"] = ("linear", "spike_cp")
        return st

    def contrib(self, case, st, v, cp):
        ch = st["channels"][0]
        out = []
        for i, run in enumerate(case.runs):
            dcp = np.zeros((12, run["n"]))
            x = run["cp"][ch]
            if st["form"] in ("stuck", "dead_zero", "dead_ambient"):
                length = v * st["u"][i]
                k0 = int(st["w"][i] * max(0.0, case.duration - length) * case.rig.hz)
                k1 = min(run["n"], k0 + int(round(length * case.rig.hz)))
                held = x[k0] if st["form"] == "stuck" else st["value"]
                dcp[ch, k0:k1] = held - x[k0:k1]
            elif st["form"] == "bias_step":
                dcp[ch] = v * st["biases"][i] * (run["t"] >= st["onsets"][i])
            else:
                dcp[ch] = v * st["shapes"][i]
            out.append((None, dcp))
        return out

    def finish(self, st, v, case):
        st["params"][st["calib"][1]] = v


# ---------------------------------------------------------------------------------------------
# Outside the vocabulary.


class QFluctuation:
    """The dynamic pressure fluctuates, q(t) = q (1 + eps(t)), while the recorded tunnel speed
    stays constant: every aerodynamic moment (and, when the taps are referenced to the
    nominal q, every Cp) scales by 1 + eps."""

    name, stream = "q_fluctuation", "cl"
    forms = ["ou", "surge"]

    def setup(self, rng, case):
        form = str(rng.choice(self.forms))
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


class CubicStiffness:
    """A roll moment cubic in the roll angle (a structural spring across the balance, or an
    aerodynamic one growing with alpha), or a cubic spring of the balance itself."""

    name, stream = "cubic_stiffness", "cl"
    forms = ["structural_phi3", "aero_phi3", "balance_cubic_spring"]

    def setup(self, rng, case):
        form = str(rng.choice(self.forms))
        return {"form": form, "sign": sign(rng, 0.3), "params": {}, "calib": ("linear", "k")}

    def contrib(self, case, st, v, cp):
        rig = case.rig
        amax = max(case.alphas)
        out = []
        for run in case.runs:
            if st["form"] == "balance_cubic_spring":
                # Gauge reads M - k3 M^3 (M in N m).
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


EFFECTS = {e.name: e for e in [ActuatorDelay(), ActuatorLag(), InertialTare(), GravityTare(), RollDamping(),
                               VortexLag(), Coupling(), PressureLag(), PressureFault(), BalanceResonance(),
                               BiasDrift(), QFluctuation(), CubicStiffness()]}


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
        ms = np.array([np.mean(d**2) if d is not None else 0.0 for d in ds])
        sig2 = float(np.mean(rig.cp_noise[channels] ** 2))
    if ms.max() <= 0:
        return 0.0, [], {}
    acting = [i for i, m in enumerate(ms) if m >= 0.01 * ms.max()]  # RMS >= 10 % of the largest
    ratio = math.sqrt(np.mean(ms[acting]) / sig2)
    chans = {}
    if stream == "cp":
        for j, c in enumerate(channels):
            m = np.mean([np.mean(ds[i][j] ** 2) for i in acting])
            chans[CHANNELS[c]] = math.sqrt(m) / rig.cp_noise[c]
    return ratio, acting, chans


def calibrate(effect, case, st, target):
    """The calibrated parameter's value reaching `target` (or the nearest in its range)."""
    stream, chans = effect.stream, st.get("channels")
    ratio = lambda v: stream_ratio(case, effect.contrib(case, st, v, False), stream, chans)[0]
    spec = st["calib"]
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
