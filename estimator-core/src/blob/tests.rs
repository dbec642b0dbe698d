//! Tests of the blob: round trips, every check of the header and the values, and fuzzed bytes.

use core::array;

use proptest::prelude::*;

use super::*;
use crate::coeffs::{
    ActuatorResponse, ControllerParams, DEMAND_SLOTS, EgkParams, Envelope, FusionParams, PlantParams, PressureModel,
    RateFilter, SCHEMA_VERSION,
};
use crate::coeffs::{N_COUPLING_VARS, N_PLANT_VARS};
use crate::sparse::{Factor, ONE_FACTOR};
use crate::sparse::{Monomial, SparseModel, Term};

/// Distinct, non-zero, exactly representable f32 values in ascending order.
struct Seq {
    count: u16,
}

impl Seq {
    fn next(&mut self) -> f32 {
        self.count += 1;
        0.125 + f32::from(self.count) * 0.0625
    }

    fn arr<const N: usize>(&mut self) -> [f32; N] {
        array::from_fn(|_| self.next())
    }

    fn mat<const R: usize, const C: usize>(&mut self) -> [[f32; C]; R] {
        array::from_fn(|_| self.arr())
    }

    fn sparse(&mut self, n_terms: u8) -> SparseModel {
        let terms = array::from_fn(|term_idx| Term {
            coeff: if term_idx % 2 == 0 { self.next() } else { -self.next() },
            monomial: Monomial {
                factors: [
                    Factor::var(term_idx % 3).unwrap_or(ONE_FACTOR),
                    Factor::var(term_idx % 3 + term_idx % 4).unwrap_or(ONE_FACTOR),
                    ONE_FACTOR,
                ],
                gate_mask: (term_idx % 64) as u8,
            },
        });
        SparseModel { terms, n_terms, gate_threshold: self.arr() }
    }

    fn egk(&mut self) -> EgkParams {
        EgkParams {
            tau1_s: self.next(),
            tau2_s: self.next(),
            breakdown_deg: self.next(),
            steepness_per_deg: self.next(),
            sideslip_gain: self.next(),
            clbeta_per_rad: -self.next(),
            clp: -self.next(),
            clpdot: -self.next(),
            clpp: -self.next(),
            vortex_gain: self.next(),
            bias: -self.next(),
            half_span_time_s: self.next(),
        }
    }
}

/// A valid set with every field set to a distinct non-zero value.
fn valid_set() -> CoefficientSet {
    let mut seq = Seq { count: 0 };
    CoefficientSet {
        schema_version: SCHEMA_VERSION,
        dt_s: 0.001,
        rate_filter: RateFilter { rate_pole: seq.next(), accel_pole: seq.next() },
        alpha_schedule_deg: seq.arr(),
        n_alpha: 3,
        egk: array::from_fn(|_| seq.egk()),
        pressure: PressureModel {
            rank: PRESSURE_RANK as u8,
            a: seq.mat(),
            b: seq.mat(),
            c: seq.mat(),
            cp_mean: seq.arr().map(|value: f32| -value),
            gain: seq.mat(),
            innovation_std: seq.arr(),
            gate_sigma: seq.next(),
            isolate_after: 300,
            settle_steps: 150,
            cl_weights: seq.mat(),
            cl_offset: seq.arr(),
        },
        fusion: FusionParams { rho: seq.next(), gain: seq.next() },
        plant: [
            PlantParams { slow_pole: 0.9, cmu_max: 0.009, model: seq.sparse(5) },
            PlantParams { slow_pole: 0.95, cmu_max: 0.012, model: seq.sparse(5) },
        ],
        coupling: seq.sparse(7),
        controller: ControllerParams {
            causality_pole: 0.95,
            feedback_kp: seq.next(),
            feedback_ki: seq.next(),
            cmu_max: seq.next(),
            inversion_iterations: 24,
        },
        actuator: [
            ActuatorResponse { delay_steps: 5, pole: 0.7, gain: 0.98 },
            ActuatorResponse { delay_steps: 6, pole: 0.75, gain: 1.02 },
        ],
        envelope: Envelope { cl_roll: [-0.05, 0.0625], cl: [-0.0625, 0.075] },
    }
}

