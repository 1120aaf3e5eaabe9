//! `cargo bench -p cutlab-bench --bench peer [-- --quick] [-- --json]`: cutlab side by side
//! with a peer, Rapier's soft bodies (`rapier3d-f64` 0.36, a dev-dependency of this bench
//! only), on the same tet meshes at the same 1 ms step and the same material: step time under
//! a sliding press, the time of one cut through the middle, and the cantilever against
//! Timoshenko on bar-2523.
//! Progress on stderr, a Markdown report (or JSON) on stdout. Single thread (neither engine is
//! built parallel here).

mod cantilever;
mod cases;
mod cutlab_side;
mod press;
mod rapier_side;
mod report;

use cutlab_sim::reference::{Elasticity, Solid};
use indicatif::{ProgressBar, ProgressStyle};

use crate::cantilever::CantileverLoad;
use crate::cases::Case;
use crate::rapier_side::{CellDamping, Settle, Setup};
use crate::report::{CantileverRow, Config, CutRow, Results, StepRow};

/// How much to measure.
#[derive(Debug, Clone, Copy)]
struct Plan {
    quick: bool,
    json: bool,
    steps: usize,
    cut_repeats: usize,
    /// Rapier at 1 substep too (steps and cantilever).
    single_substep: bool,
    /// When Rapier's cantilever runs with its default and with the mapped damping count as
    /// settled (`None`: not run).
    cantilever: Settle,
    mapped_cantilever: Option<Settle>,
}

impl Plan {
    /// From the arguments (`--quick`, `--json`; the others, such as cargo's `--bench`, ignored).
    fn from_args() -> Self {
        let args: Vec<String> = std::env::args().skip(1).collect();
        let has = |flag: &str| args.iter().any(|a| a == flag);
        let (quick, json) = (has("--quick"), has("--json"));
        if quick {
            Self {
                quick,
                json,
                steps: 60,
                cut_repeats: 2,
                single_substep: false,
                cantilever: Settle {
                    relative_change: 1e-3,
                    max_steps: 2_000,
                },
                mapped_cantilever: None,
            }
        } else {
            Self {
                quick,
                json,
                steps: 300,
                cut_repeats: 5,
                single_substep: true,
                cantilever: Settle {
                    relative_change: 1e-4,
                    max_steps: 5_000,
                },
                mapped_cantilever: Some(Settle {
                    relative_change: 1e-4,
                    max_steps: 3_000,
                }),
            }
        }
    }

    /// The configurations measured.
    fn configs(&self) -> Vec<Config> {
        Config::ALL
            .into_iter()
            .filter(|c| self.single_substep || !matches!(c, Config::Rapier { substeps: 1, .. }))
            .collect()
    }

    /// The configurations cut: cutlab's and Rapier's at its default substeps (a cut does not
    /// depend on them).
    fn cut_configs(&self) -> Vec<Config> {
        self.configs()
            .into_iter()
            .filter(|c| c.engine() == "cutlab" || c.is_rapier_default())
            .collect()
    }

    /// Rapier's cantilever runs: every Rapier configuration with its default damping, those
    /// at the default substeps with the mapped damping too (full run).
    fn rapier_cantilevers(&self) -> Vec<(Config, CellDamping, Settle)> {
        let rapier: Vec<Config> = self
            .configs()
            .into_iter()
            .filter(|c| c.engine() == "Rapier")
            .collect();
        let mut runs: Vec<(Config, CellDamping, Settle)> = rapier
            .iter()
            .map(|&c| (c, CellDamping::Default, self.cantilever))
            .collect();
        if let Some(settle) = self.mapped_cantilever {
            runs.extend(
                rapier
                    .iter()
                    .filter(|c| c.is_rapier_default())
                    .map(|&c| (c, CellDamping::Mapped, settle)),
            );
        }
        runs
    }

    fn job_count(&self) -> u64 {
        (2 * (self.configs().len() + self.cut_configs().len())
            + 2
            + self.rapier_cantilevers().len()) as u64
    }
}

/// Progress on stderr: a bar on a terminal, a line per job otherwise.
struct Progress(ProgressBar);

