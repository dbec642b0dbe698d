//! The scorer of the blind campaign: reads the sealed truth only after the diagnosis, and
//! summarises the cases as the acceptance asks (confusion matrix, accuracy by effect
//! and by signal-to-noise, shrink distribution).

use std::collections::BTreeMap;

use serde::Serialize;
use sha2::{Digest, Sha256};

use super::{CaseRecord, class_name, class_of, classes, outside_vocabulary};

/// Hex SHA-256 of `bytes`.
#[must_use]
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

/// Whether a case was diagnosed right: no effect named for `none`; `unattributed` for an
/// effect outside the vocabulary; the injected effect ranked first otherwise, and for a sensor
/// effect with exactly the injected channels in `where` (a fault on the wrong tap, or a lag of
/// one channel where all twelve lag, is wrong).
#[must_use]
pub fn is_correct(record: &CaseRecord) -> bool {
    if record.class == "none" {
        record.named.is_empty()
    } else if outside_vocabulary(&record.class) {
        record.verdict == "unattributed" && record.named.is_empty()
    } else {
        let first_right = record.named.first().is_some_and(|name| *name == record.class);
        let sensor = class_of(&record.class).is_some_and(firmware_sim::effect::Effect::is_sensor);
        first_right && (!sensor || same_channels(&record.truth_channels, &record.named_channels))
    }
}

fn same_channels(a: &[String], b: &[String]) -> bool {
    let mut a = a.to_vec();
    let mut b = b.to_vec();
    a.sort();
    b.sort();
    a.dedup();
    b.dedup();
    a == b
}

/// Signal-to-noise bins of the summary (effect RMS over noise RMS).
pub const RATIO_BINS: [(f64, f64); 4] = [(0.0, 1.0), (1.0, 2.0), (2.0, 4.01), (4.01, f64::INFINITY)];

/// The campaign's summary.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// Cases.
    pub cases: usize,
    /// No effect injected: share of cases that named an effect (goal at most 5 %).
    pub none_false_name_rate: Option<f64>,
    /// No effect injected: share of cases whose verdict is `none`, not `unattributed` (a gap
    /// claimed where there is none is a false alarm even without a name; goal at least 90 %).
    pub none_verdict_rate: Option<f64>,
    /// Single vocabulary effect at ratio >= 1: share ranked first right (goal at least 95 %).
    pub vocabulary_top1_at_ratio_ge_1: Option<f64>,
    /// The same per effect (goal at least 90 % each).
    pub per_effect_top1_at_ratio_ge_1: BTreeMap<String, Option<f64>>,
    /// Outside the vocabulary: share `unattributed` with no name (goal at least 80 %).
    pub outside_unattributed_rate: Option<f64>,
    /// Median held-out shrink of the right first effect at ratio >= 1, where it is measured
    /// (a dead channel's 1 holds by definition and is left out; goal at least 0.7).
    pub median_shrink_at_ratio_ge_1: Option<f64>,
    /// Quartiles of that shrink.
    pub shrink_quartiles: Option<[f64; 3]>,
    /// Median of the shrink against the whole gap beyond noise (the sim's own floor included).
    pub median_shrink_total_at_ratio_ge_1: Option<f64>,
    /// Accuracy per class and ratio bin: (right, cases).
    pub accuracy_by_ratio: BTreeMap<String, Vec<(usize, usize)>>,
    /// Confusion matrix: injected class -> first named effect (or the verdict) -> count.
    pub confusion: BTreeMap<String, BTreeMap<String, usize>>,
    /// Median seconds per diagnosis.
    pub median_diagnosis_s: Option<f64>,
}

fn share(hits: usize, total: usize) -> Option<f64> {
    (total > 0).then(|| hits as f64 / total as f64)
}

fn median(values: &mut [f64]) -> Option<f64> {
    quantile(values, 0.5)
}