/// A set whose every field has its largest value (largest encoding, not valid).
fn large_set() -> CoefficientSet {
    let big = f32::MAX;
    let sparse = SparseModel {
        terms: [Term { coeff: big, monomial: Monomial { factors: [ONE_FACTOR; MAX_DEGREE], gate_mask: u8::MAX } };
            MAX_TERMS],
        n_terms: u8::MAX,
        gate_threshold: [big; MAX_VARS],
    };
    let egk = EgkParams {
        tau1_s: big,
        tau2_s: big,
        breakdown_deg: big,
        steepness_per_deg: big,
        sideslip_gain: big,
        clbeta_per_rad: big,
        clp: big,
        clpdot: big,
        clpp: big,
        vortex_gain: big,
        bias: big,
        half_span_time_s: big,
    };
    CoefficientSet {
        schema_version: u16::MAX,
        dt_s: big,
        rate_filter: RateFilter { rate_pole: big, accel_pole: big },
        alpha_schedule_deg: [big; N_ALPHA],
        n_alpha: u8::MAX,
        egk: [egk; N_ALPHA],
        pressure: PressureModel {
            rank: u8::MAX,
            a: [[big; PRESSURE_RANK]; PRESSURE_RANK],
            b: [[big; N_PRESSURE_INPUTS]; PRESSURE_RANK],
            c: [[big; PRESSURE_RANK]; N_TAPS],
            cp_mean: [big; N_TAPS],
            gain: [[big; N_TAPS]; PRESSURE_RANK],
            innovation_std: [big; N_TAPS],
            gate_sigma: big,
            isolate_after: u16::MAX,
            settle_steps: u16::MAX,
            cl_weights: [[big; N_TAPS]; N_ALPHA],
            cl_offset: [big; N_ALPHA],
        },
        fusion: FusionParams { rho: big, gain: big },
        plant: [PlantParams { slow_pole: big, cmu_max: big, model: sparse }; 2],
        coupling: sparse,
        controller: ControllerParams {
            causality_pole: big,
            feedback_kp: big,
            feedback_ki: big,
            cmu_max: big,
            inversion_iterations: u8::MAX,
        },
        actuator: [ActuatorResponse { delay_steps: u8::MAX, pole: big, gain: big }; 2],
        envelope: Envelope { cl_roll: [big; 2], cl: [big; 2] },
    }
}

fn encode_vec(set: &CoefficientSet) -> Vec<u8> {
    let mut buf = vec![0u8; MAX_BLOB_LEN];
    let len = encode(set, &mut buf).expect("encode into MAX_BLOB_LEN");
    buf.truncate(len);
    buf
}

/// A blob with a correct header around an arbitrary payload.
fn seal(payload: &[u8]) -> Vec<u8> {
    let mut blob = Header::for_payload(payload).expect("payload length fits u32").to_bytes().to_vec();
    blob.extend_from_slice(payload);
    blob
}

fn valid_blob() -> Vec<u8> {
    encode_vec(&valid_set())
}

#[test]
fn blob_schema_mentions_current_constants() {
    for (name, value) in [
        ("schema_version", usize::from(SCHEMA_VERSION)),
        ("N_TAPS", N_TAPS),
        ("PRESSURE_RANK", PRESSURE_RANK),
        ("N_PRESSURE_INPUTS", N_PRESSURE_INPUTS),
        ("N_ALPHA", N_ALPHA),
        ("MAX_TERMS", MAX_TERMS),
        ("MAX_VARS", MAX_VARS),
        ("N_PLANT_VARS", N_PLANT_VARS),
        ("N_COUPLING_VARS", N_COUPLING_VARS),
        ("DEMAND_SLOTS", DEMAND_SLOTS),
    ] {
        let entry = format!("; {name}={value};");
        assert!(SCHEMA.contains(&entry), "SCHEMA lacks `{entry}`: update it (and the layout) for the new size");
    }
}

