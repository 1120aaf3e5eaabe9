//! Expert plans, exercises (a scene, a plan and metric thresholds) and the thresholds.

use serde::{Deserialize, Serialize};

use super::{BeginWrite, Store, conflict, now_ns, text};
use crate::error::{AssessError, Result};
use cutlab_scoring::device_class::DeviceClass;
use cutlab_scoring::exercise::ExercisePlan;
use cutlab_scoring::metrics::{Better, MetricValue};
use cutlab_scoring::proficiency::{Threshold, Thresholds};

/// An exercise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Exercise {
    pub id: i64,
    pub name: String,
    pub scene: String,
    pub description: String,
    pub plan_id: i64,
    /// The `k` of `mean +/- k SD` for expert-derived thresholds.
    pub threshold_k: f64,
    pub created_ns: i64,
    /// The station runs it in exam mode only (the plan never shown on the tissue).
    pub exam_only: bool,
}

/// What [`Store::create_exercise`] needs.
#[derive(Debug, Clone)]
pub struct NewExercise<'a> {
    pub name: &'a str,
    pub scene: &'a str,
    pub description: &'a str,
    pub plan: &'a ExercisePlan,
    /// Hand-set thresholds until expert attempts replace them (may be empty).
    pub thresholds: &'a [Threshold],
    pub threshold_k: f64,
    /// The station runs it in exam mode only.
    pub exam_only: bool,
}

/// What [`Store::update_exercise`] changes (besides the plan).
#[derive(Debug, Clone, Copy)]
pub struct ExerciseEdit<'a> {
    pub scene: &'a str,
    pub description: &'a str,
    pub threshold_k: f64,
    pub exam_only: bool,
}

/// Where an exercise's thresholds came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ThresholdSource {
    /// Set by hand (the built-in defaults, an import).
    Default,
    /// Derived from expert attempts.
    Experts,
}

impl ThresholdSource {
    fn as_str(self) -> &'static str {
        match self {
            ThresholdSource::Default => "default",
            ThresholdSource::Experts => "experts",
        }
    }
}

type ThresholdRow = (String, String, f64, f64, i64, Option<f64>, Option<f64>);

/// A stored threshold row.
fn threshold((key, better, mean, sd, n, lower, upper): ThresholdRow) -> Result<Threshold> {
    let better = Better::parse(&better).ok_or_else(|| {
        AssessError::InvalidInput(format!(
            "stored threshold of {key}: unknown direction {better:?}"
        ))
    })?;
    Ok(Threshold {
        key,
        better,
        mean,
        sd,
        n_experts: usize::try_from(n).unwrap_or(0),
        lower,
        upper,
    })
}
type ExerciseRow = (i64, String, String, String, i64, f64, i64, bool);
const EXERCISE_SELECT: &str = "SELECT id, name, scene, description, plan_id, threshold_k, created_ns, exam_only FROM exercises";

fn exercise(
    (id, name, scene, description, plan_id, threshold_k, created_ns, exam_only): ExerciseRow,
) -> Exercise {
    Exercise {
        id,
        name,
        scene,
        description,
        plan_id,
        threshold_k,
        created_ns,
        exam_only,
    }
}

/// Inserts `thresholds` of `exercise_id` in the write transaction `tx` (of either engine):
/// into `metric_thresholds` with their `source`, or with `class:` into `class_thresholds`
/// for that device class.
macro_rules! write_thresholds {
    (@rows $tx:expr, $sql:expr, $exercise_id:expr, $thresholds:expr, $last:expr) => {
            for t in $thresholds {
                sqlx::query($sql)
                    .bind($exercise_id)
                    .bind(&t.key)
                    .bind(t.better.as_str())
                    .bind(t.mean)
                    .bind(t.sd)
                    .bind(i64::try_from(t.n_experts).unwrap_or(i64::MAX))
                    .bind(t.lower)
                    .bind(t.upper)
                    .bind($last)
                    .execute(&mut *$tx)
                    .await?;
            }
    };
    ($tx:expr, $exercise_id:expr, $thresholds:expr, class: $class:expr) => {
        write_thresholds!(@rows $tx, "INSERT INTO class_thresholds (exercise_id, metric, better, mean, sd, n_experts, lower_limit, upper_limit, device_class) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)", $exercise_id, $thresholds, $class.as_str())
    };
    ($tx:expr, $exercise_id:expr, $thresholds:expr, $source:expr) => {
        write_thresholds!(@rows $tx, "INSERT INTO metric_thresholds (exercise_id, metric, better, mean, sd, n_experts, lower_limit, upper_limit, source) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)", $exercise_id, $thresholds, $source.as_str())
    };
}

