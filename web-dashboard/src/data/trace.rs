//! What an attempt's recording shows: the executed incision against the planned line seen
//! from above (x, y in mm), the tool tip's path, and the force over time. Read from the
//! attempt's stored `.mcap` with the assessor's `attempt_data` (off the async threads), kept
//! in a small cache keyed by attempt and file size.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use cutlab_assessor::store::Attempt;
use cutlab_recorder::Recording;
use cutlab_scoring::exercise::Drawing;
use cutlab_scoring::{ExercisePlan, attempt_data};
use nalgebra::Vector3;
use serde::Serialize;

use crate::AppState;
use crate::auth::CurrentUser;
use crate::error::AppError;

/// Points kept per series (evenly thinned).
const MAX_POINTS: usize = 1500;
/// Entries kept in memory by a [`RecordingCache`].
const CACHE_ENTRIES: usize = 64;

#[derive(Debug, Clone, Serialize)]
pub struct AttemptTrace {
    /// The planned incision, `[along, across]` in mm (top view, seen along the plan's normal;
    /// along the plan's first line, which runs left to right).
    pub planned_mm: Vec<[f64; 2]>,
    /// The blade tip while cutting, `[along, across]` in mm.
    pub cut_mm: Vec<[f64; 2]>,
    /// The tip's whole path, `[along, across]` in mm.
    pub path_mm: Vec<[f64; 2]>,
    /// `[t_s, |F| in N]`.
    pub force: Vec<[f64; 2]>,
    /// The plan's force limit (what `time_above_force_limit_s` counts above); not the pass
    /// limit on the peak force, which is the exercise's threshold (drawn on the chart).
    pub force_limit_n: f64,
    pub tolerance_mm: f64,
}

/// What was read from attempts' recordings, by attempt id, with the recording's size it was
/// read at (a recording that grew is read again); at most [`CACHE_ENTRIES`].
#[derive(Debug)]
pub struct RecordingCache<T>(Mutex<HashMap<i64, (u64, Arc<T>)>>);

/// Cached traces.
pub type TraceCache = RecordingCache<AttemptTrace>;

impl<T> Default for RecordingCache<T> {
    fn default() -> Self {
        Self(Mutex::new(HashMap::new()))
    }
}

