//! Attempts, their metric results and the proficiency state per trainee and exercise.

use serde::{Deserialize, Serialize};

use super::{BeginWrite, Store, now_ns};
use crate::error::{AssessError, Result};
use cutlab_scoring::metrics::{self, Better, MetricValue};
use cutlab_scoring::proficiency::{Course, CusumParams, CusumPoint, ProficiencyState, Verdict};

/// Where an attempt stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AttemptStatus {
    /// Started, not ended.
    Running,
    /// Ended and scored.
    Complete,
    /// Interrupted: the recording is kept, nothing scored.
    Incomplete,
    /// The assessment itself failed (e.g. an unreadable recording).
    Failed,
}

impl AttemptStatus {
    pub fn as_str(self) -> &'static str {
        match self {
            AttemptStatus::Running => "running",
            AttemptStatus::Complete => "complete",
            AttemptStatus::Incomplete => "incomplete",
            AttemptStatus::Failed => "failed",
        }
    }
    fn parse(s: &str) -> Result<Self> {
        match s {
            "running" => Ok(AttemptStatus::Running),
            "complete" => Ok(AttemptStatus::Complete),
            "incomplete" => Ok(AttemptStatus::Incomplete),
            "failed" => Ok(AttemptStatus::Failed),
            _ => Err(AssessError::InvalidInput(format!(
                "stored attempt status {s:?}"
            ))),
        }
    }
}

/// One attempt at an exercise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Attempt {
    pub id: i64,
    pub trainee_id: i64,
    pub exercise_id: i64,
    pub recording_path: Option<String>,
    /// The `.mcap`'s key (SHA-256, hex) in the recording store, once stored there.
    pub recording_sha256: Option<String>,
    /// The `.rrd`'s key in the recording store, once stored there.
    pub rrd_sha256: Option<String>,
    pub started_ns: i64,
    pub ended_ns: Option<i64>,
    pub status: AttemptStatus,
    /// A reference attempt by an expert (sets thresholds).
    pub expert: bool,
    pub scored: bool,
    pub score: Option<f64>,
    pub passed: Option<bool>,
    pub note: Option<String>,
    /// The attempt's global id, made where it was recorded: the same attempt on a station
    /// and on its hub.
    pub uuid: Option<String>,
    /// On a station: when the hub took the attempt (`None`: not yet, or no hub).
    pub synced_ns: Option<i64>,
    /// On a station: why the last upload to the hub failed.
    pub sync_error: Option<String>,
    /// On a hub: the station that uploaded the attempt (`None`: recorded here).
    pub station: Option<String>,
    /// `guided` (the plan shown) or `exam`, for a station's attempt.
    pub mode: Option<String>,
    /// The input the attempt was made with, as the station names it (`pointer`...).
    pub device: Option<String>,
}

type MetricRow = (String, Option<f64>, String, Option<bool>, Option<String>);
type ProficiencyRow = (i64, i64, i64, bool, Option<i64>, f64);
impl Attempt {
    /// The attempt's files on this machine: its recorded `.mcap` path and the `.rrd` beside
    /// it (same stem); `None` for an attempt that recorded none.
    pub fn recording_files(&self) -> Option<(std::path::PathBuf, std::path::PathBuf)> {
        let mcap =
            std::path::PathBuf::from(self.recording_path.as_deref().filter(|p| !p.is_empty())?);
        let rrd = mcap.with_extension("rrd");
        Some((mcap, rrd))
    }
}

/// An `attempts` row as stored.
#[derive(sqlx::FromRow)]
pub(super) struct AttemptRow {
    id: i64,
    trainee_id: i64,
    exercise_id: i64,
    recording_path: Option<String>,
    started_ns: i64,
    ended_ns: Option<i64>,
    status: String,
    expert: bool,
    scored: bool,
    score: Option<f64>,
    passed: Option<bool>,
    note: Option<String>,
    recording_sha256: Option<String>,
    rrd_sha256: Option<String>,
    uuid: Option<String>,
    synced_ns: Option<i64>,
    sync_error: Option<String>,
    station: Option<String>,
    mode: Option<String>,
    device: Option<String>,
}
pub(super) const ATTEMPT_COLUMNS: &str = "SELECT id, trainee_id, exercise_id, recording_path, started_ns, ended_ns, status, expert, scored, score, passed, note, recording_sha256, rrd_sha256, uuid, synced_ns, sync_error, station, mode, device FROM attempts";