#[test]
fn blob_schema_hash_is_fnv1a_of_schema() {
    // Reference vectors of FNV-1a 32.
    assert_eq!(fnv1a_32(b""), 0x811c_9dc5);
    assert_eq!(fnv1a_32(b"a"), 0xe40c_292c);
    assert_eq!(fnv1a_32(b"foobar"), 0xbf9c_f968);
    assert_eq!(SCHEMA_HASH, fnv1a_32(SCHEMA.as_bytes()));
    // The check value of CRC-32/ISO-HDLC.
    assert_eq!(PAYLOAD_CRC.checksum(b"123456789"), 0xcbf4_3926);
}

/// The payload written field by field in the order of [`SCHEMA`]: catches a reordering of
/// fields in coeffs.rs (which the schema hash alone would not see).
#[test]
fn blob_payload_follows_schema_field_order() {
    struct Writer(Vec<u8>);
    impl Writer {
        fn f32s(&mut self, values: &[f32]) {
            for value in values {
                self.0.extend_from_slice(&value.to_le_bytes());
            }
        }
        fn u8(&mut self, value: u8) {
            self.0.push(value);
        }
        fn u16(&mut self, mut value: u16) {
            while value >= 0x80 {
                self.0.push((value & 0x7f) as u8 | 0x80);
                value >>= 7;
            }
            self.0.push(value as u8);
        }
        fn sparse(&mut self, model: &SparseModel) {
            for term in &model.terms {
                self.f32s(&[term.coeff]);
                // A factor is written as the one byte of its index, as the `u8` it was.
                for factor in term.monomial.factors {
                    self.u8(factor.index() as u8);
                }
                self.u8(term.monomial.gate_mask);
            }
            self.u8(model.n_terms);
            self.f32s(&model.gate_threshold);
        }
    }
    let set = valid_set();
    let mut w = Writer(Vec::new());
    w.u16(set.schema_version);
    w.f32s(&[set.dt_s, set.rate_filter.rate_pole, set.rate_filter.accel_pole]);
    w.f32s(&set.alpha_schedule_deg);
    w.u8(set.n_alpha);
    for e in &set.egk {
        w.f32s(&[
            e.tau1_s,
            e.tau2_s,
            e.breakdown_deg,
            e.steepness_per_deg,
            e.sideslip_gain,
            e.clbeta_per_rad,
            e.clp,
            e.clpdot,
            e.clpp,
            e.vortex_gain,
            e.bias,
            e.half_span_time_s,
        ]);
    }
    let p = &set.pressure;
    w.u8(p.rank);
    w.f32s(p.a.as_flattened());
    w.f32s(p.b.as_flattened());
    w.f32s(p.c.as_flattened());
    w.f32s(&p.cp_mean);
    w.f32s(p.gain.as_flattened());
    w.f32s(&p.innovation_std);
    w.f32s(&[p.gate_sigma]);
    w.u16(p.isolate_after);
    w.u16(p.settle_steps);
    w.f32s(p.cl_weights.as_flattened());
    w.f32s(&p.cl_offset);
    w.f32s(&[set.fusion.rho, set.fusion.gain]);
    w.f32s(&[set.plant[0].slow_pole, set.plant[0].cmu_max]);
    w.sparse(&set.plant[0].model);
    w.f32s(&[set.plant[1].slow_pole, set.plant[1].cmu_max]);
    w.sparse(&set.plant[1].model);
    w.sparse(&set.coupling);
    let c = &set.controller;
    w.f32s(&[c.causality_pole, c.feedback_kp, c.feedback_ki, c.cmu_max]);
    w.u8(c.inversion_iterations);
    for response in &set.actuator {
        w.u8(response.delay_steps);
        w.f32s(&[response.pole, response.gain]);
    }
    w.f32s(&set.envelope.cl_roll);
    w.f32s(&set.envelope.cl);

    let blob = valid_blob();
    assert_eq!(&blob[HEADER_LEN..], w.0.as_slice());
}

