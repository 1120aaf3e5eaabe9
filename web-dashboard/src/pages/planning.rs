//! `/exercises/{id}/planning`: candidate incisions on a field exercise's scene, compared by
//! what each exposes (issue 62), for instructors and administrators (a trainee gets 404).
//!
//! The page shows the skin from above with the exercise's landmarks, the target's outline
//! beneath and the expert's line; up to [`LETTERS`] candidates are drawn on it (a drag, by
//! `static/planning.js`) or typed in millimetres. Comparing cuts each candidate and the
//! expert's line in the simulation ([`planning::field_pictured`]), lets the wound open,
//! spreads it as the exercise's retractor does, and shows them side by side: the field as the
//! viewpoint sees it and its figures. One comparison runs at a time on a server
//! ([`Planner`]); another meanwhile is told to wait.

use std::collections::HashMap;

use axum::Router;
use axum::extract::State;
use axum::routing::get;
use base64::Engine;
use cutlab_scoring::ExercisePlan;
use cutlab_scoring::exercise::field::FieldPlan;
use cutlab_scoring::planning::{self, CandidateIncision, FieldReport, Opening, SkinMap, View};
use cutlab_sim::scene::{BuildOptions, Scene};
use maud::{Markup, html};

use super::layout::{num, page};
use crate::AppState;
use crate::auth::CurrentUser;
use crate::error::{AppError, PageResult};
use crate::extract::{Form, Id};

/// The candidates' names, in the order the page offers them.
pub const LETTERS: [char; 4] = ['A', 'B', 'C', 'D'];
/// How long the wound opens before the field is measured, s (as `cutlab plan field`).
const OPEN_S: f64 = 0.5;
/// A picture's pixels across and down.
const PICTURE_PX: u32 = 360;

pub fn router() -> Router<AppState> {
    Router::new().route("/exercises/{id}/planning", get(planning_page).post(compare))
}

/// One comparison at a time: each cuts up to five incisions in the simulation (seconds of a
/// core), so a second is refused while one runs instead of queueing behind it.
#[derive(Debug)]
pub struct Planner(tokio::sync::Semaphore);

impl Default for Planner {
    fn default() -> Self {
        Self(tokio::sync::Semaphore::new(1))
    }
}

impl Planner {
    /// Its turn, waited for up to 30 s (an attempt's field picture, which a page asks for
    /// once and then keeps).
    pub(crate) async fn wait(&self) -> Result<tokio::sync::SemaphorePermit<'_>, AppError> {
        let busy =
            || AppError::Unavailable("The planner is busy; try again in a few seconds.".into());
        tokio::time::timeout(std::time::Duration::from_secs(30), self.0.acquire())
            .await
            .map_err(|_| busy())?
            .map_err(|_| busy())
    }
}

/// A candidate as the form gives it, mm on the skin map.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Drawn {
    letter: char,
    from_mm: [f64; 2],
    to_mm: [f64; 2],
    depth_mm: f64,
}

/// The exercise's field plan and scene, or 404 for another kind (and for a trainee).
async fn field_exercise(
    state: &AppState,
    user: &CurrentUser,
    id: i64,
) -> PageResult<(cutlab_assessor::store::Exercise, FieldPlan)> {
    if !user.is_staff() {
        return Err(AppError::NotFound);
    }
    let store = state.store();
    let exercise = store.get_exercise(id).await?;
    match store.get_plan(exercise.plan_id).await? {
        ExercisePlan::Field(plan) => Ok((exercise, plan)),
        _ => Err(AppError::NotFound),
    }
}

async fn planning_page(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
) -> PageResult<Markup> {
    let (exercise, plan) = field_exercise(&state, &user, id).await?;
    let map = skin_map(&exercise.scene).await?;
    let sheet = Sheet {
        user: &user,
        id,
        name: &exercise.name,
        plan: &plan,
        form: &HashMap::new(),
        retract_mm: plan.retractor_width_m.map(|w| w * 1e3),
    };
    Ok(sheet.markup(&map, None))
}

