//! What the pages and the JSON API show, gathered from the store once per request: the same
//! structures are rendered as HTML (`pages`) and serialised as JSON (`api`).

pub mod attempt;
pub mod debrief;
pub mod labels;
pub mod overview;
pub mod progress;
pub mod running;
pub mod trace;

use cutlab_assessor::proficiency::ProficiencyState;
use cutlab_assessor::store::User;
use serde::Serialize;

pub use labels::{Label, display_unit, label};

/// A user, by id and name.
#[derive(Debug, Clone, Serialize)]
pub struct UserRef {
    pub id: i64,
    pub name: String,
}

impl From<&User> for UserRef {
    fn from(u: &User) -> Self {
        Self {
            id: u.id,
            name: u.name.clone(),
        }
    }
}

/// An exercise, by id and name.
#[derive(Debug, Clone, Serialize)]
pub struct ExerciseRef {
    pub id: i64,
    pub name: String,
}

/// Where a trainee stands in one exercise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Standing {
    NotStarted,
    /// Attempted, never passed.
    InProgress,
    /// Passed at least once, not yet proficient.
    Passed,
    /// Reached the consecutive passes.
    Proficient,
}

impl Standing {
    pub fn as_str(self) -> &'static str {
        match self {
            Standing::NotStarted => "not started",
            Standing::InProgress => "in progress",
            Standing::Passed => "passed",
            Standing::Proficient => "proficient",
        }
    }
}

/// Proficiency over a trainee's scored attempts at one exercise, oldest first.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ProficiencySummary {
    pub attempts: u32,
    pub passes: u32,
    pub consecutive_passes: u32,
    pub proficient: bool,
    /// The number of scored attempts it took to become proficient.
    pub trials_to_proficiency: Option<u32>,
    pub standing: Standing,
}

impl ProficiencySummary {
    pub fn of(passes: impl IntoIterator<Item = bool>, any_attempt: bool) -> Self {
        let mut s = ProficiencyState::default();
        let mut trials = None;
        for p in passes {
            s.update(p);
            if trials.is_none() && s.proficient {
                trials = Some(s.attempts);
            }
        }
        let standing = if s.proficient {
            Standing::Proficient
        } else if s.passes > 0 {
            Standing::Passed
        } else if any_attempt || s.attempts > 0 {
            Standing::InProgress
        } else {
            Standing::NotStarted
        };
        Self {
            attempts: s.attempts,
            passes: s.passes,
            consecutive_passes: s.consecutive_passes,
            proficient: s.proficient,
            trials_to_proficiency: trials,
            standing,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trials_to_proficiency_by_hand() {
        let s = ProficiencySummary::of([false, true, false, true, true, false], true);
        assert_eq!(s.trials_to_proficiency, Some(5));
        assert_eq!(s.standing, Standing::Proficient);
        assert_eq!((s.attempts, s.passes, s.consecutive_passes), (6, 3, 0));
        assert_eq!(
            ProficiencySummary::of([false, true], true).standing,
            Standing::Passed
        );
        assert_eq!(
            ProficiencySummary::of([], true).standing,
            Standing::InProgress
        );
        assert_eq!(
            ProficiencySummary::of([], false).standing,
            Standing::NotStarted
        );
    }
}
