//! The hub's side of stations and hub: stations upload their attempts here, each with its
//! own token (`Authorization: Bearer ...`, made by `cutlab hub token create`), which may
//! create attempts and nothing else (no page or API call takes it, and these calls take no
//! login). The token is checked before a byte of the body is read, and a few uploads are
//! read at a time. Errors are JSON like the API's; a missing, wrong or revoked token is a
//! 401.
//!
//! | Call | Answer |
//! |---|---|
//! | `PUT /api/hub/recordings/{sha256}` | the body (up to [`MAX_UPLOAD_BYTES`]; a larger `Content-Length` is refused before a byte is read) is stored in the hub's recording store under its SHA-256, which must be the key in the path (else 422, nothing stored); 201 (200 if this station had sent it before). A body that stalls or comes too slowly (the pace every body is held to, [`crate::pace`]) is cut off (408), as is one whose token is revoked meanwhile (401) |
//! | `PUT /api/hub/attempts/{uuid}` | an [`AttemptUpload`] whose `uuid` is the path's: the attempt taken once (201; 200 with the attempt as the hub holds it for a retry; 409 if another station sent that id); its recordings must be ones this station uploaded (else 422, the same answer whether another station's exists or not); a complete attempt is scored by the hub from its recording |
//!
//! What a hostile station cannot do, and why: docs/decisions.md ("The hub and a hostile
//! station").

use std::collections::HashSet;
use std::time::{Duration, Instant};

use axum::Json;
use axum::Router;
use axum::body::{Body, Bytes};
use axum::extract::{DefaultBodyLimit, FromRequestParts, Path, State};
use axum::http::request::Parts;
use axum::http::{HeaderMap, StatusCode, header};
use axum::routing::put;
use cutlab_assessor::AssessError;
use cutlab_assessor::recordings::{RecordingStore, is_sha256_hex};
use cutlab_assessor::store::{Attempt, AttemptStatus, AttemptUpload, StationToken, is_uuid};
use cutlab_scoring::MetricValue;
use futures_util::StreamExt;
use serde::Serialize;
use sha2::{Digest, Sha256};

use crate::AppState;
use crate::error::{ApiError, AppError};

/// The largest recording a station may upload in one request (a 60 s attempt records about
/// 11 MB).
pub const MAX_UPLOAD_BYTES: usize = 512 << 20;

/// The largest attempt upload (its metrics and note; a few kB in practice).
pub const MAX_ATTEMPT_BYTES: usize = 256 << 10;

/// The memory the recordings being read may take at once, MiB (a recording is held in
/// memory while it is hashed and stored, or scored): four of the largest. An upload takes its
/// share as its bytes come, a MiB at a time, so a body that crawls holds one MiB, not a
/// turn that others wait for; when the budget is spent an upload waits, at most
/// [`TURN_WAIT`]. A station has one upload at a time ([`StationUpload`]).
const BUDGET_MIB: usize = 4 * (MAX_UPLOAD_BYTES >> 20);
const MIB: usize = 1 << 20;

/// The hub's uploads under way: the memory budget of the bodies being read, and the
/// stations uploading.
#[derive(Debug)]
pub(crate) struct Uploads {
    budget: tokio::sync::Semaphore,
    stations: std::sync::Mutex<HashSet<i64>>,
}

impl Default for Uploads {
    fn default() -> Self {
        Self {
            budget: tokio::sync::Semaphore::new(BUDGET_MIB),
            stations: Default::default(),
        }
    }
}

/// How long an upload waits for its turn before it is told to try later (503).
const TURN_WAIT: Duration = Duration::from_secs(60);

/// How often a long upload checks that its station's token was not revoked meanwhile.
const TOKEN_RECHECK: Duration = Duration::from_secs(2);

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/recordings/{sha256}", put(put_recording))
        .route(
            "/attempts/{uuid}",
            put(put_attempt).layer(DefaultBodyLimit::max(MAX_ATTEMPT_BYTES)),
        )
        .fallback(|| async { ApiError(AppError::NotFound) })
}

/// The station whose token the request carries: an extractor, so that it runs before the
/// body is read (a caller without a valid token never gets to send one).
struct Station(StationToken);

