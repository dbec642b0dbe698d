//! The human-readable diagnosis: verdict, gap ledger, candidate table, named effects with their
//! held-out shrink, confounded pairs, and plots (residual before and after, profile curves).

use reports::plot::{self, Axes, Series};
use reports::{Figure, Report, Section, Table};

use super::Evidence;
use super::result::{Diagnosis, Verdict};

/// Points plotted per time series.
const PLOT_POINTS: usize = 1500;

/// Builds the report of a diagnosis.
#[must_use]
pub fn build(diagnosis: &Diagnosis, evidence: &Evidence, dataset_name: &str) -> Report {
    let mut report = Report {
        title: format!("Sim-to-real gap diagnosis: {dataset_name}"),
        intro: vec![
            format!("Sim: {}. Split: {}.", diagnosis.sim, diagnosis.split),
            "Gap RMS values are beyond the noise floor, `sqrt(max(MSE - noise^2, 0))`, with the noise from first differences of the residual; `shrink = 1 - after / before` on the held-out part.".into(),
        ],
        sections: Vec::new(),
    };
    report.sections.push(verdict_section(diagnosis));
    report.sections.push(ledger_section(diagnosis));
    report.sections.push(candidates_section(diagnosis));
    report.sections.push(families_section(evidence));
    report.sections.push(plots_section(evidence));
    report
}

fn fmt(value: f64) -> String {
    format!("{value:.3e}")
}

/// A parameter value: plain for ordinary magnitudes, scientific for small or large ones.
fn param(value: &serde_json::Value) -> String {
    match value.as_f64() {
        Some(x) if x != 0.0 && (x.abs() < 1e-2 || x.abs() >= 1e4) => format!("{x:.4e}"),
        Some(x) => format!("{x:.4}"),
        None => value.to_string(),
    }
}

fn verdict_section(diagnosis: &Diagnosis) -> Section {
    let mut paragraphs = vec![format!(
        "Verdict: {}. Held-out gap {} beyond a noise RMS of {} (raw residual RMS {}, {} stream).",
        diagnosis.verdict.as_str(),
        fmt(diagnosis.gap.heldout_rms),
        fmt(diagnosis.gap.noise_rms),
        fmt(diagnosis.gap.heldout_raw_rms),
        diagnosis.gap.stream
    )];
    if let Some(unexplained) = &diagnosis.unexplained {
        paragraphs.push(format!("Unattributed: {}.", unexplained.description));
    }
    if diagnosis.verdict == Verdict::None {
        paragraphs.push("No candidate explains a gap of at least half the noise RMS with decisive evidence: the gap is at the noise floor.".into());
    }
    for pair in &diagnosis.confounded {
        paragraphs.push(format!(
            "`{}` and `{}` cannot be told apart with this data (canonical correlation {}); to separate them: {}.",
            pair.a,
            pair.b,
            figure(pair.canonical_correlation, 3),
            pair.experiment
        ));
    }
    let rows = diagnosis
        .effects
        .iter()
        .map(|effect| {
            let params =
                effect.params.iter().map(|(k, v)| format!("{k} = {}", param(v))).collect::<Vec<_>>().join(", ");
            vec![
                format!("`{}`", effect.name),
                effect.block.clone(),
                params,
                fmt(effect.heldout_rms_before),
                fmt(effect.heldout_rms_after),
                format!("{:.2}", effect.shrink),
                figure(effect.effect_to_noise, 2),
                effect.evidence.clone(),
            ]
        })
        .collect();
    Section {
        heading: "Verdict and named effects".into(),
        paragraphs,
        tables: vec![Table {
            caption: "Named effects, most responsible first (parameters fitted on the training part; gap on the held-out part)".into(),
            header: ["effect", "block", "parameters", "gap before", "gap after", "shrink", "effect/noise", "evidence"]
                .map(String::from)
                .to_vec(),
            rows,
        }],
        figures: Vec::new(),
    }
}

