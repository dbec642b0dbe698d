//! The `sil` report: the closed-loop comparison of the controller scenarios per angle of attack
//! (tables, SVG plots of C_l and Cmu, `sil.json` with every number).

use std::path::Path;

use firmware_sim::sil::{Mode, SilContext, SilRecord, SilResults};

use reports::plot::{Axes, Series, svg};
use reports::{Figure, Report, Section, Table, write_report};

/// The JSON file of a SIL report.
pub const JSON_FILE: &str = "sil.json";

/// Percentage with one decimal.
fn percent(value: f64) -> String {
    format!("{:.1} %", 100.0 * value)
}

fn sci(value: f64) -> String {
    format!("{value:.3e}")
}

/// The summary rows: alpha, RMS none, RMS ff+fb linear, its reduction, RMS ff+fb coupled, its
/// reduction, and what the coupling adds (difference of the reductions, percentage points).
#[must_use]
pub fn summary_rows(results: &SilResults) -> Vec<Vec<String>> {
    let mut rows = Vec::new();
    for alpha in results.alphas_deg() {
        let rms = |mode| results.run(alpha, mode).map_or(f64::NAN, |run| run.metrics.rms_cl);
        let reduction = |mode| results.reduction(alpha, mode).unwrap_or(f64::NAN);
        let (linear, coupled) = (reduction(Mode::FfFbLinear), reduction(Mode::FfFbCoupled));
        rows.push(vec![
            format!("{alpha:.1}"),
            sci(rms(Mode::None)),
            sci(rms(Mode::Feedback)),
            percent(reduction(Mode::Feedback)),
            sci(rms(Mode::Feedforward)),
            percent(reduction(Mode::Feedforward)),
            sci(rms(Mode::FfFbLinear)),
            percent(linear),
            sci(rms(Mode::FfFbCoupled)),
            percent(coupled),
            format!("{:+.2} pp", 100.0 * (coupled - linear)),
        ]);
    }
    rows
}

/// The summary header matching [`summary_rows`].
#[must_use]
pub fn summary_header() -> Vec<String> {
    [
        "alpha (deg)",
        "RMS none",
        "RMS fb",
        "red. fb",
        "RMS ff",
        "red. ff",
        "RMS ff+fb lin.",
        "red. ff+fb lin.",
        "RMS ff+fb coupl.",
        "red. ff+fb coupl.",
        "coupling adds",
    ]
    .map(String::from)
    .to_vec()
}

fn alpha_table(results: &SilResults, alpha: f64) -> Table {
    let mut rows = Vec::new();
    for mode in Mode::ALL {
        let Some(run) = results.run(alpha, mode) else { continue };
        let m = &run.metrics;
        rows.push(vec![
            format!("`{}`", mode.name()),
            sci(m.rms_cl),
            results.reduction(alpha, mode).map_or("-".into(), percent),
            sci(m.peak_cl),
            sci(m.rms_cl_balance),
            format!("{:.5}", m.mean_cmu[0]),
            format!("{:.5}", m.mean_cmu[1]),
            percent(m.saturated_fraction),
            format!("{} / {}", percent(m.at_max_fraction[0]), percent(m.at_max_fraction[1])),
            m.rms_disturbance_error.map_or("-".into(), sci),
        ]);
    }
    Table {
        caption: format!("alpha = {alpha:.1} deg ({} samples after the warm-up)", results.runs[0].metrics.n_samples),
        header: [
            "scenario",
            "RMS C_l",
            "RMS reduction",
            "peak |C_l|",
            "RMS C_l balance",
            "mean Cmu port",
            "mean Cmu stbd",
            "saturated",
            "at Cmu_max port / stbd",
            "RMS C_l,roll error (unblown)",
        ]
        .map(String::from)
        .to_vec(),
        rows,
    }
}

