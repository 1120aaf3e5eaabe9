//! `cutlab bench station`: the trainee station as a person meets it. For each size of the
//! chest wall, the dashboard in this process, a trainee's station page in headless Chromium
//! (WebGL2 on SwiftShader), and three sessions:
//!
//! 1. the page's pointer drives a scripted stroke along the planned incision, button held:
//!    frames drawn per second in the browser (`fps`; the page draws only when a new frame
//!    came, so `updates_per_s` is the same), the page's script per frame
//!    (`page_ms_per_frame`), the latency from a pointer sample to the frame that shows it
//!    (`latency_p50_ms`, `latency_p95_ms`: stamps the page sends and the server echoes;
//!    it includes the pointer device's fixed 30 ms delay, subtracted in
//!    `tick_to_frame_p95_ms`), bytes per second to the viewer;
//! 2. the station's synthetic expert cuts while the page watches, and
//! 3. the same without a page: the servo period's p99 deviation of each (streaming must not
//!    disturb the servo).
//!
//! Goals (issue 29): fps >= 60 at 12.8k tets and >= 30 at 100k, latency p95 <= 50 ms.

use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, bail};
use cutlab_assessor::store::{BUILTIN_EXERCISE, Store};
use cutlab_dashboard::{AppState, Config};
use cutlab_haptics::device::PointerOptions;
use cutlab_sim::stats::percentile;
use cutlab_station::{Ending, Running, SessionFigures, StartRequest, StationSettings};
use fantoccini::actions::{InputSource, MOUSE_BUTTON_LEFT, MouseActions, PointerAction};
use fantoccini::{Client, Locator};
use serde::Serialize;

use crate::browser;

/// What `cutlab bench station` runs.
#[derive(Debug)]
pub struct Options {
    /// Sizes of the chest wall, tets (at least).
    pub tets: Vec<usize>,
    /// Length of each measured session, s.
    pub duration_s: f64,
    /// The simulation step.
    pub time_step: cutlab_haptics::TimeStep,
    pub json: bool,
}

/// The figures of one size.
#[derive(Debug, Serialize)]
struct SizeFigures {
    tets_requested: usize,
    tets: usize,
    /// The simulation step, ms.
    time_step_ms: f64,
    surface_vertices: u64,
    fps: f64,
    updates_per_s: f64,
    /// The page's script per frame drawn (decoding, normals, WebGL calls), ms.
    page_ms_per_frame: f64,
    /// The browser's animation frames per second (what it could draw at most).
    animation_frames_per_s: f64,
    /// Frames the server sent per second (latest wins: it skips what the page cannot take).
    messages_per_s: f64,
    /// Simulation steps per wall-clock second of the pointer session.
    sim_steps_per_s: f64,
    latency_p50_ms: Option<f64>,
    latency_p95_ms: Option<f64>,
    tick_to_frame_p95_ms: Option<f64>,
    bytes_per_s: f64,
    /// The session's simulated seconds per wall-clock second (pointer session).
    speed: f64,
    servo_p99_deviation_us_pointer: f64,
    servo_p99_deviation_us_with_viewer: f64,
    servo_p99_deviation_us_without_viewer: f64,
}

pub fn run(o: &Options) -> anyhow::Result<()> {
    let missing = browser::missing();
    if !missing.is_empty() {
        bail!("bench station needs {missing:?} (apt-get install chromium chromium-driver)");
    }
    anyhow::ensure!(
        o.duration_s >= 2.0 && o.duration_s <= 600.0,
        "--duration must be between 2 and 600 s"
    );
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let driver = browser::chromedriver()?;
    let mut all = Vec::new();
    for &tets in &o.tets {
        if !o.json {
            eprintln!("station at {tets} tets ...");
        }
        let f = rt.block_on(size(tets, o, &driver))?;
        if !o.json {
            print_size(&f);
        }
        all.push(f);
    }
    if o.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({ "sizes": all }))?
        );
    }
    Ok(())
}

fn print_size(f: &SizeFigures) {
    let ms = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.1}"));
    println!(
        "{} tets ({} surface vertices, {} ms steps): {:.1} fps drawn ({:.2} ms of script each; {:.0} animation frames/s, {:.0} frames sent/s, {:.0} simulation steps/s), latency p50 {} ms p95 {} ms (tick to frame p95 {} ms), {:.0} kB/s, speed {:.2}x",
        f.tets,
        f.surface_vertices,
        f.time_step_ms,
        f.fps,
        f.page_ms_per_frame,
        f.animation_frames_per_s,
        f.messages_per_s,
        f.sim_steps_per_s,
        ms(f.latency_p50_ms),
        ms(f.latency_p95_ms),
        ms(f.tick_to_frame_p95_ms),
        f.bytes_per_s / 1e3,
        f.speed
    );
    println!(
        "  servo period p99 deviation: {:.1} us (pointer), {:.1} us (expert, page watching), {:.1} us (expert, no page)",
        f.servo_p99_deviation_us_pointer,
        f.servo_p99_deviation_us_with_viewer,
        f.servo_p99_deviation_us_without_viewer
    );
}

