//! `GET /kiosk/{ticket}`: how `cutlab station` (a station on one PC, for one trainee) logs
//! its trainee in. The command asks for a ticket ([`issue`]), opens the link in the browser,
//! and the link starts a login session and goes to `/station`. A ticket is 256 random bits,
//! kept in memory only (its SHA-256), good once and for [`TICKET_TTL`]; a new one replaces the
//! last.

use std::sync::Mutex;
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::{Path, State};
use axum::http::header::SET_COOKIE;
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::get;
use cutlab_assessor::store::Role;

use super::{sessions, tokens};
use crate::AppState;
use crate::error::AppError;

/// How long a kiosk link stays good.
pub const TICKET_TTL: Duration = Duration::from_secs(600);

/// The one pending kiosk ticket.
#[derive(Debug, Default)]
pub struct KioskTicket(Mutex<Option<Ticket>>);

#[derive(Debug)]
struct Ticket {
    token_sha256: String,
    user_id: i64,
    expires: Instant,
}

pub fn router() -> Router<AppState> {
    Router::new().route("/kiosk/{ticket}", get(enter))
}

/// A one-time link (a path, `/kiosk/…`) that logs trainee `name` in and opens the station.
pub async fn issue(state: &AppState, name: &str) -> Result<String, AppError> {
    let user = state.store().user_by_name(name).await?;
    if user.role != Role::Trainee {
        return Err(AppError::BadRequest(format!(
            "{name} is an {}: a station kiosk is for a trainee",
            user.role
        )));
    }
    let token = tokens::random_token()?;
    let ticket = Ticket {
        token_sha256: tokens::token_hash(&token),
        user_id: user.id,
        expires: Instant::now() + TICKET_TTL,
    };
    *state
        .kiosk()
        .0
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(ticket);
    Ok(format!("/kiosk/{token}"))
}

async fn enter(
    State(state): State<AppState>,
    Path(token): Path<String>,
) -> Result<Response, AppError> {
    let hash = tokens::token_hash(&token);
    let user_id = {
        let mut slot = state
            .kiosk()
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        match slot.take() {
            Some(t) if tokens::same_token(&t.token_sha256, &hash) && t.expires > Instant::now() => {
                Some(t.user_id)
            }
            // another link leaves the pending one as it was
            Some(t) if t.expires > Instant::now() => {
                *slot = Some(t);
                None
            }
            _ => None,
        }
    };
    let Some(user_id) = user_id else {
        return Err(AppError::Forbidden(
            "this kiosk link was used already or has expired; start `cutlab station` again",
        ));
    };
    let user = state.store().get_user(user_id).await?;
    let token = sessions::create(&state, &user).await?;
    tracing::info!("{} logged in at the kiosk", user.name);
    let cookie = super::session_cookie(Some(&token), state.config().secure_cookies);
    Ok(([(SET_COOKIE, cookie)], Redirect::to("/station")).into_response())
}
