//! The scorer of the blind campaign: reads the sealed truth only after the diagnosis, and
//! summarises the cases as docs/diagnosis.md (Validation campaigns, Scoring) asks (confusion
//! matrix, accuracy by effect and by signal-to-noise, shrink distribution).

use std::collections::BTreeMap;

use serde::Serialize;

use super::{CaseRecord, class_name, class_of, classes, outside_vocabulary};
use stats::{median, quantile};

/// Whether a case was diagnosed right: the verdict `none` for a clean recording; `unattributed` for an
/// effect outside the vocabulary; the injected effect ranked first otherwise, and for a sensor
/// effect with its channels in `where`: every required one ([`CaseRecord::required_channels`])
/// and no healthy one (a fault on the wrong tap, or a lag of one channel where all twelve lag
/// beyond the noise, is wrong).
#[must_use]
pub fn is_correct(record: &CaseRecord) -> bool {
    if record.class == "none" {
        // `unattributed` on a clean recording names nothing, but it is a false alarm: the
        // contract's answer is `none` (the wrong-name rate is counted apart).
        record.verdict == "none" && record.named.is_empty()
    } else if outside_vocabulary(&record.class) {
        record.verdict == "unattributed" && record.named.is_empty()
    } else {
        let first_right = record.named.first().is_some_and(|name| *name == record.class);
        let sensor = class_of(&record.class).is_some_and(firmware_sim::effect::Effect::is_sensor);
        first_right && (!sensor || its_channels(record))
    }
}

