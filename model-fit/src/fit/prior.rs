//! The eGK fit's prior: centres from physics and the literature, scaled by the dataset's own
//! geometry and free-stream speed, and widths wide enough that the data decide wherever they
//! see a parameter.
//!
//! The fit is a maximum a posteriori fit ([`super::egk`]): what the data cannot see stays at
//! the prior (at alpha = 0 the vortex states do not move, at 10 deg they barely do). So no
//! centre here is a default of the synthetic tunnel (`firmware_sim::tunnel::params`): those
//! defaults came from the same sources (below), and a prior equal to them starts a fit on that
//! tunnel at its truth and keeps it there. Where a literature value coincides with the
//! tunnel's, the centre is the geometric middle of the published range or another published
//! estimate, as each value says.
//!
//! The sources are in docs/equations.md, "Parameter ranges and sources"; "Flow state",
//! "Magnitudes" and "Tunnel" below are its sections "Flow state and published time constants",
//! "Magnitudes of the wing and its sensors" and "The synthetic tunnel's model". Their provenance
//! tags are kept: \[PUB\] checked against a primary source, \[SEC\] a secondary one, \[REC\]
//! recalled, \[INF\] inferred. Time constants are in convective times `c/U` of the dataset's own
//! root chord and speed (the manifest's `wing.chord_m` and `tunnel.u_inf_mps`), the unit the GK
//! literature quotes them in (Flow state).
//!
//! The plant has no prior here: its fit is a sparse regression on the actuation runs, which
//! a dataset must have (the fit refuses one without them), so the plant of
//! `estimator_core::prior::PRIOR` never reaches a fitted model.

use firmware_sim::dataset::{Tunnel, Wing};

/// Number of fitted eGK parameters: ln tau1, ln tau2, a* (deg), ln k, kb, C_l,beta, C_l,p,
/// C_l,pdot, C_l,p|p|, K_v, C_l,0 (the fit's coordinates, in this order).
pub const N_EGK_PARAMS: usize = 11;

/// Standard deviations of the prior in the fit's coordinates, in the order of
/// [`N_EGK_PARAMS`]:
/// - ln tau1: `ln sqrt(10)`, half the logarithmic width of GK's published range (a factor of
///   3.2 either way), so that both ends of [`TAU1_RANGE_CONVECTIVE`] lie one width away;
/// - ln tau2: 1.5 (a factor of 4.5), wider than the half-range of [`TAU2_RANGE_CONVECTIVE`]
///   because the only delta-wing value lies at its lower end;
/// - a*: 5 deg, twice the half-width of the trailing-edge crossings (Magnitudes) to cover the
///   mapping from crossing to mid-chord (the private `breakdown_deg` below);
/// - ln k: 1 (a factor of 2.7), between an airfoil's stall and a delta wing's slower
///   breakdown travel ([`STEEPNESS_PER_DEG`]);
/// - kb: 0.5, the whole range 0.7 to 1.5 (Tunnel \[INF\]) around the estimate;
/// - C_l,beta and C_l,p: 0.2 per rad, larger than the estimates themselves;
/// - C_l,pdot: 0.05, two thirds of the slender-wing value;
/// - C_l,p|p|: 2 per unit `p_hat |p_hat|`, the moment of C_l,p's width at a reduced rate of
///   0.1, the top of a forced-roll test's (a damping that doubles over the test's rates);
/// - K_v: 0.05, the whole range 0.01 to 0.05 (Magnitudes and Tunnel);
/// - C_l,0: 0.01, several times the largest asymmetry a model of this size shows.
pub const EGK_PRIOR_WIDTH: [f64; N_EGK_PARAMS] =
    [std::f64::consts::LN_10 / 2.0, 1.5, 5.0, 1.0, 0.5, 0.2, 0.2, 0.05, 2.0, 0.05, 0.01];

