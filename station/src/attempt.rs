//! A session as an attempt: the exercise's plan projected onto the tissue before it starts,
//! and after it ends the attempt scored from its recording or marked incomplete. One path for
//! `cutlab session --trainee` and the station.

use std::path::Path;

use cutlab_assessor::AssessError;
use cutlab_assessor::recordings::RecordingStore;
use cutlab_assessor::store::{Exercise, Outcome, Role, Store};
use cutlab_haptics::Session;
use cutlab_haptics::device::Planning;
use cutlab_haptics::plan::Plan;
use cutlab_recorder::Recording;
use cutlab_scoring::{ExercisePlan, MetricSet};
use cutlab_sim::{Point3, Vector3};

use crate::StationError;

/// An attempt let in: its trainee, its exercise and plan (loaded once for the whole run),
/// open to the trainee. Only [`admit`] makes one, so no attempt starts without the
/// curriculum's lock checked.
#[derive(Debug, Clone)]
pub struct Admitted {
    trainee_id: i64,
    exercise: Exercise,
    plan: ExercisePlan,
}

impl Admitted {
    /// The trainee's user id (a new name became a trainee).
    pub fn trainee_id(&self) -> i64 {
        self.trainee_id
    }

    pub fn exercise(&self) -> &Exercise {
        &self.exercise
    }

    /// The exercise's expert plan, the attempt is scored against.
    pub fn plan(&self) -> &ExercisePlan {
        &self.plan
    }
}

/// Lets `trainee`'s attempt at the exercise named `exercise` in, or says why not: an unknown
/// exercise, or one locked to them in a curriculum with progression
/// ([`Store::exercise_access`]; [`StationError::Locked`], in the words the station shows).
/// Instructors and admins are never held back, nor is an expert's reference attempt (not a
/// trainee's progression). A new name becomes a trainee.
pub async fn admit(
    store: &Store,
    exercise: &str,
    trainee: &str,
    expert: bool,
) -> Result<Admitted, StationError> {
    let exercise = store.exercise_by_name(exercise).await?;
    let plan = store.exercise_plan(exercise.id).await?;
    let user = store.trainee_named(trainee).await?;
    if !expert && user.role == Role::Trainee {
        let access = store.exercise_access(user.id, exercise.id).await?;
        if let Some(why) = access.locked_message(&exercise.name) {
            return Err(StationError::Locked(why));
        }
    }
    Ok(Admitted {
        trainee_id: user.id,
        exercise,
        plan,
    })
}

/// What the exercise's hand follows projected onto the session's tissue (33 points evenly
/// spaced along it), at the plan's depth, with its viewpoint: what a synthetic trainee
/// follows, the station shows and a review of the recording looks from.
pub fn plan_on_tissue(session: &Session, plan: &ExercisePlan) -> Result<Plan, StationError> {
    let hand = plan.kind_plan().hand_line();
    let line: Vec<Point3> = hand.line_m.iter().map(|&c| Point3::from(c)).collect();
    laid_on_tissue(
        session,
        &line,
        &hand.normal.into(),
        hand.depth_m,
        hand.viewpoint_m,
    )
}

/// The incision a synthetic trainee choosing with `planning` places (drawn with `seed`), for
/// an exercise that leaves the choice to the trainee
/// ([`cutlab_scoring::exercise::ExerciseKind::trainee_places_incision`]), laid on the
/// session's tissue as [`plan_on_tissue`] lays the expert's; `None` for the other exercises.
pub fn chosen_plan_on_tissue(
    session: &Session,
    plan: &ExercisePlan,
    planning: &Planning,
    seed: u64,
) -> Result<Option<Plan>, StationError> {
    let kind = plan.kind_plan();
    if !kind.trainee_places_incision() {
        return Ok(None);
    }
    let hand = kind.hand_line();
    let points = |line: &[[f64; 3]]| line.iter().map(|&c| Point3::from(c)).collect::<Vec<_>>();
    let marks: Vec<Vec<Point3>> = kind.drawing().marks_m.iter().map(|m| points(m)).collect();
    let normal = Vector3::from(hand.normal);
    let chosen = planning.choose(&points(&hand.line_m), &normal, hand.depth_m, &marks, seed);
    laid_on_tissue(
        session,
        &chosen.line_m,
        &normal,
        chosen.depth_m,
        hand.viewpoint_m,
    )
    .map(Some)
}

