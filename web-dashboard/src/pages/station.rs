//! `/station`: the trainee station. A trainee picks an exercise and a mode, presses Start, sees
//! the tissue (WebGL2, our `static/station.js`) and cuts it with the pointer or a pen; the
//! attempt is scored the moment the session ends and the page shows the debrief. The same
//! page, read-only, is the instructors' live view of a running session (`/supervision` links
//! to it).
//!
//! One WebSocket per viewer (`/station/{attempt}/ws`): binary frames from the server
//! ([`cutlab_station::protocol`]), pointer samples and Stop from the trainee's page (anything
//! else, or longer than the limit, is dropped and counted; the connection stays). A page that
//! goes away (a reload, a lost network) does not end the attempt: the page connects again
//! and drives on; only Stop, the time limit, or no page for the station's absence
//! (`StationSettings::absence_s`) ends it. The upgrade checks the session
//! cookie like every route, and the `Origin` against the `Host`, so another site's page cannot
//! open it with the user's cookie.

use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::State;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::http::HeaderMap;
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::{get, post};
use cutlab_assessor::store::{Exercise, Role};
use cutlab_haptics::device::DeviceSpec;
use cutlab_station::protocol::{self, ClientMessage};
use cutlab_station::{Ending, Running, StartRequest, StationError};
use maud::{Markup, html};
use serde::Deserialize;

use super::layout::page;
use crate::AppState;
use crate::access::visible_attempt;
use crate::auth::{CurrentUser, sessions};
use crate::error::{AppError, PageResult};
use crate::extract::{Form, Id};

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/station", get(choose))
        .route("/station/start", post(start))
        .route("/station/{id}", get(station))
        .route("/station/{id}/ws", get(socket))
        .route(
            "/static/station.js",
            get(|| async {
                super::static_file("text/javascript", include_str!("static/station.js"))
            }),
        )
}

fn station_error(e: StationError) -> AppError {
    match e {
        StationError::Busy(m) => AppError::Conflict(m),
        StationError::NoSuchDevice(m) => AppError::BadRequest(m),
        StationError::Locked(m) => AppError::Locked(m),
        StationError::Assess(cutlab_assessor::AssessError::NotFound(_)) => {
            AppError::BadRequest("no such exercise".into())
        }
        other => AppError::Internal(other.to_string()),
    }
}

/// `/station`: the exercises, the mode, Start.
async fn choose(State(state): State<AppState>, user: CurrentUser) -> PageResult<Markup> {
    let exercises = picker_exercises(&state, &user).await?;
    let devices = &state.station_settings().devices;
    let running = state
        .station()
        .running()
        .into_iter()
        .find(|r| r.trainee == user.user().name);
    Ok(page(
        "Station",
        Some(&user),
        html! {
            @if let Some(r) = running {
                p { "Your session of " (r.exercise) " is running: "
                    a href=(format!("/station/{}", r.attempt)) { "back to it" } "." }
            }
            form class="station-start" method="post" action="/station/start" {
                input type="hidden" name="csrf" value=(user.csrf());
                p {
                    label for="exercise" { "Exercise" } " "
                    select id="exercise" name="exercise" {
                        @for (i, (e, locked)) in exercises.iter().enumerate() {
                            option value=(e.name) selected[i == 0] disabled[locked.is_some()] {
                                (e.name) @if locked.is_some() { " (locked)" } @else if i == 0 { " (next)" }
                            }
                        }
                    }
                }
                @for (e, locked) in &exercises {
                    p class="muted brief" {
                        strong { (e.name) ": " } (e.description)
                        @if e.exam_only { " " em class="exam-only" { "(exam only: the plan is never shown)" } }
                        @if let Some(why) = locked { " " em class="locked" { "(" (why) ")" } }
                    }
                }
                fieldset {
                    legend { "Mode" }
                    label { input type="radio" name="mode" value="guided" checked; " guided: the planned incision, its entry and exit and the depth shown on the tissue" }
                    br;
                    label { input type="radio" name="mode" value="exam"; " exam: nothing shown" }
                }
                p {
                    label for="device" { "Device" } " "
                    select id="device" name="device" {
                        option value=(cutlab_station::POINTER) selected { "this page's pointer or pen" }
                        @for d in devices {
                            option value=(d.to_string()) { (device_label(d)) }
                        }
                    }
                }
                p {
                    label { input type="checkbox" id="second-hand" name="second_hand" value="on"; " Second hand: a grasper on touch (with this page's pointer or pen): touch the tissue to close its jaws there, drag to draw the tissue, lift to let go" }
                }
                p class="muted" { "With the pointer: move it over the tissue; hold the button to engage the blade; the wheel (or pen pressure, or the ↑/↓ keys) sets the depth. With another device this page is its view. The session ends at Stop, at the time limit, or when you lift the blade out after cutting." }
                button id="start" type="submit" { "Start" }
            }
        },
    ))
}