fn trace_points(t_s: &[f64], values: &[f64], end_s: f64) -> Vec<(f64, f64)> {
    t_s.iter().zip(values).filter(|(t, _)| **t <= end_s).map(|(&t, &v)| (t, v)).collect()
}

fn alpha_figures(results: &SilResults, alpha: f64) -> Vec<Figure> {
    let tag = format!("{alpha:.1}").replace('.', "p").replace('-', "m");
    let end_s = results.duration_s.min(10.0);
    let mut figures = Vec::new();
    let mut cl_series = Vec::new();
    for mode in [Mode::None, Mode::FfFbLinear, Mode::FfFbCoupled] {
        if let Some(run) = results.run(alpha, mode) {
            cl_series.push(Series {
                name: mode.name().into(),
                points: trace_points(&run.trace.t_s, &run.trace.cl_aero, end_s),
                line: true,
            });
        }
    }
    if cl_series.iter().any(|series| !series.points.is_empty()) {
        let axes = Axes {
            title: format!("Roll moment, alpha = {alpha:.1} deg"),
            x_label: "t (s)".into(),
            y_label: "C_l (aerodynamic, noise-free)".into(),
            log_y: false,
        };
        figures.push(Figure {
            file: format!("sil_cl_a{tag}.svg"),
            caption: format!(
                "Noise-free aerodynamic C_l at alpha {alpha:.1} deg: no control against feedforward + feedback (first {end_s:.0} s)."
            ),
            svg: svg(&axes, &cl_series),
        });
    }
    if let Some(run) = results.run(alpha, Mode::FfFbLinear) {
        let series = vec![
            Series {
                name: "port".into(),
                points: trace_points(&run.trace.t_s, &run.trace.cmu_port, end_s),
                line: true,
            },
            Series {
                name: "starboard".into(),
                points: trace_points(&run.trace.t_s, &run.trace.cmu_stbd, end_s),
                line: true,
            },
        ];
        if series.iter().any(|series| !series.points.is_empty()) {
            let axes = Axes {
                title: format!("Commanded Cmu (ff+fb linear), alpha = {alpha:.1} deg"),
                x_label: "t (s)".into(),
                y_label: "Cmu".into(),
                log_y: false,
            };
            figures.push(Figure {
                file: format!("sil_cmu_a{tag}.svg"),
                caption: format!(
                    "Commanded Cmu of both jets, feedforward + feedback (linear), alpha {alpha:.1} deg (first {end_s:.0} s)."
                ),
                svg: svg(&axes, &series),
            });
        }
    }
    figures
}

