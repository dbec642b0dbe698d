//! The blind validation campaign of the diagnosis (`validate-diagnosis`;
//! docs/diagnosis.md, Validation campaigns): seeded cases, each a dataset recorded by the synthetic
//! tunnel with one effect of the vocabulary, no effect, or an effect outside the vocabulary, at a
//! random angle of attack and a random magnitude (effect RMS from 0.5 to 4 times the noise RMS of
//! the stream it acts on). The model is fitted on a clean dataset of the same design; the diagnosis
//! sees only the recording (its provenance keys stripped) and the model; the truth is sealed
//! (SHA-256 recorded) before the diagnosis runs and read only by the scorer.
//!
//! The injection is the tunnel's own code (firmware_sim::tunnel::effects: RK4-integrated
//! continuous-time states, fractional delays), written apart from the diagnosis's candidates.

pub mod external;
pub mod score;

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::Instant;

use estimator_core::CoefficientSet;
use firmware_sim::campaign::{Scenario, mix_seed};
use firmware_sim::dataset::Dataset;
use firmware_sim::effect::Effect;
use firmware_sim::tunnel::effects::{
    ActuatorDelay, ActuatorLag, BalanceResonance, BiasDrift, Coupling, CubicStiffness, Effects, FaultMode, GravityTare,
    InertialTare, PressureFault, PressureLag, QFluctuation, RollDamping, VortexLag,
};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;

use crate::diagnose::result::Diagnosis;
use crate::diagnose::{DiagnoseConfig, Signature, diagnose};
use model_fit::fit::pipeline::{FitConfig, fit_dataset};

/// Classes of case, in the order cases cycle through them: no effect (`None`), every effect of
/// the vocabulary, every effect outside it.
#[must_use]
pub fn classes() -> Vec<Option<Effect>> {
    std::iter::once(None).chain(Effect::ALL.map(Some)).collect()
}

/// The name of a class as written in the records: the effect's, or `none`.
#[must_use]
pub fn class_name(class: Option<Effect>) -> &'static str {
    class.map_or("none", Effect::name)
}

/// The class a record's name stands for (`None` for `none` or a name that is no effect).
#[must_use]
pub fn class_of(name: &str) -> Option<Effect> {
    name.parse().ok()
}

/// True for the classes outside the diagnosis vocabulary: every class but `none` and the
/// vocabulary's names (another program's campaign may inject outside effects this tunnel has
/// no name for: a tone, encoder backlash, balance saturation).
#[must_use]
pub fn outside_vocabulary(class: &str) -> bool {
    class != "none" && !class_of(class).is_some_and(Effect::in_vocabulary)
}

/// Settings of a campaign.
#[derive(Debug, Clone, PartialEq)]
pub struct CampaignConfig {
    /// Number of cases (they cycle through [`classes`]).
    pub cases: usize,
    /// Master seed.
    pub seed: u64,
    /// Duration of every run, s.
    pub duration_s: f64,
    /// Angles of attack a case draws from, deg.
    pub alphas_deg: Vec<f64>,
    /// Range of the effect RMS over the noise RMS (drawn log-uniformly).
    pub ratio_range: [f64; 2],
    /// Only these classes (all when empty).
    pub classes: Vec<String>,
    /// Keep every case's recording and model here (`case-NNN/data`, `case-NNN/model.bin`,
    /// `case-NNN/diagnosis-signature.json`), to reproduce a case with `diagnose`.
    pub keep: Option<std::path::PathBuf>,
    /// Only the cases with these ids, drawn as the whole campaign draws them (all when empty):
    /// a case's draw depends on the master seed and its id alone, so one case of a campaign
    /// is diagnosed again without the others.
    pub only: Vec<usize>,
}

impl Default for CampaignConfig {
    fn default() -> Self {
        Self {
            cases: 140,
            seed: 1,
            duration_s: 30.0,
            alphas_deg: (0..=8).map(|i| 2.5 * f64::from(i)).collect(),
            ratio_range: [0.5, 4.0],
            classes: Vec::new(),
            keep: None,
            only: Vec::new(),
        }
    }
}