/// A factor is one byte, its index; a byte that names no factor does not decode.
#[test]
fn blob_factor_is_its_index_byte() {
    let mut buffer = [0u8; 4];
    for var_idx in 0..=MAX_VARS {
        let factor = Factor::var(var_idx).unwrap_or(ONE_FACTOR);
        assert_eq!(postcard::to_slice(&factor, &mut buffer).map(|bytes| bytes.to_vec()), Ok(vec![var_idx as u8]));
        assert_eq!(postcard::from_bytes::<Factor>(&[var_idx as u8]), Ok(factor));
    }
    assert!(postcard::from_bytes::<Factor>(&[MAX_VARS as u8 + 1]).is_err());
    assert!(postcard::from_bytes::<Factor>(&[u8::MAX]).is_err());
}

#[test]
fn blob_round_trip() {
    let set = valid_set();
    assert_eq!(validate(&set), Ok(()));
    let blob = valid_blob();
    assert_eq!(blob.len(), encoded_len(&set));
    println!("encoded test set: {} bytes (MAX_BLOB_LEN = {MAX_BLOB_LEN})", blob.len());
    assert_eq!(&blob[0..4], b"RLCS");
    assert_eq!(u16::from_le_bytes([blob[4], blob[5]]), BLOB_FORMAT_VERSION);
    assert_eq!(u32::from_le_bytes(blob[6..10].try_into().unwrap()), SCHEMA_HASH);
    assert_eq!(u32::from_le_bytes(blob[10..14].try_into().unwrap()) as usize, blob.len() - HEADER_LEN);
    assert_eq!(u32::from_le_bytes(blob[14..18].try_into().unwrap()), PAYLOAD_CRC.checksum(&blob[HEADER_LEN..]));
    assert_eq!(&blob[18..20], &[0, 0]);
    assert_eq!(decode(&blob), Ok(set));
}

#[test]
fn blob_max_len_bounds_the_largest_set() {
    let set = large_set();
    let mut buf = vec![0u8; MAX_BLOB_LEN];
    let len = encode(&set, &mut buf).expect("the largest set fits MAX_BLOB_LEN");
    println!("largest set: {len} bytes, MAX_BLOB_LEN = {MAX_BLOB_LEN}");
    // The bound is exact: a larger encoding means a field was added without updating it.
    assert_eq!(len, MAX_BLOB_LEN);
    assert_eq!(encoded_len(&set), MAX_BLOB_LEN);
}

#[test]
fn blob_encode_reports_small_buffers() {
    let set = valid_set();
    let needed = encoded_len(&set);
    for available in [0, 10, HEADER_LEN - 1, HEADER_LEN, HEADER_LEN + 1, needed - 1] {
        let mut buf = vec![0u8; available];
        assert_eq!(encode(&set, &mut buf), Err(EncodeError::BufferTooSmall { needed, available }), "{available}");
    }
    let mut buf = vec![0u8; needed];
    assert_eq!(encode(&set, &mut buf), Ok(needed));
}

#[test]
fn blob_rejects_short_input() {
    let blob = valid_blob();
    assert_eq!(decode(&[]), Err(DecodeError::TooShort { len: 0 }));
    assert_eq!(decode(&blob[..HEADER_LEN - 1]), Err(DecodeError::TooShort { len: HEADER_LEN - 1 }));
    let payload_len = (blob.len() - HEADER_LEN) as u32;
    assert_eq!(decode(&blob[..HEADER_LEN]), Err(DecodeError::LengthMismatch { declared: payload_len, actual: 0 }));
}

#[test]
fn blob_rejects_truncation_and_trailing_bytes() {
    let blob = valid_blob();
    let payload_len = blob.len() - HEADER_LEN;
    assert_eq!(
        decode(&blob[..blob.len() - 1]),
        Err(DecodeError::LengthMismatch { declared: payload_len as u32, actual: payload_len - 1 })
    );
    let mut longer = blob.clone();
    longer.push(0);
    assert_eq!(
        decode(&longer),
        Err(DecodeError::LengthMismatch { declared: payload_len as u32, actual: payload_len + 1 })
    );
}

