//! Why a fit failed.

use firmware_sim::dataset::RunKind;

use super::pressure::PressureFitError;
use sindy::SindyError;

/// Why a dataset could not be fitted.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    /// The dataset lacks runs a block needs.
    #[error("the dataset has no \"{kind}\" runs: {needed_for}")]
    MissingRuns {
        /// The missing kind.
        kind: RunKind,
        /// Which block needs it and why.
        needed_for: &'static str,
    },
    /// The runs were recorded at different rates; the estimator has one fixed step.
    #[error(
        "runs have different sample rates ({first_hz} Hz and {other_hz} Hz in {file}): the estimator runs at one fixed step"
    )]
    MixedRates {
        /// The first run's rate.
        first_hz: f64,
        /// A different rate.
        other_hz: f64,
        /// The run file with the different rate.
        file: String,
    },
    /// More angles of attack than the eGK schedule holds.
    #[error("roll runs at {found} angles of attack ({alphas}), the eGK schedule holds at most {max}")]
    TooManyAlphas {
        /// Number found.
        found: usize,
        /// The angles.
        alphas: String,
        /// The schedule's capacity.
        max: usize,
    },
    /// No plant model could be selected (no candidate stayed finite in free run).
    #[error("no plant model of the {} jet stayed finite when simulated on the held-out samples", if *side == 0 { "port" } else { "starboard" })]
    NoPlantModel {
        /// 0 = port, 1 = starboard.
        side: usize,
    },
    /// The sparse regression failed.
    #[error(transparent)]
    Sindy(#[from] SindyError),
    /// The pressure model fit failed.
    #[error(transparent)]
    Pressure(#[from] PressureFitError),
    /// The fitted set does not pass the estimator's validation.
    #[error("the fitted coefficient set is not valid: {0}")]
    Invalid(estimator_core::blob::InvalidSet),
    /// A bug: an invariant of the fit did not hold.
    #[error("internal error: {0}")]
    Internal(&'static str),
}