fn quantile(values: &mut [f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let pos = q * (values.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    Some(values[lo] + (pos - lo as f64) * (values[hi] - values[lo]))
}

/// The ratio used for binning: a case without an effect has none (it sits in the first bin
/// alone, so that every row adds up to its cases); a dead channel (no reading at all) counts as
/// large.
fn ratio_of(record: &CaseRecord) -> f64 {
    if record.class == "none" { 0.0 } else { record.ratio.unwrap_or(f64::INFINITY) }
}

/// Summarises the records.
#[must_use]
pub fn summarise(records: &[CaseRecord]) -> Summary {
    let none: Vec<&CaseRecord> = records.iter().filter(|r| r.class == "none").collect();
    let vocab_ge1: Vec<&CaseRecord> =
        records.iter().filter(|r| r.class != "none" && !outside_vocabulary(&r.class) && ratio_of(r) >= 1.0).collect();
    let outside: Vec<&CaseRecord> = records.iter().filter(|r| outside_vocabulary(&r.class)).collect();
    let mut per_effect = BTreeMap::new();
    for effect in classes().into_iter().flatten().filter(|e| e.in_vocabulary()) {
        let cases: Vec<&&CaseRecord> = vocab_ge1.iter().filter(|r| r.class == effect.name()).collect();
        per_effect.insert(effect.name().to_owned(), share(cases.iter().filter(|r| r.correct).count(), cases.len()));
    }
    let mut shrinks: Vec<f64> = vocab_ge1.iter().filter(|r| r.correct).filter_map(|r| r.shrink).collect();
    let quartiles = match (quantile(&mut shrinks, 0.25), quantile(&mut shrinks, 0.5), quantile(&mut shrinks, 0.75)) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    let mut accuracy_by_ratio = BTreeMap::new();
    let mut confusion: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    for class in classes().into_iter().map(class_name) {
        let cases: Vec<&CaseRecord> = records.iter().filter(|r| r.class == class).collect();
        if cases.is_empty() {
            continue;
        }
        let bins = RATIO_BINS
            .iter()
            .map(|&(lo, hi)| {
                let in_bin: Vec<&&CaseRecord> =
                    cases.iter().filter(|r| ratio_of(r) >= lo && ratio_of(r) < hi).collect();
                (in_bin.iter().filter(|r| r.correct).count(), in_bin.len())
            })
            .collect();
        accuracy_by_ratio.insert(class.to_owned(), bins);
        for record in cases {
            let said = record.named.first().cloned().unwrap_or_else(|| format!("({})", record.verdict));
            *confusion.entry(class.to_owned()).or_default().entry(said).or_default() += 1;
        }
    }
    let mut times: Vec<f64> = records.iter().map(|r| r.diagnosis_s).collect();
    Summary {
        cases: records.len(),
        none_false_name_rate: share(none.iter().filter(|r| !r.named.is_empty()).count(), none.len()),
        none_verdict_rate: share(none.iter().filter(|r| r.verdict == "none").count(), none.len()),
        vocabulary_top1_at_ratio_ge_1: share(vocab_ge1.iter().filter(|r| r.correct).count(), vocab_ge1.len()),
        per_effect_top1_at_ratio_ge_1: per_effect,
        outside_unattributed_rate: share(outside.iter().filter(|r| r.correct).count(), outside.len()),
        median_shrink_at_ratio_ge_1: median(&mut shrinks.clone()),
        median_shrink_total_at_ratio_ge_1: median(
            &mut vocab_ge1.iter().filter(|r| r.correct).filter_map(|r| r.shrink_total).collect::<Vec<_>>(),
        ),
        shrink_quartiles: quartiles,
        accuracy_by_ratio,
        confusion,
        median_diagnosis_s: median(&mut times),
    }
}

/// The campaign's report: the acceptance figures, the confusion matrix, accuracy by effect and
/// signal-to-noise, the shrink distribution, and every case.
#[must_use]
pub fn report(records: &[CaseRecord], summary: &Summary, described: &str) -> crate::report::Report {
    use crate::report::{Report, Section, Table};
    let pct = |v: Option<f64>| v.map_or_else(|| "n/a".to_owned(), |v| format!("{:.1} %", 100.0 * v));
    let acceptance = Table {
        caption: "Acceptance (issues 7 and 15)".into(),
        header: ["criterion", "goal", "measured"].map(String::from).to_vec(),
        rows: vec![
            vec!["no effect: wrong effect named".into(), "<= 5 %".into(), pct(summary.none_false_name_rate)],
            vec!["no effect: verdict none".into(), ">= 90 %".into(), pct(summary.none_verdict_rate)],
            vec![
                "single effect, ratio >= 1: right effect first".into(),
                ">= 95 %".into(),
                pct(summary.vocabulary_top1_at_ratio_ge_1),
            ],
            vec![
                "  worst single effect".into(),
                ">= 90 %".into(),
                pct(summary.per_effect_top1_at_ratio_ge_1.values().flatten().copied().reduce(f64::min)),
            ],
            vec![
                "outside the vocabulary: unattributed".into(),
                ">= 80 %".into(),
                pct(summary.outside_unattributed_rate),
            ],
            vec![
                "median held-out shrink, ratio >= 1".into(),
                ">= 0.7".into(),
                summary.median_shrink_at_ratio_ge_1.map_or_else(|| "n/a".into(), |v| format!("{v:.2}")),
            ],
            vec![
                "  the same against the whole gap (sim's own floor included)".into(),
                "".into(),
                summary.median_shrink_total_at_ratio_ge_1.map_or_else(|| "n/a".into(), |v| format!("{v:.2}")),
            ],
            vec![
                "median time per diagnosis".into(),
                "".into(),
                summary.median_diagnosis_s.map_or_else(|| "n/a".into(), |v| format!("{v:.2} s")),
            ],
        ],
    };
    let bins = RATIO_BINS.map(|(lo, hi)| {
        if hi.is_finite() { format!("{lo:.0}-{hi:.0}") } else { format!(">= {lo:.0} (or dead channel)") }
    });
    let by_ratio = Table {
        caption: "Right / cases, by injected class and effect RMS over noise RMS".into(),
        header: std::iter::once("class".to_owned())
            .chain(bins.iter().cloned())
            .chain(std::iter::once(">= 1".to_owned()))
            .collect(),
        rows: summary
            .accuracy_by_ratio
            .iter()
            .map(|(class, cells)| {
                let ge1 = summary.per_effect_top1_at_ratio_ge_1.get(class).copied().flatten();
                std::iter::once(class.clone())
                    .chain(
                        cells
                            .iter()
                            .map(|(right, total)| if *total == 0 { "-".into() } else { format!("{right}/{total}") }),
                    )
                    .chain(std::iter::once(pct(ge1)))
                    .collect()
            })
            .collect(),
    };
    let mut said: Vec<String> = summary.confusion.values().flat_map(|row| row.keys().cloned()).collect();
    said.sort();
    said.dedup();
    let confusion = Table {
        caption: "Confusion matrix: injected class (rows) against the first named effect or the verdict (columns)"
            .into(),
        header: std::iter::once("injected".to_owned()).chain(said.iter().cloned()).collect(),
        rows: summary
            .confusion
            .iter()
            .map(|(class, row)| {
                std::iter::once(class.clone())
                    .chain(said.iter().map(|name| row.get(name).map_or_else(String::new, usize::to_string)))
                    .collect()
            })
            .collect(),
    };
    let cases = Table {
        caption: "Every case".into(),
        header: ["id", "class", "alpha (deg)", "ratio", "verdict", "named", "shrink", "right"]
            .map(String::from)
            .to_vec(),
        rows: records
            .iter()
            .map(|r| {
                vec![
                    r.id.to_string(),
                    r.class.clone(),
                    format!("{:.1}", r.alpha_deg),
                    r.ratio.map_or_else(|| "dead".into(), |v| format!("{v:.2}")),
                    r.verdict.clone(),
                    r.named.join(", "),
                    r.shrink.map_or_else(String::new, |v| format!("{v:.2}")),
                    if r.correct { "yes".into() } else { "NO".into() },
                ]
            })
            .collect(),
    };
    Report {
        title: "Blind validation of the gap diagnosis".into(),
        intro: vec![described.to_owned()],
        sections: vec![
            Section { heading: "Acceptance".into(), tables: vec![acceptance], ..Section::default() },
            Section {
                heading: "Accuracy".into(),
                paragraphs: vec![summary.shrink_quartiles.map_or_else(String::new, |q| {
                    format!(
                        "Held-out shrink of the right first effect at ratio >= 1: quartiles {:.2} / {:.2} / {:.2}.",
                        q[0], q[1], q[2]
                    )
                })],
                tables: vec![by_ratio, confusion],
                ..Section::default()
            },
            Section { heading: "Cases".into(), tables: vec![cases], ..Section::default() },
        ],
    }
}
