//! The hub's side of stations and hub: stations upload their attempts here, each with its
//! own token (`Authorization: Bearer ...`, made by `cutlab hub token create`), which may
//! create attempts and nothing else (no page or API call takes it, and these calls take no
//! login). The token is checked before a byte of the body is read, and a few uploads are
//! read at a time. Errors are JSON like the API's; a missing, wrong or revoked token is a
//! 401.
//!
//! | Call | Answer |
//! |---|---|
//! | `PUT /api/hub/recordings/{sha256}` | the body (up to [`MAX_UPLOAD_BYTES`]) is stored in the hub's recording store under its SHA-256, which must be the key in the path (else 422, nothing stored); 201 (200 if it was there) |
//! | `PUT /api/hub/attempts/{uuid}` | an [`AttemptUpload`] whose `uuid` is the path's: the attempt taken once (201; 200 with the same attempt for a retry); its recordings must be in the store already (else 422) |

use axum::Json;
use axum::Router;
use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, FromRequestParts, Path, State};
use axum::http::request::Parts;
use axum::http::{StatusCode, header};
use axum::routing::put;
use cutlab_assessor::AssessError;
use cutlab_assessor::recordings::{RecordingStore, is_sha256_hex, sha256_hex};
use cutlab_assessor::store::{AttemptUpload, StationToken, is_uuid};
use serde::Serialize;

use crate::AppState;
use crate::error::{ApiError, AppError};

/// The largest recording a station may upload in one request (a 60 s attempt records about
/// 11 MB).
pub const MAX_UPLOAD_BYTES: usize = 512 << 20;

/// Recording uploads read at once (each is held in memory while it is hashed and stored);
/// more wait their turn.
const UPLOADS_AT_ONCE: usize = 4;
static UPLOADS: tokio::sync::Semaphore = tokio::sync::Semaphore::const_new(UPLOADS_AT_ONCE);

pub fn router() -> Router<AppState> {
    Router::new()
        .route(
            "/recordings/{sha256}",
            put(put_recording).layer(DefaultBodyLimit::max(MAX_UPLOAD_BYTES)),
        )
        .route("/attempts/{uuid}", put(put_attempt))
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

/// A turn to upload a recording (after the token, before the body).
struct UploadTurn(#[allow(dead_code)] tokio::sync::SemaphorePermit<'static>);

impl FromRequestParts<AppState> for UploadTurn {
    type Rejection = ApiError;

    async fn from_request_parts(_: &mut Parts, _: &AppState) -> Result<Self, ApiError> {
        UPLOADS
            .acquire()
            .await
            .map(UploadTurn)
            .map_err(|_| ApiError(AppError::Unavailable("the hub is stopping".into())))
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

fn unprocessable(message: String) -> ApiError {
    ApiError(AppError::Malformed {
        status: StatusCode::UNPROCESSABLE_ENTITY,
        message,
    })
}

#[derive(Debug, Serialize)]
struct RecordingTaken {
    sha256: String,
    bytes: usize,
}

async fn put_recording(
    State(state): State<AppState>,
    Station(station): Station,
    _turn: UploadTurn,
    Path(key): Path<String>,
    body: Bytes,
) -> Result<(StatusCode, Json<RecordingTaken>), ApiError> {
    if !is_sha256_hex(&key) {
        return Err(ApiError(AppError::BadRequest(format!(
            "{key:?} is not a SHA-256 key"
        ))));
    }
    let store = recording_store(&state)?;
    let actual = sha256_hex(&body);
    if actual != key {
        tracing::warn!(
            "station {}: a recording sent as {key} hashes to {actual}; refused",
            station.name
        );
        return Err(unprocessable(format!(
            "the recording's content hashes to {actual}, not {key}: refused"
        )));
    }
    let existed = store.size(&key).await.is_ok_and(|n| n == body.len() as u64);
    let bytes = body.len();
    // written even when an object of that size is there: it may be a damaged one
    store.put(body).await.map_err(unavailable)?;
    let status = if existed {
        StatusCode::OK
    } else {
        StatusCode::CREATED
    };
    Ok((status, Json(RecordingTaken { sha256: key, bytes })))
}

#[derive(Debug, Serialize)]
struct AttemptTaken {
    id: i64,
    uuid: String,
    created: bool,
}

async fn put_attempt(
    State(state): State<AppState>,
    Station(station): Station,
    Path(uuid): Path<String>,
    body: Bytes,
) -> Result<(StatusCode, Json<AttemptTaken>), ApiError> {
    let up: AttemptUpload = serde_json::from_slice(&body)
        .map_err(|e| unprocessable(format!("not an attempt upload: {e}")))?;
    if !is_uuid(&uuid) || up.uuid != uuid {
        return Err(ApiError(AppError::BadRequest(
            "the attempt's id must be the path's (a UUID)".into(),
        )));
    }
    if up.recording_sha256.is_some() || up.rrd_sha256.is_some() {
        let store = recording_store(&state)?;
        for key in [&up.recording_sha256, &up.rrd_sha256].into_iter().flatten() {
            match store.size(key).await {
                Ok(_) => {}
                Err(AssessError::NotFound(_)) => {
                    return Err(unprocessable(format!(
                        "recording {key} is not on this hub: upload it first"
                    )));
                }
                // the store, not the attempt: the station stops and tries later
                Err(e) => return Err(unavailable(e)),
            }
        }
    }
    let taken = state
        .store()
        .import_attempt(&up, &station.name)
        .await
        .map_err(|e| match e {
            // this attempt's own problem: it stays queued on its station, the rest go on
            AssessError::InvalidInput(m) | AssessError::Conflict(m) => unprocessable(m),
            AssessError::NotFound(m) => unprocessable(format!("not on this hub: {m}")),
            e => ApiError::from(e),
        })?;
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
        Json(AttemptTaken {
            id: taken.attempt.id,
            uuid,
            created: taken.created,
        }),
    ))
}
