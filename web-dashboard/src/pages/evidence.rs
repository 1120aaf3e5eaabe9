//! `/exercises/{id}/evidence`: the validity evidence of an exercise's scores for instructors
//! and administrators (a trainee gets 404): the experience groups' distributions of the
//! overall score and of each metric, Mann-Whitney U, p and the AUC with its bootstrap
//! interval, which metrics do not discriminate (said plainly), test-retest ICC, the
//! learning curves' plateaus and the contrasting-groups pass mark, which an instructor can
//! adopt for the exercise (`POST .../evidence/adopt`, recorded with who and when).

use axum::Router;
use axum::extract::{RawQuery, State};
use axum::response::Redirect;
use axum::routing::{get, post};
use cutlab_assessor::store::PassMark;
use cutlab_scoring::evidence::{Experience, Finding, LearningCurve, Measure, Report};
use maud::{Markup, html};
use serde::Deserialize;

use super::layout::{num, page, when};
use crate::AppState;
use crate::access::can_see_user;
use crate::auth::CurrentUser;
use crate::charts::{Chart, Layer};
use crate::data::label;
use crate::error::{AppError, PageResult};
use crate::extract::{Form, Id};

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/exercises/{id}/evidence", get(evidence))
        .route("/exercises/{id}/evidence/adopt", post(adopt))
}

/// `?reference=exclude` leaves the reference attempts out.
pub(crate) fn include_reference(query: Option<&str>) -> bool {
    !query.is_some_and(|q| q.split('&').any(|p| p == "reference=exclude"))
}

async fn evidence(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
    RawQuery(query): RawQuery,
) -> PageResult<Markup> {
    if !user.is_staff() {
        return Err(AppError::NotFound);
    }
    let store = state.store();
    let exercise = store.get_exercise(id).await?;
    let include = include_reference(query.as_deref());
    let report = store.evidence(id, include).await?;
    let adopted = store.pass_mark(id).await?;
    let mut curves = Vec::new();
    for c in &report.learning {
        if can_see_user(&state, &user, c.trainee_id).await? {
            curves.push(c);
        }
    }
    let hidden = report.learning.len() - curves.len();
    Ok(page(
        &format!("Validity evidence: {}", exercise.name),
        Some(&user),
        html! {
            (groups_section(&report, id))
            (score_section(&report, adopted.as_ref()))
            (pass_mark_section(&report, adopted.as_ref(), id, &user))
            (metrics_section(&report))
            (reliability_section(&report))
            (learning_section(&curves, hidden))
        },
    ))
}

fn level_x(level: Experience) -> f64 {
    match level {
        Experience::Novice => 1.0,
        Experience::Intermediate => 2.0,
        Experience::Expert => 3.0,
    }
}

fn level_class(level: Experience) -> &'static str {
    match level {
        Experience::Novice => "pt-novice",
        Experience::Intermediate => "pt-intermediate",
        Experience::Expert => "pt-expert",
    }
}

/// A learning curve's line class by its trainee's experience.
fn curve_class(level: Option<Experience>) -> &'static str {
    match level {
        Some(Experience::Novice) => "lc-novice",
        Some(Experience::Intermediate) => "lc-intermediate",
        Some(Experience::Expert) => "lc-expert",
        None => "lc-unknown",
    }
}

fn groups_section(r: &Report, id: i64) -> Markup {
    html! {
        p class="explain" {
            "Do the scores of this exercise mean skill? Attempts are grouped by their trainee's "
            "recorded experience (set by an administrator on the trainee's page); the most and the "
            "least experienced groups are compared. AUC: the chance that an attempt of the more "
            "experienced group is the better one (0.5: a coin toss), with its bootstrap 95 % interval. "
            "A measure discriminates when that interval lies above 0.5 (reversed when below); the "
            "Mann-Whitney p value is shown beside it, but the interval decides. "
            "Definitions: docs/guide/evidence.md."
        }
        @if r.groups.is_empty() {
            p { "No complete attempts by people with a recorded experience level yet." }
        }
        ul {
            @for g in &r.groups {
                li { strong { (g.level) } ": " (people(g.trainees)) ", " (count(g.attempts, "attempt", "attempts"))
                    @if g.reference_attempts > 0 { " (" (g.reference_attempts) " of them reference attempts)" } }
            }
            @if r.attempts_without_level > 0 {
                li class="muted" { "Left out: " (count(r.attempts_without_level, "attempt", "attempts")) " by " (people(r.trainees_without_level)) " with no experience level recorded" }
            }
        }
        p {
            @if r.include_reference {
                "Reference attempts (those that set the thresholds the scores are measured against) are counted. "
                a id="exclude-reference" href=(format!("/exercises/{id}/evidence?reference=exclude")) { "Leave them out" }
            } @else {
                "Reference attempts are left out. "
                a href=(format!("/exercises/{id}/evidence")) { "Count them" }
            }
        }
    }
}