impl FromRequestParts<AppState> for Station {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        let token = parts
            .headers
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.strip_prefix("Bearer "))
            .map(str::trim)
            .filter(|t| !t.is_empty() && t.len() <= 200)
            .ok_or(AppError::StationToken)?;
        match state.store().station_by_token(token).await? {
            Some(s) => Ok(Station(s)),
            None => Err(ApiError(AppError::StationToken)),
        }
    }
}

/// A station's one running upload (a station's sync sends one after the other); ended when
/// dropped.
struct StationUpload<'a>(&'a Uploads, i64);

impl<'a> StationUpload<'a> {
    /// Station `id`'s upload, unless one is running: 429, the station tries later.
    fn begin(uploads: &'a Uploads, id: i64) -> Result<Self, ApiError> {
        let mut running = uploads
            .stations
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if !running.insert(id) {
            return Err(with_status(
                StatusCode::TOO_MANY_REQUESTS,
                "this station's previous upload is still running".into(),
            ));
        }
        Ok(Self(uploads, id))
    }
}

impl Drop for StationUpload<'_> {
    fn drop(&mut self) {
        self.0
            .stations
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .remove(&self.1);
    }
}

/// `mib` more MiB of the upload budget, merged into `held`.
async fn take_budget<'a>(
    uploads: &'a Uploads,
    held: &mut Option<tokio::sync::SemaphorePermit<'a>>,
    mib: usize,
) -> Result<(), ApiError> {
    let mib = u32::try_from(mib).unwrap_or(u32::MAX);
    match tokio::time::timeout(TURN_WAIT, uploads.budget.acquire_many(mib)).await {
        Ok(Ok(permit)) => {
            match held {
                Some(h) => h.merge(permit),
                None => *held = Some(permit),
            }
            Ok(())
        }
        Ok(Err(_)) => Err(ApiError(AppError::Unavailable(
            "the hub is stopping".into(),
        ))),
        Err(_) => Err(ApiError(AppError::Unavailable(
            "the hub is busy with other uploads; try later".into(),
        ))),
    }
}

fn recording_store(state: &AppState) -> Result<&RecordingStore, ApiError> {
    state.config().recordings.as_ref().ok_or_else(|| {
        ApiError(AppError::Unavailable(
            "this hub keeps no recordings: start it with --recordings".into(),
        ))
    })
}

/// A recording store that failed (not the request's fault): 503, the station tries later.
fn unavailable(e: AssessError) -> ApiError {
    tracing::error!("the hub's recording store: {e}");
    ApiError(AppError::Unavailable(
        "the hub's recording store failed; try later".into(),
    ))
}

/// A refusal with its own status (the request's fault, not the hub's).
fn with_status(status: StatusCode, message: String) -> ApiError {
    ApiError(AppError::Malformed { status, message })
}

fn unprocessable(message: String) -> ApiError {
    with_status(StatusCode::UNPROCESSABLE_ENTITY, message)
}

#[derive(Debug, Serialize)]
struct RecordingTaken {
    sha256: String,
    bytes: usize,
}

async fn put_recording(
    State(state): State<AppState>,
    Station(station): Station,
    Path(key): Path<String>,
    headers: HeaderMap,
    body: Body,
) -> Result<(StatusCode, Json<RecordingTaken>), ApiError> {
    if !is_sha256_hex(&key) {
        let shown: String = key.chars().take(80).collect();
        return Err(ApiError(AppError::BadRequest(format!(
            "{shown:?} is not a SHA-256 key"
        ))));
    }
    let declared = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > MAX_UPLOAD_BYTES as u64) {
        return Err(with_status(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!("a recording over {MAX_UPLOAD_BYTES} bytes"),
        ));
    }
    let store = recording_store(&state)?;
    let _one = StationUpload::begin(state.uploads(), station.id)?;
    let mut budget = None;
    let (bytes, actual) = read_upload(&state, &station, body, declared, &mut budget).await?;
    if actual != key {
        tracing::warn!(
            "station {}: a recording sent as {key} hashes to {actual}; refused",
            station.name
        );
        return Err(unprocessable(format!(
            "the recording's content hashes to {actual}, not {key}: refused"
        )));
    }
    let len = bytes.len();
    // written even when an object of that size is there: it may be a damaged one
    store.put(bytes).await.map_err(unavailable)?;
    // 200 or 201 by this station's own uploads: whether another station sent the same bytes
    // is not told
    let status = if state.store().own_recording(&key, &station.name).await? {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    Ok((
        status,
        Json(RecordingTaken {
            sha256: key,
            bytes: len,
        }),
    ))
}