/// One case: what was injected (sealed until scoring) and what the diagnosis said.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CaseRecord {
    /// Case number.
    pub id: usize,
    /// Injected class (`none`, an effect name).
    pub class: String,
    /// Angle of attack, deg.
    pub alpha_deg: f64,
    /// Target effect RMS over noise RMS.
    pub target_ratio: f64,
    /// Achieved effect RMS over noise RMS on the stream it acts on (infinite for a dead channel
    /// written as null).
    pub ratio: Option<f64>,
    /// The injected effect's parameters (TOML of the scenario's `[effects]`).
    pub truth: String,
    /// SHA-256 of the truth, recorded before the diagnosis ran.
    pub truth_sha256: String,
    /// The injected channels, for sensor effects (one for a fault; one, some or all for a lag).
    pub truth_channels: Vec<String>,
    /// The injected channels that the diagnosis must name: those whose own effect-to-noise
    /// ratio is at least one, where the truth gives a ratio per channel, else all of them. The
    /// contract lets an effect below a ratio of one be missed (docs/spec/diagnosis.md, "The
    /// verdict `none`"); a lag of ten channels with 5 ms on one of them may leave that one at
    /// the noise floor.
    pub required_channels: Vec<String>,
    /// The diagnosis's verdict.
    pub verdict: String,
    /// Named effects, most responsible first.
    pub named: Vec<String>,
    /// The channels the diagnosis named for a sensor effect.
    pub named_channels: Vec<String>,
    /// The first named effect's fitted parameters (its form included), for the parameter
    /// recovery of a campaign whose truth states them.
    pub named_params: std::collections::BTreeMap<String, serde_json::Value>,
    /// Held-out shrink of the first named effect (beyond the sim's own floor); `None` where it
    /// is not measured (a dead channel has no reading left to compare: its 1 is by definition).
    pub shrink: Option<f64>,
    /// The same against the whole held-out gap beyond noise.
    pub shrink_total: Option<f64>,
    /// Scored as right.
    pub correct: bool,
    /// Seconds of the diagnosis.
    pub diagnosis_s: f64,
}

/// The classes a campaign's cases cycle through: [`classes`], or those of `config.classes`.
fn campaign_classes(config: &CampaignConfig) -> Vec<Option<Effect>> {
    if config.classes.is_empty() {
        classes()
    } else {
        classes().into_iter().filter(|c| config.classes.iter().any(|k| k == class_name(*c))).collect()
    }
}

/// The ids of a campaign's cases: every one below `config.cases`, or those of `config.only`.
#[must_use]
pub fn case_ids(config: &CampaignConfig) -> Vec<usize> {
    (0..config.cases).filter(|id| config.only.is_empty() || config.only.contains(id)).collect()
}

/// Runs the campaign; `progress` is called once per finished case.
pub fn run_campaign(config: &CampaignConfig, progress: &(dyn Fn() + Sync)) -> Vec<CaseRecord> {
    let models = CleanModels::default();
    let mut records: Vec<CaseRecord> = case_ids(config)
        .into_par_iter()
        .filter_map(|id| {
            let record = run_case(config, id, &models);
            progress();
            record
        })
        .collect();
    records.sort_by_key(|r| r.id);
    records
}

fn base_scenario(config: &CampaignConfig, alpha_deg: f64, seed: u64) -> Scenario {
    Scenario { seed, duration_s: config.duration_s, alphas_deg: vec![alpha_deg], ..Scenario::default() }
}