/// The named channels hold every required channel and no healthy one.
fn its_channels(record: &CaseRecord) -> bool {
    record.required_channels.iter().all(|channel| record.named_channels.contains(channel))
        && record.named_channels.iter().all(|channel| record.truth_channels.contains(channel))
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
    /// No effect injected: share of cases that named an effect (goal 0: the contract's "a
    /// recording with no effect must not be given one").
    pub none_false_name_rate: Option<f64>,
    /// No effect injected: share of cases whose verdict is `none`, not `unattributed` (a gap
    /// claimed where there is none is a false alarm even without a name; goal at least 95 %).
    pub none_verdict_rate: Option<f64>,
    /// Single vocabulary effect at ratio >= 1: share ranked first right (goal at least 95 %).
    pub vocabulary_top1_at_ratio_ge_1: Option<f64>,
    /// The same per effect (goal at least 90 % each).
    pub per_effect_top1_at_ratio_ge_1: BTreeMap<String, Option<f64>>,
    /// Outside the vocabulary: share `unattributed` with no name (goal at least 90 %).
    pub outside_unattributed_rate: Option<f64>,
    /// The same at ratio >= 1: below it the contract lets a gap be missed (`none`), as it does
    /// for effects of the vocabulary.
    pub outside_unattributed_rate_at_ratio_ge_1: Option<f64>,
    /// Outside the vocabulary, at any ratio: share given a name of the vocabulary (goal 0: a
    /// name sends the user after the wrong cause).
    pub outside_named_rate: Option<f64>,
    /// Sensor effects at ratio >= 1 named first: share with exactly the injected channels (goal
    /// at least 90 %).
    pub sensor_exact_channels_rate: Option<f64>,
    /// The same with every channel at a ratio of at least one and no healthy one
    /// ([`CaseRecord::required_channels`]).
    pub sensor_required_channels_rate: Option<f64>,
    /// Right first effects at ratio >= 1 whose shrink holds by definition (a dead channel's 1),
    /// counted apart from the measured shrinks.
    pub shrinks_by_definition: usize,
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

/// Whether `ratio` falls in the bin `[lo, hi)`; the last bin, open above, also holds an
/// infinite ratio (a dead channel, whose whole signal is the gap).
fn in_bin(ratio: f64, lo: f64, hi: f64) -> bool {
    ratio >= lo && (ratio < hi || hi == f64::INFINITY)
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
    let sensor_named_first: Vec<&CaseRecord> = vocab_ge1
        .iter()
        .copied()
        .filter(|r| class_of(&r.class).is_some_and(firmware_sim::effect::Effect::is_sensor))
        .filter(|r| r.named.first() == Some(&r.class))
        .collect();
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
    // The tunnel's own classes in their order, then any other class a campaign holds (outside
    // effects another program injects).
    let mut class_names: Vec<String> = classes().into_iter().map(|class| class_name(class).to_owned()).collect();
    let mut others: Vec<String> =
        records.iter().map(|r| r.class.clone()).filter(|class| !class_names.contains(class)).collect();
    others.sort();
    others.dedup();
    class_names.extend(others);
    for class in &class_names {
        let cases: Vec<&CaseRecord> = records.iter().filter(|r| r.class == *class).collect();
        if cases.is_empty() {
            continue;
        }
        let bins = RATIO_BINS
            .iter()
            .map(|&(lo, hi)| {
                let members: Vec<&&CaseRecord> = cases.iter().filter(|r| in_bin(ratio_of(r), lo, hi)).collect();
                (members.iter().filter(|r| r.correct).count(), members.len())
            })
            .collect();
        accuracy_by_ratio.insert(class.clone(), bins);
        for record in cases {
            let said = record.named.first().cloned().unwrap_or_else(|| format!("({})", record.verdict));
            *confusion.entry(class.clone()).or_default().entry(said).or_default() += 1;
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
        outside_unattributed_rate_at_ratio_ge_1: {
            let at_ge1: Vec<&&CaseRecord> = outside.iter().filter(|r| ratio_of(r) >= 1.0).collect();
            share(at_ge1.iter().filter(|r| r.correct).count(), at_ge1.len())
        },
        outside_named_rate: share(outside.iter().filter(|r| !r.named.is_empty()).count(), outside.len()),
        sensor_exact_channels_rate: share(
            sensor_named_first.iter().filter(|r| same_channels(&r.truth_channels, &r.named_channels)).count(),
            sensor_named_first.len(),
        ),
        sensor_required_channels_rate: share(
            sensor_named_first.iter().filter(|r| its_channels(r)).count(),
            sensor_named_first.len(),
        ),
        shrinks_by_definition: vocab_ge1
            .iter()
            .filter(|r| r.correct && r.shrink.is_none() && r.ratio.is_none())
            .count(),
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
pub fn report(records: &[CaseRecord], summary: &Summary, described: &str) -> reports::Report {
    use reports::{Report, Section, Table};
    let pct = |v: Option<f64>| v.map_or_else(|| "n/a".to_owned(), |v| format!("{:.1} %", 100.0 * v));
    let acceptance = Table {
        caption: "Acceptance".into(),
        header: ["criterion", "goal", "measured"].map(String::from).to_vec(),
        rows: vec![
            vec!["no effect: an effect named".into(), "0 %".into(), pct(summary.none_false_name_rate)],
            vec!["no effect: verdict none".into(), ">= 95 %".into(), pct(summary.none_verdict_rate)],
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
                "sensor effect named first: exactly its channels".into(),
                ">= 90 %".into(),
                pct(summary.sensor_exact_channels_rate),
            ],
            vec![
                "  every channel at ratio >= 1, none healthy".into(),
                String::new(),
                pct(summary.sensor_required_channels_rate),
            ],
            vec![
                "outside the vocabulary: unattributed".into(),
                ">= 90 %".into(),
                pct(summary.outside_unattributed_rate),
            ],
            vec!["  at ratio >= 1".into(), ">= 90 %".into(), pct(summary.outside_unattributed_rate_at_ratio_ge_1)],
            vec!["  an effect named (any ratio)".into(), "0 %".into(), pct(summary.outside_named_rate)],
            vec![
                "median held-out shrink, ratio >= 1".into(),
                ">= 0.7".into(),
                summary.median_shrink_at_ratio_ge_1.map_or_else(|| "n/a".into(), |v| format!("{v:.2}")),
            ],
            vec![
                "  right first effects whose shrink holds by definition (dead channels), apart".into(),
                "".into(),
                summary.shrinks_by_definition.to_string(),
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A case as the campaign records it, with what the diagnosis said; `correct` is set by
    /// hand in each test (from the scoring rules), not by [`is_correct`].
    fn case(class: &str, ratio: Option<f64>, verdict: &str, named: &[&str]) -> CaseRecord {
        CaseRecord {
            id: 0,
            class: class.into(),
            alpha_deg: 10.0,
            target_ratio: ratio.unwrap_or(0.0),
            ratio,
            truth: String::new(),
            truth_sha256: String::new(),
            truth_channels: Vec::new(),
            required_channels: Vec::new(),
            verdict: verdict.into(),
            named: named.iter().map(|n| (*n).to_owned()).collect(),
            named_channels: Vec::new(),
            named_params: std::collections::BTreeMap::new(),
            shrink: None,
            shrink_total: None,
            correct: false,
            diagnosis_s: 1.0,
        }
    }

    fn channels(names: &[&str]) -> Vec<String> {
        names.iter().map(|n| (*n).to_owned()).collect()
    }

    fn all_twelve() -> Vec<String> {
        (1..=12).map(|tap| format!("cp{tap:02}")).collect()
    }

    /// A sensor case with its injected and named channels.
    fn sensor_case(class: &str, named: &str, truth: &[&str], said: &[&str]) -> CaseRecord {
        CaseRecord {
            truth_channels: channels(truth),
            required_channels: channels(truth),
            named_channels: channels(said),
            ..case(class, Some(2.0), "effect", &[named])
        }
    }

    fn right(mut record: CaseRecord) -> CaseRecord {
        record.correct = true;
        record
    }

    fn with_shrink(mut record: CaseRecord, shrink: Option<f64>, shrink_total: Option<f64>) -> CaseRecord {
        record.shrink = shrink;
        record.shrink_total = shrink_total;
        record
    }

    fn assert_close(actual: Option<f64>, expected: f64) {
        let value = actual.expect("a figure");
        assert!((value - expected).abs() < 1e-12, "{value} != {expected}");
    }

    /// No effect injected: right exactly when the verdict is `none` (an `unattributed` false
    /// alarm names nothing but is not right).
    #[test]
    fn a_none_case_is_right_only_as_none() {
        assert!(is_correct(&case("none", Some(0.0), "none", &[])));
        assert!(!is_correct(&case("none", Some(0.0), "unattributed", &[])));
        assert!(!is_correct(&case("none", Some(0.0), "effect", &["bias_drift"])));
    }

    /// Outside the vocabulary: right only as `unattributed` with no name; `none` (the gap
    /// missed) and a named vocabulary effect are both wrong.
    #[test]
    fn an_effect_outside_the_vocabulary_is_right_only_as_unattributed() {
        // The tunnel's own outside effects and names another program may use.
        for class in ["q_fluctuation", "cubic_stiffness", "rig_tone", "encoder_backlash"] {
            assert!(is_correct(&case(class, Some(2.0), "unattributed", &[])), "{class}");
            assert!(!is_correct(&case(class, Some(2.0), "none", &[])), "{class}");
            assert!(!is_correct(&case(class, Some(2.0), "effect", &["roll_damping"])), "{class}");
        }
    }

    /// A balance effect is right when it is ranked first, whatever follows it; second place or
    /// no name is wrong; channels play no part for a balance effect.
    #[test]
    fn a_balance_effect_is_right_only_when_ranked_first() {
        assert!(is_correct(&case("inertial_tare", Some(2.0), "effect", &["inertial_tare", "bias_drift"])));
        assert!(!is_correct(&case("inertial_tare", Some(2.0), "effect", &["bias_drift", "inertial_tare"])));
        assert!(!is_correct(&case("inertial_tare", Some(2.0), "unattributed", &[])));
        let mut stray_channel = case("roll_damping", Some(2.0), "effect", &["roll_damping"]);
        stray_channel.named_channels = channels(&["cp01"]);
        assert!(is_correct(&stray_channel));
    }

    /// A pressure fault is right only on exactly the injected tap: the right name on the wrong
    /// channel, an extra channel or no channel is wrong.
    #[test]
    fn a_pressure_fault_on_the_wrong_channel_is_wrong() {
        assert!(is_correct(&sensor_case("pressure_fault", "pressure_fault", &["cp07"], &["cp07"])));
        assert!(!is_correct(&sensor_case("pressure_fault", "pressure_fault", &["cp07"], &["cp03"])));
        assert!(!is_correct(&sensor_case("pressure_fault", "pressure_fault", &["cp07"], &["cp07", "cp03"])));
        assert!(!is_correct(&sensor_case("pressure_fault", "pressure_fault", &["cp07"], &[])));
    }

    /// The right channel under the wrong sensor effect is wrong.
    #[test]
    fn the_right_channel_under_the_wrong_sensor_effect_is_wrong() {
        assert!(!is_correct(&sensor_case("pressure_fault", "pressure_lag", &["cp07"], &["cp07"])));
    }

    /// A lag of every channel named as a lag of one is wrong; the twelve named in another order
    /// (or one twice) are the same set and right.
    #[test]
    fn a_lag_of_one_channel_where_all_twelve_lag_is_wrong() {
        let mut record = sensor_case("pressure_lag", "pressure_lag", &[], &["cp05"]);
        record.truth_channels = all_twelve();
        record.required_channels = all_twelve();
        assert!(!is_correct(&record));
        let mut reversed = all_twelve();
        reversed.reverse();
        reversed.push("cp01".into());
        record.named_channels = reversed;
        assert!(is_correct(&record));
    }

    /// A lag's channel at the noise floor may be missed, but a healthy channel may not be
    /// named, nor a channel beyond the noise left out.
    #[test]
    fn a_lagged_channel_at_the_noise_floor_may_be_missed_but_no_healthy_one_named() {
        let mut record = sensor_case("pressure_lag", "pressure_lag", &["cp02", "cp06", "cp07"], &["cp06", "cp07"]);
        record.required_channels = channels(&["cp06", "cp07"]);
        assert!(is_correct(&record));
        record.named_channels = channels(&["cp02", "cp06", "cp07"]);
        assert!(is_correct(&record));
        record.named_channels = channels(&["cp06"]);
        assert!(!is_correct(&record));
        record.named_channels = channels(&["cp01", "cp06", "cp07"]);
        assert!(!is_correct(&record));
    }

    /// An effect outside the vocabulary below a ratio of one may be missed: `none` there counts
    /// against the strict rate only; a name counts as named at any ratio.
    #[test]
    fn an_outside_effect_below_the_noise_may_be_missed_but_not_named() {
        let records = vec![
            case("rig_tone", Some(0.6), "none", &[]),
            case("rig_tone", Some(0.7), "effect", &["vortex_lag"]),
            right(case("rig_tone", Some(1.4), "unattributed", &[])),
        ];
        let summary = summarise(&records);
        assert_close(summary.outside_unattributed_rate, 1.0 / 3.0);
        assert_close(summary.outside_unattributed_rate_at_ratio_ge_1, 1.0);
        assert_close(summary.outside_named_rate, 1.0 / 3.0);
    }

    /// Without cases there is no figure: every share, median and quartile is `None` (never a
    /// 0 %), the tables are empty, and every vocabulary effect (only those) has its empty slot.
    #[test]
    fn an_empty_campaign_has_no_figures_rather_than_zeros() {
        let summary = summarise(&[]);
        assert_eq!(summary.cases, 0);
        assert_eq!(summary.none_false_name_rate, None);
        assert_eq!(summary.none_verdict_rate, None);
        assert_eq!(summary.vocabulary_top1_at_ratio_ge_1, None);
        assert_eq!(summary.outside_unattributed_rate, None);
        assert_eq!(summary.outside_unattributed_rate_at_ratio_ge_1, None);
        assert_eq!(summary.outside_named_rate, None);
        assert_eq!(summary.median_shrink_at_ratio_ge_1, None);
        assert_eq!(summary.median_shrink_total_at_ratio_ge_1, None);
        assert_eq!(summary.shrink_quartiles, None);
        assert_eq!(summary.median_diagnosis_s, None);
        assert!(summary.accuracy_by_ratio.is_empty() && summary.confusion.is_empty());
        assert_eq!(summary.per_effect_top1_at_ratio_ge_1.len(), 11);
        assert!(summary.per_effect_top1_at_ratio_ge_1.values().all(Option::is_none));
        assert!(!summary.per_effect_top1_at_ratio_ge_1.contains_key("q_fluctuation"));
        assert!(!summary.per_effect_top1_at_ratio_ge_1.contains_key("cubic_stiffness"));
    }

    /// A small campaign with hand-counted figures: 4 `none` cases (2 `none`, 1 `unattributed`,
    /// 1 naming `bias_drift`), 2 outside the vocabulary (one right), 3 `roll_damping` cases.
    /// The shares are the hand counts, and every accuracy row and confusion row adds up to its
    /// class's cases.
    #[test]
    fn rates_are_the_hand_counts_and_every_row_adds_up_to_its_cases() {
        let records = vec![
            right(case("none", Some(0.0), "none", &[])),
            right(case("none", Some(0.0), "unattributed", &[])),
            case("none", Some(0.0), "effect", &["bias_drift"]),
            right(case("none", Some(0.0), "none", &[])),
            right(case("q_fluctuation", Some(1.2), "unattributed", &[])),
            case("q_fluctuation", Some(2.5), "effect", &["roll_damping"]),
            case("roll_damping", Some(0.5), "none", &[]),
            right(case("roll_damping", Some(1.5), "effect", &["roll_damping"])),
            right(case("roll_damping", Some(3.0), "effect", &["roll_damping"])),
        ];
        let summary = summarise(&records);
        assert_eq!(summary.cases, 9);
        assert_close(summary.none_false_name_rate, 0.25);
        assert_close(summary.none_verdict_rate, 0.5);
        assert_close(summary.outside_unattributed_rate, 0.5);
        assert_close(summary.outside_unattributed_rate_at_ratio_ge_1, 0.5);
        assert_close(summary.outside_named_rate, 0.5);
        // Ratio >= 1 in the vocabulary: the two roll_damping cases at 1.5 and 3, both right.
        assert_close(summary.vocabulary_top1_at_ratio_ge_1, 1.0);
        assert_eq!(summary.per_effect_top1_at_ratio_ge_1["roll_damping"], Some(1.0));
        assert_eq!(summary.accuracy_by_ratio["none"], vec![(3, 4), (0, 0), (0, 0), (0, 0)]);
        assert_eq!(summary.accuracy_by_ratio["q_fluctuation"], vec![(0, 0), (1, 1), (0, 1), (0, 0)]);
        assert_eq!(summary.accuracy_by_ratio["roll_damping"], vec![(0, 1), (1, 1), (1, 1), (0, 0)]);
        let none_row = &summary.confusion["none"];
        assert_eq!(none_row.get("(none)"), Some(&2));
        assert_eq!(none_row.get("(unattributed)"), Some(&1));
        assert_eq!(none_row.get("bias_drift"), Some(&1));
        for (class, row) in &summary.accuracy_by_ratio {
            let cases = records.iter().filter(|r| r.class == *class).count();
            assert_eq!(row.iter().map(|(_, total)| total).sum::<usize>(), cases, "accuracy row {class}");
            assert_eq!(summary.confusion[class].values().sum::<usize>(), cases, "confusion row {class}");
        }
    }

    /// A `none` case has no effect, so whatever ratio it carries it sits in the first bin alone
    /// and never in the ratio >= 1 figures.
    #[test]
    fn a_none_case_goes_in_the_first_ratio_bin_only() {
        let records = [
            right(case("none", Some(0.0), "none", &[])),
            right(case("none", Some(2.5), "none", &[])),
            right(case("none", None, "none", &[])),
        ];
        let summary = summarise(&records);
        assert_eq!(summary.accuracy_by_ratio["none"], vec![(3, 3), (0, 0), (0, 0), (0, 0)]);
        assert_eq!(summary.vocabulary_top1_at_ratio_ge_1, None);
    }

    /// Each bin holds `lo <= ratio < hi` (the constants by name): a ratio just below an edge
    /// falls in the bin below it, the edge itself in the bin above; ratio >= 1 starts exactly
    /// at 1.
    #[test]
    fn ratio_bins_split_exactly_at_their_edges() {
        let below = |edge: f64| edge - 1e-9;
        let ratios = [
            below(RATIO_BINS[1].0),
            RATIO_BINS[1].0,
            below(RATIO_BINS[2].0),
            RATIO_BINS[2].0,
            below(RATIO_BINS[3].0),
            RATIO_BINS[3].0,
            1e6,
        ];
        let records: Vec<CaseRecord> =
            ratios.iter().map(|&r| right(case("coupling", Some(r), "effect", &["coupling"]))).collect();
        let summary = summarise(&records);
        assert_eq!(summary.accuracy_by_ratio["coupling"], vec![(1, 1), (2, 2), (2, 2), (2, 2)]);
        // Ratio >= 1: all but the first case; a wrong case below 1 would not count either.
        let mut with_a_miss = records.clone();
        with_a_miss[0].correct = false;
        assert_close(summarise(&with_a_miss).vocabulary_top1_at_ratio_ge_1, 1.0);
        with_a_miss[1].correct = false;
        assert_close(summarise(&with_a_miss).vocabulary_top1_at_ratio_ge_1, 5.0 / 6.0);
    }

    /// A dead channel (ratio `None`: no reading left) counts as a large effect: it is part of
    /// the ratio >= 1 accuracy of its effect.
    #[test]
    fn a_dead_channel_counts_in_the_ratio_ge_1_accuracy() {
        let records = [
            right(sensor_case("pressure_fault", "pressure_fault", &["cp07"], &["cp07"])),
            CaseRecord { ratio: None, ..sensor_case("pressure_fault", "pressure_fault", &["cp02"], &["cp03"]) },
        ];
        let summary = summarise(&records);
        assert_eq!(summary.per_effect_top1_at_ratio_ge_1["pressure_fault"], Some(0.5));
        assert_close(summary.vocabulary_top1_at_ratio_ge_1, 0.5);
    }

    /// A dead channel counts as large, so its case belongs in the last ratio bin (labelled
    /// ">= 4 (or dead channel)" in the report) and the row adds up to the class's cases.
    #[test]
    fn a_dead_channel_sits_in_the_last_ratio_bin() {
        let dead =
            CaseRecord { ratio: None, ..right(sensor_case("pressure_fault", "pressure_fault", &["cp07"], &["cp07"])) };
        let summary = summarise(&[dead]);
        assert_eq!(summary.accuracy_by_ratio["pressure_fault"], vec![(0, 0), (0, 0), (0, 0), (1, 1)]);
    }

    /// The median shrink takes only right first effects at ratio >= 1 whose shrink is measured:
    /// a dead channel's (recorded `None`, its 1 holds by definition), a wrong case's and a case
    /// below ratio 1 stay out. Left: 0.5, 0.7, 0.9, so the median is 0.7 (0.8 if the dead
    /// channel's 1 got in) and the quartiles, interpolated linearly, 0.6 / 0.7 / 0.8.
    #[test]
    fn the_median_shrink_leaves_out_by_definition_wrong_and_weak_cases() {
        let records = vec![
            with_shrink(right(case("roll_damping", Some(2.0), "effect", &["roll_damping"])), Some(0.5), Some(0.4)),
            with_shrink(right(case("roll_damping", Some(3.0), "effect", &["roll_damping"])), Some(0.7), Some(0.6)),
            with_shrink(right(case("inertial_tare", Some(1.5), "effect", &["inertial_tare"])), Some(0.9), Some(0.8)),
            // A dead channel: right, large, shrink not measured.
            CaseRecord { ratio: None, ..right(sensor_case("pressure_fault", "pressure_fault", &["cp07"], &["cp07"])) },
            // Wrong first effect: its shrink says nothing of the right one.
            with_shrink(case("roll_damping", Some(2.0), "effect", &["vortex_lag"]), Some(0.1), Some(0.1)),
            // Right but below ratio 1.
            with_shrink(right(case("bias_drift", Some(0.6), "effect", &["bias_drift"])), Some(0.2), Some(0.2)),
        ];
        let summary = summarise(&records);
        assert_close(summary.median_shrink_at_ratio_ge_1, 0.7);
        assert_close(summary.median_shrink_total_at_ratio_ge_1, 0.6);
        let [q1, q2, q3] = summary.shrink_quartiles.expect("quartiles");
        assert!((q1 - 0.6).abs() < 1e-12 && (q2 - 0.7).abs() < 1e-12 && (q3 - 0.8).abs() < 1e-12, "{q1} {q2} {q3}");
        // Ratio >= 1: four right of five; per effect, bias_drift has no case at ratio >= 1.
        assert_close(summary.vocabulary_top1_at_ratio_ge_1, 0.8);
        assert_close(summary.per_effect_top1_at_ratio_ge_1["roll_damping"], 2.0 / 3.0);
        assert_eq!(summary.per_effect_top1_at_ratio_ge_1["bias_drift"], None);
    }

    /// The median of an even count is the mean of the middle two, of an odd count the middle
    /// value (times of 4, 1, 3, 2 s: 2.5 s; with 10 s more: 3 s).
    #[test]
    fn the_median_time_is_the_middle_of_the_sorted_times() {
        let timed = |s: f64| CaseRecord { diagnosis_s: s, ..case("none", Some(0.0), "none", &[]) };
        let mut records: Vec<CaseRecord> = [4.0, 1.0, 3.0, 2.0].into_iter().map(timed).collect();
        assert_close(summarise(&records).median_diagnosis_s, 2.5);
        records.push(timed(10.0));
        assert_close(summarise(&records).median_diagnosis_s, 3.0);
    }

    /// The report writes shares as percentages, a missing figure as "n/a" (never 0 %), the
    /// worst single effect as the smallest per-effect share, a dead channel's ratio as "dead"
    /// and its shrink apart from the measured ones.
    #[test]
    fn the_report_writes_percentages_n_a_and_the_worst_effect() {
        let records = vec![
            right(case("none", Some(0.0), "none", &[])),
            right(case("none", Some(0.0), "none", &[])),
            right(case("none", Some(0.0), "none", &[])),
            case("none", Some(0.0), "effect", &["bias_drift"]),
            right(case("coupling", Some(2.0), "effect", &["coupling"])),
            right(case("coupling", Some(2.0), "effect", &["coupling"])),
            case("coupling", Some(2.0), "effect", &["roll_damping"]),
            CaseRecord { ratio: None, ..right(sensor_case("pressure_fault", "pressure_fault", &["cp07"], &["cp07"])) },
        ];
        let summary = summarise(&records);
        let report = report(&records, &summary, "test campaign");
        let acceptance = &report.sections[0].tables[0];
        let measured = |criterion: &str| -> &str {
            let row = acceptance.rows.iter().find(|row| row[0] == criterion).expect("a row");
            &row[2]
        };
        assert_eq!(measured("no effect: an effect named"), "25.0 %");
        assert_eq!(measured("no effect: verdict none"), "75.0 %");
        assert_eq!(measured("  worst single effect"), "66.7 %");
        assert_eq!(measured("outside the vocabulary: unattributed"), "n/a");
        assert_eq!(measured("median held-out shrink, ratio >= 1"), "n/a");
        assert_eq!(measured("sensor effect named first: exactly its channels"), "100.0 %");
        assert_eq!(measured("  right first effects whose shrink holds by definition (dead channels), apart"), "1");
        let cases = &report.sections[2].tables[0];
        let dead_row = cases.rows.iter().find(|row| row[1] == "pressure_fault").expect("the dead case");
        assert_eq!(dead_row[3], "dead");
        assert_eq!(dead_row[7], "yes");
    }
}
