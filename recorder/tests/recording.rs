//! Recordings: written by a real session, read back intact, replayed bit for bit, damaged
//! and recovered, and read by an external MCAP reader.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

use cutlab_haptics::device::{Skill, SyntheticTrainee};
use cutlab_haptics::plan::Plan;
use cutlab_haptics::servo::ServoSample;
use cutlab_haptics::tap::{SimRecord, TapSettings};
use cutlab_haptics::{Session, SessionConfig};
use cutlab_recorder::channels::{self, BladeMsg};
use cutlab_recorder::record::{self, Provenance, RecordSettings};
use cutlab_recorder::replay::{self, ReplayOptions};
use cutlab_recorder::writer::RecordObserver;
use cutlab_recorder::{DamageKind, RecorderError, Recording, WriterOptions, recover, scan};
use cutlab_sim::scene::{BuildOptions, Scene};

const SCENE: &str = "chest-wall";
const MIN_TETS: usize = 3000;
const DURATION_S: f64 = 30.0;

/// A temporary folder, removed when the guard drops (with `name` in its name, for a look
/// while a test runs).
fn temp_dir(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("cutlab-recorder-{name}-"))
        .tempdir()
        .expect("temp dir")
}

/// Every record the writer thread saw, for comparison with what the file gives back.
#[derive(Default)]
struct Seen {
    ticks: Vec<ServoSample>,
    sim: Vec<SimRecord>,
}

struct Collect(Arc<Mutex<Seen>>);

impl RecordObserver for Collect {
    fn on_tick(&mut self, sample: &ServoSample) -> Result<(), RecorderError> {
        self.0.lock().expect("lock").ticks.push(*sample);
        Ok(())
    }
    fn on_sim(&mut self, record: &SimRecord) -> Result<(), RecorderError> {
        self.0.lock().expect("lock").sim.push(record.clone());
        Ok(())
    }
}

/// Recording settings: a keyframe and a surface every so many steps (0: no surfaces).
fn record_settings(keyframe_every_steps: u64, surface_every_steps: u64) -> RecordSettings {
    RecordSettings {
        tap: TapSettings {
            keyframe_every_steps,
            surface_every_steps,
            ..TapSettings::default()
        },
        writer: WriterOptions::default(),
    }
}

/// The chest wall at [`MIN_TETS`], settled, and the expert (seed `seed`) following 60 mm
/// across its top, 8 mm deep.
fn expert_on_the_chest_wall(seed: u64) -> (Scene, Session, Plan, Box<SyntheticTrainee>) {
    let scene = Scene::load(
        SCENE,
        BuildOptions {
            min_tets: Some(MIN_TETS),
        },
    )
    .expect("scene");
    let session = Session::new(&scene).expect("session");
    let plan = session.plan_across_top(0.06, 0.008).expect("plan");
    let preset = Skill::preset("expert").expect("preset");
    let device =
        Box::new(SyntheticTrainee::new("expert", plan.clone(), preset, seed).expect("trainee"));
    (scene, session, plan, device)
}

/// Who recorded a session of [`expert_on_the_chest_wall`].
fn provenance(seed: u64) -> Provenance {
    Provenance {
        scene: SCENE.into(),
        min_tets: Some(MIN_TETS),
        seed,
        trainee: "t".into(),
        exercise: "e".into(),
        device: "expert".into(),
    }
}

struct Recorded {
    path: PathBuf,
    seen: Seen,
    ticks: u64,
    steps: u64,
    cut_steps: u64,
    state_hash: u64,
}

/// One 30 s scripted session with cuts (the expert trainee on the chest wall), recorded once
/// and shared by the tests.
fn recorded() -> &'static Recorded {
    static ONCE: OnceLock<Recorded> = OnceLock::new();
    ONCE.get_or_init(|| {
        let (scene, session, plan, device) = expert_on_the_chest_wall(7);
        let config = SessionConfig {
            duration_s: DURATION_S,
            ..SessionConfig::default()
        };
        // one recording shared by the tests of this process (a static: never dropped)
        let path = temp_dir("shared").keep().join("session.mcap");
        let seen = Arc::new(Mutex::new(Seen::default()));
        let provenance = provenance(7);
        let settings = record_settings(1000, 100);
        let r = record::run_recorded(
            session,
            device,
            &config,
            &provenance,
            Some(&plan),
            &scene.spec,
            &path,
            settings,
            Some(Box::new(Collect(seen.clone()))),
        )
        .expect("recorded session");
        let report = r.report.expect("session ran");
        drop(r.observer);
        let seen = Arc::try_unwrap(seen)
            .ok()
            .expect("observer dropped")
            .into_inner()
            .expect("lock");
        Recorded {
            path,
            seen,
            ticks: report.servo.ticks,
            steps: report.sim_steps,
            cut_steps: report.stats.cut_steps,
            state_hash: report.state_hash,
        }
    })
}

