//! `cutlab bench`: figures of speed, printed (not asserted).

use std::time::{Duration, Instant};

use anyhow::Context;
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::{Integrator, StaticSettings};
use cutlab_sim::stats::Summary;
use cutlab_sim::{Point3, Vector3};
use serde::Serialize;

use crate::stroke::Stroke;

#[derive(Debug, Serialize)]
struct StepRow {
    /// `springs` or `corotational-fem`.
    model: &'static str,
    requested_tets: usize,
    tets: usize,
    particles: usize,
    integrator: &'static str,
    settle_ms: f64,
    substeps: u32,
    steps: usize,
    step_us: Summary,
    cg_iterations_mean: f64,
    /// Simulated time per wall time at the median step.
    realtime_factor: f64,
}

/// Step time per integrator on the chest wall, while a stroke presses on it: the paper's
/// springs with both integrators, and the finite elements (`chest-wall-fem`) with implicit
/// Euler (symplectic Euler would need thousands of sub-steps with their
/// stiffness-proportional damping). `only_tets` (when not empty) and
/// `only_integrator` narrow the set, e.g. to profile one size.
pub fn step(
    quick: bool,
    json: bool,
    only_tets: &[usize],
    only_integrator: Option<Integrator>,
) -> anyhow::Result<()> {
    let default_sizes: &[usize] = if quick {
        &[1_000, 10_000]
    } else {
        &[1_000, 10_000, 100_000]
    };
    let sizes = if only_tets.is_empty() {
        default_sizes
    } else {
        only_tets
    };
    let mut runs: Vec<(&str, usize, Integrator)> = Vec::new();
    for &n in sizes {
        for integrator in Integrator::ALL
            .into_iter()
            .filter(|i| only_integrator.is_none_or(|o| o == *i))
        {
            runs.push(("chest-wall", n, integrator));
        }
        if only_integrator.is_none_or(|o| o == Integrator::ImplicitEuler) {
            runs.push(("chest-wall-fem", n, Integrator::ImplicitEuler));
        }
    }
    let budget = if quick {
        Duration::from_secs(2)
    } else {
        Duration::from_secs(10)
    };
    let max_steps = if quick { 500 } else { 2_000 };
    let bar = crate::progress::bar(runs.len() as u64, json);
    let mut rows = Vec::new();
    for &(name, n, integrator) in &runs {
        let scene = Scene::load(name, BuildOptions { min_tets: Some(n) }).context(name)?;
        bar.set_message(format!(
            "{} tets, {}",
            scene.model.mesh.tet_count(),
            integrator.name()
        ));
        let mut sim = scene.simulation();
        sim.edit(|_, settings| settings.integrator = integrator);
        let t = Instant::now();
        let settle = sim.settle(StaticSettings::default());
        let settle_ms = t.elapsed().as_secs_f64() * 1e3;
        anyhow::ensure!(
            settle.converged,
            "settling {n} tets did not converge: {settle:?}"
        );
        let z = sim
            .state
            .positions
            .iter()
            .map(|p| p.z)
            .fold(f64::NEG_INFINITY, f64::max);
        let mut stroke = Stroke::new(
            &sim,
            Point3::new(-0.03, 0.0, z),
            Point3::new(0.03, 0.0, z),
            -Vector3::z(),
            1.5,
            0.3,
        );
        let dt = sim.settings.time_step_s;
        let mut times = Vec::new();
        let mut cg = 0;
        let started = Instant::now();
        while times.len() < max_steps && (times.len() < 20 || started.elapsed() < budget) {
            stroke.apply(&mut sim, times.len() as f64 * dt);
            let ts = Instant::now();
            let r = sim.step().context("step")?;
            times.push(ts.elapsed().as_secs_f64() * 1e6);
            cg += r.cg_iterations;
        }
        let s = Summary::of(&times);
        rows.push(StepRow {
            model: if scene.model.fem.is_some() {
                "corotational-fem"
            } else {
                "springs"
            },
            requested_tets: n,
            tets: scene.model.mesh.tet_count(),
            particles: scene.model.vertex_count(),
            integrator: integrator.name(),
            settle_ms,
            substeps: match integrator {
                Integrator::SymplecticEuler => sim.explicit_substeps(),
                Integrator::ImplicitEuler => 1,
            },
            steps: times.len(),
            cg_iterations_mean: cg as f64 / times.len() as f64,
            realtime_factor: dt * 1e6 / s.median,
            step_us: s,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    // the cut-heavy strokes, unless the run is narrowed to one size or integrator
    let strokes = if only_tets.is_empty() && only_integrator.is_none() {
        crate::cuts::strokes()?
    } else {
        Vec::new()
    };
    if json {
        let both = serde_json::json!({ "steps": rows, "strokes": strokes });
        println!("{}", serde_json::to_string_pretty(&both)?);
        return Ok(());
    }
    println!(
        "chest-wall, 1 ms steps while a 0.3 N stroke presses along the wall; {}",
        crate::perf::threads_text(cutlab_sim::solver::solver_threads())
    );
    println!(
        "| model | tets | particles | integrator | substeps | CG it. | median us | p99 us | x real time | settle ms |"
    );
    println!("|---|---:|---:|---|---:|---:|---:|---:|---:|---:|");
    for r in &rows {
        println!(
            "| {} | {} | {} | {} | {} | {:.1} | {:.0} | {:.0} | {:.2} | {:.0} |",
            r.model,
            r.tets,
            r.particles,
            r.integrator,
            r.substeps,
            r.cg_iterations_mean,
            r.step_us.median,
            r.step_us.p99,
            r.realtime_factor,
            r.settle_ms
        );
    }
    if !strokes.is_empty() {
        crate::cuts::print(&strokes);
    }
    Ok(())
}
