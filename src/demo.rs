//! `cutlab demo`: the default scene, settled, with a scripted scalpel stroke.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::StaticSettings;
use cutlab_sim::Point3;

use crate::stats::Summary;
use crate::stroke::Stroke;

pub fn run(out: &Path, min_tets: Option<usize>) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let scene = Scene::load("chest-wall", BuildOptions { min_tets }).context("building the chest-wall scene")?;
    let m = &scene.model;
    println!("scene chest-wall: {} tets, {} particles ({} held), {} springs, mass {:.1} g, built in {:.0} ms",
        m.mesh.tet_count(), m.vertex_count(), m.held_count(), m.springs.len(), m.total_mass() * 1e3,
        t0.elapsed().as_secs_f64() * 1e3);

    let mut sim = scene.simulation();
    let t1 = Instant::now();
    let settle = sim.settle(StaticSettings::default());
    anyhow::ensure!(settle.converged, "settling did not converge: {settle:?}");
    let settled = sim.state.positions.clone();
    let moved_mm = settled.iter().zip(m.mesh.positions()).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max) * 1e3;
    println!("settled under {:.0} % pre-tension in {:.0} ms ({} Newton iterations, residual {:.1e} N); the tissue drew in by up to {:.3} mm",
        m.springs.rest_length.first().zip(m.springs.ends.first()).map(|(l, [a, b])| {
            100.0 * (1.0 - l / (m.mesh.positions()[*b as usize] - m.mesh.positions()[*a as usize]).norm())
        }).unwrap_or(0.0),
        t1.elapsed().as_secs_f64() * 1e3, settle.newton_iterations, settle.residual_newtons, moved_mm);

    // The stroke: 60 mm across the top of the wall in 1.5 s, pressing with 0.3 N.
    let apex_z = settled.iter().map(|p| p.z).fold(f64::NEG_INFINITY, f64::max);
    let mut stroke = Stroke::new(&sim, Point3::new(-0.03, 0.0, apex_z), Point3::new(0.03, 0.0, apex_z), 1.5, 0.3);
    let dt = sim.settings.time_step_s;
    let steps = ((stroke.duration_s + 0.5) / dt).round() as usize;
    let mut step_us = Vec::with_capacity(steps);
    let mut max_indent_mm = 0.0f64;
    let mut cg = 0usize;
    for k in 0..steps {
        let t = k as f64 * dt;
        stroke.apply(&mut sim, t);
        let ts = Instant::now();
        let r = sim.step().context("simulation step")?;
        step_us.push(ts.elapsed().as_secs_f64() * 1e6);
        cg += r.cg_iterations;
        if t <= stroke.duration_s {
            let indent = settled.iter().zip(&sim.state.positions).map(|(a, b)| a.z - b.z).fold(0.0, f64::max);
            max_indent_mm = max_indent_mm.max(indent * 1e3);
        }
    }
    let residual_mm = settled.iter().zip(&sim.state.positions).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max) * 1e3;
    let s = Summary::of(&step_us);
    println!("stroke: 60 mm along the wall in {:.1} s pressing 0.3 N, then 0.5 s released; {} steps of {} ms ({})",
        stroke.duration_s, steps, dt * 1e3, sim.settings.integrator.name());
    println!("  deepest indentation {max_indent_mm:.3} mm; {residual_mm:.4} mm from the settled shape 0.5 s after release; max speed now {:.2e} m/s",
        sim.state.max_speed());
    println!("  step wall time: median {:.0} us, p99 {:.0} us, max {:.0} us; {:.1} CG iterations per step",
        s.median, s.p99, s.max, cg as f64 / steps as f64);
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    Ok(())
}
