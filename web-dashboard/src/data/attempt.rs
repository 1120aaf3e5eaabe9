//! One attempt: every metric with its threshold and verdict, the debriefing, its recordings.

use cutlab_assessor::store::Attempt;
use cutlab_scoring::metrics;
use serde::Serialize;

use super::debrief::{self, Comment, SignOff};
use super::{ExerciseRef, UserRef};
use crate::AppState;
use crate::error::AppError;

#[derive(Debug, Serialize)]
pub struct AttemptDetail {
    pub attempt: Attempt,
    pub trainee: UserRef,
    pub exercise: ExerciseRef,
    pub metrics: Vec<MetricRow>,
    /// The exercise's pass limits on the peak force (its `peak_force_n` threshold), in N:
    /// the force limit the attempt is scored with; `None` without such a threshold.
    pub peak_force_limits_n: Option<PassLimits>,
    /// The plan's force limit (its safety limit), N.
    pub force_limit_n: Option<f64>,
    pub comments: Vec<Comment>,
    pub signoff: Option<SignOff>,
    pub recordings: RecordingFiles,
}

#[derive(Debug, Serialize)]
pub struct MetricRow {
    pub key: String,
    pub unit: String,
    pub description: String,
    pub scored: bool,
    pub value: Option<f64>,
    pub missing: Option<String>,
    pub passed: Option<bool>,
    /// The threshold's reference (expert mean) and limits, if the metric has one.
    pub mean: Option<f64>,
    pub lower_limit: Option<f64>,
    pub upper_limit: Option<f64>,
}

/// A threshold's pass limits (SI units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PassLimits {
    pub lower: Option<f64>,
    pub upper: Option<f64>,
}

/// The metric whose threshold is the force limit drawn on the force chart.
pub const PEAK_FORCE: &str = "peak_force_n";

/// Which of the attempt's recordings the dashboard can serve: from the recording store or
/// from this machine's disk.
#[derive(Debug, Serialize)]
pub struct RecordingFiles {
    pub mcap: bool,
    pub rrd: bool,
}

impl RecordingFiles {
    pub fn of(state: &AppState, a: &Attempt) -> Self {
        let stored = state.config().recordings.is_some();
        let (mcap, rrd) = match a.recording_files() {
            Some((mcap, rrd)) => (is_file(&mcap), is_file(&rrd)),
            None => (false, false),
        };
        Self {
            mcap: mcap || (stored && a.recording_sha256.is_some()),
            rrd: rrd || (stored && a.rrd_sha256.is_some()),
        }
    }
}

fn is_file(p: &std::path::Path) -> bool {
    std::fs::metadata(p).is_ok_and(|m| m.is_file())
}

pub async fn detail(state: &AppState, a: Attempt) -> Result<AttemptDetail, AppError> {
    let store = state.store();
    let trainee = UserRef::from(&store.get_user(a.trainee_id).await?);
    let e = store.get_exercise(a.exercise_id).await?;
    let thresholds = store.attempt_thresholds(&a).await?;
    let stored = store.attempt_metrics(a.id).await?;
    let mut rows: Vec<MetricRow> = stored
        .into_iter()
        .map(|m| {
            let def = metrics::metric(&m.metric);
            let t = thresholds.metrics.iter().find(|t| t.key == m.metric);
            MetricRow {
                unit: m.unit,
                description: def.map_or("", |d| d.description).to_owned(),
                scored: def.is_some_and(|d| d.scored),
                value: m.value,
                missing: m.missing,
                passed: m.passed,
                mean: t.map(|t| t.mean),
                lower_limit: t.and_then(|t| t.lower),
                upper_limit: t.and_then(|t| t.upper),
                key: m.metric,
            }
        })
        .collect();
    rows.sort_by_key(|r| metrics::catalogue_rank(&r.key));
    let peak_force_limits_n = thresholds
        .metrics
        .iter()
        .find(|t| t.key == PEAK_FORCE)
        .map(|t| PassLimits {
            lower: t.lower,
            upper: t.upper,
        })
        .filter(|l| l.lower.is_some() || l.upper.is_some());
    // the plan's own force limit, the safety limit the station's force bar shows (the chart
    // draws it when no pass limit is set on the peak force)
    let limit_n = store.get_plan(e.plan_id).await?.kind_plan().force_limit_n();
    let force_limit_n = (limit_n.is_finite() && limit_n > 0.0).then_some(limit_n);
    let recordings = RecordingFiles::of(state, &a);
    Ok(AttemptDetail {
        comments: debrief::comments(state, a.id).await?,
        signoff: debrief::signoff(state, a.id).await?,
        trainee,
        exercise: ExerciseRef {
            id: e.id,
            name: e.name,
        },
        metrics: rows,
        peak_force_limits_n,
        force_limit_n,
        recordings,
        attempt: a,
    })
}
