//! `qemu-replay`, `hil` and `sil`: the firmware in QEMU and the closed loop.

use std::time::Instant;

use anyhow::Context;
use firmware_sim::campaign::Scenario;
use host_tools::qemu::SparseCode;

use crate::flags::*;
use host_tools::progress::*;

/// `qemu-replay`: the firmware in QEMU against the host replay, one run.
pub(crate) fn qemu_replay(args: QemuReplayArgs) -> anyhow::Result<()> {
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let run = dataset
        .runs
        .iter()
        .find(|run| run.meta.file == args.run)
        .with_context(|| format!("no run {} in {}", args.run.display(), args.data.display()))?;
    let timeout = std::time::Duration::from_secs(args.timeout_s);
    // QEMU works in a temporary folder that becomes `--out` only once the summary is written:
    // complete or absent, like every other output folder.
    let mut summary = String::new();
    firmware_sim::atomic::write_folder::<anyhow::Error>(&args.out, "summary.txt", |tmp| {
        let code = if args.interpreted { SparseCode::Interpreted } else { SparseCode::Compiled };
        let replay = host_tools::qemu::qemu_replay(run, args.samples, tmp, timeout, code)?;
        summary = host_tools::qemu::summary(&replay);
        std::fs::write(tmp.join("summary.txt"), &summary).context("writing summary.txt")
    })?;
    print!("{summary}");
    Ok(())
}

/// `hil`: the firmware's real-time loop in QEMU against the host's loop, run by run.
pub(crate) fn hil(args: HilArgs) -> anyhow::Result<()> {
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let runs: Vec<&firmware_sim::dataset::Run> = if args.run.is_empty() {
        dataset.runs.iter().collect()
    } else {
        args.run
            .iter()
            .map(|file| {
                dataset
                    .runs
                    .iter()
                    .find(|run| run.meta.file == *file)
                    .with_context(|| format!("no run {} in {}", file.display(), args.data.display()))
            })
            .collect::<anyhow::Result<_>>()?
    };
    let blob = match &args.model {
        Some(dir) => {
            let file = dir.join("model.bin");
            let bytes = std::fs::read(&file).with_context(|| format!("reading the blob {}", file.display()))?;
            Some((file, bytes))
        }
        None => None,
    };
    let (mut text, mut totals) = (String::new(), String::new());
    firmware_sim::atomic::write_folder::<anyhow::Error>(&args.out, "hil.json", |tmp| {
        let mut results = Vec::new();
        for run in &runs {
            let stem = run.meta.file.file_stem().map_or_else(|| "run".into(), |s| s.to_string_lossy().into_owned());
            let dir = tmp.join(&stem);
            std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
            let samples = host_tools::hil::samples_of(run, args.samples);
            let blob = blob.as_ref().map(|(file, bytes)| (file.as_path(), bytes.as_slice()));
            let result = host_tools::hil::hil(&run.meta.file, &samples, blob, &dir)
                .with_context(|| format!("hil of {}", run.meta.file.display()))?;
            let summary = host_tools::hil::summary(&result);
            eprint!("{summary}");
            text.push_str(&summary);
            results.push(result);
        }
        totals = host_tools::hil::totals(&results);
        text.push_str(&totals);
        std::fs::write(tmp.join("summary.txt"), &text).context("writing summary.txt")?;
        let json = serde_json::json!({ "runs": results, "totals": host_tools::hil::totals_json(&results) });
        std::fs::write(tmp.join("hil.json"), serde_json::to_string_pretty(&json)?).context("writing hil.json")
    })?;
    print!("{totals}");
    Ok(())
}

/// `sil`: the controller scenarios in closed loop with the synthetic tunnel, as a report folder.
pub(crate) fn sil(args: SilArgs) -> anyhow::Result<()> {
    use firmware_sim::sil::{Gains, Mode, SilSettings, TuneGrid, run_scenario_with_faults, tune};
    let started = Instant::now();
    let default = Scenario { duration_s: 20.0, ..Scenario::default() };
    let (scenario, described) = args.scenario.resolve(default, "the paper's campaign, 20 s per run")?;
    let (model_set, source) = host_tools::model::load(args.model.as_deref())?;
    let settings = SilSettings::default();
    let mut tuning = None;
    let mut gains = Gains::of(&model_set);
    if args.tune {
        let tune_seed = args.tune_seed.unwrap_or(scenario.seed.wrapping_add(1));
        let tune_scenario = Scenario { seed: tune_seed, ..scenario.clone() };
        let grid = TuneGrid::default();
        let progress = progress_bar(grid.len() as u64, "gain search");
        let points = tune(&tune_scenario, &model_set, &grid, &settings, &|| progress.inc(1))?;
        progress.finish_and_clear();
        if let Some(best) = points.first() {
            gains = best.gains;
        }
        tuning = Some((tune_seed, points));
    }
    gains.causality_tau_s = args.causality_tau_s.unwrap_or(gains.causality_tau_s);
    gains.feedback_kp = args.kp.unwrap_or(gains.feedback_kp);
    gains.feedback_ki = args.ki.unwrap_or(gains.feedback_ki);
    let set = gains.apply(&model_set)?;
    let n_runs = scenario.alphas_deg.len() * Mode::ALL.len();
    let progress = progress_bar(n_runs as u64, "closed-loop runs");
    let results = run_scenario_with_faults(&scenario, &set, &Mode::ALL, &settings, &args.faults, &|| progress.inc(1))?;
    progress.set_message("writing the report");
    let mut described = described;
    for fault in &args.faults {
        described.push_str(&format!(", fault {fault}"));
    }
    let context = host_tools::sil::SilContext { model: source.to_string(), scenario: described, tuning };
    host_tools::sil::write_sil_report(&args.report, &results, &context)
        .with_context(|| format!("writing the report {}", args.report.display()))?;
    progress.finish_and_clear();
    println!("SIL, seed {}: RMS of C_l per scenario", results.seed);
    println!("  {}", host_tools::sil::summary_header().join(" | "));
    for row in host_tools::sil::summary_rows(&results) {
        println!("  {}", row.join(" | "));
    }
    println!("{}", host_tools::sil::verdict(&results));
    println!("report: {}", args.report.join("report.html").display());
    eprintln!("SIL in {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}
