//! The dashboard's one error type: every handler returns it, and it becomes a response in one
//! place ([`AppError::status`]): an HTML page for the pages, JSON (`{"error": ...}`) for the
//! API ([`ApiError`]). Internal details (database errors) are logged, never shown.

use axum::Json;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use cutlab_assessor::AssessError;
use cutlab_scoring::ScoreError;

/// What can go wrong handling a request.
#[derive(Debug, thiserror::Error)]
pub enum AppError {
    /// Not there, or not the caller's to see (the same answer, so nothing leaks).
    #[error("not found")]
    NotFound,
    /// Logged in, but the role does not allow it.
    #[error("forbidden: {0}")]
    Forbidden(&'static str),
    /// An exercise the trainee has not reached in a curriculum with progression, with why.
    #[error("{0}")]
    Locked(String),
    /// A form without the session's CSRF token.
    #[error("missing or wrong CSRF token")]
    Csrf,
    /// Not logged in (API calls; pages redirect to the login form instead).
    #[error("not logged in")]
    Unauthorized,
    /// A hub upload without a valid station token (missing, wrong or revoked).
    #[error("the station token is missing, wrong or revoked")]
    StationToken,
    /// A service this server is not set up for, with what it lacks.
    #[error("{0}")]
    Unavailable(String),
    /// Too many failed logins.
    #[error("too many failed logins; try again in a minute")]
    TooManyRequests,
    /// A request whose body stalled or came too slowly, with which ([`crate::pace`]).
    #[error("{0}")]
    TimedOut(String),
    /// Input that cannot be used, with a message for the user.
    #[error("{0}")]
    BadRequest(String),
    /// A request an extractor could not read (a form missing a field, a malformed path),
    /// with the status the extractor chose (400, 413, 415, 422).
    #[error("{message}")]
    Malformed { status: StatusCode, message: String },
    /// A name already taken, an attempt already signed off...
    #[error("{0}")]
    Conflict(String),
    /// Anything else (logged; the user sees a generic message).
    #[error("internal error")]
    Internal(String),
}

impl AppError {
    pub fn status(&self) -> StatusCode {
        match self {
            AppError::NotFound => StatusCode::NOT_FOUND,
            AppError::Forbidden(_) | AppError::Locked(_) | AppError::Csrf => StatusCode::FORBIDDEN,
            AppError::Unauthorized | AppError::StationToken => StatusCode::UNAUTHORIZED,
            AppError::Unavailable(_) => StatusCode::SERVICE_UNAVAILABLE,
            AppError::TooManyRequests => StatusCode::TOO_MANY_REQUESTS,
            AppError::TimedOut(_) => StatusCode::REQUEST_TIMEOUT,
            AppError::BadRequest(_) => StatusCode::BAD_REQUEST,
            AppError::Malformed { status, .. } => *status,
            AppError::Conflict(_) => StatusCode::CONFLICT,
            AppError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    /// The message shown to the user (internal details stay in the log).
    pub fn public_message(&self) -> String {
        if let AppError::Internal(detail) = self {
            tracing::error!("request failed: {detail}");
        }
        self.to_string()
    }
}

impl From<AssessError> for AppError {
    fn from(e: AssessError) -> Self {
        match e {
            AssessError::NotFound(_) => AppError::NotFound,
            AssessError::Conflict(m) => AppError::Conflict(m),
            AssessError::InvalidPlan(_)
            | AssessError::Parse { .. }
            | AssessError::InvalidInput(_) => AppError::BadRequest(e.to_string()),
            other => AppError::Internal(other.to_string()),
        }
    }
}

/// A plan, a form or an input that scoring refuses is the request's fault; a file it cannot
/// read is the server's.
impl From<ScoreError> for AppError {
    fn from(e: ScoreError) -> Self {
        AssessError::from(e).into()
    }
}

impl From<sqlx::Error> for AppError {
    fn from(e: sqlx::Error) -> Self {
        AppError::Internal(format!("database: {e}"))
    }
}

impl IntoResponse for AppError {
    fn into_response(self) -> Response {
        let status = self.status();
        let message = self.public_message();
        (status, crate::pages::layout::error_page(status, &message)).into_response()
    }
}

/// An [`AppError`] answered as JSON, for `/api/...`.
#[derive(Debug)]
pub struct ApiError(pub AppError);

impl<E: Into<AppError>> From<E> for ApiError {
    fn from(e: E) -> Self {
        ApiError(e.into())
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = self.0.status();
        let mut response = (
            status,
            Json(
                serde_json::json!({ "error": self.0.public_message(), "status": status.as_u16() }),
            ),
        )
            .into_response();
        if matches!(self.0, AppError::StationToken) {
            response.headers_mut().insert(
                axum::http::header::WWW_AUTHENTICATE,
                axum::http::HeaderValue::from_static("Bearer"),
            );
        }
        response
    }
}

/// Results of page handlers.
pub type PageResult<T> = Result<T, AppError>;
/// Results of API handlers.
pub type ApiResult<T> = Result<Json<T>, ApiError>;