/// `line` laid on the session's tissue facing `normal` (33 points evenly spaced), `depth_m`
/// deep, seen from `viewpoint_m`.
fn laid_on_tissue(
    session: &Session,
    line: &[Point3],
    normal: &Vector3,
    depth_m: f64,
    viewpoint_m: [f64; 3],
) -> Result<Plan, StationError> {
    let on_tissue = Plan {
        viewpoint_m: Some(Point3::from(viewpoint_m)),
        ..session.plan_along(&resample(line, 33), normal, depth_m)?
    };
    on_tissue.check()?;
    Ok(on_tissue)
}

/// The lines marked on the exercise's tissue ([`cutlab_scoring::exercise::Drawing::marks_m`])
/// laid on the session's surface, lifted 0.5 mm off it so they are drawn over it: seen in
/// every mode, guided or exam.
pub fn marks_on_tissue(
    session: &Session,
    plan: &ExercisePlan,
) -> Result<Vec<Vec<Point3>>, StationError> {
    let drawing = plan.kind_plan().drawing();
    let up = Vector3::from(drawing.normal);
    drawing
        .marks_m
        .iter()
        .map(|mark| {
            let points: Vec<Point3> = mark.iter().map(|&c| Point3::from(c)).collect();
            let on = session.plan_along(&points, &up, 0.0)?;
            Ok(on
                .line_m
                .iter()
                .zip(&on.normals)
                .map(|(p, n)| p + n * 5e-4)
                .collect())
        })
        .collect()
}

/// How a session's attempt ended.
#[derive(Debug)]
pub enum Finished {
    /// Scored from its recording (its note says so when the recording was not whole).
    Scored(Box<Outcome>, MetricSet),
    /// Not scored: the session failed or was cut off; the reason is the attempt's note.
    Incomplete(String),
}

/// Ends attempt `id`: scores it from the recording at `outcome`'s path, or marks it incomplete
/// with `outcome`'s reason (or [`cutlab_scoring::UNTOUCHED_NOTE`] when the tool never touched
/// the tissue). A recording that cannot be read marks the attempt incomplete; a
/// recording that cannot be scored marks it failed; both are errors too. Scored against
/// `plan` when the caller holds it, else the attempt's exercise's plan from the store.
pub async fn finish_attempt(
    store: &Store,
    id: i64,
    outcome: Result<&Path, String>,
    recordings: Option<&RecordingStore>,
    plan: Option<&ExercisePlan>,
) -> Result<Finished, StationError> {
    let finished = end_attempt(store, id, outcome, plan).await;
    if let Some(recordings) = recordings {
        keep(store, id, recordings).await;
    }
    finished
}

/// Puts the attempt's recordings into the recording store. A failure loses nothing (the
/// files stay on this machine's disk) and is said, not an error of the attempt.
async fn keep(store: &Store, id: i64, recordings: &RecordingStore) {
    match store.keep_recordings(id, recordings).await {
        Ok(a) => tracing::info!(
            "attempt {id}: recording {} stored in {}",
            a.recording_sha256.as_deref().unwrap_or("?"),
            recordings.location()
        ),
        // a session that failed before it recorded anything
        Err(AssessError::Io { .. }) => {}
        Err(e) => tracing::warn!(
            "attempt {id}: the recording stays on this machine only, {}: {e}",
            recordings.location()
        ),
    }
}

async fn end_attempt(
    store: &Store,
    id: i64,
    outcome: Result<&Path, String>,
    plan: Option<&ExercisePlan>,
) -> Result<Finished, StationError> {
    let path = match outcome {
        Ok(path) => path,
        Err(why) => {
            store.mark_incomplete(id, Some(&why)).await?;
            return Ok(Finished::Incomplete(why));
        }
    };
    let rec = match Recording::open(path) {
        Ok(rec) => rec,
        Err(e) => {
            store.mark_incomplete(id, Some(&e.to_string())).await?;
            return Err(e.into());
        }
    };
    // Start, then Stop, and nothing between: visible as such, never a scored fail
    if !cutlab_scoring::touched_tissue(&rec) {
        store
            .mark_incomplete(id, Some(cutlab_scoring::UNTOUCHED_NOTE))
            .await?;
        return Ok(Finished::Incomplete(cutlab_scoring::UNTOUCHED_NOTE.into()));
    }
    let scored = match plan {
        Some(plan) => store.score_recording_against(id, &rec, plan).await,
        None => store.score_recording(id, &rec).await,
    };
    match scored {
        Ok((outcome, values)) => Ok(Finished::Scored(Box::new(outcome), values)),
        Err(e) => {
            store.mark_failed(id, &e.to_string()).await?;
            Err(e.into())
        }
    }
}

