//! Localisation: the implicit step solves only where the scalpel and the disturbance it causes
//! are; far particles sleep, held where they are, and wake when the disturbance reaches them.
//!
//! Every free particle is *awake* or *asleep*. A step assembles and solves the backward-Euler
//! system (see [`super::implicit`]) of the awake particles alone, with their sleeping
//! neighbours (the *border*) held at their positions: the system is gathered into a compact
//! sub-body (particles in ascending global order, springs with at least one awake end), solved,
//! and the awake particles scattered back. Nothing in a step runs over the whole mesh.
//!
//! A particle's *residual displacement* is `|f_i| / K_i`, with `f_i` the net force on it
//! (springs, dampers, gravity, external force) and `K_i` the sum of its springs' constants:
//! about how far it would move if it were released alone. For an awake particle it is read
//! from the step, `f_i ~ m_i dv_i / h`.
//!
//! A particle wakes when
//! - it lies within `focus_radius_m` of a focus point (the scalpel, [`super::Simulation::set_focus`]),
//!   found through a [`PointGrid`] of the positions (rebinned once the awake particles have
//!   moved by half a cell since);
//! - an external force acts on it, or a cut touched it ([`super::Simulation::wake`]);
//! - it neighbours (shares a spring with) an awake particle faster than `wake_speed_m_per_s`;
//! - it is on the border and its residual displacement exceeds `wake_displacement_m`. Such a
//!   border means the step just solved was held back: it is solved again with the border
//!   awake, up to `max_growth_rounds` times per step (so a disturbance, such as a cut
//!   releasing the pre-tension, spreads as far in one step as it does in the full solve).
//!
//! An awake particle outside the focus and unloaded falls asleep after `sleep_after_steps`
//! consecutive steps with speed below `sleep_speed_m_per_s` and residual displacement below
//! `sleep_displacement_m`; its velocity is then set to zero. Sleeping and waking are decided
//! in ascending particle order from the state alone, so a localised run is as deterministic
//! as a full one (a replay is bit-exact). Only the paper's springs with implicit Euler are
//! localised; other combinations run the full step.

use serde::{Deserialize, Serialize};

use crate::mesh::{Csr, PointGrid};
use crate::model::{Model, Particles, SpringSet, State};
use crate::{Point3, Vector3};

use super::StepError;
use super::forces::spring_force;
use super::implicit::{self, ImplicitScratch, ImplicitSolve};
use super::resume::{RegionResume, ResumeError, check_ids};
use super::system::CgReport;

/// Thresholds of the localisation (the `[solver.localisation]` table of a scene file).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalisationSettings {
    /// Particles within this distance of a focus point are always awake, m.
    pub focus_radius_m: f64,
    /// An awake particle faster than this wakes its neighbours, m/s.
    pub wake_speed_m_per_s: f64,
    /// A border particle whose residual displacement exceeds this wakes, m.
    pub wake_displacement_m: f64,
    /// Below this speed (m/s) ...
    pub sleep_speed_m_per_s: f64,
    /// ... and this residual displacement (m) ...
    pub sleep_displacement_m: f64,
    /// ... for this many consecutive steps, an awake particle falls asleep.
    pub sleep_after_steps: u32,
    /// Solves per step at most (the first, and the re-solves after the border woke).
    pub max_growth_rounds: u32,
}

impl Default for LocalisationSettings {
    fn default() -> Self {
        Self {
            focus_radius_m: 0.01,
            wake_speed_m_per_s: 1e-3,
            wake_displacement_m: 2e-6,
            sleep_speed_m_per_s: 2e-4,
            sleep_displacement_m: 5e-7,
            sleep_after_steps: 20,
            max_growth_rounds: 4,
        }
    }
}

impl LocalisationSettings {
    /// Every threshold (speeds and displacements) times `factor`: larger is faster and less
    /// accurate.
    pub fn scaled(self, factor: f64) -> Self {
        Self {
            wake_speed_m_per_s: self.wake_speed_m_per_s * factor,
            wake_displacement_m: self.wake_displacement_m * factor,
            sleep_speed_m_per_s: self.sleep_speed_m_per_s * factor,
            sleep_displacement_m: self.sleep_displacement_m * factor,
            ..self
        }
    }

