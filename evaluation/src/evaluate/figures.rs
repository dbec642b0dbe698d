//! Plots like the paper's Figs. 7 to 13, on the held-out part of the runs, the angles of
//! attack side by side along the time axis as in the paper (each alpha's held-out window
//! follows the previous one).

use estimator_core::Output;
use firmware_sim::dataset::{Dataset, RunKind};

use super::{Evaluation, Replayed, runs_at};
use model_fit::fit::split::Split;
use reports::Figure;
use reports::plot::{Axes, Series, svg};

/// Largest number of points per alpha and series (the plots stay small).
const POINTS_PER_ALPHA: usize = 1500;

/// One quantity along the concatenated held-out windows.
type Trace = Vec<(f64, f64)>;

/// The evaluation's figures. `noisy` is the dataset with added noise and its replay with the
/// refitted operator, for Fig. 13.
#[must_use]
pub fn figures(
    dataset: &Dataset,
    replayed: &Replayed,
    split: &Split,
    evaluation: &Evaluation,
    noisy: Option<(&Dataset, &Replayed, f64)>,
) -> Vec<Figure> {
    let window = Window { dataset, replayed, split };
    let mut figures = Vec::new();
    let act = |pick: fn(&Output) -> f32| window.trace(RunKind::Actuation, &|_, _, out| f64::from(pick(out)));
    let measured = |kind| window.trace(kind, &|run, k, _| run.channels.cl[k]);
    figures.push(time_figure(
        "fig07_plant.svg",
        "Fig. 7: actuation runs, measured C_l (balance) and the plant model's C_l,AFC (held-out)",
        vec![series("measured", measured(RunKind::Actuation)), series("SINDy plant", act(|o| o.cl_afc))],
    ));
    let (roll, actuation, both) =
        (measured(RunKind::Roll), measured(RunKind::Actuation), measured(RunKind::RollActuation));
    let sum: Trace = roll.iter().zip(&actuation).map(|(r, a)| (r.0, r.1 + a.1)).collect();
    figures.push(time_figure(
        "fig08_superposition.svg",
        "Fig. 8: measured C_l with roll and actuation, and the sum of the roll-only and actuation-only measurements",
        vec![series("C_l,RollAFC", both.clone()), series("C_l,Roll + C_l,AFC", sum.clone())],
    ));
    let delta: Trace = both.iter().zip(&sum).map(|(b, s)| (b.0, b.1 - s.1)).collect();
    figures.push(time_figure(
        "fig09_delta.svg",
        "Fig. 9: Delta C_l = C_l,RollAFC - C_l,Roll - C_l,AFC (measured)",
        vec![series("Delta C_l", delta)],
    ));
    figures.push(operator_figure(
        &window,
        "fig10_operator.svg",
        "Fig. 10: measured C_l,RollAFC minus the models' linear superposition, and the coupling operator's correction",
    ));
    let prediction = window.trace(RunKind::RollActuation, &|_, _, out| f64::from(out.cl));
    figures.push(time_figure(
        "fig11_prediction.svg",
        "Fig. 11: measured C_l with roll and actuation, and the prediction with the coupling operator",
        vec![series("measured", both), series("models + operator", prediction)],
    ));
    figures.push(inputs_figure(&window));
    if let Some((noisy_dataset, noisy_replayed, sigma)) = noisy {
        let noisy_window = Window { dataset: noisy_dataset, replayed: noisy_replayed, split };
        figures.push(operator_figure(
            &noisy_window,
            "fig13_noisy_operator.svg",
            &format!(
                "Fig. 13: as Fig. 10 with Gaussian noise of sigma = {sigma} added to the balance, operator refitted"
            ),
        ));
    }
    figures.push(blocks_figure(evaluation));
    figures.push(noise_figure(evaluation));
    figures
}

struct Window<'a> {
    dataset: &'a Dataset,
    replayed: &'a Replayed,
    split: &'a Split,
}

impl Window<'_> {
    /// A quantity over the held-out windows of the runs of `kind`, alpha by alpha; `value`
    /// returns it for (run, sample, output). The time axis restarts after each alpha's window.
    fn trace(&self, kind: RunKind, value: &dyn Fn(&firmware_sim::dataset::Run, usize, &Output) -> f64) -> Trace {
        let mut trace = Vec::new();
        let mut offset_s = 0.0;
        for alpha in self.dataset.alphas_deg() {
            let Some(&idx) = runs_at(self.dataset, Some(kind), alpha).first() else { continue };
            let run = &self.dataset.runs[idx];
            let range = self.split.heldout(run.channels.len());
            let stride = (range.len() / POINTS_PER_ALPHA).max(1);
            let start_s = range.start as f64 / run.meta.sample_hz;
            for k in range.clone().step_by(stride) {
                let y = value(run, k, &self.replayed.outputs[idx][k]);
                trace.push((offset_s + k as f64 / run.meta.sample_hz - start_s, y));
            }
            offset_s += range.len() as f64 / run.meta.sample_hz;
        }
        trace
    }
}

