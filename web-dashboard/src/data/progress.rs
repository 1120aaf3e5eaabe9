//! A trainee's progress: per exercise the attempts, per-metric learning curves with the
//! expert band and the pass limits, the normalised score, the CUSUM chart with its limits;
//! and the curriculum modules' state.

use std::collections::{BTreeMap, HashMap};

use cutlab_assessor::store::{Access, AttemptStatus, User};
use cutlab_scoring::metrics::{self, Better};
use cutlab_scoring::proficiency::{Course, CusumParams, CusumPoint, CusumSignal, Thresholds};
use serde::Serialize;

use super::{ExerciseRef, ProficiencySummary, Standing, UserRef};
use crate::AppState;
use crate::error::AppError;

#[derive(Debug, Serialize)]
pub struct Progress {
    pub trainee: UserRef,
    pub exercises: Vec<ExerciseProgress>,
    pub curricula: Vec<CurriculumProgress>,
}

#[derive(Debug, Serialize)]
pub struct ExerciseProgress {
    pub exercise: ExerciseRef,
    /// Every attempt, oldest first.
    pub attempts: Vec<AttemptPoint>,
    pub proficiency: ProficiencySummary,
    /// One series per metric with a threshold, then the others with values.
    pub metrics: Vec<MetricSeries>,
    pub cusum: CusumChart,
}

#[derive(Debug, Serialize)]
pub struct AttemptPoint {
    pub id: i64,
    /// 1-based number among the scored attempts (None: not scored).
    pub n: Option<u32>,
    pub started_ns: i64,
    pub status: AttemptStatus,
    pub score: Option<f64>,
    pub passed: Option<bool>,
    /// How it was made (`guided` or `exam`, the device), for a station's attempt.
    pub mode: Option<String>,
    pub device: Option<String>,
}

/// The expert reference and limits of one metric.
#[derive(Debug, Clone, Serialize)]
pub struct Band {
    pub mean: f64,
    pub sd: f64,
    pub k: f64,
    /// `mean - k sd`, `mean + k sd`.
    pub low: f64,
    pub high: f64,
    /// The pass limits.
    pub lower_limit: Option<f64>,
    pub upper_limit: Option<f64>,
    pub n_experts: usize,
}

#[derive(Debug, Serialize)]
pub struct MetricSeries {
    pub key: String,
    pub unit: String,
    pub better: Option<Better>,
    pub description: String,
    pub band: Option<Band>,
    /// `(n, attempt id, value, passed)` per scored attempt.
    pub points: Vec<SeriesPoint>,
}

/// One metric over a trainee's scored attempts, for the summary table (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MetricSummary {
    /// The value of the last attempt with one.
    pub latest: Option<f64>,
    /// The best value: lowest or highest by the metric's direction; two-sided, the nearest
    /// to the expert mean (none without a reference).
    pub best: Option<f64>,
    pub mean: Option<f64>,
    /// Attempts passing this metric, of those with a verdict on it.
    pub passes: usize,
    pub verdicts: usize,
}

impl MetricSeries {
    pub fn summary(&self) -> MetricSummary {
        let values: Vec<f64> = self
            .points
            .iter()
            .filter_map(|p| p.value.filter(|v| v.is_finite()))
            .collect();
        let fold = |pick: fn(f64, f64) -> f64| values.iter().copied().reduce(pick);
        let best = match self.better {
            Some(Better::LowerIsBetter) => fold(f64::min),
            Some(Better::HigherIsBetter) => fold(f64::max),
            Some(Better::TwoSided) => self.band.as_ref().and_then(|b| {
                values
                    .iter()
                    .copied()
                    .min_by(|x, y| (x - b.mean).abs().total_cmp(&(y - b.mean).abs()))
            }),
            None => None,
        };
        MetricSummary {
            latest: values.last().copied(),
            best,
            mean: (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64),
            passes: self
                .points
                .iter()
                .filter(|p| p.passed == Some(true))
                .count(),
            verdicts: self.points.iter().filter(|p| p.passed.is_some()).count(),
        }
    }
}

#[derive(Debug, Serialize)]
pub struct SeriesPoint {
    pub n: u32,
    pub attempt_id: i64,
    pub value: Option<f64>,
    pub passed: Option<bool>,
}

