//! Attempts kept from recordings: a trainee by name, an attempt started with its recording,
//! an attempt scored from its recording ([`cutlab_scoring::from_recording`]).

use cutlab_recorder::Recording;
use cutlab_scoring::from_recording::assess_recording;
use cutlab_scoring::{ExercisePlan, MetricSet};

use super::{Attempt, Outcome, Role, Store, User};
use crate::error::{AssessError, Result};

impl Store {
    /// The user `name`; a new name becomes a trainee without a password (who cannot log in
    /// until an administrator sets one).
    pub async fn trainee_named(&self, name: &str) -> Result<User> {
        match self.user_by_name(name).await {
            Err(AssessError::NotFound(_)) => self.create_user(name, Role::Trainee, None).await,
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
    ) -> Result<Attempt> {
        let e = self.exercise_by_name(exercise).await?;
        let t = self.trainee_named(trainee).await?;
        self.start_attempt(t.id, e.id, Some(&recording.display().to_string()), expert)
            .await
    }

    /// Scores attempt `attempt_id` from its recording against its exercise's plan, stores the
    /// metrics and the verdict, and updates the trainee's proficiency. A recording that is not
    /// whole (damaged, cut short) is scored on what is readable, and the attempt's note says so
    /// ([`DAMAGED_RECORDING_NOTE`](cutlab_scoring::from_recording::DAMAGED_RECORDING_NOTE)).
    pub async fn score_recording(
        &self,
        attempt_id: i64,
        rec: &Recording,
    ) -> Result<(Outcome, MetricSet)> {
        let a = self.get_attempt(attempt_id).await?;
        let plan = self.exercise_plan(a.exercise_id).await?;
        self.score_recording_against(attempt_id, rec, &plan).await
    }

    /// [`Store::score_recording`] against `plan`, the attempt's exercise's plan already loaded
    /// (the run that started the attempt holds it).
    pub async fn score_recording_against(
        &self,
        attempt_id: i64,
        rec: &Recording,
        plan: &ExercisePlan,
    ) -> Result<(Outcome, MetricSet)> {
        let a = self.get_attempt(attempt_id).await?;
        let (values, note) = assess_recording(rec, plan)?;
        // an attempt assessed from a file takes the device its recording names (whose class
        // picks the thresholds)
        if a.device.is_none()
            && let Ok(meta) = rec.meta()
        {
            self.set_attempt_setup(attempt_id, a.mode.as_deref(), &meta.provenance.device)
                .await?;
        }
        let outcome = self
            .finish_attempt_noted(attempt_id, &values, note.as_deref())
            .await?;
        Ok((outcome, values))
    }
}