async fn size(tets: usize, o: &Options, driver: &browser::Driver) -> anyhow::Result<SizeFigures> {
    let duration_s = o.duration_s;
    let dir = tempfile::tempdir()?;
    let store = Store::open(&dir.path().join("cutlab.db")).await?;
    cutlab_dashboard::seed_demo_accounts(&store).await?;
    let settings = StationSettings {
        min_tets: Some(tets),
        time_step: o.time_step,
        devices: vec!["expert".parse().map_err(anyhow::Error::msg)?],
        duration_s: 600.0,
        ..StationSettings::new(dir.path().join("station-attempts"))
    };
    let state = AppState::new(
        store.clone(),
        Config {
            station: settings.clone(),
            ..Config::default()
        },
    )?;
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
    let base = format!("http://{}", listener.local_addr()?);
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(cutlab_dashboard::serve(
        listener,
        state.clone(),
        async move {
            let _ = stopped.await;
        },
    ));
    let page = browser::chromium(driver, &dir.path().join("profile")).await?;
    let result = async {
        let link = cutlab_dashboard::auth::kiosk::issue(&state, "ana")
            .await
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        page.goto(&format!("{base}{link}")).await?;
        // 1. the pointer
        let (running, stroke) = pointer_session(&page, &base, &state, duration_s).await?;
        let pointer = figures_of(&running).await?;
        // 2. the expert, the page watching
        let watched = start_from_page(&page, &base, &state, "expert").await?;
        tokio::time::sleep(Duration::from_secs_f64(duration_s)).await;
        watched.control.stop();
        let with_viewer = figures_of(&watched).await?;
        // 3. the expert alone
        page.goto(&format!("{base}/")).await?;
        let alone = cutlab_station::run::start(
            store.clone(),
            &settings,
            request(),
            settings.input_named("expert")?,
        )
        .await?;
        tokio::time::sleep(Duration::from_secs_f64(duration_s)).await;
        alone.control.stop();
        let without_viewer = figures_of(&alone).await?;
        // the page's echo latencies, ranked as every figure here (`stats::percentile`)
        let mut latencies_ms: Vec<f64> = stroke["latencies_ms"]
            .as_array()
            .map(|l| l.iter().filter_map(serde_json::Value::as_f64).collect())
            .unwrap_or_default();
        latencies_ms.sort_by(f64::total_cmp);
        let latency = |p: f64| (!latencies_ms.is_empty()).then(|| percentile(&latencies_ms, p));
        let p95 = latency(0.95);
        anyhow::Ok(SizeFigures {
            tets_requested: tets,
            tets: pointer.tets,
            time_step_ms: pointer.time_step_s * 1e3,
            surface_vertices: stroke["vertices"].as_u64().unwrap_or(0),
            fps: stroke["fps"].as_f64().unwrap_or(0.0),
            updates_per_s: stroke["updates_per_s"].as_f64().unwrap_or(0.0),
            page_ms_per_frame: stroke["page_ms_per_frame"].as_f64().unwrap_or(0.0),
            animation_frames_per_s: stroke["animation_frames_per_s"].as_f64().unwrap_or(0.0),
            messages_per_s: stroke["messages_per_s"].as_f64().unwrap_or(0.0),
            sim_steps_per_s: pointer.sim_steps_per_s,
            latency_p50_ms: latency(0.5),
            latency_p95_ms: p95,
            // the station's pointer plays the page's samples this much behind them
            tick_to_frame_p95_ms: p95.map(|l| l - 1e3 * PointerOptions::default().delay_s),
            bytes_per_s: stroke["bytes_per_s"].as_f64().unwrap_or(0.0),
            speed: pointer.speed,
            servo_p99_deviation_us_pointer: pointer.servo.p99_deviation_us,
            servo_p99_deviation_us_with_viewer: with_viewer.servo.p99_deviation_us,
            servo_p99_deviation_us_without_viewer: without_viewer.servo.p99_deviation_us,
        })
    }
    .await;
    let _ = page.close().await;
    let _ = stop.send(());
    let _ = server.await;
    store.close().await;
    result
}

