//! The estimator in caller-owned storage: every check a pointer from C gets before it is used.
//!
//! [`RollestEstimator`] is an opaque, 8-byte aligned block of [`ROLLEST_ESTIMATOR_WORDS`] words
//! that C declares (`static rollest_estimator est;`) and this crate fills with an `Engine`:
//! the estimator, and for a blob the decoded coefficient set it refers to. The estimator holds a
//! reference into its own storage, so the storage must not be copied or moved once initialised:
//! the storage records the address it was initialised at, and every call compares it
//! ([`RollestStatus::Moved`]). A marker word says whether it holds an estimator at all.

use core::mem::{MaybeUninit, align_of, size_of};
use core::ptr::addr_of_mut;

use estimator_core::coeffs::CompiledDefault;
use estimator_core::sparse::Interpreted;
use estimator_core::{CoefficientSet, Estimator};

use crate::types::RollestStatus;

/// Size of `rollest_estimator` in 8-byte words: 8 KiB, which holds one estimator with its own
/// tables (4.3 KiB on a 64-bit host) and leaves room for the tables to grow (the library checks
/// at compile time that they fit).
pub const ROLLEST_ESTIMATOR_WORDS: usize = 1024;

/// Storage for one estimator, owned by the caller: a `static`, or a member of the caller's
/// state (the library allocates nothing). Initialise it with `rollest_init_built_in()` or
/// `rollest_init_blob()`, then do not copy or move it: the estimator refers into its own storage,
/// so a copy made by assignment or `memcpy()` gets `ROLLEST_STATUS_MOVED` from every call, and
/// the original stays usable.
// `Clone` is that bitwise copy, for Rust callers and the test that a copy is refused.
#[repr(C)]
#[derive(Clone)]
pub struct RollestEstimator {
    /// Private to the library: written only by the `rollest_*` functions (a program that writes
    /// into initialised storage breaks the estimator it holds).
    _opaque: [u64; ROLLEST_ESTIMATOR_WORDS],
}

impl RollestEstimator {
    /// Empty storage (all zero, as a C `static` starts), for Rust callers.
    #[must_use]
    pub const fn new() -> Self {
        Self { _opaque: [0; ROLLEST_ESTIMATOR_WORDS] }
    }
}

impl Default for RollestEstimator {
    fn default() -> Self {
        Self::new()
    }
}

/// Marks initialised storage ("RLES").
const MARKER: u32 = u32::from_le_bytes(*b"RLES");

