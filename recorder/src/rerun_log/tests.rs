use std::collections::HashMap;
use std::path::{Path, PathBuf};

use cutlab_haptics::render::{Mode, RenderOutput};
use cutlab_haptics::tap::{Keyframe, SurfaceSnapshot};
use cutlab_haptics::{Point3, Rotation, SimRecord, StateHash, ToolPose, Vector3};
use cutlab_sim::cut::{Blade, CutEvent};
use rerun::external::re_log_encoding::DecoderApp;
use rerun::log::{Chunk, LogMsg};

use super::*;

const PERIOD_NANOS: u64 = 1_000_000;
const TICKS: u64 = 3000;

/// A fresh path in the system's temporary directory (removed by [`TempFile`]'s drop).
struct TempFile(PathBuf);

impl TempFile {
    fn new(name: &str) -> Self {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        Self(std::env::temp_dir().join(format!(
            "cutlab-rerun-{}-{nanos}-{name}",
            std::process::id()
        )))
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

fn sample(tick: u64) -> ServoSample {
    let t = tick as f64 * 1e-3;
    let mode = match tick % 1000 {
        0..=299 => Mode::Free,
        300..=699 => Mode::Touching,
        _ => Mode::Cutting,
    };
    let tip = Point3::new(0.01 * t, 0.0, 0.02 - 0.001 * t);
    ServoSample {
        tick,
        pose: ToolPose {
            tip_in_world: tip,
            world_from_tool: Rotation::from_euler_angles(0.1 * t, 0.2, 0.0),
            buttons: 1,
        },
        render: RenderOutput {
            force_newtons: Vector3::new((3.0 * t).sin(), 0.5, 2.0 + t),
            proxy: tip + Vector3::new(0.0, 0.0, 0.001),
            mode,
            // The device is lost for ten ticks: two events (the fault, then its clearing).
            faults: if (1000..1010).contains(&tick) {
                cutlab_haptics::render::fault::DEVICE_LOST
            } else {
                0
            },
            gain: 1.0,
        },
        // the second hand beside it, its jaws closed half the time
        grasper: Some(cutlab_haptics::servo::GrasperTick {
            pose: ToolPose {
                tip_in_world: tip + Vector3::new(0.0, 0.01, 0.0),
                world_from_tool: Rotation::identity(),
                buttons: if tick % 2000 >= 1000 {
                    cutlab_haptics::pose::BUTTON_JAWS
                } else {
                    0
                },
            },
            pull_newtons: Vector3::zeros(),
        }),
    }
}

/// A unit square in the z = 0 plane, lifted by `h` at one corner.
fn surface(step: u64, h: f64, split: bool) -> SurfaceSnapshot {
    let mut vertices = vec![
        Point3::new(0.0, 0.0, 0.0),
        Point3::new(0.1, 0.0, 0.0),
        Point3::new(0.1, 0.1, h),
        Point3::new(0.0, 0.1, 0.0),
    ];
    let mut triangles = vec![[0, 1, 2], [0, 2, 3]];
    if split {
        vertices.push(Point3::new(0.05, 0.05, 0.0));
        triangles = vec![[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]];
    }
    SurfaceSnapshot {
        step,
        tick: step,
        regions: vec![0; vertices.len()],
        vertices,
        triangles,
    }
}

/// Rows per entity path (without the leading `/`), and the timelines seen on each.
#[derive(Debug, Default)]
struct Decoded {
    rows: HashMap<String, usize>,
    chunks: usize,
    timelines: HashMap<String, Vec<String>>,
    last_force_row: Option<(i64, i64)>,
    /// Entity paths of the blueprint store (`viewport`, `container/…`, `view/…`).
    blueprint: Vec<String>,
    /// A blueprint activation asked to make it active and the default.
    blueprint_activated: bool,
}

/// Reads an `.rrd` with rerun's own decoder.
fn decode(path: &Path) -> Decoded {
    let file = std::fs::File::open(path).expect("open the rrd");
    let decoder = DecoderApp::decode_eager(std::io::BufReader::new(file)).expect("an rrd stream");
    let mut out = Decoded::default();
    for msg in decoder {
        let msg = msg.expect("a message decodes");
        let (store, arrow) = match msg {
            LogMsg::ArrowMsg(store, arrow) => (store, arrow),
            LogMsg::BlueprintActivationCommand(cmd) => {
                out.blueprint_activated |= cmd.make_active && cmd.make_default;
                continue;
            }
            LogMsg::SetStoreInfo(_) => continue,
        };
        let chunk = Chunk::from_arrow_msg(&arrow).expect("a chunk decodes");
        let path = chunk
            .entity_path()
            .to_string()
            .trim_start_matches('/')
            .to_owned();
        if store.kind() == rerun::StoreKind::Blueprint {
            out.blueprint.push(path);
            continue;
        }
        out.chunks += 1;
        *out.rows.entry(path.clone()).or_default() += chunk.num_rows();
        let names = out.timelines.entry(path.clone()).or_default();
        for name in chunk.timelines().keys() {
            let name = name.to_string();
            if !names.contains(&name) {
                names.push(name);
            }
        }
        if path == paths::FORCE_NORM {
            let last = |name: &str| {
                chunk
                    .timelines()
                    .iter()
                    .find(|(n, _)| n.as_str() == name)
                    .and_then(|(_, c)| c.times_raw().last().copied())
            };
            if let (Some(tick), Some(nanos)) = (last(TIMELINE_TICK), last(TIMELINE_SIM_TIME))
                && out.last_force_row.is_none_or(|(t, _)| tick > t)
            {
                out.last_force_row = Some((tick, nanos));
            }
        }
    }
    out
}

#[test]
fn rrd_of_a_synthetic_session_decodes_with_every_entity_and_every_tick() {
    let file = TempFile::new("session.rrd");
    let mut sink = RerunSink::new(
        &RerunTarget::File(file.0.clone()),
        "cutlab-test",
        PERIOD_NANOS,
        0.015,
    )
    .expect("sink");
    sink.log_plan(&cutlab_haptics::plan::Plan {
        line_m: vec![Point3::new(0.0, 0.05, 0.0), Point3::new(0.1, 0.05, 0.0)],
        normals: vec![Vector3::z(); 2],
        depth_m: 0.005,
        approach_height_m: 0.02,
        viewpoint_m: None,
    })
    .expect("plan");

    let mut surfaces = 0;
    let mut engine_events = 0;
    for tick in 0..TICKS {
        sink.on_tick(&sample(tick)).expect("tick");
        let step = tick; // lock-step: one simulation step per tick
        sink.on_sim(&SimRecord::Step {
            step,
            tick,
            rejected: tick == 1500,
        })
        .expect("step");
        if tick % 33 == 0 {
            sink.on_sim(&SimRecord::Surface(Box::new(surface(
                step,
                1e-6 * tick as f64,
                tick >= 2000,
            ))))
            .expect("surface");
            surfaces += 1;
        }
        if tick == 2000 {
            let blade = Blade {
                tip: Point3::new(0.05, 0.05, 0.0),
                edge_direction: Vector3::z(),
                depth_m: 0.01,
            };
            let event = CutEvent {
                tets_removed: vec![1, 2],
                forced_splits: 1,
                ..CutEvent::default()
            };
            sink.on_sim(&SimRecord::Cut {
                step,
                tick,
                blade,
                event: Box::new(event),
            })
            .expect("cut");
            engine_events += 1;
        }
        if tick % 1000 == 999 {
            let keyframe = Keyframe {
                step,
                tick,
                hash: StateHash {
                    state: 0xdead_beef,
                    topology: 42,
                },
                positions: vec![Point3::origin(); 4],
                velocities: vec![Vector3::zeros(); 4],
                rest_positions: vec![Point3::origin(); 4],
                tets: vec![[0, 1, 2, 3]],
                regions: vec![0],
                resume: None,
            };
            sink.on_sim(&SimRecord::Keyframe(Box::new(keyframe)))
                .expect("keyframe");
            engine_events += 1;
        }
    }
    engine_events += 1; // the rejected step
    let events = 2; // the fault and its clearing: the review's Events view
    assert_eq!(sink.ticks_logged(), TICKS);
    sink.finish().expect("finish");

    let size = std::fs::metadata(&file.0).expect("the rrd exists").len();
    let decoded = decode(&file.0);
    eprintln!(
        "{TICKS} ticks, {surfaces} surfaces: {size} bytes, {} chunks, rows {:?}",
        decoded.chunks, decoded.rows
    );

    assert!(decoded.chunks > 0);
    for path in [
        paths::FORCE_X,
        paths::FORCE_Y,
        paths::FORCE_Z,
        paths::FORCE_NORM,
        paths::CONTACT_MODE,
        paths::CONTACT_PENETRATION,
    ] {
        // One static row of series styling, then one row per tick.
        assert_eq!(
            decoded.rows.get(path).copied(),
            Some(TICKS as usize + 1),
            "rows of {path}"
        );
        let timelines = &decoded.timelines[path];
        assert!(
            timelines.iter().any(|t| t == TIMELINE_TICK)
                && timelines.iter().any(|t| t == TIMELINE_SIM_TIME),
            "{path}: {timelines:?}"
        );
    }
    let last = TICKS as i64 - 1;
    assert_eq!(
        decoded.last_force_row,
        Some((last, last * PERIOD_NANOS as i64))
    );
    assert_eq!(decoded.rows.get(paths::TISSUE).copied(), Some(surfaces));
    // the review layout travels with the file: a viewport, its two containers and three views
    // (the tissue in 3D, the force and contact plot, the events), made active and the default;
    // sent twice, the second time framed on the plan
    assert!(decoded.blueprint_activated);
    assert!(
        decoded.blueprint.iter().any(|p| p == "viewport"),
        "{:?}",
        decoded.blueprint
    );
    let count = |kind: &str| {
        let ids: std::collections::BTreeSet<_> = decoded
            .blueprint
            .iter()
            .filter_map(|p| p.split_once('/'))
            .filter(|(k, _)| *k == kind)
            .map(|(_, rest)| rest.split('/').next())
            .collect();
        ids.len()
    };
    assert_eq!(
        (count("view"), count("container")),
        (6, 4),
        "{:?}",
        decoded.blueprint
    );
    for panel in ["blueprint_panel", "selection_panel", "time_panel"] {
        assert!(decoded.blueprint.iter().any(|p| p == panel), "{panel}");
    }
    assert!(
        decoded.timelines[paths::TISSUE]
            .iter()
            .any(|t| t == TIMELINE_STEP)
    );
    assert_eq!(decoded.rows.get(paths::EVENTS).copied(), Some(events));
    // the engine's lines apart, out of the instructor's view (issue 63)
    assert_eq!(
        decoded.rows.get(paths::ENGINE_EVENTS).copied(),
        Some(engine_events)
    );
    // The static axes, then ~30 Hz of transforms (every 33rd tick).
    let transforms = TICKS.div_ceil(33) as usize;
    assert_eq!(
        decoded.rows.get(paths::SCALPEL).copied(),
        Some(1 + transforms)
    );
    assert_eq!(decoded.rows.get(paths::PROXY).copied(), Some(transforms));
    assert_eq!(decoded.rows.get(paths::GRASPER).copied(), Some(transforms));
    assert_eq!(decoded.rows.get(paths::BLADE).copied(), Some(1));
    assert_eq!(decoded.rows.get(paths::PLAN).copied(), Some(1));
}

#[test]
fn a_short_session_is_sent_at_finish() {
    let file = TempFile::new("short.rrd");
    let mut sink = RerunSink::new(
        &RerunTarget::File(file.0.clone()),
        "cutlab-test",
        PERIOD_NANOS,
        0.015,
    )
    .expect("sink");
    for tick in 0..10 {
        sink.on_tick(&sample(tick)).expect("tick");
    }
    sink.finish().expect("finish");
    let decoded = decode(&file.0);
    assert_eq!(decoded.rows.get(paths::FORCE_NORM).copied(), Some(11));
    assert_eq!(decoded.last_force_row, Some((9, 9 * PERIOD_NANOS as i64)));
}

#[test]
fn a_dropped_sink_still_sends_its_buffer_and_completes_the_file() {
    let file = TempFile::new("dropped.rrd");
    let mut sink = RerunSink::new(
        &RerunTarget::File(file.0.clone()),
        "cutlab-test",
        PERIOD_NANOS,
        0.015,
    )
    .expect("sink");
    for tick in 0..1500 {
        sink.on_tick(&sample(tick)).expect("tick");
    }
    // Held the way the writer thread holds an observer.
    let boxed: Box<dyn Send> = Box::new(sink);
    drop(boxed);
    let decoded = decode(&file.0);
    assert_eq!(decoded.rows.get(paths::FORCE_NORM).copied(), Some(1501));
}

#[test]
fn a_viewer_that_is_not_there_is_an_error_not_a_hang() {
    // A port nobody listens on.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port();
    let target = RerunTarget::Connect(format!("rerun+http://127.0.0.1:{port}/proxy"));
    let started = std::time::Instant::now();
    let mut sink =
        RerunSink::new(&target, "cutlab-test", PERIOD_NANOS, 0.015).expect("connecting is lazy");
    for tick in 0..200 {
        sink.on_tick(&sample(tick))
            .expect("ticks are buffered or queued");
    }
    let result = sink.finish();
    eprintln!(
        "finish against no viewer: {result:?} after {:?}",
        started.elapsed()
    );
    assert!(result.is_err(), "no viewer took the data");
    assert!(started.elapsed() < LIVE_FLUSH_TIMEOUT + Duration::from_secs(5));

    let bad = RerunSink::new(
        &RerunTarget::Connect("not a url".into()),
        "cutlab-test",
        PERIOD_NANOS,
        0.015,
    );
    assert!(matches!(bad, Err(RerunLogError::Stream(_))), "{bad:?}");
    assert_eq!(
        RerunTarget::connect_default(),
        RerunTarget::Connect("rerun+http://127.0.0.1:9876/proxy".into())
    );
}

#[test]
fn settings_and_paths_are_checked() {
    let file = TempFile::new("never.rrd");
    let target = RerunTarget::File(file.0.clone());
    assert!(matches!(
        RerunSink::new(&target, "cutlab-test", 0, 0.015),
        Err(RerunLogError::Settings(_))
    ));
    assert!(matches!(
        RerunSink::new(&target, "cutlab-test", PERIOD_NANOS, f64::NAN),
        Err(RerunLogError::Settings(_))
    ));
    assert!(!file.0.exists(), "nothing is created for bad settings");

    let missing = std::env::temp_dir()
        .join("cutlab-no-such-directory")
        .join("x.rrd");
    let err = RerunSink::new(
        &RerunTarget::File(missing),
        "cutlab-test",
        PERIOD_NANOS,
        0.015,
    )
    .expect_err("no directory");
    assert!(matches!(err, RerunLogError::Stream(_)), "{err}");
}

/// The child half of [`spawning_without_a_viewer_on_path_is_an_error`].
const SPAWN_CHILD: &str = "CUTLAB_RERUN_SPAWN_CHILD";

#[test]
fn spawning_without_a_viewer_on_path_is_an_error() {
    // A viewer (or anything) on rerun's port would be connected to instead of spawned.
    let port = rerun::SpawnOptions::default().connect_addr();
    if std::net::TcpStream::connect_timeout(&port, Duration::from_millis(200)).is_ok() {
        eprintln!("skipped: something listens on {port}");
        return;
    }
    if std::env::var_os(SPAWN_CHILD).is_some() {
        // PATH has no `rerun` here.
        let err = RerunSink::new(&RerunTarget::Spawn, "cutlab-test", PERIOD_NANOS, 0.015)
            .expect_err("no viewer on PATH");
        let text = err.to_string();
        assert!(matches!(err, RerunLogError::Spawn(_)), "{text}");
        assert!(text.contains("PATH") && text.contains("install"), "{text}");
        return;
    }
    // Changing PATH in this process would race the other tests: a child of this test binary
    // runs this very test with an empty directory as its PATH.
    let empty = TempFile::new("empty-path");
    std::fs::create_dir_all(&empty.0).expect("an empty directory");
    let out = std::process::Command::new(std::env::current_exe().expect("this test binary"))
        .args([
            "--exact",
            "rerun_log::tests::spawning_without_a_viewer_on_path_is_an_error",
            "--nocapture",
        ])
        .env("PATH", &empty.0)
        .env(SPAWN_CHILD, "1")
        .output()
        .expect("the child runs");
    let _ = std::fs::remove_dir(&empty.0);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "child failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("1 passed"),
        "the child did not run the test:\n{stdout}"
    );
}

#[test]
fn vertex_normals_are_unit_and_area_weighted() {
    let s = surface(0, 0.0, false);
    let n = vertex_normals(&s.vertices, &s.triangles);
    assert_eq!(n.len(), 4);
    for v in &n {
        assert!(
            (v[2] - 1.0).abs() < 1e-6 && v[0].abs() < 1e-6 && v[1].abs() < 1e-6,
            "{v:?}"
        );
    }
    // A triangle with an index out of range is skipped, a vertex on no triangle gets zero.
    let mut vertices = s.vertices.clone();
    vertices.push(Point3::new(1.0, 1.0, 1.0));
    let n = vertex_normals(&vertices, &[[0, 1, 2], [0, 2, 99]]);
    assert_eq!(n[4], [0.0; 3]);
    assert!((n[0][2] - 1.0).abs() < 1e-6);
}

#[test]
fn event_texts_carry_the_figures() {
    let blade = Blade {
        tip: Point3::new(0.01, 0.02, 0.03),
        edge_direction: Vector3::z(),
        depth_m: 0.005,
    };
    let e = CutEvent {
        tets_removed: vec![1; 12],
        tets_added: vec![(0, [0; 4]); 37],
        ..CutEvent::default()
    };
    let text = cut_text(1234, &blade, &e);
    assert!(
        text.starts_with("step 1234: cut: 12 tets split into 37,"),
        "{text}"
    );
    assert!(!text.contains("forced"));
    let k = Keyframe {
        step: 7,
        tick: 9,
        hash: StateHash {
            state: 0xabc,
            topology: 0x1,
        },
        positions: vec![],
        velocities: vec![],
        rest_positions: vec![],
        tets: vec![],
        regions: vec![],
        resume: None,
    };
    let text = keyframe_text(&k);
    assert!(
        text.contains("state hash 0000000000000abc")
            && text.contains("topology hash 0000000000000001"),
        "{text}"
    );
}

/// The review's 3D view looks from the exercise's viewpoint: its `EyeControls3D` property is
/// in the blueprint that is made active, under the 3D view of that blueprint.
#[test]
fn the_review_view_looks_from_the_exercise_viewpoint() {
    let file = TempFile::new("framed.rrd");
    let mut sink = RerunSink::new(
        &RerunTarget::File(file.0.clone()),
        "cutlab-test",
        PERIOD_NANOS,
        0.015,
    )
    .expect("sink");
    // a 100 mm incision along x on a surface facing +y, seen from a viewpoint above and behind
    let plan = cutlab_haptics::plan::Plan {
        line_m: vec![Point3::new(0.0, 0.0, 0.0), Point3::new(0.1, 0.0, 0.0)],
        normals: vec![Vector3::y(); 2],
        depth_m: 0.005,
        approach_height_m: 0.02,
        viewpoint_m: Some(Point3::new(0.05, 0.15, -0.15)),
    };
    let eye = plan_view(&plan).expect("a view of the plan");
    let middle = Point3::new(0.05, 0.0, 0.0);
    assert!((eye.look_target_m - middle).norm() < 1e-12);
    // from the viewpoint's direction, at 1.2 times the incision's length
    let towards = Vector3::new(0.0, 1.0, -1.0).normalize();
    assert!(
        (eye.position_m - (middle + towards * 0.12)).norm() < 1e-12,
        "{eye:?}"
    );
    // the incision runs left to right: up is the incision's direction crossed with the view's
    let up = eye.up.expect("an up");
    let view = (middle - eye.position_m).normalize();
    assert!(up.dot(&view).abs() < 1e-12 && up.dot(&Vector3::x()).abs() < 1e-12);
    assert!((view.cross(&up) - Vector3::x()).norm() < 1e-12, "{up}");
    // a far viewpoint gives its direction only; a short incision is seen from 5 cm
    let far = plan_view(&cutlab_haptics::plan::Plan {
        viewpoint_m: Some(Point3::new(0.05, 3.0, 0.0)),
        ..plan.clone()
    })
    .expect("a view");
    assert!(
        (far.position_m - Point3::new(0.05, 0.12, 0.0)).norm() < 1e-12,
        "{far:?}"
    );
    let short = plan_view(&cutlab_haptics::plan::Plan {
        line_m: vec![Point3::new(0.0, 0.0, 0.0), Point3::new(0.01, 0.0, 0.0)],
        ..plan.clone()
    })
    .expect("a view");
    assert!(
        ((short.position_m - short.look_target_m).norm() - 0.05).abs() < 1e-12,
        "{short:?}"
    );
    // without a viewpoint: along the mean normal, at the framing distance
    let unplaced = cutlab_haptics::plan::Plan {
        viewpoint_m: None,
        ..plan.clone()
    };
    let normal_eye = plan_view(&unplaced).expect("a view along the normal");
    assert!(
        (normal_eye.position_m - Point3::new(0.05, 0.12, 0.0)).norm() < 1e-12,
        "{normal_eye:?}"
    );
    let flat = cutlab_haptics::plan::Plan {
        normals: vec![Vector3::zeros(); 2],
        ..unplaced
    };
    assert_eq!(plan_view(&flat), None);
    let on_the_line = cutlab_haptics::plan::Plan {
        viewpoint_m: Some(middle),
        ..plan.clone()
    };
    assert_eq!(plan_view(&on_the_line), None);
    sink.frame_view(&eye).expect("framed");
    assert!(
        sink.frame_view(&ReviewEye {
            position_m: middle,
            ..eye
        })
        .is_err(),
        "a view needs two points"
    );
    assert!(
        sink.frame_view(&ReviewEye {
            position_m: Point3::new(f64::NAN, 0.0, 0.0),
            ..eye
        })
        .is_err()
    );
    assert!(
        sink.frame_view(&ReviewEye {
            up: Some(Vector3::zeros()),
            ..eye
        })
        .is_err()
    );
    drop(sink);

    let reader = std::fs::File::open(&file.0).expect("open the rrd");
    let decoder = DecoderApp::decode_eager(std::io::BufReader::new(reader)).expect("rrd");
    let mut activated = Vec::new();
    let mut eye_controls = Vec::new();
    let mut views = Vec::new();
    for msg in decoder {
        match msg.expect("a message decodes") {
            LogMsg::BlueprintActivationCommand(cmd) if cmd.make_active => {
                activated.push(cmd.blueprint_id);
            }
            LogMsg::ArrowMsg(store, arrow) if store.kind() == rerun::StoreKind::Blueprint => {
                let chunk = Chunk::from_arrow_msg(&arrow).expect("a chunk decodes");
                let path = chunk.entity_path().to_string();
                let path = path.trim_start_matches('/');
                if let Some(view) = path.strip_suffix("/EyeControls3D") {
                    for field in ["position", "look_target", "eye_up"] {
                        assert!(
                            chunk
                                .components()
                                .keys()
                                .any(|c| c.as_str().contains(field)),
                            "{field}: {:?}",
                            chunk.components().keys().collect::<Vec<_>>()
                        );
                    }
                    eye_controls.push((store.clone(), view.to_owned()));
                } else if path.starts_with("view/") && path.matches('/').count() == 1 {
                    views.push((store.clone(), path.to_owned()));
                }
            }
            _ => {}
        }
    }
    // the unframed layout first, then the framed one, which is the last made active
    assert_eq!(activated.len(), 2, "{activated:?}");
    let last = activated.last().expect("activated");
    assert_eq!(eye_controls.len(), 1, "{eye_controls:?}");
    assert_eq!(&eye_controls[0].0, last);
    assert!(
        views.contains(&eye_controls[0]),
        "the eye belongs to a view of the same blueprint: {eye_controls:?} {views:?}"
    );
}
