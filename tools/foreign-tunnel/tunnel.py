"""Physics of the second, independent wind tunnel, shared by foreign_tunnel.py (single
recordings) and campaign.py (blind diagnosis campaigns).

Written from the physical definitions only (docs/spec and the references it cites), apart from
firmware-sim and the diagnosis. Everything here is noise-free except the explicit noise
draws; the effects of effects.py are added as contributions on top of these signals.

The rig (`Rig`): a forced-roll delta wing on a balance, a port trailing-edge jet (and, in the
rigs `Rig.random` draws, a mirrored starboard jet with its own blowing), 12 upper-surface
taps.
- Flow: each half-wing's effective incidence (body-axis roll kinematics, sideslip and
  roll-rate terms) drives a logistic static lift-loss curve through a second-order lift
  response; the roll moment is the lift asymmetry plus sideslip, linear and quadratic
  roll-rate terms.
- Jet: a pneumatic transport delay, a power-law gain falling with alpha, a second-order
  underdamped response; a bilinear blowing x roll-rate and blowing x sin(phi) coupling.
- Taps: a linear mix of (beta, p_hat, both lift states, Cmu, 1), its gains partly growing
  with sin(alpha) (the vortex suction), through a short tube lag. The original rig's mix is
  unstructured; `Rig.random` draws upper-surface taps with physical signs.
- Balance: AR(1) noise, recorded as the raw moment `mx_nm`.
"""

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

HZ = 1000.0


def legacy_taps_gain():
    """The taps' sensitivities of the original foreign tunnel (fixed seed 1234)."""
    g = np.random.default_rng(1234).normal(0, 1, (12, 6)) * np.array([0.3, 0.5, 0.4, 0.4, 0.05, 0.2])
    g[:6, 2] *= 2.5
    g[6:, 3] *= 2.5
    g[:, 5] -= 0.5
    return g


