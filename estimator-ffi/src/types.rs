//! The C structs and codes of the interface: plain `#[repr(C)]` data, converted to and from the
//! core's types field by field (the core's own types stay free to change their layout).
//!
//! Their doc comments are the header's: they name what C sees (`rollest_input`,
//! `ROLLEST_STATUS_MOVED`), not the Rust items.

use core::mem::size_of;

use estimator_core::blob::DecodeError;
use estimator_core::{Health, Input, Output};

use crate::storage::RollestEstimator;

/// Pressure taps per sample.
pub const ROLLEST_N_TAPS: usize = 12;

// The C output structs have the core's layout, field for field (the core's `Output` and
// `Health` are `repr(C)`), so a step writes C's output in place, without a copy; checked here at
// compile time. The input is converted field by field: `repr(C)` on the core's `Input` cost the
// firmware's step 4 instructions (measured in QEMU), more than the copy costs the C call.
macro_rules! same_layout {
    ($c:ty, $core:ty, [$($field:ident),+]) => {
        const _: () = {
            assert!(core::mem::size_of::<$c>() == core::mem::size_of::<$core>());
            assert!(core::mem::align_of::<$c>() == core::mem::align_of::<$core>());
            $(assert!(core::mem::offset_of!($c, $field) == core::mem::offset_of!($core, $field));)+
        };
    };
}
same_layout!(RollestHealth, Health, [cp_missing, cp_rejected, cp_isolated, flags]);
same_layout!(
    RollestOutput,
    Output,
    [cl_egk, cl_pressure, cl_roll, cl_afc_port, cl_afc_stbd, cl_afc, cl_linear, coupling, cl, phi_dot_rad_s, health]
);

/// The measurements of one step. Any value may be NaN: not measured this step (it is held and
/// flagged, never propagated).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RollestInput {
    /// Roll angle, deg (positive starboard wing down).
    pub phi_deg: f32,
    /// Angle of attack, deg.
    pub alpha_deg: f32,
    /// Momentum coefficient of the port jet.
    pub cmu_port: f32,
    /// Momentum coefficient of the starboard jet.
    pub cmu_stbd: f32,
    /// Pressure coefficients of taps 1 to 12: `cp[k]` is tap `k + 1` (`cp01` to `cp12` in the
    /// dataset's files).
    pub cp: [f32; ROLLEST_N_TAPS],
}

impl From<&RollestInput> for Input {
    fn from(input: &RollestInput) -> Self {
        Self {
            phi_deg: input.phi_deg,
            alpha_deg: input.alpha_deg,
            cmu_port: input.cmu_port,
            cmu_stbd: input.cmu_stbd,
            cp: input.cp,
        }
    }
}

/// What was missing, rejected, held or reset in one step (`ROLLEST_HEALTH_*` bits in `flags`;
/// bit `k`, `1 << k`, of a channel mask is pressure tap `k + 1`, the input's `cp[k]`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RollestHealth {
    /// Pressure channels without a finite reading.
    pub cp_missing: u16,
    /// Pressure channels whose innovation failed the gate.
    pub cp_rejected: u16,
    /// Pressure channels isolated as faulty (stuck, or rejected for too long).
    pub cp_isolated: u16,
    /// `ROLLEST_HEALTH_*` bits.
    pub flags: u16,
}

/// The estimates of one step.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RollestOutput {
    /// `C_l,roll` of the eGK alone.
    pub cl_egk: f32,
    /// `C_l,roll` of the pressure path alone.
    pub cl_pressure: f32,
    /// `C_l,roll`: the fused disturbance estimate.
    pub cl_roll: f32,
    /// `C_l,AFC` of the port jet.
    pub cl_afc_port: f32,
    /// `C_l,AFC` of the starboard jet.
    pub cl_afc_stbd: f32,
    /// `C_l,AFC = port + starboard`.
    pub cl_afc: f32,
    /// Linear superposition `C_l,roll + C_l,AFC`.
    pub cl_linear: f32,
    /// The coupling operator's correction.
    pub coupling: f32,
    /// `C_l`: the superposition with the coupling operator.
    pub cl: f32,
    /// Filtered roll rate, rad/s.
    pub phi_dot_rad_s: f32,
    /// What was missing, rejected, held or reset.
    pub health: RollestHealth,
}