    /// Checks every value: distances, speeds and displacements positive and finite, sleeping
    /// thresholds no higher than waking ones, at least one growth round.
    pub fn check(&self) -> Result<(), LocalisationError> {
        let positive = [
            ("focus_radius_m", self.focus_radius_m),
            ("wake_speed_m_per_s", self.wake_speed_m_per_s),
            ("wake_displacement_m", self.wake_displacement_m),
            ("sleep_speed_m_per_s", self.sleep_speed_m_per_s),
            ("sleep_displacement_m", self.sleep_displacement_m),
        ];
        for (name, value) in positive {
            if !(value > 0.0 && value.is_finite()) {
                return Err(LocalisationError::NotPositive { name, value });
            }
        }
        if self.sleep_speed_m_per_s > self.wake_speed_m_per_s {
            return Err(LocalisationError::SleepSpeedAboveWake);
        }
        if self.sleep_displacement_m > self.wake_displacement_m {
            return Err(LocalisationError::SleepDisplacementAboveWake);
        }
        if self.max_growth_rounds == 0 {
            return Err(LocalisationError::NoGrowthRounds);
        }
        Ok(())
    }
}

/// A [`LocalisationSettings`] value out of range.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum LocalisationError {
    /// A value that must be positive and finite is not.
    #[error("localisation.{name} must be positive, got {value}")]
    NotPositive {
        /// The setting's name.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// The speed below which particles sleep is above the one at which they wake.
    #[error("localisation.sleep_speed_m_per_s must not exceed wake_speed_m_per_s")]
    SleepSpeedAboveWake,
    /// The displacement below which particles sleep is above the one at which they wake.
    #[error("localisation.sleep_displacement_m must not exceed wake_displacement_m")]
    SleepDisplacementAboveWake,
    /// `max_growth_rounds` is zero.
    #[error("localisation.max_growth_rounds must be at least 1")]
    NoGrowthRounds,
}

const NONE: u32 = u32::MAX;

/// The springs around each particle, as the localised step reads them.
#[derive(Debug, Clone, Default)]
struct Adjacency {
    /// The springs at each particle, in the model's order.
    springs_at: Csr,
    /// `K_i`, the sum of the spring constants at each particle.
    stiffness_at: Vec<f64>,
    /// Whether the model's springs come sorted by their first end.
    sorted_by_first: bool,
    /// Whether this describes the model's springs (false until built, and after a cut).
    fresh: bool,
}

impl Adjacency {
    /// Built again for `springs` on `n` particles, unless fresh (into the buffers of the last:
    /// a cut changes the springs every few steps).
    fn refresh(&mut self, springs: &SpringSet, n: usize) {
        if self.fresh {
            return;
        }
        springs.by_particle_into(n, &mut self.springs_at);
        let csr = &self.springs_at;
        self.stiffness_at.clear();
        self.stiffness_at.extend((0..n).map(|i| {
            csr.row(i)
                .iter()
                .map(|&e| springs.stiffness[e as usize])
                .sum::<f64>()
        }));
        self.sorted_by_first = crate::model::sorted_by_first_end(&springs.ends);
        self.fresh = true;
    }
}

/// Steps between the moments quiet particles fall asleep (see [`ActiveRegion::decide`]).
pub const SLEEP_BATCH_STEPS: u64 = 10;

