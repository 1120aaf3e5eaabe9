//! `/curriculum`: exercises (scene, expert plan, thresholds) and curricula (modules of
//! exercises). Everyone reads; instructors and administrators create and edit. Every input
//! has its `<label for>`; the expert plan is asked as labelled fields or as text
//! ([`plan_form`]).

mod plan_form;

use std::collections::HashMap;

use axum::Router;
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::{get, post};
use cutlab_assessor::store::{ExerciseEdit, NewExercise, ThresholdSource, text};
use cutlab_scoring::ExercisePlan;
use cutlab_scoring::metrics::{self, Better};
use cutlab_scoring::proficiency::{DEFAULT_K, Threshold, Thresholds};
use maud::{Markup, html};
use serde::Deserialize;

use super::layout::{num, page};
use crate::AppState;
use crate::auth::CurrentUser;
use crate::data::label;
use crate::error::{AppError, PageResult};
use crate::extract::{Form, Id};

/// The longest plan text taken.
const MAX_PLAN_BYTES: usize = 64 * 1024;
/// The most thresholds one exercise takes.
const MAX_THRESHOLDS: usize = 100;
const MAX_NAME: usize = text::MAX_LABEL_CHARS;

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/curriculum", get(curriculum))
        .route("/exercises", post(create_exercise))
        .route("/exercises/{id}", get(exercise).post(edit_exercise))
        .route("/exercises/{id}/thresholds", post(edit_thresholds))
        .route("/curricula", post(create_curriculum))
        .route("/curricula/{id}/modules", post(add_module))
        .route("/plans/example.toml", get(example_plan))
        .route(
            "/static/plan.js",
            get(|| async { super::static_file("text/javascript", include_str!("static/plan.js")) }),
        )
}

/// The built-in plan's TOML, every field commented: the example the forms link to.
async fn example_plan(_user: CurrentUser) -> Response {
    (
        [(header::CONTENT_TYPE, "text/plain; charset=utf-8")],
        cutlab_scoring::exercise::CHEST_WALL_PLAN_TOML,
    )
        .into_response()
}

/// A plan from TOML or JSON (JSON when it starts with `{`).
pub fn parse_plan(text: &str) -> Result<ExercisePlan, AppError> {
    if text.len() > MAX_PLAN_BYTES {
        return Err(AppError::BadRequest(format!(
            "a plan has at most {MAX_PLAN_BYTES} bytes"
        )));
    }
    Ok(ExercisePlan::parse(text)?)
}

/// A name typed in a form, by the store's one text policy ([`text::label`]).
fn name_ok(what: &str, s: &str) -> Result<String, AppError> {
    Ok(text::label(what, s, MAX_NAME)?.to_owned())
}

fn positive(what: &str, s: &str) -> Result<f64, AppError> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(AppError::BadRequest(format!("{what}: a number > 0"))),
    }
}

