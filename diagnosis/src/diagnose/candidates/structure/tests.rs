//! Tests of [`super`]: the `structure` module on synthetic data with known answers.

use super::*;
use crate::diagnose::candidates::{test_context, test_fit};
use crate::diagnose::streams::synthetic_run;

/// Driven at its natural frequency, a resonator settles to `1 / (2 zeta)` times the input
/// amplitude (the bilinear transform is pre-warped there).
#[test]
fn resonator_peak_gain_is_one_over_two_zeta() {
    let (sample_hz, freq_hz, zeta) = (1000.0, 20.0, 0.05);
    let input: Vec<f64> = (0..20_000).map(|i| (std::f64::consts::TAU * freq_hz * i as f64 / sample_hz).sin()).collect();
    let out = resonator(&input, freq_hz, zeta, 1.0 / sample_hz);
    let amplitude = out[15_000..].iter().fold(0.0, |acc: f64, v| acc.max(v.abs()));
    assert!((amplitude - 10.0).abs() < 0.1, "{amplitude}");
}

/// The paired pass is the resonator's excess over its input, scaled, for each input.
#[test]
fn paired_mode_excess_is_the_resonator_less_its_input() {
    let a: Vec<f64> = (0..500).map(|i| (i as f64 * 0.37).sin() + 0.2).collect();
    let b: Vec<f64> = (0..500).map(|i| (i as f64 * 0.011).cos() * 3.0).collect();
    let [ea, eb] = mode_excess([&a, &b], [1.0, 0.5], 30.0, 0.02, 1e-3);
    for (input, excess, scale) in [(&a, &ea, 1.0), (&b, &eb, 0.5)] {
        let direct = resonator(input, 30.0, 0.02, 1e-3);
        for idx in 0..input.len() {
            assert!((excess[idx] - scale * (direct[idx] - input[idx])).abs() < 1e-12);
        }
    }
}

/// A mode at 50 Hz (damping 0.03) rung by white noise, under white measurement noise of
/// a third of its RMS: the rung form at the mode predicts most of it one sample ahead; a
/// steady tone of the same RMS in the band, or a residual coloured by a slow lag, gives the
/// form nothing to fit.
#[test]
fn a_randomly_rung_mode_is_predicted_from_its_past_but_a_tone_is_not() {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let (sample_hz, n, freq_hz, zeta) = (1000.0, 20_000, 50.0, 0.03);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let white = Normal::new(0.0, 1.0).unwrap();
    let drive: Vec<f64> = (0..n).map(|_| white.sample(&mut rng)).collect();
    let mode = resonator(&drive, freq_hz, zeta, 1.0 / sample_hz);
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let mode_rms = rms(&mode[2000..]);
    let noise = Normal::new(0.0, mode_rms / 3.0).unwrap();
    let mut run = synthetic_run(sample_hz, vec![vec![0.0; n]], vec![vec![0.0; n]]);
    run.residual = mode.iter().map(|m| m + noise.sample(&mut rng)).collect();
    let shape = Shape::Ringing { freq_hz, zeta };
    let columns = BalanceResonance.columns(&shape, &run, 0, &test_context());
    let target = &run.residual[2000..];
    let cut: Vec<Vec<f64>> = columns.iter().map(|c| c[2000..].to_vec()).collect();
    let beta = test_fit(&cut, target);
    let left: Vec<f64> = target.iter().enumerate().map(|(i, r)| r - beta[0] * cut[0][i]).collect();
    let removed = (rms(target).powi(2) - rms(&left).powi(2)) / rms(&mode[2000..]).powi(2);
    assert!(removed > 0.7, "removed {removed} of the mode's variance");
    // A mode's recursion at another frequency predicts little of it.
    let off = BalanceResonance.columns(&Shape::Ringing { freq_hz: 35.0, zeta }, &run, 0, &test_context());
    let off: Vec<f64> = off[0][2000..].to_vec();
    let beta_off = test_fit(std::slice::from_ref(&off), target);
    let left_off: Vec<f64> = target.iter().zip(&off).map(|(r, c)| r - beta_off[0] * c).collect();
    let removed_off = (rms(target).powi(2) - rms(&left_off).powi(2)) / rms(&mode[2000..]).powi(2);
    assert!(removed_off < 0.5 * removed, "35 Hz removed {removed_off}, 50 Hz {removed}");

    let tone: Vec<f64> = (0..n)
        .map(|i| mode_rms * 2f64.sqrt() * (std::f64::consts::TAU * freq_hz * i as f64 / sample_hz).sin())
        .collect();
    run.residual = tone.iter().map(|t| t + noise.sample(&mut rng)).collect();
    let columns = BalanceResonance.columns(&shape, &run, 0, &test_context());
    assert!(columns.iter().all(|c| c.iter().all(|v| *v == 0.0)), "a tone is no rung mode");

    // Coloured noise (white through a 0.1 s lag, as a missing slow state leaves) is
    // predictable from its past at 5 Hz too, but has no peak there.
    let coloured = model_fit::fit::signals::first_order_lag(&drive, 0.1, 1.0 / sample_hz);
    run.residual = coloured.iter().map(|c| c + noise.sample(&mut rng)).collect();
    let columns = BalanceResonance.columns(&Shape::Ringing { freq_hz: 5.0, zeta: 0.07 }, &run, 0, &test_context());
    assert!(columns.iter().all(|c| c.iter().all(|v| *v == 0.0)), "coloured noise is no rung mode");
}

