//! Times the cutter alone on the chest wall at one size: a blade 3 mm deep slides along the
//! top (x from -20 to +20 mm, a cut every 0.5 mm, `STEPS_BETWEEN` implicit steps between
//! cuts): `cargo run --release -p cutlab-sim --example cut_time -- [TETS] [STEPS_BETWEEN]`
//! (with `LOCALISED=1` in the environment, the localised step with its default thresholds).
//! Prints the median, p99 and max time of the cuts that changed the tissue and of those that
//! did not, of the steps right after a changing cut and of the others, the tets split, and a
//! hash of the final mesh and positions (FNV-1a, to see whether a change to the cutter changed
//! its results).

#[path = "workloads/mod.rs"]
mod workloads;

use cutlab_sim::stats::Summary;
use workloads::Timed;

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
    let mut sim = workloads::settled("chest-wall", tets)?;
    let (mut changed, mut idle) = (Vec::new(), Vec::new());
    let (mut step_after_cut, mut step_other) = (Vec::new(), Vec::new());
    let (mut cg_after_cut, mut cg_other) = (0usize, 0usize);
    let mut split = 0;
    let localised = std::env::var_os("LOCALISED").is_some();
    workloads::cut_along_top(&mut sim, between, localised, |timed| match timed {
        Timed::Cut { us, split: 0 } => idle.push(us),
        Timed::Cut { us, split: n } => {
            split += n;
            changed.push(us);
        }
        Timed::Step {
            us,
            cg,
            after_cut: true,
        } => {
            step_after_cut.push(us);
            cg_after_cut += cg;
        }
        Timed::Step { us, cg, .. } => {
            step_other.push(us);
            cg_other += cg;
        }
    })?;
    let hash = workloads::mesh_hash(&sim);
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
