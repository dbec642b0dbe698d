//! The software-in-the-loop harness: the estimator and the controller blocks of
//! `estimator-core` (the code that flies) in closed loop with the synthetic wind tunnel at the
//! fixed rate.
//!
//! Per sample `k`: the tunnel's measured channels (encoder, measured Cmu, 12 Cp, balance) go to
//! [`Estimator::step`]; the controller ([`Controller::step`]) gets the disturbance estimate to
//! cancel and the balance's moment for the feedback; its Cmu demand is held by the valves over
//! the next sample ([`TunnelSim::advance`], the valve dead time applies) and noted by the
//! estimator ([`Estimator::note_demand`]), which predicts a missing Cmu from it. The disturbance is the
//! roll motion: the roll command is the campaign's random sequence with holds.
//!
//! Scenarios ([`Mode`]): no control, feedback only, feedforward only, feedforward + feedback
//! with the linear-superposition estimate (`C_l,roll`), and with the coupling operator's
//! correction (`C_l,roll + coupling`). Every mode at one alpha sees the same roll command and the
//! same noise (common random numbers), so differences are the controller's.
//!
//! Metrics are taken on the noise-free aerodynamic moment of the tunnel ([`Sample::cl_aero`]),
//! after a warm-up in which the estimator's filters settle. Sensor faults ([`crate::fault`]) can
//! be injected into what the estimator and the feedback read ([`run_scenario_with_faults`]).

use estimator_core::controller::{Blocks, Controller, ControllerInput};
use estimator_core::{CoefficientSet, Estimator, Health, Input};
use rayon::prelude::*;
use serde::Serialize;

mod record;

pub use record::{METRIC, SilContext, SilRecord, Tuning};

use crate::campaign::{Scenario, ScenarioError, mix_seed};
use crate::fault::{FaultInjector, FaultSpec};
use crate::tunnel::excitation::HoldSequence;
use crate::tunnel::{Sample, TunnelConfig, TunnelSim};

/// Stream of [`mix_seed`] (with a run's noise seed) for the random choices of injected faults.
const FAULT_STREAM: u64 = 0xFA_0017;

/// Errors of a SIL run.
#[derive(Debug, thiserror::Error)]
pub enum SilError {
    /// The scenario is out of range.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// The estimator's fixed step does not match the tunnel's sample rate.
    #[error("the coefficient set's step is {dt_s} s but the scenario samples at {sample_hz} Hz; they must agree")]
    Rate {
        /// The set's step, s.
        dt_s: f64,
        /// The scenario's rate, Hz.
        sample_hz: f64,
    },
    /// Gains out of range.
    #[error("invalid gains: {0}")]
    Gains(String),
}

/// A scenario of the comparison: which controller blocks run, on which disturbance estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// No control: the valves stay closed.
    None,
    /// PI feedback on the balance's roll moment only.
    Feedback,
    /// Feedforward of the disturbance estimate `C_l,roll` only.
    Feedforward,
    /// Feedforward of `C_l,roll` (linear superposition) plus feedback.
    FfFbLinear,
    /// Feedforward of `C_l,roll + coupling` (the coupling operator) plus feedback.
    FfFbCoupled,
}

impl Mode {
    /// Every mode, in report order.
    pub const ALL: [Self; 5] = [Self::None, Self::Feedback, Self::Feedforward, Self::FfFbLinear, Self::FfFbCoupled];

    /// The name in tables and JSON.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Feedback => "feedback",
            Self::Feedforward => "feedforward",
            Self::FfFbLinear => "ff_fb_linear",
            Self::FfFbCoupled => "ff_fb_coupled",
        }
    }

    /// The controller blocks, or `None` when there is no controller.
    #[must_use]
    pub const fn blocks(self) -> Option<Blocks> {
        match self {
            Self::None => None,
            Self::Feedback => Some(Blocks { feedforward: false, feedback: true }),
            Self::Feedforward => Some(Blocks { feedforward: true, feedback: false }),
            Self::FfFbLinear | Self::FfFbCoupled => Some(Blocks { feedforward: true, feedback: true }),
        }
    }

    /// Whether the feedforward cancels the coupling operator's correction too.
    #[must_use]
    pub const fn with_coupling(self) -> bool {
        matches!(self, Self::FfFbCoupled)
    }
}

