//! Scenarios and campaigns: which runs the synthetic tunnel records, with which inputs, at
//! which angles of attack, and with which effects.
//!
//! The default scenario is the paper's campaign (sections IV and V): three kinds (roll,
//! actuation, roll+actuation with the blowing signal delayed 8 s) at alpha 0, 10 and 20 deg,
//! 50 s each at 1 kHz. The kinds at one alpha share the same roll and blowing sequences (with
//! independent noise), so the superposition difference `C_l,RollAFC - C_l,Roll - C_l,AFC` can
//! be formed sample by sample.

use std::path::Path;

use rayon::prelude::*;
use serde::Deserialize;

use crate::dataset::{Channels, Dataset, Run, RunKind, RunMeta, Tunnel, Wing};
use crate::tunnel::effects::Effects;
use crate::tunnel::excitation::{HoldDesign, HoldSequence};
use crate::tunnel::params::{ActuatorParams, AeroParams, RigParams, SensorParams};
use crate::tunnel::{RunSpec, TunnelConditions, TunnelConfig, simulate_run};

/// Errors of reading or completing a scenario.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The scenario file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The scenario file is not valid TOML or has unknown or mistyped keys.
    #[error("{path}: {message}")]
    Toml {
        /// The file.
        path: String,
        /// What the TOML parser said (it names the key and line).
        message: String,
    },
    /// An `--effect` argument could not be understood.
    #[error("effect \"{arg}\": {message}")]
    BadEffect {
        /// The argument as given.
        arg: String,
        /// What is wrong with it.
        message: String,
    },
    /// A value is out of its range.
    #[error("scenario key {key}: {message}")]
    Invalid {
        /// The key.
        key: &'static str,
        /// What was expected.
        message: String,
    },
}

/// Which trailing-edge jets a campaign blows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum BlowingSides {
    /// The port jet only, as in the paper.
    #[default]
    Port,
    /// The starboard jet only.
    Starboard,
    /// Both jets, with independent sequences.
    Both,
}

/// A scenario: everything the tunnel needs to record a dataset. Every key is optional in the
/// TOML file; missing keys take the paper's values.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Scenario {
    /// Master seed: input sequences and noise derive from it.
    pub seed: u64,
    /// Duration of every run, s.
    pub duration_s: f64,
    /// Sample rate, Hz.
    pub sample_hz: f64,
    /// Angles of attack, deg.
    pub alphas_deg: Vec<f64>,
    /// Kinds of run at each angle of attack.
    pub kinds: Vec<KindName>,
    /// Which jets blow.
    pub blowing_sides: BlowingSides,
    /// Free-stream conditions.
    pub tunnel: TunnelSection,
    /// Wing geometry and inertia.
    pub wing: WingSection,
    /// Disturbance aerodynamics.
    pub aero: AeroParams,
    /// Blowing actuators.
    pub actuator: ActuatorParams,
    /// Sensors.
    pub sensors: SensorParams,
    /// Roll rig.
    pub rig: RigParams,
    /// Input designs.
    pub excitation: Excitation,
    /// Switched-on effects (`[effects.NAME]` tables); all off by default.
    pub effects: Effects,
}

impl Default for Scenario {
    fn default() -> Self {
        let actuator = ActuatorParams::default();
        Self {
            seed: 1,
            duration_s: 50.0,
            sample_hz: 1000.0,
            alphas_deg: vec![0.0, 10.0, 20.0],
            kinds: vec![KindName(RunKind::Roll), KindName(RunKind::Actuation), KindName(RunKind::RollActuation)],
            blowing_sides: BlowingSides::Port,
            tunnel: TunnelSection::default(),
            wing: WingSection::default(),
            aero: AeroParams::default(),
            actuator,
            sensors: SensorParams::default(),
            rig: RigParams::default(),
            excitation: Excitation {
                roll_deg: HoldDesign::paper_roll_deg(),
                blowing: HoldDesign::paper_blowing(actuator.cmu_max),
            },
            effects: Effects::default(),
        }
    }
}

/// A run kind as spelled in the manifest (`"roll+actuation"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KindName(pub RunKind);

