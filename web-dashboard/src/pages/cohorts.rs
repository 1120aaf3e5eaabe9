//! `/cohorts`: per cohort, trainees x exercises with the attempts, the standing and the
//! trials to proficiency.

use axum::Router;
use axum::extract::State;
use axum::routing::get;
use maud::{Markup, html};

use super::layout::{num, page};
use crate::AppState;
use crate::auth::CurrentUser;
use crate::data::overview::overview;
use crate::error::PageResult;
use cutlab_scoring::proficiency::ProficiencyStatus;

pub fn router() -> Router<AppState> {
    Router::new().route("/cohorts", get(cohorts))
}

async fn cohorts(State(state): State<AppState>, user: CurrentUser) -> PageResult<Markup> {
    user.require_staff()?;
    let grids = overview(&state, &user).await?;
    Ok(page(
        "Cohorts",
        Some(&user),
        html! {
            @if grids.is_empty() { p class="muted" { "No cohort is led by you yet (" code { "cutlab cohort add --name N --instructor YOU" } ")." } }
            @for g in &grids {
                h2 { "Cohort " (g.cohort.name) @if let Some(i) = &g.instructor { span class="muted" { " · instructor " (i.name) } } }
                @if g.trainees.is_empty() {
                    p class="muted" { "No trainees." }
                } @else {
                    table class="grid" {
                        thead { tr { th { "Trainee" } @for e in &g.exercises { th { (e.name) } } } }
                        tbody {
                            @for row in &g.trainees {
                                tr {
                                    td { a href=(format!("/trainees/{}", row.trainee.id)) { (row.trainee.name) } }
                                    @for c in &row.cells {
                                        td class=(format!("state-{}", c.proficiency.standing.as_str().replace(' ', "-"))) {
                                            strong { (c.proficiency.standing.as_str()) } br;
                                            (c.attempts) " attempts, " (c.proficiency.passes) " passed"
                                            @if let Some(t) = c.proficiency.trials_to_proficiency { br; "proficient after " (t) }
                                            @if let ProficiencyStatus::Lapsed { since } = c.proficiency.status { br; strong class="fail" { "unacceptable failure rate since attempt " (since) ": retrain" } }
                                            @if c.last_score.is_some() { br; span class="muted" { "last score " (num(c.last_score, 2)) } }
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
        },
    ))
}
