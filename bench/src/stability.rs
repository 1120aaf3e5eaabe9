//! `cutlab bench stability`: the stability sweep of `cutlab_sim::stability` over time step,
//! stiffness, damping and mass ratio, per force model and integrator.

use std::time::Instant;

use anyhow::Context;
use cutlab_sim::cut_stress;
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
    print_sweep(&rows, cells, duration_s);
    let leaks = rows
        .iter()
        .filter(|r| r.result.outcome == Outcome::NonFiniteLeak)
        .count();
    let cut_leaks = cuts(quick)?;
    anyhow::ensure!(
        leaks + cut_leaks == 0,
        "{leaks} runs and {cut_leaks} strokes leaked non-finite values into the state"
    );
    Ok(())
}

/// The sweep's summary per model and integrator, and every case that was not stable.
fn print_sweep(rows: &[Row], cells: GridCells, duration_s: f64) {
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
}

/// The strokes of `cutlab_sim::cut_stress` (curved, closed, zig-zag) on the sheet and the
/// chest wall: prints a row per stroke and returns how many leaked non-finite values.
fn cuts(quick: bool) -> anyhow::Result<usize> {
    let cases = cut_stress::cut_sweep(quick);
    println!();
    println!(
        "strokes cut every 0.5 mm at 10 mm/s (0.1 ms steps: 100 mm/s), then 0.2 s more (the scenes' implicit Euler):"
    );
    println!(
        "| tissue | stroke | dt ms | steps | rejected steps | failed cuts | pieces | specimens | fragments reattached | tets | max speed m/s | NaN leaked | wall s |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|");
    let mut leaks = 0;
    for case in cases {
        let t = Instant::now();
        let r = cut_stress::run_cut(&case).with_context(|| format!("{case:?}"))?;
        leaks += usize::from(r.non_finite);
        println!(
            "| {} | {:?} | {} | {} | {} | {} | {} | {} | {} | {} | {:.3} | {} | {:.1} |",
            case.tissue.scene(),
            case.shape,
            case.time_step_s * 1e3,
            r.steps,
            r.failed_steps,
            r.failed_cuts,
            r.pieces,
            r.specimens,
            r.fragments_reattached,
            r.tets,
            r.max_speed_m_per_s,
            if r.non_finite { "yes" } else { "no" },
            t.elapsed().as_secs_f64()
        );
    }
    Ok(leaks)
}
