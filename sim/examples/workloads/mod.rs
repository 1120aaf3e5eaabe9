//! The workloads of the `step_time` and `cut_time` examples, shared with the golden-results
//! test (`sim/tests/golden.rs`, which includes this file): the same calls in the same order,
//! so a hash the test pins is the hash the example prints.

#![allow(dead_code)]

use std::time::Instant;

use cutlab_sim::cut::{Blade, Cutter};
use cutlab_sim::hash::Fnv1a;
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::{LocalisationSettings, Simulation, StaticSettings};
use cutlab_sim::{Point3, Vector3};

pub type Error = Box<dyn std::error::Error>;

/// The settled scene `scene` (a chest wall) at `tets` tets or more.
pub fn settled(scene: &str, tets: usize) -> Result<Simulation, Error> {
    let scene = Scene::load(
        scene,
        BuildOptions {
            min_tets: Some(tets),
        },
    )?;
    let mut sim = scene.simulation();
    let settle = sim.settle(StaticSettings::default());
    if !settle.converged {
        return Err(format!("the scene did not settle: {settle:?}").into());
    }
    Ok(sim)
}

/// `steps` implicit steps while a press of `force_n` newtons slides along the top of the
/// settled chest wall (x from -30 to +30 mm in 1.5 s, a 4 mm wide patch); `each` gets every
/// step's time (us) and CG iterations.
pub fn press(
    sim: &mut Simulation,
    steps: usize,
    force_n: f64,
    mut each: impl FnMut(f64, usize),
) -> Result<(), Error> {
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
    for k in 0..steps {
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
            sim.add_external_force(v, -Vector3::z() * (force_n * w / total));
        }
        let t = Instant::now();
        let report = sim.step()?;
        each(t.elapsed().as_secs_f64() * 1e6, report.cg_iterations);
    }
    Ok(())
}

/// What [`cut_along_top`] timed.
#[derive(Debug, Clone, Copy)]
pub enum Timed {
    /// A cut: its time (us) and the tets it split (0: it changed nothing).
    Cut { us: f64, split: usize },
    /// A step: its time (us), CG iterations, and whether a changing cut came right before.
    Step { us: f64, cg: usize, after_cut: bool },
}

/// A blade 3 mm deep along the top of the settled chest wall (x from -20 to +20 mm, a cut
/// every 0.5 mm, `between` implicit steps after each; `localised`: the localised step with
/// its default thresholds); `each` gets every cut and step timed.
pub fn cut_along_top(
    sim: &mut Simulation,
    between: usize,
    localised: bool,
    mut each: impl FnMut(Timed),
) -> Result<(), Error> {
    let x = &sim.state.positions;
    let top = |tool_x: f64| {
        x.iter()
            .filter(|p| (p.x - tool_x).abs() < 0.002 && p.y.abs() < 0.002)
            .map(|p| p.z)
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let (z0, z1) = (top(-0.02), top(0.02));
    if localised {
        sim.settings.localisation = Some(LocalisationSettings::default());
    }
    let mut cutter = Cutter::default();
    for k in 0..=80 {
        let tx = -0.02 + 0.0005 * k as f64;
        let z = z0 + (z1 - z0) * (k as f64 / 80.0) - 0.003;
        let blade = Blade {
            tip: Point3::new(tx, 0.0, z),
            edge_direction: Vector3::z(),
            depth_m: 0.008,
        };
        let t = Instant::now();
        let event = cutter.advance(sim, blade)?;
        each(Timed::Cut {
            us: t.elapsed().as_secs_f64() * 1e6,
            split: event.tets_removed.len(),
        });
        for j in 0..between {
            let t = Instant::now();
            let report = sim.step()?;
            each(Timed::Step {
                us: t.elapsed().as_secs_f64() * 1e6,
                cg: report.cg_iterations,
                after_cut: j == 0 && !event.is_empty(),
            });
        }
    }
    Ok(())
}

/// The positions' bits fed to `hash`.
fn hash_positions(hash: &mut Fnv1a, sim: &Simulation) {
    for p in &sim.state.positions {
        [p.x, p.y, p.z].into_iter().for_each(|c| hash.f64(c));
    }
}

/// FNV-1a of the positions' bits.
pub fn positions_hash(sim: &Simulation) -> u64 {
    let mut hash = Fnv1a::default();
    hash_positions(&mut hash, sim);
    hash.finish()
}

/// FNV-1a of the positions' bits, then of the tets' vertex ids.
pub fn mesh_hash(sim: &Simulation) -> u64 {
    let mut hash = Fnv1a::default();
    hash_positions(&mut hash, sim);
    sim.model
        .mesh
        .tets()
        .iter()
        .flatten()
        .for_each(|&v| hash.u32(v));
    hash.finish()
}