/// A roll angle held (missing or not finite).
pub const ROLLEST_HEALTH_PHI_HELD: u16 = 1 << 0;
/// An angle of attack held.
pub const ROLLEST_HEALTH_ALPHA_HELD: u16 = 1 << 1;
/// A Cmu held.
pub const ROLLEST_HEALTH_CMU_HELD: u16 = 1 << 2;
/// An input out of range, clamped.
pub const ROLLEST_HEALTH_INPUT_CLAMPED: u16 = 1 << 3;
/// No pressure channel corrected the pressure model this step.
pub const ROLLEST_HEALTH_PRESSURE_UNUSED: u16 = 1 << 4;
/// A stage's state was reset (it diverged or went non-finite).
pub const ROLLEST_HEALTH_STATE_RESET: u16 = 1 << 5;
/// The controller's Cmu demand was saturated.
pub const ROLLEST_HEALTH_CMU_SATURATED: u16 = 1 << 6;
/// The controller's feedback measurement was held.
pub const ROLLEST_HEALTH_FEEDBACK_HELD: u16 = 1 << 7;
/// An estimate was limited to the fitted envelope.
pub const ROLLEST_HEALTH_ESTIMATE_LIMITED: u16 = 1 << 8;
/// A missing Cmu was predicted from the noted demands.
pub const ROLLEST_HEALTH_CMU_FROM_DEMAND: u16 = 1 << 9;
/// The pressure filter is settling from its start.
pub const ROLLEST_HEALTH_PRESSURE_SETTLING: u16 = 1 << 10;

/// The result of every call that takes an estimator: `ROLLEST_STATUS_OK` (0) is success. The
/// blob codes (10 and up) name why `rollest_init_blob()` refused a blob, one code per check a
/// blob must pass. `rollest_status_text()` describes any code.
#[repr(i32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RollestStatus {
    /// Success.
    Ok = 0,
    /// A pointer argument was NULL.
    NullPointer = 1,
    /// The storage is smaller than `sizeof(rollest_estimator)` of this library (the header and
    /// the library differ).
    StorageTooSmall = 2,
    /// The storage is not aligned to 8 bytes, or an input or output struct not to 4.
    Misaligned = 3,
    /// The storage holds no estimator: not initialised, or its initialisation failed.
    NotInitialised = 4,
    /// The storage was copied or moved after its initialisation (it refers to itself).
    Moved = 5,
    /// The blob is shorter than its header.
    BlobTooShort = 10,
    /// The blob does not start with the magic `RLCS`.
    BlobBadMagic = 11,
    /// The blob's format version is not this library's.
    BlobUnsupportedVersion = 12,
    /// The blob was written for another layout of the coefficient set.
    BlobSchemaMismatch = 13,
    /// The blob's reserved header bytes are not zero.
    BlobReservedNonZero = 14,
    /// The blob's payload length differs from its header's (truncated or trailing bytes).
    BlobLengthMismatch = 15,
    /// The blob's payload fails its CRC-32 (a flipped bit).
    BlobCrcMismatch = 16,
    /// The blob's payload is not a coefficient set.
    BlobDecode = 17,
    /// The blob's payload leaves bytes unused.
    BlobTrailingPayload = 18,
    /// The blob decodes, but its coefficient set fails validation (non-finite or out-of-range
    /// tables).
    BlobInvalidSet = 19,
}

/// Every status code, in order (not exported to C: the enum is the list there).
pub(crate) const ALL_STATUSES: [RollestStatus; 16] = [
    RollestStatus::Ok,
    RollestStatus::NullPointer,
    RollestStatus::StorageTooSmall,
    RollestStatus::Misaligned,
    RollestStatus::NotInitialised,
    RollestStatus::Moved,
    RollestStatus::BlobTooShort,
    RollestStatus::BlobBadMagic,
    RollestStatus::BlobUnsupportedVersion,
    RollestStatus::BlobSchemaMismatch,
    RollestStatus::BlobReservedNonZero,
    RollestStatus::BlobLengthMismatch,
    RollestStatus::BlobCrcMismatch,
    RollestStatus::BlobDecode,
    RollestStatus::BlobTrailingPayload,
    RollestStatus::BlobInvalidSet,
];

