//! `cutlab bench recorder`: what recording costs and gives. The same scripted session (the
//! expert trainee on the chest wall, virtual clock) runs without and with the MCAP recorder;
//! then the recording is replayed and checked.
//!
//! Figures: the servo loop's work per tick (p50/p99) without and with the recorder (its one
//! extra cost on the servo thread is a push into a lock-free queue), the file size per minute
//! of session, the writer's throughput (payload bytes per second of its busy time), and the
//! replay speed against real time (on one thread, and on every core: the stretches between
//! keyframes side by side); and seeking to the middle of the session: resuming at the
//! keyframe before it against re-simulating the steps up to it.

use std::path::Path;

use anyhow::Context;
use cutlab_haptics::device::{Skill, SyntheticTrainee};
use cutlab_haptics::tap::TapSettings;
use cutlab_haptics::{Session, SessionConfig};
use cutlab_recorder::record::{self, Provenance, RecordSettings};
use cutlab_recorder::replay::{self, ReplayOptions};
use cutlab_recorder::{Recording, WriterOptions};
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::LocalisationSettings;
use cutlab_sim::stats::Summary;
use serde::Serialize;

#[derive(Debug, Serialize)]
struct Figures {
    scene: String,
    tets: usize,
    localised: bool,
    session_s: f64,
    tick_work_us_unrecorded: Summary,
    tick_work_us_recorded: Summary,
    dropped_tick_records: u64,
    file_bytes: u64,
    file_mb_per_minute: f64,
    payload_mb: f64,
    messages: u64,
    writer_busy_s: f64,
    writer_mb_per_s: f64,
    replay_wall_s: f64,
    replay_speed: f64,
    replay_verified: bool,
    keyframes_checked: u64,
    /// The same replay with the stretches between keyframes on every core.
    replay_parallel_threads: usize,
    replay_parallel_wall_s: f64,
    replay_parallel_speed: f64,
    replay_parallel_verified: bool,
    seek_to_s: f64,
    /// Seeking by resuming at the keyframe before `seek_to_s` (its hashes checked): wall time,
    /// and the keyframe's time.
    seek_wall_s: f64,
    seek_resumed_at_s: Option<f64>,
    seek_restore_verified: bool,
    /// Seeking by re-simulating every step up to `seek_to_s`: wall time.
    seek_resimulate_wall_s: f64,
}