/// The awake set, its sub-body and the buffers of the localised step.
#[derive(Debug, Clone, Default)]
pub(crate) struct ActiveRegion {
    /// Per particle: awake, steps it has been quiet, pinned awake this step (focus, load).
    awake: Vec<bool>,
    quiet_steps: Vec<u32>,
    pinned: Vec<bool>,
    pinned_list: Vec<u32>,
    /// Awake particles (unsorted between rebuilds; entries put to sleep are dropped lazily).
    awake_list: Vec<u32>,
    awake_count: usize,
    /// Localised steps taken: particles fall asleep together every [`SLEEP_BATCH_STEPS`].
    step_count: u64,
    /// Particles to wake at the next step (cuts, neighbours, the border).
    to_wake: Vec<u32>,
    to_sleep: Vec<u32>,
    /// The springs around each particle (rebuilt when the model changes).
    adjacency: Adjacency,
    /// Positions binned for the focus query, and how far an awake particle has moved since.
    grid: Option<PointGrid>,
    grid_slack_m: f64,
    /// Focus points (the scalpel).
    pub focus: Vec<Point3>,
    /// The sub-body: its particles' global ids (ascending) and the local id of each particle.
    dirty: bool,
    global_of: Vec<u32>,
    local_of: Vec<u32>,
    local_spring_ids: Vec<u32>,
    springs: SpringSet,
    mass: Vec<f64>,
    held: Vec<bool>,
    state: State,
    external: Vec<Vector3>,
    implicit: ImplicitScratch,
    /// The warm-start history by global particle: `dv` and the three before.
    history: [Vec<Vector3>; 4],
    /// The sub-body's warm start before this step's first solve (restored for a re-solve).
    saved_history: [Vec<Vector3>; 4],
    /// A growth round's solution by global particle, to start the next round from.
    round_dv: Vec<(u32, Vector3)>,
    saved_history_count: usize,
}

impl ActiveRegion {
    /// Particles awake after the last step.
    pub fn awake_count(&self) -> usize {
        debug_assert_eq!(self.awake_count, self.awake.iter().filter(|a| **a).count());
        self.awake_count
    }

    /// Call after the model changed (a cut), with the `positions` after it: new particles
    /// wake; the adjacency and the sub-body are rebuilt at the next step. The grid bins the new
    /// particles and widens its queries by how far any particle now lies from where it was
    /// binned (a cut moves vertices onto its plane), so they find the same particles a grid
    /// built anew would.
    pub fn model_changed(&mut self, positions: &[Point3]) {
        if self.awake.is_empty() {
            return; // not started: everything wakes at the first localised step
        }
        let n = positions.len();
        if let Some(grid) = &mut self.grid {
            let old = grid.len().min(n);
            let moved = (0..old)
                .map(|i| (positions[i] - grid.binned_position(i)).norm())
                .fold(0.0, f64::max);
            // (a NaN position: rebinned, as the step would)
            if moved.is_nan() || old < grid.len() {
                self.grid = None;
            } else {
                self.grid_slack_m = self.grid_slack_m.max(moved);
                grid.extend(positions);
            }
        }
        let old = self.awake.len().min(n);
        self.awake.resize(n, false);
        self.quiet_steps.resize(n, 0);
        self.pinned.resize(n, false);
        self.local_of.resize(n, NONE);
        for h in &mut self.history {
            h.resize(n, Vector3::zeros());
        }
        self.to_wake.extend(old as u32..n as u32);
        self.adjacency.fresh = false;
        self.dirty = true;
    }

    /// Call after the positions jumped outside a step (a static solve): the grid is rebinned.
    pub fn state_moved(&mut self) {
        self.grid = None;
    }

    /// Forgets the warm start.
    pub fn reset_warm_start(&mut self) {
        for h in &mut self.history {
            h.iter_mut().for_each(|d| *d = Vector3::zeros());
        }
        self.implicit.reset_warm_start();
    }

    /// What the next localised step needs of this region (None before the first one).
    pub fn resume_state(&self) -> Option<RegionResume> {
        if self.awake.is_empty() {
            return None;
        }
        let awake = self
            .awake
            .iter()
            .enumerate()
            .filter(|(_, a)| **a)
            .map(|(v, _)| v as u32)
            .collect();
        let quiet_steps = self
            .quiet_steps
            .iter()
            .enumerate()
            .filter(|(_, q)| **q > 0)
            .map(|(v, &q)| (v as u32, q))
            .collect();
        Some(RegionResume {
            awake,
            quiet_steps,
            step_count: self.step_count,
            to_wake: self.to_wake.clone(),
            dirty: self.dirty,
            sub_body: self.global_of.clone(),
            warm_start: self.implicit.warm_start(),
        })
    }