@dataclass
class Rig:
    """Wing, tunnel, flow, jet, taps, noise and excitation of one rig. The defaults are the
    original foreign tunnel (foreign_tunnel.py); `Rig.random` draws another rig."""

    u_mps: float = 9.0
    rho: float = 1.18
    chord: float = 0.28
    span: float = 0.35
    area: float = 0.055
    ixx: float = 4.5e-4
    mass: float = 0.21
    hz: float = HZ
    # Balance noise: AR(1), e[k] = ar e[k-1] + N(0, cl_white), in C_l units.
    cl_white: float = 2.0e-4
    cl_ar: float = 0.3
    cp_noise: np.ndarray = field(default_factory=lambda: np.full(12, 0.006))
    cmu_noise: float = 1.5e-5
    phi_quantum_deg: float = 0.005
    # Flow: half-wing incidences a = a_b -/+ kb beta +/- kp p_hat (kp < 0: the descending
    # starboard wing sees more incidence; the original tunnel has kp > 0), logistic static lift loss
    # centred on a_star_deg with width a_width_deg, second-order lift states (f_v, zeta_v).
    kb: float = 0.9
    kp: float = 1.2
    a_star_deg: float = 22.0
    a_width_deg: float = 4.0
    f_v: float = 3.0
    zeta_v: float = 0.8
    c_v: float = 0.06  # C_l per unit lift asymmetry, times sin(2 alpha)
    c_beta: float = 0.00045  # -C_l per rad of sideslip per deg of alpha
    c_p: float = 0.21  # -C_l per unit p_hat
    c_pp: float = 0.6  # -C_l per unit p_hat |p_hat|
    # Jet: Cmu scale, pneumatic delay, gain (1 - a2 (alpha/20)^2) (Cmu/cmu_max)^power,
    # second-order response (f_j, zeta_j), sign of its moment.
    cmu_max: float = 0.008
    jet_delay_s: float = 0.006
    jet_gain: float = 0.011
    jet_gain_a2: float = 0.35
    jet_power: float = 0.6
    f_j: float = 9.0
    zeta_j: float = 0.55
    jet_sign: float = -1.0
    cc_rate: float = 0.045  # -C_l per unit (Cmu/cmu_max) p_hat
    cc_phi: float = 0.004  # C_l per unit (Cmu/cmu_max) sin(phi) sin(alpha)
    taps_gain: np.ndarray = field(default_factory=legacy_taps_gain)
    # Added to taps_gain in proportion to sin(alpha) / sin(20 deg) (vortex suction).
    taps_gain_alpha: np.ndarray = field(default_factory=lambda: np.zeros((12, 6)))
    tube_tau_s: float = 0.004
    # Excitation.
    roll_amp_deg: float = 25.0
    roll_f_lo: float = 0.3
    roll_f_hi: float = 2.5
    roll_count: int = 5
    blow_hold: tuple = (0.25, 1.2)
    blow_ramp_s: float = 0.025
    blow_zero_prob: float = 0.2
    ra_blow_start_s: float = 5.0
    a_blow_start_s: float = 0.5
    # Starboard jet (False: the original port-only rig): its moment is the port jet's mirrored,
    # ratio x as strong; its own blowing levels; its suction on the taps `taps_gain_stbd`.
    stbd_jet: bool = False
    stbd_gain_ratio: float = 1.0
    taps_gain_stbd: np.ndarray = field(default_factory=lambda: np.zeros(12))
    # File conventions.
    t0_s: float = 12.5
    nan_channel: int = 4
    nan_count: int = 30
    temperature_c: float = 21.5
    # False: the original tunnel's states start from zero (semi-implicit Euler lift and jet
    # responses); True: exact ZOH responses started at their steady state.
    settled: bool = False

    @property
    def q(self):
        return 0.5 * self.rho * self.u_mps**2

    @property
    def qsb(self):
        return self.q * self.area * self.span

    @property
    def cl_noise_rms(self):
        """Stationary RMS of the balance noise, C_l units."""
        return self.cl_white / math.sqrt(1.0 - self.cl_ar**2)

    @classmethod
    def random(cls, rng):
        """Another rig: geometry, tunnel speed, noise, taps, flow, jet and excitation drawn."""
        lu = lambda lo, hi: float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
        un = lambda lo, hi: float(rng.uniform(lo, hi))
        chord, span = un(0.22, 0.36), un(0.27, 0.42)
        area = chord * span * un(0.5, 0.6)
        mass = un(0.12, 0.30)
        ixx = mass * span**2 * un(0.015, 0.03)
        cl_rms, cl_ar = lu(3e-4, 1e-3), un(0.1, 0.5)
        cp_sigma = lu(0.004, 0.012) * rng.uniform(0.85, 1.15, 12)
        # Taps: six on each half-wing (random positions). Pressure coefficients of an upper
        # surface: a baseline suction, more suction under the own side's vortex (its lift
        # state) growing with alpha, the sideslip and roll rate raising the leeward / rising
        # side's Cp, the port jet's circulation adding suction on the port side.
        side = np.full(12, -1.0)
        side[rng.permutation(12)[:6]] = 1.0  # +1 port, -1 starboard
        port = side > 0
        g = np.zeros((12, 6))
        g[:, 0] = side * rng.uniform(0.1, 0.5, 12)
        g[:, 1] = side * rng.uniform(0.2, 0.8, 12)
        g[:, 4] = np.where(port, -rng.uniform(0.02, 0.1, 12), rng.uniform(-0.02, 0.02, 12))
        g[:, 5] = -rng.uniform(0.05, 0.35, 12)
        ga = np.zeros((12, 6))
        own = -rng.uniform(0.4, 1.4, 12)
        other = rng.uniform(-0.1, 0.1, 12)
        ga[:, 2] = np.where(port, own, other)
        ga[:, 3] = np.where(port, other, own)
        ga[:, 5] = -rng.uniform(0.1, 0.5, 12)
        hold_lo = un(0.2, 0.4)
        rig = cls(
            u_mps=round(un(7.0, 12.0), 2), rho=round(un(1.15, 1.22), 3),
            chord=round(chord, 4), span=round(span, 4), area=round(area, 5),
            ixx=float(f"{ixx:.4g}"), mass=round(mass, 4),
            cl_white=cl_rms * math.sqrt(1 - cl_ar**2), cl_ar=cl_ar, cp_noise=cp_sigma,
            cmu_noise=lu(0.8e-5, 3e-5), phi_quantum_deg=float(rng.choice([0.002, 0.005, 0.01])),
            kb=un(0.7, 1.3), kp=-un(0.8, 1.6), a_star_deg=un(18.0, 26.0), a_width_deg=un(3.0, 6.0),
            f_v=un(1.5, 5.0), zeta_v=un(0.6, 1.1), c_v=un(0.03, 0.09), c_beta=un(0.0002, 0.0007),
            c_p=un(0.12, 0.28), c_pp=un(0.2, 1.0),
            cmu_max=un(0.006, 0.010), jet_delay_s=un(0.003, 0.010), jet_gain=un(0.007, 0.016),
            jet_gain_a2=un(0.1, 0.5), jet_power=un(0.45, 0.85), f_j=un(5.0, 14.0), zeta_j=un(0.4, 0.9),
            jet_sign=float(rng.choice([-1.0, 1.0])), cc_rate=un(0.02, 0.07), cc_phi=un(0.002, 0.006),
            taps_gain=g, taps_gain_alpha=ga, tube_tau_s=un(0.002, 0.006),
            roll_amp_deg=un(18.0, 30.0), roll_f_lo=un(0.2, 0.4), roll_f_hi=un(1.8, 3.0),
            roll_count=int(rng.integers(4, 8)), blow_hold=(hold_lo, hold_lo + un(0.6, 1.2)),
            blow_ramp_s=un(0.015, 0.04), blow_zero_prob=un(0.15, 0.3), ra_blow_start_s=un(4.0, 8.0),
            a_blow_start_s=un(0.3, 1.0), t0_s=round(un(0.0, 100.0), 3), nan_channel=int(rng.integers(0, 12)),
            nan_count=int(rng.integers(5, 40)), temperature_c=round(un(15.0, 28.0), 1), settled=True,
        )
        # Drawn last, so the draws above are those of the port-only rigs.
        rig.stbd_jet = True
        rig.stbd_gain_ratio = un(0.8, 1.2)
        rig.taps_gain_stbd = np.where(port, rng.uniform(-0.02, 0.02, 12), -rng.uniform(0.02, 0.1, 12))
        return rig