/// GK's relaxation times of a delta wing's vortex breakdown, in `c/U`: about 1.5 from
/// water-tunnel visualisation and 15 from wind-tunnel forced oscillation, a tenfold gap the
/// authors could not explain (Flow state \[SEC\]; Goman & Khrabrov, J. Aircraft 31(5), 1994).
/// The prior centres on the geometric middle, 4.7 `c/U`, near Ayancik & Mulleners' 4.24
/// (JFM 2022, Flow state), rather than on the 3 `c/U` that the tunnel took.
pub const TAU1_RANGE_CONVECTIVE: [f64; 2] = [1.5, 15.0];

/// Published GK input delays, in `c/U`: 0.5 for GK's delta wing, 4.5 for their NACA 0015
/// and 5 in Jategaonkar's example (Flow state [SEC, PUB]). The delta wing's 0.5 is what the
/// tunnel uses (25 ms), so the prior centres on the geometric middle of the range, 1.6 `c/U`;
/// the width ([`EGK_PRIOR_WIDTH`]) keeps 0.5 within one width.
pub const TAU2_RANGE_CONVECTIVE: [f64; 2] = [0.5, 5.0];

/// Incidences at which the breakdown of a 65 deg delta wing's vortex reaches the trailing
/// edge at this Reynolds number, deg (Magnitudes \[REC\]; Nelson & Pelletier, Prog. Aerosp.
/// Sci. 39, 2003).
pub const TRAILING_EDGE_CROSSING_DEG: [f64; 2] = [20.0, 25.0];

/// Steepness of the breakdown curve, per deg: the 20 per rad of Jategaonkar's GK example
/// (Flight Vehicle System Identification, 2nd ed., HystTau2.m; Flow state \[PUB\]), the one
/// published value of the tanh form, where the tunnel has 0.25 per deg (14 per rad).
pub const STEEPNESS_PER_DEG: f64 = 20.0 * std::f64::consts::PI / 180.0;

/// Vortex-breakdown asymmetry increment of a 65 deg delta wing at alpha = 20 deg: 0.01 to
/// 0.03 (Magnitudes \[REC\]; Nelson & Pelletier 2003). The tunnel takes the top, 0.03.
pub const VORTEX_INCREMENT_AT_20_DEG: [f64; 2] = [0.01, 0.03];

/// The dataset's geometry and speed the prior scales with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Root chord `c`, m.
    pub chord_m: f64,
    /// Span `b`, m.
    pub span_m: f64,
    /// Planform area `S`, m^2.
    pub area_m2: f64,
    /// Free-stream speed `U`, m/s.
    pub u_inf_mps: f64,
}

impl Geometry {
    /// The geometry of a dataset's manifest.
    #[must_use]
    pub fn new(wing: &Wing, tunnel: &Tunnel) -> Self {
        Self { chord_m: wing.chord_m, span_m: wing.span_m, area_m2: wing.area_m2, u_inf_mps: tunnel.u_inf_mps }
    }

    /// Convective time `c/U`, s.
    #[must_use]
    pub fn convective_time_s(&self) -> f64 {
        self.chord_m / self.u_inf_mps
    }

    /// Half-span time `b/(2U)`, s: the unit of the roll rate `p_hat`.
    #[must_use]
    pub fn half_span_time_s(&self) -> f64 {
        self.span_m / (2.0 * self.u_inf_mps)
    }

    /// Aspect ratio `b^2/S`.
    #[must_use]
    pub fn aspect_ratio(&self) -> f64 {
        self.span_m * self.span_m / self.area_m2
    }

    /// Lift slope of the potential flow, per rad: Helmbold's low-aspect-ratio formula
    /// `2 pi A / (2 + sqrt(A^2 + 4))` (Helmbold 1942; the `K_p` of Polhamus, NASA TN D-3767,
    /// 1966), 14 % below slender-wing theory's `pi A / 2` at the paper's A = 1.74.
    #[must_use]
    pub fn potential_lift_slope(&self) -> f64 {
        let aspect = self.aspect_ratio();
        std::f64::consts::TAU * aspect / (2.0 + (aspect * aspect + 4.0).sqrt())
    }

