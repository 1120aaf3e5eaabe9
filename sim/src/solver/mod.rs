//! Time integration and static equilibrium of the particle model.
//!
//! [`Simulation`] owns the model, the state, the external forces and scratch buffers only; a
//! step never allocates once the buffers have grown. Steps are deterministic: the same inputs
//! give bit-identical states (sequential loops in a fixed order, no hash-map iteration).
//! A step that would produce a non-finite value is rejected and the state left unchanged
//! (quarantine), with the offending particles named in the error.

mod dissection;
pub(crate) mod explicit;
pub(crate) mod forces;
pub(crate) mod implicit;
pub(crate) mod localise;
pub(crate) mod resume;
pub(crate) mod span;
pub(crate) mod statics;
pub(crate) mod system;

use serde::{Deserialize, Serialize};

pub use implicit::VELOCITY_FLOOR_M_PER_S;
pub use localise::{LocalisationError, LocalisationSettings};
pub use resume::{RegionResume, ResumeError, ResumeState, WarmStart};
pub use statics::{StaticReport, StaticSettings};
pub use system::{CgReport, CgSettings, PARALLEL_MIN_PARTICLES, SweepOrder, solver_threads};

use crate::model::{Model, State};
use crate::{Point3, Vector3};

/// Time integrator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Integrator {
    /// Symplectic Euler, explicitly sub-stepped below the estimated stability limit.
    SymplecticEuler,
    /// Linearised backward Euler solved by PCG with warm start.
    #[default]
    ImplicitEuler,
}

impl Integrator {
    /// Every integrator.
    pub const ALL: [Integrator; 2] = [Integrator::SymplecticEuler, Integrator::ImplicitEuler];

    /// The integrator's name in scene files and on the command line (kebab case).
    pub fn name(self) -> &'static str {
        match self {
            Integrator::SymplecticEuler => "symplectic-euler",
            Integrator::ImplicitEuler => "implicit-euler",
        }
    }
}

/// A name that is not an [`Integrator`]'s.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown integrator {0:?} (expected symplectic-euler or implicit-euler)")]
pub struct UnknownIntegrator(pub String);

impl std::str::FromStr for Integrator {
    type Err = UnknownIntegrator;
    fn from_str(s: &str) -> Result<Self, UnknownIntegrator> {
        Self::ALL
            .into_iter()
            .find(|i| i.name() == s)
            .ok_or_else(|| UnknownIntegrator(s.to_owned()))
    }
}

/// Solver settings (also the `[solver]` table of a scene file).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SolverSettings {
    /// The time integrator (default implicit Euler).
    pub integrator: Integrator,
    /// Fixed simulation step in seconds (default 1 ms).
    pub time_step_s: f64,
    /// Explicit sub-steps are kept below `explicit_safety` times the stability limit.
    pub explicit_safety: f64,
    /// Relative residual `|b - A x| / |b|` at which the implicit CG stops. The default 1e-3
    /// keeps the solver's error far below the integrator's own (the figures are in
    /// `docs/design/solver.md`, "The tolerance").
    pub cg_relative_tolerance: f64,
    /// The velocity, in m/s, below which the implicit CG need not resolve the step's velocity
    /// change: it stops at the latest when `|r| <= floor sqrt(sum m_i^2)`. The default,
    /// [`VELOCITY_FLOOR_M_PER_S`], only keeps the solve from chasing round-off; a
    /// scene may set the loosest floor within its error budget (`cutlab bench budget`).
    pub cg_velocity_floor_m_per_s: f64,
    /// The most iterations the implicit CG may take in one solve.
    pub cg_max_iterations: usize,
    /// Simulate only near the scalpel and the disturbance it causes (see [`localise`]);
    /// `None` (the default) simulates every particle every step.
    pub localisation: Option<LocalisationSettings>,
}

impl Default for SolverSettings {
    fn default() -> Self {
        Self {
            integrator: Integrator::ImplicitEuler,
            time_step_s: 1e-3,
            explicit_safety: 0.9,
            cg_relative_tolerance: 1e-3,
            cg_velocity_floor_m_per_s: VELOCITY_FLOOR_M_PER_S,
            cg_max_iterations: 500,
            localisation: None,
        }
    }
}