# ---------------------------------------------------------------------------------------------
# Excitation (the original tunnel's: sums of sines faded in, random blowing levels).


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


def blowing(rng, n, dt, cmu_max, start_s, hold=(0.25, 1.2), ramp_s=0.025, zero_prob=0.2):
    """Random levels held hold[0] to hold[1] s, joined by ramps; off before `start_s`."""
    cmu = np.zeros(n)
    k = int(start_s / dt)
    level = 0.0
    while k < n:
        new = rng.uniform(0, cmu_max) if rng.random() > zero_prob else 0.0
        ramp = int(ramp_s / dt)
        hold_n = int(rng.uniform(hold[0], hold[1]) / dt)
        seg = np.concatenate([np.linspace(level, new, ramp, endpoint=False), np.full(hold_n, new)])
        cmu[k : k + len(seg)] = seg[: max(0, n - k)]
        k += len(seg)
        level = new
    return cmu


# ---------------------------------------------------------------------------------------------
# Linear filters (all vectorised through scipy.signal.lfilter).


def _filter(b, a, u, settled):
    b, a = np.atleast_1d(b).astype(float), np.atleast_1d(a).astype(float)
    if settled:
        zi = signal.lfilter_zi(b, a) * u[..., :1]
        return signal.lfilter(b, a, u, axis=-1, zi=zi)[0]
    return signal.lfilter(b, a, u, axis=-1)


def second_order_legacy(u, dt, wn, zeta):
    """y'' + 2 zeta wn y' + wn^2 y = wn^2 u by semi-implicit Euler, 4 substeps per sample,
    from rest, the input held over the sample (the original tunnel's integrator, as an
    exact linear recursion)."""
    h = dt / 4
    m = np.array([[1 - h * h * wn * wn, h * (1 - 2 * zeta * wn * h)], [-h * wn * wn, 1 - 2 * zeta * wn * h]])
    nvec = np.array([h * h * wn * wn, h * wn * wn])
    a = np.linalg.matrix_power(m, 4)
    b = sum(np.linalg.matrix_power(m, i) for i in range(4)) @ nvec
    c = np.array([1.0, 0.0])
    num, den = signal.ss2tf(a, b[:, None], (c @ a)[None, :], np.array([[c @ b]]))
    return signal.lfilter(num[0], den, u)


