//! Authentication: login sessions (cookie `cutlab_session`: HttpOnly, SameSite=Strict, a
//! random token whose SHA-256 the database keeps), CSRF tokens on every form, failed-login
//! rate limiting, and the [`CurrentUser`] extractor every protected handler takes.
//!
//! [`session_layer`] runs before every handler: it resolves the cookie to an
//! [`AuthSession`] and, for every state-changing request (POST, PUT, PATCH, DELETE) of a
//! logged-in browser, checks the session's CSRF token (form field `csrf`, or header
//! `X-CSRF-Token`) before the handler sees the request: 403 when missing or wrong.

pub mod grants;
pub mod kiosk;
pub mod rate_limit;
pub mod routes;
pub mod sessions;
pub mod tokens;

use axum::body::Body;
use axum::extract::{FromRequestParts, Request, State};
use axum::http::Method;
use axum::http::request::Parts;
use axum::middleware::Next;
use axum::response::{IntoResponse, Redirect, Response};
use cutlab_assessor::store::{Role, User};

use crate::AppState;
use crate::error::{ApiError, AppError};

/// The session cookie.
pub const SESSION_COOKIE: &str = "cutlab_session";
/// The login form's double-submit CSRF cookie (before there is a session).
pub const LOGIN_CSRF_COOKIE: &str = "cutlab_login_csrf";
/// The largest form body the CSRF check reads.
const MAX_FORM_BYTES: usize = 1 << 20;

/// A logged-in user's session.
#[derive(Debug, Clone)]
pub struct AuthSession {
    pub user: User,
    /// The token every form of this session carries (`csrf` field).
    pub csrf: String,
    pub(crate) token_hash: String,
}

/// The session of the request, if any (set by [`session_layer`]).
#[derive(Debug, Clone)]
struct MaybeSession(Option<AuthSession>);

/// The logged-in user; a handler taking it is only reached when logged in. Otherwise a page
/// is redirected to `/login` and an `/api/` call gets 401.
#[derive(Debug, Clone)]
pub struct CurrentUser(pub AuthSession);

impl CurrentUser {
    pub fn user(&self) -> &User {
        &self.0.user
    }
    pub fn id(&self) -> i64 {
        self.0.user.id
    }
    pub fn role(&self) -> Role {
        self.0.user.role
    }
    pub fn csrf(&self) -> &str {
        &self.0.csrf
    }
    /// Instructors and administrators.
    pub fn is_staff(&self) -> bool {
        matches!(self.role(), Role::Instructor | Role::Admin)
    }
    /// Errors unless an instructor or administrator.
    pub fn require_staff(&self) -> Result<(), AppError> {
        if self.is_staff() {
            Ok(())
        } else {
            Err(AppError::Forbidden("instructors and administrators only"))
        }
    }
}

/// Why [`CurrentUser`] was refused.
#[derive(Debug)]
pub enum AuthRejection {
    Page,
    Api,
}

impl IntoResponse for AuthRejection {
    fn into_response(self) -> Response {
        match self {
            AuthRejection::Page => Redirect::to("/login").into_response(),
            AuthRejection::Api => ApiError(AppError::Unauthorized).into_response(),
        }
    }
}

impl<S: Send + Sync> FromRequestParts<S> for CurrentUser {
    type Rejection = AuthRejection;

    async fn from_request_parts(parts: &mut Parts, _state: &S) -> Result<Self, Self::Rejection> {
        match parts.extensions.get::<MaybeSession>() {
            Some(MaybeSession(Some(s))) => Ok(CurrentUser(s.clone())),
            _ if original_path(parts).starts_with("/api/") => Err(AuthRejection::Api),
            _ => Err(AuthRejection::Page),
        }
    }
}

/// The path as the client sent it (routers nested under `/api` see it without the prefix).
pub(crate) fn original_path(parts: &Parts) -> &str {
    parts
        .extensions
        .get::<axum::extract::OriginalUri>()
        .map_or_else(|| parts.uri.path(), |u| u.0.path())
}