    /// The region a [`RegionResume`] describes, over `model` (see [`super::resume`]). The
    /// warm start outside the sub-body is zero (a particle leaves the sub-body asleep, and a
    /// sleeper's warm start is zero); a clean sub-body is gathered again from the awake set,
    /// with the warm start kept as captured.
    pub(crate) fn resume(model: &Model, r: &RegionResume) -> Result<Self, ResumeError> {
        let n = model.vertex_count();
        check_ids(&r.awake, n, "awake particles")?;
        check_ids(&r.sub_body, n, "sub-body")?;
        if let Some(v) = r
            .to_wake
            .iter()
            .chain(r.quiet_steps.iter().map(|(v, _)| v))
            .find(|&&v| v as usize >= n)
        {
            return Err(ResumeError::Invalid(format!(
                "particle {v} of {n} queued to wake or quiet"
            )));
        }
        r.warm_start
            .check(r.sub_body.len(), "localised step", false)?;
        let mut me = Self {
            awake: vec![false; n],
            quiet_steps: vec![0; n],
            pinned: vec![false; n],
            local_of: vec![NONE; n],
            history: std::array::from_fn(|_| vec![Vector3::zeros(); n]),
            step_count: r.step_count,
            to_wake: r.to_wake.clone(),
            awake_list: r.awake.clone(),
            awake_count: r.awake.len(),
            ..Self::default()
        };
        r.awake.iter().for_each(|&v| me.awake[v as usize] = true);
        r.quiet_steps
            .iter()
            .for_each(|&(v, q)| me.quiet_steps[v as usize] = q);
        if r.dirty {
            // the next step gathers the sub-body again, starting from this one's warm start
            me.global_of.clone_from(&r.sub_body);
            for (l, &g) in me.global_of.iter().enumerate() {
                me.local_of[g as usize] = l as u32;
            }
        } else {
            me.adjacency.refresh(&model.springs, n);
            me.rebuild(model);
            if me.global_of != r.sub_body {
                return Err(ResumeError::Invalid(
                    "the sub-body differs from the one the awake particles make".into(),
                ));
            }
        }
        me.implicit.install_warm_start(&r.warm_start);
        me.dirty = r.dirty;
        Ok(me)
    }

    /// Wakes `vertices` at the next step.
    pub fn wake(&mut self, vertices: impl IntoIterator<Item = u32>) {
        if !self.awake.is_empty() {
            self.to_wake.extend(vertices);
        }
    }

    /// Starts from everything awake (the first localised step), and rebuilds what a model
    /// change invalidated.
    fn ensure(&mut self, model: &Model, state: &State, settings: &LocalisationSettings) {
        let n = model.vertex_count();
        if self.awake.len() != n {
            *self = Self {
                focus: std::mem::take(&mut self.focus),
                ..Self::default()
            };
            self.awake = vec![false; n];
            self.quiet_steps = vec![0; n];
            self.pinned = vec![false; n];
            self.local_of = vec![NONE; n];
            self.history = std::array::from_fn(|_| vec![Vector3::zeros(); n]);
            self.to_wake.extend(0..n as u32);
            self.dirty = true;
        }
        self.adjacency.refresh(&model.springs, n);
        if self.grid.is_none() || self.grid_slack_m > 0.5 * settings.focus_radius_m {
            self.grid = Some(PointGrid::build(&state.positions, settings.focus_radius_m));
            self.grid_slack_m = 0.0;
        }
    }