/// The controller gains the harness varies (the rest of `ControllerParams` is the set's).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Gains {
    /// Time constant of the feedforward's causality filter, s (pole `exp(-dt / T_F)`).
    pub causality_tau_s: f64,
    /// Proportional feedback gain, C_l per C_l.
    pub feedback_kp: f64,
    /// Integral feedback gain, C_l per (C_l s).
    pub feedback_ki: f64,
}

impl Gains {
    /// The gains of a coefficient set.
    #[must_use]
    pub fn of(set: &CoefficientSet) -> Self {
        let pole = f64::from(set.controller.causality_pole);
        let dt_s = f64::from(set.dt_s);
        let causality_tau_s = if pole > 0.0 && pole < 1.0 { -dt_s / pole.ln() } else { 0.0 };
        Self {
            causality_tau_s,
            feedback_kp: f64::from(set.controller.feedback_kp),
            feedback_ki: f64::from(set.controller.feedback_ki),
        }
    }

    /// The set with these gains.
    pub fn apply(&self, set: &CoefficientSet) -> Result<CoefficientSet, SilError> {
        let finite = [self.causality_tau_s, self.feedback_kp, self.feedback_ki].iter().all(|v| v.is_finite());
        if !finite || self.causality_tau_s < 0.0 || self.feedback_kp < 0.0 || self.feedback_ki < 0.0 {
            return Err(SilError::Gains(format!("{self:?}: expected finite, non-negative values")));
        }
        let mut tuned = *set;
        let dt_s = f64::from(set.dt_s);
        let pole = if self.causality_tau_s > 0.0 { (-dt_s / self.causality_tau_s).exp() } else { 0.0 };
        tuned.controller.causality_pole = pole as f32;
        tuned.controller.feedback_kp = self.feedback_kp as f32;
        tuned.controller.feedback_ki = self.feedback_ki as f32;
        Ok(tuned)
    }
}

/// Settings of the harness beyond the scenario.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SilSettings {
    /// Start of the metric window, s (the estimator's filters settle before it).
    pub warmup_s: f64,
    /// Every how many samples a trace point is kept (0: no trace).
    pub trace_every: usize,
}

impl Default for SilSettings {
    fn default() -> Self {
        Self { warmup_s: 1.0, trace_every: 10 }
    }
}

/// Metrics of one closed-loop run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunMetrics {
    /// Angle of attack, deg.
    pub alpha_deg: f64,
    /// The scenario.
    pub mode: Mode,
    /// RMS of the noise-free aerodynamic roll moment over the metric window.
    pub rms_cl: f64,
    /// Peak |C_l| of the noise-free aerodynamic roll moment over the window.
    pub peak_cl: f64,
    /// RMS of the balance's roll moment (noise included) over the window.
    pub rms_cl_balance: f64,
    /// Mean commanded Cmu of the port and starboard jets over the window.
    pub mean_cmu: [f64; 2],
    /// Largest commanded Cmu of either jet over the whole run.
    pub max_cmu_cmd: f64,
    /// Smallest commanded Cmu of either jet over the whole run.
    pub min_cmu_cmd: f64,
    /// Share of the window in which the controller's demand was out of the jets' reach (a jet
    /// held at 0 or at `cmu_max` while more was demanded).
    pub saturated_fraction: f64,
    /// Share of the window in which each jet was commanded to `cmu_max`.
    pub at_max_fraction: [f64; 2],
    /// RMS of the estimator's `C_l,roll` error against the true moment, while no jet blows
    /// (the disturbance estimate's quality in this loop; `None` without such samples).
    pub rms_disturbance_error: Option<f64>,
    /// Samples in the window.
    pub n_samples: usize,
}