/// A strip chart of a measure's values per group (display units), with horizontal lines.
fn strip_chart(m: &Measure, lines: Vec<Layer>) -> Markup {
    let l = label(&m.key, &m.unit);
    let (name, factor) = if m.key == cutlab_scoring::evidence::SCORE_KEY {
        ("Overall score".to_owned(), 1.0)
    } else {
        (l.with_unit(), l.factor)
    };
    let mut chart = Chart::new(&m.label, "experience", name);
    for level in Experience::ALL {
        chart = chart.category(level_x(level), level.as_str());
    }
    let points = m
        .groups
        .iter()
        .flat_map(|g| {
            g.values.iter().enumerate().map(move |(i, v)| {
                // a fixed spread within the group's column (golden-ratio offsets)
                let jitter = 0.5 * ((i as f64 * 0.618_034).fract() - 0.5);
                (level_x(g.level) + jitter, v * factor, level_class(g.level))
            })
        })
        .collect();
    chart = chart.layer(Layer::Points { points });
    for line in lines {
        chart = chart.layer(line);
    }
    chart.render()
}

fn comparison_words(m: &Measure) -> Markup {
    html! {
        @match &m.comparison {
            Some(c) => {
                "AUC " strong { (num(Some(c.auc), 2)) } " (95 % " (num(Some(c.auc_low), 2)) "–" (num(Some(c.auc_high), 2)) "), "
                "Mann-Whitney U = " (num(Some(c.u), 1)) ", p " (p_value(c.p)) (if c.exact_p { " (exact)" } else { "" })
                ": " strong { (m.finding.words()) } "."
            }
            None => { "Not computed: " (m.why_not.as_deref().unwrap_or("")) "." }
        }
    }
}

/// `1 person`, `3 people`.
fn people(n: usize) -> String {
    count(n, "person", "people")
}

