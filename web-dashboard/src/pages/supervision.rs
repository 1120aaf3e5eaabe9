//! `/supervision`: attempts in progress, live. The table is rendered on the server, then
//! kept current by server-sent events (`/supervision/events`, one `running` event with the
//! JSON list every second; our `static/supervision.js` redraws the rows). The stream ends
//! with its login session (a logout elsewhere, an expiry).

use std::convert::Infallible;
use std::time::Duration;

use axum::Router;
use axum::extract::State;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::routing::get;
use futures_util::Stream;
use maud::{Markup, html};

use super::layout::{page, when};
use crate::AppState;
use crate::auth::{CurrentUser, sessions};
use crate::data::running::{RunningAttempt, running};
use crate::error::PageResult;

/// How often the events repeat the list.
const PERIOD: Duration = Duration::from_secs(1);

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/supervision", get(supervision))
        .route("/supervision/events", get(events))
}

async fn supervision(State(state): State<AppState>, user: CurrentUser) -> PageResult<Markup> {
    let list = running(&state, &user).await?;
    Ok(page(
        "Attempts in progress",
        Some(&user),
        html! {
            p class="muted" { "Live: updated every second. " span id="live-status" {} }
            table id="running" {
                thead { tr { th { "Attempt" } th { "Trainee" } th { "Exercise" } th { "Started (UTC)" } th { "Elapsed" } th { "Recorded" } th { "Live" } } }
                tbody { @for r in &list { (row(r)) } }
            }
            @if list.is_empty() { p id="none-running" class="muted" { "Nothing running right now." } }
            script src="/static/supervision.js" {}
        },
    ))
}

fn row(r: &RunningAttempt) -> Markup {
    html! {
        tr {
            td { a href=(format!("/attempts/{}", r.id)) { "attempt " (r.id) } }
            td { a href=(format!("/trainees/{}", r.trainee.id)) { (r.trainee.name) } }
            td { (r.exercise.name) }
            td { (when(r.started_ns)) }
            td class="num" { (format!("{:.0} s", r.elapsed_s)) }
            td class="num" { @if let Some(b) = r.recording_bytes { (format!("{:.1} MB", b as f64 / 1e6)) } @else { "–" } }
            td { @if r.live { a href=(format!("/station/{}", r.id)) { "live view" } } @else { "–" } }
        }
    }
}

async fn events(
    State(state): State<AppState>,
    user: CurrentUser,
) -> Sse<impl Stream<Item = Result<Event, Infallible>>> {
    let stream =
        futures_util::stream::unfold((state, user, true), |(state, user, first)| async move {
            if !first {
                tokio::time::sleep(PERIOD).await;
                if let Ok(false) = sessions::alive(&state, &user.0.token_hash).await {
                    return None;
                }
            }
            let event = match running(&state, &user).await {
                Ok(list) => Event::default()
                    .event("running")
                    .json_data(&list)
                    .unwrap_or_else(|_| Event::default().event("error").data("serialisation")),
                Err(e) => Event::default().event("error").data(e.public_message()),
            };
            Some((Ok(event), (state, user, false)))
        });
    Sse::new(stream).keep_alive(KeepAlive::default())
}