impl<'de> Deserialize<'de> for KindName {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let text = String::deserialize(deserializer)?;
        RunKind::parse(&text).map(KindName).ok_or_else(|| {
            serde::de::Error::custom(format!(
                "unknown kind \"{text}\", expected \"roll\", \"actuation\", \"roll+actuation\" or \"static\""
            ))
        })
    }
}

/// `[tunnel]` of a scenario.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TunnelSection {
    /// Free-stream speed, m/s.
    pub u_inf_mps: f64,
    /// Air density, kg/m^3.
    pub rho_kgm3: f64,
}

impl Default for TunnelSection {
    fn default() -> Self {
        let TunnelConditions(tunnel) = TunnelConditions::default();
        Self { u_inf_mps: tunnel.u_inf_mps, rho_kgm3: tunnel.rho_kgm3 }
    }
}

/// `[wing]` of a scenario.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WingSection {
    /// Root chord, m.
    pub chord_m: f64,
    /// Span, m.
    pub span_m: f64,
    /// Planform area, m^2.
    pub area_m2: f64,
    /// Roll inertia, kg m^2.
    pub ixx_kgm2: f64,
    /// Mass, kg.
    pub mass_kg: f64,
}

impl Default for WingSection {
    fn default() -> Self {
        let wing = Wing::PAPER;
        Self {
            chord_m: wing.chord_m,
            span_m: wing.span_m,
            area_m2: wing.area_m2,
            ixx_kgm2: wing.ixx_kgm2,
            mass_kg: wing.mass_kg,
        }
    }
}

/// `[excitation]` of a scenario: the designs of the random inputs with holds.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Excitation {
    /// Roll command, deg.
    pub roll_deg: HoldDesign,
    /// Blowing command, Cmu.
    pub blowing: HoldDesign,
}

impl Default for Excitation {
    fn default() -> Self {
        Scenario::default().excitation
    }
}

impl Scenario {
    /// Reads a scenario file; keys it does not set keep the paper's values.
    pub fn from_file(path: &Path) -> Result<Self, ScenarioError> {
        let bytes =
            std::fs::read(path).map_err(|source| ScenarioError::Io { path: path.display().to_string(), source })?;
        Self::from_bytes(&path.display().to_string(), &bytes)
    }

    /// Parses the bytes of a scenario file, named `path` in errors, as [`Scenario::from_file`]
    /// does: the fuzzer's entry point (`cargo xtask fuzz --target scenario`).
    pub fn from_bytes(path: &str, bytes: &[u8]) -> Result<Self, ScenarioError> {
        let text = std::str::from_utf8(bytes).map_err(|err| ScenarioError::Io {
            path: path.to_owned(),
            source: std::io::Error::new(std::io::ErrorKind::InvalidData, err),
        })?;
        Self::from_toml(text).map_err(|message| ScenarioError::Toml { path: path.to_owned(), message })
    }

    /// Parses a scenario from TOML text.
    pub fn from_toml(text: &str) -> Result<Self, String> {
        toml::from_str(text).map_err(|error| error.to_string().trim_end().to_owned())
    }

    /// Switches an effect on from a command-line argument `NAME` or `NAME:key=value,...`, for
    /// example `actuator_delay:delay_s=0.03` or `pressure_fault:channel=3,mode=dead`.
    pub fn apply_effect_arg(&mut self, arg: &str) -> Result<(), ScenarioError> {
        let bad = |message: String| ScenarioError::BadEffect { arg: arg.to_owned(), message };
        let (name, settings) = arg.split_once(':').unwrap_or((arg, ""));
        let mut table = format!("[{}]\n", name.trim());
        for setting in settings.split(',').map(str::trim).filter(|setting| !setting.is_empty()) {
            let (key, value) =
                setting.split_once('=').ok_or_else(|| bad(format!("expected key=value, found \"{setting}\"")))?;
            table.push_str(&format!("{} = {}\n", key.trim(), toml_value(value.trim())));
        }
        let effect: Effects = toml::from_str(&table).map_err(|error| bad(error.message().to_owned()))?;
        self.effects.merge(effect);
        Ok(())
    }