pub(super) fn attempt(r: AttemptRow) -> Result<Attempt> {
    Ok(Attempt {
        id: r.id,
        trainee_id: r.trainee_id,
        exercise_id: r.exercise_id,
        recording_path: r.recording_path,
        started_ns: r.started_ns,
        ended_ns: r.ended_ns,
        status: AttemptStatus::parse(&r.status)?,
        expert: r.expert,
        scored: r.scored,
        score: r.score,
        passed: r.passed,
        note: r.note,
        recording_sha256: r.recording_sha256,
        rrd_sha256: r.rrd_sha256,
        uuid: r.uuid,
        synced_ns: r.synced_ns,
        sync_error: r.sync_error,
        station: r.station,
        mode: r.mode,
        device: r.device,
    })
}

/// One stored metric result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StoredMetric {
    pub metric: String,
    pub value: Option<f64>,
    pub unit: String,
    /// Against the thresholds at scoring time; `None` for metrics without a threshold.
    pub passed: Option<bool>,
    pub missing: Option<String>,
}

/// A trainee's proficiency in one exercise.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ProficiencyRecord {
    pub trainee_id: i64,
    pub exercise_id: i64,
    pub state: ProficiencyState,
    /// The attempt that first completed the consecutive passes (kept after a lapse).
    pub proficient_attempt_id: Option<i64>,
    /// The CUSUM now (default parameters), restarted from 0 as the standing changed
    /// ([`Course`]).
    pub cusum: f64,
}

impl ProficiencyRecord {
    /// The trainee was proficient and no longer is: the CUSUM after it signalled an
    /// unacceptable failure rate ([`Course`]); they retrain until the consecutive passes again.
    pub fn lapsed(&self) -> bool {
        !self.state.proficient && self.proficient_attempt_id.is_some()
    }
}

/// What scoring an attempt gave.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Outcome {
    pub attempt: Attempt,
    pub verdict: Verdict,
    pub proficiency: ProficiencyRecord,
}

/// Scores attempt `$attempt_id` (of `$trainee_id` at `$exercise_id`, not yet complete) in
/// the open write transaction `$tx`: the verdict and metrics stored, the attempt marked
/// complete, the trainee's proficiency re-derived; evaluates to the new
/// [`ProficiencyRecord`]. A macro, as the transaction's type differs per engine
/// ([`crate::on_db!`]); used by [`Store::finish_attempt_noted`] and by a hub's import, which
/// inserts the attempt in the same transaction.
macro_rules! score_in_tx {
    ($tx:ident, $attempt_id:expr, $trainee_id:expr, $exercise_id:expr, $verdict:expr, $metrics:expr, $note:expr) => {{
        let (attempt_id, trainee_id, exercise_id): (i64, i64, i64) =
            ($attempt_id, $trainee_id, $exercise_id);
        let verdict: &cutlab_scoring::proficiency::Verdict = $verdict;
        let metrics: &[MetricValue] = $metrics;
        let note: Option<&str> = $note;
        // the trainee's proficiency row first, locked (PostgreSQL: a row lock until
        // commit, so a second scoring of the same trainee and exercise waits and then
        // reads this one's history; SQLite holds the whole database already)
        sqlx::query(
            "INSERT INTO proficiency (trainee_id, exercise_id, attempts, passes, consecutive_passes, proficient, cusum, updated_ns) \
             VALUES ($1, $2, 0, 0, 0, FALSE, 0, $3) \
             ON CONFLICT (trainee_id, exercise_id) DO UPDATE SET updated_ns = proficiency.updated_ns",
        )
        .bind(trainee_id)
        .bind(exercise_id)
        .bind(now_ns())
        .execute(&mut *$tx)
        .await?;
        let done = sqlx::query("UPDATE attempts SET status = 'complete', ended_ns = COALESCE(ended_ns, $1), scored = TRUE, score = $2, passed = $3, note = COALESCE($4, note) WHERE id = $5 AND status <> 'complete'")
            .bind(now_ns())
            .bind(verdict.score)
            .bind(verdict.pass)
            .bind(note)
            .bind(attempt_id)
            .execute(&mut *$tx)
            .await?;
        if done.rows_affected() == 0 {
            return Err(AssessError::Conflict(format!(
                "attempt {attempt_id} is already scored"
            )));
        }
        sqlx::query("DELETE FROM metric_results WHERE attempt_id = $1")
            .bind(attempt_id)
            .execute(&mut *$tx)
            .await?;
        for m in metrics {
            let passed = verdict
                .metrics
                .iter()
                .find(|v| v.key == m.key)
                .map(|v| v.pass);
            sqlx::query("INSERT INTO metric_results (attempt_id, metric, value, unit, passed, missing) VALUES ($1, $2, $3, $4, $5, $6)")
                .bind(attempt_id)
                .bind(&m.key)
                .bind(m.value.filter(|v| v.is_finite()))
                .bind(&m.unit)
                .bind(passed)
                .bind(&m.missing)
                .execute(&mut *$tx)
                .await
                .map_err(super::conflict(|| format!("metric {:?} given twice", m.key)))?;
        }
        let history: Vec<(i64, bool)> = sqlx::query_as("SELECT id, passed FROM attempts WHERE trainee_id = $1 AND exercise_id = $2 AND status = 'complete' AND scored = TRUE ORDER BY started_ns, id")
            .bind(trainee_id)
            .bind(exercise_id)
            .fetch_all(&mut *$tx)
            .await?;
        let record = crate::store::attempts::proficiency_of(trainee_id, exercise_id, &history)?;
        sqlx::query(
            "INSERT INTO proficiency (trainee_id, exercise_id, attempts, passes, consecutive_passes, proficient, proficient_attempt_id, cusum, updated_ns) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9) \
             ON CONFLICT (trainee_id, exercise_id) DO UPDATE SET attempts = excluded.attempts, passes = excluded.passes, \
             consecutive_passes = excluded.consecutive_passes, proficient = excluded.proficient, \
             proficient_attempt_id = excluded.proficient_attempt_id, cusum = excluded.cusum, updated_ns = excluded.updated_ns",
        )
        .bind(record.trainee_id)
        .bind(record.exercise_id)
        .bind(i64::from(record.state.attempts))
        .bind(i64::from(record.state.passes))
        .bind(i64::from(record.state.consecutive_passes))
        .bind(record.state.proficient)
        .bind(record.proficient_attempt_id)
        .bind(record.cusum)
        .bind(now_ns())
        .execute(&mut *$tx)
        .await?;
        record
    }};
}
pub(super) use score_in_tx;