/// The exercises the picker offers `user`: the next in their curriculum first, then the
/// others open to them, then the locked ones, each with why it is locked.
async fn picker_exercises(
    state: &AppState,
    user: &CurrentUser,
) -> Result<Vec<(Exercise, Option<String>)>, AppError> {
    let store = state.store();
    let exercises = store.list_exercises().await?;
    if user.role() != Role::Trainee {
        return Ok(exercises.into_iter().map(|e| (e, None)).collect());
    }
    let next = store.next_exercise(user.id()).await?;
    let mut out = Vec::with_capacity(exercises.len());
    for e in exercises {
        let locked = store
            .exercise_access(user.id(), e.id)
            .await?
            .locked_message(&e.name);
        out.push((e, locked));
    }
    out.sort_by_key(|(e, locked)| (Some(e.id) != next, locked.is_some()));
    Ok(out)
}

/// How the picker names a station's device.
fn device_label(d: &DeviceSpec) -> String {
    match d {
        DeviceSpec::Trainee { name, .. } => format!("a synthetic trainee ({name}) cuts, you watch"),
        DeviceSpec::PointerHand(kind) => {
            format!(
                "a {} person's hand model on the pointer cuts, you watch",
                kind.as_str()
            )
        }
        DeviceSpec::StylusHand(kind) => {
            format!(
                "a {} person's hand model on a stylus cuts, you watch",
                kind.as_str()
            )
        }
        DeviceSpec::Csv(path) => format!("the trajectory {}", path.display()),
        DeviceSpec::Recording(path) => format!("the hand recorded in {}", path.display()),
        DeviceSpec::Igtl(port) => {
            format!("the OpenIGTLink tracker or haptic device on port {port}")
        }
    }
}

#[derive(Debug, Deserialize)]
struct StartForm {
    exercise: String,
    mode: String,
    /// `pointer` (the default) or one of the station's devices as it prints.
    #[serde(default)]
    device: Option<String>,
    /// Present (`on`) for a second hand: a grasper on the page's touch.
    #[serde(default)]
    second_hand: Option<String>,
}

/// `POST /station/start`: starts the session, then to its page.
async fn start(
    State(state): State<AppState>,
    user: CurrentUser,
    Form(form): Form<StartForm>,
) -> Result<Response, AppError> {
    let guided = match form.mode.as_str() {
        "guided" => true,
        "exam" => false,
        other => return Err(AppError::BadRequest(format!("unknown mode {other:?}"))),
    };
    let trainee = user.user().name.clone();
    state
        .station()
        .check_room(&trainee)
        .map_err(station_error)?;
    let settings = state.station_settings().clone();
    let input = settings
        .input_named(form.device.as_deref().unwrap_or(cutlab_station::POINTER))
        .map_err(station_error)?;
    let request = StartRequest {
        exercise: form.exercise,
        trainee,
        guided,
        second_hand: form.second_hand.is_some(),
    };
    let running = cutlab_station::run::start(state.store().clone(), &settings, request, input)
        .await
        .map_err(station_error)?;
    let running = state.station().insert(running).map_err(station_error)?;
    Ok(Redirect::to(&format!("/station/{}", running.attempt)).into_response())
}