    /// Checks the ranges that the TOML types cannot express.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        let invalid = |key, message: &str| Err(ScenarioError::Invalid { key, message: message.to_owned() });
        if !(self.duration_s.is_finite() && self.duration_s > 0.0) {
            return invalid("duration_s", "expected a positive number of seconds");
        }
        if !(self.sample_hz.is_finite() && self.sample_hz > 0.0) {
            return invalid("sample_hz", "expected a positive rate");
        }
        if self.alphas_deg.is_empty() || self.alphas_deg.iter().any(|alpha| !alpha.is_finite()) {
            return invalid("alphas_deg", "expected at least one finite angle of attack");
        }
        if self.kinds.is_empty() {
            return invalid("kinds", "expected at least one kind of run");
        }
        if self.rig.substeps == 0 {
            return invalid("rig.substeps", "expected at least one substep per sample");
        }
        if let Some(fault) = self.effects.pressure_fault
            && !(1..=12).contains(&fault.channel)
        {
            return invalid("effects.pressure_fault.channel", "expected a channel from 1 to 12");
        }
        Ok(())
    }

    /// The tunnel configuration of this scenario.
    #[must_use]
    pub fn tunnel_config(&self) -> TunnelConfig {
        TunnelConfig {
            tunnel: TunnelConditions(self.tunnel_conditions()),
            wing: self.wing(),
            aero: self.aero,
            actuator: self.actuator,
            sensors: self.sensors,
            rig: self.rig,
            effects: self.effects.clone(),
        }
    }

    fn tunnel_conditions(&self) -> Tunnel {
        Tunnel { u_inf_mps: self.tunnel.u_inf_mps, rho_kgm3: self.tunnel.rho_kgm3 }
    }

    fn wing(&self) -> Wing {
        let wing = self.wing;
        Wing {
            chord_m: wing.chord_m,
            span_m: wing.span_m,
            area_m2: wing.area_m2,
            ixx_kgm2: wing.ixx_kgm2,
            mass_kg: wing.mass_kg,
        }
    }

    /// The runs of the campaign, in manifest order (by alpha, then kind).
    #[must_use]
    pub fn run_specs(&self) -> Vec<RunSpec> {
        let roll = self.excitation.roll_deg.draw(self.duration_s, &mut seeded(self.seed, 1));
        let blowing = [
            self.excitation.blowing.draw(self.duration_s, &mut seeded(self.seed, 2)),
            self.excitation.blowing.draw(self.duration_s, &mut seeded(self.seed, 3)),
        ];
        let mut specs = Vec::new();
        for (alpha_idx, &alpha_deg) in self.alphas_deg.iter().enumerate() {
            for &KindName(kind) in &self.kinds {
                let (roll_cmd_deg, blowing_cmd) = self.inputs_of(kind, &roll, &blowing);
                specs.push(RunSpec {
                    kind,
                    alpha_deg,
                    duration_s: self.duration_s,
                    sample_hz: self.sample_hz,
                    roll_cmd_deg,
                    blowing_cmd,
                    noise_seed: mix_seed(self.seed, 100 + 16 * alpha_idx as u64 + kind_index(kind)),
                });
            }
        }
        specs
    }

    fn inputs_of(
        &self,
        kind: RunKind,
        roll: &HoldSequence,
        blowing: &[HoldSequence; 2],
    ) -> (HoldSequence, [HoldSequence; 2]) {
        let sides = match self.blowing_sides {
            BlowingSides::Port => [true, false],
            BlowingSides::Starboard => [false, true],
            BlowingSides::Both => [true, true],
        };
        let blowing_of = |blow: bool| -> [HoldSequence; 2] {
            std::array::from_fn(|side| if blow && sides[side] { blowing[side].clone() } else { HoldSequence::zero() })
        };
        match kind {
            RunKind::Roll => (roll.clone(), blowing_of(false)),
            RunKind::Actuation => (HoldSequence::zero(), blowing_of(true)),
            RunKind::RollActuation => (roll.clone(), blowing_of(true)),
            RunKind::Static => {
                let slow = |design: &HoldDesign, stream| {
                    let mut design = design.clone();
                    design.hold_min_s *= 5.0;
                    design.hold_max_s *= 5.0;
                    design.draw(self.duration_s, &mut seeded(self.seed, stream))
                };
                let blow = slow(&self.excitation.blowing, 5);
                let blowing = std::array::from_fn(|side| if sides[side] { blow.clone() } else { HoldSequence::zero() });
                (slow(&self.excitation.roll_deg, 4), blowing)
            }
        }
    }

    /// Simulates every run (in parallel; each run has its own seeded noise, so the result does
    /// not depend on the order) and assembles the dataset. `on_run_done` is called once per run.
    pub fn simulate(&self, on_run_done: &(dyn Fn() + Sync)) -> Result<Dataset, ScenarioError> {
        self.validate()?;
        let config = self.tunnel_config();
        let specs = self.run_specs();
        let channels: Vec<Channels> = specs
            .par_iter()
            .map(|spec| {
                let channels = simulate_run(&config, spec);
                on_run_done();
                channels
            })
            .collect();
        let runs =
            specs.iter().zip(channels).map(|(spec, channels)| Run { meta: self.run_meta(spec), channels }).collect();
        Ok(Dataset { tunnel: config.tunnel.0, wing: config.wing, extra: self.provenance(), runs })
    }

    fn run_meta(&self, spec: &RunSpec) -> RunMeta {
        let mut extra = toml::Table::new();
        extra.insert("noise_seed".into(), toml::Value::Integer(spec.noise_seed as i64 & i64::MAX));
        RunMeta {
            file: run_file_name(spec.kind, spec.alpha_deg).into(),
            kind: spec.kind,
            alpha_deg: spec.alpha_deg,
            sample_hz: spec.sample_hz,
            extra,
        }
    }

    fn provenance(&self) -> toml::Table {
        let mut extra = toml::Table::new();
        extra.insert("generator".into(), "firmware-sim synthetic wind tunnel".into());
        extra.insert("seed".into(), toml::Value::Integer(self.seed as i64 & i64::MAX));
        let effects = self.effects.on().into_iter().map(|effect| toml::Value::from(effect.name())).collect();
        extra.insert("effects".into(), toml::Value::Array(effects));
        extra
    }
}

