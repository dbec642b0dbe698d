//! The evaluation as a report (tables and figures in Markdown and HTML).

use super::Evaluation;
use reports::{Figure, Report, Section, Table};

fn f3(value: f64) -> String {
    format!("{value:.3}")
}

fn e3(value: f64) -> String {
    format!("{value:.3e}")
}

fn pct(value: f64) -> String {
    format!("{:.1} %", 100.0 * value)
}

/// Builds the report of an evaluation; `source` names the data and the model.
#[must_use]
pub fn evaluation_report(evaluation: &Evaluation, figures: Vec<Figure>, source: &str) -> Report {
    let mut sections = vec![table1(evaluation), coupling_tables(evaluation), noise(evaluation), blocks(evaluation)];
    sections.push(Section {
        heading: "Figures".into(),
        paragraphs: vec![
            "Held-out windows of every angle of attack, side by side along the time axis as in the paper.".into(),
        ],
        tables: vec![],
        figures,
    });
    let mut intro = vec![source.to_owned(), format!("Held-out data only: {}.", evaluation.split)];
    intro.extend(evaluation.notes.iter().map(|note| format!("Note: {note}.")));
    Report { title: "Evaluation: superposition, coupling operator and estimator blocks".into(), intro, sections }
}

fn table1(evaluation: &Evaluation) -> Section {
    let rows = evaluation
        .table1
        .iter()
        .map(|row| {
            vec![
                format!("{}", row.alpha_deg),
                pct(row.ratio_to_mean),
                pct(row.ratio_to_std),
                e3(row.delta_std),
                e3(row.rollact_mean),
            ]
        })
        .collect();
    Section {
        heading: "Table 1: validity of superposition".into(),
        paragraphs: vec!["`Delta C_l = C_l,RollAFC - C_l,Roll - C_l,AFC` from the measured runs, sample by sample (paper section IV); the ratio to the standard deviation stays meaningful when the mean is small.".into()],
        tables: vec![Table {
            caption: "Table 1 (paper: 11 %, 15 %, 30 % at 0, 10, 20 deg)".into(),
            header: vec!["alpha (deg)".into(), "sigma(Delta C_l) / mean(C_l,RollAFC)".into(), "sigma(Delta C_l) / sigma(C_l,RollAFC)".into(), "sigma(Delta C_l)".into(), "mean(C_l,RollAFC)".into()],
            rows,
        }],
        figures: vec![],
    }
}

fn coupling_tables(evaluation: &Evaluation) -> Section {
    let table2 = evaluation
        .coupling
        .iter()
        .map(|row| {
            vec![
                format!("{}", row.alpha_deg),
                e3(row.e_lin),
                e3(row.e_sindy),
                f3(row.ratio),
                span(row.ratio_ci95, |v| format!("{v:.3}")),
                row.n_samples.to_string(),
            ]
        })
        .collect();
    let table3 = evaluation
        .coupling
        .iter()
        .map(|row| {
            vec![
                format!("{}", row.alpha_deg),
                format!("{:.6}", row.corr_linear),
                format!("{:.6}", row.corr_operator),
                format!("{:+.2e}", row.corr_operator - row.corr_linear),
                span(row.corr_change_ci95, |v| format!("{v:+.2e}")),
            ]
        })
        .collect();
    Section {
        heading: "Tables 2 and 3: the coupling operator".into(),
        paragraphs: vec![
            "`E_lin = ||C_l,RollAFC - C_l,Roll^model - C_l,AFC^model||_2` and `E_SINDy` with the operator's correction (paper eqs. 13 and 14), on the held-out samples of the roll+actuation runs.".into(),
            "The intervals are 95 % moving-block bootstrap intervals (1000 resamples of blocks as long as the operator's error stays correlated): a ratio whose interval lies below 1, or a correlation change whose interval lies above 0, is an improvement the held-out data support; an interval that straddles the line is a tie.".into(),
        ],
        tables: vec![
            Table {
                caption: "Table 2: error with the coupling operator (paper: 0.99, 0.90, 0.85)".into(),
                header: vec![
                    "alpha (deg)".into(),
                    "E_lin".into(),
                    "E_SINDy".into(),
                    "E_SINDy / E_lin".into(),
                    "95 % interval".into(),
                    "samples".into(),
                ],
                rows: table2,
            },
            Table {
                caption: "Table 3: correlation with the measured moment (paper at 20 deg: 0.8423 linear, 0.8699 operator)".into(),
                header: vec![
                    "alpha (deg)".into(),
                    "linear assumption".into(),
                    "optimal operator".into(),
                    "change".into(),
                    "95 % interval of the change".into(),
                ],
                rows: table3,
            },
        ],
        figures: vec![],
    }
}