/// A [`SolverSettings`] value out of range (with the value given).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SettingsError {
    /// The time step is not positive and finite.
    #[error("time_step_s must be positive, got {0}")]
    TimeStep(f64),
    /// The explicit safety factor is outside `(0, 1]`.
    #[error("explicit_safety must be in (0, 1], got {0}")]
    ExplicitSafety(f64),
    /// The CG tolerance is outside `(0, 1)`.
    #[error("cg_relative_tolerance must be in (0, 1), got {0}")]
    CgTolerance(f64),
    /// The CG's velocity floor is negative or not finite.
    #[error("cg_velocity_floor_m_per_s must be finite and at least 0, got {0}")]
    CgVelocityFloor(f64),
    /// The CG may take no iteration.
    #[error("cg_max_iterations must be at least 1")]
    CgMaxIterations,
    /// A localisation setting is out of range.
    #[error(transparent)]
    Localisation(#[from] LocalisationError),
}

impl SolverSettings {
    /// Checks every value's range (see [`SettingsError`]).
    pub fn check(&self) -> Result<(), SettingsError> {
        if !(self.time_step_s > 0.0 && self.time_step_s.is_finite()) {
            return Err(SettingsError::TimeStep(self.time_step_s));
        }
        if !(self.explicit_safety > 0.0 && self.explicit_safety <= 1.0) {
            return Err(SettingsError::ExplicitSafety(self.explicit_safety));
        }
        if !(self.cg_relative_tolerance > 0.0 && self.cg_relative_tolerance < 1.0) {
            return Err(SettingsError::CgTolerance(self.cg_relative_tolerance));
        }
        if !(self.cg_velocity_floor_m_per_s >= 0.0 && self.cg_velocity_floor_m_per_s.is_finite()) {
            return Err(SettingsError::CgVelocityFloor(
                self.cg_velocity_floor_m_per_s,
            ));
        }
        if self.cg_max_iterations == 0 {
            return Err(SettingsError::CgMaxIterations);
        }
        if let Some(l) = &self.localisation {
            l.check()?;
        }
        Ok(())
    }
}

/// A step that was rejected; the state is unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepError {
    /// An external force given for the step is not finite.
    #[error("non-finite external force on particles {}", list(.vertices))]
    NonFiniteInput {
        /// The particles with such a force.
        vertices: Vec<u32>,
    },
    /// The step would have made positions or velocities non-finite.
    #[error("step rejected: it would make the state of particles {} non-finite", list(.vertices))]
    NonFinite {
        /// The particles that would have been.
        vertices: Vec<u32>,
    },
    /// The implicit solve produced a non-finite residual (e.g. forces so large that their
    /// squares overflow): its result cannot be trusted.
    #[error("step rejected: the implicit solve failed (residual {residual})")]
    SolverFailed {
        /// The residual the solve ended with.
        residual: f64,
    },
}

fn list(v: &[u32]) -> String {
    let shown: Vec<String> = v.iter().take(8).map(u32::to_string).collect();
    if v.len() > 8 {
        format!("{}, ... ({} in all)", shown.join(", "), v.len())
    } else {
        shown.join(", ")
    }
}

/// What one step did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepReport {
    /// Sub-steps taken (symplectic Euler; 1 for implicit Euler).
    pub substeps: u32,
    /// CG iterations over the step's solves (implicit Euler).
    pub cg_iterations: usize,
    /// The relative residual of the step's last solve (implicit Euler).
    pub cg_relative_residual: f64,
    /// Particles the step simulated (all free ones unless localised).
    pub awake_particles: usize,
    /// Linear solves of the step (a localised step solves again when its border woke).
    pub solves: u32,
}

/// Buffers reused by every step.
#[derive(Debug, Clone, Default)]
struct Scratch {
    backup: Option<State>,
    forces: Vec<Vector3>,
    implicit: implicit::ImplicitScratch,
    fem: crate::fem::solve::FemScratch,
}

