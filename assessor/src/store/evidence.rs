//! Validity evidence in the store: users' experience levels, the attempts an exercise's
//! evidence report is built from, and the pass marks instructors adopt from it.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::{Store, now_ns};
use crate::error::{AssessError, Result};
use cutlab_scoring::evidence::{
    EvidenceAttempt, EvidenceOptions, Experience, PassMarkFinding, Report,
};
use cutlab_scoring::metrics::Better;

/// A pass mark on an exercise's overall score, adopted by an instructor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PassMark {
    pub exercise_id: i64,
    /// `contrasting-groups`.
    pub method: String,
    /// The overall score at or above which an attempt passes by this mark.
    pub score: f64,
    pub higher_group: Experience,
    pub lower_group: Experience,
    pub n_higher: i64,
    pub n_lower: i64,
    /// Observed in the report it was adopted from.
    pub false_pass: f64,
    pub false_fail: f64,
    /// Who adopted it (user name) and when.
    pub adopted_by: String,
    pub adopted_ns: i64,
}

type AttemptRow = (i64, i64, String, Option<String>, i64, bool, Option<f64>);
type PassMarkRow = (
    i64,
    String,
    f64,
    String,
    String,
    i64,
    i64,
    f64,
    f64,
    String,
    i64,
);

fn experience(s: Option<String>) -> Result<Option<Experience>> {
    Ok(s.map(|s| s.parse()).transpose()?)
}

impl Store {
    /// Records a user's experience level (`None` clears it).
    pub async fn set_experience(&self, user_id: i64, level: Option<Experience>) -> Result<()> {
        let done = crate::on_db!(&self.db, pool => sqlx::query("UPDATE users SET experience = $1 WHERE id = $2")
            .bind(level.map(Experience::as_str))
            .bind(user_id)
            .execute(pool).await.map(|r| r.rows_affected()))?;
        if done == 0 {
            return Err(AssessError::NotFound(format!("user {user_id}")));
        }
        Ok(())
    }

    /// A user's recorded experience level.
    pub async fn experience(&self, user_id: i64) -> Result<Option<Experience>> {
        let row: Option<Option<String>> = crate::on_db!(&self.db, pool => sqlx::query_scalar("SELECT experience FROM users WHERE id = $1")
            .bind(user_id)
            .fetch_optional(pool).await)?;
        experience(row.ok_or_else(|| AssessError::NotFound(format!("user {user_id}")))?)
    }

    /// The complete attempts at an exercise with their trainees' experience, scores and
    /// metric values: what its evidence report is built from.
    pub async fn evidence_attempts(&self, exercise_id: i64) -> Result<Vec<EvidenceAttempt>> {
        let rows: Vec<AttemptRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT a.id, a.trainee_id, u.name, u.experience, a.started_ns, a.expert, a.score FROM attempts a JOIN users u ON u.id = a.trainee_id WHERE a.exercise_id = $1 AND a.status = 'complete' ORDER BY a.trainee_id, a.started_ns, a.id")
            .bind(exercise_id)
            .fetch_all(pool).await)?;
        let values: Vec<(i64, String, f64)> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT m.attempt_id, m.metric, m.value FROM metric_results m JOIN attempts a ON a.id = m.attempt_id WHERE a.exercise_id = $1 AND a.status = 'complete' AND m.value IS NOT NULL ORDER BY m.attempt_id, m.metric")
            .bind(exercise_id)
            .fetch_all(pool).await)?;
        let mut by_attempt: BTreeMap<i64, Vec<(String, f64)>> = BTreeMap::new();
        for (id, key, value) in values {
            by_attempt.entry(id).or_default().push((key, value));
        }
        rows.into_iter()
            .map(
                |(id, trainee_id, trainee, level, started_ns, reference, score)| {
                    Ok(EvidenceAttempt {
                        attempt_id: id,
                        trainee_id,
                        trainee,
                        experience: experience(level)?,
                        started_ns,
                        reference,
                        score,
                        metrics: by_attempt.remove(&id).unwrap_or_default(),
                        rating: None,
                    })
                },
            )
            .collect()
    }

    /// The evidence report of an exercise (built on a blocking thread); two-sided metrics are
    /// measured from the thresholds' expert means.
    pub async fn evidence(&self, exercise_id: i64, include_reference: bool) -> Result<Report> {
        let exercise = self.get_exercise(exercise_id).await?;
        let thresholds = self.thresholds(exercise_id).await?;
        let options = EvidenceOptions {
            include_reference,
            two_sided_reference: thresholds
                .metrics
                .iter()
                .filter(|t| t.better == Better::TwoSided)
                .map(|t| (t.key.clone(), t.mean))
                .collect(),
            ..EvidenceOptions::default()
        };
        let attempts = self.evidence_attempts(exercise_id).await?;
        // the bootstrap takes a while on many attempts: off the async threads
        tokio::task::spawn_blocking(move || Report::build(&exercise.name, &attempts, &options))
            .await
            .map_err(|e| AssessError::Task(format!("building the evidence report: {e}")))
    }

    /// Adopts the contrasting-groups pass mark of `finding` for the exercise, recorded with
    /// who (`by`, a user id) and when; an error when the finding has no cut.
    pub async fn adopt_pass_mark(
        &self,
        exercise_id: i64,
        finding: &PassMarkFinding,
        by: i64,
    ) -> Result<PassMark> {
        let (Some(cut), Some(higher), Some(lower)) = (finding.cut, finding.higher, finding.lower)
        else {
            return Err(AssessError::InvalidInput(format!(
                "no pass mark to adopt: {}",
                finding.why_not.as_deref().unwrap_or("the report has none")
            )));
        };
        self.get_exercise(exercise_id).await?;
        self.get_user(by).await?;
        crate::on_db!(&self.db, pool => sqlx::query("INSERT INTO pass_marks (exercise_id, method, score, higher_group, lower_group, n_higher, n_lower, false_pass, false_fail, adopted_by, adopted_ns) VALUES ($1, 'contrasting-groups', $2, $3, $4, $5, $6, $7, $8, $9, $10)")
            .bind(exercise_id)
            .bind(cut.cut)
            .bind(higher.as_str())
            .bind(lower.as_str())
            .bind(finding.n_higher as i64)
            .bind(finding.n_lower as i64)
            .bind(cut.false_pass)
            .bind(cut.false_fail)
            .bind(by)
            .bind(now_ns())
            .execute(pool).await.map(|_| ()))?;
        self.pass_mark(exercise_id)
            .await?
            .ok_or_else(|| AssessError::NotFound("the pass mark just adopted".into()))
    }

    /// The exercise's pass mark: the newest adopted (`None`: none adopted).
    pub async fn pass_mark(&self, exercise_id: i64) -> Result<Option<PassMark>> {
        let row: Option<PassMarkRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT p.exercise_id, p.method, p.score, p.higher_group, p.lower_group, p.n_higher, p.n_lower, p.false_pass, p.false_fail, u.name, p.adopted_ns FROM pass_marks p JOIN users u ON u.id = p.adopted_by WHERE p.exercise_id = $1 ORDER BY p.adopted_ns DESC, p.id DESC LIMIT 1")
            .bind(exercise_id)
            .fetch_optional(pool).await)?;
        row.map(|r| {
            Ok(PassMark {
                exercise_id: r.0,
                method: r.1,
                score: r.2,
                higher_group: r.3.parse()?,
                lower_group: r.4.parse()?,
                n_higher: r.5,
                n_lower: r.6,
                false_pass: r.7,
                false_fail: r.8,
                adopted_by: r.9,
                adopted_ns: r.10,
            })
        })
        .transpose()
    }
}