fn is_state_changing(m: &Method) -> bool {
    !matches!(*m, Method::GET | Method::HEAD | Method::OPTIONS)
}

/// Resolves the session cookie and checks CSRF tokens (see the module documentation).
pub async fn session_layer(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let session = match tokens::cookie(req.headers(), SESSION_COOKIE) {
        Some(token) => match sessions::lookup(&state, token).await {
            Ok(s) => s,
            Err(e) => return e.into_response(),
        },
        None => None,
    };
    let mut req = req;
    // `/login` has its own double-submit token (there may be no session yet); the hub's
    // uploads take a station's bearer token and no session, so a cookie sent along is
    // no authority there and its CSRF check (which reads a form body) is not theirs
    if let Some(s) = &session
        && is_state_changing(req.method())
        && req.uri().path() != "/login"
        && !req.uri().path().starts_with("/api/hub/")
    {
        req = match check_csrf(req, &s.csrf).await {
            Ok(r) => r,
            Err(e) if req_is_api_path(&e.1) => return ApiError(e.0).into_response(),
            Err(e) => return e.0.into_response(),
        };
    }
    req.extensions_mut().insert(MaybeSession(session));
    let mut response = next.run(req).await;
    security_headers(&mut response);
    response
}

fn req_is_api_path(path: &str) -> bool {
    path.starts_with("/api/")
}

/// The request back (body re-assembled) if its CSRF token matches `expected`; else the error
/// and the request's path.
async fn check_csrf(req: Request, expected: &str) -> Result<Request, (AppError, String)> {
    let path = req.uri().path().to_owned();
    if let Some(h) = req.headers().get("x-csrf-token") {
        return if h.to_str().is_ok_and(|h| tokens::same_token(h, expected)) {
            Ok(req)
        } else {
            Err((AppError::Csrf, path))
        };
    }
    let (parts, body) = req.into_parts();
    let bytes = match axum::body::to_bytes(body, MAX_FORM_BYTES).await {
        Ok(b) => b,
        Err(_) => {
            return Err((
                AppError::BadRequest(format!("form larger than {MAX_FORM_BYTES} bytes")),
                path,
            ));
        }
    };
    let given = form_urlencoded_field(&bytes, "csrf");
    if !given.is_some_and(|g| tokens::same_token(&g, expected)) {
        return Err((AppError::Csrf, path));
    }
    Ok(Request::from_parts(parts, Body::from(bytes)))
}

/// The first value of `name` in an `application/x-www-form-urlencoded` body.
fn form_urlencoded_field(body: &[u8], name: &str) -> Option<String> {
    form_urlencoded::parse(body)
        .find(|(k, _)| k == name)
        .map(|(_, v)| v.into_owned())
}

/// Headers on every answer: no sniffing, no framing by other sites, no referrer leaks.
fn security_headers(r: &mut Response) {
    let h = r.headers_mut();
    h.insert(
        "x-content-type-options",
        axum::http::HeaderValue::from_static("nosniff"),
    );
    h.insert(
        "x-frame-options",
        axum::http::HeaderValue::from_static("SAMEORIGIN"),
    );
    h.insert(
        "referrer-policy",
        axum::http::HeaderValue::from_static("same-origin"),
    );
    if !h.contains_key(axum::http::header::CACHE_CONTROL) {
        h.insert(
            axum::http::header::CACHE_CONTROL,
            axum::http::HeaderValue::from_static("no-store"),
        );
    }
}

/// `Set-Cookie` value of a session cookie (or its removal with `None`).
pub fn session_cookie(token: Option<&str>, secure: bool) -> String {
    let secure = if secure { "; Secure" } else { "" };
    match token {
        Some(t) => format!(
            "{SESSION_COOKIE}={t}; Path=/; HttpOnly; SameSite=Strict; Max-Age={}{secure}",
            sessions::SESSION_TTL_NS / 1_000_000_000
        ),
        None => format!("{SESSION_COOKIE}=; Path=/; HttpOnly; SameSite=Strict; Max-Age=0{secure}"),
    }
}
