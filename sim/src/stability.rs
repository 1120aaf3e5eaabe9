//! Stability stress cases, shared by `sim/tests/stability.rs` and `cutlab bench stability`:
//! a pre-tensioned slab held at its rim, kicked, and run for a fixed simulated time with a
//! given force model, integrator, time step, stiffness, damping and mass ratio. Each run ends
//! in one of the [`Outcome`]s; [`Outcome::NonFiniteLeak`] (a NaN or infinity in the state
//! after a step reported success) must never happen.

use crate::fem::FemMaterial;
use crate::generate::{GridCells, boxed};
use crate::model::{Material, Model, SpringStiffness};
use crate::reference::{Elasticity, ReferenceError};
use crate::solver::{Integrator, Simulation, SolverSettings, StaticSettings, forces};
use crate::{Point3, TetMesh, Vector3};

/// One configuration.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct StabilityCase {
    /// The force model.
    pub model: Elasticity,
    /// The time integrator.
    pub integrator: Integrator,
    /// The time step, s.
    pub time_step_s: f64,
    /// Young's modulus (springs: van Gelder constants from it; uniform springs: their mean).
    pub youngs_modulus_pa: f64,
    /// Damping level 0 (none), 1 (the defaults: 0.05 N s/m, Rayleigh alpha 1 /s and
    /// beta 0.01 s) or 2 (ten times the defaults).
    pub damping_level: u8,
    /// Density of one half of the slab over the other's (the mass ratio of neighbours).
    pub mass_ratio: f64,
}

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Outcome {
    /// Bounded energy over the whole run.
    Stable,
    /// Steps were rejected with an error and the state kept finite (a safe failure).
    Rejected,
    /// The energy grew beyond 100 times its initial value without non-finite values.
    Unbounded,
    /// The explicit integrator would need more sub-steps per step than the cap: not run
    /// (stiffness-proportional damping `beta K` makes symplectic Euler's limit `2 / (beta
    /// omega^2)`).
    TooManySubsteps,
    /// A non-finite value got into the state: a bug.
    NonFiniteLeak,
}

/// What a run measured.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct StabilityResult {
    /// How the run ended.
    pub outcome: Outcome,
    /// Steps taken.
    pub steps: u64,
    /// Sub-steps per step (symplectic Euler; 1 for implicit Euler).
    pub substeps: u32,
    /// Largest total energy over the initial one (kinetic + elastic, relative to the settled
    /// state).
    pub energy_ratio: f64,
    /// The largest particle speed seen, m/s.
    pub max_speed_m_per_s: f64,
}

/// Explicit runs needing more sub-steps per step than this are not run (the benchmark's cap).
pub const MAX_SUBSTEPS: u32 = 5_000;

/// The slab of the stress cases: 40 x 40 x 10 mm, `cells`, regions 0 (x < 20 mm) and 1.
pub fn slab(cells: GridCells) -> Result<(TetMesh, Vec<u32>), ReferenceError> {
    let g = boxed(Point3::origin(), [0.04, 0.04, 0.01], cells)?;
    let pos = g.mesh.positions().to_vec();
    let regions: Vec<u32> = g
        .mesh
        .tets()
        .iter()
        .map(|t| {
            if t.iter().map(|&v| pos[v as usize].x).sum::<f64>() / 4.0 > 0.02 {
                1
            } else {
                0
            }
        })
        .collect();
    let mesh = TetMesh::new(pos, g.mesh.tets().to_vec(), regions)?;
    Ok((mesh, g.rim))
}

/// Builds the simulation of `case` on the slab (rim held, 4 % pre-tension, settled).
pub fn build(case: &StabilityCase, cells: GridCells) -> Result<Simulation, ReferenceError> {
    let (mesh, rim) = slab(cells)?;
    let damping = [0.0, 1.0, 10.0][case.damping_level.min(2) as usize];
    let material = |density: f64, stiffness| Material {
        density_kg_per_m3: density,
        stiffness,
        damping_newton_seconds_per_metre: 0.05 * damping,
        pretension: 0.04,
    };
    let young = SpringStiffness::YoungsModulus {
        pascals: case.youngs_modulus_pa,
    };
    let mats = |stiffness| {
        [
            (0, material(900.0, stiffness)),
            (1, material(900.0 * case.mass_ratio, stiffness)),
        ]
    };
    let mut model = Model::new(mesh.clone(), &mats(young), &rim, Vector3::zeros())?;
    match case.model {
        Elasticity::SpringsYoungs => {}
        Elasticity::SpringsUniform => {
            let k = &model.springs.stiffness;
            let mean = k.iter().sum::<f64>() / k.len().max(1) as f64;
            model = Model::new(
                mesh,
                &mats(SpringStiffness::Uniform {
                    newtons_per_metre: mean,
                }),
                &rim,
                Vector3::zeros(),
            )?;
        }
        Elasticity::CorotationalFem => {
            let fem = FemMaterial {
                youngs_modulus_pa: case.youngs_modulus_pa,
                poisson_ratio: FemMaterial::CHEST_WALL.poisson_ratio,
                rayleigh_mass_per_s: FemMaterial::CHEST_WALL.rayleigh_mass_per_s * damping,
                rayleigh_stiffness_s: FemMaterial::CHEST_WALL.rayleigh_stiffness_s * damping,
            };
            model = model.with_fem(&[(0, fem), (1, fem)])?;
        }
        Elasticity::QuadraticFem => return Err(crate::reference::static_only()),
    }
    let settings = SolverSettings {
        integrator: case.integrator,
        time_step_s: case.time_step_s,
        ..SolverSettings::default()
    };
    let mut sim = Simulation::new(model, settings);
    let report = sim.settle(StaticSettings::default());
    if !report.converged {
        return Err(ReferenceError::Failed(format!(
            "the slab did not settle: {report:?}"
        )));
    }
    Ok(sim)
}

