//! `/attempts/{id}`: every metric with its threshold and verdict, the executed incision
//! against the planned line (top view), the force over time, downloads, replay review, and
//! the debriefing (instructors comment and sign off; the trainee reads).

use axum::Router;
use axum::extract::State;
use axum::response::Redirect;
use axum::routing::{get, post};
use cutlab_scoring::advice::{MetricResult, advice};
use cutlab_scoring::from_recording::DAMAGED_RECORDING_NOTE;
use cutlab_scoring::proficiency::decides;
use maud::{Markup, html};
use serde::Deserialize;

use super::layout::{limits, num, page, verdict, when};
use crate::AppState;
use crate::access::visible_attempt;
use crate::auth::CurrentUser;
use crate::charts::{Chart, Layer};
use crate::data::attempt::{AttemptDetail, PassLimits, detail};
use crate::data::debrief::{self, Comment, moment_label};
use crate::data::trace::{AttemptTrace, trace_for};
use crate::data::{device_words, label, mode_words};
use crate::error::PageResult;
use crate::extract::{Form, Id};
use crate::recordings::replay_url;

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/attempts/{id}", get(attempt))
        .route("/attempts/{id}/comments", post(comment))
        .route("/attempts/{id}/signoff", post(sign_off))
        .route(
            "/attempts/{id}/field.png",
            get(crate::data::field_picture::field_png),
        )
}

async fn attempt(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
) -> PageResult<Markup> {
    let a = visible_attempt(&state, &user, id).await?;
    let t = trace_for(&state, &user, &a).await?;
    let d = detail(&state, a).await?;
    Ok(page(
        &format!("Attempt {id}"),
        Some(&user),
        body(&user, &d, t.as_deref()),
    ))
}

/// The debrief's first lines: what to fix next (or what went well), then the feedback-only
/// metrics against the experts.
fn fix_next(d: &AttemptDetail) -> Markup {
    let results: Vec<MetricResult<'_>> = d
        .metrics
        .iter()
        .map(|m| MetricResult {
            key: &m.key,
            value: m.value,
            passed: m.passed,
            mean: m.mean,
            lower: m.lower_limit,
            upper: m.upper_limit,
        })
        .collect();
    let a = advice(&results);
    html! {
        section id="fix-next" {
            h2 { "What to fix next" }
            @if let Some(p) = &a.praise { p class="pass" { (p) } }
            @if !a.fix.is_empty() { ol { @for f in &a.fix { li { (f) } } } }
            @if !a.feedback.is_empty() {
                p class="muted" { "Feedback (does not decide the verdict):" }
                ul class="muted" { @for f in &a.feedback { li { (f) } } }
            }
        }
    }
}