/// `n` and the noun in the number it takes.
fn count(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

/// `< 0.001` or `= 0.012`.
fn p_value(p: f64) -> String {
    if p < 0.001 {
        "< 0.001".into()
    } else {
        format!("= {p:.3}")
    }
}

fn score_section(r: &Report, adopted: Option<&PassMark>) -> Markup {
    let mut lines = Vec::new();
    if let Some(c) = r.pass_mark.cut {
        lines.push(Layer::HLine {
            y: c.cut,
            class: "limit",
            label: "cut".into(),
        });
    }
    if let Some(a) = adopted {
        lines.push(Layer::HLine {
            y: a.score,
            class: "ok",
            label: "adopted".into(),
        });
    }
    html! {
        h2 { "Overall score" }
        div class="charts" { (strip_chart(&r.score, lines)) }
        p { (comparison_words(&r.score)) }
    }
}

fn pass_mark_section(
    r: &Report,
    adopted: Option<&PassMark>,
    id: i64,
    user: &CurrentUser,
) -> Markup {
    let p = &r.pass_mark;
    html! {
        h2 { "Pass mark by contrasting groups" }
        @match (p.cut, p.higher, p.lower) {
            (Some(c), Some(h), Some(l)) => {
                p id="contrasting-cut" {
                    "Where the " (h) " (" (p.n_higher) " attempts) and " (l) " (" (p.n_lower) ") groups' score "
                    "distributions cross (normal fits): " strong { (format!("{:+.3}", c.cut)) } ". "
                    "It would pass " (num(Some(100.0 * c.false_pass), 0)) " % of the " (l) " attempts "
                    "(" (num(Some(100.0 * c.false_pass_normal), 1)) " % by the fits) and fail "
                    (num(Some(100.0 * c.false_fail), 0)) " % of the " (h) " attempts ("
                    (num(Some(100.0 * c.false_fail_normal), 1)) " % by the fits)."
                }
                form method="post" action=(format!("/exercises/{id}/evidence/adopt")) {
                    input type="hidden" name="csrf" value=(user.csrf());
                    input type="hidden" name="reference" value=(if r.include_reference { "include" } else { "exclude" });
                    button id="adopt-pass-mark" type="submit" { "Adopt " (format!("{:+.3}", c.cut)) " as this exercise's pass mark" }
                }
            }
            _ => { p { "Not computed: " (p.why_not.as_deref().unwrap_or("")) "." } }
        }
        @match adopted {
            Some(a) => p id="adopted-pass-mark" {
                "Adopted pass mark: " strong { (format!("{:+.3}", a.score)) } " (" (a.method) ", " (a.higher_group) " "
                (a.n_higher) " against " (a.lower_group) " " (a.n_lower) " attempts), by " (a.adopted_by) " on " (when(a.adopted_ns)) ". "
                "The expert-band thresholds still decide each attempt's verdict."
            },
            None => p class="muted" { "No pass mark adopted for this exercise." },
        }
    }
}

fn metrics_section(r: &Report) -> Markup {
    let computed: Vec<&Measure> = r
        .metrics
        .iter()
        .filter(|m| m.comparison.is_some())
        .collect();
    html! {
        h2 { "Metrics" }
        @if !r.not_discriminating.is_empty() {
            p id="not-discriminating" { strong { "Do not discriminate between the groups: " } (r.not_discriminating.join(", ")) "." }
        } @else if !computed.is_empty() {
            p { "Every metric compared discriminates or is reversed (below)." }
        }
        table class="evidence" {
            thead { tr { th { "Metric" } th { "Median, " (r.higher.map_or("higher", |l| l.as_str())) } th { "Median, " (r.lower.map_or("lower", |l| l.as_str())) } th { "AUC (95 %): decides" } th { "p" } th { "ICC" } th { "Finding" } } }
            tbody {
                @for m in &r.metrics { (metric_row(m)) }
            }
        }
        @if !computed.is_empty() {
            details {
                summary { "Distributions per metric" }
                div class="charts" { @for m in &computed { (strip_chart(m, Vec::new())) } }
            }
        }
    }
}

fn metric_row(m: &Measure) -> Markup {
    let l = label(&m.key, &m.unit);
    let finding_class = match m.finding {
        Finding::Discriminates => "finding-discriminates",
        Finding::Reversed => "finding-reversed",
        Finding::DoesNotDiscriminate => "finding-does-not-discriminate",
        Finding::NotComputed => "muted",
    };
    html! {
        tr {
            td { (l.with_unit()) }
            @match &m.comparison {
                Some(c) => {
                    td class="num" { (num(Some(c.median_higher * l.factor), 3)) }
                    td class="num" { (num(Some(c.median_lower * l.factor), 3)) }
                    td class="num" { (num(Some(c.auc), 2)) " (" (num(Some(c.auc_low), 2)) "–" (num(Some(c.auc_high), 2)) ")" }
                    td class="num" { (p_value(c.p).trim_start_matches("= ")) }
                }
                None => { td colspan="4" class="muted" { (m.why_not.as_deref().unwrap_or("")) } }
            }
            td class="num" { (num(m.icc, 2)) }
            td class=(finding_class) { (m.finding.words()) }
        }
    }
}

fn reliability_section(r: &Report) -> Markup {
    let rel = &r.reliability;
    html! {
        h2 { "Test-retest reliability" }
        @match (rel.icc, rel.band) {
            (Some(icc), Some(band)) => p id="reliability" {
                "ICC(2,1) of the overall score over each trainee's last two attempts: " strong { (num(Some(icc), 2)) }
                " (" (band) ", Koo and Li 2016), " (rel.trainees) " trainees."
            },
            _ => p id="reliability" { "Not computed: " (rel.why_not.as_deref().unwrap_or("")) "." },
        }
    }
}

fn learning_section(curves: &[&LearningCurve], hidden: usize) -> Markup {
    let mut chart = Chart::new("Overall score by attempt", "attempt", "score").integer_x();
    // each trainee's line in the colour of their experience, named at its last attempt
    for c in curves {
        let points: Vec<(f64, Option<f64>)> = c
            .scores
            .iter()
            .enumerate()
            .map(|(i, s)| ((i + 1) as f64, Some(*s)))
            .collect();
        if let Some(&(x, Some(y))) = points.last() {
            chart = chart.layer(Layer::Text {
                x,
                y,
                text: c.trainee.clone(),
            });
        }
        chart = chart.layer(Layer::Line {
            points,
            class: curve_class(c.experience),
        });
    }
    for level in Experience::ALL {
        if curves.iter().any(|c| c.experience == Some(level)) {
            chart = chart.legend(curve_class(Some(level)), level.as_str());
        }
    }
    if curves.iter().any(|c| c.experience.is_none()) {
        chart = chart.legend(curve_class(None), "no level recorded");
    }
    html! {
        h2 { "Learning curves" }
        @if !curves.is_empty() { div class="charts" { (chart.render()) } }
        table {
            thead { tr { th { "Trainee" } th { "Experience" } th { "Attempts" } th { "Plateau" } th { "Reached at attempt" } } }
            tbody {
                @for c in curves {
                    tr {
                        td { a href=(format!("/trainees/{}", c.trainee_id)) { (c.trainee) } }
                        td { (c.experience.map_or("–", |e| e.as_str())) }
                        td class="num" { (c.scores.len()) }
                        @match c.plateau {
                            Some(p) if p.levelled => { td class="num" { (format!("{:+.2}", p.plateau)) } td class="num" { (p.reached_at) } }
                            Some(_) => { td colspan="2" class="muted" { "still improving: not levelled off yet" } }
                            None => { td colspan="2" class="muted" { "needs 4 attempts" } }
                        }
                    }
                }
            }
        }
        @if hidden > 0 { p class="muted" { "And " (hidden) " trainees you do not supervise (counted in the figures above)." } }
    }
}

#[derive(Debug, Deserialize)]
struct AdoptForm {
    #[serde(default)]
    reference: String,
}

/// `POST /exercises/{id}/evidence/adopt`: the report's cut adopted as the pass mark.
async fn adopt(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
    Form(f): Form<AdoptForm>,
) -> PageResult<Redirect> {
    if !user.is_staff() {
        return Err(AppError::NotFound);
    }
    let include = f.reference != "exclude";
    let report = state.store().evidence(id, include).await?;
    state
        .store()
        .adopt_pass_mark(id, &report.pass_mark, user.id())
        .await?;
    let query = if include { "" } else { "?reference=exclude" };
    Ok(Redirect::to(&format!("/exercises/{id}/evidence{query}")))
}