/// Reads a recording's body, hashing it as it comes (SHA-256, hex): cut off past
/// [`MAX_UPLOAD_BYTES`] (413), when the station's token is revoked meanwhile (401), or when it
/// stalls or comes too slowly (the server's pace on every body, [`crate::pace`]: 408).
async fn read_upload<'a>(
    state: &'a AppState,
    station: &StationToken,
    body: Body,
    declared: Option<u64>,
    budget: &mut Option<tokio::sync::SemaphorePermit<'a>>,
) -> Result<(Bytes, String), ApiError> {
    let mut checked = Instant::now();
    let capacity = declared.map_or(0, |n| usize::try_from(n).unwrap_or(0).min(MIB));
    let mut bytes = bytes::BytesMut::with_capacity(capacity);
    let mut hash = Sha256::new();
    let mut stream = body.into_data_stream();
    while let Some(chunk) = stream.next().await {
        let chunk =
            chunk.map_err(|e| AppError::BadRequest(format!("the recording's body: {e}")))?;
        if bytes.len() + chunk.len() > MAX_UPLOAD_BYTES {
            return Err(with_status(
                StatusCode::PAYLOAD_TOO_LARGE,
                format!("a recording over {MAX_UPLOAD_BYTES} bytes"),
            ));
        }
        let held_mib = budget.as_ref().map_or(0, |p| p.num_permits());
        let need_mib = (bytes.len() + chunk.len()).div_ceil(MIB);
        if need_mib > held_mib {
            take_budget(state.uploads(), budget, need_mib - held_mib).await?;
        }
        hash.update(&chunk);
        bytes.extend_from_slice(&chunk);
        if checked.elapsed() > TOKEN_RECHECK {
            checked = Instant::now();
            if !state.store().station_token_valid(station.id).await? {
                return Err(ApiError(AppError::StationToken));
            }
        }
    }
    Ok((
        bytes.freeze(),
        cutlab_assessor::recordings::hex(&hash.finalize()),
    ))
}

#[derive(Debug, Serialize)]
struct AttemptTaken {
    id: i64,
    uuid: String,
    created: bool,
    /// How the attempt stands on the hub: what a retry is answered with.
    status: AttemptStatus,
    score: Option<f64>,
    passed: Option<bool>,
}

impl AttemptTaken {
    fn of(a: &Attempt, created: bool) -> Self {
        Self {
            id: a.id,
            uuid: a.uuid.clone().unwrap_or_default(),
            created,
            status: a.status,
            score: a.score,
            passed: a.passed,
        }
    }
}

/// An import's error: the attempt's own problem (it stays queued on its station, the rest
/// go on) is a 4xx; the store's, a 5xx.
fn import_error(e: AssessError) -> ApiError {
    match e {
        AssessError::Conflict(m) => ApiError(AppError::Conflict(m)),
        AssessError::InvalidInput(m) | AssessError::InvalidPlan(m) => unprocessable(m),
        AssessError::NotFound(m) => unprocessable(format!("not on this hub: {m}")),
        e => ApiError::from(e),
    }
}