/// What the page's script needs, in the canvas's `data-config`.
fn config_json(r: &Running, driver: bool) -> String {
    // the plan as recorded (its serde form), shown in guided mode only
    let plan = r.guided.then_some(&r.plan);
    let viewpoint = r.viewpoint.as_ref().map(|v| {
        serde_json::json!({
            "eye_m": v.eye_mm.map(|c| c * 1e-3),
            "look_at_m": v.look_at_mm.map(|c| c * 1e-3),
        })
    });
    serde_json::json!({
        "attempt": r.attempt,
        "driver": driver,
        // the page's pointer drives the session (else another device does, the page views)
        "pointer": r.pointer.is_some(),
        // the page's touch drives a second hand's grasper
        "grasper": r.grasper.is_some(),
        // the trainee may set a wound retractor (a scene with something behind the tissue
        // to expose: a field exercise)
        "retractor": r.pointer.is_some() && !r.targets.is_empty(),
        "exercise": r.exercise,
        "trainee": r.trainee,
        "guided": r.guided,
        "force_limit_n": r.force_limit_newtons,
        "plan": plan,
        // lines marked on the tissue (a pattern's circle), in exam mode too
        "marks": r.marks.iter().map(|m| m.iter().map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>()).collect::<Vec<_>>(),
        // the colour of each region of the tissue the scene gives one: [region, r, g, b]
        "region_colours": r.region_colours.iter().map(|(id, c)| [f64::from(*id), c[0], c[1], c[2]]).collect::<Vec<_>>(),
        // the name of each region the scene names: [region, name] (the HUD's layer)
        "region_names": r.region_names.iter().map(|(id, name)| serde_json::json!([id, name])).collect::<Vec<_>>(),
        // the depth the blade starts at, in exam mode too (the depth is part of the task
        // the page states; the line is not shown)
        "start_depth_m": r.plan.depth_m,
        // the deepest the pointer's depth goes: the scene's blade (the thorax's reaches
        // through a 40 mm wall)
        "max_depth_m": r.blade_length_m,
        // how long the session waits for a page that lost its connection
        "absence_s": r.control.absence().as_secs_f64(),
        "viewpoint": viewpoint,
        // what lies behind the tissue (the heart): ellipsoids, drawn where an opening shows them
        "targets": r.targets.iter().map(|t| serde_json::json!({
            "name": t.name,
            "centre_m": t.centre_mm.map(|c| c * 1e-3),
            "radii_m": t.radii_mm.map(|c| c * 1e-3),
            "spare": t.spare,
        })).collect::<Vec<_>>(),
        "up": r.plan.normals.first().map(|n| [n.x, n.y, n.z]),
        "ws": format!("/station/{}/ws", r.attempt),
    })
    .to_string()
}