/// The model of a case: fitted on a clean recording at the case's angle of attack (one per
/// angle, shared by the cases that draw it).
///
/// The clean recording is twice as long as a case's, so that the model's diagnosis signature
/// (taken on its held-out part, as `fit` does) rests on as many samples as a case's training part.
fn clean_model(config: &CampaignConfig, alpha_deg: f64, models: &CleanModels) -> Option<(CoefficientSet, Signature)> {
    let key = alpha_deg.to_bits();
    if let Some(entry) = models.0.lock().ok()?.get(&key) {
        return Some(entry.clone());
    }
    let mut scenario = base_scenario(config, alpha_deg, mix_seed(config.seed, 0xC1EA_0000 + key % 1000));
    scenario.duration_s *= 2.0;
    let dataset = scenario.simulate(&|| {}).ok()?;
    let set = fit_dataset(&dataset, &FitConfig::default(), &|_| {}).ok()?.set;
    let signature = crate::diagnose::signature(&dataset, &set, FitConfig::default().split).ok()?;
    models.0.lock().ok()?.insert(key, (set, signature.clone()));
    Some((set, signature))
}

/// Clean models and their signatures, per angle of attack: fitted once, shared by the cases of
/// a campaign that draw the angle.
#[derive(Debug, Default)]
pub struct CleanModels(Mutex<HashMap<u64, (CoefficientSet, Signature)>>);

/// One case as drawn, before it is diagnosed: the recording the diagnosis sees (its provenance
/// stripped), the model fitted on a clean recording and its signature, and the truth, sealed.
#[derive(Debug, Clone)]
pub struct DrawnCase {
    /// The recording, blind.
    pub real: Dataset,
    /// The sim: fitted on a clean recording at the case's angle of attack.
    pub set: CoefficientSet,
    /// The sim's diagnosis signature.
    pub signature: Signature,
    /// What was injected: for the scorer only.
    pub sealed: Sealed,
}

/// The truth of a case, with its hash recorded when it was drawn: read only by the scorer,
/// after the diagnosis ([`Sealed::score`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Sealed {
    id: usize,
    class: String,
    alpha_deg: f64,
    target_ratio: f64,
    ratio: Option<f64>,
    truth: String,
    truth_sha256: String,
    truth_channels: Vec<String>,
    required_channels: Vec<String>,
}

impl Sealed {
    /// The case's id.
    #[must_use]
    pub fn id(&self) -> usize {
        self.id
    }

    /// The case scored: the truth against what the diagnosis said.
    #[must_use]
    pub fn score(self, diagnosed: Diagnosed) -> CaseRecord {
        let mut record = CaseRecord {
            id: self.id,
            class: self.class,
            alpha_deg: self.alpha_deg,
            target_ratio: self.target_ratio,
            ratio: self.ratio,
            truth: self.truth,
            truth_sha256: self.truth_sha256,
            truth_channels: self.truth_channels,
            required_channels: self.required_channels,
            verdict: diagnosed.verdict,
            named: diagnosed.named,
            named_channels: diagnosed.named_channels,
            named_params: diagnosed.named_params,
            shrink: diagnosed.shrink,
            shrink_total: diagnosed.shrink_total,
            correct: false,
            diagnosis_s: diagnosed.diagnosis_s,
        };
        record.correct = score::is_correct(&record);
        record
    }
}

/// What a case's diagnosis said, as the scorer reads it: the verdict, the named effects, the
/// channels, the first effect's parameters and its held-out shrink where it is measured.
#[derive(Debug, Clone, PartialEq)]
pub struct Diagnosed {
    /// The verdict's word, or `error: ...` when the diagnosis failed.
    pub verdict: String,
    /// Named effects, most responsible first.
    pub named: Vec<String>,
    /// The channels named for a sensor effect.
    pub named_channels: Vec<String>,
    /// The first named effect's parameters.
    pub named_params: std::collections::BTreeMap<String, serde_json::Value>,
    /// Held-out shrink of the first named effect, where measured.
    pub shrink: Option<f64>,
    /// The same against the whole held-out gap.
    pub shrink_total: Option<f64>,
    /// Seconds of the diagnosis.
    pub diagnosis_s: f64,
}

