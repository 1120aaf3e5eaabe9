//! An attempt's data from its recording: the tool poses and forces of every servo tick, the
//! blade path while it was in the tissue, and the deformed tissue surface of the last
//! keyframe.

use cutlab_recorder::haptics::pose::BUTTON_BLADE;
use cutlab_recorder::channels::ModeName;
use cutlab_recorder::Recording;
use cutlab_sim::TetMesh;

use crate::input::{AttemptData, CutSample, ForceSample, PoseSample, SurfaceMesh};
use crate::metrics::incision::depth_below_plan;
use crate::plan::ExpertPlan;
use crate::AssessError;

/// The data `plan` is assessed on, from `rec`. A cut sample's depth is its blade tip's depth
/// below the planned surface (`depth_below_plan`).
pub fn attempt_data(rec: &Recording, plan: &ExpertPlan) -> Result<AttemptData, AssessError> {
    let meta = rec.meta().map_err(|e| AssessError::InvalidInput(e.to_string()))?;
    let period_s = meta.period_nanos as f64 * 1e-9;
    let buttons: std::collections::HashMap<u64, u32> = rec.tool_states.iter().map(|s| (s.tick, s.buttons)).collect();
    let poses = rec
        .poses
        .iter()
        .map(|(tick, tip, rotation)| {
            let q = rotation.quaternion();
            PoseSample {
                t_s: *tick as f64 * period_s,
                tip_m: tip.coords.into(),
                quat_wxyz: [q.w, q.i, q.j, q.k],
                blade_engaged: buttons.get(tick).is_some_and(|b| b & BUTTON_BLADE != 0),
            }
        })
        .collect();
    let forces = rec
        .tool_states
        .iter()
        .map(|s| ForceSample { t_s: s.tick as f64 * period_s, force_newtons: s.force_newtons, touching: s.mode == ModeName::Touching, cutting: s.mode == ModeName::Cutting })
        .collect();
    // The cut's trace: the blade at every tick the renderer had it in the tissue (the blade
    // path; the topology events only mark where the mesh changed, a few per centimetre on a
    // coarse mesh).
    let modes: std::collections::HashMap<u64, ModeName> = rec.tool_states.iter().map(|s| (s.tick, s.mode)).collect();
    let cuts = rec
        .poses
        .iter()
        .filter(|(tick, _, _)| modes.get(tick) == Some(&ModeName::Cutting))
        .map(|(tick, tip, rotation)| {
            let edge = rotation * nalgebra::Vector3::z();
            let tip_m: [f64; 3] = tip.coords.into();
            CutSample { t_s: *tick as f64 * period_s, tip_m, edge_dir: edge.into(), depth_m: depth_below_plan(plan, tip_m) }
        })
        .collect();
    Ok(AttemptData { poses, forces, cuts, surface: last_surface(rec) })
}

/// The boundary of the last keyframe's mesh at its deformed positions.
fn last_surface(rec: &Recording) -> Option<SurfaceMesh> {
    let k = rec.keyframes.last()?;
    let rest = k.rest_positions_m.iter().map(|&p| cutlab_sim::Point3::from(p)).collect();
    let mesh = TetMesh::new(rest, k.tets.clone(), k.regions.clone()).ok()?;
    let triangles = mesh.topology().boundary.iter().map(|t| [t[0], t[1], t[2]]).collect();
    Some(SurfaceMesh { vertices_m: k.positions_m.clone(), triangles })
}

impl crate::store::Store {
    /// The user `name`; a new name becomes a trainee without a password (who cannot log in
    /// until an administrator sets one).
    pub async fn trainee_named(&self, name: &str) -> crate::Result<crate::store::User> {
        match self.user_by_name(name).await {
            Err(AssessError::NotFound(_)) => self.create_user(name, crate::store::Role::Trainee, None).await,
            other => other,
        }
    }

    /// Starts an attempt (status running) at exercise `exercise` by `trainee` (created when
    /// new), recorded at `recording`.
    pub async fn start_recorded_attempt(&self, exercise: &str, trainee: &str, recording: &std::path::Path, expert: bool) -> crate::Result<crate::store::Attempt> {
        let e = self.exercise_by_name(exercise).await?;
        let t = self.trainee_named(trainee).await?;
        self.start_attempt(t.id, e.id, Some(&recording.display().to_string()), expert).await
    }

    /// Scores attempt `attempt_id` from its recording against its exercise's plan, stores the
    /// metrics and the verdict, and updates the trainee's proficiency.
    pub async fn score_recording(&self, attempt_id: i64, rec: &Recording) -> crate::Result<(crate::store::Outcome, crate::MetricSet)> {
        let a = self.get_attempt(attempt_id).await?;
        let plan = self.exercise_plan(a.exercise_id).await?;
        let data = attempt_data(rec, &plan)?;
        let values = crate::metrics::assess(&plan, &data)?;
        let outcome = self.finish_attempt(attempt_id, &values).await?;
        Ok((outcome, values))
    }
}