/// Decimated time series of one run, for plots.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Trace {
    /// Time, s.
    pub t_s: Vec<f64>,
    /// Noise-free aerodynamic roll moment.
    pub cl_aero: Vec<f64>,
    /// Commanded Cmu, port.
    pub cmu_port: Vec<f64>,
    /// Commanded Cmu, starboard.
    pub cmu_stbd: Vec<f64>,
    /// The estimator's disturbance estimate `C_l,roll`.
    pub cl_roll: Vec<f64>,
    /// Roll angle, deg.
    pub phi_deg: Vec<f64>,
}

/// One run's metrics and trace.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunOutcome {
    /// Metrics.
    pub metrics: RunMetrics,
    /// Trace (empty when `trace_every` is 0); plotted, left out of the JSON (the metrics are
    /// the numbers).
    #[serde(skip)]
    pub trace: Trace,
}

/// One closed-loop run's conditions.
#[derive(Debug, Clone)]
pub struct RunConditions<'a> {
    /// The tunnel.
    pub config: &'a TunnelConfig,
    /// Angle of attack, deg.
    pub alpha_deg: f64,
    /// Sample rate, Hz (the estimator's step must match).
    pub sample_hz: f64,
    /// Duration, s.
    pub duration_s: f64,
    /// Roll command, deg.
    pub roll_cmd_deg: &'a HoldSequence,
    /// Seed of the tunnel's noise (and, mixed, of the injected faults' random choices).
    pub noise_seed: u64,
    /// Sensor faults injected into the estimator's inputs and the balance reading the feedback
    /// sees (`crate::fault`); the metrics stay on the tunnel's true moment.
    pub faults: &'a [FaultSpec],
}

/// Runs the estimator and controller of `set` in closed loop with the tunnel.
#[must_use]
pub fn run_closed_loop(
    run: &RunConditions<'_>,
    set: &CoefficientSet,
    mode: Mode,
    settings: &SilSettings,
) -> RunOutcome {
    let mut tunnel = TunnelSim::new(run.config, run.alpha_deg, run.sample_hz, run.roll_cmd_deg.clone(), run.noise_seed);
    let mut estimator = Estimator::new(set);
    let mut controller = Controller::new();
    let n_samples = (run.duration_s * run.sample_hz).round().max(0.0) as usize;
    let warmup = ((settings.warmup_s * run.sample_hz).round().max(0.0) as usize).min(n_samples.saturating_sub(1));
    let alpha_rad = (run.alpha_deg as f32).to_radians();
    let cmu_max = f64::from(set.controller.cmu_max);
    let mut acc = Accumulator::default();
    let mut trace = Trace::default();
    let mut injector = FaultInjector::new(run.faults, run.sample_hz, mix_seed(run.noise_seed, FAULT_STREAM));
    for k in 0..n_samples {
        let sample = tunnel.sample();
        let (mut input, mut measured_cl) = (estimator_input(&sample, run.alpha_deg), sample.cl);
        injector.apply(sample.t_s, &mut input, &mut measured_cl);
        let output = estimator.step(&input);
        let (cmu_cmd, saturated) = match mode.blocks() {
            None => ([0.0; 2], false),
            Some(blocks) => {
                let disturbance = if mode.with_coupling() { output.cl_roll + output.coupling } else { output.cl_roll };
                let input = ControllerInput { disturbance_cl: disturbance, measured_cl: measured_cl as f32, alpha_rad };
                let mut health = Health::default();
                let demand = controller.step(set, estimator.plants(), &input, blocks, &mut health);
                (demand.cmu.map(f64::from), health.has(Health::CMU_SATURATED))
            }
        };
        // The demand goes to the valves: the estimator predicts a missing Cmu from it.
        estimator.note_demand(cmu_cmd.map(|cmd| cmd as f32));
        acc.cmd_range(cmu_cmd);
        if k >= warmup {
            acc.add(&sample, cmu_cmd, saturated, cmu_max, f64::from(output.cl_roll));
        }
        if settings.trace_every > 0 && k % settings.trace_every == 0 {
            trace.t_s.push(sample.t_s);
            trace.cl_aero.push(sample.cl_aero);
            trace.cmu_port.push(cmu_cmd[0]);
            trace.cmu_stbd.push(cmu_cmd[1]);
            trace.cl_roll.push(f64::from(output.cl_roll));
            trace.phi_deg.push(sample.phi_deg);
        }
        tunnel.advance(cmu_cmd);
    }
    RunOutcome { metrics: acc.metrics(run.alpha_deg, mode), trace }
}