#[test]
fn the_recorded_hand_played_back_drives_the_same_session_again() {
    let r = recorded();
    let hand = cutlab_recorder::RecordedHand::new(&Recording::open(&r.path).expect("readable"))
        .expect("a hand to play");
    assert!(
        (hand.duration_s() - (DURATION_S - 0.001)).abs() < 1e-9,
        "{} s",
        hand.duration_s()
    );
    let scene = Scene::load(
        SCENE,
        BuildOptions {
            min_tets: Some(MIN_TETS),
        },
    )
    .expect("scene");
    let config = SessionConfig {
        duration_s: DURATION_S,
        ..SessionConfig::default()
    };
    let again = Session::new(&scene)
        .expect("session")
        .run(Box::new(hand), &config)
        .expect("session driven by the recording");
    assert_eq!(
        (again.servo.ticks, again.stats.cut_steps),
        (r.ticks, r.cut_steps)
    );
    assert_eq!(
        again.state_hash, r.state_hash,
        "the same hand on the same scene gives the same session, bit for bit"
    );
}

#[test]
fn a_recording_reads_back_with_every_message_intact() {
    let r = recorded();
    let rec = Recording::open(&r.path).expect("readable");
    assert!(
        rec.complete && rec.damage.is_none(),
        "a finished recording is complete"
    );
    assert_eq!(r.ticks, 30_000);
    assert!(r.cut_steps > 0, "the session cut");

    // every tick: pose and tool state, exactly
    let samples = rec.samples();
    assert_eq!(samples.len() as u64, r.ticks);
    assert_eq!(r.seen.ticks.len() as u64, r.ticks);
    for s in &r.seen.ticks {
        assert_eq!(samples.get(&s.tick), Some(s), "tick {}", s.tick);
    }
    // every simulation record
    let (mut steps, mut cuts, mut keyframes, mut surfaces, mut damages) = (0, 0, 0, 0, 0);
    let mut surface_steps = Vec::new();
    for record in &r.seen.sim {
        match record {
            SimRecord::Step {
                step,
                tick,
                rejected,
            } => {
                let m = rec.steps[*step as usize];
                assert_eq!((m.step, m.tick, m.rejected), (*step, *tick, *rejected));
                steps += 1;
            }
            SimRecord::Cut {
                step,
                tick,
                blade,
                event,
            } => {
                let m = &rec.topology[cuts];
                assert_eq!((m.step, m.tick), (*step, *tick));
                assert_eq!(m.blade, BladeMsg::from(blade));
                assert_eq!(
                    &m.event, &**event,
                    "the topology event of step {step} reads back bit for bit"
                );
                cuts += 1;
            }
            SimRecord::Keyframe(k) => {
                let m = &rec.keyframes[keyframes];
                assert_eq!(m.hash(), k.hash);
                assert_eq!(rec.hashes[keyframes].hash(), k.hash);
                assert_eq!(m.positions_m.len(), k.positions.len());
                assert!(
                    m.positions_m
                        .iter()
                        .zip(&k.positions)
                        .all(|(a, b)| a == &<[f64; 3]>::from(b.coords))
                );
                assert_eq!(m.tets, k.tets);
                keyframes += 1;
            }
            SimRecord::Surface(s) => {
                surface_steps.push(s.step);
                surfaces += 1;
            }
            SimRecord::Damage { step, tick, damage } => {
                let m = &rec.tissue_damage[damages];
                assert_eq!((m.step, m.tick), (*step, *tick));
                assert_eq!((m.kind, m.region), (damage.kind, damage.region));
                damages += 1;
            }
        }
    }
    // the tissue from the first step on, then one surface every 100 steps
    assert_eq!(surface_steps.first(), Some(&0));
    assert_eq!(surface_steps.get(1..4), Some(&[99, 199, 299][..]));
    assert_eq!(steps, r.steps);
    assert_eq!(damages, rec.tissue_damage.len());
    assert_eq!(cuts as u64, r.cut_steps);
    assert_eq!(cuts, rec.topology.len());
    assert_eq!(keyframes, 30, "one keyframe a second");
    assert_eq!(surfaces, rec.surfaces);
    let meta = rec.meta().expect("metadata");
    assert_eq!(
        (
            meta.provenance.scene.as_str(),
            meta.provenance.min_tets,
            meta.provenance.seed,
            meta.provenance.trainee.as_str()
        ),
        (SCENE, Some(MIN_TETS), 7, "t")
    );
    assert!(rec.plan().expect("plan attachment").is_some());
    assert!(rec.attachment(channels::SCENE_ATTACHMENT).is_some());
    assert_eq!(
        rec.end
            .as_ref()
            .and_then(|e| e.get("status"))
            .map(String::as_str),
        Some("complete")
    );
}

#[test]
fn a_30_s_session_with_cuts_replays_with_every_hash_equal() {
    let r = recorded();
    let rec = Recording::open(&r.path).expect("readable");
    let report = replay::replay(
        &rec,
        ReplayOptions {
            jobs: 1,
            ..ReplayOptions::default()
        },
    )
    .expect("replay runs");
    assert!(
        report.first_divergence.is_none(),
        "{:?}",
        report.first_divergence
    );
    assert_eq!(report.keyframes_checked, 30);
    assert_eq!(report.keyframes_matched, 30);
    assert_eq!(report.cuts_replayed, r.cut_steps);
    assert_eq!(report.steps, r.steps);
    assert!(report.verified());
    assert_eq!(report.final_hash.state, r.state_hash);
    // the stretches between keyframes side by side: the same checks, the same end
    let parallel = replay::replay(
        &rec,
        ReplayOptions {
            jobs: 3,
            ..ReplayOptions::default()
        },
    )
    .expect("replay runs");
    assert_eq!(parallel.jobs, 3);
    assert!(parallel.verified(), "{:?}", parallel.first_divergence);
    let counts = |r: &replay::ReplayReport| {
        (
            r.steps,
            r.keyframes_checked,
            r.keyframes_matched,
            r.cuts_recorded,
            r.cuts_replayed,
            r.final_hash,
        )
    };
    assert_eq!(counts(&parallel), counts(&report));
    assert!((parallel.simulated_s - report.simulated_s).abs() < 1e-9);
}

