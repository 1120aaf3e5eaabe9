//! `cutlab bench skip`: what the work a session leaves out would cost if it were done, measured
//! on the settled chest wall at 10k and 100k tets (single thread):
//!
//! - the surface BVH: built again from the mesh's boundary (what a cut that changes the surface
//!   does), refitted after every surface particle moved (what a step does), and the refit
//!   skipped because no surface particle moved (the sleeping surface of a localised run);
//! - the surface extracted again: the whole topology built from the tetrahedra, which the
//!   boundary comes from (no step does it; a cut carries the topology over instead);
//! - a step with the tool resting on the tissue and nothing else going on: the full step, and
//!   the localised one, which runs over the awake particles only;
//! - rerun logging, which a session does only when asked (`--rrd`, `--rerun`): one surface
//!   snapshot handed to the rerun sink (a `.rrd` file), and the whole cost per snapshot once
//!   the file is flushed.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use cutlab_haptics::SimRecord;
use cutlab_haptics::collision::SurfaceCollider;
use cutlab_haptics::tap::SurfaceSnapshot;
use cutlab_recorder::{RerunSink, RerunTarget};
use cutlab_sim::mesh::Topology;
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::{LocalisationSettings, Simulation, StaticSettings};
use cutlab_sim::stats::Summary;
use cutlab_sim::{Point3, Vector3};
use serde::Serialize;

#[derive(Debug, Serialize)]
struct SkipRow {
    tets: usize,
    particles: usize,
    surface_triangles: usize,
    /// `SurfaceCollider::rebuild`, ms.
    bvh_rebuild_ms: Summary,
    /// `SurfaceCollider::refit` after every surface particle moved, ms.
    bvh_refit_ms: Summary,
    /// `SurfaceCollider::refit` with the surface where it was (nothing to do), ms.
    bvh_refit_still_ms: Summary,
    /// `Topology::build` over the whole mesh, ms.
    surface_extract_ms: Summary,
    /// A full step with the tool resting on the surface, ms.
    step_full_ms: Summary,
    /// The localised step in the same state, ms, and its awake particles (mean).
    step_localised_ms: Summary,
    localised_awake: f64,
    /// `RerunSink::on_sim` with a surface snapshot, ms on the calling thread ...
    rerun_snapshot_call_ms: Summary,
    /// ... and the wall time per snapshot including the flush to the file, ms.
    rerun_snapshot_total_ms: f64,
}

/// Times `f` `count` times, ms.
fn time_ms(count: usize, mut f: impl FnMut()) -> Summary {
    let samples: Vec<f64> = (0..count)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    Summary::of(&samples)
}

/// Steps `sim` `count` times with the tool resting on the surface at `tip` (the focus, no force).
fn resting_steps(
    sim: &mut Simulation,
    tip: Point3,
    count: usize,
) -> anyhow::Result<(Summary, f64)> {
    sim.set_focus(&[tip]);
    let (mut samples, mut awake) = (Vec::with_capacity(count), 0usize);
    for _ in 0..count {
        let t = Instant::now();
        let report = sim.step().context("step")?;
        samples.push(t.elapsed().as_secs_f64() * 1e3);
        awake += report.awake_particles;
    }
    Ok((Summary::of(&samples), awake as f64 / count as f64))
}