impl Diagnosed {
    /// What `outcome` said (its error's message when it failed), in `diagnosis_s` seconds.
    #[must_use]
    pub fn of(outcome: Result<&Diagnosis, String>, diagnosis_s: f64) -> Self {
        match outcome {
            Ok(diagnosis) => {
                let first = diagnosis.effects.first().filter(|e| e.shrink_measured);
                Self {
                    verdict: diagnosis.verdict.as_str().to_owned(),
                    named: diagnosis.effects.iter().map(|e| e.name.clone()).collect(),
                    named_channels: diagnosis.where_.channels.clone(),
                    named_params: diagnosis.effects.first().map(|e| e.params.clone()).unwrap_or_default(),
                    shrink: first.map(|e| e.shrink),
                    shrink_total: first.map(|e| e.shrink_total),
                    diagnosis_s,
                }
            }
            Err(message) => Self {
                verdict: format!("error: {message}"),
                named: Vec::new(),
                named_channels: Vec::new(),
                named_params: std::collections::BTreeMap::new(),
                shrink: None,
                shrink_total: None,
                diagnosis_s,
            },
        }
    }

    /// What a `diagnosis.json` says (the contract of docs/spec/diagnosis.md, "Machine-readable
    /// result"): a diagnosis run elsewhere (another process or machine) scored here. A field the
    /// contract requires but the file lacks reads as nothing named.
    #[must_use]
    pub fn from_contract(json: &serde_json::Value, diagnosis_s: f64) -> Self {
        let effects = json["effects"].as_array().map(Vec::as_slice).unwrap_or_default();
        let first = effects.first();
        let measured = first.filter(|e| e["shrink_measured"].as_bool().unwrap_or(true));
        let strings = |value: &serde_json::Value| -> Vec<String> {
            value
                .as_array()
                .map(|items| items.iter().filter_map(|v| v.as_str().map(str::to_owned)).collect())
                .unwrap_or_default()
        };
        Self {
            verdict: json["verdict"].as_str().unwrap_or("error: no verdict").to_owned(),
            named: effects.iter().filter_map(|e| e["name"].as_str().map(str::to_owned)).collect(),
            named_channels: strings(&json["where"]["channels"]),
            named_params: first
                .and_then(|e| e["params"].as_object())
                .map(|params| params.iter().map(|(k, v)| (k.clone(), v.clone())).collect())
                .unwrap_or_default(),
            shrink: measured.and_then(|e| e["shrink"].as_f64()),
            shrink_total: measured.and_then(|e| e["shrink_total"].as_f64()),
            diagnosis_s,
        }
    }
}

/// Draws case `id` of the campaign as [`run_campaign`] does (its draw depends on the master
/// seed and the id alone): the recording, blind, its model and the sealed truth. `None` when
/// the clean recording cannot be fitted or the effect cannot be calibrated.
#[must_use]
pub fn draw_case(config: &CampaignConfig, id: usize, models: &CleanModels) -> Option<DrawnCase> {
    let classes = campaign_classes(config);
    if classes.is_empty() {
        return None;
    }
    let class = classes[id % classes.len()];
    let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(config.seed, 7_000 + id as u64));
    let alpha_deg = config.alphas_deg[rng.random_range(0..config.alphas_deg.len())];
    let [low, high] = config.ratio_range;
    let target_ratio = if class.is_none() { 0.0 } else { (low.ln() + rng.random::<f64>() * (high / low).ln()).exp() };
    let case_seed = mix_seed(config.seed, 9_000 + id as u64);
    let base = base_scenario(config, alpha_deg, case_seed);
    let (set, signature) = clean_model(config, alpha_deg, models)?;
    let clean = base.simulate(&|| {}).ok()?;
    let (effects, truth_channels) = draw_effect(class, &base, &mut rng);
    let (effects, ratio) = calibrate(class, &base, &clean, effects, target_ratio)?;
    let mut scenario = base;
    scenario.effects = effects.clone();
    let mut real = scenario.simulate(&|| {}).ok()?;
    blind(&mut real);
    let truth = format!("{effects:?}");
    let truth_sha256 = model_fit::digest::sha256_hex(truth.as_bytes());
    let sealed = Sealed {
        id,
        class: class_name(class).to_owned(),
        alpha_deg,
        target_ratio,
        ratio,
        truth,
        truth_sha256,
        required_channels: truth_channels.clone(),
        truth_channels,
    };
    Some(DrawnCase { real, set, signature, sealed })
}