/// How the sparse models are evaluated: the built-in tables' generated code, or a loaded set's
/// tables.
enum Estimate {
    BuiltIn(Estimator<'static, CompiledDefault>),
    Loaded(Estimator<'static, Interpreted>),
}

/// What the storage holds.
#[repr(C)]
pub(crate) struct Engine {
    marker: u32,
    /// The address the storage was initialised at.
    home: usize,
    /// The loaded coefficient set (written only by `rollest_init_blob`).
    set: MaybeUninit<CoefficientSet>,
    estimate: Estimate,
}

const _: () = assert!(size_of::<Engine>() <= size_of::<RollestEstimator>(), "grow ROLLEST_ESTIMATOR_WORDS");
const _: () = assert!(align_of::<Engine>() <= align_of::<RollestEstimator>());

/// Checks `storage` as fresh storage for an engine: not NULL, large enough, aligned.
///
/// # Safety
///
/// `storage` is NULL or points to `storage_len` writable bytes.
pub(crate) unsafe fn fresh(storage: *mut RollestEstimator, storage_len: usize) -> Result<*mut Engine, RollestStatus> {
    if storage.is_null() {
        return Err(RollestStatus::NullPointer);
    }
    if storage_len < size_of::<RollestEstimator>() {
        return Err(RollestStatus::StorageTooSmall);
    }
    if !(storage as usize).is_multiple_of(align_of::<RollestEstimator>()) {
        return Err(RollestStatus::Misaligned);
    }
    let engine = storage.cast::<Engine>();
    // SAFETY: `storage` is non-null, aligned and at least `size_of::<Engine>()` bytes (checked
    // above and at compile time), and the caller gave it to us to write (this function's
    // contract). Clearing the marker
    // first means a failed initialisation leaves storage every other call refuses.
    unsafe { addr_of_mut!((*engine).marker).write(0) };
    Ok(engine)
}

/// Initialises the engine in `engine` (from [`fresh`]) with the built-in tables.
///
/// # Safety
///
/// `engine` comes from [`fresh`].
pub(crate) unsafe fn init_built_in(engine: *mut Engine) {
    // SAFETY: `engine` comes from `fresh` (this function's contract): valid for writes of an
    // `Engine`. Fields are written
    // through raw pointers, never through a reference to the whole (partly uninitialised) engine.
    unsafe {
        addr_of_mut!((*engine).estimate).write(Estimate::BuiltIn(Estimator::built_in()));
        addr_of_mut!((*engine).home).write(engine as usize);
        addr_of_mut!((*engine).marker).write(MARKER);
    }
}

/// Initialises the engine in `engine` (from [`fresh`]) with a decoded, validated set.
///
/// # Safety
///
/// `engine` comes from [`fresh`].
pub(crate) unsafe fn init_loaded(engine: *mut Engine, set: CoefficientSet) {
    // SAFETY: as in `init_built_in`. The estimator refers to the set in the same storage, which
    // stays valid as long as the caller keeps the storage; a moved copy is refused by `live`
    // before that reference is followed. The set is written once here and only read afterwards.
    unsafe {
        let slot = addr_of_mut!((*engine).set).cast::<CoefficientSet>();
        slot.write(set);
        let tables: &'static CoefficientSet = &*slot;
        addr_of_mut!((*engine).estimate).write(Estimate::Loaded(Estimator::new(tables)));
        addr_of_mut!((*engine).home).write(engine as usize);
        addr_of_mut!((*engine).marker).write(MARKER);
    }
}

/// What the C calls do with the estimator of an initialised storage, whichever evaluator it
/// has.
pub(crate) trait WithEstimator {
    /// `Estimator::step`, whichever evaluator it has.
    fn step(&mut self, input: &estimator_core::Input) -> estimator_core::Output;
    /// `Estimator::note_demand`.
    fn note_demand(&mut self, cmu_demand: [f32; 2]);
    /// `Estimator::reset`.
    fn reset(&mut self);
    /// The tables' fixed step, s.
    fn dt_s(&self) -> f32;
}

impl WithEstimator for Estimate {
    fn step(&mut self, input: &estimator_core::Input) -> estimator_core::Output {
        match self {
            Self::BuiltIn(estimator) => estimator.step(input),
            Self::Loaded(estimator) => estimator.step(input),
        }
    }

    fn note_demand(&mut self, cmu_demand: [f32; 2]) {
        match self {
            Self::BuiltIn(estimator) => estimator.note_demand(cmu_demand),
            Self::Loaded(estimator) => estimator.note_demand(cmu_demand),
        }
    }

    fn reset(&mut self) {
        match self {
            Self::BuiltIn(estimator) => estimator.reset(),
            Self::Loaded(estimator) => estimator.reset(),
        }
    }

    fn dt_s(&self) -> f32 {
        match self {
            Self::BuiltIn(estimator) => estimator.coefficients().dt_s,
            Self::Loaded(estimator) => estimator.coefficients().dt_s,
        }
    }
}

/// The estimator in `storage`, checked: not NULL, aligned, initialised, not moved.
///
/// # Safety
///
/// `storage` is NULL or points to a `rollest_estimator`, not used elsewhere for `'a`.
pub(crate) unsafe fn live<'a>(storage: *mut RollestEstimator) -> Result<&'a mut impl WithEstimator, RollestStatus> {
    if storage.is_null() {
        return Err(RollestStatus::NullPointer);
    }
    if !(storage as usize).is_multiple_of(align_of::<RollestEstimator>()) {
        return Err(RollestStatus::Misaligned);
    }
    let engine = storage.cast::<Engine>();
    // SAFETY: non-null and aligned, and a `rollest_estimator` by this function's contract. The marker and the home address are plain integers, so
    // any bytes read there are a valid value; only a matching marker and address let the
    // estimator be touched.
    let (marker, home) = unsafe { (addr_of_mut!((*engine).marker).read(), addr_of_mut!((*engine).home).read()) };
    if marker != MARKER {
        return Err(RollestStatus::NotInitialised);
    }
    if home != engine as usize {
        return Err(RollestStatus::Moved);
    }
    // SAFETY: the marker is written last by an initialisation at this very address, so the
    // estimator (and, for a loaded set, the set it refers to) is initialised and in place. The
    // mutable reference covers the estimator field only; the set it reads stays shared.
    Ok(unsafe { &mut *addr_of_mut!((*engine).estimate) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_storage_holds_an_engine_with_room_to_grow() {
        let (engine, storage) = (size_of::<Engine>(), size_of::<RollestEstimator>());
        assert!(engine * 5 / 4 <= storage, "engine {engine} bytes in {storage}");
    }
}
