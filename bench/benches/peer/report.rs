//! What the bench measured, and its Markdown report.

use std::fmt::Write as _;

use cutlab_sim::stats::Summary;
use rapier3d_f64::prelude::SoftBodySolver;
use serde::Serialize;

use crate::cases::Case;
use crate::rapier_side::{CantileverRun, CellDamping, Settle, damping_ratio_for};

/// Rapier's two soft-body solvers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RapierSolver {
    /// Every element a constraint, swept Gauss-Seidel (XPBD-like) with contacts and joints.
    Constraints,
    /// Implicit Euler elasticity over the whole body, CG per substep (the `fem` feature).
    Fem,
}

impl RapierSolver {
    pub fn soft_body_solver(self) -> SoftBodySolver {
        match self {
            RapierSolver::Constraints => SoftBodySolver::Constraints,
            RapierSolver::Fem => SoftBodySolver::Fem,
        }
    }
}

/// An engine with a force model and a solver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Config {
    CutlabFem,
    CutlabSprings,
    /// Rapier's co-rotational cells; `substeps` per 1 ms step (Rapier's
    /// `num_solver_iterations`, default 4).
    Rapier {
        solver: RapierSolver,
        substeps: usize,
    },
}

impl Config {
    pub const ALL: [Config; 6] = [
        Config::CutlabFem,
        Config::CutlabSprings,
        Config::Rapier {
            solver: RapierSolver::Constraints,
            substeps: 4,
        },
        Config::Rapier {
            solver: RapierSolver::Fem,
            substeps: 4,
        },
        Config::Rapier {
            solver: RapierSolver::Constraints,
            substeps: 1,
        },
        Config::Rapier {
            solver: RapierSolver::Fem,
            substeps: 1,
        },
    ];

    /// Rapier at its default substeps: the configurations the cut and the mapped damping
    /// run with.
    pub fn is_rapier_default(self) -> bool {
        matches!(self, Config::Rapier { substeps: 4, .. })
    }

    pub fn engine(self) -> &'static str {
        match self {
            Config::CutlabFem | Config::CutlabSprings => "cutlab",
            Config::Rapier { .. } => "Rapier",
        }
    }

    pub fn label(self) -> String {
        match self {
            Config::CutlabFem => {
                let tolerance = cutlab_sim::solver::SolverSettings::default().cg_relative_tolerance;
                format!("co-rotational FEM, implicit Euler (1 linear solve, PCG to {tolerance:e})")
            }
            Config::CutlabSprings => {
                "paper's springs (chest wall 100 N/m, bar van Gelder's k from E), implicit Euler"
                    .into()
            }
            Config::Rapier {
                solver: RapierSolver::Constraints,
                substeps,
            } => {
                format!(
                    "co-rotational cells, constraints solver ({}, 4 sweeps each)",
                    substeps_text(substeps)
                )
            }
            Config::Rapier {
                solver: RapierSolver::Fem,
                substeps,
            } => {
                format!(
                    "co-rotational cells, FEM solver ({}, CG to 1e-5, at most 20 it.)",
                    substeps_text(substeps)
                )
            }
        }
    }

    pub fn short(self) -> String {
        match self {
            Config::CutlabFem => "FEM".into(),
            Config::CutlabSprings => "springs".into(),
            Config::Rapier {
                solver: RapierSolver::Constraints,
                substeps,
            } => format!("constraints, {}", substeps_text(substeps)),
            Config::Rapier {
                solver: RapierSolver::Fem,
                substeps,
            } => format!("FEM solver, {}", substeps_text(substeps)),
        }
    }
}