fn noise(evaluation: &Evaluation) -> Section {
    let mut rows = Vec::new();
    for level in &evaluation.noise_robustness {
        for row in &level.per_alpha {
            rows.push(vec![
                format!("{:.2e}", level.sigma),
                format!("{}", row.alpha_deg),
                f3(row.ratio),
                format!("{:.4}", row.corr_linear),
                format!("{:.4}", row.corr_operator),
            ]);
        }
    }
    Section {
        heading: "Noise robustness".into(),
        paragraphs: vec!["Gaussian noise added to the balance moment of every run (the paper's test uses sigma = 0.001), the coupling operator refitted on the noisy training part and scored on the noisy held-out part.".into()],
        tables: vec![Table {
            caption: "Refitted operator on noisy data".into(),
            header: vec!["sigma".into(), "alpha (deg)".into(), "E_SINDy / E_lin".into(), "corr. linear".into(), "corr. operator".into()],
            rows,
        }],
        figures: vec![],
    }
}

fn blocks(evaluation: &Evaluation) -> Section {
    let rows = evaluation
        .blocks
        .iter()
        .map(|row| {
            vec![
                format!("{}", row.alpha_deg),
                row.block.clone(),
                row.runs.clone(),
                e3(row.rms),
                format!("{:.4}", row.correlation),
                format!("{:.2}", row.rms_over_noise),
            ]
        })
        .collect();
    let fusion = evaluation
        .fusion
        .iter()
        .map(|row| {
            vec![
                format!("{}", row.alpha_deg),
                format!("{:.4}", row.over_egk),
                span(row.over_egk_ci95, |v| format!("{v:.4}")),
                format!("{:.4}", row.over_pressure),
                span(row.over_pressure_ci95, |v| format!("{v:.4}")),
            ]
        })
        .collect();
    let noise = evaluation.noise_rms.iter().map(|(alpha, rms)| vec![format!("{alpha}"), e3(*rms)]).collect();
    let information = evaluation
        .pressure_information
        .iter()
        .map(|row| {
            vec![
                format!("{}", row.alpha_deg),
                e3(row.egk_rms),
                e3(row.fused_rms),
                e3(row.best_linear_rms),
                format!("{:+.2} %", 100.0 * (row.best_linear_rms / row.egk_rms - 1.0)),
            ]
        })
        .collect();
    Section {
        heading: "Blocks".into(),
        paragraphs: vec!["Each block's held-out error against the balance: eGK alone, pressure path alone and fused on the roll runs, the plant on the actuation runs, the linear superposition and the estimate with the coupling operator on the roll+actuation runs. RMS / noise divides by the balance's white-noise RMS estimated from the data (the floor no estimator can beat).".into()],
        tables: vec![
            Table {
                caption: "Held-out error per block".into(),
                header: vec!["alpha (deg)".into(), "block".into(), "runs".into(), "RMS".into(), "correlation".into(), "RMS / noise".into()],
                rows,
            },
            Table {
                caption: "The fusion against its sources (roll runs): fused RMS over each source's, with 95 % moving-block bootstrap intervals; below 1 beyond the interval is a gain the held-out data support".into(),
                header: vec![
                    "alpha (deg)".into(),
                    "fused / eGK".into(),
                    "95 % interval".into(),
                    "fused / pressure path".into(),
                    "95 % interval".into(),
                ],
                rows: fusion,
            },
            Table { caption: "Balance noise (white, from first differences)".into(), header: vec!["alpha (deg)".into(), "noise RMS".into()], rows: noise },
            Table {
                caption: "What the pressures know about the eGK's error (roll runs): the eGK's residual regressed on every tap, raw and low-passed at 5, 30 and 200 ms, and on both estimates, fitted on the training part, scored held out; a generous stand-in for the best linear fusion".into(),
                header: vec!["alpha (deg)".into(), "eGK RMS".into(), "fused RMS".into(), "eGK + best linear use of the pressures".into(), "change against the eGK".into()],
                rows: information,
            },
        ],
        figures: vec![],
    }
}

/// A bootstrap interval as `low .. high` with each end written by `each`, `-` without one.
fn span(interval: Option<[f64; 2]>, each: impl Fn(f64) -> String) -> String {
    interval.map_or_else(|| "-".to_owned(), |[low, high]| format!("{} .. {}", each(low), each(high)))
}