#[test]
fn a_replay_seeks_through_the_nearest_keyframe_and_stays_bit_exact() {
    let r = recorded();
    let rec = Recording::open(&r.path).expect("readable");
    let period_s = 1e-3;
    // every keyframe can be resumed (the surface BVH was built again at each); one of them
    // in the middle of a stroke
    let resumable: Vec<_> = rec
        .keyframes
        .iter()
        .filter(|k| k.resume.is_some())
        .collect();
    assert_eq!(
        resumable.len(),
        30,
        "every keyframe carries its resume state"
    );
    let mid_stroke = resumable
        .iter()
        .find(|k| {
            k.resume
                .as_ref()
                .is_some_and(|s| !s.cutter.trail.is_empty())
        })
        .expect("a keyframe mid-stroke");
    let mid_stroke_s = (mid_stroke.tick + 1) as f64 * period_s;
    for from_s in [mid_stroke_s + 0.25, 20.2] {
        let to_s = from_s + 2.0;
        let options = ReplayOptions {
            from_s: Some(from_s),
            to_s: Some(to_s),
            ..ReplayOptions::default()
        };
        let seek = replay::replay(&rec, options).expect("replay runs");
        let resumed = seek.resumed_at.expect("resumed at a keyframe");
        let (step, t) = (resumed.step, resumed.session_s);
        assert!(
            (t - (resumed.tick + 1) as f64 * period_s).abs() < 1e-12,
            "the keyframe's time is that of its tick"
        );
        assert!(
            t <= from_s && from_s - t < 1.0,
            "from {from_s} s: resumed at {t} s"
        );
        assert!(
            seek.verified() && seek.keyframes_checked >= 2,
            "from {from_s} s: {:?} ({} keyframes)",
            seek.first_divergence,
            seek.keyframes_checked
        );
        assert!(
            seek.steps < 3100,
            "from {from_s} s: {} steps re-simulated",
            seek.steps
        );
        // the same window re-simulated from the start ends in the same state
        let options = ReplayOptions {
            from_s: Some(from_s),
            to_s: Some(to_s),
            resimulate: true,
            ..ReplayOptions::default()
        };
        let full = replay::replay(&rec, options).expect("replay runs");
        assert!(full.resumed_at.is_none() && full.verified());
        assert_eq!(
            full.final_hash, seek.final_hash,
            "from {from_s} s (resumed at step {step})"
        );
    }

    // a damaged resume state is an error, not a panic nor a silent re-simulation
    let mut damaged = Recording::open(&r.path).expect("readable");
    let k = damaged
        .keyframes
        .iter_mut()
        .find(|k| k.step == mid_stroke.step)
        .expect("keyframe");
    if let Some(resume) = k.resume.as_mut() {
        resume.cutter.stroke.push(u32::MAX);
    }
    let options = ReplayOptions {
        from_s: Some(mid_stroke_s + 0.25),
        ..ReplayOptions::default()
    };
    let err = replay::replay(&damaged, options).expect_err("refused");
    assert!(
        err.to_string()
            .contains(&format!("keyframe at step {}", mid_stroke.step)),
        "{err}"
    );
    // a keyframe whose state was tampered with is caught by its hash
    let mut tampered = Recording::open(&r.path).expect("readable");
    let k = tampered
        .keyframes
        .iter_mut()
        .find(|k| k.step == mid_stroke.step)
        .expect("keyframe");
    k.positions_m[0][0] += 1e-9;
    let report = replay::replay(
        &tampered,
        ReplayOptions {
            from_s: Some(mid_stroke_s + 0.25),
            ..ReplayOptions::default()
        },
    )
    .expect("replay runs");
    let d = report.first_divergence.expect("found");
    assert!(
        d.step == mid_stroke.step && d.what.contains("restored"),
        "{d}"
    );
}

#[test]
fn a_changed_input_is_reported_at_the_step_that_consumed_it() {
    let r = recorded();
    let mut rec = Recording::open(&r.path).expect("readable");
    // nudge the scalpel by 0.1 um at the tick of the second cut: that cut's blade differs
    let cut = rec.topology[1].clone();
    let pose = rec
        .poses
        .iter_mut()
        .find(|p| p.0 == cut.tick)
        .expect("pose of the cut's tick");
    pose.1.x += 1e-7;
    for jobs in [1, 2] {
        let report = replay::replay(
            &rec,
            ReplayOptions {
                jobs,
                ..ReplayOptions::default()
            },
        )
        .expect("replay runs");
        let d = report
            .first_divergence
            .clone()
            .expect("the change is found");
        assert_eq!(
            (d.step, d.tick),
            (cut.step, cut.tick),
            "{jobs} threads: {d}"
        );
        assert!(d.what.contains("blade"), "{d}");
        assert!(!report.verified());
    }
}