#[test]
fn blob_rejects_bad_header_fields() {
    let blob = valid_blob();

    let mut bad = blob.clone();
    bad[0] = b'X';
    assert_eq!(decode(&bad), Err(DecodeError::BadMagic { found: *b"XLCS" }));

    let mut bad = blob.clone();
    bad[4..6].copy_from_slice(&2u16.to_le_bytes());
    assert_eq!(decode(&bad), Err(DecodeError::UnsupportedVersion { found: 2 }));

    let mut bad = blob.clone();
    bad[6..10].copy_from_slice(&0xdead_beef_u32.to_le_bytes());
    assert_eq!(decode(&bad), Err(DecodeError::SchemaMismatch { expected: SCHEMA_HASH, found: 0xdead_beef }));

    let mut bad = blob.clone();
    bad[19] = 1;
    assert_eq!(decode(&bad), Err(DecodeError::ReservedNonZero { found: 0x0100 }));
}

#[test]
fn blob_rejects_crc_mismatch() {
    let mut bad = valid_blob();
    let stored = u32::from_le_bytes(bad[14..18].try_into().unwrap());
    bad[HEADER_LEN + 100] ^= 0x01;
    let found = PAYLOAD_CRC.checksum(&bad[HEADER_LEN..]);
    assert_ne!(stored, found);
    assert_eq!(decode(&bad), Err(DecodeError::CrcMismatch { expected: stored, found }));
}

#[test]
fn blob_rejects_undecodable_and_overlong_payloads() {
    let blob = valid_blob();
    let payload = &blob[HEADER_LEN..];
    assert_eq!(decode(&seal(&payload[..payload.len() - 4])), Err(DecodeError::Decode("unexpected end of payload")));
    assert_eq!(decode(&seal(&[])), Err(DecodeError::Decode("unexpected end of payload")));
    // schema_version as a varint that never terminates within a u16.
    assert_eq!(decode(&seal(&[0xff, 0xff, 0xff, 0xff])), Err(DecodeError::Decode("bad varint")));
    let mut longer = payload.to_vec();
    longer.extend_from_slice(&[1, 2, 3]);
    assert_eq!(decode(&seal(&longer)), Err(DecodeError::TrailingPayload { unused: 3 }));
}

#[test]
fn blob_rejects_invalid_set_after_decoding() {
    let mut set = valid_set();
    set.pressure.gain[3][7] = f32::NAN;
    let blob = encode_vec(&set);
    assert_eq!(decode(&blob), Err(DecodeError::Invalid(InvalidSet("pressure.gain is not finite"))));
}

/// Found by the fuzzer of `cargo xtask fuzz --target blob`: finite pressure tables whose
/// product overflows passed validation, and the step then returned a NaN `cl_pressure`.
#[test]
fn pressure_tables_that_overflow_are_rejected_and_never_reach_the_output() {
    let mut set = crate::coeffs::DEFAULT;
    set.pressure.cl_weights[0][1] = 1e30;
    set.pressure.c[1][0] = 1e23;
    assert!(matches!(validate(&set), Err(InvalidSet(what)) if what.starts_with("pressure tables overflow")));
    let mut estimator = crate::Estimator::new(&set);
    let input = crate::Input { phi_deg: 5.0, alpha_deg: 10.0, cmu_port: 0.0, cmu_stbd: 0.0, cp: [-0.4; N_TAPS] };
    for _ in 0..10 {
        assert!(estimator.step(&input).estimates().iter().all(|value| value.is_finite()));
    }
}

#[test]
fn blob_every_single_bit_flip_is_rejected() {
    let blob = valid_blob();
    let mut flipped = blob.clone();
    for byte_idx in 0..blob.len() {
        for bit in 0..8 {
            flipped[byte_idx] ^= 1 << bit;
            let result = decode(&flipped);
            let expected_kind = match byte_idx {
                0..4 => matches!(result, Err(DecodeError::BadMagic { .. })),
                4..6 => matches!(result, Err(DecodeError::UnsupportedVersion { .. })),
                6..10 => matches!(result, Err(DecodeError::SchemaMismatch { .. })),
                10..14 => matches!(result, Err(DecodeError::LengthMismatch { .. })),
                18..20 => matches!(result, Err(DecodeError::ReservedNonZero { .. })),
                _ => matches!(result, Err(DecodeError::CrcMismatch { .. })),
            };
            assert!(expected_kind, "flip of byte {byte_idx} bit {bit} gave {result:?}");
            flipped[byte_idx] ^= 1 << bit;
        }
    }
    assert_eq!(flipped, blob);
}