fn ledger_section(diagnosis: &Diagnosis) -> Section {
    let where_ = &diagnosis.where_;
    let mut paragraphs = vec![format!(
        "Block: {}. Angles of attack: {:?} deg. Channel: {}. Band: {}. Runs: {}.",
        where_.block.as_deref().unwrap_or("none"),
        where_.alpha_deg,
        where_.channel.as_deref().unwrap_or("none"),
        where_.band_hz.map_or_else(|| "n/a".to_owned(), |b| format!("{:.1}-{:.1} Hz", b[0], b[1])),
        if where_.runs.is_empty() { "none".to_owned() } else { where_.runs.join(", ") }
    )];
    paragraphs.push(format!(
        "Balance residual on the training part: noise variance {:.3e}, integrated autocorrelation time {:.1} samples; diagnosis took {:.2} s.",
        diagnosis.noise_var_training, diagnosis.autocorrelation_time_samples, diagnosis.elapsed_s
    ));
    let ledger = &diagnosis.ledger;
    let white = |w: &Option<super::ledger::Whiteness>| {
        w.as_ref().map_or_else(
            || "n/a".to_owned(),
            |w| {
                format!(
                    "Q = {:.1} over {} lags, p = {:.3} ({})",
                    w.q,
                    w.lags,
                    w.p_value,
                    if w.white { "white" } else { "not white" }
                )
            },
        )
    };
    paragraphs.push(format!(
        "Whiteness of the held-out balance residual (Ljung-Box, 1 %): before, {}; after the named effects, {}.",
        white(&ledger.whiteness_before),
        white(&ledger.whiteness_after)
    ));
    let regimes = Table {
        caption: "Held-out balance residual energy by regime (95 % stationary-bootstrap interval of the mean square)"
            .into(),
        header: ["regime", "samples", "share", "mean square", "95 % interval"].map(String::from).to_vec(),
        rows: ledger
            .regimes
            .iter()
            .map(|r| {
                vec![
                    r.label.clone(),
                    r.n_samples.to_string(),
                    format!("{:.3}", r.share),
                    fmt(r.mse),
                    format!("{} - {}", fmt(r.mse_ci95[0]), fmt(r.mse_ci95[1])),
                ]
            })
            .collect(),
    };
    let bands = Table {
        caption: "Share of the residual power beyond the white-noise floor, by band".into(),
        header: ["band (Hz)", "share", "RMS"].map(String::from).to_vec(),
        rows: ledger
            .bands
            .iter()
            .map(|b| vec![format!("{:.1} - {:.1}", b.band_hz[0], b.band_hz[1]), format!("{:.3}", b.share), fmt(b.rms)])
            .collect(),
    };
    let ccf = Table {
        caption: "Residual-input cross-correlation (held-out; positive lag: the input leads; 99 % bound for coloured signals, family-wise over the lags)".into(),
        header: ["input", "peak lag (samples)", "peak", "bound", "significant", "coherent bands (Hz)"].map(String::from).to_vec(),
        rows: ledger
            .cross_correlation
            .iter()
            .map(|c| {
                let bands = ledger
                    .coherent_bands_hz
                    .iter()
                    .find(|(name, _)| *name == c.input)
                    .map(|(_, b)| b.iter().take(4).map(|b| format!("{:.1}-{:.1}", b[0], b[1])).collect::<Vec<_>>().join(", "))
                    .unwrap_or_default();
                vec![c.input.clone(), c.peak_lag.to_string(), format!("{:.3}", c.peak), format!("{:.3}", c.family_bound_99), if c.significant { "yes".into() } else { "no".into() }, bands]
            })
            .collect(),
    };
    let channels = Table {
        caption: "Pressure channels: innovation statistics on the held-out part (normalised by each channel's difference-based noise)".into(),
        header: ["channel", "missing", "mean (sigma)", "std ratio", "outliers", "longest constant (s)", "whiteness p"].map(String::from).to_vec(),
        rows: ledger
            .channels
            .iter()
            .map(|c| {
                vec![
                    c.channel.clone(),
                    format!("{:.3}", c.missing_fraction),
                    format!("{:.2}", c.mean_sigma),
                    format!("{:.2}", c.std_ratio),
                    format!("{:.4}", c.outlier_fraction),
                    format!("{:.3}", c.longest_constant_run_s),
                    format!("{:.3}", c.whiteness_p),
                ]
            })
            .collect(),
    };
    Section {
        heading: "Where the gap lies".into(),
        paragraphs,
        tables: vec![regimes, bands, ccf, channels],
        figures: Vec::new(),
    }
}

fn candidates_section(diagnosis: &Diagnosis) -> Section {
    let rows = diagnosis
        .candidates
        .iter()
        .map(|c| {
            let hyper = c.hyper.iter().map(|(k, v)| format!("{k} = {}", param(v))).collect::<Vec<_>>().join(", ");
            vec![
                format!("`{}`", c.name),
                c.block.clone(),
                hyper,
                figure(c.explained_to_noise, 3),
                figure(c.selected_to_noise, 3),
                figure(c.delta_bic, 1),
                figure(c.heldout_shrink, 2),
            ]
        })
        .collect();
    Section {
        heading: "Which effect: every candidate".into(),
        paragraphs: vec![
            "Each candidate is profiled over its grid of physical parameters on the training part; `explained/noise` is the mean square it explains on the runs it touches over the noise variance; `delta BIC` penalises its columns and profiled parameters on the effective number of samples. `confirmed/noise` is the size the selection part, which it was not fitted on, confirms per sample where it acts: the larger of what it removes there and what it explains on the training part times its calibration slope there (balance candidates; for sensor findings, what it removes there). An effect is named on it, beyond the sim's own signature, and its shrink is reported on the held-out part, which chooses nothing. Recalibration of the existing blocks competes with the new effects.".into(),
        ],
        tables: vec![Table {
            caption: "Candidates (balance, best first; then sensor)".into(),
            header: [
                "candidate",
                "block",
                "profiled parameters",
                "explained/noise (training)",
                "confirmed/noise (selection)",
                "delta BIC",
                "held-out shrink",
            ]
            .map(String::from)
            .to_vec(),
            rows,
        }],
        figures: Vec::new(),
    }
}