#[test]
fn a_different_scene_is_reported_before_the_first_step() {
    let r = recorded();
    let mut rec = Recording::open(&r.path).expect("readable");
    if let Some(m) = rec.meta.as_mut() {
        m.provenance.min_tets = Some(2000);
    }
    let report = replay::replay(&rec, ReplayOptions::default()).expect("replay runs");
    let d = report.first_divergence.expect("found");
    assert_eq!(report.steps, 0);
    assert!(d.what.contains("settled scene"), "{d}");
}

/// A deterministic sequence of offsets in `0..len`.
fn offsets(len: u64, n: usize, seed: u64) -> Vec<u64> {
    let mut rng = cutlab_sim::rng::Rng::new(seed);
    (0..n).map(|_| rng.next_u64() % len).collect()
}

#[test]
fn truncation_at_random_offsets_is_read_and_recovered_without_panics() {
    let r = recorded();
    let bytes = std::fs::read(&r.path).expect("bytes");
    let full = Recording::from_bytes(&bytes).expect("full");
    let full_messages: u64 = full.counts().values().sum();
    let dir_guard = temp_dir("truncated");
    let dir = dir_guard.path();
    let mut cuts = offsets(bytes.len() as u64, 24, 11);
    cuts.extend([
        0,
        3,
        8,
        9,
        64,
        bytes.len() as u64 / 2,
        bytes.len() as u64 - 1,
    ]);
    let mut replayed_partial = false;
    for (k, &at) in cuts.iter().enumerate() {
        let cut = &bytes[..at as usize];
        let damaged = dir.join(format!("cut-{k}.mcap"));
        std::fs::write(&damaged, cut).expect("write");
        let read = Recording::from_bytes(cut);
        let fixed = dir.join(format!("cut-{k}.recovered.mcap"));
        let recovered = recover::recover(&damaged, &fixed);
        let Ok(rec) = read else {
            // only files without even the magic fail to open
            assert!(at < 8, "a file cut at {at} bytes opens");
            assert!(recovered.is_err());
            continue;
        };
        assert!(
            !rec.complete,
            "a file cut at {at} of {} bytes is not complete",
            bytes.len()
        );
        let kept: u64 = rec.counts().values().sum();
        assert!(kept <= full_messages);
        let report = recovered.expect("recovered");
        assert_eq!(
            report.messages, kept,
            "recover keeps what the reader reads (cut at {at})"
        );
        let again = Recording::open(&fixed).expect("the recovered file opens");
        assert!(again.complete, "the recovered file is complete");
        assert_eq!(again.counts().values().sum::<u64>(), kept);
        // a recovered file with a keyframe replays bit for bit up to where it ends
        if !again.hashes.is_empty() && again.meta.is_some() && !replayed_partial {
            let rp = replay::replay(&again, ReplayOptions::default())
                .expect("replay of the recovered part");
            assert!(rp.first_divergence.is_none(), "{:?}", rp.first_divergence);
            assert_eq!(rp.keyframes_matched, rp.keyframes_checked);
            replayed_partial = true;
        }
    }
    assert!(replayed_partial, "some truncated recording kept a keyframe");
}

/// Damage in the middle of a complete file (a flipped CRC, a chunk size of 0xff bytes that
/// once made the parser ask for exabytes) is told apart from a file cut short: it is found at
/// the damaged chunk, every record before it is kept (as many as a file cut at that chunk
/// holds), the summary still announces what was lost, and recovery keeps the same records.
#[test]
fn damage_in_the_middle_is_found_at_its_chunk_and_everything_before_is_kept() {
    let r = recorded();
    let bytes = std::fs::read(&r.path).expect("bytes");
    let whole = Recording::from_bytes(&bytes).expect("whole");
    assert!(whole.is_whole() && whole.shortfall().is_none());
    assert_eq!(whole.announced_steps(), Some(whole.steps.len() as u64));
    let chunks: Vec<usize> = scan::record_spans(&bytes)
        .filter(|s| s.opcode == 0x06)
        .map(|s| s.at)
        .collect();
    assert!(chunks.len() > 4, "{} chunks", chunks.len());
    let at = chunks[chunks.len() / 2];
    let cut_there = Recording::from_bytes(&bytes[..at]).expect("cut short");
    let cut_damage = cut_there.damage.clone().expect("cut short is damage");
    assert_eq!(cut_damage.kind, DamageKind::EndsEarly, "{cut_damage}");
    let dir_guard = temp_dir("mid-damage");
    let dir = dir_guard.path();
    // chunk record: opcode, length, start time, end time, uncompressed size, uncompressed CRC
    for (name, field, width, reason) in [("crc", 9 + 24, 4, "chunk CRC"), ("size", 9 + 16, 8, "")] {
        let mut damaged = bytes.clone();
        damaged[at + field..at + field + width].fill(0xff);
        let rec = Recording::from_bytes(&damaged).expect("opens, damaged");
        let d = rec.damage.clone().expect("damage found");
        assert_eq!(
            (d.kind, d.byte),
            (DamageKind::Corrupt, at as u64),
            "{name}: {d}"
        );
        assert!(d.reason.contains(reason), "{name}: {d}");
        assert!(
            d.to_string()
                .starts_with(&format!("damaged at byte {at} ("))
        );
        assert!(!rec.complete && !rec.is_whole());
        assert_eq!(
            rec.counts(),
            cut_there.counts(),
            "{name}: every record before is kept"
        );
        assert_eq!(rec.announced_steps(), whole.announced_steps());
        assert!(rec.steps.len() < whole.steps.len());
        let why = rec.shortfall().expect("not whole");
        assert!(
            why.contains(&format!("damaged at byte {at}")) && why.contains(" of "),
            "{why}"
        );

        let path = dir.join(format!("{name}.mcap"));
        std::fs::write(&path, &damaged).expect("write");
        let fixed = dir.join(format!("{name}.recovered.mcap"));
        let report = recover::recover(&path, &fixed).expect("recovered");
        let kept: u64 = rec.counts().values().sum();
        assert_eq!(report.messages, kept, "{name}");
        assert_eq!(report.damage.as_ref().map(|d| d.byte), Some(at as u64));
        assert!(report.announced_messages.is_some_and(|n| n > kept));
        let again = Recording::open(&fixed).expect("recovered opens");
        assert!(again.is_whole(), "{:?}", again.damage);
        assert_eq!(again.counts(), rec.counts());
    }
}