/// How long after its start an attempt may be without its lock ([`AttemptLock`]) before
/// [`end_abandoned`] takes it for dead: an attempt from before the lock, or one assessed from a
/// file (`cutlab assess`), which is scored at once.
pub const STARTING_GRACE_NS: i64 = 10 * 60 * 1_000_000_000;

/// The process running an attempt: an exclusive lock on `<recording>.lock`, held from before
/// the attempt starts until it has ended (scored or marked incomplete). The operating system
/// lets go of it when the process dies, which is how [`end_abandoned`] tells a dead station's
/// attempt from a live one. The file stays (empty).
#[derive(Debug)]
pub struct AttemptLock {
    _file: std::fs::File,
}

impl AttemptLock {
    /// Takes the lock of the attempt recorded at `recording`.
    pub fn hold(recording: &Path) -> Result<Self, StationError> {
        let path = lock_path(recording);
        let io = |source| StationError::Io {
            what: format!("locking {}", path.display()),
            source,
        };
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io)?;
        file.lock().map_err(io)?;
        // stamped: a lock file older than its attempt is an earlier attempt's, at the same path
        file.set_modified(std::time::SystemTime::now())
            .map_err(io)?;
        Ok(Self { _file: file })
    }
}

fn lock_path(recording: &Path) -> std::path::PathBuf {
    let mut name = recording.as_os_str().to_owned();
    name.push(".lock");
    name.into()
}

/// Ends the attempts whose process died (a station killed, a power cut): `running` in this
/// database, but their [`AttemptLock`] is free, or was never taken [`STARTING_GRACE_NS`] after
/// their start. One whose recording is whole and says the session completed is scored (its
/// process died before it could score it); any other is marked incomplete with the reason,
/// its recording kept for review. Either way it is put into `recordings` and enters the
/// station's queue for the hub. Returns the attempts ended and how; one that cannot be ended
/// is said and left.
///
/// Only on a station's own SQLite database, whose sessions all run on this machine (on a
/// shared PostgreSQL database another machine's session may be running), and only for
/// attempts recorded at an absolute path (a relative one was the recording process's own).
pub async fn end_abandoned(
    store: &Store,
    recordings: Option<&RecordingStore>,
) -> Result<Vec<(i64, Finished)>, StationError> {
    let mut ended = Vec::new();
    if !matches!(store.db(), cutlab_assessor::store::Db::Sqlite(_)) {
        return Ok(ended);
    }
    let now_ns = cutlab_assessor::store::now_ns();
    for a in store.running_attempts().await? {
        if a.station.is_some() {
            // a hub's import, never a session of this machine's (an older hub's, left
            // between its insert and its scoring): the station's retry ends it
            continue;
        }
        let young = now_ns.saturating_sub(a.started_ns) < STARTING_GRACE_NS;
        let path = a.recording_path.as_deref().map(Path::new);
        if path.is_some_and(Path::is_relative) {
            continue;
        }
        let owner = path.map(|p| owner_of(&lock_path(p), a.started_ns));
        match owner {
            Some(Ok(Owner::Alive)) => continue,
            Some(Ok(Owner::Dead)) => {}
            Some(Err(e)) => {
                tracing::warn!("attempt {}: its lock cannot be checked: {e}", a.id);
                continue;
            }
            Some(Ok(Owner::Never)) | None if young => continue,
            Some(Ok(Owner::Never)) | None => {}
        }
        let nothing = || "the session's process stopped before it recorded anything".to_owned();
        let outcome = match path {
            // a sink of a process from before the attempt's lock
            Some(p) if cutlab_recorder::recording_in_use(p).unwrap_or(false) => continue,
            None => Err(nothing()),
            Some(p) => match Recording::open(p) {
                // an older session's file where this one was to record (`--out` used again)
                Ok(rec) if rec.meta().is_ok_and(|m| began_before(m, a.started_ns)) => {
                    Err(nothing())
                }
                Ok(rec) if rec.is_whole() && ended_complete(&rec) => Ok(p),
                Ok(_) => Err(
                    "the session's process stopped before the attempt ended; its \
                     recording is kept as far as it was written"
                        .to_owned(),
                ),
                Err(_) if !p.exists() => Err(nothing()),
                Err(e) => Err(format!(
                    "the session's process stopped before the attempt ended; its recording \
                     cannot be read: {e}"
                )),
            },
        };
        match finish_attempt(store, a.id, outcome, recordings, None).await {
            Ok(finished) => ended.push((a.id, finished)),
            Err(e) => tracing::warn!("attempt {}: abandoned, but not ended: {e}", a.id),
        }
    }
    Ok(ended)
}

