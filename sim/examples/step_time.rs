//! Times the implicit step of the chest wall at one size while a 0.3 N press slides along its
//! top (the solver's hot path alone, without the CLI's benchmarks around it):
//! `cargo run --release -p cutlab-sim --example step_time -- [TETS] [STEPS]`.
//! Prints the median and p99 step time, the mean CG iterations and a hash of the final
//! positions (FNV-1a, to see whether a change to the solver changed its results; pinned by
//! `sim/tests/golden.rs`). `SCENE=chest-wall-fem` runs the finite elements.

#[path = "workloads/mod.rs"]
mod workloads;

use cutlab_sim::stats::percentile;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let tets: usize = args
        .next()
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(100_000);
    let steps: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(400);
    let scene = std::env::var("SCENE").unwrap_or_else(|_| "chest-wall".into());
    let mut sim = workloads::settled(&scene, tets)?;
    let force: f64 = std::env::var("FORCE_N")
        .ok()
        .and_then(|f| f.parse().ok())
        .unwrap_or(0.3);
    let (mut times, mut cg) = (Vec::with_capacity(steps), 0usize);
    workloads::press(&mut sim, steps, force, |us, iterations| {
        times.push(us);
        cg += iterations;
    })?;
    let hash = workloads::positions_hash(&sim);
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
