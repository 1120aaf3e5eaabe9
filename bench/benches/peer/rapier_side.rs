//! Rapier's side (`rapier3d-f64`, its soft bodies): the same tet mesh as co-rotational cells
//! with the same lumped masses and pinned (held) particles, no collider (cutlab's step has no
//! collision either), never asleep, 1 ms steps.

use std::time::Instant;

use anyhow::Context;
use cutlab_sim::fem::FemMaterial;
use cutlab_sim::model::Model;
use cutlab_sim::stats::Summary;
use cutlab_sim::{Point3, TetMesh, Vector3};
use rapier3d_f64::prelude::{
    PhysicsWorld, SoftBodyBuilder, SoftBodyCellModel, SoftBodyHandle, SoftBodyMaterial,
    SoftBodySolver, Vector,
};

use crate::cantilever::CantileverLoad;
use crate::cases::Case;

/// The time step of both engines, s.
pub const TIME_STEP_S: f64 = 1e-3;

/// How Rapier runs: its soft-body solver, substeps per step, the cells' damping ratio.
#[derive(Debug, Clone, Copy)]
pub struct Setup {
    pub solver: SoftBodySolver,
    pub substeps: usize,
    pub cell_damping: CellDamping,
}

/// A world holding one soft body.
pub struct World {
    pub world: PhysicsWorld,
    pub body: SoftBodyHandle,
}

fn vector(v: &Vector3) -> Vector {
    Vector::new(v.x, v.y, v.z)
}

fn point(p: &Point3) -> Vector {
    Vector::new(p.x, p.y, p.z)
}

/// The damping ratio of Rapier's elastic cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CellDamping {
    /// The ratio that gives cutlab's Rayleigh `beta` on average ([`damping_ratio_for`]).
    Mapped,
    /// Rapier's default, 1.
    Default,
}

/// Rapier's material for cutlab's: Young's modulus and Poisson's ratio as they are, the
/// stiffness-proportional Rayleigh damping as the cells' damping ratio (`damping`).
pub fn material(
    mesh: &TetMesh,
    inv_mass: &[f64],
    fem: &FemMaterial,
    damping: CellDamping,
) -> SoftBodyMaterial {
    let default = SoftBodyMaterial::default();
    SoftBodyMaterial {
        young_modulus: fem.youngs_modulus_pa,
        poisson_ratio: fem.poisson_ratio,
        elastic_damping_ratio: match damping {
            CellDamping::Mapped => damping_ratio_for(mesh, inv_mass, fem),
            CellDamping::Default => default.elastic_damping_ratio,
        },
        ..default
    }
}

/// Rapier damps each cell in proportion to its stiffness with `beta_c = 2 zeta / mean_r
/// omega_r`, `omega_r = sqrt(k_r V (sum_p w_p |g_r[p]|^2))` over the six strain rows
/// (`k_r = 2 mu + lambda` or `4 mu`, `w_p` the particles' inverse masses, `g_r[p]` the row's
/// gradient; its FEM solver's `rayleigh_coefficient`). The damping ratio `zeta` whose
/// volume-weighted mean `beta_c` is cutlab's Rayleigh `beta`.
pub fn damping_ratio_for(mesh: &TetMesh, inv_mass: &[f64], fem: &FemMaterial) -> f64 {
    let (mu, lambda) = fem.lame_pa();
    let (mut weighted, mut volume) = (0.0, 0.0);
    for (t, tet) in mesh.tets().iter().enumerate() {
        let v = mesh.tet_volume(t).abs();
        if let Some(beta) = unit_beta(mesh, tet, inv_mass, mu, lambda, v) {
            weighted += beta * v;
            volume += v;
        }
    }
    if volume > 0.0 && weighted > 0.0 {
        fem.rayleigh_stiffness_s / (weighted / volume)
    } else {
        1.0
    }
}