def c2d(num, den, dt, method="zoh"):
    """Discretise a continuous transfer function: 'zoh' (exact for held input), 'foh' (exact
    for a linearly interpolated input) or 'tustin' (bilinear)."""
    return _c2d(tuple(float(x) for x in num), tuple(float(x) for x in den), float(dt), method)


@functools.lru_cache(maxsize=4096)
def _c2d(num, den, dt, method):
    if len(den) == 2 and len(num) == 1 and method in ("zoh", "tustin"):
        # First-order lag k / (tau s + 1), in closed form.
        k, tau = num[0] / den[1], den[0] / den[1]
        if method == "tustin":
            c = 2 * tau / dt
            return np.array([k, k]) / (1 + c), np.array([1.0, (1 - c) / (1 + c)])
        a = math.exp(-dt / tau)
        return np.array([0.0, k * (1 - a)]), np.array([1.0, -a])
    if method == "tustin":
        b, a = signal.bilinear(num, den, fs=1.0 / dt)
    else:
        b, a, _ = signal.cont2discrete((num, den), dt, method=method)
        b = np.ravel(b)
    b = np.asarray(b, float)
    a = np.asarray(a, float)
    b[np.abs(b) < 1e-300] = 0.0
    return b / a[0], a / a[0]


def second_order(u, dt, wn, zeta, settled):
    if not settled:
        return second_order_legacy(u, dt, wn, zeta)
    b, a = c2d([wn * wn], [1.0, 2 * zeta * wn, wn * wn], dt)
    return _filter(b, a, u, True)


def first_order_legacy(u, dt, tau):
    """y[k] = a y[k-1] + (1-a) u[k], y[-1] = u[0] (the original tunnel's tube lag); rows of u."""
    a = math.exp(-dt / tau)
    return _filter([1 - a], [1.0, -a], u, True)


def lag(u, dt, tau, method="zoh", settled=True):
    """First-order lag 1/(tau s + 1): exact ZOH or Tustin (bilinear)."""
    b, a = c2d([1.0], [tau, 1.0], dt, method)
    return _filter(b, a, u, settled)


def delay_samples(u, d):
    """Integer delay, padded with the first value."""
    d = int(d)
    if d <= 0:
        return u.copy()
    return np.concatenate([np.full(d, u[0]), u[:-d]])


# ---------------------------------------------------------------------------------------------
# The plant (noise-free).


def flow(rig, alpha_deg, phi, p):
    """Flow states of a run: sideslip, reduced roll rate, lift states, the roll moment."""
    dt = 1.0 / rig.hz
    alpha = math.radians(alpha_deg)
    p_hat = p * rig.span / (2 * rig.u_mps)
    beta = np.arcsin(np.sin(alpha) * np.sin(phi))
    a_body = np.arctan(np.tan(alpha) * np.cos(phi))
    a_port = a_body - rig.kb * beta + rig.kp * p_hat
    a_stbd = a_body + rig.kb * beta - rig.kp * p_hat
    a_star, a_w = math.radians(rig.a_star_deg), math.radians(rig.a_width_deg)
    static = lambda a: 1.0 / (1.0 + np.exp((a - a_star) / a_w))
    wn = 2 * np.pi * rig.f_v
    l_port = second_order(static(a_port), dt, wn, rig.zeta_v, rig.settled)
    l_stbd = second_order(static(a_stbd), dt, wn, rig.zeta_v, rig.settled)
    cl_roll = (
        rig.c_v * math.sin(2 * alpha) * (l_port - l_stbd)
        - rig.c_beta * alpha_deg * beta
        - rig.c_p * p_hat
        - rig.c_pp * p_hat * np.abs(p_hat)
    )
    return {"alpha_deg": alpha_deg, "phi": phi, "p": p, "p_hat": p_hat, "beta": beta,
            "l_port": l_port, "l_stbd": l_stbd, "cl_roll": cl_roll}


