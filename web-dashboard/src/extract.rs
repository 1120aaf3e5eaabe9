//! Extractors whose refusals are answered like every other error ([`AppError`]): a numeric
//! id from the path ([`Id`]), a form ([`Form`]), other path parameters ([`Path`]). Handlers
//! take these, never axum's own, whose refusals are plain text.

use axum::extract::rejection::{FormRejection, PathRejection};
use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::request::Parts;
use axum::response::{IntoResponse, Response};
use serde::de::DeserializeOwned;

use crate::error::{ApiError, AppError};

/// The `{id}` of the route: a 64-bit integer, else 400 (without echoing the input).
#[derive(Debug, Clone, Copy)]
pub struct Id(pub i64);

/// A refused id, answered as JSON under `/api/`, as a page elsewhere.
#[derive(Debug)]
pub struct IdRejection {
    api: bool,
}

impl IntoResponse for IdRejection {
    fn into_response(self) -> Response {
        let e = AppError::BadRequest("the id in the address is not a number".into());
        if self.api {
            ApiError(e).into_response()
        } else {
            e.into_response()
        }
    }
}

impl<S: Send + Sync> FromRequestParts<S> for Id {
    type Rejection = IdRejection;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        match axum::extract::Path::<i64>::from_request_parts(parts, state).await {
            Ok(axum::extract::Path(id)) => Ok(Id(id)),
            Err(_) => Err(IdRejection {
                api: crate::auth::original_path(parts).starts_with("/api/"),
            }),
        }
    }
}

/// The longest part of an extractor's message shown (the rest is cut).
const MAX_MESSAGE: usize = 300;

fn short(text: &str) -> String {
    match text.char_indices().nth(MAX_MESSAGE) {
        Some((at, _)) => format!("{}…", &text[..at]),
        None => text.to_owned(),
    }
}

impl From<FormRejection> for AppError {
    /// The status axum chose (422 for a missing or unreadable field, 415 for another content
    /// type, 413 for too large), answered as our error page.
    fn from(r: FormRejection) -> Self {
        AppError::Malformed {
            status: r.status(),
            message: format!("The form could not be read: {}.", short(&r.body_text())),
        }
    }
}

impl From<PathRejection> for AppError {
    /// Without echoing the path (as [`Id`]).
    fn from(r: PathRejection) -> Self {
        AppError::Malformed {
            status: r.status(),
            message: "The address could not be read: a part of it is malformed.".into(),
        }
    }
}

/// axum's `Form` (an `application/x-www-form-urlencoded` body, or the query of a GET) whose
/// refusal is an [`AppError`]: the styled error page, not axum's plain text.
#[derive(Debug, Clone, Copy, Default)]
pub struct Form<T>(pub T);

impl<T, S> FromRequest<S> for Form<T>
where
    T: DeserializeOwned,
    S: Send + Sync,
{
    type Rejection = AppError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        let axum::Form(value) = axum::Form::<T>::from_request(req, state).await?;
        Ok(Form(value))
    }
}

/// axum's `Path` whose refusal is an [`AppError`] (for path parameters other than an [`Id`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct Path<T>(pub T);

impl<T, S> FromRequestParts<S> for Path<T>
where
    T: DeserializeOwned + Send,
    S: Send + Sync,
{
    type Rejection = AppError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        let axum::extract::Path(value) =
            axum::extract::Path::<T>::from_request_parts(parts, state).await?;
        Ok(Path(value))
    }
}