#[test]
fn garbage_is_refused_with_a_clear_error() {
    let err = Recording::from_bytes(b"this is not a recording at all").expect_err("refused");
    assert!(err.to_string().contains("not an MCAP file"), "{err}");
    let mut bytes = mcap::MAGIC.to_vec();
    bytes.extend(std::iter::repeat_n(0xffu8, 100));
    let rec = Recording::from_bytes(&bytes).expect("opens, damaged");
    assert!(!rec.complete && rec.damage.is_some());
    assert!(rec.meta().is_err());
}

#[test]
fn a_flushed_recording_is_readable_while_still_open() {
    let r = recorded();
    let rec = Recording::open(&r.path).expect("readable");
    let meta = rec.meta().expect("meta").clone();
    let dir = temp_dir("open");
    let path = dir.path().join("open.mcap");
    let mut sink = cutlab_recorder::McapSink::create(&path, &meta, &[], WriterOptions::default())
        .expect("sink");
    for s in r.seen.ticks.iter().take(1500) {
        sink.on_tick(s).expect("tick");
    }
    sink.flush().expect("flush");
    // what a killed process would leave: no summary, no footer
    let open = Recording::open(&path).expect("readable while open");
    assert!(!open.complete);
    assert_eq!(open.samples().len(), 1500);
    // a recording being made is known as such, and a second sink may not truncate it
    assert!(cutlab_recorder::recording_in_use(&path).expect("lock state"));
    let bytes = std::fs::metadata(&path).expect("metadata").len();
    let busy = cutlab_recorder::McapSink::create(&path, &meta, &[], WriterOptions::default())
        .expect_err("a file being recorded is refused");
    assert!(busy.to_string().contains("another session"), "{busy}");
    assert_eq!(std::fs::metadata(&path).expect("metadata").len(), bytes);
    drop(sink);
    // its writer gone (as when a process dies), the file is free
    assert!(!cutlab_recorder::recording_in_use(&path).expect("lock state"));
}

/// The `mcap` package from PyPI (a reader nobody here wrote) reads the recording with CRC
/// checks, and decodes the Foxglove protobuf poses with the schema the file carries.
#[test]
fn the_external_mcap_reader_reads_it_with_crc_checks() {
    let Ok(python) = std::env::var("CUTLAB_MCAP_PYTHON") else {
        eprintln!(
            "skipped: CUTLAB_MCAP_PYTHON is not set (.ci/run sets it to a venv with mcap and mcap-protobuf-support)"
        );
        return;
    };
    let r = recorded();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/read_mcap.py");
    let out = std::process::Command::new(python)
        .arg(&script)
        .arg(&r.path)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    let rec = Recording::open(&r.path).expect("readable");
    for (topic, n) in rec.counts() {
        // a channel without messages (no damage done) is not in the reader's counts
        assert_eq!(v["counts"][&topic].as_u64().unwrap_or(0), n, "{topic}");
    }
    let first = rec.samples().into_values().next().expect("a tick");
    let x = v["first_pose_xyz"][0].as_f64().expect("x");
    assert_eq!(x.to_bits(), first.pose.tip_in_world.x.to_bits());
    assert_eq!(v["first_tool_state"]["tick"].as_u64(), Some(0));
    let meta_names: Vec<&str> = v["metadata"]
        .as_array()
        .expect("metadata")
        .iter()
        .filter_map(|m| m.as_str())
        .collect();
    assert!(
        meta_names.contains(&channels::SESSION_METADATA)
            && meta_names.contains(&channels::SESSION_END_METADATA)
    );
    let attachments: Vec<&str> = v["attachments"]
        .as_array()
        .expect("attachments")
        .iter()
        .filter_map(|m| m.as_str())
        .collect();
    assert!(
        attachments.contains(&channels::PLAN_ATTACHMENT)
            && attachments.contains(&channels::SCENE_ATTACHMENT)
    );
}