/// Inserts `plan` (an [`ExercisePlan`]) into `expert_plans` on `$conn` (a pool or a write
/// transaction of either engine); its value is the new plan's id.
macro_rules! insert_plan {
    ($conn:expr, $plan:expr) => {{
        let kind = $plan.kind_plan();
        let id: i64 = sqlx::query_scalar("INSERT INTO expert_plans (name, scene, depth_m, tolerance_m, plan_json, created_ns) VALUES ($1, $2, $3, $4, $5, $6) RETURNING id")
            .bind(kind.name())
            .bind(kind.scene())
            .bind(kind.depth_m())
            .bind(kind.tolerance_m())
            .bind($plan.to_json()?)
            .bind(now_ns())
            .fetch_one($conn)
            .await?;
        id
    }};
}

impl Store {
    /// Stores a plan (checked first); returns its id.
    pub async fn create_plan(&self, plan: &ExercisePlan) -> Result<i64> {
        plan.check()?;
        Ok(crate::on_db!(&self.db, pool => insert_plan!(pool, plan)))
    }

    /// The plan with `id`.
    pub async fn get_plan(&self, id: i64) -> Result<ExercisePlan> {
        let json: Option<String> = crate::on_db!(&self.db, pool => sqlx::query_scalar("SELECT plan_json FROM expert_plans WHERE id = $1")
                .bind(id)
                .fetch_optional(pool).await)?;
        Ok(ExercisePlan::from_json(&json.ok_or_else(|| {
            AssessError::NotFound(format!("expert plan {id}"))
        })?)?)
    }