impl Store {
    /// Records the start of an attempt (status `running`).
    pub async fn start_attempt(
        &self,
        trainee_id: i64,
        exercise_id: i64,
        recording_path: Option<&str>,
        expert: bool,
    ) -> Result<Attempt> {
        self.get_user(trainee_id).await?;
        self.get_exercise(exercise_id).await?;
        let id: i64 = crate::on_db!(&self.db, pool => sqlx::query_scalar("INSERT INTO attempts (trainee_id, exercise_id, recording_path, started_ns, status, expert, uuid) VALUES ($1, $2, $3, $4, 'running', $5, $6) RETURNING id")
            .bind(trainee_id)
            .bind(exercise_id)
            .bind(recording_path)
            .bind(now_ns())
            .bind(expert)
            .bind(super::hub::new_uuid()?)
            .fetch_one(pool).await)?;
        self.get_attempt(id).await
    }

    /// Records how an attempt is made: the station's `mode` (`guided` or `exam`; `None` for a
    /// session from the command line) and its `device` (whose class picks its thresholds,
    /// [`cutlab_scoring::DeviceClass::of`]).
    pub async fn set_attempt_setup(&self, id: i64, mode: Option<&str>, device: &str) -> Result<()> {
        crate::on_db!(&self.db, pool => sqlx::query("UPDATE attempts SET mode = $1, device = $2 WHERE id = $3")
            .bind(mode)
            .bind(device)
            .bind(id)
            .execute(pool).await.map(|_| ()))?;
        Ok(())
    }

    pub async fn get_attempt(&self, id: i64) -> Result<Attempt> {
        let row: Option<AttemptRow> = crate::on_db!(&self.db, pool => sqlx::query_as(sqlx::AssertSqlSafe(format!(
            "{ATTEMPT_COLUMNS} WHERE id = $1"
        )))
        .bind(id)
        .fetch_optional(pool).await)?;
        attempt(row.ok_or_else(|| AssessError::NotFound(format!("attempt {id}")))?)
    }

    /// Records where the attempt's recordings are in the recording store: the keys
    /// (SHA-256, hex) of its `.mcap` and `.rrd` (`None` keeps what is recorded).
    pub async fn set_recording_keys(
        &self,
        attempt_id: i64,
        mcap_sha256: Option<&str>,
        rrd_sha256: Option<&str>,
    ) -> Result<Attempt> {
        let done = crate::on_db!(&self.db, pool => sqlx::query("UPDATE attempts SET recording_sha256 = COALESCE($1, recording_sha256), rrd_sha256 = COALESCE($2, rrd_sha256) WHERE id = $3")
            .bind(mcap_sha256)
            .bind(rrd_sha256)
            .bind(attempt_id)
            .execute(pool).await.map(|r| r.rows_affected()))?;
        if done == 0 {
            return Err(AssessError::NotFound(format!("attempt {attempt_id}")));
        }
        self.get_attempt(attempt_id).await
    }