impl Scratch {
    /// The whole-body step's scratch: its sweep order carried across cuts (see
    /// [`system::SpringSystem::carry_sweep_order`]).
    fn new() -> Self {
        let mut scratch = Self::default();
        scratch.implicit.system.carry_sweep_order();
        scratch
    }
}

/// The particle simulation: model, state, inputs and scratch.
#[derive(Debug, Clone)]
pub struct Simulation {
    /// The model: mesh, masses, held particles, springs (and finite elements).
    pub model: Model,
    /// Positions and velocities.
    pub state: State,
    /// The integrator, time step and solver settings.
    pub settings: SolverSettings,
    /// External force on each particle for the next steps (N), e.g. the scalpel contact.
    external_forces: Vec<Vector3>,
    /// Particles given an external force since the last clear ([`Self::add_external_force`]),
    /// unless `loaded_unknown` (the forces were written through
    /// [`Self::external_forces_mut`]): lets a localised step skip the unloaded particles.
    loaded: Vec<u32>,
    loaded_unknown: bool,
    /// The awake particles of the localised step (see [`localise`]).
    region: localise::ActiveRegion,
    /// Sub-steps per step of the explicit integrator (recomputed when the model changes).
    /// Computed on first use after a model change (the estimate costs a few milliseconds,
    /// worth paying only when the explicit integrator runs).
    explicit_substeps: Option<u32>,
    step_index: u64,
    scratch: Scratch,
}

impl Simulation {
    /// A simulation at rest in the mesh's reference positions.
    pub fn new(model: Model, settings: SolverSettings) -> Self {
        let state = State::at_rest(&model.mesh);
        let n = model.vertex_count();
        let explicit_substeps = None;
        Self {
            model,
            state,
            settings,
            external_forces: vec![Vector3::zeros(); n],
            loaded: Vec::new(),
            loaded_unknown: false,
            region: localise::ActiveRegion::default(),
            explicit_substeps,
            step_index: 0,
            scratch: Scratch::new(),
        }
    }

    /// The force on every particle at the current positions and `velocities` (N): springs or
    /// elements, their dampers, gravity; no external force. Held particles included: theirs
    /// is what holds them (see [`crate::grasp`]).
    pub fn forces_at(&self, velocities: &[Vector3]) -> Vec<Vector3> {
        let n = self.model.vertex_count();
        let mut out = vec![Vector3::zeros(); n];
        let zero = vec![Vector3::zeros(); n];
        let x = &self.state.positions;
        match &self.model.fem {
            Some(fem) => {
                crate::fem::solve::total_forces(&self.model, fem, x, velocities, &zero, &mut out)
            }
            None => forces::total_forces(&self.model, x, velocities, &zero, &mut out),
        }
        out
    }

    /// [`Self::forces_at`] the state's velocities.
    pub fn particle_forces(&self) -> Vec<Vector3> {
        self.forces_at(&self.state.velocities)
    }

    /// Steps taken so far.
    pub fn step_index(&self) -> u64 {
        self.step_index
    }

    /// Simulated time in seconds.
    pub fn time_s(&self) -> f64 {
        self.step_index as f64 * self.settings.time_step_s
    }

    /// Sub-steps the explicit integrator takes per step.
    pub fn explicit_substeps(&mut self) -> u32 {
        *self.explicit_substeps.get_or_insert_with(|| {
            let (dt, safety) = (self.settings.time_step_s, self.settings.explicit_safety);
            match &self.model.fem {
                Some(fem) => crate::fem::solve::substeps_for(&self.model, fem, dt, safety),
                None => explicit::substeps_for(&self.model, dt, safety),
            }
        })
    }