    /// One localised backward-Euler step of `h` seconds (see the module documentation).
    /// `loaded` lists the particles with an external force (any order, duplicates allowed).
    /// Returns the last solve's report (with the iterations of all) and the number of solves.
    #[allow(clippy::too_many_arguments)]
    pub fn step(
        &mut self,
        model: &Model,
        state: &mut State,
        external: &[Vector3],
        loaded: &[u32],
        settings: &LocalisationSettings,
        h: f64,
        solve: ImplicitSolve,
    ) -> Result<(CgReport, u32), StepError> {
        self.ensure(model, state, settings);
        self.pin(model, state, loaded, settings);
        self.apply_wakes(model);
        let mut total = CgReport {
            iterations: 0,
            relative_residual: 0.0,
            converged: true,
        };
        if self.dirty {
            self.rebuild(model);
        }
        self.save_history();
        let mut solves = 0;
        for round in 1..=settings.max_growth_rounds {
            solves = round;
            let report = self.solve(model, state, external, h, solve)?;
            total = CgReport {
                iterations: total.iterations + report.iterations,
                ..report
            };
            // a border that was held back is woken, and the step solved again with it
            let grew = self.wake_border(model, state, external, settings);
            if grew == 0 || round == settings.max_growth_rounds {
                break;
            }
            // the next round starts from this one's solution where it had one (the woken
            // border from the extrapolation): it differs from it mostly near that border
            self.round_dv.clear();
            let solved = self.global_of.iter().zip(&self.held).zip(&self.implicit.dv);
            self.round_dv.extend(
                solved
                    .filter(|((_, held), _)| !**held)
                    .map(|((&g, _), &d)| (g, d)),
            );
            self.restore_history();
            self.apply_wakes(model);
            self.rebuild(model);
            self.save_history();
            let m = self.global_of.len();
            let guess = &mut self.implicit.guess;
            guess.clear();
            guess.resize(m, None);
            for &(g, d) in &self.round_dv {
                if let Some(&l) = self.local_of.get(g as usize).filter(|&&l| l != NONE) {
                    guess[l as usize] = Some(d);
                }
            }
        }

        // Scatter the awake particles.
        let grid = self.grid.as_ref().expect("built by ensure");
        for (l, &g) in self.global_of.iter().enumerate() {
            if !self.held[l] {
                let g = g as usize;
                state.positions[g] = self.state.positions[l];
                state.velocities[g] = self.state.velocities[l];
                if g < grid.len() {
                    self.grid_slack_m = self
                        .grid_slack_m
                        .max((state.positions[g] - grid.binned_position(g)).norm());
                }
            }
        }
        if self.grid_slack_m > 0.5 * settings.focus_radius_m {
            self.grid = None;
        }
        self.step_count += 1;
        self.decide(model, state, settings, h);
        Ok((total, solves))
    }

    /// Gathers the sub-body (the border held, at rest) and solves it; the global state is
    /// not touched.
    fn solve(
        &mut self,
        model: &Model,
        state: &State,
        external: &[Vector3],
        h: f64,
        solve: ImplicitSolve,
    ) -> Result<CgReport, StepError> {
        for (l, &g) in self.global_of.iter().enumerate() {
            let g = g as usize;
            self.state.positions[l] = state.positions[g];
            self.state.velocities[l] = if self.held[l] {
                Vector3::zeros()
            } else {
                state.velocities[g]
            };
            self.external[l] = external[g];
        }
        let particles = Particles {
            mass: &self.mass,
            held: &self.held,
            springs: &self.springs,
            gravity: model.gravity,
        };
        let report = implicit::step(
            &particles,
            &mut self.state,
            &self.external,
            h,
            solve,
            &mut self.implicit,
        );
        if !report.relative_residual.is_finite() {
            self.reset_warm_start();
            return Err(StepError::SolverFailed {
                residual: report.relative_residual,
            });
        }
        let bad: Vec<u32> = self
            .state
            .non_finite_particles()
            .into_iter()
            .map(|l| self.global_of[l as usize])
            .collect();
        if !bad.is_empty() {
            self.reset_warm_start();
            return Err(StepError::NonFinite { vertices: bad });
        }
        Ok(report)
    }

