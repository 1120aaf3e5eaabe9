//! cutlab's side: implicit Euler steps under the press, one cut along the quad, the
//! cantilever by `cutlab_sim::reference` (Newton statics).

use std::time::Instant;

use anyhow::Context;
use cutlab_sim::Vector3;
use cutlab_sim::cut::{self, CutOptions, CutPolygon};
use cutlab_sim::model::Model;
use cutlab_sim::reference::{self, Elasticity, Solid};
use cutlab_sim::solver::{Simulation, SolverSettings, StaticSettings};
use cutlab_sim::stats::Summary;

use crate::cases::{Case, bar_mesh};

/// Step times of one run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct StepRun {
    pub step_us: Summary,
    pub cg_iterations_mean: f64,
}

/// A simulation of `model` at the scenes' settings (implicit Euler, 1 ms, CG to 1e-4),
/// settled when `settle`.
fn simulation(model: &Model, settle: bool) -> anyhow::Result<Simulation> {
    let mut sim = Simulation::new(model.clone(), SolverSettings::default());
    if settle {
        let report = sim.settle(StaticSettings::default());
        anyhow::ensure!(report.converged, "settling did not converge: {report:?}");
    }
    Ok(sim)
}

/// `steps` timed steps of `model` while the case's press slides along it.
pub fn steps(case: &Case, model: &Model, steps: usize) -> anyhow::Result<StepRun> {
    let mut sim = simulation(model, case.settle)?;
    let dt = sim.settings.time_step_s;
    let mut forces: Vec<(u32, Vector3)> = Vec::new();
    let mut times_us = Vec::with_capacity(steps);
    let mut cg = 0;
    for i in 0..steps {
        case.press.forces(
            i as f64 * dt,
            |v| sim.state.positions[v as usize],
            &mut forces,
        );
        sim.clear_external_forces();
        let external = sim.external_forces_mut();
        forces.iter().for_each(|&(v, f)| external[v as usize] = f);
        let t = Instant::now();
        let report = sim.step().context("cutlab step")?;
        times_us.push(t.elapsed().as_secs_f64() * 1e6);
        cg += report.cg_iterations;
    }
    Ok(StepRun {
        step_us: Summary::of(&times_us),
        cg_iterations_mean: cg as f64 / steps.max(1) as f64,
    })
}

/// Times of one cut along the case's quad.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CutRun {
    pub cut_ms: Summary,
    pub tets_before: usize,
    pub tets_after: usize,
    pub vertices_before: usize,
    pub vertices_after: usize,
}

/// `repeats` times the same cut (`cut::cut` along the quad, the model rebuilt) on copies of
/// the (settled) simulation.
pub fn cut(case: &Case, model: &Model, repeats: usize) -> anyhow::Result<CutRun> {
    let base = simulation(model, case.settle)?;
    let polygon = CutPolygon::new(&case.cut_quad).context("cut quad spans no area")?;
    let mut times_ms = Vec::with_capacity(repeats);
    let mut after = (0, 0);
    for _ in 0..repeats {
        let mut sim = base.clone();
        let t = Instant::now();
        cut::cut(&mut sim, &polygon, &CutOptions::default()).context("cutlab cut")?;
        times_ms.push(t.elapsed().as_secs_f64() * 1e3);
        after = (sim.model.mesh.tet_count(), sim.model.vertex_count());
    }
    Ok(CutRun {
        cut_ms: Summary::of(&times_ms),
        tets_before: base.model.mesh.tet_count(),
        tets_after: after.0,
        vertices_before: base.model.vertex_count(),
        vertices_after: after.1,
    })
}

/// The cantilever on bar-2523 by `reference::cantilever`: relative error and solve time.
pub fn cantilever(
    kind: Elasticity,
    solid: Solid,
) -> anyhow::Result<(reference::CantileverResult, f64)> {
    let mesh = bar_mesh()?;
    let t = Instant::now();
    let result = reference::cantilever(mesh, kind, solid).context("cutlab cantilever")?;
    Ok((result, t.elapsed().as_secs_f64() * 1e3))
}