#[test]
fn a_localised_session_with_cuts_replays_localised_and_bit_exact() {
    let (scene, mut session, plan, device) = expert_on_the_chest_wall(7);
    session.sim.settings.localisation = Some(cutlab_sim::solver::LocalisationSettings::default());
    let config = SessionConfig {
        duration_s: 8.0,
        ..SessionConfig::default()
    };
    let dir = temp_dir("localised");
    let path = dir.path().join("session.mcap");
    let provenance = provenance(7);
    let settings = record_settings(500, 0);
    let r = record::run_recorded(
        session,
        device,
        &config,
        &provenance,
        Some(&plan),
        &scene.spec,
        &path,
        settings,
        None,
    )
    .expect("recorded session");
    let report = r.report.expect("session ran");
    assert!(report.stats.cut_steps > 0, "{:?}", report.stats);

    let rec = Recording::open(&path).expect("readable");
    assert_eq!(
        rec.meta().expect("meta").localisation,
        Some(cutlab_sim::solver::LocalisationSettings::default())
    );
    let replayed = replay::replay(&rec, ReplayOptions::default()).expect("replay runs");
    assert!(replayed.verified(), "{:?}", replayed.first_divergence);
    assert_eq!(replayed.cuts_replayed, report.stats.cut_steps);
    assert_eq!(replayed.keyframes_checked, 16);
    // seeking restores the localised region too
    let seek = replay::replay(
        &rec,
        ReplayOptions {
            from_s: Some(5.2),
            ..ReplayOptions::default()
        },
    )
    .expect("replay runs");
    assert_eq!(seek.resumed_at.map(|k| k.step), Some(4999));
    assert!(
        seek.verified() && seek.keyframes_checked == 6,
        "{:?}",
        seek.first_divergence
    );
    assert_eq!(seek.final_hash, replayed.final_hash);
}

/// A trajectory file (`csv:` device) that presses the blade through the middle of the `sheet`
/// (its top at z = 2 mm) and traces a circle of radius 20 mm 1.08 times round at 7 mm/s, the
/// cutting edge (tool +z) upright and its cutting direction (tool +x) along the circle; then
/// lifts. Written as a person's script would be: a row every 20 ms.
fn circle_through_the_sheet(path: &Path) -> f64 {
    let (cx, cy, r, turns) = (0.05, 0.05, 0.02, 1.08);
    let mut rows = vec!["t_s, x_m, y_m, z_m, qw, qx, qy, qz, button".to_string()];
    let mut t = 0.0;
    let mut row = |t: &mut f64, a: f64, z: f64, button: u8| {
        // world_from_tool: a turn about z taking tool +x to the circle's tangent
        let half = (a + std::f64::consts::FRAC_PI_2) / 2.0;
        let (x, y) = (cx + r * a.cos(), cy + r * a.sin());
        rows.push(format!(
            "{t:.3}, {x:.6}, {y:.6}, {z:.6}, {:.9}, 0, 0, {:.9}, {button}",
            half.cos(),
            half.sin()
        ));
        *t += 0.02;
    };
    for k in 0..=50 {
        row(
            &mut t,
            0.0,
            0.012 - 0.014 * k as f64 / 50.0,
            u8::from(k > 0),
        );
    }
    let samples = (turns * std::f64::consts::TAU * r / 0.007 / 0.02) as usize;
    for k in 1..=samples {
        let a = turns * std::f64::consts::TAU * k as f64 / samples as f64;
        row(&mut t, a, -0.002, 1);
    }
    let end = turns * std::f64::consts::TAU;
    for k in 1..=25 {
        row(
            &mut t,
            end,
            -0.002 + 0.02 * k as f64 / 25.0,
            u8::from(k < 3),
        );
    }
    std::fs::write(path, rows.join("\n") + "\n").expect("trajectory written");
    t
}

/// Records a session on the sheet played from the CSV `trajectory` into `path`.
fn record_sheet_from_csv(
    trajectory: &Path,
    config: &SessionConfig,
    settings: RecordSettings,
    path: &Path,
) -> cutlab_haptics::SessionReport {
    let scene = Scene::load("sheet", BuildOptions::default()).expect("scene");
    let session = Session::new(&scene).expect("session");
    let device =
        Box::new(cutlab_haptics::device::CsvDevice::open(trajectory).expect("a valid trajectory"));
    let provenance = Provenance {
        scene: "sheet".into(),
        min_tets: None,
        seed: 0,
        trainee: "t".into(),
        exercise: "e".into(),
        device: format!("csv:{}", trajectory.display()),
    };
    let r = record::run_recorded(
        session,
        device,
        config,
        &provenance,
        None,
        &scene.spec,
        path,
        settings,
        None,
    )
    .expect("recorded session");
    r.report.expect("session ran")
}

