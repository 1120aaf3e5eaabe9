//! The JSON API: the data of the pages for other tools. Every call needs a logged-in session
//! (the `cutlab_session` cookie from `POST /login`; 401 without) and sees what the role may:
//! a trainee their own data, an instructor their cohorts' trainees, an administrator all.
//! Someone else's data is a 404. Errors are `{"error": "...", "status": N}`.
//!
//! | Call | Answer |
//! |---|---|
//! | `GET /api/me` | the logged-in user `{id, name, role, has_password, created_ns}` |
//! | `GET /api/cohorts` | instructors/admins: per cohort the trainees x exercises grid (attempts, standing, trials to proficiency, last score); trainees: 403 |
//! | `GET /api/trainees` | the trainees the caller may see |
//! | `GET /api/trainees/{id}/progress` | per exercise: attempts, proficiency, learning curves per metric with the expert band and limits, CUSUM with `h0`/`h1`; curriculum modules' state |
//! | `GET /api/attempts/{id}` | the attempt, every metric with threshold and verdict, the peak-force pass limits (`peak_force_limits_n`, drawn on the force chart) and the plan's force limit (`force_limit_n`, drawn without them), comments, sign-off, which recordings exist |
//! | `GET /api/attempts/{id}/trace` | from the recording: planned line (not to a trainee on an exam-only exercise) and cut (top view, mm), tip path, force over time; 404 without a readable recording |
//! | `GET /api/running` | attempts in progress with elapsed time and recording size |
//! | `GET /api/exercises` | exercises with their thresholds |
//! | `GET /api/exercises/{id}` | an exercise with its expert plan and thresholds (trainees: no plan for an exam-only exercise) |
//! | `GET /api/curricula` | curricula with their modules |
//! | `GET /api/exercises/{id}/evidence` | instructors/admins: the exercise's validity evidence (`?reference=exclude` leaves the reference attempts out) and its adopted pass mark; trainees: 404 |
//!
//! Times are nanoseconds since the Unix epoch (UTC); values are SI (m, s, N).

use axum::extract::State;
use axum::routing::get;
use axum::{Json, Router};
use cutlab_assessor::store::{Curriculum, Exercise, Module, User};
use cutlab_scoring::ExercisePlan;
use cutlab_scoring::proficiency::Thresholds;
use serde::Serialize;

use crate::AppState;
use crate::access::{visible_attempt, visible_trainees, visible_user};
use crate::auth::CurrentUser;
use crate::data::attempt::{AttemptDetail, detail};
use crate::data::overview::{CohortOverview, overview};
use crate::data::progress::cached_progress;
use crate::data::running::{RunningAttempt, running};
use crate::data::trace::{AttemptTrace, trace_for};
use crate::error::{ApiError, ApiResult, AppError};
use crate::extract::Id;

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/me", get(me))
        .route("/cohorts", get(cohorts))
        .route("/trainees", get(trainees))
        .route("/trainees/{id}/progress", get(trainee_progress))
        .route("/attempts/{id}", get(attempt))
        .route("/attempts/{id}/trace", get(attempt_trace))
        .route("/running", get(running_attempts))
        .route("/exercises", get(exercises))
        .route("/exercises/{id}", get(exercise))
        .route("/curricula", get(curricula))
        .route("/exercises/{id}/evidence", get(evidence))
        .fallback(|| async { ApiError(AppError::NotFound) })
}

/// An exercise's validity evidence with its adopted pass mark.
#[derive(Debug, Serialize)]
struct Evidence {
    report: cutlab_scoring::evidence::Report,
    pass_mark: Option<cutlab_assessor::store::PassMark>,
}

async fn evidence(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
    axum::extract::RawQuery(query): axum::extract::RawQuery,
) -> ApiResult<Evidence> {
    if !user.is_staff() {
        return Err(ApiError(AppError::NotFound));
    }
    let include = crate::pages::evidence::include_reference(query.as_deref());
    Ok(Json(Evidence {
        report: state.store().evidence(id, include).await?,
        pass_mark: state.store().pass_mark(id).await?,
    }))
}

async fn me(user: CurrentUser) -> Json<User> {
    Json(user.user().clone())
}

async fn cohorts(
    State(state): State<AppState>,
    user: CurrentUser,
) -> ApiResult<Vec<CohortOverview>> {
    user.require_staff()?;
    Ok(Json(overview(&state, &user).await?))
}

async fn trainees(State(state): State<AppState>, user: CurrentUser) -> ApiResult<Vec<User>> {
    Ok(Json(visible_trainees(&state, &user).await?))
}

async fn trainee_progress(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
) -> Result<axum::response::Response, ApiError> {
    use axum::response::IntoResponse;
    let t = visible_user(&state, &user, id).await?;
    let c = cached_progress(&state, &t).await?;
    let json = match c.json.get() {
        Some(j) => j.clone(),
        None => {
            let j = serde_json::to_vec(&c.data).map_err(|e| AppError::Internal(e.to_string()))?;
            c.json.get_or_init(|| j.into()).clone()
        }
    };
    Ok((
        [(axum::http::header::CONTENT_TYPE, "application/json")],
        json,
    )
        .into_response())
}

async fn attempt(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
) -> ApiResult<AttemptDetail> {
    let a = visible_attempt(&state, &user, id).await?;
    Ok(Json(detail(&state, a).await?))
}

async fn attempt_trace(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
) -> Result<Json<std::sync::Arc<AttemptTrace>>, ApiError> {
    let a = visible_attempt(&state, &user, id).await?;
    Ok(Json(
        trace_for(&state, &user, &a)
            .await?
            .ok_or(AppError::NotFound)?,
    ))
}

async fn running_attempts(
    State(state): State<AppState>,
    user: CurrentUser,
) -> ApiResult<Vec<RunningAttempt>> {
    Ok(Json(running(&state, &user).await?))
}

#[derive(Debug, Serialize)]
struct ExerciseView {
    #[serde(flatten)]
    exercise: Exercise,
    thresholds: Thresholds,
    #[serde(skip_serializing_if = "Option::is_none")]
    plan: Option<ExercisePlan>,
}

async fn exercises(
    State(state): State<AppState>,
    _user: CurrentUser,
) -> ApiResult<Vec<ExerciseView>> {
    let mut out = Vec::new();
    for e in state.store().list_exercises().await? {
        let thresholds = state.store().thresholds(e.id).await?;
        out.push(ExerciseView {
            exercise: e,
            thresholds,
            plan: None,
        });
    }
    Ok(Json(out))
}

async fn exercise(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
) -> ApiResult<ExerciseView> {
    let e = state.store().get_exercise(id).await?;
    // the station never shows a trainee an exam-only exercise's plan: nor does the API
    let plan = if e.exam_only && !user.is_staff() {
        None
    } else {
        Some(state.store().get_plan(e.plan_id).await?)
    };
    let thresholds = state.store().thresholds(id).await?;
    Ok(Json(ExerciseView {
        exercise: e,
        thresholds,
        plan,
    }))
}

#[derive(Debug, Serialize)]
struct CurriculumView {
    #[serde(flatten)]
    curriculum: Curriculum,
    modules: Vec<Module>,
}

async fn curricula(
    State(state): State<AppState>,
    _user: CurrentUser,
) -> ApiResult<Vec<CurriculumView>> {
    let mut out = Vec::new();
    for c in state.store().list_curricula().await? {
        let modules = state.store().curriculum_modules(c.id).await?;
        out.push(CurriculumView {
            curriculum: c,
            modules,
        });
    }
    Ok(Json(out))
}
