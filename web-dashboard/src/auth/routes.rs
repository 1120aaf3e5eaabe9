//! `GET /login` (the form), `POST /login`, `POST /logout`.

use std::net::SocketAddr;

use axum::Router;
use axum::extract::{ConnectInfo, State};
use axum::http::header::SET_COOKIE;
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::{get, post};
use serde::Deserialize;

use super::{CurrentUser, LOGIN_CSRF_COOKIE, sessions, tokens};
use crate::AppState;
use crate::error::AppError;
use crate::extract::Form;
use crate::pages::layout;

/// The longest user name or password the form takes (argon2 has its own limits; this keeps
/// hostile input cheap).
const MAX_FIELD: usize = 256;

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/login", get(login_form).post(login))
        .route("/logout", post(logout))
}

async fn login_form(State(state): State<AppState>) -> Result<Response, AppError> {
    login_page(&state, StatusCode::OK, None)
}

fn login_page(
    state: &AppState,
    status: StatusCode,
    message: Option<&str>,
) -> Result<Response, AppError> {
    let csrf = tokens::random_token()?;
    let cookie = format!(
        "{LOGIN_CSRF_COOKIE}={csrf}; Path=/login; HttpOnly; SameSite=Strict; Max-Age=3600{}",
        if state.config().secure_cookies {
            "; Secure"
        } else {
            ""
        }
    );
    Ok((
        status,
        [(SET_COOKIE, cookie)],
        layout::login_page(&csrf, message),
    )
        .into_response())
}

#[derive(Debug, Deserialize)]
struct LoginForm {
    #[serde(default)]
    username: String,
    #[serde(default)]
    password: String,
    #[serde(default)]
    csrf: String,
}

/// The peer's IP address (from the server's connection info; "unknown" without it).
struct ClientIp(String);

impl<S: Send + Sync> axum::extract::FromRequestParts<S> for ClientIp {
    type Rejection = std::convert::Infallible;
    async fn from_request_parts(
        parts: &mut axum::http::request::Parts,
        _: &S,
    ) -> Result<Self, Self::Rejection> {
        Ok(ClientIp(
            parts
                .extensions
                .get::<ConnectInfo<SocketAddr>>()
                .map_or_else(|| "unknown".to_owned(), |c| c.0.ip().to_string()),
        ))
    }
}

async fn login(
    State(state): State<AppState>,
    headers: HeaderMap,
    ClientIp(ip): ClientIp,
    Form(form): Form<LoginForm>,
) -> Result<Response, AppError> {
    // login CSRF: the hidden field must match the cookie set with the form
    if !tokens::cookie(&headers, LOGIN_CSRF_COOKIE)
        .is_some_and(|c| tokens::same_token(c, &form.csrf))
    {
        return Err(AppError::Csrf);
    }
    let name = form.username.trim();
    // two limits: per user name and address (low: guessing one account's password; a
    // stranger elsewhere cannot lock its owner out) and per address (high: the users of a
    // clinic share its NAT's address). Each login takes its place before the check.
    let user_key = format!("user:{}@{ip}", name.to_lowercase());
    let ip_key = format!("ip:{ip}");
    let Some(user_place) = state.limiter().take(&user_key) else {
        return Err(AppError::TooManyRequests);
    };
    let Some(ip_place) = state.ip_limiter().take(&ip_key) else {
        state.limiter().give_back(&user_key, user_place);
        return Err(AppError::TooManyRequests);
    };
    let user = if name.is_empty() || name.len() > MAX_FIELD || form.password.len() > MAX_FIELD {
        None
    } else {
        state.store().verify_password(name, &form.password).await?
    };
    let Some(user) = user else {
        tracing::info!("failed login for {name:?}");
        return login_page(
            &state,
            StatusCode::UNAUTHORIZED,
            Some("Unknown user or wrong password."),
        );
    };
    state.limiter().clear(&user_key);
    state.ip_limiter().give_back(&ip_key, ip_place);
    let token = sessions::create(&state, &user).await?;
    tracing::info!("{} ({}) logged in", user.name, user.role);
    let cookie = super::session_cookie(Some(&token), state.config().secure_cookies);
    Ok(([(SET_COOKIE, cookie)], Redirect::to("/")).into_response())
}

async fn logout(State(state): State<AppState>, user: CurrentUser) -> Result<Response, AppError> {
    sessions::delete(&state, &user.0.token_hash).await?;
    let cookie = super::session_cookie(None, state.config().secure_cookies);
    Ok(([(SET_COOKIE, cookie)], Redirect::to("/login")).into_response())
}
