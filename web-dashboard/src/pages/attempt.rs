//! `/attempts/{id}`: every metric with its threshold and verdict, the executed incision
//! against the planned line (top view), the force over time, downloads, replay review, and
//! the debriefing (instructors comment and sign off; the trainee reads).

use axum::Router;
use axum::extract::State;
use axum::response::Redirect;
use axum::routing::{get, post};
use cutlab_assessor::from_recording::DAMAGED_RECORDING_NOTE;
use maud::{Markup, html};
use serde::Deserialize;

use super::layout::{num, page, verdict, when};
use crate::AppState;
use crate::access::visible_attempt;
use crate::auth::CurrentUser;
use crate::charts::{Chart, Layer};
use crate::data::attempt::{AttemptDetail, detail};
use crate::data::debrief;
use crate::data::label;
use crate::data::trace::{AttemptTrace, trace};
use crate::error::PageResult;
use crate::extract::{Form, Id};

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/attempts/{id}", get(attempt))
        .route("/attempts/{id}/comments", post(comment))
        .route("/attempts/{id}/signoff", post(sign_off))
}

async fn attempt(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
) -> PageResult<Markup> {
    let a = visible_attempt(&state, &user, id).await?;
    let t = trace(&state, &a).await?;
    let d = detail(&state, a).await?;
    Ok(page(
        &format!("Attempt {id}"),
        Some(&user),
        body(&user, &d, t.as_deref()),
    ))
}

fn limits(lower: Option<f64>, upper: Option<f64>, f: f64) -> String {
    match (lower, upper) {
        (Some(l), Some(u)) => format!("{} … {}", num(Some(l * f), 3), num(Some(u * f), 3)),
        (Some(l), None) => format!("≥ {}", num(Some(l * f), 3)),
        (None, Some(u)) => format!("≤ {}", num(Some(u * f), 3)),
        (None, None) => "–".into(),
    }
}

fn body(user: &CurrentUser, d: &AttemptDetail, t: Option<&AttemptTrace>) -> Markup {
    let a = &d.attempt;
    html! {
        p {
            "Trainee " a href=(format!("/trainees/{}", d.trainee.id)) { (d.trainee.name) }
            " · exercise " (d.exercise.name) " · started " (when(a.started_ns)) " UTC · " (a.status.as_str())
            @if let Some(s) = a.score { " · score " (num(Some(s), 2)) } " · " (verdict(a.passed))
        }
        @if let Some(n) = &a.note {
            // an attempt scored from a damaged recording says so where it is seen
            p class=(if n.starts_with(DAMAGED_RECORDING_NOTE) { "warning" } else { "muted" }) { (n) }
        }
        p class="downloads" {
            @if d.recordings.mcap { a href=(format!("/attempts/{}/recording.mcap", a.id)) { "Download .mcap" } } @else { span class="muted" { "no .mcap" } }
            " · "
            @if d.recordings.rrd {
                a href=(format!("/attempts/{}/recording.rrd", a.id)) { "Download .rrd" } " · "
                a id="review-replay" href=(format!("/attempts/{}/replay", a.id)) { strong { "Review replay" } }
            } @else { span class="muted" { "no .rrd (replay review needs " code { "cutlab session --rrd" } ")" } }
        }
        @if let Some(t) = t {
            div class="charts" { (top_view(t)) (force_chart(t)) }
        } @else {
            p class="muted" { "No readable recording: no incision or force plot." }
        }
        h2 { "Metrics" }
        table class="metrics" {
            thead { tr { th { "Metric" } th { "Value" } th { "Unit" } th { "Expert" } th { "Pass limits" } th { "Verdict" } th { "What" } } }
            tbody {
                @for m in &d.metrics {
                    @let l = label(&m.key, &m.unit);
                    @let (f, unit) = (l.factor, l.unit);
                    tr {
                        td { (l.name) @if m.scored { " *" } }
                        td class="num" { (num(m.value.map(|v| v * f), 3)) @if let Some(w) = &m.missing { br; span class="muted" { (w) } } }
                        td { (unit) }
                        td class="num" { (num(m.mean.map(|v| v * f), 3)) }
                        td class="num" { (limits(m.lower_limit, m.upper_limit, f)) }
                        td { (verdict(m.passed)) }
                        td class="muted" { (m.description) }
                    }
                }
            }
        }
        p class="muted" { "* scored: pass/fail and the score use it." }
        h2 { "Debriefing" }
        @if let Some(s) = &d.signoff { p class="pass" { "Signed off by " (s.instructor.name) " at " (when(s.signed_ns)) " UTC" } }
        @if d.comments.is_empty() { p class="muted" { "No comments yet." } }
        @for c in &d.comments {
            div class="comment" { strong { (c.author.name) } " · " span class="muted" { (when(c.created_ns)) } br; (c.body) }
        }
        @if user.is_staff() {
            form method="post" action=(format!("/attempts/{}/comments", a.id)) {
                input type="hidden" name="csrf" value=(user.csrf());
                textarea name="body" rows="3" maxlength=(debrief::MAX_COMMENT_CHARS) required placeholder="Comment for the trainee" {}
                br; button type="submit" { "Add comment" }
            }
            @if d.signoff.is_none() {
                form method="post" action=(format!("/attempts/{}/signoff", a.id)) {
                    input type="hidden" name="csrf" value=(user.csrf());
                    button type="submit" { "Sign off" }
                }
            }
        }
    }
}

fn top_view(t: &AttemptTrace) -> Markup {
    let mut c = Chart::new("Incision, top view", "x (mm)", "y (mm)")
        .layer(Layer::Line {
            points: t.path_mm.iter().map(|p| (p[0], Some(p[1]))).collect(),
            class: "series-2",
        })
        .layer(Layer::Line {
            points: t.planned_mm.iter().map(|p| (p[0], Some(p[1]))).collect(),
            class: "plan",
        })
        .layer(Layer::Line {
            points: t.cut_mm.iter().map(|p| (p[0], Some(p[1]))).collect(),
            class: "cut",
        });
    c.equal_aspect = true;
    c.height = 300.0;
    c.render()
}

fn force_chart(t: &AttemptTrace) -> Markup {
    let mut c = Chart::new("Force on the hand", "time (s)", "|F| (N)")
        .layer(Layer::HLine {
            y: t.force_limit_n,
            class: "limit",
            label: "limit".into(),
        })
        .layer(Layer::Line {
            points: t.force.iter().map(|p| (p[0], Some(p[1]))).collect(),
            class: "series",
        });
    c.y_include = vec![0.0];
    c.height = 300.0;
    c.render()
}

#[derive(Debug, Deserialize)]
struct CommentForm {
    body: String,
}

async fn comment(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
    Form(f): Form<CommentForm>,
) -> PageResult<Redirect> {
    user.require_staff()?;
    let a = visible_attempt(&state, &user, id).await?;
    debrief::add_comment(&state, a.id, user.id(), &f.body).await?;
    Ok(Redirect::to(&format!("/attempts/{id}")))
}

async fn sign_off(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
) -> PageResult<Redirect> {
    user.require_staff()?;
    let a = visible_attempt(&state, &user, id).await?;
    debrief::sign_off(&state, a.id, user.id()).await?;
    Ok(Redirect::to(&format!("/attempts/{id}")))
}