/// The estimator's input from a tunnel sample.
fn estimator_input(sample: &Sample, alpha_deg: f64) -> Input {
    Input {
        phi_deg: sample.phi_deg as f32,
        alpha_deg: alpha_deg as f32,
        cmu_port: sample.cmu[0] as f32,
        cmu_stbd: sample.cmu[1] as f32,
        cp: sample.cp.map(|cp| cp as f32),
    }
}

/// Running sums of the metrics.
#[derive(Debug, Default)]
struct Accumulator {
    n: usize,
    sum_sq: f64,
    peak: f64,
    sum_sq_balance: f64,
    sum_cmu: [f64; 2],
    n_saturated: usize,
    n_at_max: [usize; 2],
    max_cmd: f64,
    min_cmd: f64,
    n_unblown: usize,
    sum_sq_disturbance: f64,
}

impl Accumulator {
    fn cmd_range(&mut self, cmu_cmd: [f64; 2]) {
        for cmd in cmu_cmd {
            self.max_cmd = self.max_cmd.max(cmd);
            self.min_cmd = self.min_cmd.min(cmd);
        }
    }

    fn add(&mut self, sample: &Sample, cmu_cmd: [f64; 2], saturated: bool, cmu_max: f64, cl_roll: f64) {
        self.n += 1;
        self.sum_sq += sample.cl_aero * sample.cl_aero;
        self.peak = self.peak.max(sample.cl_aero.abs());
        self.sum_sq_balance += sample.cl * sample.cl;
        for (side, &cmd) in cmu_cmd.iter().enumerate() {
            self.sum_cmu[side] += cmd;
            if cmd >= cmu_max {
                self.n_at_max[side] += 1;
            }
        }
        if saturated {
            self.n_saturated += 1;
        }
        // The jets' own moment lingers after the valves close (circulation, about 0.1 s); the
        // measured Cmu is a fair proxy for "no jet acts" only well after it; a small threshold
        // keeps the sensor noise of a closed valve out.
        if sample.cmu.iter().all(|&cmu| cmu < 1e-6) && cmu_cmd.iter().all(|&cmd| cmd == 0.0) {
            self.n_unblown += 1;
            self.sum_sq_disturbance += (cl_roll - sample.cl_aero).powi(2);
        }
    }

    fn metrics(&self, alpha_deg: f64, mode: Mode) -> RunMetrics {
        let n = self.n.max(1) as f64;
        RunMetrics {
            alpha_deg,
            mode,
            rms_cl: (self.sum_sq / n).sqrt(),
            peak_cl: self.peak,
            rms_cl_balance: (self.sum_sq_balance / n).sqrt(),
            mean_cmu: self.sum_cmu.map(|sum| sum / n),
            max_cmu_cmd: self.max_cmd,
            min_cmu_cmd: self.min_cmd,
            saturated_fraction: self.n_saturated as f64 / n,
            at_max_fraction: self.n_at_max.map(|count| count as f64 / n),
            rms_disturbance_error: (self.n_unblown > 0)
                .then(|| (self.sum_sq_disturbance / self.n_unblown as f64).sqrt()),
            n_samples: self.n,
        }
    }
}

