//! Proficiency-based progression: in a curriculum with progression on, the exercises (its
//! modules' in order) open one after the other. An exercise opens to a trainee when the one
//! before it is proficient by its own rule (its thresholds, the consecutive passes of
//! [`cutlab_scoring::proficiency`]; a later lapse does not lock it again), or when an instructor has
//! opened it early, which is recorded (who, when, why). The first exercise is always open; an
//! exercise in no such curriculum too.
//!
//! The station asks [`Store::exercise_access`] before a trainee's session starts; expert
//! attempts and the command line's sessions are not held back.

use serde::{Deserialize, Serialize};

use super::{Attempt, Store, now_ns};
use crate::error::{AssessError, Result};
use cutlab_scoring::proficiency::{Course, CusumParams, REQUIRED_CONSECUTIVE_PASSES};

/// The built-in curriculum's name: the cutting exercises in order, with progression.
pub const CUTTING_BASICS: &str = "cutting-basics";

/// An instructor's opening of an exercise to a trainee before its turn.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Opening {
    pub trainee_id: i64,
    pub exercise_id: i64,
    /// The instructor (or admin) who opened it.
    pub opened_by: String,
    pub reason: String,
    pub opened_ns: i64,
}

/// Whether a trainee may start an exercise, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "access")]
pub enum Access {
    /// In no curriculum with progression, or first in each.
    Open,
    /// Opened by proficiency in the exercise before it (`after`, by name).
    Earned { after: String },
    /// Opened early by an instructor.
    OpenedEarly(Opening),
    /// Locked until `after` (the exercise before it in `curriculum`) is proficient.
    Locked { curriculum: String, after: String },
}

impl Access {
    pub fn is_open(&self) -> bool {
        !matches!(self, Access::Locked { .. })
    }

    /// What a trainee is told of a locked exercise (`None` when open).
    pub fn locked_message(&self, exercise: &str) -> Option<String> {
        match self {
            Access::Locked { curriculum, after } => Some(format!(
                "{exercise} is locked in the {curriculum} curriculum until you are proficient in \
                 {after} ({REQUIRED_CONSECUTIVE_PASSES} passes in a row); an instructor can open it early"
            )),
            _ => None,
        }
    }
}

impl Attempt {
    /// Whether the attempt passed, when it counts towards its trainee's proficiency (scored,
    /// complete, not an expert's reference); `None` when it does not count.
    pub fn counted_pass(&self) -> Option<bool> {
        (self.scored && self.status == super::AttemptStatus::Complete && !self.expert)
            .then(|| self.passed.unwrap_or(false))
    }
}

/// Whether `attempts` (one trainee's at one exercise, oldest first) ever reached proficiency.
pub fn reached_proficiency(attempts: &[Attempt]) -> bool {
    let passes: Vec<bool> = attempts.iter().filter_map(Attempt::counted_pass).collect();
    Course::of(&passes, &CusumParams::default()).is_ok_and(|c| c.first_proficient.is_some())
}

/// The longest reason for opening an exercise early, in characters.
pub const MAX_REASON_CHARS: usize = 500;

impl Store {
    /// Whether `trainee_id` may start `exercise_id` (see the module documentation).
    pub async fn exercise_access(&self, trainee_id: i64, exercise_id: i64) -> Result<Access> {
        if let Some(o) = self.opening(trainee_id, exercise_id).await? {
            return Ok(Access::OpenedEarly(o));
        }
        let mut earned = None;
        for c in self.list_curricula().await? {
            if !c.progression {
                continue;
            }
            let order = self.curriculum_exercise_ids(c.id).await?;
            let Some(before) = order
                .iter()
                .position(|&e| e == exercise_id)
                .and_then(|i| i.checked_sub(1))
                .map(|i| order[i])
            else {
                continue;
            };
            let after = self.get_exercise(before).await?.name;
            let attempts = self.list_attempts(Some(trainee_id), Some(before)).await?;
            if !reached_proficiency(&attempts) {
                return Ok(Access::Locked {
                    curriculum: c.name,
                    after,
                });
            }
            earned = Some(after);
        }
        Ok(earned.map_or(Access::Open, |after| Access::Earned { after }))
    }

    /// The exercise `trainee_id` does next: in the curricula with progression (by name), the
    /// first exercise open to them in which they have not reached proficiency.
    pub async fn next_exercise(&self, trainee_id: i64) -> Result<Option<i64>> {
        for c in self.list_curricula().await? {
            if !c.progression {
                continue;
            }
            for m in self.curriculum_modules(c.id).await? {
                for e in m.exercise_ids {
                    let attempts = self.list_attempts(Some(trainee_id), Some(e)).await?;
                    if !reached_proficiency(&attempts)
                        && self.exercise_access(trainee_id, e).await?.is_open()
                    {
                        return Ok(Some(e));
                    }
                }
            }
        }
        Ok(None)
    }

    /// The instructor's opening of `exercise_id` to `trainee_id`, if any.
    pub async fn opening(&self, trainee_id: i64, exercise_id: i64) -> Result<Option<Opening>> {
        let row: Option<(String, String, i64)> = crate::on_db!(&self.db, pool => sqlx::query_as(
            "SELECT u.name, o.reason, o.opened_ns FROM exercise_openings o JOIN users u ON u.id = o.opened_by WHERE o.trainee_id = $1 AND o.exercise_id = $2",
        )
        .bind(trainee_id)
        .bind(exercise_id)
        .fetch_optional(pool).await)?;
        Ok(row.map(|(opened_by, reason, opened_ns)| Opening {
            trainee_id,
            exercise_id,
            opened_by,
            reason,
            opened_ns,
        }))
    }

    /// Records that `instructor_id` opened `exercise_id` to `trainee_id` early, for `reason`;
    /// opening it again keeps the first opening.
    pub async fn open_early(
        &self,
        trainee_id: i64,
        exercise_id: i64,
        instructor_id: i64,
        reason: &str,
    ) -> Result<Opening> {
        let reason = super::text::text("the reason", reason, MAX_REASON_CHARS)?;
        self.get_exercise(exercise_id).await?;
        let instructor = self.get_user(instructor_id).await?;
        if instructor.role == super::Role::Trainee {
            return Err(AssessError::InvalidInput(format!(
                "{} is a trainee: only an instructor or an admin opens an exercise early",
                instructor.name
            )));
        }
        crate::on_db!(&self.db, pool => sqlx::query(
            "INSERT INTO exercise_openings (trainee_id, exercise_id, opened_by, reason, opened_ns) VALUES ($1, $2, $3, $4, $5) ON CONFLICT (trainee_id, exercise_id) DO NOTHING",
        )
        .bind(trainee_id)
        .bind(exercise_id)
        .bind(instructor_id)
        .bind(reason)
        .bind(now_ns())
        .execute(pool).await.map(|r| r.rows_affected()))?;
        self.opening(trainee_id, exercise_id)
            .await?
            .ok_or_else(|| AssessError::NotFound(format!("the opening of exercise {exercise_id}")))
    }
}