/// The CUSUM of failures over the scored attempts, restarted from 0 after each attempt that
/// changed the standing (proficient, lapsed: see `cutlab_scoring::proficiency::Course`).
#[derive(Debug, Serialize)]
pub struct CusumChart {
    pub params: CusumParams,
    /// The acceptable limit is at `-h0`, the unacceptable one at `h1`.
    pub h0: f64,
    pub h1: f64,
    /// Per scored attempt, the value after it in its phase (at an attempt that changed the
    /// standing: the phase it ended).
    pub points: Vec<CusumPointView>,
    /// The attempts (`n`) after which the chart restarted from 0.
    pub restarts: Vec<u32>,
    /// The CUSUM now: after the last attempt, 0 when the standing changed at it.
    pub current: CusumPoint,
}

#[derive(Debug, Serialize)]
pub struct CusumPointView {
    pub n: u32,
    pub attempt_id: i64,
    pub value: f64,
    pub signal: CusumSignal,
}

#[derive(Debug, Serialize)]
pub struct CurriculumProgress {
    pub id: i64,
    pub name: String,
    /// Each exercise opens when the one before it is proficient.
    pub progression: bool,
    pub modules: Vec<ModuleProgress>,
}

#[derive(Debug, Serialize)]
pub struct ModuleProgress {
    pub id: i64,
    pub position: i64,
    pub name: String,
    pub standing: Standing,
    pub exercises: Vec<ModuleExercise>,
}

/// An exercise of a module, where the trainee stands in it and (with progression) whether
/// it is open to them.
#[derive(Debug, Serialize)]
pub struct ModuleExercise {
    pub exercise: ExerciseRef,
    pub standing: Standing,
    /// `None` in a curriculum without progression.
    pub access: Option<Access>,
}

/// A trainee's progress as cached (see [`crate::cache`]), with its page body and JSON made
/// once.
#[derive(Debug)]
pub struct Cached {
    pub data: Progress,
    pub html: std::sync::OnceLock<axum::body::Bytes>,
    pub json: std::sync::OnceLock<axum::body::Bytes>,
}

impl Cached {
    pub fn new(data: Progress) -> Self {
        Self {
            data,
            html: Default::default(),
            json: Default::default(),
        }
    }
}

/// [`progress`] through the cache.
pub async fn cached_progress(
    state: &AppState,
    trainee: &User,
) -> Result<std::sync::Arc<Cached>, AppError> {
    let cache = &state.caches().progress;
    if let Some((c, refresh)) = cache.get_or_claim(&trainee.id) {
        if refresh {
            let (state, trainee) = (state.clone(), trainee.clone());
            tokio::spawn(async move {
                let cache = &state.caches().progress;
                let stamp = cache.stamp();
                match progress(&state, &trainee).await {
                    Ok(data) => {
                        cache.put(trainee.id, std::sync::Arc::new(Cached::new(data)), stamp)
                    }
                    Err(e) => tracing::warn!("refreshing the progress of {}: {e}", trainee.name),
                }
            });
        }
        return Ok(c);
    }
    cache
        .load_once(trainee.id, || async {
            Ok(std::sync::Arc::new(Cached::new(
                progress(state, trainee).await?,
            )))
        })
        .await
}

type MetricRow = (i64, String, Option<f64>, String, Option<bool>);
/// An attempt's stored metric: key, value, unit, verdict.
type StoredValue = (String, Option<f64>, String, Option<bool>);