/// What an attempt's lock file says of the process that runs it.
enum Owner {
    /// The lock is held.
    Alive,
    /// Taken for this attempt, and let go without the attempt ending.
    Dead,
    /// Never taken for this attempt (no file, or an earlier attempt's at the same path).
    Never,
}

fn owner_of(lock: &Path, started_ns: i64) -> std::io::Result<Owner> {
    let modified = match std::fs::metadata(lock).and_then(|m| m.modified()) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Owner::Never),
        Err(e) => return Err(e),
    };
    let modified_ns = modified
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX));
    if cutlab_recorder::recording_in_use(lock)? {
        Ok(Owner::Alive)
    } else if modified_ns < started_ns.saturating_sub(CLOCK_SLACK_NS) {
        Ok(Owner::Never)
    } else {
        Ok(Owner::Dead)
    }
}

/// Whether the recording's session-end metadata says the session completed.
fn ended_complete(rec: &Recording) -> bool {
    rec.end
        .as_ref()
        .and_then(|e| e.get("status"))
        .is_some_and(|s| s == "complete")
}

/// How much earlier than its attempt's start a lock or recording of that attempt may be
/// stamped (clocks read at different moments).
const CLOCK_SLACK_NS: i64 = 1_000_000_000;

/// Whether the recording with metadata `meta` began before an attempt that started at
/// `started_ns` (a session records after its attempt starts).
fn began_before(meta: &cutlab_recorder::channels::SessionMeta, started_ns: i64) -> bool {
    meta.started_unix_s * 1e9 < (started_ns - CLOCK_SLACK_NS) as f64
}

/// [`end_abandoned`], each attempt ended (or the failure to look) said in the log.
pub async fn end_abandoned_and_say(store: &Store, recordings: Option<&RecordingStore>) {
    match end_abandoned(store, recordings).await {
        Ok(ended) => {
            for (id, finished) in ended {
                match finished {
                    Finished::Scored(..) => tracing::info!(
                        "attempt {id}: its process stopped after the session; scored now"
                    ),
                    Finished::Incomplete(why) => {
                        tracing::warn!("attempt {id}: marked incomplete: {why}");
                    }
                }
            }
        }
        Err(e) => tracing::warn!("looking for attempts left running: {e}"),
    }
}

/// `n >= 2` points evenly spaced by arc length along the polyline `line`, its ends included.
pub fn resample(line: &[Point3], n: usize) -> Vec<Point3> {
    let lengths: Vec<f64> = line.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
    let total: f64 = lengths.iter().sum();
    let (mut seg, mut walked) = (0, 0.0);
    (0..n)
        .map(|i| {
            let s = total * i as f64 / (n - 1) as f64;
            while seg + 1 < lengths.len() && walked + lengths[seg] < s {
                walked += lengths[seg];
                seg += 1;
            }
            match lengths.get(seg) {
                Some(&l) if l > 0.0 => {
                    line[seg] + (line[seg + 1] - line[seg]) * ((s - walked) / l).clamp(0.0, 1.0)
                }
                _ => line[seg],
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resampling_keeps_the_ends_and_spaces_evenly() {
        let line = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.01, 0.0, 0.0),
            Point3::new(0.01, 0.03, 0.0),
        ];
        let r = resample(&line, 5);
        assert_eq!((r[0], r[4]), (line[0], line[2]));
        for w in r.windows(2) {
            assert!(((w[1] - w[0]).norm() - 0.01).abs() < 1e-12, "{r:?}");
        }
        assert!((r[1] - line[1]).norm() < 1e-12);
    }
}