    fn save_history(&mut self) {
        let ImplicitScratch {
            dv,
            dv_previous: [p1, p2, p3],
            history,
            ..
        } = &self.implicit;
        for (saved, local) in self.saved_history.iter_mut().zip([dv, p1, p2, p3]) {
            saved.clone_from(local);
        }
        self.saved_history_count = *history;
    }

    fn restore_history(&mut self) {
        let ImplicitScratch {
            dv,
            dv_previous: [p1, p2, p3],
            history,
            ..
        } = &mut self.implicit;
        for (saved, local) in self.saved_history.iter().zip([dv, p1, p2, p3]) {
            local.clone_from(saved);
        }
        *history = self.saved_history_count;
    }

    /// Queues the border particles whose residual displacement (with the sub-body's solved
    /// positions) exceeds the wake threshold; returns how many.
    fn wake_border(
        &mut self,
        model: &Model,
        state: &State,
        external: &[Vector3],
        settings: &LocalisationSettings,
    ) -> usize {
        let springs_at = &self.adjacency.springs_at;
        let s = &model.springs;
        let before = self.to_wake.len();
        let position = |g: usize| match self.local_of[g] {
            NONE => (state.positions[g], state.velocities[g]),
            l => (
                self.state.positions[l as usize],
                self.state.velocities[l as usize],
            ),
        };
        for (l, &g) in self.global_of.iter().enumerate() {
            let gi = g as usize;
            if !self.held[l] || model.held[gi] {
                continue;
            }
            let mut f = model.gravity * model.mass[gi] + external[gi];
            for &e in springs_at.row(gi) {
                let e = e as usize;
                let [a, b] = s.ends[e].map(|v| v as usize);
                let ((xa, va), (xb, vb)) = (position(a), position(b));
                let pull = spring_force(
                    &(xb - xa),
                    &(vb - va),
                    s.rest_length[e],
                    s.stiffness[e],
                    s.damping[e],
                );
                f += if a == gi { pull } else { -pull };
            }
            if f.norm() > settings.wake_displacement_m * self.adjacency.stiffness_at[gi] {
                self.to_wake.push(g);
            }
        }
        self.to_wake.len() - before
    }

    /// Pins (and wakes) the particles near a focus point and the loaded ones for this step.
    fn pin(
        &mut self,
        model: &Model,
        state: &State,
        loaded: &[u32],
        settings: &LocalisationSettings,
    ) {
        for &v in &self.pinned_list {
            self.pinned[v as usize] = false;
        }
        self.pinned_list.clear();
        let (pinned, list) = (&mut self.pinned, &mut self.pinned_list);
        let mut pin = |v: u32| {
            let i = v as usize;
            if i < pinned.len() && !model.held[i] && !pinned[i] {
                pinned[i] = true;
                list.push(v);
            }
        };
        let grid = self.grid.as_ref().expect("built by ensure");
        let r = settings.focus_radius_m;
        for f in &self.focus {
            grid.for_each_within(f, r + self.grid_slack_m, |v| {
                if (state.positions[v as usize] - f).norm() <= r {
                    pin(v);
                }
            });
        }
        loaded.iter().for_each(|&v| pin(v));
        self.to_wake.extend_from_slice(&self.pinned_list);
    }

    fn apply_wakes(&mut self, model: &Model) {
        for v in self.to_wake.drain(..) {
            let i = v as usize;
            if i < self.awake.len() && !self.awake[i] && !model.held[i] {
                self.awake[i] = true;
                self.quiet_steps[i] = 0;
                self.awake_list.push(v);
                self.awake_count += 1;
                self.dirty = true;
            }
        }
    }