/// The results of a scenario: every (alpha, mode) run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SilResults {
    /// Master seed of the roll command and the noise.
    pub seed: u64,
    /// Duration of every run, s.
    pub duration_s: f64,
    /// Sample rate, Hz.
    pub sample_hz: f64,
    /// The gains used.
    pub gains: Gains,
    /// `cmu_max` of the controller.
    pub cmu_max: f64,
    /// Harness settings.
    pub settings: SilSettings,
    /// Runs, by alpha then mode (in [`Mode::ALL`] order).
    pub runs: Vec<RunOutcome>,
}

impl SilResults {
    /// The run at `alpha_deg` in `mode`.
    #[must_use]
    pub fn run(&self, alpha_deg: f64, mode: Mode) -> Option<&RunOutcome> {
        self.runs.iter().find(|run| run.metrics.alpha_deg == alpha_deg && run.metrics.mode == mode)
    }

    /// `1 - rms(mode) / rms(none)` at `alpha_deg`.
    #[must_use]
    pub fn reduction(&self, alpha_deg: f64, mode: Mode) -> Option<f64> {
        let none = self.run(alpha_deg, Mode::None)?.metrics.rms_cl;
        let this = self.run(alpha_deg, mode)?.metrics.rms_cl;
        (none > 0.0).then(|| 1.0 - this / none)
    }

    /// The angles of attack, in scenario order.
    #[must_use]
    pub fn alphas_deg(&self) -> Vec<f64> {
        let mut alphas: Vec<f64> = Vec::new();
        for run in &self.runs {
            if !alphas.contains(&run.metrics.alpha_deg) {
                alphas.push(run.metrics.alpha_deg);
            }
        }
        alphas
    }
}

/// The roll command of a scenario: the campaign's (same stream as `Scenario::run_specs`).
#[must_use]
pub fn roll_command(scenario: &Scenario) -> HoldSequence {
    let mut rng: rand_chacha::ChaCha8Rng = rand::SeedableRng::seed_from_u64(mix_seed(scenario.seed, 1));
    scenario.excitation.roll_deg.draw(scenario.duration_s, &mut rng)
}

/// Seed of the tunnel noise at the `alpha_idx`-th alpha (shared by every mode there).
#[must_use]
pub fn noise_seed(seed: u64, alpha_idx: usize) -> u64 {
    mix_seed(seed, 300 + alpha_idx as u64)
}

/// Checks the scenario and that the set's step matches its rate.
pub fn check(scenario: &Scenario, set: &CoefficientSet) -> Result<(), SilError> {
    scenario.validate()?;
    let dt_s = f64::from(set.dt_s);
    let mismatch = (dt_s * scenario.sample_hz - 1.0).abs();
    if mismatch.is_nan() || mismatch >= 1e-6 {
        return Err(SilError::Rate { dt_s, sample_hz: scenario.sample_hz });
    }
    Ok(())
}

/// Runs `modes` at every alpha of the scenario (in parallel; each run is seeded, so the result
/// does not depend on the order). `on_run_done` is called once per run.
pub fn run_scenario(
    scenario: &Scenario,
    set: &CoefficientSet,
    modes: &[Mode],
    settings: &SilSettings,
    on_run_done: &(dyn Fn() + Sync),
) -> Result<SilResults, SilError> {
    run_scenario_with_faults(scenario, set, modes, settings, &[], on_run_done)
}