async fn put_attempt(
    State(state): State<AppState>,
    Station(station): Station,
    Path(uuid): Path<String>,
    body: Bytes,
) -> Result<(StatusCode, Json<AttemptTaken>), ApiError> {
    if !is_uuid(&uuid) {
        return Err(ApiError(AppError::BadRequest(
            "the attempt's id must be a UUID".into(),
        )));
    }
    if let Some(a) = state
        .store()
        .imported_by(&uuid, &station.name)
        .await
        .map_err(import_error)?
        && a.status != AttemptStatus::Running
    {
        return Ok((StatusCode::OK, Json(AttemptTaken::of(&a, false))));
    }
    let mut up: AttemptUpload = serde_json::from_slice(&body)
        .map_err(|e| unprocessable(format!("not an attempt upload: {e}")))?;
    if up.uuid != uuid {
        return Err(ApiError(AppError::BadRequest(
            "the attempt's id must be the path's".into(),
        )));
    }
    up.validate(cutlab_assessor::store::now_ns())
        .map_err(import_error)?;
    check_recordings(&state, &station, &up).await?;
    let metrics = if up.status == AttemptStatus::Complete {
        let (metrics, damaged) = rescore(&state, &up).await?;
        if damaged.is_some() {
            up.note = damaged;
        }
        metrics
    } else {
        Vec::new()
    };
    let taken = state
        .store()
        .import_attempt(&up, &station.name, &metrics)
        .await
        .map_err(import_error)?;
    if taken.created {
        tracing::info!(
            "station {}: attempt {} of {} taken as {}",
            station.name,
            up.uuid,
            up.trainee,
            taken.attempt.id
        );
    }
    let status = if taken.created {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    Ok((
        status,
        Json(AttemptTaken::of(&taken.attempt, taken.created)),
    ))
}

/// The attempt's recordings must be ones `station` uploaded and the store has: one answer
/// for "not there" and "another station's", so that no station learns what others sent.
async fn check_recordings(
    state: &AppState,
    station: &StationToken,
    up: &AttemptUpload,
) -> Result<(), ApiError> {
    if up.recording_sha256.is_none() && up.rrd_sha256.is_none() {
        return Ok(());
    }
    let store = recording_store(state)?;
    for key in [&up.recording_sha256, &up.rrd_sha256].into_iter().flatten() {
        let not_here = || {
            unprocessable(format!(
                "recording {key} is not on this hub: upload it first"
            ))
        };
        if !state.store().owns_recording(key, &station.name).await? {
            return Err(not_here());
        }
        match store.size(key).await {
            Ok(_) => {}
            Err(AssessError::NotFound(_)) => return Err(not_here()),
            // the store, not the attempt: the station stops and tries later
            Err(e) => return Err(unavailable(e)),
        }
    }
    Ok(())
}

/// A complete attempt's metrics as the hub measures them from its recording, against the
/// hub's plan of the exercise (the station's own are not used), and the note a damaged
/// recording calls for. Read and assessed on a blocking thread, one upload turn at a time.
async fn rescore(
    state: &AppState,
    up: &AttemptUpload,
) -> Result<(Vec<MetricValue>, Option<String>), ApiError> {
    let store = recording_store(state)?;
    let key = up.recording_sha256.as_deref().unwrap_or_default();
    let exercise = state
        .store()
        .exercise_by_name(&up.exercise)
        .await
        .map_err(|_| unprocessable(format!("this hub has no exercise {:?}", up.exercise)))?;
    let plan = state.store().exercise_plan(exercise.id).await?;
    let size = store.size(key).await.map_err(unavailable)?;
    let mut held = None;
    let mib = usize::try_from(size)
        .unwrap_or(usize::MAX)
        .div_ceil(MIB)
        .max(1);
    take_budget(state.uploads(), &mut held, mib).await?;
    let bytes = store.get(key).await.map_err(unavailable)?;
    let span_ns = up.ended_ns.unwrap_or(up.started_ns) - up.started_ns;
    tokio::task::spawn_blocking(move || {
        let rec = cutlab_recorder::Recording::from_bytes(&bytes)
            .map_err(|e| format!("its recording is not a readable recording: {e}"))?;
        let (read_s, _) = rec.readable_s();
        // the recording fits in the attempt's time (a second's slack for the clocks)
        if read_s > span_ns as f64 * 1e-9 + 1.0 {
            return Err(format!(
                "its recording lasts {read_s:.1} s, longer than the attempt's {:.1} s",
                span_ns as f64 * 1e-9
            ));
        }
        cutlab_scoring::from_recording::assess_recording(&rec, &plan)
            .map_err(|e| format!("its recording cannot be scored: {e}"))
    })
    .await
    .map_err(|e| ApiError(AppError::Internal(format!("scoring a recording: {e}"))))?
    .map_err(|why| unprocessable(format!("attempt {}: {why}", up.uuid)))
}
