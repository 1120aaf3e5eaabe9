//! `cutlab demo`: the default scene, settled, with a scripted scalpel stroke.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use cutlab_sim::Vector3;
use cutlab_sim::cut;
use cutlab_sim::io::PointData;
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::StaticSettings;
use cutlab_sim::stats::Summary;

pub fn run(out: &Path, min_tets: Option<usize>, scene_name: &str) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let scene = Scene::load(scene_name, BuildOptions { min_tets })
        .with_context(|| format!("building the {scene_name} scene"))?;
    let m = &scene.model;
    let model_name = if m.fem.is_some() {
        "co-rotational finite elements"
    } else {
        "springs"
    };
    println!(
        "scene {scene_name} ({model_name}): {} tets, {} particles ({} held), {} springs, mass {:.1} g, built in {:.0} ms",
        m.mesh.tet_count(),
        m.vertex_count(),
        m.held_count(),
        m.springs.len(),
        m.total_mass() * 1e3,
        t0.elapsed().as_secs_f64() * 1e3
    );

    let mut sim = scene.simulation();
    let t1 = Instant::now();
    let settle = sim.settle(StaticSettings::default());
    anyhow::ensure!(settle.converged, "settling did not converge: {settle:?}");
    let settled = sim.state.positions.clone();
    let moved_mm = settled
        .iter()
        .zip(m.mesh.positions())
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max)
        * 1e3;
    let pretension_percent = 100.0
        * scene
            .spec
            .materials
            .first()
            .map(|m| m.pretension)
            .unwrap_or(0.0);
    println!(
        "settled under {pretension_percent:.0} % pre-tension in {:.0} ms ({} Newton iterations, residual {:.1e} N); the tissue drew in by up to {:.3} mm",
        t1.elapsed().as_secs_f64() * 1e3,
        settle.newton_iterations,
        settle.residual_newtons,
        moved_mm
    );

    incise(&mut sim)?;
    wound(&mut sim, pretension_percent)?;
    write_final(out, &sim)
}

/// The incision: 60 mm across the top of the wall in 1.5 s, the blade 8 mm deep and normal
/// to the surface, cutting at every 1 ms step; then 0.5 s for the wound to open.
fn incise(sim: &mut cutlab_sim::solver::Simulation) -> anyhow::Result<()> {
    let blade_at = |x: f64| cut::Blade::normal_to_curved_slab(x, 0.0003, 0.15, 0.008, 0.005);
    let dt = sim.settings.time_step_s;
    let stroke_steps = 1500;
    let mut cutter = cut::Cutter::default();
    let mut cut_us = Vec::with_capacity(stroke_steps);
    let mut step_us = Vec::new();
    let (mut created, mut split, mut moved, mut removed, mut added, mut skipped) =
        (0, 0, 0, 0, 0, 0);
    let tets_before = sim.model.mesh.tet_count();
    for k in 0..stroke_steps + 500 {
        if k <= stroke_steps {
            let x = -0.03 + 0.06 * k as f64 / stroke_steps as f64;
            let tc = Instant::now();
            let ev = match cutter.advance(sim, blade_at(x)) {
                Ok(ev) => ev,
                Err(cut::CutError::Unresolved(_)) => {
                    skipped += 1;
                    cut_us.push(tc.elapsed().as_secs_f64() * 1e6);
                    continue_sim(sim, &mut step_us)?;
                    continue;
                }
                Err(e) => return Err(e).context("cutting"),
            };
            cut_us.push(tc.elapsed().as_secs_f64() * 1e6);
            created += ev.vertices_created.len();
            split += ev.vertices_split.len();
            moved += ev.vertices_moved.len();
            removed += ev.tets_removed.len();
            added += ev.tets_added.len();
        }
        continue_sim(sim, &mut step_us)?;
    }
    let c = Summary::of(&cut_us);
    let s = Summary::of(&step_us);
    println!(
        "incision: 60 mm, 8 mm deep, in {} steps of {} ms ({}), then 0.5 s to open",
        stroke_steps,
        dt * 1e3,
        sim.settings.integrator.name()
    );
    println!(
        "  topology: {removed} tets split into {added}; {created} vertices created on cut edges, {split} split, {moved} moved onto the cut; {} -> {} tets",
        tets_before,
        sim.model.mesh.tet_count()
    );
    println!(
        "  cut latency per step: median {:.0} us, p99 {:.0} us, max {:.0} us; {skipped} steps skipped (unresolved); sim step: median {:.0} us, p99 {:.0} us",
        c.median, c.p99, c.max, s.median, s.p99
    );

    Ok(())
}

/// The wound at rest: the gap between the two copies of each split vertex, along the cut.
fn wound(sim: &mut cutlab_sim::solver::Simulation, pretension_percent: f64) -> anyhow::Result<()> {
    let settle = sim.settle(StaticSettings::default());
    anyhow::ensure!(
        settle.converged,
        "settling after the cut did not converge: {settle:?}"
    );
    let gaps: Vec<(f64, f64)> = cut::wound_gaps(sim)
        .into_iter()
        .map(|(p, gap)| (p.x, gap))
        .collect();
    println!(
        "  wound opening under {pretension_percent:.0} % tension (gap across the cut at rest, by position along it):"
    );
    let mut line = String::from("   ");
    for i in -6..=6 {
        let x0 = i as f64 * 0.005;
        let g = gaps
            .iter()
            .filter(|(x, _)| (x - x0).abs() <= 0.0025)
            .map(|p| p.1)
            .fold(0.0, f64::max);
        line.push_str(&format!(" {:+.0}mm:{:.2}", x0 * 1e3, g * 1e3));
    }
    println!("{line} (mm)");
    println!(
        "  widest gap {:.2} mm",
        gaps.iter().map(|p| p.1).fold(0.0, f64::max) * 1e3
    );
    let (xlo, xhi) = gaps
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.0), b.max(p.0))
        });
    println!(
        "  the cut spans x = {:.1} .. {:.1} mm (the blade went from -30 to +30 mm)",
        xlo * 1e3,
        xhi * 1e3
    );
    Ok(())
}

/// Writes the deformed mesh and its displacement to `out/final.vtu`.
fn write_final(out: &Path, sim: &cutlab_sim::solver::Simulation) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let deformed = cutlab_sim::TetMesh::new(
        sim.state.positions.clone(),
        sim.model.mesh.tets().to_vec(),
        sim.model.mesh.regions().to_vec(),
    )?;
    let displacement: Vec<Vector3> = sim
        .state
        .positions
        .iter()
        .zip(sim.model.mesh.positions())
        .map(|(p, q)| p - q)
        .collect();
    let path = out.join("final.vtu");
    cutlab_sim::io::write_vtu(
        &path,
        &deformed,
        &[("displacement", PointData::Vector(&displacement))],
    )
    .with_context(|| format!("writing {}", path.display()))?;
    println!("wrote {} (open it in ParaView)", path.display());
    Ok(())
}

/// One timed simulation step.
fn continue_sim(
    sim: &mut cutlab_sim::solver::Simulation,
    step_us: &mut Vec<f64>,
) -> anyhow::Result<()> {
    let ts = Instant::now();
    sim.step().context("simulation step")?;
    step_us.push(ts.elapsed().as_secs_f64() * 1e6);
    Ok(())
}