/// Rapier's `beta` of one cell at damping ratio 1.
fn unit_beta(
    mesh: &TetMesh,
    tet: &[u32; 4],
    inv_mass: &[f64],
    mu: f64,
    lambda: f64,
    volume: f64,
) -> Option<f64> {
    let x = tet.map(|i| mesh.positions()[i as usize]);
    let (e1, e2, e3) = (x[1] - x[0], x[2] - x[0], x[3] - x[0]);
    let det = e1.dot(&e2.cross(&e3));
    if det.abs() <= f64::EPSILON * e1.norm() * e2.norm() * e3.norm() {
        return None;
    }
    // shape-function gradients: the rows of Dm^-1 for vertices 1..3, minus their sum for 0
    let mut g = [
        Vector3::zeros(),
        e2.cross(&e3) / det,
        e3.cross(&e1) / det,
        e1.cross(&e2) / det,
    ];
    g[0] = -(g[1] + g[2] + g[3]);
    // the diagonal of the inverse-mass-weighted Gram matrix sum_p w_p g_p g_p^T
    let mut gram = [0.0; 3];
    for (p, &vertex) in tet.iter().enumerate() {
        (0..3).for_each(|a| gram[a] += inv_mass[vertex as usize] * g[p][a] * g[p][a]);
    }
    let normal = (0..3).map(|a| ((2.0 * mu + lambda) * volume * gram[a]).sqrt());
    let shear = [(0, 1), (0, 2), (1, 2)]
        .map(|(a, b)| (4.0 * mu * volume * 0.25 * (gram[a] + gram[b])).sqrt());
    let omegas: Vec<f64> = normal.chain(shear).filter(|w| *w > 0.0).collect();
    let sum: f64 = omegas.iter().sum();
    (sum > 0.0).then(|| 2.0 * omegas.len() as f64 / sum)
}

/// Half the median edge length: Rapier's particle radius (it bounds the travel per substep).
fn particle_radius_m(model: &Model) -> f64 {
    model.median_edge_length().map_or(1e-3, |m| 0.5 * m)
}

/// A world with `model`'s mesh, masses and held vertices as one soft body; `linear_damping`
/// (1/s, Rapier's particle damping, mass-proportional) plays cutlab's Rayleigh `alpha`.
pub fn world(model: &Model, fem: &FemMaterial, setup: Setup, linear_damping_per_s: f64) -> World {
    let mesh = &model.mesh;
    let held: Vec<u32> = (0..model.vertex_count() as u32)
        .filter(|&v| model.held[v as usize])
        .collect();
    let builder = SoftBodyBuilder::new(mesh.positions().iter().map(point).collect())
        .cells(mesh.tets().to_vec())
        .masses(model.mass.clone())
        .pinned_particles(held)
        .cell_model(SoftBodyCellModel::Corotational)
        .solver(setup.solver)
        .material(material(mesh, &model.inv_mass, fem, setup.cell_damping))
        .no_surface_collider()
        .can_sleep(false)
        .linear_damping(linear_damping_per_s)
        .particle_radius(particle_radius_m(model));
    let mut world = PhysicsWorld::new();
    world.gravity = vector(&model.gravity);
    world.integration_parameters.dt = TIME_STEP_S;
    world.integration_parameters.num_solver_iterations = setup.substeps;
    let body = world.insert_soft_body(builder);
    World { world, body }
}

impl World {
    fn position(&self, v: u32) -> Point3 {
        let p = self
            .world
            .soft_bodies
            .get(self.body)
            .map(|b| b.particle_position(v as usize))
            .unwrap_or(Vector::ZERO);
        Point3::new(p.x, p.y, p.z)
    }

    /// Replaces the user forces (N per particle).
    fn set_forces(&mut self, forces: &[(u32, Vector3)]) -> anyhow::Result<()> {
        let body = self
            .world
            .soft_bodies
            .get_mut(self.body)
            .context("soft body gone")?;
        body.reset_forces(false);
        for (v, f) in forces {
            body.add_particle_force(*v as usize, vector(f), false);
        }
        Ok(())
    }
}

/// `steps` timed steps while the case's press slides along the body.
pub fn steps(case: &Case, setup: Setup, steps: usize) -> anyhow::Result<Summary> {
    let mut w = world(
        &case.fem,
        &case.material,
        setup,
        case.material.rayleigh_mass_per_s,
    );
    let mut forces = Vec::new();
    let mut times_us = Vec::with_capacity(steps);
    for i in 0..steps {
        case.press
            .forces(i as f64 * TIME_STEP_S, |v| w.position(v), &mut forces);
        w.set_forces(&forces)?;
        let t = Instant::now();
        w.world.step();
        times_us.push(t.elapsed().as_secs_f64() * 1e6);
        anyhow::ensure!(
            w.world.quarantine().is_empty(),
            "Rapier quarantined the soft body at step {i} (non-finite state)"
        );
    }
    Ok(Summary::of(&times_us))
}