/// The grids and ranges every family searched: what a `none` or an `unattributed` rules out.
fn families_section(evidence: &Evidence) -> Section {
    let rows = evidence
        .families
        .iter()
        .map(|family| {
            vec![
                format!("`{}`", family.name),
                family.forms.map_or_else(|| "scan".to_owned(), |n| n.to_string()),
                family.searched.clone(),
            ]
        })
        .collect();
    Section {
        heading: "What each candidate family searched".into(),
        paragraphs: vec![
            "An effect outside these forms and ranges is not ruled out by this diagnosis; the structure probe only says that something remains.".into(),
        ],
        tables: vec![Table {
            caption: "Candidate families on this recording".into(),
            header: ["candidate", "forms", "parameters searched"].map(String::from).to_vec(),
            rows,
        }],
        figures: Vec::new(),
    }
}

fn plots_section(evidence: &Evidence) -> Section {
    let mut figures = Vec::new();
    if let Some((run_idx, run)) = evidence.runs.iter().enumerate().max_by(|a, b| {
        let energy = |idx: usize| -> f64 {
            let run = &evidence.runs[idx];
            run.heldout.clone().map(|i| run.residual[i]).filter(|v| v.is_finite()).map(|v| v * v).sum()
        };
        energy(a.0).total_cmp(&energy(b.0))
    }) {
        let step = (run.heldout.len() / PLOT_POINTS).max(1);
        let series = |name: &str, values: &[f64]| Series {
            name: name.into(),
            points: run.heldout.clone().step_by(step).map(|i| (run.t_s[i], values[i])).collect(),
            line: true,
        };
        figures.push(Figure {
            file: "residual.svg".into(),
            caption: format!(
                "Balance residual on the held-out part of {}, before and after the named effects",
                run.file
            ),
            svg: plot::svg(
                &Axes {
                    title: format!("Residual, {}", run.file),
                    x_label: "t (s)".into(),
                    y_label: "C_l".into(),
                    log_y: false,
                },
                &[
                    series("measured - sim", &run.residual),
                    series("after the named effects", &evidence.remainder[run_idx]),
                ],
            ),
        });
    }
    for profiled in evidence.first_round.iter().filter(|p| p.profile.len() > 1).take(3) {
        let name = profiled.candidate.name();
        figures.push(Figure {
            file: format!("profile_{name}.svg"),
            caption: format!("Profile of `{name}`: training residual sum of squares over its first grid parameter"),
            svg: plot::svg(
                &Axes {
                    title: format!("Profile, {name}"),
                    x_label: profiled.form.coordinate().map_or("parameter", |(k, _)| k).into(),
                    y_label: "SSR".into(),
                    log_y: false,
                },
                &[Series { name: name.into(), points: profiled.profile.clone(), line: false }],
            ),
        });
    }
    Section { heading: "Plots".into(), paragraphs: Vec::new(), tables: Vec::new(), figures }
}

/// A figure with `decimals` decimals, or `n/a` where it is unknown.
fn figure(value: Option<f64>, decimals: usize) -> String {
    value.map_or_else(|| "n/a".to_owned(), |v| format!("{v:.decimals$}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::Family;

    /// One row per family, a scanned family marked as such, the text as given.
    #[test]
    fn the_families_section_has_a_row_per_family() {
        let families = vec![
            Family { name: "inertial_tare", forms: Some(1), searched: "the roll acceleration".into() },
            Family { name: "pressure_lag", forms: None, searched: "every channel".into() },
        ];
        let evidence =
            Evidence { runs: Vec::new(), first_round: Vec::new(), named: Vec::new(), remainder: Vec::new(), families };
        let section = families_section(&evidence);
        let rows = &section.tables[0].rows;
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0], ["`inertial_tare`", "1", "the roll acceleration"].map(String::from).to_vec());
        assert_eq!(rows[1], ["`pressure_lag`", "scan", "every channel"].map(String::from).to_vec());
    }
}