    /// Lift coefficient at `alpha_deg` by Polhamus's leading-edge-suction analogy,
    /// `K_p sin a cos^2 a + K_v sin^2 a cos a`, with `K_v = pi` (slender-wing limit; NASA
    /// TN D-3767, 1966).
    #[must_use]
    pub fn lift_coefficient(&self, alpha_deg: f64) -> f64 {
        let (sin, cos) = alpha_deg.to_radians().sin_cos();
        self.potential_lift_slope() * sin * cos * cos + std::f64::consts::PI * sin * sin * cos
    }
}

/// The prior of the eGK at one angle of attack: its centre (the core's parameters, in f64)
/// and, in [`EGK_PRIOR_WIDTH`], its widths.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgkPrior {
    /// GK relaxation time, s.
    pub tau1_s: f64,
    /// GK input delay, s.
    pub tau2_s: f64,
    /// Incidence of the breakdown curve's midpoint, deg.
    pub breakdown_deg: f64,
    /// Steepness of the breakdown curve, per deg.
    pub steepness_per_deg: f64,
    /// Sideslip-to-incidence gain of each half-wing.
    pub sideslip_gain: f64,
    /// Sideslip derivative, per rad.
    pub clbeta_per_rad: f64,
    /// Roll damping per unit `p_hat`.
    pub clp: f64,
    /// Roll-acceleration derivative per unit `p_hat_dot`.
    pub clpdot: f64,
    /// Quadratic roll damping per unit `p_hat |p_hat|`.
    pub clpp: f64,
    /// Roll moment per unit vortex-state asymmetry.
    pub vortex_gain: f64,
    /// Roll moment at zero roll.
    pub bias: f64,
    /// `b/(2U)` of the dataset, s.
    pub half_span_time_s: f64,
}

impl EgkPrior {
    /// The prior at `alpha_deg` for a wing of `geometry`.
    #[must_use]
    pub fn new(geometry: &Geometry, alpha_deg: f64) -> Self {
        let convective_s = geometry.convective_time_s();
        Self {
            tau1_s: geometric_middle(TAU1_RANGE_CONVECTIVE) * convective_s,
            tau2_s: geometric_middle(TAU2_RANGE_CONVECTIVE) * convective_s,
            breakdown_deg: breakdown_deg(),
            steepness_per_deg: STEEPNESS_PER_DEG,
            sideslip_gain: sideslip_gain(geometry, alpha_deg),
            clbeta_per_rad: clbeta_per_rad(geometry, alpha_deg),
            clp: clp(geometry),
            clpdot: clpdot(geometry),
            // No published value for a wing like this one, nor a sign that theory fixes: the
            // linear damping's moment carries the prior, this term only what the data show.
            clpp: 0.0,
            vortex_gain: vortex_gain(alpha_deg),
            // A mirror-symmetric wing has no roll moment at zero roll.
            bias: 0.0,
            half_span_time_s: geometry.half_span_time_s(),
        }
    }

    /// The centre as the core's parameters (f32).
    #[must_use]
    pub fn to_core(&self) -> estimator_core::coeffs::EgkParams {
        estimator_core::coeffs::EgkParams {
            tau1_s: self.tau1_s as f32,
            tau2_s: self.tau2_s as f32,
            breakdown_deg: self.breakdown_deg as f32,
            steepness_per_deg: self.steepness_per_deg as f32,
            sideslip_gain: self.sideslip_gain as f32,
            clbeta_per_rad: self.clbeta_per_rad as f32,
            clp: self.clp as f32,
            clpdot: self.clpdot as f32,
            clpp: self.clpp as f32,
            vortex_gain: self.vortex_gain as f32,
            bias: self.bias as f32,
            half_span_time_s: self.half_span_time_s as f32,
        }
    }
}