#[test]
fn blob_validate_rejects_bad_values() {
    type Corruption = (fn(&mut CoefficientSet), &'static str);
    let cases: [Corruption; 33] = [
        (|s| s.schema_version = SCHEMA_VERSION + 1, "schema_version differs from this build's SCHEMA_VERSION"),
        (|s| s.pressure.gain[9][11] = f32::NAN, "pressure.gain is not finite"),
        (|s| s.pressure.a[0][0] = f32::INFINITY, "pressure.a is not finite"),
        (|s| s.egk[3].bias = f32::NEG_INFINITY, "egk.bias is not finite"),
        (|s| s.plant[1].model.terms[15].coeff = f32::NAN, "plant[1].terms.coeff is not finite"),
        (|s| s.coupling.gate_threshold[5] = f32::INFINITY, "coupling.gate_threshold is not finite"),
        (|s| s.controller.feedback_ki = f32::NAN, "controller.feedback_ki is not finite"),
        (|s| s.dt_s = 0.0, "dt_s must be > 0"),
        (|s| s.dt_s = -0.001, "dt_s must be > 0"),
        (|s| s.n_alpha = 0, "n_alpha must be in 1..=N_ALPHA"),
        (|s| s.n_alpha = N_ALPHA as u8 + 1, "n_alpha must be in 1..=N_ALPHA"),
        (
            |s| s.alpha_schedule_deg[2] = s.alpha_schedule_deg[1],
            "alpha_schedule_deg must be strictly ascending over the n_alpha used breakpoints",
        ),
        (
            |s| s.alpha_schedule_deg.swap(0, 1),
            "alpha_schedule_deg must be strictly ascending over the n_alpha used breakpoints",
        ),
        (|s| s.egk[2].tau1_s = 0.0, "egk.tau1_s must be > 0"),
        (|s| s.egk[0].tau2_s = -0.01, "egk.tau2_s must be >= 0"),
        (|s| s.pressure.rank = PRESSURE_RANK as u8 + 1, "pressure.rank must be <= PRESSURE_RANK"),
        (|s| s.pressure.gate_sigma = 0.0, "pressure.gate_sigma must be > 0"),
        (|s| s.plant[0].model.n_terms = MAX_TERMS as u8 + 1, "plant[0].n_terms must be <= MAX_TERMS"),
        (|s| s.coupling.n_terms = u8::MAX, "coupling.n_terms must be <= MAX_TERMS"),
        (|s| s.controller.cmu_max = 0.0, "controller.cmu_max must be > 0"),
        (|s| s.pressure.rank = 4, "pressure modes beyond rank must be zero"),
        (
            |s| s.coupling.terms[15].monomial.factors = [ONE_FACTOR, Factor::Var0, ONE_FACTOR],
            "coupling factors must be variables or ONE_FACTOR, ascending",
        ),
        (
            |s| s.plant[1].model.terms[0].monomial.factors = [Factor::Var2, Factor::Var1, ONE_FACTOR],
            "plant[1] factors must be variables or ONE_FACTOR, ascending",
        ),
        (|s| s.actuator[0].pole = f32::NAN, "actuator.pole is not finite"),
        (|s| s.actuator[1].gain = f32::INFINITY, "actuator.gain is not finite"),
        (|s| s.actuator[0].delay_steps = DEMAND_SLOTS as u8, "actuator[0].delay_steps must be < DEMAND_SLOTS"),
        (|s| s.actuator[1].pole = 1.0, "actuator[1].pole must be in [0, 1)"),
        (|s| s.actuator[0].pole = -0.1, "actuator[0].pole must be in [0, 1)"),
        (|s| s.actuator[1].gain = 0.0, "actuator[1].gain must be in (0, 10]"),
        (|s| s.actuator[0].gain = 10.5, "actuator[0].gain must be in (0, 10]"),
        (|s| s.envelope.cl[1] = f32::NAN, "envelope.cl is not finite"),
        (|s| s.envelope.cl_roll = [0.01, -0.01], "envelope.cl_roll must be ordered within +-ENVELOPE_LIMIT"),
        (|s| s.envelope.cl = [-2.0, 0.1], "envelope.cl must be ordered within +-ENVELOPE_LIMIT"),
    ];
    for (corrupt, what) in cases {
        let mut set = valid_set();
        corrupt(&mut set);
        assert_eq!(validate(&set), Err(InvalidSet(what)));
    }
}

#[test]
fn blob_validate_accepts_edge_values() {
    // Unused breakpoints and eGK entries may be anything finite; tau2 = 0 and rank = 0 are fine.
    let mut set = valid_set();
    set.alpha_schedule_deg[3] = -90.0;
    set.egk[3].tau1_s = 0.0;
    set.egk[0].tau2_s = 0.0;
    set.pressure = PressureModel { rank: 0, ..crate::prior::PRIOR.pressure };
    set.plant[0].model.n_terms = MAX_TERMS as u8;
    assert_eq!(validate(&set), Ok(()));
    set.n_alpha = 1;
    set.alpha_schedule_deg[1] = -90.0;
    assert_eq!(validate(&set), Ok(()));
    // The longest dead time, no lag, the largest gain, a range of one value, the limits.
    set.actuator[0] = ActuatorResponse { delay_steps: (DEMAND_SLOTS - 1) as u8, pole: 0.0, gain: 10.0 };
    set.envelope = Envelope { cl_roll: [0.02, 0.02], cl: [-ENVELOPE_LIMIT, ENVELOPE_LIMIT] };
    assert_eq!(validate(&set), Ok(()));
}

#[test]
fn blob_error_messages() {
    assert_eq!(DecodeError::TooShort { len: 12 }.to_string(), "blob too short: 12 bytes, a header needs 20");
    assert_eq!(
        DecodeError::Invalid(InvalidSet("dt_s must be > 0")).to_string(),
        InvalidSet("dt_s must be > 0").to_string(),
        "a decoded set that is invalid reads as the set's own error"
    );
    let encoding = [EncodeError::BufferTooSmall { needed: 2000, available: 10 }, EncodeError::Encode];
    let decoding = [
        DecodeError::TooShort { len: 3 },
        DecodeError::BadMagic { found: *b"XLCS" },
        DecodeError::UnsupportedVersion { found: 2 },
        DecodeError::SchemaMismatch { expected: SCHEMA_HASH, found: 0 },
        DecodeError::ReservedNonZero { found: 1 },
        DecodeError::LengthMismatch { declared: 10, actual: 9 },
        DecodeError::CrcMismatch { expected: 1, found: 2 },
        DecodeError::Decode("bad varint"),
        DecodeError::TrailingPayload { unused: 3 },
        DecodeError::Invalid(InvalidSet("dt_s must be > 0")),
    ];
    let messages = encoding
        .iter()
        .map(|error| (error.to_string(), error as &dyn core::error::Error))
        .chain(decoding.iter().map(|error| (error.to_string(), error as &dyn core::error::Error)))
        .chain([(InvalidSet("n_alpha").to_string(), &InvalidSet("n_alpha") as &dyn core::error::Error)]);
    for (message, _) in messages {
        assert!(message.starts_with(|c: char| c.is_ascii_lowercase()), "{message}");
        assert!(!message.ends_with('.'), "{message}");
    }
}

proptest! {
    #[test]
    fn blob_decode_never_panics_on_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let _ = decode(&bytes);
    }

    #[test]
    fn blob_decode_never_panics_on_sealed_arbitrary_payloads(
        payload in proptest::collection::vec(any::<u8>(), 0..(MAX_PAYLOAD_LEN + 8)),
    ) {
        let _ = decode(&seal(&payload));
    }

    #[test]
    fn blob_decode_of_resealed_mutations_is_valid_or_err(
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
    ) {
        let blob = valid_blob();
        let mut payload = blob[HEADER_LEN..].to_vec();
        for (index, value) in edits {
            let idx = index.index(payload.len());
            payload[idx] = value;
        }
        if let Ok(set) = decode(&seal(&payload)) {
            prop_assert_eq!(validate(&set), Ok(()));
        }
    }
}
