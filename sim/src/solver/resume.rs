//! Resuming a simulation at a step it reached before: what, beyond the positions, velocities
//! and mesh, decides the steps after it.
//!
//! A step reads the model (masses, springs, held particles: derived again from the mesh by
//! [`crate::model::Model::rebuild`], with the same bits as the cuts that led there carried
//! over), the state, and what the solver keeps from step to step: the implicit integrator's
//! last four velocity changes (the warm start: their span, [`super::span`], and their
//! extrapolation, [`super::implicit::extrapolate_warm_start`]), the whole-body step's sweep
//! order (carried across cuts, [`super::dissection`]) and, localised, which particles are
//! awake, how long each has been quiet, the wakes queued for the next step and the sub-body the
//! warm start is laid out on. [`ResumeState`] holds exactly that, so that
//! [`Simulation::resume`] from a state captured by [`Simulation::resume_state`] continues bit
//! for bit as the original run did (a recording's keyframes carry one; a replay seeks through
//! them). Scratch buffers are not part of it.

use serde::{Deserialize, Serialize};

use super::implicit::ImplicitScratch;
use super::localise::ActiveRegion;
use super::system::SweepOrder;
use super::{Scratch, Simulation};
use crate::Vector3;
use crate::mesh::TetMesh;
use crate::model::{ModelError, State};

/// The implicit integrator's warm start: per particle, the last velocity change and the three
/// before it (`dv`, `dv_1`, `dv_2`, `dv_3`), and how many of them hold solutions.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct WarmStart {
    /// How many of the four velocity changes hold solutions (0 to 4).
    pub count: usize,
    /// Per particle, `[dv, dv_1, dv_2, dv_3]`.
    pub rows: Vec<[Vector3; 4]>,
    /// The last SSOR-preconditioned CG solve's ratio of true to preconditioned relative
    /// residual, which the next solve's stopping test starts from (0: none yet). Read as 0
    /// when null: recordings made before the ratio was kept finite carry an exact solve's as
    /// null, which the solver read as none.
    #[serde(default, deserialize_with = "null_as_none")]
    pub cg_residual_ratio: f64,
}

fn null_as_none<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(0.0))
}

impl WarmStart {
    pub(crate) fn of(dv: &[Vector3], [p1, p2, p3]: &[Vec<Vector3>; 3], count: usize) -> Self {
        let rows = dv
            .iter()
            .zip(p1)
            .zip(p2)
            .zip(p3)
            .map(|(((&a, &b), &c), &d)| [a, b, c, d])
            .collect();
        Self {
            count,
            rows,
            cg_residual_ratio: 0.0,
        }
    }

    /// Writes the warm start into a solver's buffers.
    pub(crate) fn install(
        &self,
        dv: &mut Vec<Vector3>,
        [p1, p2, p3]: &mut [Vec<Vector3>; 3],
        count: &mut usize,
    ) {
        for (k, buf) in [dv, p1, p2, p3].into_iter().enumerate() {
            buf.clear();
            buf.extend(self.rows.iter().map(|r| r[k]));
        }
        *count = self.count;
    }

    /// Whether this fits `rows` particles: as many rows, none, or (`fewer_allowed`, the
    /// whole-body steps) fewer, for a state captured after a cut added particles and before the
    /// next step gave them their zero rows.
    pub(crate) fn check(
        &self,
        rows: usize,
        what: &str,
        fewer_allowed: bool,
    ) -> Result<(), ResumeError> {
        if self.count > 4 {
            return Err(ResumeError::Invalid(format!(
                "{what}: warm-start count {} (at most 4)",
                self.count
            )));
        }
        if !self.rows.is_empty()
            && self.rows.len() != rows
            && !(fewer_allowed && self.rows.len() < rows)
        {
            return Err(ResumeError::Invalid(format!(
                "{what}: {} warm-start rows for {rows} particles",
                self.rows.len()
            )));
        }
        if !(self.cg_residual_ratio >= 0.0 && self.cg_residual_ratio.is_finite()) {
            return Err(ResumeError::Invalid(format!(
                "{what}: CG residual ratio {}",
                self.cg_residual_ratio
            )));
        }
        if !self
            .rows
            .iter()
            .flatten()
            .flat_map(|v| v.iter())
            .all(|c| c.is_finite())
        {
            return Err(ResumeError::Invalid(format!(
                "{what}: a non-finite warm start"
            )));
        }
        Ok(())
    }
}