pub fn run(
    min_tets: Option<usize>,
    duration_s: f64,
    localise: bool,
    json: bool,
    out: &Path,
) -> anyhow::Result<()> {
    if !(duration_s > 0.0 && duration_s <= 3600.0) {
        anyhow::bail!("--duration must be in (0, 3600] s");
    }
    let scene =
        Scene::load("chest-wall", BuildOptions { min_tets }).context("loading the chest wall")?;
    let config = SessionConfig {
        duration_s,
        ..SessionConfig::default()
    };
    let make =
        || -> anyhow::Result<(Session, cutlab_haptics::plan::Plan, Box<SyntheticTrainee>)> {
            let mut session = Session::new(&scene)?;
            if localise {
                session.sim.settings.localisation = Some(LocalisationSettings::default());
            }
            let plan = session.plan_across_top(0.06, 0.008)?;
            let device = Box::new(SyntheticTrainee::new(
                "expert",
                plan.clone(),
                Skill::preset("expert").context("expert preset")?,
                1,
            )?);
            Ok((session, plan, device))
        };
    let tick_us = |r: &cutlab_haptics::SessionReport| {
        Summary::of(
            &r.servo
                .tick_work_nanos
                .iter()
                .map(|&n| n as f64 * 1e-3)
                .collect::<Vec<_>>(),
        )
    };

    if !json {
        eprintln!(
            "session without the recorder ({duration_s} s, {} tets)...",
            scene.model.mesh.tet_count()
        );
    }
    let (session, _, device) = make()?;
    let plain = session.run(device, &config)?;

    if !json {
        eprintln!("session with the recorder...");
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let path = out.join("session.mcap");
    let (session, plan, device) = make()?;
    let provenance = Provenance {
        scene: "chest-wall".into(),
        min_tets,
        seed: 1,
        device: "expert".into(),
        ..Provenance::default()
    };
    let settings = RecordSettings {
        tap: TapSettings::default(),
        writer: WriterOptions::default(),
    };
    let recorded = record::run_recorded(
        session,
        device,
        &config,
        &provenance,
        Some(&plan),
        &scene.spec,
        &path,
        settings,
        None,
    )?;
    let report = recorded.report?;
    let file_bytes = std::fs::metadata(&path)?.len();

    if !json {
        eprintln!("replaying...");
    }
    let rec = Recording::open(&path)?;
    let rp = replay::replay(
        &rec,
        ReplayOptions {
            jobs: 1,
            ..ReplayOptions::default()
        },
    )?;
    let parallel = replay::replay(
        &rec,
        ReplayOptions {
            jobs: 0,
            ..ReplayOptions::default()
        },
    )?;
    if !json {
        eprintln!("seeking...");
    }
    let seek_to_s = duration_s / 2.0 + 0.5;
    let window = |resimulate| {
        replay::replay(
            &rec,
            ReplayOptions {
                from_s: Some(seek_to_s),
                to_s: Some(seek_to_s),
                resimulate,
                jobs: 1,
                ..ReplayOptions::default()
            },
        )
    };
    let (seek, resimulated) = (window(false)?, window(true)?);
    let w = &recorded.write;
    let f = Figures {
        scene: "chest-wall".into(),
        tets: scene.model.mesh.tet_count(),
        localised: localise,
        session_s: duration_s,
        tick_work_us_unrecorded: tick_us(&plain),
        tick_work_us_recorded: tick_us(&report),
        dropped_tick_records: report.servo.dropped_records,
        file_bytes,
        file_mb_per_minute: file_bytes as f64 * 1e-6 * 60.0 / duration_s,
        payload_mb: w.payload_bytes as f64 * 1e-6,
        messages: w.messages.values().sum(),
        writer_busy_s: w.busy_s,
        writer_mb_per_s: w.payload_bytes as f64 * 1e-6 / w.busy_s.max(1e-9),
        replay_wall_s: rp.wall_s,
        replay_speed: rp.speed(),
        replay_verified: rp.verified(),
        keyframes_checked: rp.keyframes_checked,
        replay_parallel_threads: parallel.jobs,
        replay_parallel_wall_s: parallel.wall_s,
        replay_parallel_speed: parallel.speed(),
        replay_parallel_verified: parallel.verified() && parallel.final_hash == rp.final_hash,
        seek_to_s,
        seek_wall_s: seek.wall_s,
        seek_resumed_at_s: seek.resumed_at.map(|k| k.session_s),
        seek_restore_verified: seek.resumed_at.is_some() && seek.first_divergence.is_none(),
        seek_resimulate_wall_s: resimulated.wall_s,
    };
    if json {
        println!("{}", serde_json::to_string_pretty(&f)?);
        return Ok(());
    }
    let how = if f.localised { "localised" } else { "full" };
    println!(
        "recorder on a {:.0} s session, {} ({} tets, {how} simulation), expert trainee, virtual clock",
        f.session_s, f.scene, f.tets
    );
    let t = |s: &Summary| {
        format!(
            "p50 {:.2} us, p99 {:.2} us, max {:.1} us",
            s.median, s.p99, s.max
        )
    };
    println!(
        "  servo work per tick without the recorder: {}",
        t(&f.tick_work_us_unrecorded)
    );
    println!(
        "  servo work per tick with the recorder:    {}",
        t(&f.tick_work_us_recorded)
    );
    println!("  dropped tick records: {}", f.dropped_tick_records);
    println!(
        "  file: {:.2} MB ({:.1} MB per minute of session); {} messages, {:.1} MB of payload before compression",
        f.file_bytes as f64 * 1e-6,
        f.file_mb_per_minute,
        f.messages,
        f.payload_mb
    );
    println!(
        "  writer thread: busy {:.2} s, {:.0} MB/s of payload",
        f.writer_busy_s, f.writer_mb_per_s
    );
    println!(
        "  replay: {:.2} s wall, {:.2}x real time, {} ({} keyframes)",
        f.replay_wall_s,
        f.replay_speed,
        if f.replay_verified {
            "bit-exact"
        } else {
            "DIVERGED"
        },
        f.keyframes_checked
    );
    println!(
        "  replay on {} threads (the stretches between keyframes side by side): {:.2} s wall, {:.2}x real time, {}",
        f.replay_parallel_threads,
        f.replay_parallel_wall_s,
        f.replay_parallel_speed,
        if f.replay_parallel_verified {
            "bit-exact, the same final state"
        } else {
            "DIVERGED"
        }
    );
    match f.seek_resumed_at_s {
        Some(t) => println!(
            "  seek to {:.1} s: {:.2} s wall resuming at the keyframe of {t:.1} s (hashes {}), {:.2} s re-simulating from the start",
            f.seek_to_s,
            f.seek_wall_s,
            if f.seek_restore_verified {
                "equal"
            } else {
                "DIFFER"
            },
            f.seek_resimulate_wall_s
        ),
        None => println!(
            "  seek to {:.1} s: no keyframe to resume at; {:.2} s re-simulating from the start",
            f.seek_to_s, f.seek_resimulate_wall_s
        ),
    }
    Ok(())
}