/// A mode of damping 0.01 at 27.3 Hz, between two points of the coarse grid, rung by white
/// noise under white noise of a third of its RMS: its spectral peak is a seed within a bin
/// (0.5 Hz) of its frequency, and white noise alone seeds nothing.
#[test]
fn a_narrow_mode_off_the_grid_seeds_its_own_frequency() {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let (sample_hz, n, freq_hz, zeta) = (1000.0, 20_000, 27.3, 0.01);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let white = Normal::new(0.0, 1.0).unwrap();
    let drive: Vec<f64> = (0..n).map(|_| white.sample(&mut rng)).collect();
    let mode = resonator(&drive, freq_hz, zeta, 1.0 / sample_hz);
    let mode_rms = (mode.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
    let noise = Normal::new(0.0, mode_rms / 3.0).unwrap();
    let mut run = synthetic_run(sample_hz, vec![vec![0.0; n]], vec![vec![0.0; n]]);
    let residual: Vec<f64> = mode.iter().map(|m| m + noise.sample(&mut rng)).collect();
    run.residual.clone_from(&residual);
    let band_hz = BalanceResonance::band_hz(sample_hz, 4.0);
    let grid = log_grid(band_hz.0, band_hz.1, RESONANCE_COARSE);
    let nearest = grid.iter().map(|f| (f / freq_hz).ln().abs()).fold(f64::INFINITY, f64::min);
    assert!(nearest > 2.0 * zeta, "the mode lies off the grid");
    let seeds = resonance_seeds_hz(std::slice::from_ref(&run), &[residual], band_hz);
    assert!((seeds[0] - freq_hz).abs() <= 0.5, "{seeds:?}");
    let quiet: Vec<f64> = (0..n).map(|_| noise.sample(&mut rng)).collect();
    assert_eq!(resonance_seeds_hz(std::slice::from_ref(&run), &[quiet], band_hz), Vec::<f64>::new());
}

/// A stiff mode (35 Hz, damping 0.09) driven by a slow roll (sines of 0.3 to 2.7 Hz) that
/// an encoder reads in steps of 0.005 deg: what the mode adds is about a hundredth of the
/// acceleration, and above the motion the twice-differentiated steps are all the 40 Hz
/// acceleration holds there. Its gain comes out a few hundredths of the truth (measured:
/// 0.02); the corner that explains the most (4 Hz, 2 % of the effect left) gives it within a
/// fifth.
#[test]
fn a_mode_driven_by_a_slow_quantised_motion_is_fitted_on_the_smoothed_acceleration() {
    let (sample_hz, n) = (1000.0, 20_000);
    let t = |i: usize| i as f64 / sample_hz;
    let sines = [(0.3, 0.30, 0.2), (0.9, 0.12, 1.0), (1.7, 0.06, 2.0), (2.7, 0.03, 4.0)];
    let phi = |time: f64| sines.iter().map(|(f, a, p)| a * (std::f64::consts::TAU * f * time + p).sin()).sum::<f64>();
    let accel = |time: f64| {
        sines
            .iter()
            .map(|(f, a, p)| -a * (std::f64::consts::TAU * f).powi(2) * (std::f64::consts::TAU * f * time + p).sin())
            .sum::<f64>()
    };
    let quantum_rad = 0.005f64.to_radians();
    let mut run = synthetic_run(sample_hz, vec![vec![0.0; n]], vec![vec![0.0; n]]);
    run.phi_rad = (0..n).map(|i| (phi(t(i)) / quantum_rad).round() * quantum_rad).collect();
    run.phi_ddot_rad_s2 = crate::diagnose::streams::acceleration(&run.phi_rad, MODE_DRIVE_CORNERS_HZ[0], sample_hz);
    run.phi_ddot_smoother_rad_s2 = MODE_DRIVE_CORNERS_HZ[1..]
        .iter()
        .map(|corner_hz| crate::diagnose::streams::acceleration(&run.phi_rad, *corner_hz, sample_hz))
        .collect();
    let context = test_context();
    let (freq_hz, zeta, gain) = (35.0, 0.09, 2.0);
    let true_accel: Vec<f64> = (0..n).map(|i| accel(t(i))).collect();
    let [_, effect] =
        mode_excess([&true_accel, &true_accel], [1.0, gain / context.moment_scale_nm], freq_hz, zeta, 1e-3);
    let fitted: Vec<(f64, f64)> = MODE_DRIVE_CORNERS_HZ
        .iter()
        .map(|&drive_corner_hz| {
            let shape = Shape::Mode { freq_hz, zeta, drive_corner_hz };
            let column = BalanceResonance.columns(&shape, &run, 0, &context).swap_remove(1);
            let beta = test_fit(std::slice::from_ref(&column), &effect)[0];
            let left: f64 = column.iter().zip(&effect).map(|(c, e)| (e - beta * c).powi(2)).sum();
            (beta, left / effect.iter().map(|e| e * e).sum::<f64>())
        })
        .collect();
    assert!(fitted[0].0.abs() < 0.3 * gain, "40 Hz: {:?}", fitted[0]);
    let best = fitted.iter().min_by(|a, b| a.1.total_cmp(&b.1)).copied().unwrap_or_default();
    assert!((best.0 - gain).abs() < 0.2 * gain && best.1 < 0.1, "{fitted:?}");
}

/// The resonance's coarse grid starts at the context's floor and stops at 0.35 of the sample
/// rate, for the recorded drives and the rung form alike; its refinement around a leading
/// form holds every damping from 0.005 to 0.3 (to 0.1 for the rung form) within a coarse cell
/// of its frequency.
#[test]
fn resonance_forms_span_the_stated_ranges() {
    let context = test_context();
    let shapes = BalanceResonance.shapes(1000.0, &context);
    let span = |shapes: &[Shape]| {
        let (mut low, mut high, mut least_zeta, mut most_zeta) = (f64::MAX, 0.0f64, f64::MAX, 0.0f64);
        for shape in shapes {
            let (Shape::Mode { freq_hz, zeta, .. } | Shape::Ringing { freq_hz, zeta }) = *shape else {
                panic!("{shape:?}")
            };
            (low, high) = (low.min(freq_hz), high.max(freq_hz));
            (least_zeta, most_zeta) = (least_zeta.min(zeta), most_zeta.max(zeta));
        }
        (low, high, least_zeta, most_zeta)
    };
    let (low, high, _, _) = span(&shapes);
    assert!((low - 4.0).abs() < 1e-9 && (high - 300.0).abs() < 1e-9, "{low} {high}");
    assert_eq!(
        shapes.len(),
        RESONANCE_COARSE
            * (RESONANCE_DAMPING_COARSE.len() * RESONANCE_CORNERS_COARSE.len() + RINGING_DAMPING_COARSE.len())
    );
    let rung: Vec<Shape> = shapes.iter().filter(|s| matches!(s, Shape::Ringing { .. })).copied().collect();
    let (low, high, _, _) = span(&rung);
    assert!((low - 4.0).abs() < 1e-9 && (high - 300.0).abs() < 1e-9, "{low} {high}");
    let fine_rung = BalanceResonance.refine(&Shape::Ringing { freq_hz: 50.0, zeta: 0.02 }, 1000.0, &context);
    assert!(fine_rung.iter().all(|s| matches!(s, Shape::Ringing { .. })));
    assert_eq!(span(&fine_rung).2..=span(&fine_rung).3, 0.005..=0.1);
    let fine =
        BalanceResonance.refine(&Shape::Mode { freq_hz: 50.0, zeta: 0.08, drive_corner_hz: 8.0 }, 1000.0, &context);
    let corners: std::collections::BTreeSet<u64> = fine
        .iter()
        .map(|s| if let Shape::Mode { drive_corner_hz, .. } = s { drive_corner_hz.to_bits() } else { 0 })
        .collect();
    assert_eq!(corners.len(), MODE_DRIVE_CORNERS_HZ.len(), "every corner at the leading mode");
    let (low, high, least_zeta, most_zeta) = span(&fine);
    let ratio = (300.0f64 / 4.0).powf(1.0 / (RESONANCE_COARSE - 1) as f64);
    assert!((low - 50.0 / ratio).abs() < 1e-9 && (high - 50.0 * ratio).abs() < 1e-9, "{low} {high}");
    assert_eq!((least_zeta, most_zeta), (0.005, 0.3));
}

/// A zero that steps twice in a run is found at its two steps (to a few samples) from the
/// training part, and a step form of two steps reproduces it.
#[test]
fn a_stepped_zero_is_found_at_its_steps() {
    let sample_hz = 100.0;
    let n = 3000;
    let mut run = synthetic_run(sample_hz, vec![vec![0.0; n]], vec![vec![0.0; n]]);
    run.training = 0..2400;
    run.residual = run
        .t_s
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let noise = 2e-4 * ((i * 7919 % 101) as f64 / 50.0 - 1.0);
            noise + if *t >= 7.3 { 2e-3 } else { 0.0 } + if *t >= 15.55 { -3e-3 } else { 0.0 }
        })
        .collect();
    let times = step_times_s(&run, 2);
    assert_eq!(times.len(), 2);
    assert!((times[0] - 7.3).abs() < 0.05 && (times[1] - 15.55).abs() < 0.05, "{times:?}");
}