    /// All stored plans `(id, plan)`, oldest first.
    pub async fn list_plans(&self) -> Result<Vec<(i64, ExercisePlan)>> {
        let rows: Vec<(i64, String)> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT id, plan_json FROM expert_plans ORDER BY id")
                .fetch_all(pool).await)?;
        rows.into_iter()
            .map(|(id, json)| Ok((id, ExercisePlan::from_json(&json)?)))
            .collect()
    }

    /// Adds an exercise with its plan and hand-set thresholds (one transaction).
    pub async fn create_exercise(&self, new: &NewExercise<'_>) -> Result<Exercise> {
        new.plan.check()?;
        let name = text::label("an exercise's name", new.name, text::MAX_LABEL_CHARS)?;
        let scene = text::label("an exercise's scene", new.scene, text::MAX_LABEL_CHARS)?;
        let description = text::text(
            "an exercise's description",
            new.description,
            text::MAX_DESCRIPTION_CHARS,
        )?;
        if !(new.threshold_k > 0.0) {
            return Err(AssessError::InvalidInput(format!(
                "threshold k = {}: must be > 0",
                new.threshold_k
            )));
        }
        let id = crate::on_db!(&self.db, pool => {
            let mut tx = pool.begin_write().await?;
            let plan_id = insert_plan!(&mut *tx, new.plan);
            let id: i64 = sqlx::query_scalar("INSERT INTO exercises (name, scene, description, plan_id, threshold_k, created_ns, exam_only) VALUES ($1, $2, $3, $4, $5, $6, $7) RETURNING id")
                .bind(name)
                .bind(scene)
                .bind(description)
                .bind(plan_id)
                .bind(new.threshold_k)
                .bind(now_ns())
                .bind(new.exam_only)
                .fetch_one(&mut *tx)
                .await
                .map_err(conflict(|| format!("an exercise named {name:?} exists")))?;
            write_thresholds!(tx, id, new.thresholds, ThresholdSource::Default);
            tx.commit().await?;
            id
        });
        self.get_exercise(id).await
    }

    pub async fn get_exercise(&self, id: i64) -> Result<Exercise> {
        let row: Option<ExerciseRow> = crate::on_db!(&self.db, pool => sqlx::query_as(sqlx::AssertSqlSafe(format!(
            "{EXERCISE_SELECT} WHERE id = $1"
        )))
        .bind(id)
        .fetch_optional(pool).await)?;
        row.map(exercise)
            .ok_or_else(|| AssessError::NotFound(format!("exercise {id}")))
    }

    pub async fn exercise_by_name(&self, name: &str) -> Result<Exercise> {
        let row: Option<ExerciseRow> = crate::on_db!(&self.db, pool => sqlx::query_as(sqlx::AssertSqlSafe(format!(
            "{EXERCISE_SELECT} WHERE name = $1"
        )))
        .bind(name)
        .fetch_optional(pool).await)?;
        row.map(exercise)
            .ok_or_else(|| AssessError::NotFound(format!("exercise {name:?}")))
    }

    pub async fn list_exercises(&self) -> Result<Vec<Exercise>> {
        let rows: Vec<ExerciseRow> = crate::on_db!(&self.db, pool => sqlx::query_as(sqlx::AssertSqlSafe(format!(
            "{EXERCISE_SELECT} ORDER BY name"
        )))
        .fetch_all(pool).await)?;
        Ok(rows.into_iter().map(exercise).collect())
    }

    /// Edits an exercise: its scene, description, `k` and exam-only flag, and (if given) a new
    /// expert plan (stored as a new plan; attempts already scored keep their results). One
    /// transaction.
    pub async fn update_exercise(
        &self,
        id: i64,
        edit: &ExerciseEdit<'_>,
        plan: Option<&ExercisePlan>,
    ) -> Result<Exercise> {
        let ExerciseEdit {
            scene,
            description,
            threshold_k,
            exam_only,
        } = *edit;
        let scene = text::label("an exercise's scene", scene, text::MAX_LABEL_CHARS)?;
        let description = text::text(
            "an exercise's description",
            description,
            text::MAX_DESCRIPTION_CHARS,
        )?;
        if !(threshold_k > 0.0) || !threshold_k.is_finite() {
            return Err(AssessError::InvalidInput(format!(
                "threshold k = {threshold_k}: must be > 0"
            )));
        }
        if let Some(p) = plan {
            p.check()?;
        }
        crate::on_db!(&self.db, pool => {
            let mut tx = pool.begin_write().await?;
            let done = sqlx::query(
                "UPDATE exercises SET scene = $1, description = $2, threshold_k = $3, exam_only = $4 WHERE id = $5",
            )
            .bind(scene)
            .bind(description)
            .bind(threshold_k)
            .bind(exam_only)
            .bind(id)
            .execute(&mut *tx)
            .await?;
            if done.rows_affected() == 0 {
                return Err(AssessError::NotFound(format!("exercise {id}")));
            }
            if let Some(p) = plan {
                let plan_id = insert_plan!(&mut *tx, p);
                sqlx::query("UPDATE exercises SET plan_id = $1 WHERE id = $2")
                    .bind(plan_id)
                    .bind(id)
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await?;
        });
        self.get_exercise(id).await
    }

    /// The exercise's expert plan.
    pub async fn exercise_plan(&self, exercise_id: i64) -> Result<ExercisePlan> {
        let e = self.get_exercise(exercise_id).await?;
        self.get_plan(e.plan_id).await
    }

    /// The exercise's current thresholds for any device: pooled over its experts or set by
    /// hand (what the exercise's pages show).
    pub async fn thresholds(&self, exercise_id: i64) -> Result<Thresholds> {
        self.thresholds_of(exercise_id, None).await
    }

    /// The thresholds an attempt made with a device of `class` is judged by: the class's own
    /// (derived from experts with such a device) where it has them, metric by metric, the
    /// exercise's ([`Store::thresholds`]) otherwise.
    pub async fn thresholds_for(&self, exercise_id: i64, class: DeviceClass) -> Result<Thresholds> {
        self.thresholds_of(exercise_id, Some(class)).await
    }

    /// The thresholds for `attempt`'s device class.
    pub async fn attempt_thresholds(&self, attempt: &super::Attempt) -> Result<Thresholds> {
        let class = DeviceClass::of(attempt.device.as_deref());
        self.thresholds_for(attempt.exercise_id, class).await
    }

    async fn thresholds_of(
        &self,
        exercise_id: i64,
        class: Option<DeviceClass>,
    ) -> Result<Thresholds> {
        let e = self.get_exercise(exercise_id).await?;
        let rows: Vec<ThresholdRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT metric, better, mean, sd, n_experts, lower_limit, upper_limit FROM metric_thresholds WHERE exercise_id = $1 ORDER BY metric").bind(exercise_id).fetch_all(pool).await)?;
        let mut metrics = rows
            .into_iter()
            .map(threshold)
            .collect::<Result<Vec<_>>>()?;
        if let Some(class) = class {
            let rows: Vec<ThresholdRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT metric, better, mean, sd, n_experts, lower_limit, upper_limit FROM class_thresholds WHERE exercise_id = $1 AND device_class = $2 ORDER BY metric").bind(exercise_id).bind(class.as_str()).fetch_all(pool).await)?;
            for t in rows.into_iter().map(threshold) {
                let t = t?;
                metrics.retain(|m| m.key != t.key);
                metrics.push(t);
            }
            metrics.sort_by(|a, b| a.key.cmp(&b.key));
        }
        // a peak-force limit derived from expert attempts (a scripted hand's, whose spread is
        // a robot's) is the plan's force limit, a safety limit; one set by hand stays
        let force_limit_n = self.get_plan(e.plan_id).await?.kind_plan().force_limit_n();
        if let Some(t) = metrics
            .iter_mut()
            .find(|t| t.key == "peak_force_n" && t.n_experts > 0)
        {
            t.upper = Some(force_limit_n);
            t.lower = None;
            t.mean = t.mean.min(force_limit_n);
        }
        Ok(Thresholds {
            k: e.threshold_k,
            metrics,
        })
    }

    /// Replaces the exercise's thresholds.
    pub async fn set_thresholds(
        &self,
        exercise_id: i64,
        thresholds: &Thresholds,
        source: ThresholdSource,
    ) -> Result<()> {
        self.get_exercise(exercise_id).await?;
        crate::on_db!(&self.db, pool => {
            let mut tx = pool.begin_write().await?;
            sqlx::query("DELETE FROM metric_thresholds WHERE exercise_id = $1")
                .bind(exercise_id)
                .execute(&mut *tx)
                .await?;
            sqlx::query("DELETE FROM class_thresholds WHERE exercise_id = $1")
                .bind(exercise_id)
                .execute(&mut *tx)
                .await?;
            write_thresholds!(tx, exercise_id, &thresholds.metrics, source);
            tx.commit().await?;
        });
        Ok(())
    }

    /// Derives the exercise's thresholds from its complete expert attempts (`mean +/- k SD`
    /// after outlier removal, `k` of the exercise): pooled over all of them, and for each
    /// device class with at least 2 expert attempts, over theirs ([`Store::thresholds_for`]).
    /// Stores them (replacing every threshold of the exercise) and returns the pooled ones.
    /// Errors when no metric has at least 2 expert values.
    pub async fn thresholds_from_experts(&self, exercise_id: i64) -> Result<Thresholds> {
        let e = self.get_exercise(exercise_id).await?;
        let rows: Vec<(i64, Option<String>)> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT id, device FROM attempts WHERE exercise_id = $1 AND expert = TRUE AND status = 'complete' ORDER BY id").bind(exercise_id).fetch_all(pool).await)?;
        let mut attempts: Vec<(DeviceClass, Vec<MetricValue>)> = Vec::with_capacity(rows.len());
        for (id, device) in rows {
            let class = DeviceClass::of(device.as_deref());
            attempts.push((class, self.attempt_metric_values(id).await?));
        }
        let tolerance_m = self
            .exercise_plan(exercise_id)
            .await?
            .kind_plan()
            .tolerance_m();
        let pooled: Vec<Vec<MetricValue>> = attempts.iter().map(|(_, m)| m.clone()).collect();
        let t =
            Thresholds::from_experts(&pooled, e.threshold_k)?.within_plan_tolerance(tolerance_m);
        if t.metrics.is_empty() {
            return Err(AssessError::InvalidInput(format!(
                "exercise {:?}: {} complete expert attempts, need at least 2 with metric values",
                e.name,
                attempts.len()
            )));
        }
        self.set_thresholds(exercise_id, &t, ThresholdSource::Experts)
            .await?;
        for class in DeviceClass::ALL {
            let theirs: Vec<Vec<MetricValue>> = attempts
                .iter()
                .filter(|(c, _)| *c == class)
                .map(|(_, m)| m.clone())
                .collect();
            if theirs.len() >= 2 {
                let t = Thresholds::from_experts(&theirs, e.threshold_k)?
                    .within_plan_tolerance(tolerance_m);
                self.write_class_thresholds(exercise_id, class, &t).await?;
            }
        }
        Ok(t)
    }

    async fn write_class_thresholds(
        &self,
        exercise_id: i64,
        class: DeviceClass,
        thresholds: &Thresholds,
    ) -> Result<()> {
        crate::on_db!(&self.db, pool => {
            let mut tx = pool.begin_write().await?;
            write_thresholds!(tx, exercise_id, &thresholds.metrics, class: class);
            tx.commit().await?;
        });
        Ok(())
    }
}