    /// Rebuilds the sub-body for the current awake set, carrying the warm start over.
    fn rebuild(&mut self, model: &Model) {
        // the old sub-body's warm start back to the global history (zero for sleepers)
        for (l, &g) in self.global_of.iter().enumerate() {
            let g = g as usize;
            let ImplicitScratch {
                dv,
                dv_previous: [p1, p2, p3],
                ..
            } = &self.implicit;
            let awake = self.awake[g];
            for (h, local) in self.history.iter_mut().zip([dv, p1, p2, p3]) {
                h[g] = if awake {
                    local.get(l).copied().unwrap_or_default()
                } else {
                    Vector3::zeros()
                };
            }
            self.local_of[g] = NONE;
        }
        let awake = &self.awake;
        self.awake_list.retain(|&v| awake[v as usize]);
        self.awake_list.sort_unstable();
        // a particle that fell asleep and woke again since the last rebuild is listed twice
        self.awake_list.dedup();
        let springs_at = &self.adjacency.springs_at;
        let ends = &model.springs.ends;
        self.global_of.clear();
        self.local_spring_ids.clear();
        for &g in &self.awake_list {
            self.local_of[g as usize] = 0;
            self.global_of.push(g);
        }
        for &g in &self.awake_list {
            for &e in springs_at.row(g as usize) {
                let [a, b] = ends[e as usize];
                let other = if a == g { b } else { a };
                if !self.awake[other as usize] && self.local_of[other as usize] == NONE {
                    self.local_of[other as usize] = 0;
                    self.global_of.push(other);
                }
            }
        }
        self.global_of.sort_unstable();
        for (l, &g) in self.global_of.iter().enumerate() {
            self.local_of[g as usize] = l as u32;
        }
        // the springs with an awake end, each from its first end (which is in the sub-body):
        // the rows list them in the model's order, so they come sorted where the model's
        // springs are sorted by their first end (as a model's are), and need no sort
        let awake = &self.awake;
        for &g in &self.global_of {
            for &e in springs_at.row(g as usize) {
                let [a, b] = ends[e as usize];
                if a == g && (awake[a as usize] || awake[b as usize]) {
                    self.local_spring_ids.push(e);
                }
            }
        }
        if !self.adjacency.sorted_by_first {
            self.local_spring_ids.sort_unstable();
        }
        let s = &model.springs;
        let local = &mut self.springs;
        local.ends.clear();
        local.rest_length.clear();
        local.stiffness.clear();
        local.damping.clear();
        for &e in &self.local_spring_ids {
            let e = e as usize;
            local
                .ends
                .push(s.ends[e].map(|v| self.local_of[v as usize]));
            local.rest_length.push(s.rest_length[e]);
            local.stiffness.push(s.stiffness[e]);
            local.damping.push(s.damping[e]);
        }
        let m = self.global_of.len();
        self.mass.clear();
        self.held.clear();
        for &g in &self.global_of {
            self.mass.push(model.mass[g as usize]);
            self.held.push(!self.awake[g as usize]);
        }
        self.state.positions.resize(m, Point3::origin());
        self.state.velocities.resize(m, Vector3::zeros());
        self.external.resize(m, Vector3::zeros());
        let ImplicitScratch {
            dv,
            dv_previous: [p1, p2, p3],
            ..
        } = &mut self.implicit;
        for (h, local) in self.history.iter().zip([dv, p1, p2, p3]) {
            local.clear();
            local.extend(self.global_of.iter().map(|&g| h[g as usize]));
        }
        self.dirty = false;
    }

