//! `/trainees/{id}`: a trainee's progress: per exercise a summary table (per metric the
//! latest, best and mean values, the pass limits, the pass rate) first, then on demand
//! (collapsed) the normalised score and CUSUM charts (explained) and the learning curves per
//! metric with the expert band and the pass limits; the attempts; the curriculum modules.

use axum::Router;
use axum::body::Bytes;
use axum::extract::State;
use axum::response::Html;
use axum::response::Redirect;
use axum::routing::{get, post};
use cutlab_assessor::store::{Access, Role, iso8601};
use cutlab_scoring::evidence::Experience;
use maud::{Markup, html};
use serde::Deserialize;

use super::layout::{limits, num, page_around, verdict, when};
use crate::AppState;
use crate::access::visible_user;
use crate::auth::CurrentUser;
use crate::charts::{Chart, Layer};
use crate::data::ExerciseRef;
use crate::data::ProficiencySummary;
use crate::data::progress::{
    CusumChart, ExerciseProgress, MetricSeries, Progress, cached_progress,
};
use crate::data::{device_words, label, mode_words};
use crate::error::{AppError, PageResult};
use crate::extract::{Form, Id};
use cutlab_scoring::proficiency::{CusumSignal, ProficiencyStatus, REQUIRED_CONSECUTIVE_PASSES};

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/trainees/{id}", get(trainee))
        .route("/trainees/{id}/open", post(open_early))
        .route("/trainees/{id}/experience", post(set_experience))
}

async fn trainee(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
) -> PageResult<Html<Bytes>> {
    let trainee = visible_user(&state, &user, id).await?;
    let c = cached_progress(&state, &trainee).await?;
    let body = c
        .html
        .get_or_init(|| Bytes::from(body(&c.data).into_string()));
    // the instructor's form is the viewer's (its CSRF token), not the cached page's
    let opener = if user.is_staff() {
        let level = state.store().experience(trainee.id).await?;
        let forms =
            html! { (experience_form(&trainee, level, &user)) (open_early_form(&c.data, &user)) };
        forms.into_string()
    } else {
        String::new()
    };
    Ok(page_around(
        &format!("Progress of {}", c.data.trainee.name),
        Some(&user),
        &[body.as_ref(), opener.as_bytes()].concat(),
    ))
}

/// The instructor's form to open a locked exercise to the trainee before its turn.
fn open_early_form(p: &Progress, user: &CurrentUser) -> Markup {
    let mut locked: Vec<&ExerciseRef> = p
        .curricula
        .iter()
        .flat_map(|c| c.modules.iter().flat_map(|m| &m.exercises))
        .filter(|x| x.access.as_ref().is_some_and(|a| !a.is_open()))
        .map(|x| &x.exercise)
        .collect();
    locked.dedup_by_key(|e| e.id);
    html! {
        @if !locked.is_empty() {
            form class="open-early" method="post" action=(format!("/trainees/{}/open", p.trainee.id)) {
                input type="hidden" name="csrf" value=(user.csrf());
                label for="open-exercise" { "Open early" } " "
                select id="open-exercise" name="exercise" {
                    @for e in &locked { option value=(e.name) { (e.name) } }
                }
                " "
                input id="open-reason" name="reason" placeholder="why (recorded)" maxlength="500";
                " "
                button id="open-early" type="submit" { "Open to " (p.trainee.name) }
            }
        }
    }
}

/// The trainee's recorded experience (the evidence report's groups); an administrator
/// sets it.
fn experience_form(
    trainee: &cutlab_assessor::store::User,
    level: Option<Experience>,
    user: &CurrentUser,
) -> Markup {
    let shown = level.map_or("not recorded", Experience::as_str);
    html! {
        @if user.role() == Role::Admin {
            form class="experience" method="post" action=(format!("/trainees/{}/experience", trainee.id)) {
                input type="hidden" name="csrf" value=(user.csrf());
                label for="experience" { "Experience" } " "
                select id="experience" name="level" {
                    option value="none" selected[level.is_none()] { "not recorded" }
                    @for e in Experience::ALL { option value=(e.as_str()) selected[level == Some(e)] { (e.as_str()) } }
                }
                " "
                button id="set-experience" type="submit" { "Record" }
            }
        } @else {
            p class="experience" { "Experience: " (shown) }
        }
    }
}

#[derive(Debug, Deserialize)]
struct ExperienceForm {
    level: String,
}