async fn curriculum(State(state): State<AppState>, user: CurrentUser) -> PageResult<Markup> {
    let store = state.store();
    let exercises = store.list_exercises().await?;
    let mut curricula = Vec::new();
    for c in store.list_curricula().await? {
        let modules = store.curriculum_modules(c.id).await?;
        curricula.push((c, modules));
    }
    let name_of = |id: i64| {
        exercises
            .iter()
            .find(|e| e.id == id)
            .map_or("?", |e| e.name.as_str())
    };
    let sample_plan = ExercisePlan::chest_wall()?;
    Ok(page(
        "Curriculum",
        Some(&user),
        html! {
            h2 { "Exercises" }
            table {
                thead { tr { th { "Exercise" } th { "Scene" } th { "k" } th { "Description" } } }
                tbody {
                    @for e in &exercises {
                        tr { td { a href=(format!("/exercises/{}", e.id)) { (e.name) } } td { (e.scene) } td class="num" { (num(Some(e.threshold_k), 1)) } td { (e.description) } }
                    }
                }
            }
            h2 { "Curricula" }
            @if curricula.is_empty() { p class="muted" { "None yet." } }
            @for (c, modules) in &curricula {
                h3 { (c.name) } p class="muted" { (c.description) }
                ol { @for m in modules { li { (m.name) ": " @for (i, e) in m.exercise_ids.iter().enumerate() { @if i > 0 { ", " } (name_of(*e)) } } } }
                @if user.is_staff() {
                    form method="post" action=(format!("/curricula/{}/modules", c.id)) {
                        input type="hidden" name="csrf" value=(user.csrf());
                        label for=(format!("module-name-{}", c.id)) { "Add module" } " "
                        input type="text" id=(format!("module-name-{}", c.id)) name="name" required maxlength=(MAX_NAME) placeholder="module name"; " "
                        label for=(format!("module-exercise-{}", c.id)) { "with exercise" } " "
                        select id=(format!("module-exercise-{}", c.id)) name="exercise_id" { @for e in &exercises { option value=(e.id) { (e.name) } } } " "
                        button type="submit" { "Add" }
                    }
                }
            }
            @if user.is_staff() {
                h2 { "New curriculum" }
                form method="post" action="/curricula" {
                    input type="hidden" name="csrf" value=(user.csrf());
                    p {
                        label for="curriculum-name" { "Name" } " "
                        input type="text" id="curriculum-name" name="name" required maxlength=(MAX_NAME); " "
                        label for="curriculum-description" { "Description" } " "
                        input type="text" id="curriculum-description" name="description" maxlength=(text::MAX_DESCRIPTION_CHARS) size="50"; " "
                        button type="submit" { "Create" }
                    }
                }
                h2 { "New exercise" }
                form method="post" action="/exercises" {
                    input type="hidden" name="csrf" value=(user.csrf());
                    (exercise_fields(true, "chest-wall", "", DEFAULT_K, false))
                    (plan_form::plan_fields(&sample_plan))
                    (plan_form::plan_text(MAX_PLAN_BYTES))
                    (plan_form::plan_reference(&sample_plan))
                    p class="muted" { "The new exercise starts with the built-in provisional thresholds; edit them on its page." }
                    button type="submit" { "Create exercise" }
                }
            }
        },
    ))
}

/// The exercise's own fields (the name only for a new one), labelled.
fn exercise_fields(
    with_name: bool,
    scene: &str,
    description: &str,
    k: f64,
    exam_only: bool,
) -> Markup {
    html! {
        p {
            @if with_name {
                label for="exercise-name" { "Name" } " "
                input type="text" id="exercise-name" name="name" required maxlength=(MAX_NAME); " "
            }
            label for="exercise-scene" { "Scene" } " "
            input type="text" id="exercise-scene" name="scene" required maxlength=(MAX_NAME) value=(scene); " "
            label for="exercise-k" { "k (pass limits at the expert mean ± k SD)" } " "
            input type="number" step="any" min="0" id="exercise-k" name="threshold_k" value=(k) size="4";
        }
        p {
            label for="exercise-description" { "Description" } " "
            input type="text" id="exercise-description" name="description" value=(description) maxlength=(text::MAX_DESCRIPTION_CHARS) size="80";
        }
        p {
            input type="checkbox" id="exercise-exam-only" name="exam_only" value="on" checked[exam_only];
            " "
            label for="exercise-exam-only" { "Exam only: the station never shows the planned incision" }
        }
    }
}

#[derive(Debug, Deserialize)]
struct ExerciseForm {
    #[serde(default)]
    name: String,
    scene: String,
    #[serde(default)]
    description: String,
    threshold_k: String,
    /// The exam-only checkbox (`on` when ticked, absent otherwise).
    #[serde(default)]
    exam_only: Option<String>,
    /// The plan as TOML or JSON; when empty, the plan's fields (in `rest`) give it.
    #[serde(default)]
    plan: String,
    /// The other fields: the plan's values (see [`plan_form`]) and the CSRF token.
    #[serde(flatten)]
    rest: HashMap<String, String>,
}