#[test]
fn a_closed_circle_through_the_sheet_frees_a_specimen_recorded_and_replayed_bit_exact() {
    let dir = temp_dir("circle");
    let trajectory = dir.path().join("circle.csv");
    let duration_s = circle_through_the_sheet(&trajectory) + 0.5;
    let config = SessionConfig {
        duration_s,
        ..SessionConfig::default()
    };
    let path = dir.path().join("session.mcap");
    let report = record_sheet_from_csv(&trajectory, &config, record_settings(5000, 0), &path);
    assert_eq!(report.stats.specimens, 1, "{:?}", report.stats);
    // the whole sheet and the disc, no fragment
    let sim = &report.simulation;
    let pieces = cutlab_sim::mesh::pieces(&sim.model.mesh, &sim.model.held);
    assert_eq!(pieces.len(), 2, "{pieces:?}");

    let rec = Recording::open(&path).expect("readable");
    let specimens: Vec<_> = rec.specimens().collect();
    assert_eq!(specimens.len(), 1);
    let (step, tick, disc) = specimens[0];
    assert!(
        step > 0 && tick >= step,
        "freed at step {step}, tick {tick}"
    );
    let area = disc.volume_m3 / 0.002;
    assert!(
        (area / (std::f64::consts::PI * 0.02 * 0.02) - 1.0).abs() < 0.05,
        "disc of {:.0} mm2",
        area * 1e6
    );
    assert!(pieces.iter().any(|p| p.tets == disc.tets));
    let replayed = replay::replay(&rec, ReplayOptions::default()).expect("replay runs");
    assert!(replayed.verified(), "{:?}", replayed.first_divergence);
    assert_eq!(replayed.cuts_replayed, report.stats.cut_steps);
}

/// A session's last keyframe can be resumed whenever the session ends (here 0.737 s, between
/// two of its regular keyframes): scoring a field resumes it to set a retractor in the wound.
#[test]
fn the_last_keyframe_can_be_resumed_wherever_the_session_ends() {
    let (scene, session, plan, device) = expert_on_the_chest_wall(3);
    let config = SessionConfig {
        duration_s: 0.737,
        collider_rebuild_every_steps: 100,
        ..SessionConfig::default()
    };
    let dir = temp_dir("last-keyframe");
    let path = dir.path().join("session.mcap");
    let provenance = provenance(3);
    let r = record::run_recorded(
        session,
        device,
        &config,
        &provenance,
        Some(&plan),
        &scene.spec,
        &path,
        record_settings(100, 0),
        None,
    )
    .expect("recorded session");
    let steps = r.report.expect("session ran").sim_steps;
    assert!(
        !steps.is_multiple_of(100),
        "{steps} steps end between keyframes"
    );
    let rec = Recording::open(&path).expect("read back");
    let last = rec.keyframes.last().expect("a keyframe");
    assert_eq!(last.step + 1, steps, "the last keyframe is the last step's");
    let (stepper, tick) = replay::stepper_at_last_keyframe(&rec).expect("resumed");
    assert_eq!((tick, stepper.steps()), (last.tick, steps));
}

/// Two hands on the gauze: the expert's scalpel across the pad while a grasper hand holds it
/// 8 mm beside the line and draws it 4 mm up. The grasper's pose and jaws go to their own
/// channels; the replay, from the start and seeking to a keyframe while the jaws hold, runs
/// both hands again bit for bit.
#[test]
fn a_two_handed_session_records_the_grasper_and_replays_bit_exact() {
    use cutlab_haptics::device::{GraspPlan, GrasperHand};
    let scene = Scene::load("gauze", BuildOptions::default()).expect("scene");
    let session = Session::new(&scene).expect("session");
    let plan = session.plan_across_top(0.04, 0.0015).expect("plan");
    let preset = Skill::preset("expert").expect("preset");
    let scalpel = Box::new(SyntheticTrainee::new("expert", plan.clone(), preset, 5).expect("hand"));
    let hold_m = plan.line_m[plan.line_m.len() / 2] + cutlab_haptics::Vector3::new(0.0, 0.008, 0.0);
    let grasp = GraspPlan {
        hold_m,
        pull_m: cutlab_haptics::Vector3::new(0.0, 0.0, 0.004),
        up: cutlab_haptics::Vector3::z(),
        release_s: Some(4.5),
    };
    let grasper = Box::new(GrasperHand::new(grasp, 5).expect("grasper"));
    let config = SessionConfig {
        duration_s: 5.0,
        ..SessionConfig::default()
    };
    let dir = temp_dir("two-hands");
    let path = dir.path().join("session.mcap");
    let provenance = Provenance {
        scene: "gauze".into(),
        min_tets: None,
        seed: 5,
        trainee: "t".into(),
        exercise: "e".into(),
        device: "expert".into(),
    };
    let r = record::run_recorded(
        session,
        cutlab_haptics::Hands {
            scalpel,
            grasper: Some(grasper),
        },
        &config,
        &provenance,
        Some(&plan),
        &scene.spec,
        &path,
        record_settings(500, 0),
        None,
    )
    .expect("recorded session");
    let report = r.report.expect("session ran");
    let stats = report.stats;
    assert_eq!(stats.grasps, 1, "{stats:?}");
    assert_eq!(stats.grasp_slips, 0, "{stats:?}");
    // held from 1.2 s to 4.5 s, at 1 ms steps
    assert!((3200..=3400).contains(&stats.grasp_steps), "{stats:?}");
    assert!(stats.max_grasp_pull_newtons > 0.01, "{stats:?}");
    assert!(stats.cut_steps > 0, "{stats:?}");
    // released at the end: nothing of the pad is held but its clips
    let sim = &report.simulation;
    let clips = Session::new(&scene).expect("session").sim.model.held;
    let held_now = sim.model.held.iter().filter(|h| **h).count();
    assert_eq!(held_now, clips.iter().filter(|h| **h).count());

    let rec = Recording::open(&path).expect("readable");
    assert_eq!(rec.grasper_poses.len() as u64, report.servo.ticks);
    let closed = rec
        .grasper_states
        .iter()
        .filter(|s| s.buttons & cutlab_haptics::pose::BUTTON_JAWS != 0)
        .count();
    assert!((3200..=3400).contains(&closed), "{closed} ticks closed");
    // the held tissue's pull on the jaws, every tick they held it
    let pulls: Vec<f64> = rec
        .grasper_states
        .iter()
        .map(|s| cutlab_haptics::Vector3::from(s.pull_newtons).norm())
        .collect();
    let held = pulls.iter().filter(|p| **p > 0.0).count();
    assert!((3200..=3400).contains(&held), "{held} ticks held");
    let strongest = pulls.iter().copied().fold(0.0, f64::max);
    assert!(
        (strongest - stats.max_grasp_pull_newtons).abs() <= 0.02 * stats.max_grasp_pull_newtons,
        "{strongest} N recorded, {} N simulated",
        stats.max_grasp_pull_newtons
    );
    let replayed = replay::replay(&rec, ReplayOptions::default()).expect("replay runs");
    assert!(replayed.verified(), "{:?}", replayed.first_divergence);
    assert_eq!(replayed.final_hash.state, report.state_hash);
    // a keyframe while the jaws hold (2.5 s): resumed with its grasp, on to the end
    let seek = replay::replay(
        &rec,
        ReplayOptions {
            from_s: Some(2.7),
            ..ReplayOptions::default()
        },
    )
    .expect("replay runs");
    let resumed = seek.resumed_at.expect("resumed at a keyframe");
    let held_there = rec
        .keyframes
        .iter()
        .find(|k| k.step == resumed.step)
        .and_then(|k| k.resume.as_ref())
        .is_some_and(|r| r.grasp.is_some());
    assert!(
        held_there,
        "the keyframe at step {} holds the grasp",
        resumed.step
    );
    assert!(seek.verified(), "{:?}", seek.first_divergence);
    assert_eq!(seek.final_hash, replayed.final_hash);
}