/// `POST /trainees/{id}/experience`: an administrator records the trainee's experience.
async fn set_experience(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
    Form(f): Form<ExperienceForm>,
) -> PageResult<Redirect> {
    if user.role() != Role::Admin {
        return Err(AppError::Forbidden("administrators only"));
    }
    let trainee = visible_user(&state, &user, id).await?;
    let level = match f.level.as_str() {
        "none" => None,
        l => Some(
            l.parse::<Experience>()
                .map_err(|e| AppError::BadRequest(e.to_string()))?,
        ),
    };
    state.store().set_experience(trainee.id, level).await?;
    Ok(Redirect::to(&format!("/trainees/{id}")))
}

#[derive(Debug, Deserialize)]
struct OpenForm {
    /// The exercise's name.
    exercise: String,
    #[serde(default)]
    reason: String,
}

/// `POST /trainees/{id}/open`: an instructor opens an exercise to the trainee early.
async fn open_early(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
    Form(f): Form<OpenForm>,
) -> PageResult<Redirect> {
    user.require_staff()?;
    let trainee = visible_user(&state, &user, id).await?;
    let reason = f.reason.trim();
    let store = state.store();
    let exercise = match store.exercise_by_name(&f.exercise).await {
        Err(cutlab_assessor::AssessError::NotFound(_)) => {
            return Err(AppError::BadRequest(format!(
                "no exercise named {:?}",
                f.exercise
            )));
        }
        other => other?,
    };
    store
        .open_early(trainee.id, exercise.id, user.id(), reason)
        .await?;
    state.caches().progress.remove(&trainee.id);
    Ok(Redirect::to(&format!("/trainees/{id}")))
}

/// How an exercise of a curriculum with progression stands for the trainee.
fn access_words(a: &Access) -> String {
    match a {
        Access::Open => "open".into(),
        Access::Earned { after } => format!("open: proficient in {after}"),
        Access::OpenedEarly(o) => format!(
            "opened early by {} on {}{}",
            o.opened_by,
            &iso8601(o.opened_ns)[..10],
            if o.reason.is_empty() {
                String::new()
            } else {
                format!(": {}", o.reason)
            }
        ),
        Access::Locked { after, .. } => format!("locked until proficient in {after}"),
    }
}

fn body(p: &Progress) -> Markup {
    html! {
        @if p.exercises.is_empty() { p class="muted" { "No attempts yet." } }
        @for e in &p.exercises { (exercise_section(e)) }
        h2 { "Curriculum" }
        @if p.curricula.is_empty() { p class="muted" { "No curriculum defined." } }
        @for c in &p.curricula {
            h3 { (c.name) }
            @if c.progression {
                p class="muted" { "Each exercise opens when the one before it is proficient ("
                    (REQUIRED_CONSECUTIVE_PASSES) " passes in a row), or when an instructor opens it early." }
            }
            table {
                thead { tr { th { "#" } th { "Module" } th { "State" } th { "Exercises" } } }
                tbody {
                    @for m in &c.modules {
                        tr {
                            td class="num" { (m.position) }
                            td { (m.name) }
                            td class=(format!("state-{}", m.standing.as_str().replace(' ', "-"))) { (m.standing.as_str()) }
                            td { @for x in &m.exercises {
                                span class=(if x.access.as_ref().is_some_and(|a| !a.is_open()) { "locked" } else { "" }) {
                                    (x.exercise.name) " (" (x.standing.as_str())
                                    @if let Some(a) = &x.access { "; " (access_words(a)) }
                                    ")"
                                }
                                br;
                            } }
                        }
                    }
                }
            }
        }
    }
}