fn run_case(config: &CampaignConfig, id: usize, models: &CleanModels) -> Option<CaseRecord> {
    let DrawnCase { real, set, signature, sealed } = draw_case(config, id, models)?;
    if let Some(keep) = &config.keep {
        let dir = keep.join(format!("case-{id:03}"));
        let _ = std::fs::create_dir_all(&dir);
        let _ = firmware_sim::dataset::write_dataset(&dir.join("data"), &real);
        if let Ok(blob) = model_fit::model::encode(&set) {
            let _ = std::fs::write(dir.join(model_fit::model::BLOB_FILE), blob);
        }
        let _ = std::fs::write(
            dir.join(crate::diagnose::SIGNATURE_FILE),
            serde_json::to_string_pretty(&signature).unwrap_or_default(),
        );
    }
    let clock = Instant::now();
    let diagnose_config = DiagnoseConfig { signature: Some(signature), ..DiagnoseConfig::default() };
    let outcome = diagnose(&real, Some((&set, "fitted on a clean recording".into())), &diagnose_config, &|_| {});
    let diagnosis_s = clock.elapsed().as_secs_f64();
    let diagnosed = Diagnosed::of(outcome.as_ref().map(|(d, _)| d).map_err(ToString::to_string), diagnosis_s);
    Some(sealed.score(diagnosed))
}

/// Strips what would tell the answer: the provenance keys the tunnel writes into the manifest
/// and the runs (effect names, seeds).
fn blind(dataset: &mut Dataset) {
    dataset.extra.clear();
    for run in &mut dataset.runs {
        run.meta.extra.clear();
    }
}

