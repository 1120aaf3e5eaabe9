//! An attempt's data from its recording: the tool poses and forces of every servo tick, the
//! blade path while it was in the tissue, and the deformed tissue surface of the last
//! keyframe.

use cutlab_recorder::Recording;
use cutlab_recorder::haptics::render::Mode;
use cutlab_sim::TetMesh;

use crate::AssessError;
use crate::input::{AttemptData, CutSample, ForceSample, PoseSample, SurfaceMesh};
use crate::metrics::incision::depth_below_plan;
use crate::plan::ExpertPlan;

/// How the note of an attempt scored from a recording that is not whole begins.
pub const DAMAGED_RECORDING_NOTE: &str = "Scored from a damaged recording";

/// The data `plan` is assessed on, from `rec`. A cut sample's depth is its blade tip's depth
/// below the planned surface (`depth_below_plan`).
pub fn attempt_data(rec: &Recording, plan: &ExpertPlan) -> Result<AttemptData, AssessError> {
    let meta = rec
        .meta()
        .map_err(|e| AssessError::InvalidInput(e.to_string()))?;
    let period_s = meta.period_nanos as f64 * 1e-9;
    // every tick with both its pose and its tool state, in tick order
    let samples = rec.samples();
    let t_s = |tick: u64| tick as f64 * period_s;
    let poses = samples
        .values()
        .map(|s| {
            let q = s.pose.world_from_tool.quaternion();
            PoseSample {
                t_s: t_s(s.tick),
                tip_m: s.pose.tip_in_world.coords.into(),
                quat_wxyz: [q.w, q.i, q.j, q.k],
                blade_engaged: s.pose.blade_engaged(),
            }
        })
        .collect();
    let forces = samples
        .values()
        .map(|s| ForceSample {
            t_s: t_s(s.tick),
            force_newtons: s.render.force_newtons.into(),
            touching: s.render.mode == Mode::Touching,
            cutting: s.render.mode == Mode::Cutting,
        })
        .collect();
    // The cut's trace: the blade at every tick the renderer had it in the tissue (the blade
    // path; the topology events only mark where the mesh changed, a few per centimetre on a
    // coarse mesh).
    let cuts = samples
        .values()
        .filter(|s| s.render.mode == Mode::Cutting)
        .map(|s| {
            let tip_m: [f64; 3] = s.pose.tip_in_world.coords.into();
            CutSample {
                t_s: t_s(s.tick),
                tip_m,
                edge_dir: s.pose.edge_direction().into(),
                depth_m: depth_below_plan(plan, tip_m),
            }
        })
        .collect();
    Ok(AttemptData {
        poses,
        forces,
        cuts,
        surface: last_surface(rec),
    })
}

/// `rec`'s metrics against `plan`, and what the attempt's note must say of a recording that
/// is not whole (damaged, cut short: scored on what is readable, never silently).
pub fn assess_recording(
    rec: &Recording,
    plan: &ExpertPlan,
) -> Result<(crate::MetricSet, Option<String>), AssessError> {
    let data = attempt_data(rec, plan)?;
    let values = crate::metrics::assess(plan, &data)?;
    let note = rec
        .shortfall()
        .map(|why| format!("{DAMAGED_RECORDING_NOTE}: {why}"));
    Ok((values, note))
}

/// The boundary of the last keyframe's mesh at its deformed positions.
fn last_surface(rec: &Recording) -> Option<SurfaceMesh> {
    let k = rec.keyframes.last()?;
    let rest = k
        .rest_positions_m
        .iter()
        .map(|&p| cutlab_sim::Point3::from(p))
        .collect();
    let mesh = TetMesh::new(rest, k.tets.clone(), k.regions.clone()).ok()?;
    let triangles = mesh
        .topology()
        .boundary
        .iter()
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    Some(SurfaceMesh {
        vertices_m: k.positions_m.clone(),
        triangles,
    })
}

impl crate::store::Store {
    /// The user `name`; a new name becomes a trainee without a password (who cannot log in
    /// until an administrator sets one).
    pub async fn trainee_named(&self, name: &str) -> crate::Result<crate::store::User> {
        match self.user_by_name(name).await {
            Err(AssessError::NotFound(_)) => {
                self.create_user(name, crate::store::Role::Trainee, None)
                    .await
            }
            other => other,
        }
    }

    /// Starts an attempt (status running) at exercise `exercise` by `trainee` (created when
    /// new), recorded at `recording`.
    pub async fn start_recorded_attempt(
        &self,
        exercise: &str,
        trainee: &str,
        recording: &std::path::Path,
        expert: bool,
    ) -> crate::Result<crate::store::Attempt> {
        let e = self.exercise_by_name(exercise).await?;
        let t = self.trainee_named(trainee).await?;
        self.start_attempt(t.id, e.id, Some(&recording.display().to_string()), expert)
            .await
    }

    /// Scores attempt `attempt_id` from its recording against its exercise's plan, stores the
    /// metrics and the verdict, and updates the trainee's proficiency. A recording that is not
    /// whole (damaged, cut short) is scored on what is readable, and the attempt's note says so
    /// ([`DAMAGED_RECORDING_NOTE`]).
    pub async fn score_recording(
        &self,
        attempt_id: i64,
        rec: &Recording,
    ) -> crate::Result<(crate::store::Outcome, crate::MetricSet)> {
        let a = self.get_attempt(attempt_id).await?;
        let plan = self.exercise_plan(a.exercise_id).await?;
        let (values, note) = assess_recording(rec, &plan)?;
        let outcome = self
            .finish_attempt_noted(attempt_id, &values, note.as_deref())
            .await?;
        Ok((outcome, values))
    }
}