impl<T> RecordingCache<T> {
    pub(crate) fn get(&self, id: i64, len: u64) -> Option<Arc<T>> {
        let map = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        map.get(&id)
            .filter(|(l, _)| *l == len)
            .map(|(_, t)| t.clone())
    }
    pub(crate) fn put(&self, id: i64, len: u64, t: Arc<T>) {
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

/// The view from above the tissue: a point's coordinates in the plane whose normal is the
/// plan's, along the plan's first line (from its start to its end, so the line runs left to
/// right in every exercise) and across it (`normal x along`), mm. Depth along the normal does
/// not show: a cut 8 mm below a line on the surface lies on the line, as the lateral metrics
/// measure it. Before, the chart took world x and y, which for the body wall (its normal +y)
/// drew the blade's depth as a lateral miss.
#[derive(Debug, Clone, Copy, PartialEq)]
struct TopView {
    along: Vector3<f64>,
    across: Vector3<f64>,
}

/// From the start of `line` to its end, unless the line (nearly) closes on itself: its end
/// nearer its start than half the farthest point's distance.
fn open_direction(line: &[[f64; 3]]) -> Option<Vector3<f64>> {
    let start = Vector3::from(*line.first()?);
    let d = Vector3::from(*line.last()?) - start;
    let reach = line
        .iter()
        .map(|p| (Vector3::from(*p) - start).norm())
        .fold(0.0, f64::max);
    (d.norm() >= 0.5 * reach).then_some(d)
}

impl TopView {
    fn of(drawing: &Drawing) -> Self {
        let n = Vector3::from(drawing.normal)
            .try_normalize(1e-12)
            .unwrap_or_else(Vector3::z);
        let in_plane = |d: Vector3<f64>| (d - n * n.dot(&d)).try_normalize(1e-9);
        let first = drawing
            .lines_m
            .iter()
            .chain(&drawing.marks_m)
            .find(|l| l.len() >= 2);
        let along = first
            .and_then(|l| in_plane(open_direction(l)?))
            // a line that closes on itself (an excision's outline, a pattern's circle) or
            // none: world x, else y, in the plane (as the station's view)
            .or_else(|| in_plane(Vector3::x()))
            .or_else(|| in_plane(Vector3::y()))
            .unwrap_or_else(Vector3::x);
        Self {
            along,
            across: n.cross(&along),
        }
    }

    fn mm(&self, p: [f64; 3]) -> [f64; 2] {
        let p = Vector3::from(p);
        [self.along.dot(&p) * 1e3, self.across.dot(&p) * 1e3]
    }
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

/// [`trace`] as `user` may see it: a trainee is not handed the planned line of an exam-only
/// exercise (the station never shows it; drawn after one attempt, it would guide the next).
pub async fn trace_for(
    state: &AppState,
    user: &CurrentUser,
    a: &Attempt,
) -> Result<Option<Arc<AttemptTrace>>, AppError> {
    let Some(t) = trace(state, a).await? else {
        return Ok(None);
    };
    if user.is_staff() || !state.store().get_exercise(a.exercise_id).await?.exam_only {
        return Ok(Some(t));
    }
    Ok(Some(Arc::new(AttemptTrace {
        planned_mm: Vec::new(),
        ..(*t).clone()
    })))
}

/// Why an attempt's recording gave no trace (logged; the page goes without it).
#[derive(Debug, thiserror::Error)]
enum TraceError {
    #[error(transparent)]
    Recording(#[from] cutlab_recorder::RecorderError),
    #[error(transparent)]
    Attempt(#[from] cutlab_scoring::ScoreError),
}

fn read_trace(mcap: &std::path::Path, plan: &ExercisePlan) -> Result<AttemptTrace, TraceError> {
    let rec = Recording::open(mcap)?;
    let data = attempt_data(&rec, plan)?;
    let drawing = plan.kind_plan().drawing();
    let view = TopView::of(&drawing);
    let cut: Vec<[f64; 2]> = data.cuts.iter().map(|c| view.mm(c.tip_m)).collect();
    let path: Vec<[f64; 2]> = data.poses.iter().map(|p| view.mm(p.tip_m)).collect();
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
        planned_mm: drawing
            .lines_m
            .iter()
            .flatten()
            .map(|&p| view.mm(p))
            .collect(),
        cut_mm: thin(&cut),
        path_mm: thin(&path),
        force: thin(&force),
        force_limit_n: drawing.force_limit_n,
        tolerance_mm: drawing.tolerance_m * 1e3,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn drawing(normal: [f64; 3], line: Vec<[f64; 3]>) -> Drawing {
        Drawing {
            lines_m: vec![line],
            marks_m: Vec::new(),
            normal,
            tolerance_m: 0.002,
            force_limit_n: 2.5,
        }
    }

    #[test]
    fn the_top_view_looks_along_the_plans_normal_with_its_line_left_to_right() {
        // the body wall: normal +y, the line along +z
        let d = drawing([0.0, 1.0, 0.0], vec![[0.01, 0.05, 0.0], [0.01, 0.05, 0.06]]);
        let v = TopView::of(&d);
        let [a0, c0] = v.mm([0.01, 0.05, 0.0]);
        let [a1, c1] = v.mm([0.01, 0.05, 0.06]);
        assert!(
            (a1 - a0 - 60.0).abs() < 1e-9,
            "runs left to right: {a0} {a1}"
        );
        assert!((c1 - c0).abs() < 1e-9);
        // 8 mm below the line's middle: on the line, seen from above
        let [a, c] = v.mm([0.01, 0.042, 0.03]);
        assert!(
            (a - a0 - 30.0).abs() < 1e-9 && (c - c0).abs() < 1e-9,
            "{a} {c}"
        );
        // 1 mm to the side (x) shows as 1 mm across
        let [_, c] = v.mm([0.011, 0.05, 0.03]);
        assert!(((c - c0).abs() - 1.0).abs() < 1e-9, "{c}");
    }

    #[test]
    fn the_chest_walls_view_is_world_x_and_y_as_before() {
        let d = drawing([0.0, 0.0, 1.0], vec![[-0.03, 0.0, 0.02], [0.03, 0.0, 0.02]]);
        let v = TopView::of(&d);
        assert_eq!(v.mm([0.001, 0.002, 0.5]), [1.0, 2.0]);
        // a closed line (a circle) has no direction of its own: world x
        let circle = drawing(
            [0.0, 0.0, 1.0],
            vec![[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.01, 0.0, 0.0]],
        );
        assert_eq!(TopView::of(&circle).mm([0.001, 0.002, 0.0]), [1.0, 2.0]);
    }
}