/// A zero that wanders, piecewise linear with kinks at 2 s and 6 s, is reproduced exactly by
/// the 2 s knots of run 1; run 0's columns are zero in run 1; the largest drift is the value
/// at the end of the run.
#[test]
fn wandering_drift_is_reproduced_in_its_own_runs_columns() {
    let context = test_context();
    let sample_hz = 100.0;
    let run = synthetic_run(sample_hz, vec![vec![0.0; 1001]], vec![vec![0.0; 1001]]);
    let drift: Vec<f64> =
        run.t_s.iter().map(|t| 1e-3 * t - 3e-3 * (t - 2.0).max(0.0) + 2.5e-3 * (t - 6.0).max(0.0)).collect();
    let shape = Shape::Wander { knot_spacing_s: 2.0 };
    let columns = BiasDrift.columns(&shape, &run, 1, &context);
    let width = 1 + (context.longest_run_s / 2.0).floor() as usize;
    assert_eq!(columns.len(), 2 * width);
    assert!(columns[..width].iter().flatten().all(|v| *v == 0.0), "run 0's slots");
    let own = &columns[width..];
    // The columns of the knots at and past the run's end (10 s) are all zero: leave them out.
    let used: Vec<Vec<f64>> = own.iter().filter(|c| c.iter().any(|v| *v != 0.0)).cloned().collect();
    let beta = test_fit(&used, &drift);
    let fitted: Vec<f64> = (0..run.len()).map(|i| used.iter().zip(&beta).map(|(c, b)| c[i] * b).sum()).collect();
    let worst = fitted.iter().zip(&drift).map(|(f, d)| (f - d).abs()).fold(0.0, f64::max);
    assert!(worst < 1e-12, "{worst}");
    let full_beta: Vec<f64> = {
        let mut it = beta.iter();
        own.iter().map(|c| if c.iter().any(|v| *v != 0.0) { *it.next().unwrap() } else { 0.0 }).collect()
    };
    let params = BiasDrift.params(&shape, &full_beta, &context, &[own.to_vec()]);
    assert!((params[0].1 - drift[1000]).abs() < 1e-12, "{params:?} vs {}", drift[1000]);
}

/// A trend of degree 2 holds t/T and (t/T)^2 and nothing else.
#[test]
fn trend_columns_are_powers_of_normalised_time() {
    let context = test_context();
    let run = synthetic_run(10.0, vec![vec![0.0; 11]], vec![vec![0.0; 11]]);
    let columns = BiasDrift.columns(&Shape::Trend { degree: 2 }, &run, 0, &context);
    assert_eq!(columns.len(), 4);
    assert!((columns[0][5] - 0.5).abs() < 1e-12 && (columns[1][5] - 0.25).abs() < 1e-12);
    assert!(columns[2].iter().chain(&columns[3]).all(|v| *v == 0.0));
}
