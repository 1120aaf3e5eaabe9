//! `cutlab bench step`'s cut-heavy strokes: a closed circle cut through the sheet, a
//! semicircle and a zig-zag on the chest wall (`cutlab_sim::cut_stress`), at each scene's own
//! step, a cut every 0.5 mm at 10 mm/s as a session cuts; the time of every step and cut, and
//! the simulated time over the wall time of both.

use std::time::Instant;

use anyhow::Context;
use cutlab_sim::cut::Cutter;
use cutlab_sim::cut_stress::{StrokeShape, Tissue};
use cutlab_sim::mesh::pieces;
use cutlab_sim::stats::Summary;
use serde::Serialize;

/// Blade speed along the stroke, m/s.
const SPEED_M_PER_S: f64 = 0.01;
/// Blade travel between cuts, m (as a session's `cut_step_m`).
const CUT_STEP_M: f64 = 0.0005;

/// One stroke's figures.
#[derive(Debug, Serialize)]
pub struct StrokeRow {
    tissue: Tissue,
    shape: StrokeShape,
    tets_before: usize,
    tets_after: usize,
    steps: usize,
    step_us: Summary,
    cut_ms: Summary,
    cg_iterations_mean: f64,
    /// Simulated time over the wall time of the steps and cuts.
    realtime_factor: f64,
    pieces: usize,
    specimens: usize,
    fragments_reattached: usize,
}

/// Runs the three strokes (whole, quick or not: the circle frees its disc at its end).
pub fn strokes() -> anyhow::Result<Vec<StrokeRow>> {
    let cases = [
        (Tissue::Sheet, StrokeShape::Circle, 0.004),
        (Tissue::ChestWall, StrokeShape::Semicircle, 0.006),
        (Tissue::ChestWall, StrokeShape::ZigZag, 0.006),
    ];
    let mut rows = Vec::new();
    for (tissue, shape, depth_m) in cases {
        let mut sim = tissue.simulation(None).context(tissue.scene())?;
        let dt = sim.settings.time_step_s;
        let steps_per_cut = ((CUT_STEP_M / SPEED_M_PER_S) / dt).round().max(1.0) as usize;
        let path = shape.path(CUT_STEP_M);
        let tets_before = sim.model.mesh.tet_count();
        let mut cutter = Cutter::default();
        let (mut step_us, mut cut_ms) = (Vec::new(), Vec::new());
        let (mut cg, mut specimens, mut reattached) = (0, 0, 0);
        for &p in &path {
            let t = Instant::now();
            let event = cutter
                .advance(&mut sim, tissue.blade(p, depth_m))
                .with_context(|| format!("cut at {p:?}"))?;
            cut_ms.push(t.elapsed().as_secs_f64() * 1e3);
            specimens += event.specimens.len();
            reattached += event.fragments_reattached;
            for _ in 0..steps_per_cut {
                let t = Instant::now();
                cg += sim.step().context("step")?.cg_iterations;
                step_us.push(t.elapsed().as_secs_f64() * 1e6);
            }
        }
        let wall_s = (step_us.iter().sum::<f64>() * 1e-6) + cut_ms.iter().sum::<f64>() * 1e-3;
        rows.push(StrokeRow {
            tissue,
            shape,
            tets_before,
            tets_after: sim.model.mesh.tet_count(),
            steps: step_us.len(),
            cg_iterations_mean: cg as f64 / step_us.len().max(1) as f64,
            realtime_factor: step_us.len() as f64 * dt / wall_s,
            step_us: Summary::of(&step_us),
            cut_ms: Summary::of(&cut_ms),
            pieces: pieces(&sim.model.mesh, &sim.model.held).len(),
            specimens,
            fragments_reattached: reattached,
        });
    }
    Ok(rows)
}

/// The strokes' table.
pub fn print(rows: &[StrokeRow]) {
    println!();
    println!(
        "cut-heavy strokes at the scene's 1 ms step, a cut every 0.5 mm at 10 mm/s (50 steps apart):"
    );
    println!(
        "| tissue | stroke | tets before | after | step median us | p99 us | CG it. | cut median ms | p99 ms | max ms | x real time | pieces | specimens | fragments reattached |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in rows {
        println!(
            "| {} | {:?} | {} | {} | {:.0} | {:.0} | {:.1} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} | {} |",
            r.tissue.scene(),
            r.shape,
            r.tets_before,
            r.tets_after,
            r.step_us.median,
            r.step_us.p99,
            r.cg_iterations_mean,
            r.cut_ms.median,
            r.cut_ms.p99,
            r.cut_ms.max,
            r.realtime_factor,
            r.pieces,
            r.specimens,
            r.fragments_reattached
        );
    }
}