/// A random setting of the class's effect at a reference magnitude (later scaled), and the
/// channels of a sensor effect.
fn draw_effect(class: Option<Effect>, base: &Scenario, rng: &mut ChaCha8Rng) -> (Effects, Vec<String>) {
    let mut effects = Effects::default();
    let mut channel = Vec::new();
    let sign = |rng: &mut ChaCha8Rng| if rng.random::<bool>() { 1.0 } else { -1.0 };
    let log_uniform =
        |rng: &mut ChaCha8Rng, low: f64, high: f64| (low.ln() + rng.random::<f64>() * (high / low).ln()).exp();
    let Some(effect) = class else { return (effects, channel) };
    match effect {
        Effect::ActuatorDelay => effects.actuator_delay = Some(ActuatorDelay { delay_s: 0.02 }),
        Effect::ActuatorLag => effects.actuator_lag = Some(ActuatorLag { tau_s: 0.03 }),
        Effect::InertialTare => effects.inertial_tare = Some(InertialTare { ixx_kgm2: 1e-5 * sign(rng) }),
        Effect::GravityTare => {
            effects.gravity_tare =
                Some(GravityTare { mass_kg: 0.13, cg_offset_m: 5e-4, phase_deg: rng.random_range(-40.0..40.0) });
        }
        Effect::RollDamping => effects.roll_damping = Some(RollDamping { clp: -0.03 * log_uniform(rng, 0.5, 2.0) }),
        Effect::VortexLag => {
            effects.vortex_lag = Some(VortexLag { tau_s: log_uniform(rng, 0.2, 2.0), weight: 0.3 });
        }
        Effect::Coupling => effects.coupling = Some(Coupling { gain: 0.3 * sign(rng) }),
        Effect::PressureLag => {
            // One channel, a group of two to six (one tube bundle, one scanner module), or all.
            let form = rng.random::<f64>();
            let channels = if form < 0.3 {
                vec![rng.random_range(1..=12usize)]
            } else if form < 0.6 {
                let mut taps: Vec<usize> = (1..=12).collect();
                taps.shuffle(rng);
                let mut group = taps[..rng.random_range(2..=6usize)].to_vec();
                group.sort_unstable();
                group
            } else {
                Vec::new()
            };
            channel = if channels.is_empty() {
                (1..=12).map(|tap| format!("cp{tap:02}")).collect()
            } else {
                channels.iter().map(|tap| format!("cp{tap:02}")).collect()
            };
            effects.pressure_lag = Some(PressureLag { tau_s: 0.02, channels });
        }
        Effect::PressureFault => {
            let ch = rng.random_range(1..=12usize);
            channel = vec![format!("cp{ch:02}")];
            let mode = [FaultMode::Bias, FaultMode::Spike, FaultMode::Stuck, FaultMode::Dead][rng.random_range(0..4)];
            effects.pressure_fault = Some(PressureFault {
                channel: ch,
                mode,
                value: 0.01 * sign(rng),
                spike_rate_hz: rng.random_range(2.0..10.0),
                start_s: rng.random_range(0.0..0.5 * base.duration_s),
            });
        }
        Effect::BalanceResonance => {
            effects.balance_resonance = Some(BalanceResonance {
                freq_hz: log_uniform(rng, 8.0, 60.0),
                zeta: log_uniform(rng, 0.01, 0.1),
                gain: 0.01,
            });
        }
        Effect::BiasDrift => {
            let walk = if rng.random::<bool>() { 2e-5 } else { 0.0 };
            effects.bias_drift = Some(BiasDrift { rate_per_s: 2e-5 * sign(rng), walk_per_sqrt_s: walk });
        }
        Effect::QFluctuation => {
            effects.q_fluctuation = Some(QFluctuation { rel_std: 0.03, tau_s: log_uniform(rng, 0.2, 2.0) })
        }
        Effect::CubicStiffness => effects.cubic_stiffness = Some(CubicStiffness { gain: 0.002 * sign(rng) }),
    }
    (effects, channel)
}

/// RMS of what the effect adds to the stream it acts on (the balance, or the pressure channels
/// for sensor effects), over the runs and channels it touches, divided by that stream's noise
/// RMS; `None` when the effect removes the readings (a dead channel).
#[must_use]
pub fn effect_ratio(effect: Effect, base: &Scenario, clean: &Dataset, real: &Dataset) -> Option<f64> {
    let sensor = effect.is_sensor();
    let noise = if sensor { base.sensors.cp_noise_std } else { base.sensors.balance_noise_std_cl };
    let mut streams: Vec<(&[f64], &[f64])> = Vec::new();
    for (a, b) in clean.runs.iter().zip(&real.runs) {
        if sensor {
            for tap in 0..a.channels.cp.len() {
                streams.push((&a.channels.cp[tap], &b.channels.cp[tap]));
            }
        } else {
            streams.push((&a.channels.cl, &b.channels.cl));
        }
    }
    let (mut sum, mut count) = (0.0, 0usize);
    for (a, b) in streams {
        let diffs: Vec<f64> = a.iter().zip(b).map(|(x, y)| y - x).collect();
        if diffs.iter().any(|d| d.is_nan()) && a.iter().all(|x| x.is_finite()) {
            return None;
        }
        if diffs.iter().all(|d| d.abs() < 1e-12) {
            continue;
        }
        sum += diffs.iter().filter(|d| d.is_finite()).map(|d| d * d).sum::<f64>();
        count += diffs.len();
    }
    if count == 0 {
        return Some(0.0);
    }
    Some((sum / count as f64).sqrt() / noise)
}