    /// Attempts, optionally of one trainee and/or exercise, oldest first.
    /// The attempts still running (status `running`), oldest first.
    pub async fn running_attempts(&self) -> Result<Vec<Attempt>> {
        let rows: Vec<AttemptRow> = crate::on_db!(&self.db, pool => sqlx::query_as(sqlx::AssertSqlSafe(format!("{ATTEMPT_COLUMNS} WHERE status = 'running' ORDER BY started_ns, id")))
            .fetch_all(pool).await)?;
        rows.into_iter().map(attempt).collect()
    }

    pub async fn list_attempts(
        &self,
        trainee_id: Option<i64>,
        exercise_id: Option<i64>,
    ) -> Result<Vec<Attempt>> {
        let rows: Vec<AttemptRow> = crate::on_db!(&self.db, pool => sqlx::query_as(sqlx::AssertSqlSafe(format!("{ATTEMPT_COLUMNS} WHERE ($1 IS NULL OR trainee_id = $2) AND ($3 IS NULL OR exercise_id = $4) ORDER BY started_ns, id")))
            .bind(trainee_id)
            .bind(trainee_id)
            .bind(exercise_id)
            .bind(exercise_id)
            .fetch_all(pool).await)?;
        rows.into_iter().map(attempt).collect()
    }

    /// Sets the end time (if not set) of a running attempt, `status` and a note.
    async fn end_unscored(
        &self,
        attempt_id: i64,
        status: AttemptStatus,
        note: Option<&str>,
    ) -> Result<Attempt> {
        let done = crate::on_db!(&self.db, pool => sqlx::query("UPDATE attempts SET status = $1, ended_ns = COALESCE(ended_ns, $2), note = COALESCE($3, note) WHERE id = $4 AND status = 'running'")
            .bind(status.as_str())
            .bind(now_ns())
            .bind(note)
            .bind(attempt_id)
            .execute(pool).await.map(|r| r.rows_affected()))?;
        if done == 0 {
            let a = self.get_attempt(attempt_id).await?;
            return Err(AssessError::Conflict(format!(
                "attempt {attempt_id} is {}, not running",
                a.status.as_str()
            )));
        }
        self.get_attempt(attempt_id).await
    }

    /// An interrupted attempt: `incomplete`, the recording path kept, nothing scored.
    pub async fn mark_incomplete(&self, attempt_id: i64, note: Option<&str>) -> Result<Attempt> {
        self.end_unscored(attempt_id, AttemptStatus::Incomplete, note)
            .await
    }

    /// An attempt whose assessment failed (`failed`, with the reason).
    pub async fn mark_failed(&self, attempt_id: i64, reason: &str) -> Result<Attempt> {
        self.end_unscored(attempt_id, AttemptStatus::Failed, Some(reason))
            .await
    }

    /// Scores an attempt (running, incomplete or failed; not already complete) against its
    /// exercise's current thresholds, stores its metrics, marks it complete and updates the
    /// trainee's proficiency, in one transaction.
    pub async fn finish_attempt(
        &self,
        attempt_id: i64,
        metrics: &[MetricValue],
    ) -> Result<Outcome> {
        self.finish_attempt_noted(attempt_id, metrics, None).await
    }

    /// [`Store::finish_attempt`], with a note stored in the same transaction (what the scores
    /// rest on, e.g. a damaged recording); `None` keeps the attempt's note.
    pub async fn finish_attempt_noted(
        &self,
        attempt_id: i64,
        metrics: &[MetricValue],
        note: Option<&str>,
    ) -> Result<Outcome> {
        let a = self.get_attempt(attempt_id).await?;
        let thresholds = self.attempt_thresholds(&a).await?;
        let verdict = thresholds.verdict(metrics);
        let record = crate::on_db!(&self.db, pool => {
            let mut tx = pool.begin_write().await?;
            let record = score_in_tx!(tx, attempt_id, a.trainee_id, a.exercise_id, &verdict, metrics, note);
            tx.commit().await?;
            record
        });
        Ok(Outcome {
            attempt: self.get_attempt(attempt_id).await?,
            verdict,
            proficiency: record,
        })
    }

