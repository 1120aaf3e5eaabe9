//! What an attempt's recording shows: the executed incision against the planned line seen
//! from above (x, y in mm), the tool tip's path, and the force over time. Read from the
//! attempt's stored `.mcap` with the assessor's `attempt_data` (off the async threads), kept
//! in a small cache keyed by attempt and file size.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use cutlab_assessor::store::Attempt;
use cutlab_assessor::{ExercisePlan, attempt_data};
use cutlab_recorder::Recording;
use serde::Serialize;

use crate::AppState;
use crate::error::AppError;

/// Points kept per series (evenly thinned).
const MAX_POINTS: usize = 1500;
/// Traces kept in memory.
const CACHE_ENTRIES: usize = 64;

#[derive(Debug, Serialize)]
pub struct AttemptTrace {
    /// The planned incision, `[x, y]` in mm (top view, along the plan's z).
    pub planned_mm: Vec<[f64; 2]>,
    /// The blade tip while cutting, `[x, y]` in mm.
    pub cut_mm: Vec<[f64; 2]>,
    /// The tip's whole path, `[x, y]` in mm.
    pub path_mm: Vec<[f64; 2]>,
    /// `[t_s, |F| in N]`.
    pub force: Vec<[f64; 2]>,
    /// The plan's force limit (what `time_above_force_limit_s` counts above); not the pass
    /// limit on the peak force, which is the exercise's threshold (drawn on the chart).
    pub force_limit_n: f64,
    pub tolerance_mm: f64,
}

/// Cached traces by attempt id, with the recording's size they were read at.
#[derive(Debug, Default)]
pub struct TraceCache(Mutex<HashMap<i64, (u64, Arc<AttemptTrace>)>>);

impl TraceCache {
    fn get(&self, id: i64, len: u64) -> Option<Arc<AttemptTrace>> {
        let map = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        map.get(&id)
            .filter(|(l, _)| *l == len)
            .map(|(_, t)| t.clone())
    }
    fn put(&self, id: i64, len: u64, t: Arc<AttemptTrace>) {
        let mut map = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if map.len() >= CACHE_ENTRIES
            && !map.contains_key(&id)
            && let Some(k) = map.keys().next().copied()
        {
            map.remove(&k);
        }
        map.insert(id, (len, t));
    }
}

fn thin<T: Copy>(v: &[T]) -> Vec<T> {
    if v.len() <= MAX_POINTS {
        return v.to_vec();
    }
    let step = v.len().div_ceil(MAX_POINTS);
    v.iter()
        .step_by(step)
        .copied()
        .chain(v.last().copied())
        .collect()
}

fn xy_mm(p: [f64; 3]) -> [f64; 2] {
    [p[0] * 1e3, p[1] * 1e3]
}

/// The trace of attempt `a`, or `None` when it has no readable recording.
pub async fn trace(state: &AppState, a: &Attempt) -> Result<Option<Arc<AttemptTrace>>, AppError> {
    let Some((mcap, _)) = a.recording_files() else {
        return Ok(None);
    };
    let Ok(meta) = tokio::fs::metadata(&mcap).await else {
        return Ok(None);
    };
    if !meta.is_file() {
        return Ok(None);
    }
    if let Some(t) = state.traces().get(a.id, meta.len()) {
        return Ok(Some(t));
    }
    let plan = state.store().exercise_plan(a.exercise_id).await?;
    let read = tokio::task::spawn_blocking(move || read_trace(&mcap, &plan))
        .await
        .map_err(|e| AppError::Internal(format!("trace reader: {e}")))?;
    match read {
        Ok(t) => {
            let t = Arc::new(t);
            state.traces().put(a.id, meta.len(), t.clone());
            Ok(Some(t))
        }
        Err(e) => {
            tracing::warn!("attempt {}: recording unreadable: {e}", a.id);
            Ok(None)
        }
    }
}

/// Why an attempt's recording gave no trace (logged; the page goes without it).
#[derive(Debug, thiserror::Error)]
enum TraceError {
    #[error(transparent)]
    Recording(#[from] cutlab_recorder::RecorderError),
    #[error(transparent)]
    Attempt(#[from] cutlab_assessor::AssessError),
}

fn read_trace(mcap: &std::path::Path, plan: &ExercisePlan) -> Result<AttemptTrace, TraceError> {
    let rec = Recording::open(mcap)?;
    let data = attempt_data(&rec, plan)?;
    let drawing = plan.kind_plan().drawing();
    let cut: Vec<[f64; 2]> = data.cuts.iter().map(|c| xy_mm(c.tip_m)).collect();
    let path: Vec<[f64; 2]> = data.poses.iter().map(|p| xy_mm(p.tip_m)).collect();
    let force: Vec<[f64; 2]> = data
        .forces
        .iter()
        .map(|f| {
            [
                f.t_s,
                f.force_newtons.iter().map(|c| c * c).sum::<f64>().sqrt(),
            ]
        })
        .collect();
    Ok(AttemptTrace {
        planned_mm: drawing.lines_m.into_iter().flatten().map(xy_mm).collect(),
        cut_mm: thin(&cut),
        path_mm: thin(&path),
        force: thin(&force),
        force_limit_n: drawing.force_limit_n,
        tolerance_mm: drawing.tolerance_m * 1e3,
    })
}