    /// Changes the model or the settings through `edit`, then brings what depends on them up
    /// to date ([`Self::model_changed`]): the way to change either. Returns what `edit` returns.
    ///
    /// ```
    /// use cutlab_sim::scene::{BuildOptions, Scene};
    /// use cutlab_sim::solver::Integrator;
    ///
    /// let scene = Scene::load("sheet", BuildOptions::default())?;
    /// let mut sim = scene.simulation();
    /// sim.edit(|_, settings| settings.integrator = Integrator::SymplecticEuler);
    /// assert!(sim.explicit_substeps() >= 1);
    /// # Ok::<(), cutlab_sim::scene::SceneError>(())
    /// ```
    pub fn edit<R>(&mut self, edit: impl FnOnce(&mut Model, &mut SolverSettings) -> R) -> R {
        let r = edit(&mut self.model, &mut self.settings);
        self.model_changed();
        r
    }

    /// Brings what depends on the model and the settings up to date; [`Self::edit`] calls it.
    /// Call after changing the model's springs or masses or the settings directly.
    pub fn model_changed(&mut self) {
        self.explicit_substeps = None;
        let n = self.model.vertex_count();
        self.external_forces.resize(n, Vector3::zeros());
        self.region.model_changed(&self.state.positions);
    }

    /// External forces for the next steps (N per particle). Prefer
    /// [`Self::add_external_force`], which tells a localised step which particles are loaded.
    pub fn external_forces(&self) -> &[Vector3] {
        &self.external_forces
    }

    /// External forces for the next steps, to write (N per particle).
    pub fn external_forces_mut(&mut self) -> &mut [Vector3] {
        self.loaded_unknown = true;
        &mut self.external_forces
    }

    /// Adds `force_newtons` to the external force on particle `vertex` (ignored when out of
    /// range).
    pub fn add_external_force(&mut self, vertex: u32, force_newtons: Vector3) {
        if let Some(f) = self.external_forces.get_mut(vertex as usize) {
            *f += force_newtons;
            self.loaded.push(vertex);
        }
    }

    /// Sets every external force to zero.
    pub fn clear_external_forces(&mut self) {
        if self.loaded_unknown {
            self.external_forces
                .iter_mut()
                .for_each(|f| *f = Vector3::zeros());
        } else {
            for &v in &self.loaded {
                self.external_forces[v as usize] = Vector3::zeros();
            }
        }
        self.loaded.clear();
        self.loaded_unknown = false;
    }

    /// Where the scalpel is: particles near these points stay awake in a localised step.
    pub fn set_focus(&mut self, points: &[Point3]) {
        self.region.focus.clear();
        self.region.focus.extend_from_slice(points);
    }

    /// Holds `vertices` where they are: infinite mass to the integrators (a grasper's jaws,
    /// a retractor's grip). Ids past the mesh are skipped.
    pub fn hold(&mut self, vertices: &[u32]) {
        self.edit(|model, _| {
            for &v in vertices {
                if let Some(h) = model.held.get_mut(v as usize) {
                    *h = true;
                    model.inv_mass[v as usize] = 0.0;
                }
            }
        });
    }

    /// Lets held `vertices` go: free again, with their masses, and awake. Ids past the mesh
    /// and massless particles are skipped.
    pub fn let_go(&mut self, vertices: &[u32]) {
        self.edit(|model, _| {
            for &v in vertices {
                let v = v as usize;
                if v < model.vertex_count() && model.mass[v] > 0.0 {
                    model.held[v] = false;
                    model.inv_mass[v] = 1.0 / model.mass[v];
                }
            }
        });
        self.wake(vertices.iter().copied());
    }

    /// Wakes `vertices` for the next localised step (e.g. those a cut touched); nothing
    /// when the simulation is not localised.
    pub fn wake(&mut self, vertices: impl IntoIterator<Item = u32>) {
        if self.settings.localisation.is_some() {
            self.region.wake(vertices);
        }
    }

    /// Particles awake after the last localised step (0 before the first one).
    pub fn awake_particles(&self) -> usize {
        self.region.awake_count()
    }

    /// Moves the free particles to static equilibrium (velocities zero), ignoring the external
    /// forces.
    pub fn settle(&mut self, settings: StaticSettings) -> StaticReport {
        self.reset_warm_start();
        let none = vec![Vector3::zeros(); self.model.vertex_count()];
        match &self.model.fem {
            Some(fem) => {
                crate::fem::solve::statics(&self.model, fem, &mut self.state, &none, settings)
            }
            None => statics::solve(&self.model, &mut self.state, settings),
        }
    }