fn series(name: &str, points: Trace) -> Series {
    Series { name: name.to_owned(), points, line: true }
}

fn time_figure(file: &str, caption: &str, series: Vec<Series>) -> Figure {
    let axes = Axes {
        title: caption.split(':').next().unwrap_or(caption).to_owned(),
        x_label: "held-out time, alpha after alpha (s)".into(),
        y_label: "C_l".into(),
        log_y: false,
    };
    Figure { file: file.to_owned(), caption: caption.to_owned(), svg: svg(&axes, &series) }
}

fn operator_figure(window: &Window<'_>, file: &str, caption: &str) -> Figure {
    let target = window.trace(RunKind::RollActuation, &|run, k, out| run.channels.cl[k] - f64::from(out.cl_linear));
    let correction = window.trace(RunKind::RollActuation, &|_, _, out| f64::from(out.coupling));
    time_figure(
        file,
        caption,
        vec![series("C_l - C_l,roll - C_l,AFC (models)", target), series("coupling operator", correction)],
    )
}

/// Fig. 12: the operator's correction against Cmu and phi, both scaled to its range.
fn inputs_figure(window: &Window<'_>) -> Figure {
    let correction = window.trace(RunKind::RollActuation, &|_, _, out| f64::from(out.coupling));
    let cmu = window.trace(RunKind::RollActuation, &|run, k, _| run.channels.cmu_port[k] + run.channels.cmu_stbd[k]);
    let phi = window.trace(RunKind::RollActuation, &|run, k, _| run.channels.phi_deg[k]);
    let peak = |trace: &Trace| trace.iter().map(|p| p.1.abs()).filter(|v| v.is_finite()).fold(0.0, f64::max);
    let scale = |trace: Trace, target: f64| -> Trace {
        let peak = peak(&trace);
        let factor = if peak > 0.0 { target / peak } else { 0.0 };
        trace.into_iter().map(|(t, v)| (t, v * factor)).collect()
    };
    let target = peak(&correction);
    time_figure(
        "fig12_correction_inputs.svg",
        "Fig. 12: scaled Cmu, scaled phi, and the coupling operator's correction",
        vec![
            series("Cmu (scaled)", scale(cmu, target)),
            series("phi (scaled)", scale(phi, target)),
            series("correction", correction),
        ],
    )
}

fn blocks_figure(evaluation: &Evaluation) -> Figure {
    let mut all: Vec<Series> = Vec::new();
    for block in ["egk", "pressure", "fused", "plant", "linear", "coupled"] {
        let points =
            evaluation.blocks.iter().filter(|row| row.block == block).map(|row| (row.alpha_deg, row.rms)).collect();
        all.push(Series { name: block.to_owned(), points, line: true });
    }
    all.push(Series { name: "balance noise".into(), points: evaluation.noise_rms.clone(), line: true });
    let axes = Axes {
        title: "held-out RMS error per block".into(),
        x_label: "alpha (deg)".into(),
        y_label: "RMS of C_l".into(),
        log_y: true,
    };
    Figure {
        file: "blocks.svg".into(),
        caption: "Held-out RMS error of each block against the balance, and the balance's noise floor".into(),
        svg: svg(&axes, &all),
    }
}

fn noise_figure(evaluation: &Evaluation) -> Figure {
    let mut all: Vec<Series> = Vec::new();
    let alphas: Vec<f64> = evaluation.coupling.iter().map(|row| row.alpha_deg).collect();
    for alpha in alphas {
        let ratio: Vec<(f64, f64)> = evaluation
            .noise_robustness
            .iter()
            .filter_map(|row| {
                row.per_alpha.iter().find(|r| (r.alpha_deg - alpha).abs() < 1e-6).map(|r| (row.sigma * 1e3, r.ratio))
            })
            .collect();
        all.push(Series { name: format!("E_SINDy/E_lin, alpha {alpha}"), points: ratio, line: true });
    }
    let axes = Axes {
        title: "noise robustness".into(),
        x_label: "added noise sigma (1e-3 C_l)".into(),
        y_label: "E_SINDy / E_lin".into(),
        log_y: false,
    };
    Figure {
        file: "noise_sweep.svg".into(),
        caption: "Error ratio of the refitted coupling operator against the added noise".into(),
        svg: svg(&axes, &all),
    }
}