async fn create_exercise(
    State(state): State<AppState>,
    user: CurrentUser,
    Form(f): Form<ExerciseForm>,
) -> PageResult<Redirect> {
    user.require_staff()?;
    let name = name_ok("name", &f.name)?;
    let scene = name_ok("scene", &f.scene)?;
    let k = positive("k", &f.threshold_k)?;
    let plan = plan_form::plan_from_form(&f.plan, &f.rest, &ExercisePlan::chest_wall()?)?
        .ok_or_else(|| {
            AppError::BadRequest(
                "an exercise needs an expert plan: its fields or its text (TOML or JSON)".into(),
            )
        })?;
    let thresholds = plan.kind_plan().default_thresholds();
    let e = state
        .store()
        .create_exercise(&NewExercise {
            name: &name,
            scene: &scene,
            description: f.description.trim(),
            plan: &plan,
            thresholds: &thresholds,
            threshold_k: k,
            exam_only: f.exam_only.is_some(),
        })
        .await?;
    Ok(Redirect::to(&format!("/exercises/{}", e.id)))
}

async fn edit_exercise(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
    Form(f): Form<ExerciseForm>,
) -> PageResult<Redirect> {
    user.require_staff()?;
    let scene = name_ok("scene", &f.scene)?;
    let k = positive("k", &f.threshold_k)?;
    // nothing said about the plan, or its fields as shown: the plan stays
    let current = state
        .store()
        .get_plan(state.store().get_exercise(id).await?.plan_id)
        .await?;
    let plan = plan_form::plan_from_form(&f.plan, &f.rest, &current)?.filter(|p| *p != current);
    state
        .store()
        .update_exercise(
            id,
            &ExerciseEdit {
                scene: &scene,
                description: f.description.trim(),
                threshold_k: k,
                exam_only: f.exam_only.is_some(),
            },
            plan.as_ref(),
        )
        .await?;
    state.caches().progress.clear();
    Ok(Redirect::to(&format!("/exercises/{id}")))
}

async fn exercise(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
) -> PageResult<Markup> {
    let store = state.store();
    let e = store.get_exercise(id).await?;
    let plan = store.get_plan(e.plan_id).await?;
    let t = store.thresholds(id).await?;
    let plan_json =
        serde_json::to_string_pretty(&plan).map_err(|err| AppError::Internal(err.to_string()))?;
    Ok(page(
        &format!("Exercise {}", e.name),
        Some(&user),
        html! {
            p { "Scene " code { (e.scene) } " · k = " (num(Some(e.threshold_k), 2)) } p { (e.description) }
            @if user.is_staff() {
                p { a id="evidence-link" href=(format!("/exercises/{id}/evidence")) { "Validity evidence of its scores" } " (experience groups, AUC, reliability, the contrasting-groups pass mark)" }
                @if matches!(plan, ExercisePlan::Field(_)) {
                    p { a id="planning-link" href=(format!("/exercises/{id}/planning")) { "Plan incisions on its scene" } " (draw candidates, compare what each exposes)" }
                }
            }
            h2 { "Thresholds" }
            @if user.is_staff() {
                form method="post" action=(format!("/exercises/{id}/thresholds")) {
                    input type="hidden" name="csrf" value=(user.csrf());
                    (thresholds_table(&t, true))
                    p class="muted" { "SI units (m, s, N). Empty limit: none. Clear a metric's key to drop it; the last row adds one." }
                    button type="submit" { "Save thresholds" }
                }
            } @else {
                (thresholds_table(&t, false))
            }
            h2 { "Expert plan" }
            @if user.is_staff() {
                form method="post" action=(format!("/exercises/{id}")) {
                    input type="hidden" name="csrf" value=(user.csrf());
                    (exercise_fields(false, &e.scene, &e.description, e.threshold_k, e.exam_only))
                    (plan_form::plan_fields(&plan))
                    (plan_form::plan_text(MAX_PLAN_BYTES))
                    p class="muted" { "Fields left as shown and an empty plan text keep the plan as it is." }
                    button type="submit" { "Save exercise" }
                }
            }
            details {
                summary { "The plan as stored (JSON)" }
                pre { (plan_json) }
            }
            (plan_form::plan_reference(&plan))
        },
    ))
}