/// The report of a SIL comparison.
#[must_use]
pub fn sil_report(results: &SilResults, context: &SilContext) -> Report {
    let gains = results.gains;
    let intro = vec![
        format!("Model: {}. Scenario: {}.", context.model, context.scenario),
        format!(
            "Closed loop at {} Hz, {} s per run, seed {} (roll command and noise; every scenario at one alpha sees the same ones). Metrics on the tunnel's noise-free aerodynamic roll moment after a {} s warm-up. Gains: causality filter T_F = {:.4} s, K_p = {}, K_i = {} /s, Cmu_max = {}.",
            results.sample_hz,
            results.duration_s,
            results.seed,
            results.settings.warmup_s,
            gains.causality_tau_s,
            gains.feedback_kp,
            gains.feedback_ki,
            results.cmu_max
        ),
    ];
    let mut summary = Section {
        heading: "Summary".into(),
        paragraphs: vec![
            "RMS reduction = 1 - RMS(scenario) / RMS(no control). \"Coupling adds\" is the reduction with the coupling operator's correction in the feedforward minus the reduction with the linear-superposition estimate.".into(),
        ],
        tables: vec![Table { caption: "RMS C_l per scenario".into(), header: summary_header(), rows: summary_rows(results) }],
        figures: Vec::new(),
    };
    summary.paragraphs.push(verdict(results));
    let mut sections = vec![summary];
    for alpha in results.alphas_deg() {
        sections.push(Section {
            heading: format!("alpha = {alpha:.1} deg"),
            paragraphs: Vec::new(),
            tables: vec![alpha_table(results, alpha)],
            figures: alpha_figures(results, alpha),
        });
    }
    if let Some((seed, points)) = &context.tuning {
        let rows = points
            .iter()
            .take(12)
            .map(|point| {
                let mut row = vec![
                    format!("{:.4}", point.gains.causality_tau_s),
                    format!("{}", point.gains.feedback_kp),
                    format!("{}", point.gains.feedback_ki),
                ];
                row.extend(point.ratios.iter().map(|&ratio| format!("{ratio:.4}")));
                row.push(format!("{:.4}", point.objective));
                row
            })
            .collect();
        let mut header: Vec<String> = ["T_F (s)", "K_p", "K_i (1/s)"].map(String::from).to_vec();
        header.extend(results.alphas_deg().iter().map(|alpha| format!("ratio a{alpha:.0}")));
        header.push("worst ratio".into());
        sections.push(Section {
            heading: "Gain search".into(),
            paragraphs: vec![format!(
                "Grid search of the feedforward + feedback (linear) gains at seed {seed} (not the reported seed): the objective is the worst RMS(ff+fb)/RMS(none) over the alphas. Best {} of {} points:",
                points.len().min(12),
                points.len()
            )],
            tables: vec![Table { caption: "gain search, best first".into(), header, rows }],
            figures: Vec::new(),
        });
    }
    Report { title: "SIL: estimator and controller in closed loop with the synthetic tunnel".into(), intro, sections }
}

/// One sentence on the acceptance criterion and the coupling operator.
#[must_use]
pub fn verdict(results: &SilResults) -> String {
    let alphas = results.alphas_deg();
    let reductions: Vec<f64> =
        alphas.iter().map(|&alpha| results.reduction(alpha, Mode::FfFbLinear).unwrap_or(f64::NAN)).collect();
    let all_lower = reductions.iter().all(|&r| r > 0.0);
    let within =
        results.runs.iter().all(|run| run.metrics.min_cmu_cmd >= 0.0 && run.metrics.max_cmu_cmd <= results.cmu_max);
    let gains: Vec<f64> = alphas
        .iter()
        .map(|&alpha| {
            results.reduction(alpha, Mode::FfFbCoupled).unwrap_or(f64::NAN)
                - results.reduction(alpha, Mode::FfFbLinear).unwrap_or(f64::NAN)
        })
        .collect();
    let lowest = gains.iter().copied().fold(f64::INFINITY, f64::min);
    let highest = gains.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let coupling = if highest < 0.005 {
        format!(
            "The coupling operator adds nothing: with its correction in the feedforward the reduction changes by {:+.2} to {:+.2} percentage points.",
            100.0 * lowest,
            100.0 * highest
        )
    } else {
        format!(
            "The coupling operator changes the reduction by {:+.2} to {:+.2} percentage points.",
            100.0 * lowest,
            100.0 * highest
        )
    };
    format!(
        "Feedforward + feedback (linear) {} the RMS roll moment against no control at every alpha ({}), with commands {} [0, Cmu_max]. {coupling}",
        if all_lower { "lowers" } else { "does not lower" },
        alphas
            .iter()
            .zip(&reductions)
            .map(|(alpha, r)| format!("{alpha:.0} deg: {}", percent(*r)))
            .collect::<Vec<_>>()
            .join(", "),
        if within { "within" } else { "outside" },
    )
}

/// Writes the report folder `dir` (report.md, report.html, SVG plots, `sil.json`).
pub fn write_sil_report(dir: &Path, results: &SilResults, context: &SilContext) -> std::io::Result<()> {
    let record = serde_json::to_value(SilRecord::new(results, context)).map_err(std::io::Error::other)?;
    write_report(dir, &sil_report(results, context), JSON_FILE, &record)
}