    /// Moves the free particles to static equilibrium under the current external forces
    /// (e.g. a static load), velocities zero.
    pub fn settle_loaded(&mut self, settings: StaticSettings) -> StaticReport {
        self.reset_warm_start();
        let external = &self.external_forces;
        match &self.model.fem {
            Some(fem) => {
                crate::fem::solve::statics(&self.model, fem, &mut self.state, external, settings)
            }
            None => statics::solve_loaded(&self.model, &mut self.state, external, settings),
        }
    }

    /// Forgets the implicit integrator's past velocity changes (after a jump of the state).
    fn reset_warm_start(&mut self) {
        self.scratch.implicit.reset_warm_start();
        self.scratch.fem.reset_warm_start();
        self.region.reset_warm_start();
        self.region.state_moved();
    }

    /// Advances one fixed step of `settings.time_step_s`.
    ///
    /// A 1 cm cube of tissue held at its bottom face, pushed sideways at its top:
    ///
    /// ```
    /// use cutlab_sim::generate::{GridCells, boxed};
    /// use cutlab_sim::model::{Material, Model};
    /// use cutlab_sim::solver::{Simulation, SolverSettings, StaticSettings};
    /// use cutlab_sim::{Point3, Vector3};
    ///
    /// let cube = boxed(Point3::origin(), [0.01; 3], GridCells { nx: 2, ny: 2, nz: 2 })?.mesh;
    /// let bottom: Vec<u32> = (0..cube.vertex_count() as u32)
    ///     .filter(|&v| cube.positions()[v as usize].z == 0.0)
    ///     .collect();
    /// let top: Vec<u32> = (0..cube.vertex_count() as u32)
    ///     .filter(|&v| cube.positions()[v as usize].z == 0.01)
    ///     .collect();
    /// let model = Model::new(cube, &[(0, Material::default())], &bottom, Vector3::zeros())?;
    /// let mut sim = Simulation::new(model, SolverSettings::default());
    /// sim.settle(StaticSettings::default()); // equilibrium under the pre-tension
    /// let mean_top_x = |sim: &Simulation| {
    ///     top.iter().map(|&v| sim.state.positions[v as usize].x).sum::<f64>() / top.len() as f64
    /// };
    /// let settled_x = mean_top_x(&sim);
    /// for &v in &top {
    ///     sim.add_external_force(v, Vector3::new(0.01, 0.0, 0.0));
    /// }
    /// for _ in 0..10 {
    ///     sim.step()?;
    /// }
    /// assert_eq!(sim.step_index(), 10);
    /// assert!(mean_top_x(&sim) > settled_x); // the top has moved along the push
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn step(&mut self) -> Result<StepReport, StepError> {
        if let (Some(localisation), Integrator::ImplicitEuler, None) = (
            self.settings.localisation,
            self.settings.integrator,
            &self.model.fem,
        ) {
            return self.step_localised(&localisation);
        }
        self.check_external_forces(0..self.external_forces.len() as u32)?;
        let backup = self
            .scratch
            .backup
            .get_or_insert_with(|| self.state.clone());
        backup.positions.clone_from(&self.state.positions);
        backup.velocities.clone_from(&self.state.velocities);

        let dt = self.settings.time_step_s;
        let mut report = StepReport::default();
        let fem = self.model.fem.as_ref();
        match (self.settings.integrator, fem) {
            (Integrator::SymplecticEuler, Some(_)) => {
                let substeps = self.explicit_substeps();
                report.substeps = substeps;
                if let Some(fem) = &self.model.fem {
                    let forces = &mut self.scratch.forces;
                    crate::fem::solve::explicit_step(
                        &self.model,
                        fem,
                        &mut self.state,
                        &self.external_forces,
                        dt,
                        substeps,
                        forces,
                    );
                }
            }
            (Integrator::ImplicitEuler, Some(fem)) => {
                let solve = self.implicit_solve();
                let r = crate::fem::solve::implicit_step(
                    &self.model,
                    fem,
                    &mut self.state,
                    &self.external_forces,
                    dt,
                    solve,
                    &mut self.scratch.fem,
                );
                report.substeps = 1;
                report.cg_iterations = r.iterations;
                report.cg_relative_residual = r.relative_residual;
            }
            (Integrator::SymplecticEuler, None) => {
                let substeps = self.explicit_substeps();
                report.substeps = substeps;
                explicit::step(
                    &self.model,
                    &mut self.state,
                    &self.external_forces,
                    dt,
                    substeps,
                    &mut self.scratch.forces,
                );
            }
            (Integrator::ImplicitEuler, None) => {
                let solve = self.implicit_solve();
                let r = implicit::step(
                    &self.model.particles(),
                    &mut self.state,
                    &self.external_forces,
                    dt,
                    solve,
                    &mut self.scratch.implicit,
                );
                report.substeps = 1;
                report.cg_iterations = r.iterations;
                report.cg_relative_residual = r.relative_residual;
            }
        }
        if !report.cg_relative_residual.is_finite() {
            if let Some(backup) = &self.scratch.backup {
                self.state.positions.clone_from(&backup.positions);
                self.state.velocities.clone_from(&backup.velocities);
            }
            self.reset_warm_start();
            return Err(StepError::SolverFailed {
                residual: report.cg_relative_residual,
            });
        }
        let bad = self.state.non_finite_particles();
        if !bad.is_empty() {
            if let Some(backup) = &self.scratch.backup {
                self.state.positions.clone_from(&backup.positions);
                self.state.velocities.clone_from(&backup.velocities);
            }
            // the warm start may be poisoned too
            self.reset_warm_start();
            return Err(StepError::NonFinite { vertices: bad });
        }
        self.step_index += 1;
        report.awake_particles = self.model.held.iter().filter(|h| !**h).count();
        report.solves = 1;
        Ok(report)
    }

