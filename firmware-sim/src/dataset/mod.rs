//! The on-disk dataset format of wind-tunnel recordings and synthetic runs
//! (`docs/spec/dataset-format.md`): a `manifest.toml` and one CSV file per run.
//!
//! Loading either succeeds completely or fails with a [`DatasetError`] that names the file, the
//! row (1-based, header = row 1) or the key, and what was expected. Missing samples are `NaN` in
//! memory: a missing measurement is never turned into zero.

mod error;
mod manifest;
mod read;
mod write;

pub use error::DatasetError;
pub use manifest::Manifest;
pub use read::{channels_from_columns, load_dataset, load_run, parse_manifest_bytes, parse_run};
pub use write::{check_dataset, write_dataset};

use std::path::PathBuf;

/// The exact format string that every manifest must carry.
pub const FORMAT: &str = "roll-dataset/1";

/// Number of upper-surface pressure taps (`cp01` .. `cp12`).
pub const N_TAPS: usize = 12;

/// Free-stream conditions of the tunnel (`[tunnel]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tunnel {
    /// Free-stream speed, m/s.
    pub u_inf_mps: f64,
    /// Air density, kg/m^3.
    pub rho_kgm3: f64,
}

impl Tunnel {
    /// Dynamic pressure `q = rho U^2 / 2`, Pa.
    #[must_use]
    pub fn dynamic_pressure_pa(&self) -> f64 {
        0.5 * self.rho_kgm3 * self.u_inf_mps * self.u_inf_mps
    }
}

/// Wing geometry and inertia (`[wing]`); defaults are the paper's UCAS model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wing {
    /// Centreline (root) chord, m.
    pub chord_m: f64,
    /// Span, m.
    pub span_m: f64,
    /// Planform area, m^2.
    pub area_m2: f64,
    /// Moment of inertia about the body x-axis, kg m^2.
    pub ixx_kgm2: f64,
    /// Mass of the model, kg.
    pub mass_kg: f64,
}

impl Wing {
    /// The paper's UCAS model (section II): c = 330 mm, b = 287 mm, S = 0.0474 m^2,
    /// I_xx = 3.12e-4 kg m^2, m = 0.130 kg.
    pub const PAPER: Self = Self { chord_m: 0.330, span_m: 0.287, area_m2: 0.0474, ixx_kgm2: 3.12e-4, mass_kg: 0.130 };
}

impl Default for Wing {
    fn default() -> Self {
        Self::PAPER
    }
}

/// Which inputs a run excited.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum RunKind {
    /// Roll motion, no blowing.
    Roll,
    /// Blowing, wing held at phi = 0.
    Actuation,
    /// Roll motion and blowing at once.
    RollActuation,
    /// Holds only.
    Static,
}

impl RunKind {
    /// All kinds, in the order of the format's list.
    pub const ALL: [Self; 4] = [Self::Roll, Self::Actuation, Self::RollActuation, Self::Static];

    /// The manifest spelling (`"roll"`, `"actuation"`, `"roll+actuation"`, `"static"`).
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Roll => "roll",
            Self::Actuation => "actuation",
            Self::RollActuation => "roll+actuation",
            Self::Static => "static",
        }
    }

    /// Parses the manifest spelling; `None` for anything else.
    #[must_use]
    pub fn parse(text: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|kind| kind.as_str() == text)
    }
}

impl std::fmt::Display for RunKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One `[[run]]` table of the manifest.
#[derive(Debug, Clone, PartialEq)]
pub struct RunMeta {
    /// Path of the run file relative to the manifest, as written in the manifest.
    pub file: PathBuf,
    /// Which inputs were excited.
    pub kind: RunKind,
    /// Angle of attack of the run, deg (a per-sample `alpha_deg` column overrides it).
    pub alpha_deg: f64,
    /// Sample rate, Hz.
    pub sample_hz: f64,
    /// Further keys of the run table (notes, seed, ...): allowed, kept, and written back.
    pub extra: toml::Table,
}

/// The channels of one run, one `Vec` per column, all of the same length.
///
/// A missing sample is `f64::NAN`. Optional columns that were absent from the file are `None`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Channels {
    /// Sample time, s.
    pub t_s: Vec<f64>,
    /// Measured roll angle, deg (positive starboard wing down).
    pub phi_deg: Vec<f64>,
    /// Momentum coefficient of the port jet, >= 0.
    pub cmu_port: Vec<f64>,
    /// Momentum coefficient of the starboard jet, >= 0 (all zero when the column is absent).
    pub cmu_stbd: Vec<f64>,
    /// Upper-surface pressure coefficients `cp01` .. `cp12`.
    pub cp: [Vec<f64>; N_TAPS],
    /// Measured roll-moment coefficient `Mx / (q S b)` (converted from `mx_nm` when `cl` is
    /// absent).
    pub cl: Vec<f64>,
    /// Per-sample angle of attack, deg, when logged.
    pub alpha_deg: Option<Vec<f64>>,
    /// Commanded roll angle, deg, when logged.
    pub phi_cmd_deg: Option<Vec<f64>>,
    /// Commanded port momentum coefficient, when logged.
    pub cmu_port_cmd: Option<Vec<f64>>,
    /// Commanded starboard momentum coefficient, when logged.
    pub cmu_stbd_cmd: Option<Vec<f64>>,
}

impl Channels {
    /// Number of samples.
    #[must_use]
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// True when the run has no samples.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// Angle of attack of sample `sample_idx`, deg: the per-sample column when present and
    /// finite, else the run's value.
    #[must_use]
    pub fn alpha_at(&self, sample_idx: usize, run_alpha_deg: f64) -> f64 {
        self.alpha_deg
            .as_ref()
            .and_then(|alpha| alpha.get(sample_idx).copied())
            .filter(|alpha| alpha.is_finite())
            .unwrap_or(run_alpha_deg)
    }
}

/// One run: its manifest entry and its channels.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// The manifest entry.
    pub meta: RunMeta,
    /// The recorded channels.
    pub channels: Channels,
}

/// A whole dataset: tunnel, wing and runs, in manifest order.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// Free-stream conditions.
    pub tunnel: Tunnel,
    /// Wing geometry (the paper's model when the manifest has no `[wing]`).
    pub wing: Wing,
    /// Top-level keys other than `format`, `tunnel`, `wing` and `run`: kept and written back.
    pub extra: toml::Table,
    /// The runs, in manifest order.
    pub runs: Vec<Run>,
}

impl Dataset {
    /// The runs of one kind at one angle of attack (within 1e-6 deg), in manifest order.
    pub fn runs_of(&self, kind: RunKind, alpha_deg: f64) -> impl Iterator<Item = &Run> {
        self.runs.iter().filter(move |run| run.meta.kind == kind && (run.meta.alpha_deg - alpha_deg).abs() < 1e-6)
    }

    /// The distinct angles of attack of the runs, ascending.
    #[must_use]
    pub fn alphas_deg(&self) -> Vec<f64> {
        let mut alphas: Vec<f64> = self.runs.iter().map(|run| run.meta.alpha_deg).collect();
        alphas.sort_by(f64::total_cmp);
        alphas.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
        alphas
    }
}
