//! Validity evidence of an exercise's scores (issue 45): do the more experienced score better
//! (construct validity: Mann-Whitney U, the AUC with a bootstrap interval, per metric and
//! for the overall score), are the scores reproducible (test-retest ICC(2,1) over each
//! trainee's last two attempts), where do the learning curves level off, and where would a
//! pass mark by the contrasting-groups method lie and how many would it misclassify.
//!
//! [`Report::build`] is pure: it takes the attempts ([`EvidenceAttempt`], from the store's
//! `evidence_attempts` or imported kinematics) and says, for each figure it cannot compute,
//! why. The definitions are in `docs/guide/evidence.md`.

pub mod predict;
pub mod report;

pub use report::{
    Comparison, Concurrent, EvidenceAttempt, EvidenceOptions, Finding, Group, GroupValues,
    LearningCurve, Measure, PassMarkFinding, Reliability, Report, SCORE_KEY,
};

use serde::{Deserialize, Serialize};

use crate::error::{Result, ScoreError};

/// A person's surgical experience, recorded by an administrator: the groups the evidence
/// contrasts. Ordered from the least experienced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Experience {
    Novice,
    Intermediate,
    Expert,
}

impl Experience {
    pub const ALL: [Experience; 3] = [
        Experience::Novice,
        Experience::Intermediate,
        Experience::Expert,
    ];

    /// The name stored in the database.
    pub fn as_str(self) -> &'static str {
        match self {
            Experience::Novice => "novice",
            Experience::Intermediate => "intermediate",
            Experience::Expert => "expert",
        }
    }
}

impl std::str::FromStr for Experience {
    type Err = ScoreError;
    fn from_str(s: &str) -> Result<Self> {
        Experience::ALL
            .into_iter()
            .find(|e| e.as_str() == s)
            .ok_or_else(|| {
                ScoreError::InvalidInput(format!(
                    "unknown experience level {s:?} (novice, intermediate or expert)"
                ))
            })
    }
}

impl std::fmt::Display for Experience {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}
