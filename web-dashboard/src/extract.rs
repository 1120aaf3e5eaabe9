//! Extractors whose refusals are answered like every other error ([`AppError`]): a numeric
//! id from the path.

use axum::extract::{FromRequestParts, Path};
use axum::http::request::Parts;
use axum::response::{IntoResponse, Response};

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
        match Path::<i64>::from_request_parts(parts, state).await {
            Ok(Path(id)) => Ok(Id(id)),
            Err(_) => Err(IdRejection {
                api: crate::auth::original_path(parts).starts_with("/api/"),
            }),
        }
    }
}