fn exercise_section(e: &ExerciseProgress) -> Markup {
    let pr = &e.proficiency;
    let score_points: Vec<(f64, Option<f64>)> = e
        .attempts
        .iter()
        .filter_map(|a| a.n.map(|n| (f64::from(n), a.score)))
        .collect();
    let score_chart = Chart::new("Normalised score", "attempt", "score")
        .integer_x()
        .layer(Layer::HLine {
            y: 0.0,
            class: "limit",
            label: "pass ≥ 0".into(),
        })
        .layer(Layer::HLine {
            y: 1.0,
            class: "mean",
            label: "expert".into(),
        })
        .layer(Layer::Line {
            points: score_points.clone(),
            class: "series",
        })
        .layer(Layer::Points {
            points: e
                .attempts
                .iter()
                .filter_map(|a| {
                    Some((
                        f64::from(a.n?),
                        a.score?,
                        if a.passed == Some(true) {
                            "pt-pass"
                        } else {
                            "pt-fail"
                        },
                    ))
                })
                .collect(),
        });
    let mut cusum = Chart::new("CUSUM of failures", "attempt", "CUSUM")
        .integer_x()
        .layer(Layer::HLine {
            y: e.cusum.h1,
            class: "limit",
            label: format!("h1 {:.2}", e.cusum.h1),
        })
        .layer(Layer::HLine {
            y: -e.cusum.h0,
            class: "ok",
            label: format!("−h0 {:.2}", e.cusum.h0),
        })
        .layer(Layer::HLine {
            y: 0.0,
            class: "zero",
            label: String::new(),
        })
        .layer(Layer::Line {
            points: cusum_line(&e.cusum),
            class: "series",
        });
    cusum.y_include = vec![e.cusum.h1, -e.cusum.h0];
    html! {
        h2 { (e.exercise.name) }
        p {
            (pr.attempts) " scored attempts, " (pr.passes) " passed, " (pr.consecutive_passes) " consecutive; "
            (standing_words(pr))
        }
        (cusum_status(&e.cusum, pr.status))
        (summary_table(&e.metrics))
        details class="score-charts" {
            summary { "Score and CUSUM charts" }
            div class="charts" {
                (score_chart.render())
                (cusum.render())
            }
            (cusum_explanation(&e.cusum))
        }
        details class="curves" {
            summary { "Learning curves (" (e.metrics.len()) " metrics)" }
            div class="charts learning-curves" {
                @for m in &e.metrics { (metric_chart(m)) }
            }
        }
        h3 { "Attempts" }
        table {
            thead { tr { th { "#" } th { "Attempt" } th { "Started (UTC)" } th { "Mode" } th { "Device" } th { "Status" } th { "Score" } th { "Verdict" } } }
            tbody {
                @for a in e.attempts.iter().rev() {
                    tr {
                        td class="num" { @if let Some(n) = a.n { (n) } }
                        td { a href=(format!("/attempts/{}", a.id)) { "attempt " (a.id) } }
                        td { (when(a.started_ns)) }
                        td { (mode_words(a.mode.as_deref())) }
                        td { (a.device.as_deref().map(device_words).unwrap_or_default()) }
                        td { (a.status.as_str()) }
                        td class="num" { (num(a.score, 2)) }
                        td { (verdict(a.passed)) }
                    }
                }
            }
        }
    }
}

/// Per metric (thresholded first): the latest, best and mean values in display units, the
/// pass limits and the pass rate.
fn summary_table(metrics: &[MetricSeries]) -> Markup {
    html! {
        table class="summary" {
            thead { tr { th { "Metric" } th { "Unit" } th { "Latest" } th { "Best" } th { "Mean" } th { "Pass limits" } th { "Passed" } } }
            tbody {
                @for m in metrics {
                    @let l = label(&m.key, &m.unit);
                    @let s = m.summary();
                    @let f = l.factor;
                    tr {
                        td { (l.name) }
                        td { (l.unit) }
                        td class="num" { (num(s.latest.map(|v| v * f), 2)) }
                        td class="num" { (num(s.best.map(|v| v * f), 2)) }
                        td class="num" { (num(s.mean.map(|v| v * f), 2)) }
                        td class="num" { (m.band.as_ref().map_or_else(|| "–".into(), |b| limits(b.lower_limit, b.upper_limit, f))) }
                        td class="num" {
                            @if s.verdicts > 0 {
                                (s.passes) " of " (s.verdicts) " (" (100 * s.passes / s.verdicts) " %)"
                            } @else { "–" }
                        }
                    }
                }
            }
        }
    }
}

/// The trainee's standing in words: proficient since attempt N, lapsed since attempt M (the
/// CUSUM after proficiency reached its unacceptable limit), or the standing while learning.
fn standing_words(pr: &ProficiencySummary) -> Markup {
    html! {
        @match pr.status {
            ProficiencyStatus::Proficient { since } => {
                strong class="pass" { "proficient since attempt " (since) }
                @if let Some(t) = pr.trials_to_proficiency.filter(|&t| t != since) {
                    " (first after " (t) " attempts)"
                }
            }
            ProficiencyStatus::Lapsed { since } => {
                strong class="fail" { "proficiency lapsed: unacceptable failure rate since attempt " (since) " — retrain" }
                @if let Some(t) = pr.trials_to_proficiency { " (proficient after " (t) " attempts before)" }
            }
            ProficiencyStatus::Learning => strong { (pr.standing.as_str()) },
        }
    }
}