/// Total energy: kinetic plus potential (elastic) of the current state, J.
pub fn energy(sim: &Simulation) -> f64 {
    let m = &sim.model;
    let kinetic = forces::kinetic_energy(m, &sim.state.velocities);
    let potential = match &m.fem {
        Some(fem) => crate::fem::solve::potential_energy(m, fem, &sim.state.positions),
        None => forces::potential_energy(m, &sim.state.positions),
    };
    kinetic + potential
}

/// Kicks the settled slab (0.1 m/s along z, in a sine over the free vertices) and runs it for
/// `duration_s` of simulated time; explicit runs needing more than `max_substeps` per step are
/// not run.
pub fn run(
    case: &StabilityCase,
    cells: GridCells,
    duration_s: f64,
    max_substeps: u32,
) -> Result<StabilityResult, ReferenceError> {
    if !(case.time_step_s > 0.0 && case.time_step_s.is_finite() && duration_s.is_finite()) {
        return Err(ReferenceError::Failed(format!(
            "bad time step {} s or duration {duration_s} s",
            case.time_step_s
        )));
    }
    let mut sim = build(case, cells)?;
    let substeps = if case.integrator == Integrator::SymplecticEuler {
        sim.explicit_substeps()
    } else {
        1
    };
    let mut result = StabilityResult {
        outcome: Outcome::Stable,
        steps: 0,
        substeps,
        energy_ratio: 1.0,
        max_speed_m_per_s: 0.0,
    };
    if substeps > max_substeps {
        result.outcome = Outcome::TooManySubsteps;
        return Ok(result);
    }
    let rest_energy = energy(&sim);
    let x0 = sim.model.mesh.positions().to_vec();
    for (i, v) in sim.state.velocities.iter_mut().enumerate() {
        if !sim.model.held[i] {
            let p = x0[i];
            *v = Vector3::z()
                * 0.1
                * (p.x * std::f64::consts::PI / 0.04).sin()
                * (p.y * std::f64::consts::PI / 0.04).sin();
        }
    }
    let initial = (energy(&sim) - rest_energy).max(f64::MIN_POSITIVE);
    let steps = (duration_s / case.time_step_s).round().max(1.0) as u64;
    let mut rejected = 0;
    for _ in 0..steps {
        match sim.step() {
            Ok(_) => {}
            Err(_) => rejected += 1,
        }
        let finite = sim.state.is_finite();
        if !finite {
            result.outcome = Outcome::NonFiniteLeak;
            return Ok(result);
        }
        result.steps += 1;
        result.max_speed_m_per_s = result.max_speed_m_per_s.max(sim.state.max_speed());
        let ratio = (energy(&sim) - rest_energy) / initial;
        result.energy_ratio = result.energy_ratio.max(ratio);
        if rejected > 0 {
            // the state is the last good one: a further step would be rejected again
            result.outcome = Outcome::Rejected;
            return Ok(result);
        }
        if ratio > 100.0 {
            result.outcome = Outcome::Unbounded;
            return Ok(result);
        }
    }
    Ok(result)
}

/// The sweep: every model and integrator over time steps 0.1, 1 and 10 ms, E of 1 kPa, 30 kPa
/// and 1 MPa, damping levels 0, 1, 2 and mass ratios 1 and 100 (`quick`: the extremes of each
/// axis only, with the default in between left out).
pub fn sweep(quick: bool) -> Vec<StabilityCase> {
    let dts: &[f64] = &[1e-4, 1e-3, 1e-2];
    let es: &[f64] = if quick { &[1e3, 1e6] } else { &[1e3, 3e4, 1e6] };
    let dampings: &[u8] = if quick { &[0, 2] } else { &[0, 1, 2] };
    let ratios: &[f64] = &[1.0, 100.0];
    let mut cases = Vec::new();
    for model in Elasticity::ALL {
        for integrator in Integrator::ALL {
            for &time_step_s in dts {
                for &youngs_modulus_pa in es {
                    for &damping_level in dampings {
                        for &mass_ratio in ratios {
                            cases.push(StabilityCase {
                                model,
                                integrator,
                                time_step_s,
                                youngs_modulus_pa,
                                damping_level,
                                mass_ratio,
                            });
                        }
                    }
                }
            }
        }
    }
    cases
}
