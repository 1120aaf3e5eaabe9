//! The server-rendered pages, one module per area; every page handler takes
//! [`CurrentUser`](crate::auth::CurrentUser) and checks what the role may see.

pub mod attempt;
pub mod cohorts;
pub mod curriculum;
pub mod evidence;
pub mod layout;
pub mod planning;
mod planning_map;
pub mod progress;
pub mod station;
pub mod supervision;

use axum::Router;
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::get;

use crate::AppState;
use crate::auth::CurrentUser;

/// Our pages load nothing from elsewhere and run only our own script files.
const CSP: &str = "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; frame-src 'self'; object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors 'self'";

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/", get(home))
        .route(
            "/static/style.css",
            get(|| async { static_file("text/css", include_str!("static/style.css")) }),
        )
        .route(
            "/static/planning.js",
            get(|| async { static_file("text/javascript", include_str!("static/planning.js")) }),
        )
        .route(
            "/static/supervision.js",
            get(|| async { static_file("text/javascript", include_str!("static/supervision.js")) }),
        )
        .merge(cohorts::router())
        .merge(progress::router())
        .merge(attempt::router())
        .merge(supervision::router())
        .merge(station::router())
        .merge(curriculum::router())
        .merge(evidence::router())
        .merge(planning::router())
        .layer(axum::middleware::map_response(
            |mut r: Response| async move {
                r.headers_mut().insert(
                    header::CONTENT_SECURITY_POLICY,
                    HeaderValue::from_static(CSP),
                );
                r
            },
        ))
}

pub(crate) fn static_file(mime: &'static str, text: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, mime),
            (header::CACHE_CONTROL, "public, max-age=3600"),
        ],
        text,
    )
        .into_response()
}

/// `/`: instructors and administrators to the cohorts, trainees to their progress.
async fn home(user: CurrentUser) -> Redirect {
    if user.is_staff() {
        Redirect::to("/cohorts")
    } else {
        Redirect::to(&format!("/trainees/{}", user.id()))
    }
}