fn measure(min_tets: usize, quick: bool, out: &Path) -> anyhow::Result<SkipRow> {
    let scene = Scene::load(
        "chest-wall",
        BuildOptions {
            min_tets: Some(min_tets),
        },
    )
    .context("chest-wall")?;
    let mut sim = scene.simulation();
    let settle = sim.settle(StaticSettings::default());
    anyhow::ensure!(
        settle.converged,
        "settling {min_tets} tets did not converge: {settle:?}"
    );
    let repeats = if quick { 5 } else { 20 };

    let mut collider = SurfaceCollider::build(&sim)?;
    let bvh_rebuild_ms = time_ms(repeats, || {
        if let Err(e) = collider.rebuild(&sim) {
            tracing::error!("rebuilding the surface BVH: {e}");
        }
    });
    // every surface particle moves by a micrometre, back and forth
    let mut moved = sim.state.positions.clone();
    let mut sign = 1.0;
    let bvh_refit_ms = time_ms(repeats * 10, || {
        for &v in collider.vertex_ids() {
            moved[v as usize].z += sign * 1e-6;
        }
        sign = -sign;
        collider.refit(&moved);
    });
    let bvh_refit_still_ms = time_ms(repeats * 10, || {
        collider.refit(&moved);
    });
    let mesh = &sim.model.mesh;
    let surface_extract_ms = time_ms(repeats, || {
        std::hint::black_box(Topology::build(mesh.vertex_count(), mesh.tets()));
    });

    // the tool resting on the top of the wall, at its middle
    let tip = sim
        .state
        .positions
        .iter()
        .copied()
        .max_by(|a, b| a.z.total_cmp(&b.z))
        .context("no particles")?;
    let steps = if quick { 100 } else { 300 };
    let mut full = sim.clone();
    let (step_full_ms, _) = resting_steps(&mut full, tip, steps)?;
    let mut local = sim.clone();
    local.settings.localisation = Some(LocalisationSettings::default());
    // a localised run starts with every particle awake: the first steps let the far ones sleep
    resting_steps(&mut local, tip, 100)?;
    let (step_localised_ms, localised_awake) = resting_steps(&mut local, tip, steps)?;

    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let rrd = out.join(format!("surface-{}.rrd", mesh.tet_count()));
    let mut sink = RerunSink::new(
        &RerunTarget::File(rrd.clone()),
        "cutlab-bench-skip",
        1_000_000,
        0.01,
    )
    .with_context(|| format!("opening {}", rrd.display()))?;
    let snapshots = if quick { 20 } else { 100 };
    let started = Instant::now();
    let mut step = 0u64;
    let rerun_snapshot_call_ms = time_ms(snapshots, || {
        step += 100;
        for p in &mut moved {
            *p += Vector3::z() * 1e-6;
        }
        let record =
            SimRecord::Surface(Box::new(SurfaceSnapshot::of(&collider, &moved, step, step)));
        if let Err(e) = sink.on_sim(&record) {
            tracing::error!("logging a surface to rerun: {e}");
        }
    });
    sink.finish().context("finishing the rerun file")?;
    let rerun_snapshot_total_ms = started.elapsed().as_secs_f64() * 1e3 / snapshots as f64;

    Ok(SkipRow {
        tets: mesh.tet_count(),
        particles: mesh.vertex_count(),
        surface_triangles: collider.triangle_count(),
        bvh_rebuild_ms,
        bvh_refit_ms,
        bvh_refit_still_ms,
        surface_extract_ms,
        step_full_ms,
        step_localised_ms,
        localised_awake,
        rerun_snapshot_call_ms,
        rerun_snapshot_total_ms,
    })
}

pub fn run(quick: bool, json: bool, out: &Path) -> anyhow::Result<()> {
    let sizes: &[usize] = if quick { &[10_000] } else { &[10_000, 100_000] };
    let bar = crate::progress::bar(sizes.len() as u64, json);
    let mut rows = Vec::new();
    for &n in sizes {
        bar.set_message(format!("chest-wall, {n} tets"));
        rows.push(measure(n, quick, out)?);
        bar.inc(1);
    }
    bar.finish_and_clear();
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!(
        "What the work a session skips would cost, chest wall settled, single thread, medians in ms"
    );
    println!(
        "| tets | particles | surface triangles | BVH built again | BVH refitted | refit skipped (surface still) | surface extracted again | step, tool resting: full | localised (awake) | rerun: surface snapshot, call / with the file written |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in &rows {
        println!(
            "| {} | {} | {} | {:.2} | {:.3} | {:.3} | {:.2} | {:.2} | {:.3} ({:.0}) | {:.3} / {:.2} |",
            r.tets,
            r.particles,
            r.surface_triangles,
            r.bvh_rebuild_ms.median,
            r.bvh_refit_ms.median,
            r.bvh_refit_still_ms.median,
            r.surface_extract_ms.median,
            r.step_full_ms.median,
            r.step_localised_ms.median,
            r.localised_awake,
            r.rerun_snapshot_call_ms.median,
            r.rerun_snapshot_total_ms,
        );
    }
    Ok(())
}