impl Progress {
    fn new(plan: &Plan) -> Self {
        let bar = ProgressBar::new(plan.job_count());
        let style = ProgressStyle::with_template("{bar:30} {pos}/{len} {elapsed} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar());
        bar.set_style(style);
        Self(bar)
    }

    fn start(&self, message: String) {
        if self.0.is_hidden() {
            eprintln!(
                "[{}/{}] {message}",
                self.0.position() + 1,
                self.0.length().unwrap_or(0)
            );
        }
        self.0.set_message(message);
    }

    fn done(&self) {
        self.0.inc(1);
    }
}

/// Rapier's setup for `config` (`None` for cutlab's).
fn rapier_setup(config: Config, cell_damping: CellDamping) -> Option<Setup> {
    match config {
        Config::Rapier { solver, substeps } => Some(Setup {
            solver: solver.soft_body_solver(),
            substeps,
            cell_damping,
        }),
        Config::CutlabFem | Config::CutlabSprings => None,
    }
}

/// Step times of `config` on `case`.
fn step_row(case: &Case, config: Config, plan: &Plan) -> anyhow::Result<StepRow> {
    let (step_us, cg) = match (config, rapier_setup(config, CellDamping::Mapped)) {
        (_, Some(setup)) => (rapier_side::steps(case, setup, plan.steps)?, None),
        (Config::CutlabSprings, None) => {
            let run = cutlab_side::steps(case, &case.springs, plan.steps)?;
            (run.step_us, Some(run.cg_iterations_mean))
        }
        (_, None) => {
            let run = cutlab_side::steps(case, &case.fem, plan.steps)?;
            (run.step_us, Some(run.cg_iterations_mean))
        }
    };
    Ok(StepRow {
        config,
        mesh: case.name,
        tets: case.tets(),
        step_us,
        cg_iterations_mean: cg,
    })
}

/// Cut times of `config` on `case`.
fn cut_row(case: &Case, config: Config, plan: &Plan) -> anyhow::Result<CutRow> {
    Ok(match (config, rapier_setup(config, CellDamping::Mapped)) {
        (_, Some(setup)) => {
            let run = rapier_side::cut(case, setup, plan.cut_repeats)?;
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
            let model = if config == Config::CutlabSprings {
                &case.springs
            } else {
                &case.fem
            };
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
fn cantilever_rows(
    bar: &Case,
    plan: &Plan,
    progress: &Progress,
) -> anyhow::Result<Vec<CantileverRow>> {
    let solid = Solid::CHEST_WALL;
    let load = CantileverLoad::new(&bar.fem.mesh, solid);
    let held: Vec<u32> = (0..bar.fem.vertex_count() as u32)
        .filter(|&v| bar.fem.held[v as usize])
        .collect();
    anyhow::ensure!(
        held == load.clamped,
        "the bar's held vertices are not the cantilever's clamped face"
    );
    let mut rows = Vec::new();
    for (config, kind) in [
        (Config::CutlabFem, Elasticity::CorotationalFem),
        (Config::CutlabSprings, Elasticity::SpringsYoungs),
    ] {
        progress.start(format!("cantilever, {}", config.label()));
        let (result, wall_ms) = cutlab_side::cantilever(kind, solid)?;
        anyhow::ensure!(
            (result.analytic_m - load.analytic_m).abs() <= 1e-12 * load.analytic_m,
            "the bench's cantilever load differs from cutlab_sim::reference's"
        );
        rows.push(CantileverRow::cutlab(
            config,
            result.deflection_m,
            load.analytic_m,
            wall_ms,
        ));
        progress.done();
    }
    for (config, damping, settle) in plan.rapier_cantilevers() {
        let Some(setup) = rapier_setup(config, damping) else {
            continue;
        };
        progress.start(format!(
            "cantilever, {}, {damping:?} cell damping",
            config.label()
        ));
        let run = rapier_side::cantilever(&bar.fem, &bar.material, &load, setup, settle)?;
        rows.push(CantileverRow::rapier(
            config,
            damping,
            &run,
            settle,
            load.analytic_m,
            rapier_side::TIME_STEP_S,
        ));
        progress.done();
    }
    Ok(rows)
}

fn measure(plan: &Plan) -> anyhow::Result<Results> {
    let progress = Progress::new(plan);
    progress.0.set_message("building the meshes");
    let cases = [cases::bar()?, cases::chest_wall()?];
    let mut results = Results::new(&cases, plan.quick, plan.steps);
    for case in &cases {
        for config in plan.configs() {
            progress.start(format!("{}: steps, {}", case.name, config.label()));
            results.steps.push(step_row(case, config, plan)?);
            progress.done();
        }
        for config in plan.cut_configs() {
            progress.start(format!("{}: cut, {}", case.name, config.label()));
            results.cuts.push(cut_row(case, config, plan)?);
            progress.done();
        }
    }
    results.cantilevers = cantilever_rows(&cases[0], plan, &progress)?;
    progress.0.finish_and_clear();
    Ok(results)
}

fn main() -> anyhow::Result<()> {
    // `cargo test --benches` runs this without cargo bench's `--bench`: no four-minute run there
    if !std::env::args().any(|a| a == "--bench") {
        eprintln!("the peer comparison runs under `cargo bench -p cutlab-bench --bench peer`");
        return Ok(());
    }
    let plan = Plan::from_args();
    // single thread on both sides: cutlab's sweeps and assembly take a second thread on large
    // systems, Rapier's soft bodies run on one
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build_global()
        .map_err(|e| anyhow::anyhow!("a one-thread pool for cutlab: {e}"))?;
    let results = measure(&plan)?;
    if plan.json {
        println!("{}", serde_json::to_string_pretty(&results)?);
    } else {
        print!("{}", report::markdown(&results));
    }
    Ok(())
}