async fn compare(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
    Form(form): Form<HashMap<String, String>>,
) -> PageResult<Markup> {
    let (exercise, plan) = field_exercise(&state, &user, id).await?;
    let drawn = drawn_candidates(&form)?;
    let retract_mm = retractor_mm(&form)?;
    let Ok(_permit) = state.planner().0.try_acquire() else {
        return Err(AppError::Unavailable(
            "The planner is comparing another set of candidates; try again in a few seconds."
                .into(),
        ));
    };
    let scene_name = exercise.scene.clone();
    let expert = CandidateIncision {
        incision_m: plan.incision_m.clone(),
        depth_m: plan.depth_m,
    };
    let (map, compared) = tokio::task::spawn_blocking(move || {
        compare_blocking(&scene_name, expert, &drawn, retract_mm)
    })
    .await
    .map_err(|e| AppError::Internal(format!("the planner: {e}")))??;
    let sheet = Sheet {
        user: &user,
        id,
        name: &exercise.name,
        plan: &plan,
        form: &form,
        retract_mm,
    };
    Ok(sheet.markup(&map, Some(&compared)))
}

/// The scene's skin map, built off the async threads.
async fn skin_map(scene_name: &str) -> PageResult<SkinMap> {
    let name = scene_name.to_owned();
    tokio::task::spawn_blocking(move || Ok(SkinMap::of(&load_scene(&name)?)?))
        .await
        .map_err(|e| AppError::Internal(format!("the skin map: {e}")))?
}

fn load_scene(name: &str) -> PageResult<Scene> {
    Scene::load(name, BuildOptions::default())
        .map_err(|e| AppError::Internal(format!("the scene {name}: {e}")))
}

/// One column of the comparison: a name, the field and its pictures (PNG).
struct Compared {
    name: String,
    report: FieldReport,
    pictures_png: Vec<Vec<u8>>,
}

/// Lays each candidate on the skin, cuts it and the expert's line, and measures their fields.
fn compare_blocking(
    scene_name: &str,
    expert: CandidateIncision,
    drawn: &[Drawn],
    retract_mm: Option<f64>,
) -> PageResult<(SkinMap, Vec<Compared>)> {
    let scene = load_scene(scene_name)?;
    let map = SkinMap::of(&scene)?;
    let camera = map
        .camera(&scene.spec, PICTURE_PX)
        .ok_or_else(|| AppError::BadRequest(format!("the scene {scene_name} has no viewpoint")))?;
    let mut named = vec![("Expert's plan".to_owned(), expert)];
    for d in drawn {
        named.push((format!("Candidate {}", d.letter), on_skin(&map, d)?));
    }
    let opening = Opening {
        open_s: OPEN_S,
        retract_m: retract_mm.map(|w| w * 1e-3),
    };
    let mut out = Vec::new();
    for (name, candidate) in named {
        let (report, pictures) =
            planning::field_pictured(&scene, &candidate, opening, Some(&camera))
                .map_err(|e| AppError::BadRequest(format!("{name}: {e}")))?;
        let pictures_png = pictures.iter().map(|p| p.png()).collect::<Result<_, _>>()?;
        out.push(Compared {
            name,
            report,
            pictures_png,
        });
    }
    Ok((map, out))
}

/// The candidate's line laid on the skin, or what is off the tissue.
fn on_skin(map: &SkinMap, d: &Drawn) -> PageResult<CandidateIncision> {
    let point = |end: &str, [x, y]: [f64; 2]| {
        map.point(x * 1e-3, y * 1e-3).ok_or_else(|| {
            AppError::BadRequest(format!(
                "Candidate {}: its {end} (x {x} mm, y {y} mm) is off the tissue.",
                d.letter
            ))
        })
    };
    let candidate = CandidateIncision {
        incision_m: vec![point("start", d.from_mm)?, point("end", d.to_mm)?],
        depth_m: d.depth_mm * 1e-3,
    };
    candidate
        .check()
        .map_err(|e| AppError::BadRequest(format!("Candidate {}: {e}", d.letter)))?;
    Ok(candidate)
}

/// The form's field `key` as mm, or none when it is empty.
fn mm(form: &HashMap<String, String>, key: &str, what: &str) -> PageResult<Option<f64>> {
    let text = form.get(key).map_or("", |s| s.trim());
    if text.is_empty() {
        return Ok(None);
    }
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v.abs() < 1e4 => Ok(Some(v)),
        _ => Err(AppError::BadRequest(format!(
            "{what}: {text:?} is not a length in mm."
        ))),
    }
}

