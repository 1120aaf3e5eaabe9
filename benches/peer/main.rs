//! `cargo bench --bench peer [-- --quick] [-- --json]`: cutlab side by side with a peer, Rapier's
//! soft bodies (`rapier3d-f64` 0.36, a dev-dependency of this bench only), on the same tet
//! meshes at the same 1 ms step and the same material: step time under a sliding press, the
//! time of one cut through the middle, and the cantilever against Timoshenko on bar-2523.
//! Progress on stderr, a Markdown report (or JSON) on stdout. Single thread (neither engine is
//! built parallel here).

mod cantilever;
mod cases;
mod cutlab_side;
mod press;
mod rapier_side;
mod report;
#[allow(unused_imports)]
#[path = "../../src/stats.rs"]
mod stats;

use cutlab_sim::reference::{Elasticity, Solid};
use indicatif::{ProgressBar, ProgressStyle};
use rapier3d_f64::prelude::SoftBodySolver;

use crate::cantilever::CantileverLoad;
use crate::cases::Case;
use crate::rapier_side::CellDamping;
use crate::report::{CantileverRow, Config, CutRow, Results, StepRow};

/// How much to measure.
#[derive(Debug, Clone, Copy)]
struct Plan {
    quick: bool,
    json: bool,
    steps: usize,
    cut_repeats: usize,
    /// Step caps of Rapier's cantilever runs with its default and with the mapped damping
    /// (`None`: not run).
    cantilever_max_steps: usize,
    mapped_cantilever_max_steps: Option<usize>,
}

impl Plan {
    /// From the arguments (`--quick`, `--json`; the others, such as cargo's `--bench`, ignored).
    fn from_args() -> Self {
        let args: Vec<String> = std::env::args().skip(1).collect();
        let has = |flag: &str| args.iter().any(|a| a == flag);
        let quick = has("--quick");
        if quick {
            Self { quick, json: has("--json"), steps: 60, cut_repeats: 2, cantilever_max_steps: 2_000, mapped_cantilever_max_steps: None }
        } else {
            Self { quick, json: has("--json"), steps: 300, cut_repeats: 5, cantilever_max_steps: 5_000, mapped_cantilever_max_steps: Some(3_000) }
        }
    }

    /// Jobs: per case and configuration steps and a cut; the cantilevers.
    fn job_count(&self) -> u64 {
        let per_case = 2 * Config::ALL.len();
        let cantilevers = 2 + 2 * (1 + usize::from(self.mapped_cantilever_max_steps.is_some()));
        (2 * per_case + cantilevers) as u64
    }
}

/// A progress bar on stderr.
fn progress(plan: &Plan) -> ProgressBar {
    let bar = ProgressBar::new(plan.job_count());
    let style = ProgressStyle::with_template("{bar:30} {pos}/{len} {elapsed} {msg}").unwrap_or_else(|_| ProgressStyle::default_bar());
    bar.set_style(style);
    bar
}

fn rapier_solver(config: Config) -> Option<SoftBodySolver> {
    match config {
        Config::RapierConstraints => Some(SoftBodySolver::Constraints),
        Config::RapierFem => Some(SoftBodySolver::Fem),
        Config::CutlabFem | Config::CutlabSprings => None,
    }
}

/// Step times of `config` on `case`.
fn step_row(case: &Case, config: Config, plan: &Plan) -> anyhow::Result<StepRow> {
    let (step_us, cg) = match (config, rapier_solver(config)) {
        (_, Some(solver)) => (rapier_side::steps(case, solver, plan.steps)?, None),
        (Config::CutlabSprings, None) => {
            let run = cutlab_side::steps(case, &case.springs, plan.steps)?;
            (run.step_us, Some(run.cg_iterations_mean))
        }
        (_, None) => {
            let run = cutlab_side::steps(case, &case.fem, plan.steps)?;
            (run.step_us, Some(run.cg_iterations_mean))
        }
    };
    Ok(StepRow { config, mesh: case.name, tets: case.tets(), step_us, cg_iterations_mean: cg })
}