def jet_gain(rig, alpha_deg):
    return rig.jet_gain * (1.0 - rig.jet_gain_a2 * (alpha_deg / 20.0) ** 2)


def actuation(rig, fl, cmu_eff, cmu_eff_s=None):
    """The jets' moment and the plant's own blowing-roll coupling for the effective Cmu of the
    port jet (and of the starboard jet, mirrored, when the rig has one)."""
    dt = 1.0 / rig.hz
    c = np.maximum(cmu_eff, 0.0) / rig.cmu_max
    gain = jet_gain(rig, fl["alpha_deg"])
    u = c**rig.jet_power
    cd = c
    if cmu_eff_s is not None:
        cs = np.maximum(cmu_eff_s, 0.0) / rig.cmu_max
        u = u - rig.stbd_gain_ratio * cs**rig.jet_power
        cd = c - cs
        c = c + cs
    jet = second_order(rig.jet_sign * gain * u, dt, 2 * np.pi * rig.f_j, rig.zeta_j, rig.settled)
    coupling = -rig.cc_rate * c * fl["p_hat"] + rig.cc_phi * cd * np.sin(fl["phi"]) * math.sin(math.radians(fl["alpha_deg"]))
    return jet, coupling


def taps(rig, fl, cmu_eff, cmu_eff_s=None):
    """The 12 pressure coefficients (noise-free) for the effective Cmu (port, starboard)."""
    n = len(cmu_eff)
    states = np.vstack([fl["beta"], fl["p_hat"], fl["l_port"], fl["l_stbd"], cmu_eff / rig.cmu_max, np.ones(n)])
    gain = rig.taps_gain
    if np.any(rig.taps_gain_alpha):
        gain = gain + math.sin(math.radians(fl["alpha_deg"])) / math.sin(math.radians(20.0)) * rig.taps_gain_alpha
    cp = gain @ states
    if cmu_eff_s is not None:
        cp = cp + np.outer(rig.taps_gain_stbd, cmu_eff_s / rig.cmu_max)
    return first_order_legacy(cp, 1.0 / rig.hz, rig.tube_tau_s)


def plant_cmu(rig, cmu):
    """The effective Cmu: the recorded Cmu through the pneumatic line's own delay."""
    return delay_samples(cmu, int(rig.jet_delay_s * rig.hz))


def ar1_noise(white, ar):
    return signal.lfilter([1.0], [1.0, -ar], white)


def quantise_phi(rig, phi):
    return np.round(np.degrees(phi) / rig.phi_quantum_deg) * rig.phi_quantum_deg


def measured_cmu(cmu, noise):
    return np.maximum(cmu + noise * (cmu > 0), 0.0)


# ---------------------------------------------------------------------------------------------
# Files.


def write_run_csv(path, columns, order, formats, nan_text="NaN"):
    """One run file: header in `order`, each column printed with its %-format; NaN spelled
    `nan_text`."""
    fmt = ",".join(formats[c] for c in order)
    data = np.column_stack([columns[c] for c in order]).tolist()
    body = "\n".join(fmt % tuple(row) for row in data)
    body = body.replace("nan", nan_text)
    with open(path, "w") as f:
        f.write(",".join(order) + "\n")
        f.write(body + "\n")


def manifest_text(rig, runs):
    """`runs`: (file, kind, alpha_deg) triples."""
    lines = [
        'format = "roll-dataset/1"',
        "",
        "[tunnel]",
        f"u_inf_mps = {rig.u_mps}",
        f"rho_kgm3 = {rig.rho}",
        "",
        "[wing]",
        f"chord_m = {rig.chord}",
        f"span_m = {rig.span}",
        f"area_m2 = {rig.area}",
        f"ixx_kgm2 = {rig.ixx}",
        f"mass_kg = {rig.mass}",
    ]
    for name, kind, alpha in runs:
        lines += ["", "[[run]]", f'file = "{name}"', f'kind = "{kind}"', f"alpha_deg = {alpha}", f"sample_hz = {rig.hz}"]
    return "\n".join(lines) + "\n"