/// The progress of `trainee` (whom the caller may see: checked by the caller).
pub async fn progress(state: &AppState, trainee: &User) -> Result<Progress, AppError> {
    let store = state.store();
    let attempts = store.list_attempts(Some(trainee.id), None).await?;
    let rows: Vec<MetricRow> = cutlab_assessor::on_db!(store.db(), pool => sqlx::query_as("SELECT r.attempt_id, r.metric, r.value, r.unit, r.passed FROM metric_results r JOIN attempts a ON a.id = r.attempt_id WHERE a.trainee_id = $1")
        .bind(trainee.id)
        .fetch_all(pool).await)?;
    let mut by_attempt: HashMap<i64, Vec<StoredValue>> = HashMap::new();
    for (a, metric, value, unit, passed) in rows {
        by_attempt
            .entry(a)
            .or_default()
            .push((metric, value, unit, passed));
    }
    let exercises = store.list_exercises().await?;
    let mut standings: HashMap<i64, Standing> = HashMap::new();
    let mut out = Vec::new();
    for e in &exercises {
        let mine: Vec<_> = attempts
            .iter()
            .filter(|a| a.exercise_id == e.id && !a.expert)
            .collect();
        if mine.is_empty() {
            continue;
        }
        let mut n = 0u32;
        let points: Vec<AttemptPoint> = mine
            .iter()
            .map(|a| {
                let scored = a.counted_pass().is_some();
                let this = scored.then(|| {
                    n += 1;
                    n
                });
                AttemptPoint {
                    id: a.id,
                    n: this,
                    started_ns: a.started_ns,
                    status: a.status,
                    score: a.score,
                    passed: a.passed,
                    mode: a.mode.clone(),
                    device: a.device.clone(),
                }
            })
            .collect();
        let scored: Vec<&AttemptPoint> = points.iter().filter(|p| p.n.is_some()).collect();
        let params = CusumParams::default();
        let passes: Vec<bool> = scored.iter().map(|p| p.passed.unwrap_or(false)).collect();
        // the standing and the CUSUM from one course, so they agree
        let course = Course::of(&passes, &params)?;
        let proficiency = ProficiencySummary::of_course(&course, true);
        standings.insert(e.id, proficiency.standing);
        let thresholds = store.thresholds(e.id).await?;
        let metric_list = metric_series(&thresholds, &scored, &by_attempt);
        let cusum = cusum_chart(&scored, course, params);
        out.push(ExerciseProgress {
            exercise: ExerciseRef {
                id: e.id,
                name: e.name.clone(),
            },
            attempts: points,
            proficiency,
            metrics: metric_list,
            cusum,
        });
    }
    let curricula = curricula_progress(state, trainee.id, &exercises, &standings).await?;
    Ok(Progress {
        trainee: UserRef::from(trainee),
        exercises: out,
        curricula,
    })
}

/// Per metric with a threshold or a value, its series over the `scored` attempts (their
/// stored values `by_attempt`): the thresholded first, each group in catalogue order.
fn metric_series(
    thresholds: &Thresholds,
    scored: &[&AttemptPoint],
    by_attempt: &HashMap<i64, Vec<StoredValue>>,
) -> Vec<MetricSeries> {
    let mut series: BTreeMap<String, MetricSeries> = BTreeMap::new();
    for t in &thresholds.metrics {
        let def = metrics::metric(&t.key);
        let band = Band {
            mean: t.mean,
            sd: t.sd,
            k: thresholds.k,
            low: t.mean - thresholds.k * t.sd,
            high: t.mean + thresholds.k * t.sd,
            lower_limit: t.lower,
            upper_limit: t.upper,
            n_experts: t.n_experts,
        };
        series.insert(
            t.key.clone(),
            MetricSeries {
                key: t.key.clone(),
                unit: def.map_or("", |d| d.unit).to_owned(),
                better: Some(t.better),
                description: def.map_or("", |d| d.description).to_owned(),
                band: Some(band),
                points: Vec::new(),
            },
        );
    }
    for p in scored {
        let n = p.n.unwrap_or(0);
        for (metric, value, unit, passed) in by_attempt.get(&p.id).into_iter().flatten() {
            let s = series.entry(metric.clone()).or_insert_with(|| {
                let def = metrics::metric(metric);
                MetricSeries {
                    key: metric.clone(),
                    unit: unit.clone(),
                    better: def.map(|d| d.better),
                    description: def.map_or("", |d| d.description).to_owned(),
                    band: None,
                    points: Vec::new(),
                }
            });
            s.points.push(SeriesPoint {
                n,
                attempt_id: p.id,
                value: *value,
                passed: *passed,
            });
        }
    }
    // thresholded metrics first, in catalogue order, then the rest in catalogue order
    let mut metric_list: Vec<MetricSeries> = series
        .into_values()
        .filter(|s| s.band.is_some() || s.points.iter().any(|p| p.value.is_some()))
        .collect();
    metric_list.sort_by_key(|s| (s.band.is_none(), metrics::catalogue_rank(&s.key)));
    metric_list
}