impl Effects {
    /// Takes every effect that `other` switches on.
    pub fn merge(&mut self, other: Effects) {
        macro_rules! take {
            ($($field:ident),*) => { $( if other.$field.is_some() { self.$field = other.$field; } )* };
        }
        take!(
            actuator_delay,
            actuator_lag,
            inertial_tare,
            gravity_tare,
            roll_damping,
            vortex_lag,
            coupling,
            pressure_lag,
            pressure_fault,
            balance_resonance,
            bias_drift,
            q_fluctuation,
            cubic_stiffness
        );
    }
}

/// `runs/roll_a10.csv`, `runs/rollact_a12p5.csv`, `runs/act_am5.csv`.
#[must_use]
pub fn run_file_name(kind: RunKind, alpha_deg: f64) -> String {
    let tag = match kind {
        RunKind::Roll => "roll",
        RunKind::Actuation => "act",
        RunKind::RollActuation => "rollact",
        RunKind::Static => "static",
    };
    let alpha = format!("{:02}", alpha_deg.abs()).replace('.', "p");
    let sign = if alpha_deg < 0.0 { "m" } else { "" };
    format!("runs/{tag}_a{sign}{alpha}.csv")
}

fn kind_index(kind: RunKind) -> u64 {
    RunKind::ALL.iter().position(|&other| other == kind).unwrap_or(0) as u64
}

/// A TOML literal for a command-line value: itself when it parses as TOML, else a string.
fn toml_value(text: &str) -> String {
    let parses = toml::from_str::<toml::Table>(&format!("v = {text}")).is_ok();
    if parses { text.to_owned() } else { format!("{text:?}") }
}

/// SplitMix64 of a seed and a stream number: independent streams from one master seed.
#[must_use]
pub fn mix_seed(seed: u64, stream: u64) -> u64 {
    let mut z = seed.wrapping_add(stream.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn seeded(seed: u64, stream: u64) -> rand_chacha::ChaCha8Rng {
    rand::SeedableRng::seed_from_u64(mix_seed(seed, stream))
}