/// A metric's display name with its SI unit (thresholds are edited in SI units).
fn metric_name(key: &str) -> String {
    let si = cutlab_scoring::metrics::metric(key).map_or("", |d| d.unit);
    let name = label(key, si).name;
    if si.is_empty() || si == "1" {
        name.to_owned()
    } else {
        format!("{name} ({si})")
    }
}

fn thresholds_table(t: &Thresholds, editable: bool) -> Markup {
    let f = |v: Option<f64>| v.map(|v| format!("{v}")).unwrap_or_default();
    html! {
        table {
            thead { tr { th { "Metric" } th { "Direction" } th { "Expert mean" } th { "SD" } th { "Lower limit" } th { "Upper limit" } th { "Experts" } } }
            tbody {
                @if editable {
                    @for (i, m) in t.metrics.iter().map(Some).chain(std::iter::once(None)).enumerate() {
                        tr {
                            @let row = m.map_or_else(|| "new metric".to_owned(), |m| metric_name(&m.key));
                            td {
                                label class="visually-hidden" for=(format!("key_{i}")) { "Metric (" (row) ")" }
                                select id=(format!("key_{i}")) name=(format!("key_{i}")) {
                                    option value="" { "–" }
                                    @for d in metrics::all().filter(|d| d.scored) { option value=(d.key) selected[m.is_some_and(|m| m.key == d.key)] { (metric_name(d.key)) } }
                                }
                            }
                            td {
                                label class="visually-hidden" for=(format!("better_{i}")) { "Direction (" (row) ")" }
                                select id=(format!("better_{i}")) name=(format!("better_{i}")) {
                                    @for b in [Better::LowerIsBetter, Better::HigherIsBetter, Better::TwoSided] { option value=(b.as_str()) selected[m.is_some_and(|m| m.better == b)] { (b.as_str()) } }
                                }
                            }
                            @for (field, what, v) in [
                                ("mean", "Expert mean", m.map(|m| m.mean)),
                                ("sd", "SD", m.map(|m| m.sd)),
                                ("lower", "Lower limit", m.and_then(|m| m.lower)),
                                ("upper", "Upper limit", m.and_then(|m| m.upper)),
                            ] {
                                td {
                                    label class="visually-hidden" for=(format!("{field}_{i}")) { (what) " (" (row) ")" }
                                    input type="text" size="8" id=(format!("{field}_{i}")) name=(format!("{field}_{i}")) value=(f(v));
                                }
                            }
                            td class="num" { @if let Some(m) = m { (m.n_experts) } }
                        }
                    }
                } @else {
                    @for m in &t.metrics {
                        tr { td { (metric_name(&m.key)) } td { (m.better.as_str()) } td class="num" { (m.mean) } td class="num" { (m.sd) } td class="num" { (f(m.lower)) } td class="num" { (f(m.upper)) } td class="num" { (m.n_experts) } }
                    }
                }
            }
        }
    }
}