fn body(user: &CurrentUser, d: &AttemptDetail, t: Option<&AttemptTrace>) -> Markup {
    let a = &d.attempt;
    html! {
        p {
            "Trainee " a href=(format!("/trainees/{}", d.trainee.id)) { (d.trainee.name) }
            " · exercise " (d.exercise.name) " · started " (when(a.started_ns)) " UTC · " (a.status.as_str())
            @if let Some(s) = a.score { " · score " (num(Some(s), 2)) } " · " (verdict(a.passed))
            " · " span class="setup" { (mode_words(a.mode.as_deref())) @if let Some(device) = &a.device { ", " (device_words(device)) } }
            @if let Some(station) = &a.station { " · " span class="station" { "uploaded by station " (station) } }
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
            div class="charts" { (top_view(t).render()) (force_chart(t, d.peak_force_limits_n, d.force_limit_n).render()) }
            @if d.recordings.mcap && d.metrics.iter().any(|m| m.key == "field_of_expert" && m.value.is_some()) {
                figure id="field-picture" class="field-picture" {
                    img src=(format!("/attempts/{}/field.png", a.id)) width="360" height="360" alt="The field as scored: the wound at the end, seen from the viewpoint";
                    figcaption { "The field as scored: the wound at the end, spread by the exercise's retractor, seen from the viewpoint; the target deep red where it shows." }
                }
            }
        } @else {
            p class="muted" { "No readable recording: no incision or force plot." }
        }
        @if a.scored { (fix_next(d)) }
        @else if a.note.as_deref() == Some(cutlab_scoring::UNTOUCHED_NOTE) {
            section id="fix-next" {
                h2 { "What to fix next" }
                p { "Nothing was cut: the tool never touched the tissue, so this attempt is kept but not scored. Start, press the blade into the tissue where the incision begins and draw it along the line before you stop." }
            }
        }
        h2 { "Metrics" }
        table class="metrics" {
            thead { tr { th { "Metric" } th { "Value" } th { "Unit" } th { "Expert" } th { "Pass limits" } th { "Verdict" } th { "What" } } }
            tbody {
                @for m in &d.metrics {
                    @let l = label(&m.key, &m.unit);
                    @let (f, unit) = (l.factor, l.unit);
                    tr {
                        td { (l.name) @if m.scored && decides(&m.key) { " *" } }
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
        p class="muted" { "* decides: pass/fail and the score use it. Time, path, movements and smoothness are feedback only (shown against the experts, not deciding) until thresholds come from people." }
        h2 { "Debriefing" }
        @if let Some(s) = &d.signoff { p class="pass" { "Signed off by " (s.instructor.name) " at " (when(s.signed_ns)) " UTC" } }
        @if d.comments.is_empty() { p class="muted" { "No comments yet." } }
        @for c in &d.comments { (comment_markup(a.id, c, d.recordings.rrd)) }
        @if user.is_staff() {
            (comment_form(user, a.id, false))
            @if d.signoff.is_none() {
                form method="post" action=(format!("/attempts/{}/signoff", a.id)) {
                    input type="hidden" name="csrf" value=(user.csrf());
                    button type="submit" { "Sign off" }
                }
            }
        }
    }
}

/// One debriefing comment; a review note (pinned to a moment) links to the replay at that
/// moment when the attempt has one.
pub(crate) fn comment_markup(attempt_id: i64, c: &Comment, has_replay: bool) -> Markup {
    html! {
        div class="comment" {
            strong { (c.author.name) } " · " span class="muted" { (when(c.created_ns)) }
            @if let Some(at) = c.at_ns {
                " · "
                @if has_replay {
                    a class="moment" href=(replay_url(attempt_id, Some(at))) data-at-ns=(at) { "at " (moment_label(at)) }
                } @else {
                    span class="moment" { "at " (moment_label(at)) }
                }
            }
            br; (c.body)
        }
    }
}

/// The form an instructor comments with: on the attempt page, or beside the replay (`replay`:
/// back to the replay at the note's moment afterwards). The moment is optional.
pub(crate) fn comment_form(user: &CurrentUser, attempt_id: i64, replay: bool) -> Markup {
    html! {
        form class="comment-form" method="post" action=(format!("/attempts/{attempt_id}/comments")) {
            input type="hidden" name="csrf" value=(user.csrf());
            @if replay { input type="hidden" name="next" value="replay"; }
            label { "At (s, or m:ss; the viewer's time, e.g. +1.700s; empty: the whole attempt) "
                input type="text" name="at" size="10" maxlength="20" inputmode="decimal" placeholder="e.g. 1.7"; }
            br;
            label { "Note for the trainee" br;
                textarea name="body" rows="3" maxlength=(debrief::MAX_COMMENT_CHARS) required placeholder="Comment for the trainee" {} }
            br; button type="submit" { @if replay { "Pin note" } @else { "Add comment" } }
        }
    }
}

/// The incision seen from above: the tip's path (grey), the executed cut (orange) and the
/// planned line (dashed blue, drawn last so it shows over a cut that follows it), with a
/// legend.
fn top_view(t: &AttemptTrace) -> Chart {
    let mut c = Chart::new("The cut, top view", "along the plan (mm)", "across (mm)")
        .layer(Layer::Line {
            points: t.path_mm.iter().map(|p| (p[0], Some(p[1]))).collect(),
            class: "series-2",
        })
        .layer(Layer::Line {
            points: t.cut_mm.iter().map(|p| (p[0], Some(p[1]))).collect(),
            class: "cut",
        });
    // no plan for a trainee's exam-only exercise ([`trace_for`])
    if !t.planned_mm.is_empty() {
        c = c
            .layer(Layer::Line {
                points: t.planned_mm.iter().map(|p| (p[0], Some(p[1]))).collect(),
                class: "plan",
            })
            .legend("plan", "planned");
    }
    let mut c = c.legend("cut", "cut").legend("series-2", "tip path");
    c.equal_aspect = true;
    c.height = 300.0;
    c
}

/// The force over time with the pass limits the exercise scores the peak force with (its
/// `peak_force_n` threshold), or without one the plan's own force limit `safety_n`.
fn force_chart(t: &AttemptTrace, limits: Option<PassLimits>, safety_n: Option<f64>) -> Chart {
    let mut c = Chart::new("Force on the hand", "time (s)", "|F| (N)");
    if limits.is_none()
        && let Some(y) = safety_n
    {
        c = c.layer(Layer::HLine {
            y,
            class: "limit",
            label: format!("force limit {} N", num_short(y)),
        });
    }
    let limits = limits.map_or([None, None], |l| [l.lower, l.upper]);
    for (limit, sign) in limits.into_iter().zip(["≥", "≤"]) {
        if let Some(y) = limit.filter(|y| y.is_finite()) {
            c = c.layer(Layer::HLine {
                y,
                class: "limit",
                label: format!("pass {sign} {} N", num_short(y)),
            });
        }
    }
    c = c.layer(Layer::Line {
        points: t.force.iter().map(|p| (p[0], Some(p[1]))).collect(),
        class: "series",
    });
    // from no force up, the limits and at least 1 N in view: a chart of an attempt that
    // never pressed reads 0 N, not a line in the middle of -1..1
    c.y_include = vec![0.0, 1.0];
    c.height = 300.0;
    c
}

/// A number with at most 2 decimals, without trailing zeros (0.9, 2.5, 3).
fn num_short(v: f64) -> String {
    let s = format!("{v:.2}");
    s.trim_end_matches('0').trim_end_matches('.').to_owned()
}

#[derive(Debug, Deserialize)]
struct CommentForm {
    body: String,
    /// The moment the note is pinned to (see [`debrief::parse_moment`]); absent or empty: none.
    #[serde(default)]
    at: String,
    /// `replay`: answer with the replay at the note's moment instead of the attempt page.
    #[serde(default)]
    next: String,
}

async fn comment(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
    Form(f): Form<CommentForm>,
) -> PageResult<Redirect> {
    user.require_staff()?;
    let a = visible_attempt(&state, &user, id).await?;
    let at_ns = debrief::parse_moment(&f.at)?;
    debrief::add_comment(&state, a.id, user.id(), &f.body, at_ns).await?;
    Ok(Redirect::to(&if f.next == "replay" {
        replay_url(id, at_ns)
    } else {
        format!("/attempts/{id}")
    }))
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

#[cfg(test)]
mod tests {
    use super::*;

    fn trace() -> AttemptTrace {
        AttemptTrace {
            planned_mm: vec![[0.0, 0.0], [60.0, 0.0]],
            cut_mm: vec![[1.0, 0.5], [30.0, 1.0], [58.0, 0.8]],
            path_mm: vec![[-5.0, 3.0], [1.0, 0.5], [58.0, 0.8], [62.0, 4.0]],
            force: vec![[0.0, 0.0], [1.0, 0.7], [2.0, 1.2], [3.0, 0.4]],
            force_limit_n: 2.5,
            tolerance_mm: 2.0,
        }
    }

    fn hlines(c: &Chart) -> Vec<(f64, &str, &str)> {
        c.layers
            .iter()
            .filter_map(|l| match l {
                Layer::HLine { y, class, label } => Some((*y, *class, label.as_str())),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn the_force_chart_draws_the_exercises_peak_force_limit_not_the_plans() {
        let t = trace();
        let c = force_chart(
            &t,
            Some(PassLimits {
                lower: None,
                upper: Some(0.9),
            }),
            Some(2.5),
        );
        assert_eq!(hlines(&c), vec![(0.9, "limit", "pass ≤ 0.9 N")]);
        let svg = c.render().into_string();
        assert!(
            svg.contains("pass ≤ 0.9 N") && !svg.contains("2.5"),
            "{svg}"
        );
        // two-sided: both limits
        let c = force_chart(
            &t,
            Some(PassLimits {
                lower: Some(0.2),
                upper: Some(3.0),
            }),
            Some(2.5),
        );
        assert_eq!(
            hlines(&c),
            vec![(0.2, "limit", "pass ≥ 0.2 N"), (3.0, "limit", "pass ≤ 3 N")]
        );
        // no threshold on the peak force: the plan's force limit, named as such
        let c = force_chart(&t, None, Some(2.5));
        assert_eq!(hlines(&c), vec![(2.5, "limit", "force limit 2.5 N")]);
        // and without either, no line at all
        let c = force_chart(&t, None, None);
        assert!(hlines(&c).is_empty());
        assert!(!c.render().into_string().contains("class=\"limit\""));
        // an attempt that never pressed: the chart runs from 0 N up, not -1..1
        let still = AttemptTrace {
            force: vec![[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]],
            ..trace()
        };
        let c = force_chart(&still, None, None);
        let (_, (lo, hi)) = c.ranges();
        assert!(lo > -0.1 && lo <= 0.0 && hi >= 1.0, "{lo}..{hi}");
    }

    #[test]
    fn the_top_view_tells_the_plan_from_the_cut() {
        let svg = top_view(&trace()).render().into_string();
        // the lines carry the styled classes (dashed blue plan, orange cut) ...
        assert_eq!(svg.matches("<polyline class=\"plan\"").count(), 1, "{svg}");
        assert_eq!(svg.matches("<polyline class=\"cut\"").count(), 1);
        // ... and a legend names them with the same classes
        let legend = &svg[svg.find("class=\"legend\"").unwrap()..];
        for (class, label) in [
            ("plan", "planned"),
            ("cut", "cut"),
            ("series-2", "tip path"),
        ] {
            assert!(
                legend.contains(&format!("<line class=\"{class}\""))
                    && legend.contains(&format!(">{label}</text>")),
                "{class} {label}: {legend}"
            );
        }
        let css = include_str!("static/style.css");
        assert!(css.contains("svg.chart .plan {") && css.contains("stroke-dasharray"));
        assert!(css.contains("svg.chart .cut {"));
    }
}
