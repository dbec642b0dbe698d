//! `simulate` and `superposition`: recordings of the synthetic tunnel and the paper's Table 1.

use std::time::Instant;

use anyhow::Context;
use firmware_sim::campaign::Scenario;

use crate::flags::*;
use host_tools::progress::*;

/// `simulate`: scenario -> synthetic tunnel -> dataset folder.
pub(crate) fn simulate(args: SimulateArgs) -> anyhow::Result<()> {
    let (scenario, _) = args.scenario.resolve(Scenario::default(), "the paper's campaign")?;
    let started = Instant::now();
    let n_runs = scenario.alphas_deg.len() * scenario.kinds.len();
    let progress = progress_bar(n_runs as u64, "simulating runs");
    let dataset = scenario.simulate(&|| progress.inc(1))?;
    progress.set_message("writing dataset");
    firmware_sim::dataset::write_dataset(&args.out, &dataset)
        .with_context(|| format!("writing the dataset to {}", args.out.display()))?;
    progress.finish_and_clear();
    eprintln!(
        "wrote {} runs to {} in {:.1} s",
        dataset.runs.len(),
        args.out.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `superposition`: the paper's Table 1 for a dataset.
pub(crate) fn superposition(args: SuperpositionArgs) -> anyhow::Result<()> {
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let rows = host_tools::analysis::superposition::superposition_table(&dataset)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!("Table 1: validity of superposition, Delta C_l = C_l,RollAFC - C_l,Roll - C_l,AFC");
    println!(
        "{:>9}  {:>22}  {:>22}  {:>12}  {:>12}",
        "alpha_deg", "sigma(dCl)/mean(ClRA)", "sigma(dCl)/sigma(ClRA)", "sigma(dCl)", "mean(ClRA)"
    );
    for row in rows {
        println!(
            "{:>9.1}  {:>21.1}%  {:>21.1}%  {:>12.3e}  {:>12.3e}",
            row.alpha_deg,
            100.0 * row.ratio_to_mean,
            100.0 * row.ratio_to_std,
            row.delta_std,
            row.rollact_mean
        );
    }
    Ok(())
}