/// Where the CUSUM stands after the last scored attempt, in the phase it counts (since the
/// last change of standing, which restarts it from 0).
fn cusum_status(c: &CusumChart, status: ProficiencyStatus) -> Markup {
    let restarted = match status {
        ProficiencyStatus::Proficient { since } => Some((since, "the trainee became proficient")),
        ProficiencyStatus::Lapsed { since } => Some((since, "the proficiency lapsed")),
        ProficiencyStatus::Learning => None,
    };
    html! {
        @if let Some(last) = c.points.last() {
            p {
                "CUSUM after attempt " (last.n) ": " (num(Some(c.current.value), 2)) ", "
                @match c.current.signal {
                    CusumSignal::Acceptable => strong class="pass" { "acceptable failure rate" },
                    CusumSignal::Unacceptable => strong class="fail" { "unacceptable failure rate" },
                    CusumSignal::None => span { "no signal yet" },
                }
                @if let Some((n, why)) = restarted { ", counted afresh from 0 after attempt " (n) ", when " (why) }
                " (acceptable at −h0 = −" (num(Some(c.h0), 2)) ", unacceptable at h1 = " (num(Some(c.h1), 2)) ")."
            }
        }
    }
}

/// The CUSUM chart's line: from 0 before the first attempt, down to 0 again after each
/// attempt that restarted it.
fn cusum_line(c: &CusumChart) -> Vec<(f64, Option<f64>)> {
    let mut line = vec![(0.0, Some(0.0))];
    for p in &c.points {
        line.push((f64::from(p.n), Some(p.value)));
        if c.restarts.contains(&p.n) {
            line.push((f64::from(p.n), Some(0.0)));
        }
    }
    line
}

/// What the CUSUM chart's lines mean.
fn cusum_explanation(c: &CusumChart) -> Markup {
    let s = c.params.s();
    let pct = |p: f64| format!("{:.0} %", 100.0 * p);
    html! {
        p class="muted explain" {
            "The CUSUM line rises by " (num(Some(1.0 - s), 2)) " with each failed attempt and falls by "
            (num(Some(s), 2)) " with each pass. Reaching the green line −h0 means the trainee's failure rate is acceptable (at most "
            (pct(c.params.p0)) "): proficient by CUSUM; reaching the red line h1 means it is unacceptable (" (pct(c.params.p1))
            " or more) and their technique needs review. The standing above counts "
            (REQUIRED_CONSECUTIVE_PASSES) " consecutive passes; the line starts again from 0 after the attempt that completes them "
            "(the failures while learning are behind the trainee), and once proficient, reaching h1 means the proficiency has lapsed: "
            "the trainee retrains until " (REQUIRED_CONSECUTIVE_PASSES) " consecutive passes again, when the line restarts once more."
        }
    }
}

fn metric_chart(m: &MetricSeries) -> Markup {
    let l = label(&m.key, &m.unit);
    let (f, unit) = (l.factor, l.unit);
    let mut c = Chart::new(l.with_unit(), "attempt", unit).integer_x();
    if let Some(b) = &m.band {
        if b.sd > 0.0 {
            c = c.layer(Layer::HBand {
                low: b.low * f,
                high: b.high * f,
                class: "band",
            });
        }
        c = c.layer(Layer::HLine {
            y: b.mean * f,
            class: "mean",
            label: "expert".into(),
        });
        for l in [b.lower_limit, b.upper_limit].into_iter().flatten() {
            c = c.layer(Layer::HLine {
                y: l * f,
                class: "limit",
                label: "pass".into(),
            });
        }
    }
    c = c
        .layer(Layer::Line {
            points: m
                .points
                .iter()
                .map(|p| (f64::from(p.n), p.value.map(|v| v * f)))
                .collect(),
            class: "series",
        })
        .layer(Layer::Points {
            points: m
                .points
                .iter()
                .filter_map(|p| {
                    Some((
                        f64::from(p.n),
                        p.value? * f,
                        match p.passed {
                            Some(true) => "pt-pass",
                            Some(false) => "pt-fail",
                            None => "pt",
                        },
                    ))
                })
                .collect(),
        });
    c.render()
}