/// The form's field names of a candidate and how the page labels them.
fn fields(letter: char) -> [(String, String); 5] {
    let l = letter.to_ascii_lowercase();
    [
        ("from_x", "start x"),
        ("from_y", "start y"),
        ("to_x", "end x"),
        ("to_y", "end y"),
        ("depth", "depth"),
    ]
    .map(|(k, label)| (format!("{l}_{k}"), label.to_owned()))
}

/// The candidates the form gives: each either whole or left empty.
fn drawn_candidates(form: &HashMap<String, String>) -> PageResult<Vec<Drawn>> {
    let mut out = Vec::new();
    for letter in LETTERS {
        let mut v = [None; 5];
        for (slot, (key, label)) in v.iter_mut().zip(fields(letter)) {
            *slot = mm(form, &key, &format!("Candidate {letter}, {label}"))?;
        }
        match v {
            [None, None, None, None, None] => {}
            [Some(x0), Some(y0), Some(x1), Some(y1), Some(depth_mm)] => out.push(Drawn {
                letter,
                from_mm: [x0, y0],
                to_mm: [x1, y1],
                depth_mm,
            }),
            _ => {
                return Err(AppError::BadRequest(format!(
                    "Candidate {letter}: give its start, its end and its depth (mm), or none of them."
                )));
            }
        }
    }
    if out.is_empty() {
        return Err(AppError::BadRequest(
            "Draw or type at least one candidate.".into(),
        ));
    }
    Ok(out)
}

/// The retractor's width, mm (none: the wound as its tension opens it).
fn retractor_mm(form: &HashMap<String, String>) -> PageResult<Option<f64>> {
    let w = mm(form, "retract_mm", "The retractor's width")?;
    match w {
        Some(w) if !(0.0..=200.0).contains(&w) => Err(AppError::BadRequest(format!(
            "The retractor's width: from 0 to 200 mm, got {w}."
        ))),
        Some(0.0) => Ok(None),
        _ => Ok(w),
    }
}

/// What the page shows besides a comparison: the exercise, its plan, the form as sent.
struct Sheet<'a> {
    user: &'a CurrentUser,
    id: i64,
    name: &'a str,
    plan: &'a FieldPlan,
    form: &'a HashMap<String, String>,
    retract_mm: Option<f64>,
}

impl Sheet<'_> {
    /// The page: the skin map with its drawing, the candidates' fields, and the comparison.
    fn markup(&self, map: &SkinMap, compared: Option<&[Compared]>) -> Markup {
        page(
            &format!("Planning: {}", self.name),
            Some(self.user),
            html! {
                p { "Draw candidate incisions on the skin (drag on the map, or type the ends in mm) and compare what each exposes: each is cut in the simulation at its depth, the wound opens under the tissue's tension"
                    @if self.retract_mm.is_some() { " and a retractor spreads it" }
                    ", and the field is measured from the exercise's viewpoint, beside the expert's plan." }
                p { a href=(format!("/exercises/{}", self.id)) { "Back to the exercise" } }
                div class="planning" {
                    (super::planning_map::map_svg(self.plan, map))
                    (self.candidate_form())
                }
                @if let Some(compared) = compared {
                    (comparison(compared, self.retract_mm.is_some()))
                }
                script src="/static/planning.js" {}
            },
        )
    }

    fn candidate_form(&self) -> Markup {
        let value = |key: &str| self.form.get(key).cloned().unwrap_or_default();
        let retract = self
            .form
            .get("retract_mm")
            .cloned()
            .unwrap_or_else(|| self.retract_mm.map_or(String::new(), |w| num(Some(w), 1)));
        let depth_mm = num(Some(self.plan.depth_m * 1e3), 1);
        html! {
            form id="planning-form" method="post" action=(format!("/exercises/{}/planning", self.id)) data-depth=(depth_mm) {
                input type="hidden" name="csrf" value=(self.user.csrf());
                table class="candidates" {
                    thead { tr { th { "Draw" } th { "" } th { "start x" } th { "start y" } th { "end x" } th { "end y" } th { "depth" } } }
                    tbody {
                        @for (i, letter) in LETTERS.iter().enumerate() {
                            tr {
                                td { input type="radio" name="drawing" value=(letter) checked[i == 0] aria-label=(format!("Draw candidate {letter}")); }
                                th scope="row" { (letter) }
                                @for (key, label) in fields(*letter) {
                                    td { input type="number" step="0.5" size="6" id=(key) name=(key) value=(value(&key)) aria-label=(format!("Candidate {letter}, {label} (mm)")); }
                                }
                            }
                        }
                    }
                }
                p class="muted" { "mm on the skin map: x to the right of the map, y up it. The depth is below the skin (the expert cuts " (depth_mm) " mm). Leave a row empty to leave it out." }
                p {
                    label for="retract_mm" { "Retractor width (mm, empty: none)" } " "
                    input type="number" step="1" min="0" max="200" size="6" id="retract_mm" name="retract_mm" value=(retract);
                }
                button type="submit" id="compare" { "Compare the fields" }
            }
        }
    }
}