/// `sqrt(low high)`: the middle of a range known to a factor.
fn geometric_middle([low, high]: [f64; 2]) -> f64 {
    (low * high).sqrt()
}

/// The breakdown curve's midpoint `a*`, deg. The state is the breakdown's position along the
/// chord (1: beyond the trailing edge; Flow state), so its midpoint is the incidence at which
/// the breakdown stands at mid-chord, above the trailing-edge crossing: taking the crossing
/// (the geometric middle of [`TRAILING_EDGE_CROSSING_DEG`], 22.4 deg) where the curve is at
/// 0.9 puts the midpoint `atanh(0.8) / k` = 3.1 deg higher, at 25.5 deg \[INF\].
fn breakdown_deg() -> f64 {
    geometric_middle(TRAILING_EDGE_CROSSING_DEG) + 0.8f64.atanh() / STEEPNESS_PER_DEG
}

/// The sideslip-to-incidence gain `kb` \[INF\]: the leading edges of a delta wing in sideslip
/// beta are swept by `Lambda -+ beta`, and the vortex scales with the incidence normal to the
/// edge, `atan(tan a / cos Lambda)`. The incidence that gives the windward edge's normal
/// incidence at the nominal sweep is `a + kb beta` with `kb = sin(2a) tan(Lambda) / 2`, and a
/// delta wing's sweep is `tan Lambda = 2c/b`: 0.39 at 10 deg and 0.74 at 20 deg on the paper's
/// wing, below the 1 of Tunnel (\[INF\], the tunnel's value).
fn sideslip_gain(geometry: &Geometry, alpha_deg: f64) -> f64 {
    let tan_sweep = 2.0 * geometry.chord_m / geometry.span_m;
    0.5 * (2.0 * alpha_deg.to_radians()).sin() * tan_sweep
}

/// The sideslip derivative \[INF\]: in slender-wing theory (Jones, NACA Report 835, 1946) the
/// load of a flat delta wing acts at the middle of its widest cross-section, which sideslip
/// shifts off the body axis by `c tan^2(eps) beta` (`tan eps = b / 2c`, the half apex angle);
/// the moment is then `C_l,beta = -C_L tan(eps) / 2 = -C_L b / 4c`, with the lift of
/// [`Geometry::lift_coefficient`]: -0.11 at 10 deg and -0.23 at 20 deg on the paper's wing,
/// where Magnitudes (\[INF\], the tunnel's `-0.0075 alpha_deg`) gives -0.075 and -0.15.
/// It is zero at alpha = 0, where a flat wing has no lift.
fn clbeta_per_rad(geometry: &Geometry, alpha_deg: f64) -> f64 {
    -geometry.lift_coefficient(alpha_deg) * geometry.span_m / (4.0 * geometry.chord_m)
}

/// Roll damping \[INF\]: slender-wing theory's `-pi A / 32` (Magnitudes \[REC\]; Ribner, NACA
/// TN 1423, 1947) is the limit of small aspect ratio, and it equals the tunnel's -0.17 at the
/// paper's A. Damping is lift from the antisymmetric upwash; at finite A the prior scales it
/// by Helmbold's lift slope over slender theory's `pi A / 2`, which gives `-K_p / 16`: -0.147
/// on the paper's wing.
fn clp(geometry: &Geometry) -> f64 {
    -geometry.potential_lift_slope() / 16.0
}

/// Roll-acceleration derivative \[INF\]: the added moment of inertia of the air, in the same
/// slender-wing theory. A flat section of half-span `s` rolling in still air carries
/// `pi rho s^4 / 8` per unit length (Newman, Marine Hydrodynamics, 1977, section 4.13);
/// integrated over a delta wing and made dimensionless with `p_hat_dot = p_dot (b/2U)^2` it is
/// `-pi b c / (80 S)`: -0.078 on the paper's wing, where Tunnel (\[INF\], the
/// tunnel) gives -0.01.
fn clpdot(geometry: &Geometry) -> f64 {
    -std::f64::consts::PI * geometry.span_m * geometry.chord_m / (80.0 * geometry.area_m2)
}

