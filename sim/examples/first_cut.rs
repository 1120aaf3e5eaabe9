//! A first cut, from scene to `.vtu`: loads the built-in chest wall, settles it under its
//! pre-tension, draws a scalpel 20 mm across its top while the simulation steps, lets the
//! wound open for a few more steps and writes the mesh with its displacements and velocities
//! as a `.vtu` file that ParaView opens.
//!
//! `cargo run --release -p cutlab-sim --example first_cut -- [OUT.vtu]` (default: `first_cut.vtu`
//! in the system's temporary directory).

use std::path::PathBuf;

use cutlab_sim::Vector3;
use cutlab_sim::cut::{Blade, Cutter};
use cutlab_sim::io::{PointData, write_vtu};
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::StaticSettings;

/// The chest wall's outer radius (`sim/scenes/chest-wall.toml`), m.
const RADIUS_M: f64 = 0.15;
/// Where the cut runs across the slab's axis: just beside the layer of vertices at `y = 0`.
const Y_M: f64 = 0.0004;
/// How deep the blade's tip goes below the surface, m.
const DEPTH_M: f64 = 0.008;
/// Poses of the blade along the cut, one per simulation step.
const POSES: usize = 41;
/// Steps after the blade has left, for the wound to open.
const STEPS_AFTER: usize = 50;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args_os()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("first_cut.vtu"));

    // 1. The scene: a curved slab of chest wall, held at its rim (a coarse mesh, to be quick).
    let scene = Scene::load(
        "chest-wall",
        BuildOptions {
            min_tets: Some(10_000),
        },
    )?;
    let mut sim = scene.simulation();
    println!(
        "{}: {} tets, {} particles",
        scene.spec.name,
        sim.model.mesh.tet_count(),
        sim.model.vertex_count()
    );

    // 2. Settle: the pre-tensioned springs pull the tissue into static equilibrium.
    let settle = sim.settle(StaticSettings::default());
    println!(
        "settled in {} Newton iterations (residual {:.1e} N)",
        settle.newton_iterations, settle.residual_newtons
    );
    let settled = sim.state.positions.clone();

    // 3. Cut: the blade stands normal to the surface, its tip below it, and moves 20 mm along
    //    x; the cutter cuts along the path the tip swept since the last pose, then the
    //    simulation steps.
    let mut cutter = Cutter::default();
    let (mut changing_cuts, mut tets_split, mut vertices_split) = (0, 0, 0);
    let mut cg_iterations = 0;
    for k in 0..POSES {
        let x_m = -0.01 + 0.02 * k as f64 / (POSES - 1) as f64;
        let blade = Blade::normal_to_curved_slab(x_m, Y_M, RADIUS_M, DEPTH_M, 0.005);
        let event = cutter.advance(&mut sim, blade)?;
        changing_cuts += usize::from(!event.is_empty());
        tets_split += event.tets_removed.len();
        vertices_split += event.vertices_split.len();
        cg_iterations += sim.step()?.cg_iterations;
    }
    cutter.end_stroke();

    // 4. Step on: the pre-tension opens the wound.
    for _ in 0..STEPS_AFTER {
        cg_iterations += sim.step()?.cg_iterations;
    }
    let steps = sim.step_index();
    println!(
        "cut: {changing_cuts} cuts changed the tissue, {tets_split} tets and {vertices_split} vertices split, now {} tets; {steps} steps ({:.3} s), {:.1} CG it. per step",
        sim.model.mesh.tet_count(),
        sim.time_s(),
        cg_iterations as f64 / steps as f64
    );

    // 5. Write the deformed mesh with its displacement from the settled state and velocities.
    //    Vertices the cut added have no settled position: their displacement is from their
    //    reference one.
    let mut mesh = sim.model.mesh.clone();
    let displacement: Vec<Vector3> = sim
        .state
        .positions
        .iter()
        .zip(mesh.positions())
        .enumerate()
        .map(|(i, (x, rest))| x - settled.get(i).unwrap_or(rest))
        .collect();
    mesh.positions_mut().copy_from_slice(&sim.state.positions);
    write_vtu(
        &out,
        &mesh,
        &[
            ("displacement", PointData::Vector(&displacement)),
            ("velocity", PointData::Vector(&sim.state.velocities)),
        ],
    )?;
    println!("wrote {}", out.display());
    Ok(())
}
