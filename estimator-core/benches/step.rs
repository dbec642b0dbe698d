//! One full estimator step (every stage, default sizes) on the host.
//!
//! Run: `cargo bench -p estimator-core --bench step`. Criterion prints the time per step and the
//! steps per second (`thrpt`, `Melem/s`): one stream (goal: at least 5 million) and 64
//! independent streams on one core (goal: at least 20 million per core).
#![allow(missing_docs)] // criterion_group! generates an undocumented public function.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use estimator_core::coeffs::{MAX_TERMS, N_TAPS, PRESSURE_RANK};
use estimator_core::egk::{Egk, EgkInput};
use estimator_core::pressure::PressureFilter;
use estimator_core::prior::full_size_fixture;
use estimator_core::{Estimator, Health, Input};
use std::hint::black_box;

/// A second of recorded-like input: roll at 1.5 Hz, blowing switching every 0.3 s, noisy
/// pressures, so that no branch is always taken.
fn inputs() -> Vec<Input> {
    (0..1000)
        .map(|step| {
            let t = step as f32 * 1e-3;
            let cp = core::array::from_fn(|tap| -0.3 + 0.02 * tap as f32 + 0.01 * (t * (tap as f32 + 3.0)).sin());
            Input {
                phi_deg: 25.0 * (std::f32::consts::TAU * 1.5 * t).sin(),
                alpha_deg: 20.0,
                cmu_port: if (step / 300) % 2 == 0 { 0.0 } else { 0.006 },
                cmu_stbd: 0.0,
                cp,
            }
        })
        .collect()
}

fn step(c: &mut Criterion) {
    let set = full_size_fixture();
    let inputs = inputs();
    eprintln!(
        "model sizes: {N_TAPS} taps, pressure rank {PRESSURE_RANK}, plant 2 x {MAX_TERMS} terms, coupling {MAX_TERMS} terms, \
         estimator state {} bytes, coefficient set {} bytes",
        std::mem::size_of::<Estimator<'static>>(),
        std::mem::size_of_val(&set)
    );
    let mut estimator = Estimator::new(&set);
    let mut group = c.benchmark_group("estimator");
    group.throughput(Throughput::Elements(1));
    group.bench_function("full_step", |b| {
        let mut idx = 0;
        b.iter(|| {
            idx = (idx + 1) % inputs.len();
            black_box(estimator.step(black_box(&inputs[idx])))
        });
    });
    group.finish();
}

/// Each stage alone, to see where a step's time goes.
fn stages(c: &mut Criterion) {
    let set = full_size_fixture();
    let mut group = c.benchmark_group("stage");
    let mut egk = Egk::new();
    let mut phase = 0.0f32;
    group.bench_function("egk", |b| {
        b.iter(|| {
            phase = (phase + 1e-3) % 1.0;
            let input =
                EgkInput { phi_rad: 0.4 * phase, phi_dot_rad_s: 1.0 - phase, phi_ddot_rad_s2: 3.0, alpha_deg: 20.0 };
            black_box(egk.step(&set, black_box(&input)))
        });
    });
    let mut pressure = PressureFilter::new(&set.pressure);
    let cp = core::array::from_fn(|tap| -0.3 + 0.02 * tap as f32);
    group.bench_function("pressure", |b| {
        b.iter(|| {
            let mut health = Health::default();
            black_box(pressure.step(
                &set.pressure,
                black_box(estimator_core::schedule::SchedulePosition { lower: 0, upper: 1, weight: 0.5 }),
                black_box(&[0.1, 0.2, 0.003, 0.0, 1.0]),
                black_box(&cp),
                &mut health,
            ))
        });
    });
    let vars = [0.01, 0.005, 0.001, 0.3, 0.002, 0.2, 0.5];
    group.bench_function("sparse_16_terms", |b| b.iter(|| black_box(set.coupling.eval(black_box(&vars)))));
    group.finish();
}

/// Independent streams (a replay or a validation campaign steps many runs): one estimator per
/// stream, all stepped in turn on one core; the throughput is steps per second over all streams.
fn many_streams(c: &mut Criterion) {
    const STREAMS: usize = 64;
    let set = full_size_fixture();
    let inputs = inputs();
    let mut estimators: Vec<Estimator<'_>> = (0..STREAMS).map(|_| Estimator::new(&set)).collect();
    let mut group = c.benchmark_group("estimator");
    group.throughput(Throughput::Elements(STREAMS as u64));
    group.bench_function("many_streams_64", |b| {
        let mut idx = 0;
        b.iter(|| {
            idx = (idx + 1) % inputs.len();
            for (stream, estimator) in estimators.iter_mut().enumerate() {
                black_box(estimator.step(black_box(&inputs[(idx + 17 * stream) % inputs.len()])));
            }
        });
    });
    group.finish();
}

criterion_group!(benches, step, stages, many_streams);
criterion_main!(benches);