/// The warm start of a solver's scratch (the springs' and the finite elements' keep the same
/// fields): its past velocity changes and its CG's residual ratio.
macro_rules! warm_start_of {
    ($scratch:ty) => {
        impl $scratch {
            /// Forgets the past velocity changes (after a jump of the state).
            pub fn reset_warm_start(&mut self) {
                let [p1, p2, p3] = &mut self.dv_previous;
                for buf in [&mut self.dv, p1, p2, p3] {
                    buf.iter_mut().for_each(|d| *d = crate::Vector3::zeros());
                }
                self.history = 0;
            }

            pub(crate) fn warm_start(&self) -> WarmStart {
                WarmStart {
                    cg_residual_ratio: self.cg.residual_ratio,
                    ..WarmStart::of(&self.dv, &self.dv_previous, self.history)
                }
            }

            pub(crate) fn install_warm_start(&mut self, w: &WarmStart) {
                w.install(&mut self.dv, &mut self.dv_previous, &mut self.history);
                self.cg.residual_ratio = w.cg_residual_ratio;
            }
        }
    };
}

warm_start_of!(ImplicitScratch);
warm_start_of!(crate::fem::solve::FemScratch);

/// What a localised simulation carries from one step to the next (see the module
/// documentation): ids are global particle ids.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegionResume {
    /// Awake particles, ascending.
    pub awake: Vec<u32>,
    /// Particles quiet for some steps, and for how many.
    pub quiet_steps: Vec<(u32, u32)>,
    /// Localised steps taken (particles fall asleep in batches every few steps).
    pub step_count: u64,
    /// Particles queued to wake at the next step.
    pub to_wake: Vec<u32>,
    /// The sub-body must be gathered again at the next step (the awake set changed).
    pub dirty: bool,
    /// The particles of the sub-body (ascending).
    pub sub_body: Vec<u32>,
    /// The sub-body's warm start, a row per particle of `sub_body`.
    pub warm_start: WarmStart,
}

/// What a simulation carries from one step to the next beyond its state and mesh.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResumeState {
    /// Steps taken.
    pub step_index: u64,
    /// Held particles, ascending.
    pub held: Vec<u32>,
    /// The warm start of the whole-body implicit step (springs).
    pub warm_start: WarmStart,
    /// The warm start of the finite elements' implicit step.
    #[serde(default)]
    pub fem_warm_start: WarmStart,
    /// The localised step's region, once it has stepped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region: Option<RegionResume>,
    /// The whole-body step's sweep order, once it has stepped (carried across cuts, see
    /// [`super::system::SpringSystem::carry_sweep_order`]). Without it (older recordings) the
    /// order is found anew, which after cuts can differ from the captured run's in the last
    /// bits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sweep_order: Option<SweepOrder>,
}

