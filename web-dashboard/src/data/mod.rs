//! What the pages and the JSON API show, gathered from the store once per request: the same
//! structures are rendered as HTML (`pages`) and serialised as JSON (`api`).

pub mod attempt;
pub mod debrief;
pub mod field_picture;
pub mod labels;
pub mod overview;
pub mod progress;
pub mod running;
pub mod trace;

use cutlab_assessor::store::User;
use cutlab_scoring::proficiency::{Course, CusumParams, ProficiencyStatus};
use serde::Serialize;

pub use labels::{Label, device_words, label, mode_words};

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
    /// Reached the consecutive passes, and no lapse since.
    Proficient,
    /// Was proficient; the CUSUM after it signalled an unacceptable failure rate: to retrain
    /// (not proficient, for the curriculum either).
    Lapsed,
}

impl Standing {
    pub fn as_str(self) -> &'static str {
        match self {
            Standing::NotStarted => "not started",
            Standing::InProgress => "in progress",
            Standing::Passed => "passed",
            Standing::Proficient => "proficient",
            Standing::Lapsed => "proficiency lapsed",
        }
    }
}

/// Proficiency over a trainee's scored attempts at one exercise, oldest first (the
/// assessor's [`Course`]: the rule is in `cutlab_scoring::proficiency`).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ProficiencySummary {
    pub attempts: u32,
    pub passes: u32,
    pub consecutive_passes: u32,
    /// Proficient now (not lapsed).
    pub proficient: bool,
    /// The number of scored attempts it took to become proficient (the first time).
    pub trials_to_proficiency: Option<u32>,
    pub standing: Standing,
    /// Proficient since, or lapsed since, which attempt.
    pub status: ProficiencyStatus,
}

impl ProficiencySummary {
    /// Of the pass/fail outcomes of the scored attempts, oldest first (`any_attempt`: the
    /// trainee has attempts, scored or not).
    pub fn of(passes: impl IntoIterator<Item = bool>, any_attempt: bool) -> Self {
        let passes: Vec<bool> = passes.into_iter().collect();
        // the default parameters are valid: the course of any sequence
        let course = Course::of(&passes, &CusumParams::default()).unwrap_or_default();
        Self::of_course(&course, any_attempt)
    }

    /// Of a trainee's course through the exercise.
    pub fn of_course(c: &Course, any_attempt: bool) -> Self {
        let s = c.state;
        let standing = match c.status {
            ProficiencyStatus::Proficient { .. } => Standing::Proficient,
            ProficiencyStatus::Lapsed { .. } => Standing::Lapsed,
            ProficiencyStatus::Learning if s.passes > 0 => Standing::Passed,
            ProficiencyStatus::Learning if any_attempt || s.attempts > 0 => Standing::InProgress,
            ProficiencyStatus::Learning => Standing::NotStarted,
        };
        Self {
            attempts: s.attempts,
            passes: s.passes,
            consecutive_passes: s.consecutive_passes,
            proficient: s.proficient,
            trials_to_proficiency: c.first_proficient,
            standing,
            status: c.status,
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

    #[test]
    fn a_lapse_after_proficiency_is_not_proficient() {
        // proficient at the 2nd; the failures after it reach h1 (4 in a row): lapsed
        let mut passes = vec![true, true];
        let mut lapsed = None;
        for _ in 0..20 {
            if lapsed.is_some() {
                break;
            }
            passes.push(false);
            let s = ProficiencySummary::of(passes.clone(), true);
            if s.standing == Standing::Lapsed {
                lapsed = Some(s);
            } else {
                assert_eq!(s.standing, Standing::Proficient, "{passes:?}");
            }
        }
        let s = lapsed.expect("a lapse within 20 failures");
        assert!(!s.proficient);
        assert_eq!(s.trials_to_proficiency, Some(2), "the first time is kept");
        assert_eq!(
            s.status,
            ProficiencyStatus::Lapsed {
                since: passes.len() as u32
            }
        );
        // two passes again: proficient since the second of them
        passes.extend([true, true]);
        let s = ProficiencySummary::of(passes.clone(), true);
        assert_eq!(s.standing, Standing::Proficient);
        assert_eq!(
            s.status,
            ProficiencyStatus::Proficient {
                since: passes.len() as u32
            }
        );
    }
}