/// `/station/{attempt}`: the trainee's station, or an instructor's live view; once the session
/// ended, its attempt.
async fn station(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
) -> Result<Response, AppError> {
    visible_attempt(&state, &user, id).await?;
    let Some(r) = state.station().get(id) else {
        return Ok(Redirect::to(&format!("/attempts/{id}")).into_response());
    };
    let driver = r.trainee == user.user().name;
    // the written task: the exercise's description (in exam mode all the page says of it)
    let mut description = match state.store().exercise_by_name(&r.exercise).await {
        Ok(e) => e.description,
        Err(_) => r.exercise.clone(),
    };
    // a sentence, before the exam's note follows it
    if !description.trim_end().ends_with(['.', '!', '?']) {
        description = format!("{}.", description.trim_end());
    }
    let title = if driver {
        format!("Station: {}", r.exercise)
    } else {
        format!("Live: {} at {}", r.trainee, r.exercise)
    };
    Ok(page(
        &title,
        Some(&user),
        html! {
            p id="task" class="brief" {
                strong { "Task: " } (description)
                @if !r.guided { " " span class="muted" { "Exam: the plan is not shown. The white ticks on the tissue's edges are 10 mm apart (long ones every 50 mm and at the middle)." } }
            }
            div class="station" {
                canvas id="tissue" width="960" height="600" data-config=(config_json(&r, driver)) {}
                div class="hud" {
                    div { "Force " span id="force-value" { "0.00 N" } " (limit " (format!("{:.1}", r.force_limit_newtons)) " N)" }
                    div class="force-bar" { div id="force-bar" {} }
                    div id="force-warning" class="fail" hidden { "Too much force: over the limit the score uses" }
                    div { "Time " span id="elapsed" { "0.0 s" } }
                    div { "Blade " span id="blade" { "free" } }
                    div { "Blade depth " span id="blade-depth" { "–" } " (planned " (format!("{:.1}", r.plan.depth_m * 1e3)) " mm)" }
                    div { "Set depth " span id="depth" { "–" } }
                    @if !r.region_names.is_empty() { div { "Layer " span id="blade-layer" { "–" } } }
                    @if r.grasper.is_some() { div { "Grasper " span id="grasper" { "open" } } }
                    canvas id="depth-gauge" width="120" height="150" title="The cut from the side: the surface at the top, the planned depth dashed green, the set depth dotted grey, the blade red below the surface" {}
                    @if driver && r.pointer.is_some() { div class="muted" { (format!("Wheel down or ↓: deeper; wheel up or ↑: shallower ({:.1} mm a step, to {:.0} mm).", (r.blade_length_m / 40.0).max(0.0005) * 1e3, r.blade_length_m * 1e3)) } }
                    div class="scale" { span id="scale-bar" {} " 10 mm" }
                    canvas id="axes" width="64" height="64" title="The world's axes as this view shows them: x red, y green, z blue (the frame of the recording and the replay)" {}
                    div { "Mode " span id="mode" { (if r.guided { "guided" } else { "exam" }) } }
                    @if driver && r.pointer.is_some() && !r.targets.is_empty() {
                        button id="retract" type="button" aria-pressed="false" title="A soft-tissue retractor set into your incision spreads it 20 mm, as for a mini-thoracotomy" { "Set the retractor (R)" }
                    }
                    @if driver { button id="stop" type="button" { "Stop" } }
                    @else { p class="muted" { "Live view (read only)." } }
                    div id="status" class="muted" {}
                }
            }
            div id="debrief" {}
            script src="/static/station.js" {}
        },
    )
    .into_response())
}

/// Whether the request's `Origin` is this server (the `Host` it was sent to).
fn same_origin(headers: &HeaderMap) -> bool {
    let header = |name| headers.get(name).and_then(|v| v.to_str().ok());
    let (Some(origin), Some(host)) = (header("origin"), header("host")) else {
        return false;
    };
    origin
        .strip_prefix("http://")
        .or_else(|| origin.strip_prefix("https://"))
        .is_some_and(|o| o == host)
}

/// `/station/{attempt}/ws`: the session's frames; the trainee's pointer samples and Stop.
async fn socket(
    State(state): State<AppState>,
    user: CurrentUser,
    headers: HeaderMap,
    Id(id): Id,
    upgrade: WebSocketUpgrade,
) -> Result<Response, AppError> {
    if !same_origin(&headers) {
        return Err(AppError::Forbidden(
            "the station's socket is opened by its own page only",
        ));
    }
    visible_attempt(&state, &user, id).await?;
    let r = state.station().get(id).ok_or(AppError::NotFound)?;
    let driver = r.trainee == user.user().name;
    let session = user.0.token_hash.clone();
    Ok(upgrade
        .max_message_size(protocol::MAX_WIRE_MESSAGE_BYTES)
        .max_frame_size(protocol::MAX_WIRE_MESSAGE_BYTES)
        .on_upgrade(move |ws| async move {
            serve(ws, r, driver, sessions::ended(&state, &session)).await;
        }))
}

/// How often the server looks for a new frame when none was announced (the end of a session
/// is announced on its own channel).
const IDLE: Duration = Duration::from_millis(250);

