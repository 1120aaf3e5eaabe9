//! Times the cutter alone on the chest wall at one size: a blade 3 mm deep slides along the
//! top (x from -20 to +20 mm, a cut every 0.5 mm, `STEPS_BETWEEN` implicit steps between
//! cuts): `cargo run --release -p cutlab-sim --example cut_time -- [TETS] [STEPS_BETWEEN]`
//! (with `LOCALISED=1` in the environment, the localised step with its default thresholds).
//! Prints the median, p99 and max time of the cuts that changed the tissue and of those that
//! did not, of the steps right after a changing cut and of the others, the tets split, and a
//! hash of the final mesh and positions (FNV-1a, to see whether a change to the cutter changed
//! its results).

use std::time::Instant;

use cutlab_sim::cut::{Blade, Cutter};
use cutlab_sim::hash::Fnv1a;
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::StaticSettings;
use cutlab_sim::stats::Summary;
use cutlab_sim::{Point3, Vector3};

fn summary(v: &[f64]) -> String {
    if v.is_empty() {
        return "none".into();
    }
    let s = Summary::of(v);
    format!(
        "{} cuts, median {:.0} us, p99 {:.0} us, max {:.0} us",
        s.count, s.median, s.p99, s.max
    )
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let tets: usize = args
        .next()
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(100_000);
    let between: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(3);
    let scene = Scene::load(
        "chest-wall",
        BuildOptions {
            min_tets: Some(tets),
        },
    )?;
    let mut sim = scene.simulation();
    let settle = sim.settle(StaticSettings::default());
    assert!(settle.converged, "{settle:?}");
    let x = &sim.state.positions;
    let top = |tool_x: f64| {
        x.iter()
            .filter(|p| (p.x - tool_x).abs() < 0.002 && p.y.abs() < 0.002)
            .map(|p| p.z)
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let (z0, z1) = (top(-0.02), top(0.02));
    if std::env::var_os("LOCALISED").is_some() {
        sim.settings.localisation = Some(cutlab_sim::solver::LocalisationSettings::default());
    }
    let mut cutter = Cutter::default();
    let (mut changed, mut idle) = (Vec::new(), Vec::new());
    let (mut step_after_cut, mut step_other) = (Vec::new(), Vec::new());
    let (mut cg_after_cut, mut cg_other) = (0usize, 0usize);
    let mut split = 0;
    for k in 0..=80 {
        let tx = -0.02 + 0.0005 * k as f64;
        let z = z0 + (z1 - z0) * (k as f64 / 80.0) - 0.003;
        let blade = Blade {
            tip: Point3::new(tx, 0.0, z),
            edge_direction: Vector3::z(),
            depth_m: 0.008,
        };
        let t = Instant::now();
        let event = cutter.advance(&mut sim, blade)?;
        let us = t.elapsed().as_secs_f64() * 1e6;
        if event.is_empty() {
            idle.push(us);
        } else {
            split += event.tets_removed.len();
            changed.push(us);
        }
        for j in 0..between {
            let t = Instant::now();
            let report = sim.step()?;
            let us = t.elapsed().as_secs_f64() * 1e6;
            if j == 0 && !event.is_empty() {
                step_after_cut.push(us);
                cg_after_cut += report.cg_iterations;
            } else {
                step_other.push(us);
                cg_other += report.cg_iterations;
            }
        }
    }
    let mut hash = Fnv1a::default();
    for p in &sim.state.positions {
        [p.x, p.y, p.z].into_iter().for_each(|c| hash.f64(c));
    }
    sim.model
        .mesh
        .tets()
        .iter()
        .flatten()
        .for_each(|&v| hash.u32(v));
    let hash = hash.finish();
    println!(
        "{} tets before, {} after, {split} tets split",
        tets,
        sim.model.mesh.tet_count()
    );
    println!("changing: {}", summary(&changed));
    println!("idle:     {}", summary(&idle));
    let mean = |sum: usize, of: &[f64]| sum as f64 / of.len().max(1) as f64;
    let cg = (
        mean(cg_after_cut, &step_after_cut),
        mean(cg_other, &step_other),
    );
    println!(
        "steps right after a changing cut: {}, {:.1} CG it.",
        summary(&step_after_cut).replace("cuts", "steps"),
        cg.0
    );
    println!(
        "other steps: {}, {:.1} CG it.",
        summary(&step_other).replace("cuts", "steps"),
        cg.1
    );
    println!("hash {hash:016x}");
    Ok(())
}