/// Times of one cut: the quad as two blade triangles.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CutRun {
    pub cut_ms: Summary,
    pub particles_before: usize,
    pub particles_after: usize,
    pub cells: usize,
}

/// `repeats` times the cut along the case's quad (`PhysicsWorld::cut_soft_body` with its two
/// triangles) on fresh worlds stepped once.
pub fn cut(case: &Case, setup: Setup, repeats: usize) -> anyhow::Result<CutRun> {
    let [a, b, c, d] = case.cut_quad.map(|p| point(&p));
    let mut times_ms = Vec::with_capacity(repeats);
    let mut counts = (0, 0, 0);
    for _ in 0..repeats {
        let mut w = world(
            &case.fem,
            &case.material,
            setup,
            case.material.rayleigh_mass_per_s,
        );
        w.world.step();
        let before = particles(&w);
        let t = Instant::now();
        let first = w.world.cut_soft_body(w.body, &[a, b, c]);
        let second = w.world.cut_soft_body(w.body, &[a, c, d]);
        times_ms.push(t.elapsed().as_secs_f64() * 1e3);
        anyhow::ensure!(
            first.is_some() || second.is_some(),
            "Rapier's cut changed nothing"
        );
        let cells = w.world.soft_bodies().map(|(_, sb)| sb.cells().len()).sum();
        counts = (before, particles(&w), cells);
    }
    Ok(CutRun {
        cut_ms: Summary::of(&times_ms),
        particles_before: counts.0,
        particles_after: counts.1,
        cells: counts.2,
    })
}

/// All particles of all soft bodies (a cut may split the body).
fn particles(w: &World) -> usize {
    w.world
        .soft_bodies()
        .map(|(_, sb)| sb.num_particles())
        .sum()
}

/// A cantilever run to rest.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CantileverRun {
    pub deflection_m: f64,
    pub relative_error: f64,
    pub steps: usize,
    pub wall_ms: f64,
    pub converged: bool,
}

/// When a dynamic run counts as at rest.
#[derive(Debug, Clone, Copy)]
pub struct Settle {
    /// The tip deflection changed by less than this fraction of itself over 100 steps.
    pub relative_change: f64,
    /// Give up (not settled) after this many steps.
    pub max_steps: usize,
}

/// The cantilever load case on `model` (the bar, clamped at `x = min`, no gravity), run
/// dynamically until it settles. Particle damping `2 omega_1` (the first bending mode
/// critically damped) brings it to rest; damping does not change the static answer.
pub fn cantilever(
    model: &Model,
    fem: &FemMaterial,
    load: &CantileverLoad,
    setup: Setup,
    settle: Settle,
) -> anyhow::Result<CantileverRun> {
    let mut w = world(model, fem, setup, 2.0 * load.first_mode_rad_per_s);
    let tip: Vec<(u32, Vector3)> = load
        .tip
        .iter()
        .map(|&(v, f)| {
            let mut force = Vector3::zeros();
            force[load.axis] = f;
            (v, force)
        })
        .collect();
    w.set_forces(&tip)?;
    let deflection = |w: &World| load.deflection_m(&model.mesh, |v| w.position(v));
    let t = Instant::now();
    let mut previous = f64::INFINITY;
    let mut steps = 0;
    let mut converged = false;
    while steps < settle.max_steps {
        w.world.step();
        steps += 1;
        anyhow::ensure!(
            w.world.quarantine().is_empty(),
            "Rapier quarantined the bar at step {steps} (non-finite state)"
        );
        if steps % 100 == 0 {
            let d = deflection(&w);
            if (d - previous).abs() < settle.relative_change * d.abs() {
                converged = true;
                break;
            }
            previous = d;
        }
    }
    let d = deflection(&w);
    Ok(CantileverRun {
        deflection_m: d,
        relative_error: load.relative_error(d),
        steps,
        wall_ms: t.elapsed().as_secs_f64() * 1e3,
        converged,
    })
}