fn request() -> StartRequest {
    StartRequest {
        exercise: BUILTIN_EXERCISE.into(),
        trainee: "ana".into(),
        guided: true,
        second_hand: false,
    }
}

/// Starts the built-in exercise from the station page with `device`; the running session.
async fn start_from_page(
    page: &Client,
    base: &str,
    state: &AppState,
    device: &str,
) -> anyhow::Result<Arc<Running>> {
    page.goto(&format!("{base}/station")).await?;
    page.find(Locator::Css(&format!("option[value='{BUILTIN_EXERCISE}']")))
        .await?
        .click()
        .await?;
    page.find(Locator::Css(&format!("#device option[value='{device}']")))
        .await?
        .click()
        .await?;
    page.find(Locator::Css("input[value=guided]"))
        .await?
        .click()
        .await?;
    page.find(Locator::Id("start")).await?.click().await?;
    page.wait()
        .at_most(Duration::from_secs(600))
        .for_element(Locator::Id("tissue"))
        .await?;
    let path = page.current_url().await?.path().to_owned();
    let attempt: i64 = path
        .strip_prefix("/station/")
        .and_then(|id| id.parse().ok())
        .with_context(|| format!("not the station's page: {path}"))?;
    let running = state
        .station()
        .get(attempt)
        .with_context(|| format!("attempt {attempt} is not running"))?;
    until(
        page,
        "window.cutlabStation && window.cutlabStation.stats().frames > 5",
    )
    .await?;
    Ok(running)
}

/// The pointer's session: a stroke along the planned line over `duration_s`, then Stop; the
/// page's figures of the stroke.
async fn pointer_session(
    page: &Client,
    base: &str,
    state: &AppState,
    duration_s: f64,
) -> anyhow::Result<(Arc<Running>, serde_json::Value)> {
    let running = start_from_page(page, base, state, cutlab_station::POINTER).await?;
    let line = page
        .execute(
            "const s = window.cutlabStation; return s.config.plan.line_m.map(p => s.project(p))",
            vec![],
        )
        .await?;
    let line: Vec<(f64, f64)> = line
        .as_array()
        .context("the plan's points on the page")?
        .iter()
        .filter_map(|p| Some((p[0].as_f64()?, p[1].as_f64()?)))
        .collect();
    anyhow::ensure!(line.len() >= 2, "the plan is not on the page");
    let to = |&(x, y): &(f64, f64), ms: u64| PointerAction::MoveTo {
        duration: Some(Duration::from_millis(ms)),
        x: x.round(),
        y: y.round(),
    };
    let step_ms = (duration_s * 1e3 / (line.len() - 1) as f64) as u64;
    let mut stroke = MouseActions::new("mouse".into())
        .then(to(&line[0], 300))
        .pause(Duration::from_millis(300))
        .then(PointerAction::Down {
            button: MOUSE_BUTTON_LEFT,
        });
    for p in &line[1..] {
        stroke = stroke.then(to(p, step_ms));
    }
    page.execute("window.cutlabStation.reset()", vec![]).await?;
    page.perform_actions(stroke).await?;
    let figures = page
        .execute(
            "const s = window.cutlabStation.stats(); s.vertices = window.cutlabStation.vertices(); return s",
            vec![],
        )
        .await?;
    page.perform_actions(MouseActions::new("mouse".into()).then(PointerAction::Up {
        button: MOUSE_BUTTON_LEFT,
    }))
    .await?;
    page.find(Locator::Id("stop")).await?.click().await?;
    Ok((running, figures))
}

/// Waits until `script` (a JavaScript expression) is true in the page.
async fn until(page: &Client, script: &str) -> anyhow::Result<()> {
    let deadline = std::time::Instant::now() + Duration::from_secs(300);
    loop {
        if page
            .execute(&format!("return Boolean({script})"), vec![])
            .await?
            .as_bool()
            == Some(true)
        {
            return Ok(());
        }
        if std::time::Instant::now() > deadline {
            bail!("timed out waiting for {script}");
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// The session's figures once it ended.
async fn figures_of(running: &Running) -> anyhow::Result<SessionFigures> {
    let mut ending = running.ending.clone();
    let ended = tokio::time::timeout(Duration::from_secs(300), ending.wait_for(Option::is_some))
        .await
        .context("the session did not end")?
        .context("the session's thread went away")?
        .clone();
    if let Some(Ending::Incomplete { why, .. }) = ended {
        tracing::info!("attempt {}: {why}", running.attempt);
    }
    running.figures.get().cloned().with_context(|| {
        format!(
            "attempt {}: no figures (the session failed)",
            running.attempt
        )
    })
}
