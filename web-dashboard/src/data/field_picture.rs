//! `/attempts/{id}/field.png`: the field a field exercise's attempt scored on, as the scene's
//! viewpoint sees it: the wound the trainee left, resumed from the recording's last keyframe
//! and spread by the plan's retractor as scoring spreads it
//! ([`cutlab_scoring::from_recording::field_picture`]). Rendered off the async threads, one
//! at a time with the planning page's comparisons ([`crate::pages::planning::Planner`]), and
//! kept in a small cache by attempt.

use std::sync::Arc;

use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use bytes::Bytes;
use cutlab_recorder::Recording;
use cutlab_scoring::ExercisePlan;

use crate::AppState;
use crate::access::visible_attempt;
use crate::auth::CurrentUser;
use crate::error::AppError;
use crate::extract::Id;

/// The picture's pixels across and down.
pub const PICTURE_PX: u32 = 360;

pub async fn field_png(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
) -> Result<Response, AppError> {
    let a = visible_attempt(&state, &user, id).await?;
    let ExercisePlan::Field(plan) = state.store().exercise_plan(a.exercise_id).await? else {
        return Err(AppError::NotFound);
    };
    let Some((mcap, _)) = a.recording_files() else {
        return Err(AppError::NotFound);
    };
    let len = tokio::fs::metadata(&mcap)
        .await
        .map_err(|_| AppError::NotFound)?
        .len();
    let png = match state.field_pictures().get(id, len) {
        Some(png) => png,
        None => {
            let _permit = state.planner().wait().await?;
            // another request may have drawn it while this one waited for its turn
            if let Some(png) = state.field_pictures().get(id, len) {
                return Ok(png_response(&png));
            }
            let png = tokio::task::spawn_blocking(move || {
                let rec = Recording::open(&mcap).map_err(|e| e.to_string())?;
                cutlab_scoring::from_recording::field_picture(&rec, &plan, PICTURE_PX)
                    .and_then(|p| p.png())
                    .map_err(|e| e.to_string())
            })
            .await
            .map_err(|e| AppError::Internal(format!("the field's picture: {e}")))?
            .map_err(|e| {
                tracing::warn!("attempt {id}: no picture of its field: {e}");
                AppError::NotFound
            })?;
            let png = Arc::new(Bytes::from(png));
            state.field_pictures().put(id, len, png.clone());
            png
        }
    };
    Ok(png_response(&png))
}

/// A PNG's bytes as the answer (shared with the cache, not copied).
fn png_response(png: &Bytes) -> Response {
    (
        [
            (header::CONTENT_TYPE, "image/png"),
            (header::CACHE_CONTROL, "private, max-age=300"),
        ],
        png.clone(),
    )
        .into_response()
}