/// Cut times of `config` on `case`.
fn cut_row(case: &Case, config: Config, plan: &Plan) -> anyhow::Result<CutRow> {
    Ok(match (config, rapier_solver(config)) {
        (_, Some(solver)) => {
            let run = rapier_side::cut(case, solver, plan.cut_repeats)?;
            CutRow {
                config,
                mesh: case.name,
                cut_ms: run.cut_ms,
                tets_before: case.tets(),
                tets_after: run.cells,
                vertices_before: run.particles_before,
                vertices_after: run.particles_after,
            }
        }
        (_, None) => {
            let model = if config == Config::CutlabSprings { &case.springs } else { &case.fem };
            let run = cutlab_side::cut(case, model, plan.cut_repeats)?;
            CutRow {
                config,
                mesh: case.name,
                cut_ms: run.cut_ms,
                tets_before: run.tets_before,
                tets_after: run.tets_after,
                vertices_before: run.vertices_before,
                vertices_after: run.vertices_after,
            }
        }
    })
}

/// The cantilever rows: cutlab's two models (Newton statics), Rapier's two solvers run to rest
/// with its default cell damping and (full run) the mapped one.
fn cantilever_rows(bar: &Case, plan: &Plan, progress: &ProgressBar) -> anyhow::Result<Vec<CantileverRow>> {
    let solid = Solid::CHEST_WALL;
    let load = CantileverLoad::new(&bar.fem.mesh, solid);
    let held: Vec<u32> = (0..bar.fem.vertex_count() as u32).filter(|&v| bar.fem.held[v as usize]).collect();
    anyhow::ensure!(held == load.clamped, "the bar's held vertices are not the cantilever's clamped face");
    let mut rows = Vec::new();
    for (config, kind) in [(Config::CutlabFem, Elasticity::CorotationalFem), (Config::CutlabSprings, Elasticity::SpringsYoungs)] {
        progress.set_message(format!("cantilever, {}", config.label()));
        let (result, wall_ms) = cutlab_side::cantilever(kind, solid)?;
        anyhow::ensure!(
            (result.analytic_m - load.analytic_m).abs() <= 1e-12 * load.analytic_m,
            "the bench's cantilever load differs from cutlab_sim::reference's"
        );
        rows.push(CantileverRow::cutlab(config, result.deflection_m, load.analytic_m, wall_ms));
        progress.inc(1);
    }
    let mut runs = vec![(CellDamping::Default, plan.cantilever_max_steps)];
    runs.extend(plan.mapped_cantilever_max_steps.map(|n| (CellDamping::Mapped, n)));
    for (damping, max_steps) in runs {
        for config in [Config::RapierConstraints, Config::RapierFem] {
            let Some(solver) = rapier_solver(config) else { continue };
            progress.set_message(format!("cantilever, {}, {damping:?} cell damping", config.label()));
            let run = rapier_side::cantilever(&bar.fem, &bar.material, &load, solver, damping, max_steps)?;
            rows.push(CantileverRow::rapier(config, damping, &run, load.analytic_m, rapier_side::TIME_STEP_S));
            progress.inc(1);
        }
    }
    Ok(rows)
}

fn measure(plan: &Plan) -> anyhow::Result<Results> {
    let progress = progress(plan);
    progress.set_message("building the meshes");
    let cases = [cases::bar()?, cases::chest_wall()?];
    let mut results = Results::new(&cases, plan.quick, plan.steps);
    for case in &cases {
        for config in Config::ALL {
            progress.set_message(format!("{}: steps, {}", case.name, config.label()));
            results.steps.push(step_row(case, config, plan)?);
            progress.inc(1);
            progress.set_message(format!("{}: cut, {}", case.name, config.label()));
            results.cuts.push(cut_row(case, config, plan)?);
            progress.inc(1);
        }
    }
    results.cantilevers = cantilever_rows(&cases[0], plan, &progress)?;
    progress.finish_and_clear();
    Ok(results)
}

fn main() -> anyhow::Result<()> {
    let plan = Plan::from_args();
    let results = measure(&plan)?;
    if plan.json {
        println!("{}", serde_json::to_string_pretty(&results)?);
    } else {
        print!("{}", report::markdown(&results));
    }
    Ok(())
}