/// A session in which the trainee sets the wound retractor (the scalpel's retract button)
/// into a line cut through the sheet and takes it out again: recorded, it replays bit for
/// bit from the start and from a keyframe taken while the retractor holds the wound open.
#[test]
fn a_session_with_the_retractor_set_replays_bit_exact_from_a_keyframe_in_it() {
    let dir = temp_dir("retract");
    let trajectory = dir.path().join("retract.csv");
    // x, y, z of the tip and the buttons at t: in 0.2 s through the sheet at x = 30 mm, along
    // to 70 mm in 1.6 s, lifted, the retractor held from 2.2 to 3.4 s, then let go
    let rows: Vec<String> = [
        (0.0, 0.030, 0.004, 0),
        (0.2, 0.030, -0.002, 1),
        (1.8, 0.070, -0.002, 1),
        (2.0, 0.070, 0.006, 0),
        (2.2, 0.070, 0.006, 4),
        (3.4, 0.070, 0.006, 4),
        (3.45, 0.070, 0.006, 0),
    ]
    .iter()
    .map(|(t, x, z, b)| format!("{t}, {x}, 0.0503, {z}, 1, 0, 0, 0, {b}"))
    .collect();
    let header = "t_s, x_m, y_m, z_m, qw, qx, qy, qz, button";
    std::fs::write(&trajectory, format!("{header}\n{}\n", rows.join("\n"))).expect("written");
    let config = SessionConfig {
        duration_s: 4.0,
        collider_rebuild_every_steps: 500,
        ..SessionConfig::default()
    };
    let path = dir.path().join("session.mcap");
    let report = record_sheet_from_csv(&trajectory, &config, record_settings(500, 0), &path);
    assert_eq!(report.stats.retractions, 1, "{:?}", report.stats);
    let rec = Recording::open(&path).expect("readable");
    let open = rec
        .keyframes
        .iter()
        .find(|k| {
            k.resume
                .as_ref()
                .is_some_and(|s| s.retraction.opening.is_some())
        })
        .expect("a keyframe with the retractor set");
    let replayed = replay::replay(&rec, ReplayOptions::default()).expect("replay runs");
    assert!(replayed.verified(), "{:?}", replayed.first_divergence);
    let from_s = (open.tick + 1) as f64 * 1e-3 + 0.1;
    let seek = replay::replay(
        &rec,
        ReplayOptions {
            from_s: Some(from_s),
            ..ReplayOptions::default()
        },
    )
    .expect("replay runs");
    assert!(
        seek.resumed_at.is_some_and(|k| k.tick == open.tick),
        "{:?}",
        seek.resumed_at
    );
    assert!(
        seek.verified() && seek.keyframes_checked >= 2,
        "{:?} ({} keyframes)",
        seek.first_divergence,
        seek.keyframes_checked
    );
}
