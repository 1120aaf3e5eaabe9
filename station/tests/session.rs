//! A station session end to end on the server side: an exercise started through the station,
//! driven by a device, seen through the view feed, scored the moment it ends; the set's limits.

use std::sync::Arc;
use std::time::Duration;

use cutlab_assessor::store::{AttemptStatus, Role, Store};
use cutlab_haptics::device::{HapticDevice, Skill, SyntheticTrainee};
use cutlab_haptics::servo::Clock;
use cutlab_station::attempt::AttemptLock;
use cutlab_station::protocol::{self, KIND_FRAME, KIND_TOPOLOGY};
use cutlab_station::run::{self, DeviceFactory};
use cutlab_station::{Ending, Input, StartRequest, StationError, StationSet, StationSettings};

const EXERCISE: &str = cutlab_assessor::store::BUILTIN_EXERCISE;

/// A temporary folder, removed when the guard drops.
fn temp_dir(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("cutlab-station-{name}-"))
        .tempdir()
        .expect("temp dir")
}

async fn store(dir: &std::path::Path) -> Store {
    let store = Store::open(&dir.join("cutlab.db")).await.expect("store");
    store.ensure_builtins().await.expect("builtins");
    store
}

fn expert() -> DeviceFactory {
    Box::new(|plan| {
        let skill = Skill::preset("expert").expect("preset");
        let hand = SyntheticTrainee::new("expert", plan.clone(), skill, 3)?;
        Ok(Box::new(hand) as Box<dyn HapticDevice>)
    })
}

fn settings(dir: &std::path::Path, duration_s: f64) -> StationSettings {
    StationSettings {
        duration_s,
        clock: Clock::Virtual,
        rrd: false,
        ..StationSettings::new(dir)
    }
}