/// A resume state that does not fit the mesh it comes with.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ResumeError {
    /// A part of the state does not fit the mesh (says which).
    #[error("resume state: {0}")]
    Invalid(String),
    /// The sweep order does not fit the particles.
    #[error("resume state: {0}")]
    SweepOrder(#[from] super::system::SweepOrderError),
    /// The model could not be rebuilt with the held particles given.
    #[error("resume state: rebuilding the model: {0}")]
    Model(#[from] ModelError),
}

/// Checks that `ids` are ascending (strictly) and below `n`.
pub(crate) fn check_ids(ids: &[u32], n: usize, what: &str) -> Result<(), ResumeError> {
    if let Some(&v) = ids.iter().find(|&&v| v as usize >= n) {
        return Err(ResumeError::Invalid(format!("{what}: particle {v} of {n}")));
    }
    if !ids.windows(2).all(|w| w[0] < w[1]) {
        return Err(ResumeError::Invalid(format!(
            "{what}: ids not strictly ascending"
        )));
    }
    Ok(())
}

impl Simulation {
    /// What [`Self::resume`] needs, beyond the state and the mesh, to continue from here.
    pub fn resume_state(&self) -> ResumeState {
        ResumeState {
            step_index: self.step_index,
            held: self
                .model
                .held
                .iter()
                .enumerate()
                .filter(|(_, h)| **h)
                .map(|(v, _)| v as u32)
                .collect(),
            warm_start: self.scratch.implicit.warm_start(),
            fem_warm_start: self.scratch.fem.warm_start(),
            region: self.region.resume_state(),
            sweep_order: self.scratch.implicit.system.sweep_order(),
        }
    }

    /// Continues from a captured step: the model is derived again from `mesh` (by the same
    /// rules as at the start and after every cut, with this simulation's materials), the state
    /// set, and the solver's warm start and localised region restored from `resume`. The
    /// following steps are bit-identical to those the captured run took. Inconsistent input
    /// (sizes, ids, non-finite values) is an error and leaves the simulation unchanged.
    pub fn resume(
        &mut self,
        mesh: TetMesh,
        state: State,
        resume: &ResumeState,
    ) -> Result<(), ResumeError> {
        let n = mesh.vertex_count();
        if state.positions.len() != n || state.velocities.len() != n {
            return Err(ResumeError::Invalid(format!(
                "{} positions and {} velocities for {n} vertices",
                state.positions.len(),
                state.velocities.len()
            )));
        }
        if !state
            .positions
            .iter()
            .map(|p| &p.coords)
            .chain(&state.velocities)
            .flat_map(|v| v.iter())
            .all(|c| c.is_finite())
        {
            return Err(ResumeError::Invalid(
                "a non-finite position or velocity".into(),
            ));
        }
        check_ids(&resume.held, n, "held particles")?;
        resume.warm_start.check(n, "whole-body step", true)?;
        resume.fem_warm_start.check(n, "finite elements", true)?;
        if let Some(order) = &resume.sweep_order {
            order.check(n)?;
        }
        let mut held = vec![false; n];
        resume.held.iter().for_each(|&v| held[v as usize] = true);
        let mut model = self.model.clone();
        model.rebuild(mesh, held)?;
        let mut region = match &resume.region {
            Some(r) => ActiveRegion::resume(&model, r)?,
            None => ActiveRegion::default(),
        };
        let mut scratch = Scratch::new();
        scratch.implicit.install_warm_start(&resume.warm_start);
        if let Some(order) = &resume.sweep_order {
            scratch.implicit.system.install_sweep_order(order);
        }
        scratch.fem.install_warm_start(&resume.fem_warm_start);

        self.model = model;
        self.state = state;
        self.external_forces = vec![Vector3::zeros(); n];
        self.loaded.clear();
        self.loaded_unknown = false;
        region.focus = std::mem::take(&mut self.region.focus);
        self.region = region;
        self.explicit_substeps = None;
        self.step_index = resume.step_index;
        self.scratch = scratch;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::WarmStart;

    #[test]
    fn a_null_cg_residual_ratio_reads_as_none() {
        let read = |json: &str| {
            serde_json::from_str::<WarmStart>(json)
                .expect("reads")
                .cg_residual_ratio
        };
        assert_eq!(
            read(r#"{"count":4,"rows":[],"cg_residual_ratio":null}"#),
            0.0
        );
        assert_eq!(read(r#"{"count":4,"rows":[]}"#), 0.0);
        assert_eq!(
            read(r#"{"count":4,"rows":[],"cg_residual_ratio":0.5}"#),
            0.5
        );
        assert!(
            serde_json::from_str::<WarmStart>(r#"{"count":4,"rows":[],"cg_residual_ratio":"x"}"#)
                .is_err()
        );
    }
}