/// Scales the effect so that its ratio meets `target` (linearly for amplitude parameters, by
/// bisection in log space for delays and time constants), and returns the ratio reached.
fn calibrate(
    class: Option<Effect>,
    base: &Scenario,
    clean: &Dataset,
    mut effects: Effects,
    target: f64,
) -> Option<(Effects, Option<f64>)> {
    let Some(effect) = class else { return Some((effects, Some(0.0))) };
    let measure = |effects: &Effects| -> Option<Option<f64>> {
        let mut scenario = base.clone();
        scenario.effects = effects.clone();
        let real = scenario.simulate(&|| {}).ok()?;
        Some(effect_ratio(effect, base, clean, &real))
    };
    if let Some(fault) = &effects.pressure_fault
        && matches!(fault.mode, FaultMode::Stuck | FaultMode::Dead)
    {
        let ratio = measure(&effects)?;
        return Some((effects, ratio));
    }
    let bisect = |effects: &mut Effects, set: &dyn Fn(&mut Effects, f64), low: f64, high: f64| -> Option<Option<f64>> {
        let (mut lo, mut hi) = (low.ln(), high.ln());
        let mut last = None;
        for _ in 0..12 {
            let mid = 0.5 * (lo + hi);
            set(effects, mid.exp());
            last = measure(effects)?;
            let ratio = last.unwrap_or(f64::INFINITY);
            if (ratio / target - 1.0).abs() < 0.03 {
                break;
            }
            if ratio > target { hi = mid } else { lo = mid }
        }
        Some(last)
    };
    let ratio = match effect {
        Effect::ActuatorDelay => {
            bisect(&mut effects, &|e, v| e.actuator_delay = Some(ActuatorDelay { delay_s: v }), 2e-4, 0.5)?
        }
        Effect::ActuatorLag => {
            bisect(&mut effects, &|e, v| e.actuator_lag = Some(ActuatorLag { tau_s: v }), 5e-4, 1.0)?
        }
        Effect::PressureLag => {
            let channels = effects.pressure_lag.as_ref().map(|p| p.channels.clone()).unwrap_or_default();
            bisect(
                &mut effects,
                &move |e, v| e.pressure_lag = Some(PressureLag { tau_s: v, channels: channels.clone() }),
                2e-4,
                0.5,
            )?
        }
        _ => {
            let reference = measure(&effects)?.unwrap_or(0.0);
            if reference <= 0.0 {
                return Some((effects, Some(0.0)));
            }
            let mut factor = target / reference;
            if let Some(vortex) = &mut effects.vortex_lag {
                // The share of the slow state cannot exceed one.
                factor = factor.min(1.0 / vortex.weight);
            }
            scale(&mut effects, factor);
            measure(&effects)?
        }
    };
    Some((effects, ratio))
}

/// Multiplies the amplitude parameter of every switched-on effect by `factor`.
fn scale(effects: &mut Effects, factor: f64) {
    if let Some(e) = &mut effects.inertial_tare {
        e.ixx_kgm2 *= factor;
    }
    if let Some(e) = &mut effects.gravity_tare {
        e.cg_offset_m *= factor;
    }
    if let Some(e) = &mut effects.roll_damping {
        e.clp *= factor;
    }
    if let Some(e) = &mut effects.vortex_lag {
        e.weight *= factor;
    }
    if let Some(e) = &mut effects.coupling {
        e.gain *= factor;
    }
    if let Some(e) = &mut effects.pressure_fault {
        e.value *= factor;
    }
    if let Some(e) = &mut effects.balance_resonance {
        e.gain *= factor;
    }
    if let Some(e) = &mut effects.bias_drift {
        e.rate_per_s *= factor;
        e.walk_per_sqrt_s *= factor;
    }
    if let Some(e) = &mut effects.q_fluctuation {
        e.rel_std *= factor;
    }
    if let Some(e) = &mut effects.cubic_stiffness {
        e.gain *= factor;
    }
}