/// Thresholds from the form's rows `key_i, better_i, mean_i, sd_i, lower_i, upper_i`.
fn thresholds_from_form(fields: &[(String, String)], k: f64) -> Result<Thresholds, AppError> {
    let get = |name: String| {
        fields
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, v)| v.trim())
    };
    let number = |name: String, what: &str, key: &str| -> Result<Option<f64>, AppError> {
        match get(name).filter(|v| !v.is_empty()) {
            None => Ok(None),
            Some(v) => match v.parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(Some(x)),
                _ => Err(AppError::BadRequest(format!(
                    "{key}: {what} is not a number"
                ))),
            },
        }
    };
    let mut metrics: Vec<Threshold> = Vec::new();
    for i in 0..=MAX_THRESHOLDS {
        let Some(key) = get(format!("key_{i}")) else {
            break;
        };
        if key.is_empty() {
            continue;
        }
        if i == MAX_THRESHOLDS {
            return Err(AppError::BadRequest(format!(
                "at most {MAX_THRESHOLDS} thresholds"
            )));
        }
        let def = cutlab_scoring::metrics::metric(key)
            .filter(|d| d.scored)
            .ok_or_else(|| AppError::BadRequest(format!("{key:?} is not a scored metric")))?;
        if metrics.iter().any(|m| m.key == def.key) {
            return Err(AppError::BadRequest(format!("{} given twice", def.key)));
        }
        let better = get(format!("better_{i}"))
            .and_then(Better::parse)
            .ok_or_else(|| AppError::BadRequest(format!("{key}: unknown direction")))?;
        let mean = number(format!("mean_{i}"), "the mean", key)?
            .ok_or_else(|| AppError::BadRequest(format!("{key}: the mean is needed")))?;
        let sd = number(format!("sd_{i}"), "the SD", key)?.unwrap_or(0.0);
        if sd < 0.0 {
            return Err(AppError::BadRequest(format!("{key}: a negative SD")));
        }
        let (lower, upper) = (
            number(format!("lower_{i}"), "the lower limit", key)?,
            number(format!("upper_{i}"), "the upper limit", key)?,
        );
        if lower.is_none() && upper.is_none() {
            return Err(AppError::BadRequest(format!(
                "{key}: a threshold needs a limit"
            )));
        }
        if let (Some(l), Some(u)) = (lower, upper)
            && l > u
        {
            return Err(AppError::BadRequest(format!(
                "{key}: lower limit above upper"
            )));
        }
        metrics.push(Threshold {
            key: def.key.into(),
            better,
            mean,
            sd,
            n_experts: 0,
            lower,
            upper,
        });
    }
    Ok(Thresholds { k, metrics })
}

async fn edit_thresholds(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
    Form(fields): Form<Vec<(String, String)>>,
) -> PageResult<Redirect> {
    user.require_staff()?;
    let e = state.store().get_exercise(id).await?;
    let t = thresholds_from_form(&fields, e.threshold_k)?;
    state
        .store()
        .set_thresholds(id, &t, ThresholdSource::Default)
        .await?;
    state.caches().progress.clear();
    Ok(Redirect::to(&format!("/exercises/{id}")))
}

#[derive(Debug, Deserialize)]
struct CurriculumForm {
    name: String,
    #[serde(default)]
    description: String,
}

async fn create_curriculum(
    State(state): State<AppState>,
    user: CurrentUser,
    Form(f): Form<CurriculumForm>,
) -> PageResult<Redirect> {
    user.require_staff()?;
    let name = name_ok("name", &f.name)?;
    state
        .store()
        .create_curriculum(&name, f.description.trim())
        .await?;
    state.caches().progress.clear();
    Ok(Redirect::to("/curriculum"))
}

async fn add_module(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
    Form(fields): Form<Vec<(String, String)>>,
) -> PageResult<Redirect> {
    user.require_staff()?;
    let name = name_ok(
        "module name",
        fields
            .iter()
            .find(|(k, _)| k == "name")
            .map_or("", |(_, v)| v.as_str()),
    )?;
    let ids: Vec<i64> = fields
        .iter()
        .filter(|(k, _)| k == "exercise_id")
        .take(MAX_THRESHOLDS)
        .map(|(_, v)| {
            v.trim()
                .parse::<i64>()
                .map_err(|_| AppError::BadRequest("exercise ids are numbers".into()))
        })
        .collect::<Result<_, _>>()?;
    state.store().get_curriculum(id).await?;
    state.store().add_module(id, &name, &ids).await?;
    state.caches().progress.clear();
    Ok(Redirect::to("/curriculum"))
}