async fn ending(running: &cutlab_station::Running) -> Ending {
    let mut rx = running.ending.clone();
    let wait = rx.wait_for(Option::is_some);
    tokio::time::timeout(Duration::from_secs(300), wait)
        .await
        .expect("the session ends")
        .expect("the session thread reports")
        .clone()
        .expect("an ending")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_station_session_is_seen_while_it_runs_and_scored_when_it_ends() {
    let dir_guard = temp_dir("scored");
    let dir = dir_guard.path();
    let store = store(dir).await;
    // attempts a station process that died will have left `running` (whose files come
    // later, below)
    let zoe = store
        .create_user("zoe", Role::Trainee, None)
        .await
        .expect("zoe");
    let exercise = store.exercise_by_name(EXERCISE).await.expect("exercise");
    let mut orphans = [0; 4];
    let mut locks = Vec::new();
    for (id, name) in orphans
        .iter_mut()
        .zip(["whole", "cut-short", "writing", "starting"])
    {
        let file = dir.join(format!("{name}.mcap"));
        locks.push(AttemptLock::hold(&file).expect("the attempt's lock"));
        *id = store
            .start_attempt(zoe.id, exercise.id, file.to_str(), false)
            .await
            .expect("started")
            .id;
    }
    let request = StartRequest {
        exercise: EXERCISE.into(),
        trainee: "ana".into(),
        guided: true,
        second_hand: false,
    };
    // the station's own synthetic expert, picked by name as the page does
    let settings = StationSettings {
        devices: vec!["expert".parse().expect("a device")],
        ..settings(dir, 6.0)
    };
    assert!(matches!(
        settings.input_named("novice"),
        Err(StationError::NoSuchDevice(m)) if m.contains("pointer, expert")
    ));
    let input = settings
        .input_named("expert")
        .expect("the station's expert");
    assert!(matches!(input, Input::Spec(_)));
    let running = run::start(store.clone(), &settings, request, input)
        .await
        .expect("started");
    assert!(running.pointer.is_none());
    assert!(running.plan.line_m.len() >= 2);
    // the view: a topology, then frames whose positions match it
    let mut feed = running.feed.clone();
    let mut frames = 0;
    let mut cut_seen = false;
    let mut last_tick = None;
    let mut rest: Option<std::sync::Arc<cutlab_station::view::RestSurface>> = None;
    while let Ok(()) = feed.changed().await {
        let state = feed.borrow_and_update().clone();
        if state.ended {
            break;
        }
        let Some(frame) = state.frame else { continue };
        // the rest surface comes with the first frame and stays the session's first surface
        // (the cut changes the topology, not it)
        let now_rest = state.rest.clone().expect("a rest surface with every frame");
        let first = rest.get_or_insert_with(|| {
            assert_eq!(
                now_rest.positions_m.len(),
                3 * state.topology.vertex_count,
                "the rest surface is the first surface"
            );
            now_rest.clone()
        });
        assert!(std::sync::Arc::ptr_eq(first, &now_rest));
        assert_eq!(protocol::encode_rest(&now_rest)[0], protocol::KIND_REST);
        let topology = protocol::encode_topology(&state.topology);
        assert_eq!(topology[0], KIND_TOPOLOGY);
        assert_eq!(state.topology.regions.len(), state.topology.vertex_count);
        assert_eq!(frame.positions_m.len(), 3 * state.topology.vertex_count);
        let bytes = protocol::encode_frame(&frame);
        assert_eq!(bytes[0], KIND_FRAME);
        // two surfaces may reach the view within one servo tick (the step-0 surface and the
        // next, on a loaded machine): a frame's tick never goes back
        assert!(
            last_tick.is_none_or(|t| frame.tick >= t),
            "frames never go back"
        );
        last_tick = Some(frame.tick);
        cut_seen |= frame.mode == 2;
        frames += 1;
    }
    assert!(frames > 10, "{frames} frames");
    assert!(cut_seen, "a frame shows the blade cutting");
    let Ending::Scored { attempt, score, .. } = ending(&running).await else {
        panic!("scored")
    };
    assert_eq!(attempt, running.attempt);
    assert!((-1.0..=1.0).contains(&score));
    let a = store.get_attempt(attempt).await.expect("attempt");
    assert_eq!(a.status, AttemptStatus::Complete);
    assert!(a.scored && a.note.is_none(), "{a:?}");
    let path = a.recording_path.clone().expect("recording path");
    let rec = cutlab_recorder::Recording::open(std::path::Path::new(&path)).expect("recording");
    assert!(rec.is_whole() && !rec.topology.is_empty());

    // attempts left `running` by station processes: dead with the whole recording (died
    // before scoring it) or with it cut short; alive, recording; alive, not yet recording
    let bytes = std::fs::read(&path).expect("the recording");
    let [whole, cut_short, writing, starting] = orphans;
    std::fs::write(dir.join("whole.mcap"), &bytes).expect("a copy");
    let half = &bytes[..bytes.len() / 2];
    std::fs::write(dir.join("cut-short.mcap"), half).expect("a copy");
    std::fs::write(dir.join("writing.mcap"), half).expect("a copy");
    let [died_whole, died_short, writer, starter] =
        <[AttemptLock; 4]>::try_from(locks).expect("four");
    drop((died_whole, died_short));
    // dead too, started after that recording began where it lies: an older session's file
    let late_lock = AttemptLock::hold(&dir.join("whole.mcap")).expect("lock");
    let late = store
        .start_attempt(zoe.id, exercise.id, dir.join("whole.mcap").to_str(), false)
        .await
        .expect("started")
        .id;
    drop(late_lock);
    // never locked, just started (`cutlab assess` scores such an attempt at once)
    let fresh = store
        .start_attempt(
            zoe.id,
            exercise.id,
            dir.join("cut-short.mcap").to_str(),
            false,
        )
        .await
        .expect("started")
        .id;
    let ended = cutlab_station::attempt::end_abandoned(&store, None)
        .await
        .expect("swept");
    let ids: Vec<i64> = ended.iter().map(|e| e.0).collect();
    assert_eq!(ids, [whole, cut_short, late]);
    let status = |id| {
        let store = store.clone();
        async move { store.get_attempt(id).await.expect("attempt") }
    };
    assert_eq!(status(whole).await.status, AttemptStatus::Complete);
    for (id, why) in [
        (cut_short, "stopped before the attempt ended"),
        (late, "stopped before it recorded anything"),
    ] {
        let a = status(id).await;
        assert_eq!(a.status, AttemptStatus::Incomplete);
        assert!(a.note.as_deref().is_some_and(|n| n.contains(why)), "{a:?}");
    }
    for id in [writing, starting, fresh] {
        assert_eq!(status(id).await.status, AttemptStatus::Running);
    }
    // the ended ones wait for the hub; once the writer is gone, its attempt is ended too
    let queued: Vec<i64> = store
        .sync_queue()
        .await
        .expect("queue")
        .iter()
        .map(|a| a.id)
        .collect();
    assert!(
        [whole, cut_short, late]
            .iter()
            .all(|id| queued.contains(id)),
        "{queued:?}"
    );
    drop(writer);
    let ended = cutlab_station::attempt::end_abandoned(&store, None)
        .await
        .expect("swept");
    assert_eq!(ended.iter().map(|e| e.0).collect::<Vec<_>>(), [writing]);
    drop(starter);
    store.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stop_ends_the_session_early_and_a_lost_page_leaves_it_incomplete() {
    let dir_guard = temp_dir("stop");
    let dir = dir_guard.path();
    let store = store(dir).await;
    let set = Arc::new(StationSet::new(1));
    let request = |trainee: &str| StartRequest {
        exercise: EXERCISE.into(),
        trainee: trainee.into(),
        guided: false,
        second_hand: false,
    };
    let settings = settings(dir, 60.0);
    let running = set
        .insert(
            run::start(
                store.clone(),
                &settings,
                request("ana"),
                Input::Device(expert()),
            )
            .await
            .expect("started"),
        )
        .expect("room");
    // one session per trainee, and at most one here
    assert!(matches!(set.check_room("ana"), Err(StationError::Busy(m)) if m.contains("already")));
    assert!(matches!(set.check_room("ben"), Err(StationError::Busy(m)) if m.contains("at most 1")));
    running.control.stop();
    // stopped before the hand reached the tissue: kept, not scored (issue 63)
    let Ending::Incomplete { attempt, why } = ending(&running).await else {
        panic!("a session stopped before any contact is not scored")
    };
    assert_eq!(why, cutlab_scoring::UNTOUCHED_NOTE);
    let a = store.get_attempt(attempt).await.expect("attempt");
    assert!(a.status == AttemptStatus::Incomplete && !a.scored, "{a:?}");
    let rec_path = store
        .get_attempt(attempt)
        .await
        .expect("attempt")
        .recording_path
        .expect("path");
    let rec = cutlab_recorder::Recording::open(std::path::Path::new(&rec_path)).expect("rec");
    assert!(
        rec.duration_s() < 30.0,
        "stopped long before 60 s: {}",
        rec.duration_s()
    );
    assert!(set.get(attempt).is_none() && set.check_room("ben").is_ok());

    let lost = set
        .insert(
            run::start(
                store.clone(),
                &settings,
                request("ben"),
                Input::Device(expert()),
            )
            .await
            .expect("started"),
        )
        .expect("room");
    lost.control.lose();
    let Ending::Incomplete { attempt, why } = ending(&lost).await else {
        panic!("a lost page leaves the attempt incomplete")
    };
    assert!(why.contains("went away"), "{why}");
    let a = store.get_attempt(attempt).await.expect("attempt");
    assert_eq!(a.status, AttemptStatus::Incomplete);
    let rec =
        cutlab_recorder::Recording::open(std::path::Path::new(&a.recording_path.expect("path")))
            .expect("the recording of a lost session");
    assert!(
        rec.is_whole(),
        "the recording is complete: {:?}",
        rec.damage
    );
    store.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_that_stops_sending_leaves_the_attempt_incomplete() {
    use cutlab_haptics::device::PointerSample;
    let dir_guard = temp_dir("stalled");
    let dir = dir_guard.path();
    let store = store(dir).await;
    let settings = StationSettings {
        clock: Clock::Live,
        absence_s: 2.0,
        ..settings(dir, 60.0)
    };
    let request = StartRequest {
        exercise: EXERCISE.into(),
        trainee: "ana".into(),
        guided: true,
        second_hand: false,
    };
    let running = run::start(store.clone(), &settings, request, Input::Pointer)
        .await
        .expect("started");
    let feed = running.pointer.clone().expect("the page's pointer");
    assert!(running.grasper.is_none(), "no second hand was asked for");
    let entry = running.plan.line_m[0];
    feed.push(PointerSample::new(1.0, entry.into(), 0.0, false))
        .expect("a sample");
    // then nothing: the blade pauses; past the absence the session ends, not scored
    let Ending::Incomplete { attempt, why } = ending(&running).await else {
        panic!("a stalled page is not scored")
    };
    assert!(why.contains("pointer failed"), "{why}");
    assert!(
        feed.counters()
            .paused_ticks
            .load(std::sync::atomic::Ordering::Relaxed)
            > 1000
    );
    let a = store.get_attempt(attempt).await.expect("attempt");
    assert_eq!(a.status, AttemptStatus::Incomplete);
    assert!(a.note.is_some_and(|n| n.contains("pointer")));
    store.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_that_pauses_or_reconnects_keeps_its_attempt() {
    use cutlab_haptics::device::PointerSample;
    use std::sync::atomic::Ordering::Relaxed;
    let dir_guard = temp_dir("paused");
    let dir = dir_guard.path();
    let store = store(dir).await;
    let settings = StationSettings {
        clock: Clock::Live,
        absence_s: 3.0,
        ..settings(dir, 60.0)
    };
    let request = StartRequest {
        exercise: EXERCISE.into(),
        trainee: "ana".into(),
        guided: true,
        second_hand: false,
    };
    let running = run::start(store.clone(), &settings, request, Input::Pointer)
        .await
        .expect("started");
    let feed = running.pointer.clone().expect("the page's pointer");
    let line = running.plan.line_m.clone();
    // a page at 60 Hz along the first half of the line; then it is hidden for a second and a
    // half (nothing sent) and reloaded (its socket gone and back, its clock from zero again)
    let send = |t0_ms: f64, from: usize, to: usize| {
        let feed = feed.clone();
        let line = line.clone();
        async move {
            for (k, p) in line[from..to].iter().enumerate() {
                let s = PointerSample::new(t0_ms + 16.7 * k as f64, (*p).into(), 0.004, true);
                feed.push(s).expect("a sample");
                tokio::time::sleep(Duration::from_millis(17)).await;
            }
        }
    };
    running.control.attach();
    send(1000.0, 0, line.len() / 2).await;
    tokio::time::sleep(Duration::from_millis(1500)).await;
    running.control.leave();
    tokio::time::sleep(Duration::from_millis(500)).await;
    running.control.attach();
    send(3.0, line.len() / 2, line.len()).await;
    assert!(running.ending.borrow().is_none(), "still running");
    running.control.stop();
    let Ending::Scored { attempt, .. } = ending(&running).await else {
        panic!("a paused and reconnected page's attempt is scored")
    };
    assert!(feed.counters().paused_ticks.load(Relaxed) > 500);
    assert_eq!(feed.counters().resumes.load(Relaxed), 1);
    let a = store.get_attempt(attempt).await.expect("attempt");
    assert_eq!(a.status, AttemptStatus::Complete);
    store.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_gone_past_the_absence_ends_its_attempt_incomplete() {
    let dir_guard = temp_dir("gone");
    let dir = dir_guard.path();
    let store = store(dir).await;
    let settings = StationSettings {
        absence_s: 1.0,
        clock: Clock::Live,
        ..settings(dir, 60.0)
    };
    let request = StartRequest {
        exercise: EXERCISE.into(),
        trainee: "ana".into(),
        guided: false,
        second_hand: false,
    };
    let running = run::start(store.clone(), &settings, request, Input::Device(expert()))
        .await
        .expect("started");
    running.control.attach();
    running.control.leave();
    let t0 = std::time::Instant::now();
    let Ending::Incomplete { why, .. } = ending(&running).await else {
        panic!("a page that never came back leaves the attempt incomplete")
    };
    assert!(why.contains("did not come back within 1 s"), "{why}");
    assert!(t0.elapsed() < Duration::from_secs(20));
    store.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_exam_only_exercise_never_shows_its_plan_and_brings_its_force_limit() {
    use cutlab_assessor::store::NewExercise;
    use cutlab_scoring::IncisionPlan;
    let dir_guard = temp_dir("exam-only");
    let dir = dir_guard.path();
    let store = store(dir).await;
    let plan = IncisionPlan {
        force_limit_n: 1.75,
        ..IncisionPlan::chest_wall().expect("the built-in plan")
    }
    .into();
    store
        .create_exercise(&NewExercise {
            name: "chest-wall-exam",
            scene: cutlab_assessor::store::BUILTIN_SCENE,
            description: "the chest wall incision, examined",
            plan: &plan,
            thresholds: &[],
            threshold_k: 2.0,
            exam_only: true,
        })
        .await
        .expect("exercise");
    let settings = settings(dir, 60.0);
    let start = |exercise: &str, guided| {
        run::start(
            store.clone(),
            &settings,
            StartRequest {
                exercise: exercise.into(),
                trainee: "ana".into(),
                guided,
                second_hand: false,
            },
            Input::Device(expert()),
        )
    };
    // asked for guided, run as an exam, with the exercise's force limit
    let exam = start("chest-wall-exam", true).await.expect("started");
    assert!(!exam.guided, "an exam-only exercise runs as an exam");
    assert_eq!(exam.force_limit_newtons, 1.75);
    exam.control.stop();
    ending(&exam).await;
    // an ordinary exercise honours the choice
    let guided = start(EXERCISE, true).await.expect("started");
    assert!(guided.guided);
    guided.control.stop();
    ending(&guided).await;
    store.close().await;
}

/// Pattern cutting at the station in exam mode: the marked circle is laid on the sheet and
/// shown (the plan is not); the expert cuts the piece free and passes; the attempt's metrics
/// are the pattern kind's.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pattern_cutting_shows_its_mark_in_exam_mode_and_scores_the_freed_piece() {
    let dir_guard = temp_dir("pattern");
    let dir = dir_guard.path();
    let store = store(dir).await;
    let settings = settings(dir, 12.0);
    let request = || StartRequest {
        exercise: cutlab_assessor::store::PATTERN_EXERCISE.into(),
        trainee: "ana".into(),
        guided: false,
        second_hand: false,
    };
    // second in cutting-basics: locked until the incision is proficient
    let refused = run::start(store.clone(), &settings, request(), Input::Device(expert())).await;
    match refused {
        Err(cutlab_station::StationError::Locked(why)) => {
            assert!(
                why.contains(EXERCISE) && why.contains("instructor"),
                "{why}"
            );
        }
        other => panic!("locked: {:?}", other.map(|r| r.attempt)),
    }
    // until an instructor opens it early
    let kim = store
        .create_user("dr-kim", Role::Instructor, None)
        .await
        .expect("kim");
    let (ana, pattern) = (
        store.user_by_name("ana").await.expect("ana"),
        store
            .exercise_by_name(cutlab_assessor::store::PATTERN_EXERCISE)
            .await
            .expect("pattern"),
    );
    let opening = store
        .open_early(ana.id, pattern.id, kim.id, "FLS course next week")
        .await
        .expect("opened");
    assert_eq!(opening.opened_by, "dr-kim");
    let running = run::start(store.clone(), &settings, request(), Input::Device(expert()))
        .await
        .expect("started");
    assert!(!running.guided);
    // the mark: one closed circle of radius 20 mm about the sheet's centre, on its top
    assert_eq!(running.marks.len(), 1);
    let mark = &running.marks[0];
    assert!(mark.len() > 300, "{} points", mark.len());
    for p in mark {
        let r = (p.x - 0.05).hypot(p.y - 0.05);
        assert!((r - 0.02).abs() < 5e-4, "{p:?}: radius {r}");
        assert!(
            (p.z - 0.0025).abs() < 5e-4,
            "{p:?}: on the top, lifted 0.5 mm"
        );
    }
    let Ending::Scored {
        attempt, passed, ..
    } = ending(&running).await
    else {
        panic!("scored");
    };
    assert!(passed, "the expert passes");
    let metrics = store.attempt_metrics(attempt).await.expect("metrics");
    let value = |key: &str| {
        metrics
            .iter()
            .find(|m| m.metric == key)
            .and_then(|m| m.value)
    };
    assert_eq!(value("piece_freed"), Some(1.0));
    assert!(value("mistels_score").is_some_and(|s| s > 250.0));
    assert!(value("entry_error_m").is_none(), "no incision metrics");
    store.close().await;
}

/// The mini-thoracotomy in exam mode: the landmarks (the sternum's edge, four ribs) are on
/// the skin, the plan's line is not; the expert's attempt is scored on what its retracted
/// wound shows of the heart, without harm.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mini_thoracotomy_is_scored_on_its_retracted_field() {
    let dir_guard = temp_dir("field");
    let dir = dir_guard.path();
    let store = store(dir).await;
    let settings = settings(dir, 10.0);
    let name = cutlab_assessor::store::FIELD_EXERCISE;
    let kim = store
        .create_user("dr-kim", Role::Instructor, None)
        .await
        .expect("kim");
    let ana = store
        .create_user("ana", Role::Trainee, None)
        .await
        .expect("ana");
    let field = store.exercise_by_name(name).await.expect("the exercise");
    store
        .open_early(ana.id, field.id, kim.id, "thoracic rotation")
        .await
        .expect("opened");
    let request = StartRequest {
        exercise: name.into(),
        trainee: "ana".into(),
        guided: false,
        second_hand: false,
    };
    let running = run::start(store.clone(), &settings, request, Input::Device(expert()))
        .await
        .expect("started");
    assert!(!running.guided);
    assert_eq!(running.marks.len(), 5, "the sternum's edge and four ribs");
    let Ending::Scored {
        attempt, passed, ..
    } = ending(&running).await
    else {
        panic!("scored");
    };
    let metrics = store.attempt_metrics(attempt).await.expect("metrics");
    let value = |key: &str| {
        metrics
            .iter()
            .find(|m| m.metric == key)
            .and_then(|m| m.value)
    };
    assert!(passed, "the expert passes: {metrics:?}");
    assert!(
        value("field_of_expert").is_some_and(|f| f > 0.5),
        "{metrics:?}"
    );
    assert!(value("field_working_width_m").is_some_and(|w| w > 0.005));
    assert_eq!(value("wall_opened"), Some(1.0));
    assert_eq!(value("bone_contacts"), Some(0.0));
    assert_eq!(value("critical_damage"), Some(0.0));
    assert!(value("lateral_mean_m").is_none(), "no distance to the line");
    // the debrief's picture of that field: the heart's deep red through the retracted wound
    let a = store.get_attempt(attempt).await.expect("the attempt");
    let (mcap, _) = a.recording_files().expect("recorded");
    let rec = cutlab_recorder::Recording::open(&mcap).expect("the recording");
    let cutlab_scoring::ExercisePlan::Field(plan) =
        store.exercise_plan(field.id).await.expect("the plan")
    else {
        panic!("a field plan");
    };
    let picture =
        cutlab_scoring::from_recording::field_picture(&rec, &plan, 200).expect("a picture");
    let heart = picture
        .rgb
        .chunks(3)
        .filter(|p| p[0] > 40 && u32::from(p[0]) > 3 * u32::from(p[1]))
        .count();
    assert!(
        heart > 100,
        "the heart shows through the retracted wound: {heart} pixels"
    );
    store.close().await;
}

/// A page with a second hand: its touch closes the grasper 12 mm beside the line's middle,
/// draws the tissue 4 mm further away and lifts it while the pen cuts the line, and lets go
/// at the end. The frames show the jaws holding; the attempt is scored with the handling of
/// the tissue. A session started without a second hand has no grasper to feed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_second_hand_on_the_pages_touch_holds_the_tissue_while_the_pen_cuts() {
    use cutlab_haptics::device::PointerSample;
    let dir_guard = temp_dir("two-hands");
    let dir = dir_guard.path();
    let store = store(dir).await;
    let settings = StationSettings {
        clock: Clock::Live,
        ..settings(dir, 60.0)
    };
    let request = StartRequest {
        exercise: EXERCISE.into(),
        trainee: "ana".into(),
        guided: true,
        second_hand: true,
    };
    let running = run::start(store.clone(), &settings, request, Input::Pointer)
        .await
        .expect("started");
    let (pen, touch) = (
        running.pointer.clone().expect("the page's pointer"),
        running.grasper.clone().expect("the page's grasper"),
    );
    let line = running.plan.line_m.clone();
    let (a, b) = (line[0], line[line.len() - 1]);
    let up = running.plan.normals[line.len() / 2];
    let beside = up.cross(&(b - a)).normalize();
    let hold = line[line.len() / 2] + beside * 0.012;
    running.control.attach();
    let mut feed = running.feed.clone();
    let mut held_seen = false;
    // 60 Hz: the touch lands and closes (0.3 s), draws 4 mm away and lifts 4 mm (0.5 s),
    // then the pen cuts the line 4 mm deep (3 s) while the touch holds
    let steps = 60 + line.len() * 6;
    for k in 0..steps {
        let t_ms = 1000.0 + 16.7 * k as f64;
        let draw = (k.saturating_sub(18) as f64 / 30.0).min(1.0);
        let jaws = hold + beside * (0.004 * draw);
        let grasp = PointerSample::new(t_ms, jaws.into(), -0.004 * draw, k >= 12);
        touch.push(grasp).expect("a grasper sample");
        let along = line[(k.saturating_sub(60) / 6).min(line.len() - 1)];
        let cutting = k >= 60;
        let depth_m = if cutting { 0.004 } else { 0.0 };
        let cut = PointerSample::new(t_ms, along.into(), depth_m, cutting);
        pen.push(cut).expect("a pen sample");
        tokio::time::sleep(Duration::from_millis(17)).await;
        let frame = feed.borrow_and_update().frame.clone();
        held_seen |= frame
            .and_then(|f| f.grasper)
            .is_some_and(|g| g.state() == 3);
    }
    assert!(held_seen, "the frames never showed the jaws holding");
    let t_ms = 1000.0 + 16.7 * steps as f64;
    touch
        .push(PointerSample::new(t_ms, hold.into(), -0.004, false))
        .expect("let go");
    tokio::time::sleep(Duration::from_millis(200)).await;
    running.control.stop();
    let Ending::Scored { attempt, .. } = ending(&running).await else {
        panic!("the two-handed attempt is scored")
    };
    let metrics = store.attempt_metrics(attempt).await.expect("metrics");
    let value = |key: &str| {
        metrics
            .iter()
            .find(|m| m.metric == key)
            .and_then(|m| m.value)
            .unwrap_or_else(|| panic!("{key}: {metrics:?}"))
    };
    assert_eq!(value("grasps"), 1.0);
    assert!(value("peak_traction_n") > 0.0);
    assert!(value("countertraction_fraction") > 0.5, "{metrics:?}");
    store.close().await;
}