    /// Computes the attempt's metrics from `data` against its exercise's plan
    /// ([`cutlab_scoring::ExercisePlan::assess`]) and scores it ([`Store::finish_attempt`]).
    pub async fn score_attempt(
        &self,
        attempt_id: i64,
        data: &cutlab_scoring::input::AttemptData,
    ) -> Result<Outcome> {
        let a = self.get_attempt(attempt_id).await?;
        let plan = self.exercise_plan(a.exercise_id).await?;
        let values = plan.assess(data)?;
        self.finish_attempt(attempt_id, &values).await
    }

    /// The stored metric results of an attempt, by metric.
    pub async fn attempt_metrics(&self, attempt_id: i64) -> Result<Vec<StoredMetric>> {
        let rows: Vec<MetricRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT metric, value, unit, passed, missing FROM metric_results WHERE attempt_id = $1 ORDER BY metric").bind(attempt_id).fetch_all(pool).await)?;
        Ok(rows
            .into_iter()
            .map(|(metric, value, unit, passed, missing)| StoredMetric {
                metric,
                value,
                unit,
                passed,
                missing,
            })
            .collect())
    }

    /// The stored metric results of an attempt as [`MetricValue`]s (direction and scoring
    /// from the catalogue; unknown keys are two-sided and not scored).
    pub async fn attempt_metric_values(&self, attempt_id: i64) -> Result<Vec<MetricValue>> {
        Ok(self
            .attempt_metrics(attempt_id)
            .await?
            .into_iter()
            .map(|m| {
                let def = metrics::metric(&m.metric);
                MetricValue {
                    better: def.map_or(Better::TwoSided, |d| d.better),
                    scored: def.is_some_and(|d| d.scored),
                    key: m.metric,
                    value: m.value,
                    unit: m.unit,
                    missing: m.missing,
                }
            })
            .collect())
    }

    /// A trainee's proficiency in an exercise (all zero before the first scored attempt).
    pub async fn proficiency(
        &self,
        trainee_id: i64,
        exercise_id: i64,
    ) -> Result<ProficiencyRecord> {
        let row: Option<ProficiencyRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT attempts, passes, consecutive_passes, proficient, proficient_attempt_id, cusum FROM proficiency WHERE trainee_id = $1 AND exercise_id = $2")
                .bind(trainee_id)
                .bind(exercise_id)
                .fetch_optional(pool).await)?;
        let u = |v: i64| u32::try_from(v).unwrap_or(0);
        Ok(match row {
            Some((attempts, passes, consecutive, proficient, at, cusum)) => ProficiencyRecord {
                trainee_id,
                exercise_id,
                state: ProficiencyState {
                    attempts: u(attempts),
                    passes: u(passes),
                    consecutive_passes: u(consecutive),
                    proficient,
                },
                proficient_attempt_id: at,
                cusum,
            },
            None => ProficiencyRecord {
                trainee_id,
                exercise_id,
                state: ProficiencyState::default(),
                proficient_attempt_id: None,
                cusum: 0.0,
            },
        })
    }

    /// The CUSUM chart of a trainee's scored attempts at an exercise, oldest first, with
    /// the attempt ids: restarted from 0 after each attempt that changed the standing
    /// ([`Course`]; the point of such an attempt ends the phase before it).
    pub async fn cusum_chart(
        &self,
        trainee_id: i64,
        exercise_id: i64,
        params: &CusumParams,
    ) -> Result<Vec<(i64, CusumPoint)>> {
        let history: Vec<(i64, bool)> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT id, passed FROM attempts WHERE trainee_id = $1 AND exercise_id = $2 AND status = 'complete' AND scored = TRUE ORDER BY started_ns, id")
            .bind(trainee_id)
            .bind(exercise_id)
            .fetch_all(pool).await)?;
        let passes: Vec<bool> = history.iter().map(|h| h.1).collect();
        Ok(history
            .iter()
            .map(|h| h.0)
            .zip(Course::of(&passes, params)?.cusum)
            .collect())
    }
}

/// The proficiency of a trainee whose scored attempts at an exercise, oldest first, are
/// `history` (`(attempt id, passed)`): [`Course`] with the default CUSUM parameters.
pub(super) fn proficiency_of(
    trainee_id: i64,
    exercise_id: i64,
    history: &[(i64, bool)],
) -> Result<ProficiencyRecord> {
    let passes: Vec<bool> = history.iter().map(|h| h.1).collect();
    let course = Course::of(&passes, &CusumParams::default())?;
    let proficient_attempt_id = course
        .first_proficient
        .and_then(|n| history.get(n as usize - 1))
        .map(|h| h.0);
    Ok(ProficiencyRecord {
        trainee_id,
        exercise_id,
        state: course.state,
        proficient_attempt_id,
        cusum: course.current.value,
    })
}