/// Serves one viewer's socket until the session ends, the page goes away or `logged_out`
/// completes (then as a page that went away: the blade pauses for its absence).
async fn serve(ws: WebSocket, r: Arc<Running>, driver: bool, logged_out: impl Future<Output = ()>) {
    if driver {
        r.control.attach();
    }
    let (mut tx, mut rx) = futures_util::StreamExt::split(ws);
    let mut feed = r.feed.clone();
    let mut ending = r.ending.clone();
    let sender = async {
        use futures_util::SinkExt;
        let (mut topology, mut rest_sent) = (None, false);
        loop {
            let state = feed.borrow_and_update().clone();
            if let Some(rest) = state.rest.as_ref().filter(|_| !rest_sent) {
                let bytes = protocol::encode_rest(rest);
                if tx.send(Message::Binary(bytes.into())).await.is_err() {
                    return;
                }
                rest_sent = true;
            }
            if let Some(frame) = &state.frame {
                if !topology
                    .as_ref()
                    .is_some_and(|t| Arc::ptr_eq(t, &state.topology))
                {
                    let bytes = protocol::encode_topology(&state.topology);
                    if tx.send(Message::Binary(bytes.into())).await.is_err() {
                        return;
                    }
                    topology = Some(state.topology.clone());
                }
                let bytes = protocol::encode_frame(frame);
                if tx.send(Message::Binary(bytes.into())).await.is_err() {
                    return;
                }
            }
            tokio::select! {
                changed = feed.changed() => if changed.is_err() { break },
                _ = ending.wait_for(Option::is_some) => break,
                _ = tokio::time::sleep(IDLE) => {}
            }
        }
        // the session ended: say how, then close
        let done =
            tokio::time::timeout(Duration::from_secs(120), ending.wait_for(Option::is_some)).await;
        let text = match done.ok().and_then(Result::ok).and_then(|e| e.clone()) {
            Some(Ending::Scored {
                attempt,
                score,
                passed,
            }) => serde_json::json!({
                "type": "ended", "attempt": attempt, "scored": true, "score": score, "passed": passed,
            }),
            Some(Ending::Incomplete { attempt, why }) => serde_json::json!({
                "type": "ended", "attempt": attempt, "scored": false, "why": why,
            }),
            None => {
                serde_json::json!({ "type": "ended", "attempt": r.attempt, "scored": false, "why": "no answer from the session" })
            }
        };
        let _ = tx.send(Message::Text(text.to_string().into())).await;
        let _ = tx.close().await;
    };
    let receiver = async {
        let mut dropped = 0u64;
        while let Some(Ok(msg)) = futures_util::StreamExt::next(&mut rx).await {
            let Message::Text(text) = msg else {
                if matches!(msg, Message::Close(_)) {
                    break;
                }
                if !matches!(msg, Message::Ping(_) | Message::Pong(_)) {
                    dropped += 1;
                }
                continue;
            };
            if !driver {
                dropped += 1;
                continue;
            }
            match protocol::decode_client(text.as_str()) {
                Ok(ClientMessage::Pointer(sample)) => {
                    if let Some(p) = &r.pointer
                        && p.push(sample).is_err()
                    {
                        dropped += 1;
                    }
                }
                Ok(ClientMessage::Grasper(sample)) => {
                    // a session without a second hand has no grasper to take it
                    if r.grasper.as_ref().is_none_or(|g| g.push(sample).is_err()) {
                        dropped += 1;
                    }
                }
                Ok(ClientMessage::Stop {}) => r.control.stop(),
                Err(_) => dropped += 1,
            }
        }
        dropped
    };
    tokio::pin!(sender);
    tokio::pin!(receiver);
    let (dropped, went_away) = tokio::select! {
        // the session ended; what the page still sends does not matter
        () = &mut sender => (0, false),
        dropped = &mut receiver => (dropped, true),
        () = logged_out => (0, true),
    };
    // the trainee's last page went away: the session waits for one (the blade pauses) and
    // ends only if none comes back within the absence allowed
    if driver && r.control.leave() && went_away && r.ending.borrow().is_none() {
        tracing::warn!(
            "station attempt {}: the trainee's page went away; waiting {:.0} s for it",
            r.attempt,
            r.control.absence().as_secs_f64()
        );
    }
    if dropped > 0 {
        tracing::info!(
            "station attempt {}: {dropped} messages from a page dropped (malformed, oversized or refused)",
            r.attempt
        );
    }
}