/// Roll moment per unit vortex-state asymmetry: the geometric middle of
/// [`VORTEX_INCREMENT_AT_20_DEG`], 0.017, at 20 deg, scaled with alpha as Polhamus's vortex
/// lift `sin^2 a cos a` (NASA TN D-3767, 1966); the tunnel has 0.03 scaled with `sin^2 a`.
fn vortex_gain(alpha_deg: f64) -> f64 {
    let vortex_lift = |deg: f64| {
        let (sin, cos) = deg.to_radians().sin_cos();
        sin * sin * cos
    };
    geometric_middle(VORTEX_INCREMENT_AT_20_DEG) * vortex_lift(alpha_deg) / vortex_lift(20.0)
}

#[cfg(test)]
mod tests {
    use firmware_sim::tunnel::TunnelConfig;

    use super::*;

    fn paper() -> Geometry {
        let config = TunnelConfig::default();
        Geometry::new(&config.wing, &config.tunnel.0)
    }

    fn centres(prior: &EgkPrior) -> [(&'static str, f64); 9] {
        [
            ("tau1", prior.tau1_s),
            ("tau2", prior.tau2_s),
            ("a*", prior.breakdown_deg),
            ("k", prior.steepness_per_deg),
            ("kb", prior.sideslip_gain),
            ("C_l,beta", prior.clbeta_per_rad),
            ("C_l,p", prior.clp),
            ("C_l,pdot", prior.clpdot),
            ("K_v", prior.vortex_gain),
        ]
    }

    /// No centre of the fit's prior is the synthetic tunnel's default at the paper's
    /// geometry, nor within 5 % of it (a copy rounded differently is still a copy). Values the
    /// tunnel and the prior both put at zero by the wing's symmetry (the sideslip derivative
    /// and the vortex gain at alpha = 0, the bias) are physics, not a copy, and are skipped.
    #[test]
    fn no_prior_centre_is_a_tunnel_default() {
        let config = TunnelConfig::default();
        let aero = config.aero;
        for alpha_deg in [0.0f64, 5.0, 10.0, 15.0, 20.0, 25.0] {
            let vortex_scale = (alpha_deg.to_radians().sin() / 20f64.to_radians().sin()).powi(2);
            let tunnel = [
                aero.tau1_s,
                aero.tau2_s,
                aero.breakdown_alpha_deg,
                aero.breakdown_steepness_per_deg,
                aero.sideslip_incidence_gain,
                aero.clbeta_per_rad_per_deg * alpha_deg,
                aero.clp,
                aero.clpdot,
                aero.vortex_gain * vortex_scale,
            ];
            let prior = EgkPrior::new(&paper(), alpha_deg);
            for ((name, centre), default) in centres(&prior).into_iter().zip(tunnel) {
                if default == 0.0 && centre == 0.0 {
                    continue;
                }
                assert!(
                    (centre - default).abs() > 0.05 * default.abs(),
                    "{name} at {alpha_deg} deg: prior {centre} against the tunnel's {default}"
                );
            }
            assert_eq!(prior.bias, 0.0);
        }
    }

    /// The time constants are convective: they scale with `c/U`, and `p_hat`'s unit with
    /// `b/2U`; a slower tunnel or a longer chord stretches them alike.
    #[test]
    fn time_constants_scale_with_the_convective_time() {
        let base = paper();
        let convective_s = base.convective_time_s();
        let prior = EgkPrior::new(&base, 20.0);
        assert!((prior.tau1_s / convective_s - 22.5f64.sqrt()).abs() < 1e-12);
        assert!((prior.tau2_s / convective_s - 2.5f64.sqrt()).abs() < 1e-12);
        let slower = EgkPrior::new(&Geometry { u_inf_mps: base.u_inf_mps / 2.0, ..base }, 20.0);
        assert!((slower.tau1_s / prior.tau1_s - 2.0).abs() < 1e-12);
        assert!((slower.tau2_s / prior.tau2_s - 2.0).abs() < 1e-12);
        assert!((slower.half_span_time_s / prior.half_span_time_s - 2.0).abs() < 1e-12);
        let chord = 1.5 * base.chord_m;
        let longer = EgkPrior::new(&Geometry { chord_m: chord, area_m2: 0.5 * chord * base.span_m, ..base }, 20.0);
        assert!((longer.tau1_s / prior.tau1_s - 1.5).abs() < 1e-12);
        assert!((longer.tau2_s / prior.tau2_s - 1.5).abs() < 1e-12);
        // The dimensionless centres do not depend on the speed.
        assert_eq!(slower.clp, prior.clp);
        assert_eq!(slower.breakdown_deg, prior.breakdown_deg);
    }

    /// The core's `PRIOR` is this prior at the paper's geometry, to its printed digits.
    #[test]
    fn the_core_prior_is_this_prior_on_the_paper_wing() {
        let set = estimator_core::prior::PRIOR;
        for (slot, alpha_deg) in [0.0, 10.0, 20.0].into_iter().enumerate() {
            let core = set.egk[slot];
            let host = EgkPrior::new(&paper(), alpha_deg).to_core();
            let pairs = [
                (core.tau1_s, host.tau1_s),
                (core.tau2_s, host.tau2_s),
                (core.breakdown_deg, host.breakdown_deg),
                (core.steepness_per_deg, host.steepness_per_deg),
                (core.sideslip_gain, host.sideslip_gain),
                (core.clbeta_per_rad, host.clbeta_per_rad),
                (core.clp, host.clp),
                (core.clpdot, host.clpdot),
                (core.clpp, host.clpp),
                (core.vortex_gain, host.vortex_gain),
                (core.bias, host.bias),
                (core.half_span_time_s, host.half_span_time_s),
            ];
            for (index, (core, host)) in pairs.into_iter().enumerate() {
                assert!((core - host).abs() <= 2e-5 * host.abs(), "alpha {alpha_deg}, field {index}: {core} vs {host}");
            }
            assert_eq!(f64::from(set.alpha_schedule_deg[slot]), alpha_deg);
        }
    }

    /// The physical estimates on the paper's wing, against the numbers their doc comments
    /// quote, and the symmetry at alpha = 0.
    #[test]
    fn estimates_on_the_paper_wing() {
        let geometry = paper();
        let close = |value: f64, expected: f64, tol: f64| (value - expected).abs() < tol;
        assert!(close(geometry.aspect_ratio(), 1.74, 0.005));
        let at_10 = EgkPrior::new(&geometry, 10.0);
        let at_20 = EgkPrior::new(&geometry, 20.0);
        assert!(close(at_20.breakdown_deg, 25.5, 0.05), "{}", at_20.breakdown_deg);
        assert!(close(at_10.sideslip_gain, 0.39, 0.005) && close(at_20.sideslip_gain, 0.74, 0.005));
        assert!(close(at_10.clbeta_per_rad, -0.11, 0.005) && close(at_20.clbeta_per_rad, -0.23, 0.005));
        assert!(close(at_20.clp, -0.147, 0.0005), "{}", at_20.clp);
        assert!(close(at_20.clpdot, -0.0785, 0.0001), "{}", at_20.clpdot);
        assert!(close(at_20.vortex_gain, 0.0173, 0.0001), "{}", at_20.vortex_gain);
        let at_0 = EgkPrior::new(&geometry, 0.0);
        assert_eq!((at_0.sideslip_gain, at_0.clbeta_per_rad, at_0.vortex_gain), (0.0, 0.0, 0.0));
    }
}