    /// The implicit solve's settings (the relative tolerance and the velocity floor; the
    /// absolute floor is the integrator's, from the floor and the masses).
    fn implicit_solve(&self) -> implicit::ImplicitSolve {
        implicit::ImplicitSolve {
            cg: CgSettings {
                relative_tolerance: self.settings.cg_relative_tolerance,
                absolute_tolerance: 0.0,
                max_iterations: self.settings.cg_max_iterations,
            },
            velocity_floor_m_per_s: self.settings.cg_velocity_floor_m_per_s,
        }
    }

    /// Rejects the step when the external force on one of `vertices` is not finite.
    fn check_external_forces(&self, vertices: impl Iterator<Item = u32>) -> Result<(), StepError> {
        let bad: Vec<u32> = vertices
            .filter(|&v| {
                !self.external_forces[v as usize]
                    .iter()
                    .all(|c| c.is_finite())
            })
            .collect();
        if bad.is_empty() {
            Ok(())
        } else {
            Err(StepError::NonFiniteInput { vertices: bad })
        }
    }

    /// [`Self::step`] on the awake particles only (see [`localise`]).
    fn step_localised(
        &mut self,
        localisation: &LocalisationSettings,
    ) -> Result<StepReport, StepError> {
        if self.loaded_unknown {
            self.loaded.clear();
            let loaded = self
                .external_forces
                .iter()
                .enumerate()
                .filter(|(_, f)| **f != Vector3::zeros());
            self.loaded.extend(loaded.map(|(i, _)| i as u32));
            self.loaded_unknown = false;
        }
        self.loaded.sort_unstable();
        self.loaded.dedup();
        self.check_external_forces(self.loaded.iter().copied())?;
        let (h, solve) = (self.settings.time_step_s, self.implicit_solve());
        let (r, solves) = self.region.step(
            &self.model,
            &mut self.state,
            &self.external_forces,
            &self.loaded,
            localisation,
            h,
            solve,
        )?;
        self.step_index += 1;
        Ok(StepReport {
            substeps: 1,
            cg_iterations: r.iterations,
            cg_relative_residual: r.relative_residual,
            awake_particles: self.region.awake_count(),
            solves,
        })
    }
}