    /// Who wakes at the next step (the neighbours of fast particles) and who falls asleep now.
    fn decide(
        &mut self,
        model: &Model,
        state: &mut State,
        settings: &LocalisationSettings,
        h: f64,
    ) {
        let springs_at = &self.adjacency.springs_at;
        let s = &model.springs;
        self.to_sleep.clear();
        for (l, &g) in self.global_of.iter().enumerate() {
            let gi = g as usize;
            if self.held[l] {
                continue;
            }
            let speed = state.velocities[gi].norm();
            if speed > settings.wake_speed_m_per_s {
                for &e in springs_at.row(gi) {
                    let [a, b] = s.ends[e as usize];
                    let other = if a == g { b } else { a };
                    if !self.awake[other as usize] && !model.held[other as usize] {
                        self.to_wake.push(other);
                    }
                }
            }
            // residual displacement m |dv| / (h K)
            let residual_m =
                model.mass[gi] * self.implicit.dv[l].norm() / (h * self.adjacency.stiffness_at[gi]);
            let quiet = !self.pinned[gi]
                && speed < settings.sleep_speed_m_per_s
                && residual_m < settings.sleep_displacement_m;
            self.quiet_steps[gi] = if quiet { self.quiet_steps[gi] + 1 } else { 0 };
            if self.quiet_steps[gi] >= settings.sleep_after_steps {
                self.to_sleep.push(g);
            }
        }
        // Sleepers are let go in batches, so that the sub-body is not rebuilt at every step
        // for one particle more or less (a quiet particle waits at most this many steps more).
        if !self.step_count.is_multiple_of(SLEEP_BATCH_STEPS) {
            return;
        }
        for &g in &self.to_sleep {
            let gi = g as usize;
            self.awake[gi] = false;
            self.quiet_steps[gi] = 0;
            state.velocities[gi] = Vector3::zeros();
            self.awake_count -= 1;
            self.dirty = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{BuildOptions, Scene};
    use crate::solver::StaticSettings;

    #[test]
    fn the_awake_count_and_the_sub_body_stay_consistent_while_particles_sleep_and_wake() {
        let scene = Scene::load(
            "chest-wall",
            BuildOptions {
                min_tets: Some(3_000),
            },
        )
        .expect("built-in scene");
        let mut sim = scene.simulation();
        assert!(sim.settle(StaticSettings::default()).converged);
        let z = sim
            .state
            .positions
            .iter()
            .map(|p| p.z)
            .fold(f64::NEG_INFINITY, f64::max);
        let surface: Vec<u32> = sim.model.mesh.topology().boundary_vertices();
        // (the springs reversed as well: no longer sorted by their first end)
        for (scale, reversed) in [(1.0, false), (30.0, false), (1.0, true)] {
            let mut sim = sim.clone();
            if reversed {
                let s = &mut sim.model.springs;
                for v in [&mut s.rest_length, &mut s.stiffness, &mut s.damping] {
                    v.reverse();
                }
                s.ends.reverse();
            }
            sim.settings.localisation = Some(LocalisationSettings::default().scaled(scale));
            for step in 0..800 {
                // a tool tapping along a circle: particles enter and leave its focus, and the
                // border wakes and falls asleep again
                let a = step as f64 * 0.03;
                let tip = Point3::new(0.02 * a.cos(), 0.02 * a.sin(), z);
                sim.clear_external_forces();
                sim.set_focus(&[tip]);
                if step % 40 < 20 {
                    let near = surface
                        .iter()
                        .copied()
                        .filter(|&v| (sim.state.positions[v as usize] - tip).norm() < 0.005);
                    for v in near.collect::<Vec<_>>() {
                        sim.add_external_force(v, Vector3::new(0.0, 0.0, -0.05));
                    }
                }
                sim.step().expect("step");
                if step % 50 == 49 {
                    // as a cut does: wakes particles, some of which just fell asleep
                    sim.wake(0..sim.model.vertex_count() as u32);
                }
                let r = &sim.region;
                assert_eq!(
                    r.awake_count,
                    r.awake.iter().filter(|a| **a).count(),
                    "x{scale} step {step}: awake count"
                );
                assert!(
                    r.global_of.windows(2).all(|w| w[0] < w[1]),
                    "x{scale} step {step}: a particle twice in the sub-body"
                );
                if !r.dirty {
                    let ends = &sim.model.springs.ends;
                    let with_awake_end = (0..ends.len() as u32)
                        .filter(|&e| ends[e as usize].iter().any(|&v| r.awake[v as usize]));
                    assert!(
                        r.local_spring_ids.iter().copied().eq(with_awake_end),
                        "x{scale} {reversed} step {step}: the sub-body's springs"
                    );
                }
            }
        }
    }
}