/// [`run_scenario`] with the sensor `faults` injected into every run (`crate::fault`).
pub fn run_scenario_with_faults(
    scenario: &Scenario,
    set: &CoefficientSet,
    modes: &[Mode],
    settings: &SilSettings,
    faults: &[FaultSpec],
    on_run_done: &(dyn Fn() + Sync),
) -> Result<SilResults, SilError> {
    check(scenario, set)?;
    let config = scenario.tunnel_config();
    let roll = roll_command(scenario);
    let jobs: Vec<(usize, f64, Mode)> = scenario
        .alphas_deg
        .iter()
        .enumerate()
        .flat_map(|(idx, &alpha)| modes.iter().map(move |&mode| (idx, alpha, mode)))
        .collect();
    let runs = jobs
        .par_iter()
        .map(|&(alpha_idx, alpha_deg, mode)| {
            let conditions = RunConditions {
                config: &config,
                alpha_deg,
                sample_hz: scenario.sample_hz,
                duration_s: scenario.duration_s,
                roll_cmd_deg: &roll,
                noise_seed: noise_seed(scenario.seed, alpha_idx),
                faults,
            };
            let outcome = run_closed_loop(&conditions, set, mode, settings);
            on_run_done();
            outcome
        })
        .collect();
    Ok(SilResults {
        seed: scenario.seed,
        duration_s: scenario.duration_s,
        sample_hz: scenario.sample_hz,
        gains: Gains::of(set),
        cmu_max: f64::from(set.controller.cmu_max),
        settings: *settings,
        runs,
    })
}

/// One point of a gain search.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TunePoint {
    /// The gains.
    pub gains: Gains,
    /// `rms(ff_fb_linear) / rms(none)` per alpha.
    pub ratios: Vec<f64>,
    /// The objective: the largest ratio over the alphas (every alpha must improve).
    pub objective: f64,
}

/// The grid of a gain search.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TuneGrid {
    /// Causality time constants, s.
    pub causality_tau_s: Vec<f64>,
    /// Proportional gains.
    pub feedback_kp: Vec<f64>,
    /// Integral gains.
    pub feedback_ki: Vec<f64>,
}

impl Default for TuneGrid {
    fn default() -> Self {
        Self {
            causality_tau_s: vec![0.002, 0.01, 0.05],
            feedback_kp: vec![0.0, 0.25, 0.5, 1.0],
            feedback_ki: vec![0.0, 5.0, 20.0],
        }
    }
}

impl TuneGrid {
    /// Number of points.
    #[must_use]
    pub fn len(&self) -> usize {
        self.causality_tau_s.len() * self.feedback_kp.len() * self.feedback_ki.len()
    }

    /// Whether the grid is empty.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A grid search of the feedforward + feedback (linear) gains on `scenario` (use a seed other
/// than the reported one): minimises the worst RMS ratio against no control over the alphas.
/// Returns every point, best first. `on_point_done` is called once per point.
pub fn tune(
    scenario: &Scenario,
    set: &CoefficientSet,
    grid: &TuneGrid,
    settings: &SilSettings,
    on_point_done: &(dyn Fn() + Sync),
) -> Result<Vec<TunePoint>, SilError> {
    let quiet = SilSettings { trace_every: 0, ..*settings };
    let baseline = run_scenario(scenario, set, &[Mode::None], &quiet, &|| {})?;
    let mut points = Vec::with_capacity(grid.len());
    let mut candidates = Vec::with_capacity(grid.len());
    for &causality_tau_s in &grid.causality_tau_s {
        for &feedback_kp in &grid.feedback_kp {
            for &feedback_ki in &grid.feedback_ki {
                candidates.push(Gains { causality_tau_s, feedback_kp, feedback_ki });
            }
        }
    }
    for gains in candidates {
        let tuned = gains.apply(set)?;
        let results = run_scenario(scenario, &tuned, &[Mode::FfFbLinear], &quiet, &|| {})?;
        let ratios: Vec<f64> = scenario
            .alphas_deg
            .iter()
            .map(|&alpha| {
                let none = baseline.run(alpha, Mode::None).map_or(f64::NAN, |run| run.metrics.rms_cl);
                let this = results.run(alpha, Mode::FfFbLinear).map_or(f64::NAN, |run| run.metrics.rms_cl);
                this / none
            })
            .collect();
        let objective = ratios.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        points.push(TunePoint { gains, ratios, objective });
        on_point_done();
    }
    points.sort_by(|a, b| a.objective.total_cmp(&b.objective));
    Ok(points)
}
