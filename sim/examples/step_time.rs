//! Times the implicit step of the chest wall at one size while a 0.3 N press slides along its
//! top (the solver's hot path alone, without the CLI's benchmarks around it):
//! `cargo run --release -p cutlab-sim --example step_time -- [TETS] [STEPS]`.
//! Prints the median and p99 step time, the mean CG iterations and a hash of the final
//! positions (FNV-1a, to see whether a change to the solver changed its results).

use std::time::Instant;

use cutlab_sim::Vector3;
use cutlab_sim::hash::Fnv1a;
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::StaticSettings;
use cutlab_sim::stats::percentile;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let tets: usize = args
        .next()
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(100_000);
    let steps: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(400);
    let scene = Scene::load(
        "chest-wall",
        BuildOptions {
            min_tets: Some(tets),
        },
    )?;
    let mut sim = scene.simulation();
    let settle = sim.settle(StaticSettings::default());
    assert!(settle.converged, "{settle:?}");
    // the free particles of the outer surface: boundary triangles facing up (+z)
    let x = &sim.state.positions;
    let mut surface: Vec<u32> = Vec::new();
    for tri in &sim.model.mesh.topology().boundary {
        let [a, b, c] = tri.map(|v| x[v as usize]);
        if (b - a).cross(&(c - a)).normalize().z > 0.7 {
            surface.extend(tri.iter().filter(|&&v| !sim.model.held[v as usize]));
        }
    }
    surface.sort_unstable();
    surface.dedup();
    let dt = sim.settings.time_step_s;
    let force: f64 = std::env::var("FORCE_N")
        .ok()
        .and_then(|f| f.parse().ok())
        .unwrap_or(0.3);
    let (mut times, mut cg) = (Vec::with_capacity(steps), 0usize);
    for k in 0..steps {
        // the press slides from x = -30 mm to +30 mm over 1.5 s
        let tool_x = -0.03 + 0.06 * (k as f64 * dt / 1.5).min(1.0);
        sim.clear_external_forces();
        let near: Vec<(u32, f64)> = surface
            .iter()
            .map(|&v| {
                let p = sim.state.positions[v as usize];
                (v, ((p.x - tool_x).powi(2) + p.y.powi(2)).sqrt())
            })
            .filter(|(_, r)| *r < 0.004)
            .map(|(v, r)| (v, (1.0 - r / 0.004).powi(2)))
            .collect();
        let total: f64 = near.iter().map(|(_, w)| w).sum();
        for &(v, w) in &near {
            sim.add_external_force(v, -Vector3::z() * (force * w / total));
        }
        let t = Instant::now();
        let report = sim.step()?;
        times.push(t.elapsed().as_secs_f64() * 1e6);
        cg += report.cg_iterations;
    }
    let mut hash = Fnv1a::default();
    for p in &sim.state.positions {
        [p.x, p.y, p.z].into_iter().for_each(|c| hash.f64(c));
    }
    let hash = hash.finish();
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    println!(
        "{} tets, {} particles, {} steps: median {:.0} us, p99 {:.0} us, mean {:.0} us, {:.2} CG it., positions hash {:016x}",
        sim.model.mesh.tet_count(),
        sim.model.vertex_count(),
        steps,
        percentile(&sorted, 0.5),
        percentile(&sorted, 0.99),
        times.iter().sum::<f64>() / steps as f64,
        cg as f64 / steps as f64,
        hash
    );
    Ok(())
}