fn substeps_text(substeps: usize) -> String {
    if substeps == 1 {
        "1 substep".into()
    } else {
        format!("{substeps} substeps")
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct StepRow {
    pub config: Config,
    pub mesh: &'static str,
    pub tets: usize,
    pub step_us: Summary,
    /// cutlab only.
    pub cg_iterations_mean: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct CutRow {
    pub config: Config,
    pub mesh: &'static str,
    pub cut_ms: Summary,
    /// Tets (Rapier: cells) before and after the cut.
    pub tets_before: usize,
    pub tets_after: usize,
    /// Vertices (Rapier: particles) before and after the cut.
    pub vertices_before: usize,
    pub vertices_after: usize,
}

#[derive(Debug, Clone, Serialize)]
pub struct CantileverRow {
    pub config: Config,
    /// Rapier only.
    pub cell_damping: Option<CellDamping>,
    pub deflection_m: f64,
    pub analytic_m: f64,
    /// `deflection / analytic`.
    pub ratio_to_analytic: f64,
    /// `|deflection - analytic| / analytic`.
    pub relative_error: f64,
    /// False when Rapier's run hit its step cap before the deflection settled.
    pub settled: bool,
    /// Rapier only: simulated time until it settled (or the cap).
    pub simulated_s: Option<f64>,
    /// Rapier only: settled when the tip deflection changed by less than this fraction of
    /// itself over 100 steps.
    pub settle_relative_change: Option<f64>,
    pub wall_ms: f64,
}

impl CantileverRow {
    pub fn cutlab(config: Config, deflection_m: f64, analytic_m: f64, wall_ms: f64) -> Self {
        Self {
            config,
            cell_damping: None,
            deflection_m,
            analytic_m,
            ratio_to_analytic: deflection_m / analytic_m,
            relative_error: (deflection_m - analytic_m).abs() / analytic_m,
            settled: true,
            simulated_s: None,
            settle_relative_change: None,
            wall_ms,
        }
    }

    pub fn rapier(
        config: Config,
        damping: CellDamping,
        run: &CantileverRun,
        settle: Settle,
        analytic_m: f64,
        time_step_s: f64,
    ) -> Self {
        Self {
            config,
            cell_damping: Some(damping),
            deflection_m: run.deflection_m,
            analytic_m,
            ratio_to_analytic: run.deflection_m / analytic_m,
            relative_error: run.relative_error,
            settled: run.converged,
            simulated_s: Some(run.steps as f64 * time_step_s),
            settle_relative_change: Some(settle.relative_change),
            wall_ms: run.wall_ms,
        }
    }
}

/// Rapier's cell damping ratio that stands for cutlab's Rayleigh `beta` on a mesh.
#[derive(Debug, Clone, Serialize)]
pub struct MappedDamping {
    pub mesh: &'static str,
    pub rayleigh_beta_s: f64,
    pub rayleigh_alpha_per_s: f64,
    pub cell_damping_ratio: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Results {
    pub rapier_version: &'static str,
    pub quick: bool,
    pub time_step_s: f64,
    pub steps_per_run: usize,
    pub damping: Vec<MappedDamping>,
    pub steps: Vec<StepRow>,
    pub cuts: Vec<CutRow>,
    pub cantilevers: Vec<CantileverRow>,
}

impl Results {
    pub fn new(cases: &[Case], quick: bool, steps_per_run: usize) -> Self {
        let damping = cases
            .iter()
            .map(|c| MappedDamping {
                mesh: c.name,
                rayleigh_beta_s: c.material.rayleigh_stiffness_s,
                rayleigh_alpha_per_s: c.material.rayleigh_mass_per_s,
                cell_damping_ratio: damping_ratio_for(&c.fem.mesh, &c.fem.inv_mass, &c.material),
            })
            .collect();
        Self {
            rapier_version: rapier3d_f64::VERSION,
            quick,
            time_step_s: crate::rapier_side::TIME_STEP_S,
            steps_per_run,
            damping,
            steps: Vec::new(),
            cuts: Vec::new(),
            cantilevers: Vec::new(),
        }
    }

    fn meshes(&self) -> Vec<(&'static str, usize)> {
        let mut meshes: Vec<(&'static str, usize)> = Vec::new();
        for r in &self.steps {
            if !meshes.iter().any(|(m, _)| *m == r.mesh) {
                meshes.push((r.mesh, r.tets));
            }
        }
        meshes
    }

    /// The configurations measured, in [`Config::ALL`]'s order.
    fn configs(&self) -> Vec<Config> {
        Config::ALL
            .into_iter()
            .filter(|c| self.steps.iter().any(|r| r.config == *c))
            .collect()
    }

    fn step(&self, config: Config, mesh: &str) -> Option<&StepRow> {
        self.steps
            .iter()
            .find(|r| r.config == config && r.mesh == mesh)
    }

    fn cut(&self, config: Config, mesh: &str) -> Option<&CutRow> {
        self.cuts
            .iter()
            .find(|r| r.config == config && r.mesh == mesh)
    }
}

/// The whole report.
pub fn markdown(r: &Results) -> String {
    let mut out = String::new();
    header(&mut out, r);
    step_table(&mut out, r);
    cut_table(&mut out, r);
    cantilever_table(&mut out, r);
    ratio_table(&mut out, r);
    out
}

fn header(out: &mut String, r: &Results) {
    let _ = writeln!(
        out,
        "cutlab vs Rapier {} (`rapier3d-f64`, soft bodies, features dim3 f64 std fem); single thread; {} ms steps; \
         {} steps per run{}; E 30 kPa, nu 0.45, rho 900 kg/m3, cutlab's lumped masses and held vertices in both.",
        r.rapier_version,
        r.time_step_s * 1e3,
        r.steps_per_run,
        if r.quick { " (--quick)" } else { "" }
    );
    for d in &r.damping {
        let _ = writeln!(
            out,
            "Damping on {}: Rayleigh alpha {} /s -> Rapier particle damping {} /s; beta {} s -> cell damping ratio {:.2}.",
            d.mesh,
            d.rayleigh_alpha_per_s,
            d.rayleigh_alpha_per_s,
            d.rayleigh_beta_s,
            d.cell_damping_ratio
        );
    }
    let _ = writeln!(out);
}

fn step_table(out: &mut String, r: &Results) {
    let meshes = r.meshes();
    let _ = writeln!(
        out,
        "Time per step, median / p99 us, while a press slides along the surface:\n"
    );
    let _ = write!(out, "| engine | model, solver |");
    meshes.iter().for_each(|(m, t)| {
        let _ = write!(out, " {m} ({t} tets) |");
    });
    let _ = writeln!(out, "\n|---|---|{}", "---:|".repeat(meshes.len()));
    for config in r.configs() {
        let _ = write!(out, "| {} | {} |", config.engine(), config.label());
        for (mesh, _) in &meshes {
            let cell = r.step(config, mesh).map_or_else(
                || "-".to_owned(),
                |s| {
                    let cg = s
                        .cg_iterations_mean
                        .map_or_else(String::new, |c| format!(" ({c:.1} CG it.)"));
                    format!("{:.0} / {:.0}{cg}", s.step_us.median, s.step_us.p99)
                },
            );
            let _ = write!(out, " {cell} |");
        }
        let _ = writeln!(out);
    }
    let _ = writeln!(out);
}

fn cut_table(out: &mut String, r: &Results) {
    let meshes = r.meshes();
    let _ = writeln!(
        out,
        "Time per cut through the middle (median ms; tets or cells and vertices or particles before -> after):\n"
    );
    let _ = write!(out, "| engine | model |");
    meshes.iter().for_each(|(m, _)| {
        let _ = write!(out, " {m} |");
    });
    let _ = writeln!(out, "\n|---|---|{}", "---:|".repeat(meshes.len()));
    for config in r
        .configs()
        .into_iter()
        .filter(|c| r.cuts.iter().any(|row| row.config == *c))
    {
        let _ = write!(out, "| {} | {} |", config.engine(), config.label());
        for (mesh, _) in &meshes {
            let cell = r.cut(config, mesh).map_or_else(
                || "-".to_owned(),
                |c| {
                    format!(
                        "{:.2} ({} -> {} tets, {} -> {} vertices)",
                        c.cut_ms.median,
                        c.tets_before,
                        c.tets_after,
                        c.vertices_before,
                        c.vertices_after
                    )
                },
            );
            let _ = write!(out, " {cell} |");
        }
        let _ = writeln!(out);
    }
    let _ = writeln!(out);
}

fn cantilever_table(out: &mut String, r: &Results) {
    let fe = r
        .cantilevers
        .iter()
        .find(|c| c.config == Config::CutlabFem)
        .map(|c| c.deflection_m);
    let _ = writeln!(
        out,
        "Cantilever on bar-2523 (tip load, deflection 1e-3 of the length by Timoshenko); `/ FE` is the deflection over \
         cutlab's static finite-element solution of the same mesh:\n"
    );
    let _ = writeln!(
        out,
        "| engine | model, solver | cell damping | deflection / Timoshenko | error % | / FE | solved by |"
    );
    let _ = writeln!(out, "|---|---|---|---:|---:|---:|---|");
    for c in &r.cantilevers {
        let damping = match c.cell_damping {
            None => "-".to_owned(),
            Some(CellDamping::Default) => "Rapier's default (1)".to_owned(),
            Some(CellDamping::Mapped) => "mapped from beta".to_owned(),
        };
        let vs_fe = fe.map_or_else(|| "-".to_owned(), |d| format!("{:.3}", c.deflection_m / d));
        let tolerance = c.settle_relative_change.unwrap_or(0.0);
        let how = match c.simulated_s {
            None => format!("Newton statics, {:.0} ms", c.wall_ms),
            Some(t) if c.settled => format!(
                "dynamics to rest (tip moving < {tolerance:.0e} of itself per 100 steps) after {t:.1} s simulated ({:.1} s wall)",
                c.wall_ms / 1e3
            ),
            Some(t) => format!(
                "dynamics, NOT at rest after {t:.1} s simulated ({:.1} s wall)",
                c.wall_ms / 1e3
            ),
        };
        let _ = writeln!(
            out,
            "| {} | {} | {damping} | {:.3} | {:.1} | {vs_fe} | {how} |",
            c.config.engine(),
            c.config.label(),
            c.ratio_to_analytic,
            100.0 * c.relative_error
        );
    }
    let _ = writeln!(out);
}

fn ratio_table(out: &mut String, r: &Results) {
    let meshes = r.meshes();
    let _ = writeln!(
        out,
        "Ratios cutlab / Rapier (below 1: cutlab takes less time), step median and p99, cut median:\n"
    );
    let _ = write!(out, "| cutlab | Rapier |");
    for (m, _) in &meshes {
        let _ = write!(out, " step {m} | step p99 {m} | cut {m} |");
    }
    let _ = writeln!(out, "\n|---|---|{}", "---:|".repeat(3 * meshes.len()));
    let configs = r.configs();
    for ours in [Config::CutlabFem, Config::CutlabSprings] {
        for &theirs in configs.iter().filter(|c| c.engine() == "Rapier") {
            let _ = write!(out, "| {} | {} |", ours.short(), theirs.short());
            for (mesh, _) in &meshes {
                let ratio = |a: Option<f64>, b: Option<f64>| match (a, b) {
                    (Some(a), Some(b)) if b > 0.0 => format!("{:.2}", a / b),
                    _ => "-".to_owned(),
                };
                let (s1, s2) = (r.step(ours, mesh), r.step(theirs, mesh));
                let (c1, c2) = (r.cut(ours, mesh), r.cut(theirs, mesh));
                let _ = write!(
                    out,
                    " {} | {} | {} |",
                    ratio(s1.map(|s| s.step_us.median), s2.map(|s| s.step_us.median)),
                    ratio(s1.map(|s| s.step_us.p99), s2.map(|s| s.step_us.p99)),
                    ratio(c1.map(|c| c.cut_ms.median), c2.map(|c| c.cut_ms.median)),
                );
            }
            let _ = writeln!(out);
        }
    }
}