impl RollestStatus {
    /// The description of any integer code (`rollest_status_text`).
    #[must_use]
    pub fn text_of(status: i32) -> &'static core::ffi::CStr {
        Self::from_code(status).map_or(c"unknown status code", Self::text)
    }

    /// The code of `status`, if it is one.
    #[must_use]
    pub fn from_code(status: i32) -> Option<Self> {
        ALL_STATUSES.iter().copied().find(|known| *known as i32 == status)
    }

    /// A NUL-terminated description (for `rollest_status_text`).
    #[must_use]
    pub const fn text(self) -> &'static core::ffi::CStr {
        match self {
            Self::Ok => c"ok",
            Self::NullPointer => c"a pointer argument is NULL",
            Self::StorageTooSmall => c"the storage is smaller than this library's rollest_estimator",
            Self::Misaligned => c"the storage is not aligned to 8 bytes, or an input or output struct not to 4",
            Self::NotInitialised => c"the storage holds no estimator (not initialised, or initialisation failed)",
            Self::Moved => c"the estimator was copied or moved after initialisation",
            Self::BlobTooShort => c"blob: shorter than its header",
            Self::BlobBadMagic => c"blob: wrong magic",
            Self::BlobUnsupportedVersion => c"blob: unsupported format version",
            Self::BlobSchemaMismatch => c"blob: written for another coefficient-set layout",
            Self::BlobReservedNonZero => c"blob: reserved header bytes are not zero",
            Self::BlobLengthMismatch => c"blob: payload length differs from the header's",
            Self::BlobCrcMismatch => c"blob: payload CRC-32 mismatch",
            Self::BlobDecode => c"blob: payload is not a coefficient set",
            Self::BlobTrailingPayload => c"blob: payload has trailing bytes",
            Self::BlobInvalidSet => c"blob: coefficient set fails validation",
        }
    }
}

impl From<&DecodeError> for RollestStatus {
    fn from(error: &DecodeError) -> Self {
        match error {
            DecodeError::TooShort { .. } => Self::BlobTooShort,
            DecodeError::BadMagic { .. } => Self::BlobBadMagic,
            DecodeError::UnsupportedVersion { .. } => Self::BlobUnsupportedVersion,
            DecodeError::SchemaMismatch { .. } => Self::BlobSchemaMismatch,
            DecodeError::ReservedNonZero { .. } => Self::BlobReservedNonZero,
            DecodeError::LengthMismatch { .. } => Self::BlobLengthMismatch,
            DecodeError::CrcMismatch { .. } => Self::BlobCrcMismatch,
            DecodeError::Decode(_) => Self::BlobDecode,
            DecodeError::TrailingPayload { .. } => Self::BlobTrailingPayload,
            DecodeError::Invalid(_) => Self::BlobInvalidSet,
        }
    }
}

/// The public structs, named for `rollest_struct_size()`: the library's `sizeof` of each, which
/// `ROLLEST_ABI_OK()` compares with the program's.
#[repr(i32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RollestStruct {
    /// `rollest_estimator`.
    Estimator = 0,
    /// `rollest_input`.
    Input = 1,
    /// `rollest_output`.
    Output = 2,
    /// `rollest_health`.
    Health = 3,
}

/// Every struct code, in order (not exported to C: the enum is the list there).
pub(crate) const ALL_STRUCTS: [RollestStruct; 4] =
    [RollestStruct::Estimator, RollestStruct::Input, RollestStruct::Output, RollestStruct::Health];

impl RollestStruct {
    /// The struct of `code`, if it is one (C may pass any integer).
    #[must_use]
    pub fn from_code(code: i32) -> Option<Self> {
        ALL_STRUCTS.iter().copied().find(|known| *known as i32 == code)
    }

    /// The struct's size in this library, bytes (`rollest_struct_size`).
    #[must_use]
    pub const fn size_bytes(self) -> usize {
        match self {
            Self::Estimator => size_of::<RollestEstimator>(),
            Self::Input => size_of::<RollestInput>(),
            Self::Output => size_of::<RollestOutput>(),
            Self::Health => size_of::<RollestHealth>(),
        }
    }
}
