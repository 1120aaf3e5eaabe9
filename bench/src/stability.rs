//! `cutlab bench stability`: the stability sweep of `cutlab_sim::stability` over time step,
//! stiffness, damping and mass ratio, per force model and integrator.

use std::time::Instant;

use anyhow::Context;
use cutlab_sim::generate::GridCells;
use cutlab_sim::stability::{self, Outcome, StabilityCase, StabilityResult};
use serde::Serialize;

#[derive(Debug, Serialize)]
struct Row {
    case: StabilityCase,
    result: StabilityResult,
    wall_ms: f64,
}

/// Runs the sweep and prints a summary per model and integrator and every case that was not
/// stable.
pub fn run(quick: bool, json: bool) -> anyhow::Result<()> {
    let cases = stability::sweep(quick);
    let cells = GridCells {
        nx: 6,
        ny: 6,
        nz: 2,
    };
    let duration_s = if quick { 0.05 } else { 0.2 };
    let bar = crate::progress::bar(cases.len() as u64, json);
    let mut rows = Vec::new();
    for case in cases {
        bar.set_message(format!(
            "{} {} {} ms E {} kPa",
            case.model.name(),
            case.integrator.name(),
            case.time_step_s * 1e3,
            case.youngs_modulus_pa / 1e3
        ));
        let t = Instant::now();
        let result = stability::run(&case, cells, duration_s, stability::MAX_SUBSTEPS)
            .with_context(|| format!("{case:?}"))?;
        rows.push(Row {
            case,
            result,
            wall_ms: t.elapsed().as_secs_f64() * 1e3,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!(
        "slab 40 x 40 x 10 mm ({} tets), rim held, 4 % pre-tension, settled, kicked at 0.1 m/s, {} s simulated;",
        6 * cells.nx * cells.ny * cells.nz,
        duration_s
    );
    println!("dt 0.1/1/10 ms, E 1 kPa..1 MPa, damping levels 0/1/2, mass ratio 1/100");
    println!(
        "| model | integrator | cases | stable | rejected safely | unbounded | too many substeps | NaN leaked | max energy ratio (stable) |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|");
    let mut groups: Vec<(&str, &str)> = rows
        .iter()
        .map(|r| (r.case.model.name(), r.case.integrator.name()))
        .collect();
    groups.dedup();
    for (model, integrator) in groups {
        let sel: Vec<&Row> = rows
            .iter()
            .filter(|r| r.case.model.name() == model && r.case.integrator.name() == integrator)
            .collect();
        let count = |o: Outcome| sel.iter().filter(|r| r.result.outcome == o).count();
        let worst = sel
            .iter()
            .filter(|r| r.result.outcome == Outcome::Stable)
            .map(|r| r.result.energy_ratio)
            .fold(0.0, f64::max);
        println!(
            "| {model} | {integrator} | {} | {} | {} | {} | {} | {} | {worst:.3} |",
            sel.len(),
            count(Outcome::Stable),
            count(Outcome::Rejected),
            count(Outcome::Unbounded),
            count(Outcome::TooManySubsteps),
            count(Outcome::NonFiniteLeak),
        );
    }
    println!();
    println!("cases that were not stable:");
    println!(
        "| model | integrator | dt ms | E kPa | damping | mass ratio | outcome | substeps | energy ratio |"
    );
    println!("|---|---|---:|---:|---:|---:|---|---:|---:|");
    for r in rows.iter().filter(|r| r.result.outcome != Outcome::Stable) {
        let c = &r.case;
        println!(
            "| {} | {} | {} | {} | {} | {} | {:?} | {} | {:.2} |",
            c.model.name(),
            c.integrator.name(),
            c.time_step_s * 1e3,
            c.youngs_modulus_pa / 1e3,
            c.damping_level,
            c.mass_ratio,
            r.result.outcome,
            r.result.substeps,
            r.result.energy_ratio
        );
    }
    let leaks = rows
        .iter()
        .filter(|r| r.result.outcome == Outcome::NonFiniteLeak)
        .count();
    anyhow::ensure!(
        leaks == 0,
        "{leaks} runs leaked non-finite values into the state"
    );
    Ok(())
}