fn png_uri(png: &[u8]) -> String {
    format!(
        "data:image/png;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(png)
    )
}

/// What the exercise scores: the retracted field when it has a retractor.
fn scored(report: &FieldReport) -> &View {
    report.retracted.as_ref().unwrap_or(&report.unretracted)
}

/// The columns side by side, and which candidate exposes the most per mm without damage.
fn comparison(compared: &[Compared], retracted: bool) -> Markup {
    let expert_m2 = compared
        .first()
        .map(|c| scored(&c.report).target_visible_area_m2);
    let best = compared
        .iter()
        .skip(1)
        .filter(|c| c.report.damaged.is_empty() && scored(&c.report).target_visible_area_m2 > 0.0)
        .max_by(|a, b| efficiency(&a.report).total_cmp(&efficiency(&b.report)));
    html! {
        h2 { "The fields compared" }
        p id="planning-best" {
            @match best {
                Some(b) => { (b.name) " exposes the most of the target for each mm of incision, without damage." }
                None => { "No candidate exposes the target without damage." }
            }
        }
        div class="compared" {
            @for c in compared {
                (column(c, expert_m2, retracted))
            }
        }
    }
}

/// Target seen per mm of incision, mm.
fn efficiency(r: &FieldReport) -> f64 {
    scored(r).target_visible_area_m2 / r.incision_length_m.max(1e-6) * 1e3
}

fn column(c: &Compared, expert_m2: Option<f64>, retracted: bool) -> Markup {
    let v = scored(&c.report);
    let of_expert = expert_m2
        .filter(|&e| e > 0.0)
        .map(|e| 100.0 * v.target_visible_area_m2 / e);
    let slug = c.name.to_lowercase().replace([' ', '\''], "-");
    html! {
        section class="field-column" id=(format!("field-{slug}")) {
            h3 { (c.name) }
            @for (k, png) in c.pictures_png.iter().enumerate() {
                figure {
                    img src=(png_uri(png)) width="360" height="360" alt=(format!("{}: the field from the viewpoint{}", c.name, if k == 1 { ", retracted" } else { "" }));
                    figcaption { @if k == 0 { "Opened by the tissue's tension" } @else { "Retracted" } }
                }
            }
            dl {
                dt { "Target seen" @if retracted { " (retracted)" } }
                dd class="seen" { (num(Some(v.target_visible_area_m2 * 1e6), 0)) " mm²" @if let Some(p) = of_expert { " · " (num(Some(p), 0)) " % of the expert's" } }
                dt { "Working width" } dd { (num(Some(v.working_width_m * 1e3), 1)) " mm" }
                dt { "Incision length" } dd { (num(Some(c.report.incision_length_m * 1e3), 1)) " mm" }
                dt { "Approach angle" } dd { (num(v.approach_angle_deg, 0)) "°" }
                dt { "Damaged" }
                dd class="damaged" {
                    @if c.report.damaged.is_empty() { "nothing" } @else { strong { (c.report.damaged.join(", ")) } }
                }
            }
        }
    }
}