/// The CUSUM chart of the `scored` attempts, from their `course`.
fn cusum_chart(scored: &[&AttemptPoint], course: Course, params: CusumParams) -> CusumChart {
    let points = scored
        .iter()
        .zip(&course.cusum)
        .map(|(p, c)| CusumPointView {
            n: p.n.unwrap_or(0),
            attempt_id: p.id,
            value: c.value,
            signal: c.signal,
        })
        .collect();
    CusumChart {
        params,
        h0: params.h0(),
        h1: params.h1(),
        points,
        restarts: course.restarts,
        current: course.current,
    }
}

/// Every curriculum's modules with the trainee's standing in each (`standings` by exercise
/// id; an exercise not there is not started).
async fn curricula_progress(
    state: &AppState,
    trainee_id: i64,
    exercises: &[cutlab_assessor::store::Exercise],
    standings: &HashMap<i64, Standing>,
) -> Result<Vec<CurriculumProgress>, AppError> {
    let store = state.store();
    let names: HashMap<i64, &str> = exercises.iter().map(|e| (e.id, e.name.as_str())).collect();
    let mut curricula = Vec::new();
    for c in store.list_curricula().await? {
        let mut modules = Vec::new();
        for m in store.curriculum_modules(c.id).await? {
            let mut ex = Vec::with_capacity(m.exercise_ids.len());
            for &id in &m.exercise_ids {
                let access = match c.progression {
                    true => Some(store.exercise_access(trainee_id, id).await?),
                    false => None,
                };
                ex.push(ModuleExercise {
                    exercise: ExerciseRef {
                        id,
                        name: names.get(&id).copied().unwrap_or("?").to_owned(),
                    },
                    standing: standings.get(&id).copied().unwrap_or(Standing::NotStarted),
                    access,
                });
            }
            let standing = module_standing(ex.iter().map(|e| e.standing));
            modules.push(ModuleProgress {
                id: m.id,
                position: m.position,
                name: m.name,
                standing,
                exercises: ex,
            });
        }
        curricula.push(CurriculumProgress {
            id: c.id,
            name: c.name,
            progression: c.progression,
            modules,
        });
    }
    Ok(curricula)
}

/// A module is proficient when every exercise is, not started when none is started.
fn module_standing(s: impl Iterator<Item = Standing> + Clone) -> Standing {
    if s.clone().all(|s| s == Standing::Proficient) && s.clone().next().is_some() {
        Standing::Proficient
    } else if s.clone().all(|s| s == Standing::NotStarted) {
        Standing::NotStarted
    } else {
        Standing::InProgress
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(better: Option<Better>, values: &[(Option<f64>, Option<bool>)]) -> MetricSeries {
        MetricSeries {
            key: "k".into(),
            unit: "m".into(),
            better,
            description: String::new(),
            band: Some(Band {
                mean: 1.0,
                sd: 0.1,
                k: 2.0,
                low: 0.8,
                high: 1.2,
                lower_limit: None,
                upper_limit: Some(2.0),
                n_experts: 0,
            }),
            points: values
                .iter()
                .enumerate()
                .map(|(i, (value, passed))| SeriesPoint {
                    n: i as u32 + 1,
                    attempt_id: i as i64,
                    value: *value,
                    passed: *passed,
                })
                .collect(),
        }
    }

    #[test]
    fn summaries_by_hand() {
        let v = [
            (Some(3.0), Some(false)),
            (Some(0.25), Some(true)),
            (None, Some(false)),
            (Some(1.5), Some(true)),
        ];
        let s = series(Some(Better::LowerIsBetter), &v).summary();
        assert_eq!(
            s,
            MetricSummary {
                latest: Some(1.5),
                best: Some(0.25),
                mean: Some(4.75 / 3.0),
                passes: 2,
                verdicts: 4,
            }
        );
        assert_eq!(
            series(Some(Better::HigherIsBetter), &v).summary().best,
            Some(3.0)
        );
        // two-sided: nearest the expert mean 1.0
        assert_eq!(series(Some(Better::TwoSided), &v).summary().best, Some(1.5));
        let empty = series(None, &[]).summary();
        assert_eq!(
            (empty.latest, empty.best, empty.mean, empty.verdicts),
            (None, None, None, 0)
        );
    }
}
