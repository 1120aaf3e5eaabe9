//! `cutlab bench accuracy`: run time against error per force model, mesh and integrator on
//! the reference problems of `cutlab_sim::reference`; a Markdown table (or CSV, or JSON) and an
//! SVG plot of error against run time with the Pareto front of each problem.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use cutlab_sim::generate::GridCells;
use cutlab_sim::reference::{
    self, CantileverResult, Elasticity, IPC_BARS, IPC_UNIT_M, Solid, ipc_dir, read_bar,
};
use cutlab_sim::solver::Integrator;
use serde::Serialize;

use crate::plot;

/// One measurement.
#[derive(Debug, Clone, Serialize)]
pub struct AccuracyRow {
    pub problem: &'static str,
    pub model: &'static str,
    pub tets: usize,
    /// `static` for a static solve, else the integrator and its step.
    pub solver: String,
    /// Wall time of the solve (static problems) or per simulated second (dynamic), ms.
    pub wall_ms: f64,
    /// What `wall_ms` measures.
    pub wall_kind: &'static str,
    /// Relative error against the analytic answer.
    pub error: f64,
    pub value: f64,
    pub analytic: f64,
}

enum Job {
    Patch(Elasticity),
    Cantilever(Elasticity, &'static str),
    Wound(Elasticity, usize),
    Vibration(Elasticity, &'static str, Integrator, f64),
}

fn jobs(quick: bool) -> Vec<Job> {
    let mut jobs = Vec::new();
    for kind in Elasticity::STATIC {
        jobs.push(Job::Patch(kind));
    }
    for kind in Elasticity::STATIC {
        for bar in IPC_BARS {
            jobs.push(Job::Cantilever(kind, bar));
        }
    }
    for kind in Elasticity::STATIC {
        // the quadratic elements need fewer cells, and their PCG on the thin graded sheet
        // converges slowly (8 cells per half length, 12,960 tets: 0.9 % in 138 s)
        let refinements: &[usize] = match (quick, kind) {
            (_, Elasticity::QuadraticFem) => &[2, 4],
            (true, _) => &[4, 8],
            (false, _) => &[4, 8, 16],
        };
        for &m in refinements {
            jobs.push(Job::Wound(kind, m));
        }
    }
    let bars: &[&'static str] = if quick { &IPC_BARS[..2] } else { &IPC_BARS };
    let steppers: &[(Integrator, f64)] = if quick {
        &[
            (Integrator::ImplicitEuler, 1e-4),
            (Integrator::ImplicitEuler, 1e-3),
        ]
    } else {
        &[
            (Integrator::ImplicitEuler, 1e-4),
            (Integrator::ImplicitEuler, 1e-3),
            (Integrator::SymplecticEuler, 1e-4),
        ]
    };
    for kind in Elasticity::ALL {
        for &bar in bars {
            for &(integrator, dt) in steppers {
                jobs.push(Job::Vibration(kind, bar, integrator, dt));
            }
        }
    }
    jobs
}

fn run_job(job: &Job, solid: Solid) -> anyhow::Result<AccuracyRow> {
    let bar = |name: &str| {
        read_bar(&ipc_dir().join(name), IPC_UNIT_M).with_context(|| format!("reading {name}"))
    };
    Ok(match *job {
        Job::Patch(kind) => {
            let cells = GridCells {
                nx: 4,
                ny: 3,
                nz: 3,
            };
            let t = Instant::now();
            let r = reference::patch_test(kind, solid, cells, 1e-3)?;
            let wall_ms = t.elapsed().as_secs_f64() * 1e3;
            AccuracyRow {
                problem: "patch test (axial force)",
                model: kind.name(),
                tets: r.tets,
                solver: "static".into(),
                wall_ms,
                wall_kind: "solve",
                error: r.axial_force_error.max(r.displacement_error),
                value: r.axial_force_error,
                analytic: 0.0,
            }
        }
        Job::Cantilever(kind, name) => {
            let mesh = bar(name)?;
            let t = Instant::now();
            let r = reference::cantilever(mesh, kind, solid)?;
            let wall_ms = t.elapsed().as_secs_f64() * 1e3;
            AccuracyRow {
                problem: "cantilever tip deflection",
                model: kind.name(),
                tets: r.tets,
                solver: "static".into(),
                wall_ms,
                wall_kind: "solve",
                error: r.relative_error,
                value: r.deflection_m,
                analytic: r.analytic_m,
            }
        }
        Job::Wound(kind, m) => {
            let t = Instant::now();
            let r = reference::wound_opening(kind, solid, 0.01, m)?;
            let wall_ms = t.elapsed().as_secs_f64() * 1e3;
            AccuracyRow {
                problem: "wound opening (centre gap)",
                model: kind.name(),
                tets: r.tets,
                solver: "static".into(),
                wall_ms,
                wall_kind: "solve",
                error: r.centre_error,
                value: r.centre_gap_m,
                analytic: r.analytic_centre_gap_m,
            }
        }
        Job::Vibration(kind, name, integrator, dt) => {
            let mesh = bar(name)?;
            let t = Instant::now();
            let r = reference::vibration(mesh, kind, solid, integrator, dt)?;
            let wall_s = t.elapsed().as_secs_f64();
            let simulated_s = r.steps as f64 * dt;
            AccuracyRow {
                problem: "first frequency (fixed-free bar)",
                model: kind.name(),
                tets: r.tets,
                solver: format!("{} {} ms", integrator.name(), dt * 1e3),
                wall_ms: 1e3 * wall_s / simulated_s,
                wall_kind: "per simulated s",
                error: r.relative_error,
                value: r.frequency_hz,
                analytic: r.analytic_hz,
            }
        }
    })
}

/// Runs the benchmark; writes the plot to `out/accuracy.svg` and the CSV to `out/accuracy.csv`.
pub fn run(quick: bool, json: bool, out: &Path) -> anyhow::Result<()> {
    let solid = Solid::CHEST_WALL;
    let jobs = jobs(quick);
    let bar = crate::progress::bar(jobs.len() as u64, json);
    let mut rows = Vec::new();
    for job in &jobs {
        bar.set_message(match job {
            Job::Patch(k) => format!("patch test, {}", k.name()),
            Job::Cantilever(k, b) => format!("cantilever {b}, {}", k.name()),
            Job::Wound(k, m) => format!("wound opening, {m} cells per half length, {}", k.name()),
            Job::Vibration(k, b, i, dt) => {
                format!("vibration {b}, {} {} ms, {}", i.name(), dt * 1e3, k.name())
            }
        });
        rows.push(run_job(job, solid)?);
        bar.inc(1);
    }
    bar.finish_and_clear();
    // the simulation step against its error on a session (what `--time-step-ms` trades)
    let session_tets = if quick { 5_000 } else { 12_800 };
    for (scene, model) in [
        ("chest-wall", "springs"),
        ("chest-wall-fem", Elasticity::CorotationalFem.name()),
    ] {
        if !json {
            eprintln!("press-and-cut session at 1-10 ms steps, {model}...");
        }
        rows.extend(crate::step_size::rows(scene, model, session_tets)?);
    }
    // Richardson extrapolation of the finite elements' cantilever on the two finest bars.
    let fem_bars: Vec<CantileverResult> = IPC_BARS[1..]
        .iter()
        .map(|b| {
            reference::cantilever(
                read_bar(&ipc_dir().join(b), IPC_UNIT_M)?,
                Elasticity::CorotationalFem,
                solid,
            )
        })
        .collect::<Result<_, _>>()?;
    let extrapolated = reference::richardson(&fem_bars[0], &fem_bars[1]);
    let extrapolated_error = (extrapolated - fem_bars[1].analytic_m).abs() / fem_bars[1].analytic_m;

    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let csv_path = out.join("accuracy.csv");
    std::fs::write(&csv_path, csv(&rows))
        .with_context(|| format!("writing {}", csv_path.display()))?;
    let svg_path = out.join("accuracy.svg");
    std::fs::write(&svg_path, svg(&rows))
        .with_context(|| format!("writing {}", svg_path.display()))?;
    if json {
        let doc = serde_json::json!({
            "solid": solid,
            "rows": rows,
            "fem_cantilever_richardson_error": extrapolated_error,
        });
        println!("{}", serde_json::to_string_pretty(&doc)?);
        return Ok(());
    }
    println!(
        "chest-wall solid: E {} kPa, nu {}, rho {} kg/m3; single thread; errors relative to the analytic answer",
        solid.youngs_modulus_pa / 1e3,
        solid.poisson_ratio,
        solid.density_kg_per_m3
    );
    println!("| problem | model | tets | solver | wall ms | error % |");
    println!("|---|---|---:|---|---:|---:|");
    for r in &rows {
        let wall = if r.wall_kind == "solve" {
            format!("{:.1}", r.wall_ms)
        } else {
            format!("{:.0} / sim s", r.wall_ms)
        };
        println!(
            "| {} | {} | {} | {} | {} | {:.2} |",
            r.problem,
            r.model,
            r.tets,
            r.solver,
            wall,
            100.0 * r.error
        );
    }
    let finest_wound = rows
        .iter()
        .filter(|r| r.problem.starts_with("wound") && r.model == Elasticity::CorotationalFem.name())
        .max_by_key(|r| r.tets);
    let finest = |model: Elasticity| {
        rows.iter()
            .filter(|r| r.problem.starts_with("cantilever") && r.model == model.name())
            .max_by_key(|r| r.tets)
    };
    let (finest_bar, finest_quadratic_bar) = (
        finest(Elasticity::CorotationalFem),
        finest(Elasticity::QuadraticFem),
    );
    println!();
    if let Some(w) = finest_wound {
        let verdict = if w.error < 0.05 {
            "reached"
        } else {
            "NOT reached"
        };
        println!(
            "goal, FEM within 5 % of the wound opening ({} tets): {:.1} %, {verdict}",
            w.tets,
            100.0 * w.error
        );
    }
    if let Some(c) = finest_bar {
        let verdict = if c.error < 0.05 {
            "reached"
        } else {
            "NOT reached (linear tetrahedra lock in bending)"
        };
        println!(
            "goal, linear FEM within 5 % of the cantilever at the finest IPC bar ({} tets): {:.1} %, {verdict}",
            c.tets,
            100.0 * c.error
        );
    }
    if let Some(c) = finest_quadratic_bar {
        let verdict = if c.error < 0.05 {
            "reached"
        } else {
            "NOT reached"
        };
        println!(
            "goal, quadratic FEM within 5 % of the cantilever at the finest IPC bar ({} tets): {:.1} %, {verdict}",
            c.tets,
            100.0 * c.error
        );
    }
    println!(
        "FEM cantilever, Richardson extrapolation of the two finest bars: {:.1} % (error ~ h^2)",
        100.0 * extrapolated_error
    );
    println!("wrote {} and {}", csv_path.display(), svg_path.display());
    Ok(())
}

fn csv(rows: &[AccuracyRow]) -> String {
    let mut s = String::from("problem,model,tets,solver,wall_ms,wall_kind,error,value,analytic\n");
    for r in rows {
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{}\n",
            r.problem,
            r.model,
            r.tets,
            r.solver,
            r.wall_ms,
            r.wall_kind,
            r.error,
            r.value,
            r.analytic
        ));
    }
    s
}

/// Log-log plot of error against wall time, one colour per model, one panel per problem,
/// with each problem's Pareto front (no other run is both faster and more accurate).
fn svg(rows: &[AccuracyRow]) -> String {
    let problems: Vec<&str> = {
        let mut p: Vec<&str> = rows
            .iter()
            .map(|r| r.problem)
            .filter(|p| !p.starts_with("patch"))
            .collect();
        p.dedup();
        p
    };
    let colours = [
        ("springs-uniform", "#d62728"),
        ("springs-youngs", "#ff7f0e"),
        ("corotational-fem", "#1f77b4"),
        ("quadratic-fem", "#2ca02c"),
    ];
    let point = |r: &AccuracyRow| plot::Point {
        x: r.wall_ms,
        y: 100.0 * r.error,
        title: format!(
            "{} {} tets {}: {:.2} %",
            r.model,
            r.tets,
            r.solver,
            100.0 * r.error
        ),
    };
    let panels: Vec<plot::Panel> = problems
        .iter()
        .map(|problem| {
            let sel: Vec<&AccuracyRow> = rows.iter().filter(|r| r.problem == *problem).collect();
            let mut series: Vec<plot::Series> = colours
                .iter()
                .map(|(name, colour)| plot::Series {
                    name: (*name).into(),
                    colour,
                    line: plot::Line::None,
                    markers: true,
                    points: sel
                        .iter()
                        .filter(|r| r.model == *name)
                        .map(|r| point(r))
                        .collect(),
                })
                .collect();
            // Pareto front: sorted by time, keep the runs more accurate than every faster one
            let mut by_time: Vec<&AccuracyRow> = sel
                .iter()
                .copied()
                .filter(|r| r.error > 0.0 && r.wall_ms > 0.0)
                .collect();
            by_time.sort_by(|a, b| a.wall_ms.total_cmp(&b.wall_ms));
            let mut best = f64::INFINITY;
            let mut front = Vec::new();
            for r in by_time {
                if r.error < best {
                    best = r.error;
                    front.push(point(r));
                }
            }
            series.insert(
                0,
                plot::Series {
                    name: String::new(),
                    colour: "#999",
                    line: plot::Line::Dashed,
                    markers: false,
                    points: front,
                },
            );
            plot::Panel {
                title: format!(
                    "{problem}: error % (log) against wall ms, {} (log)",
                    sel.first().map_or("", |r| r.wall_kind)
                ),
                y_unit: " %".into(),
                series,
                ..plot::Panel::default()
            }
        })
        .collect();
    plot::log_log(640.0, 220.0, &panels)
}
